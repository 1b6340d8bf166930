//! `conductor`: a smooth metal mirror with the exact conductor Fresnel term.

use super::fresnel::{fresnel_conductor, reflect};
use super::{BsdfSample, Conductor, ConductorIor};
use crate::spectrum::Rgb;
use crate::texture::TexPoint;
use glam::Vec3;

/// Conductor Fresnel reflectance; `None` (Mitsuba's `material="none"`) reflects everything.
pub(super) fn conductor_reflectance(ior: &Option<ConductorIor>, cos_theta_i: f32) -> Rgb {
    match ior {
        Some(ior) => fresnel_conductor(cos_theta_i, ior.eta, ior.k),
        None => Rgb::ONE,
    }
}

impl Conductor {
    pub(super) fn sample(&self, wo: Vec3, tp: TexPoint) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let weight = self.specular_reflectance.eval(tp) * conductor_reflectance(&self.ior, wo.z);
        Some(BsdfSample {
            wi: reflect(wo),
            weight,
            pdf: 1.0,
            delta: true,
            eta: 1.0,
        })
    }
}
