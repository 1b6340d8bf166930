//! Directional light (Mitsuba's `directional`): irradiance E arriving from one direction.

use super::bounds::EmitterBounds;
use super::channel_mean;
use super::{EmissionSample, LightSample, SceneSphere};
use crate::math::Ray;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A distant light.
#[derive(Debug, Clone, Copy)]
pub struct DirectionalLight {
    /// Unit direction of propagation.
    pub direction: Vec3,
    /// Irradiance on a surface facing the light.
    pub irradiance: Rgb,
}

impl DirectionalLight {
    /// Direct illumination at `p` (the shadow ray is unbounded).
    pub fn sample_li(&self, p: Vec3, sphere: &SceneSphere) -> LightSample {
        let wi = -self.direction;
        LightSample {
            wi,
            p: p + wi * (2.0 * sphere.radius + (p - sphere.center).length()),
            dist: f32::INFINITY,
            weight: self.irradiance,
            pdf: 1.0,
            delta: true,
            infinite: true,
            light: 0,
        }
    }

    /// A photon starting on a disk covering the scene's bounding sphere, facing the light.
    pub fn sample_emission(&self, u: Vec2, sphere: &SceneSphere) -> EmissionSample {
        EmissionSample {
            ray: Ray::new(sphere.photon_origin(self.direction, u), self.direction),
            flux: self.irradiance * (PI * sphere.radius * sphere.radius),
            light: 0,
        }
    }

    /// Emission bounds for light selection: the irradiance on a surface facing the light.
    pub fn bounds(&self) -> EmitterBounds {
        EmitterBounds::Directional {
            toward: -self.direction,
            irradiance: channel_mean(self.irradiance),
        }
    }

    /// Power through the scene's bounding disk, E·πR².
    pub fn power(&self, sphere: &SceneSphere) -> Rgb {
        self.irradiance * (PI * sphere.radius * sphere.radius)
    }
}
