//! `thindielectric`: a thin glass sheet — two parallel interfaces whose internal bounces are
//! summed in closed form; transmission continues straight through (no offset, no 1/η²).

use super::fresnel::{fresnel_dielectric, reflect};
use super::{BsdfSample, ThinDielectric};
use crate::texture::TexPoint;
use glam::Vec3;

impl ThinDielectric {
    /// Total reflectance of the slab: R + T²R/(1 − R²) = 2R/(1 + R) for a single-interface
    /// Fresnel reflectance R (no absorption inside).
    pub(super) fn slab_reflectance(&self, cos_theta: f32) -> f32 {
        let r = fresnel_dielectric(cos_theta.abs(), self.eta).r;
        r * 2.0 / (1.0 + r)
    }

    pub(super) fn sample(&self, wo: Vec3, tp: TexPoint, u_lobe: f32) -> Option<BsdfSample> {
        let r = self.slab_reflectance(wo.z);
        if u_lobe <= r {
            let weight = self.specular_reflectance.eval(tp);
            Some(BsdfSample {
                wi: reflect(wo),
                weight,
                pdf: r,
                delta: true,
                eta: 1.0,
            })
        } else {
            let weight = self.specular_transmittance.eval(tp);
            Some(BsdfSample {
                wi: -wo,
                weight,
                pdf: 1.0 - r,
                delta: true,
                eta: 1.0,
            })
        }
    }
}
