//! `dielectric`: a smooth glass interface (Fresnel-weighted choice of mirror reflection or
//! refraction; radiance is scaled by 1/η² on refraction).

use super::fresnel::{fresnel_dielectric, reflect, refract};
use super::{BsdfSample, Dielectric, TransportMode};
use crate::texture::TexPoint;
use glam::Vec3;

impl Dielectric {
    pub(super) fn sample(
        &self,
        wo: Vec3,
        tp: TexPoint,
        u_lobe: f32,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let f = fresnel_dielectric(wo.z, self.eta);
        if u_lobe <= f.r {
            // Weight: R (throughput) / R (probability) times the tint.
            let weight = self.specular_reflectance.eval(tp);
            Some(BsdfSample {
                wi: reflect(wo),
                weight,
                pdf: f.r,
                delta: true,
                eta: 1.0,
            })
        } else {
            let mut weight = self.specular_transmittance.eval(tp);
            if mode == TransportMode::Radiance {
                // Solid-angle compression when crossing the interface.
                weight *= f.eta_ti * f.eta_ti;
            }
            let wi = refract(wo, f.cos_theta_t, f.eta_ti);
            Some(BsdfSample {
                wi,
                weight,
                pdf: 1.0 - f.r,
                delta: true,
                eta: f.eta_it,
            })
        }
    }
}
