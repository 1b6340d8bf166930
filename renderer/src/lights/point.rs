//! Point light (Mitsuba's `point`): radiant intensity I (W/sr) from one position.

use super::bounds::LightBounds;
use super::channel_mean;
use super::{EmissionSample, LightSample};
use crate::math::Ray;
use crate::sampling::{square_to_uniform_sphere, UNIFORM_SPHERE_PDF};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// An isotropic point light.
#[derive(Debug, Clone, Copy)]
pub struct PointLight {
    /// Position.
    pub position: Vec3,
    /// Radiant intensity.
    pub intensity: Rgb,
}

impl PointLight {
    /// Direct illumination at `p`: irradiance-like weight I / d².
    pub fn sample_li(&self, p: Vec3) -> Option<LightSample> {
        let d = self.position - p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let dist = dist2.sqrt();
        Some(LightSample {
            wi: d / dist,
            p: self.position,
            dist,
            weight: self.intensity / dist2,
            pdf: 1.0,
            delta: true,
            infinite: false,
            light: 0,
        })
    }

    /// A photon in a uniformly sampled direction: flux I / (1/4π).
    pub fn sample_emission(&self, u: Vec2) -> EmissionSample {
        let d = square_to_uniform_sphere(u);
        EmissionSample {
            ray: Ray::new(self.position, d),
            flux: self.intensity / UNIFORM_SPHERE_PDF,
            light: 0,
        }
    }

    /// Emission bounds for light selection: intensity I into every direction.
    pub fn bounds(&self) -> LightBounds {
        LightBounds::omnidirectional(self.position, 0.0, channel_mean(self.intensity))
    }

    /// Power 4πI.
    pub fn power(&self) -> Rgb {
        self.intensity * (4.0 * std::f32::consts::PI)
    }
}
