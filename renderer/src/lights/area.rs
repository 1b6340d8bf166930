//! Area light (Mitsuba's `area`): constant radiance leaving the front side of a shape.

use super::{EmissionSample, LightSample};
use crate::math::{coordinate_system, spawn_ray};
use crate::sampling::square_to_cosine_hemisphere;
use crate::shapes::Shape;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Emission attached to a shape.
#[derive(Debug, Clone, Copy)]
pub struct AreaLight {
    /// Index of the shape in the scene.
    pub shape: u32,
    /// Emitted radiance.
    pub radiance: Rgb,
}

impl AreaLight {
    /// Radiance leaving the surface with normal `n` in direction `w` (front side only).
    #[inline]
    pub fn eval(&self, n: Vec3, w: Vec3) -> Rgb {
        if n.dot(w) > 0.0 {
            self.radiance
        } else {
            Rgb::ZERO
        }
    }

    /// Direct illumination at `p` from a point sampled uniformly by area on `shape`.
    pub fn sample_li(&self, shape: &Shape, p: Vec3, u_prim: f32, u: Vec2) -> Option<LightSample> {
        let s = shape.sample_area(u_prim, u);
        let d = s.p - p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let dist = dist2.sqrt();
        let wi = d / dist;
        let cos_l = -s.n.dot(wi);
        if cos_l <= 0.0 {
            return None;
        }
        let pdf = s.pdf * dist2 / cos_l;
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        Some(LightSample {
            wi,
            p: s.p,
            dist,
            weight: self.radiance / pdf,
            pdf,
            delta: false,
            infinite: false,
            light: 0,
        })
    }

    /// Solid-angle density of [`Self::sample_li`] for a hit at distance `dist` where the light's
    /// normal makes cosine `cos_l` with the ray.
    #[inline]
    pub fn pdf_li(&self, shape: &Shape, dist: f32, cos_l: f32) -> f32 {
        if cos_l <= 0.0 {
            return 0.0;
        }
        dist * dist / (cos_l * shape.area())
    }

    /// A photon from a uniform point, cosine-distributed over the front hemisphere: flux L·π·A.
    pub fn sample_emission(
        &self,
        shape: &Shape,
        u_prim: f32,
        u_pos: Vec2,
        u_dir: Vec2,
    ) -> EmissionSample {
        let s = shape.sample_area(u_prim, u_pos);
        let local = square_to_cosine_hemisphere(u_dir);
        let (t, b) = coordinate_system(s.n);
        let d = (t * local.x + b * local.y + s.n * local.z).normalize();
        EmissionSample {
            ray: spawn_ray(s.p, s.n, d),
            flux: self.radiance * (PI / s.pdf),
            light: 0,
        }
    }

    /// Power L·π·A.
    pub fn power(&self, shape: &Shape) -> Rgb {
        self.radiance * (PI * shape.area())
    }
}
