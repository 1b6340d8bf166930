//! Constant environment (Mitsuba's `constant`): the same radiance from every direction.

use super::bounds::EmitterBounds;
use super::channel_mean;
use super::{EmissionSample, LightSample, SceneSphere};
use crate::math::Ray;
use crate::sampling::{square_to_uniform_sphere, UNIFORM_SPHERE_PDF};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A uniform environment light.
#[derive(Debug, Clone, Copy)]
pub struct ConstantLight {
    /// Radiance.
    pub radiance: Rgb,
}

impl ConstantLight {
    /// Direct illumination at `p` from a uniformly sampled direction.
    pub fn sample_li(&self, p: Vec3, u: Vec2, sphere: &SceneSphere) -> LightSample {
        let wi = square_to_uniform_sphere(u);
        LightSample {
            wi,
            p: p + wi * (2.0 * sphere.radius + (p - sphere.center).length()),
            dist: f32::INFINITY,
            weight: self.radiance / UNIFORM_SPHERE_PDF,
            pdf: UNIFORM_SPHERE_PDF,
            delta: false,
            infinite: true,
            light: 0,
        }
    }

    /// Solid-angle density of [`Self::sample_li`].
    pub fn pdf_li(&self) -> f32 {
        UNIFORM_SPHERE_PDF
    }

    /// A photon arriving from a uniform direction, starting on a disk that covers the scene's
    /// bounding sphere: flux L·4π·πR².
    pub fn sample_emission(
        &self,
        u_dir: Vec2,
        u_pos: Vec2,
        sphere: &SceneSphere,
    ) -> EmissionSample {
        let d = -square_to_uniform_sphere(u_dir);
        EmissionSample {
            ray: Ray::new(sphere.photon_origin(d, u_pos), d),
            flux: self.power(sphere),
            light: 0,
        }
    }

    /// Emission bounds for light selection: π·L on one side of any surface.
    pub fn bounds(&self) -> EmitterBounds {
        EmitterBounds::Environment {
            irradiance: PI * channel_mean(self.radiance),
        }
    }

    /// Power entering the bounding sphere, L·4π·πR².
    pub fn power(&self, sphere: &SceneSphere) -> Rgb {
        self.radiance * (4.0 * PI * PI * sphere.radius * sphere.radius)
    }
}
