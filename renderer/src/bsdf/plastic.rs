//! `plastic`: a diffuse base under a smooth dielectric coating (Mitsuba 3's smooth plastic:
//! delta specular reflection plus a diffuse term attenuated by the two Fresnel transmissions
//! and amplified by the internal reflections at the coating).

use super::fresnel::{fresnel_dielectric, fresnel_diffuse_reflectance, reflect};
use super::{BsdfSample, Plastic};
use crate::sampling::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// The share of lobe-selection effort given to the specular layer: s̄/(d̄ + s̄) of the mean
/// channel values, as Mitsuba (it only affects variance, never the expected value).
pub(super) fn specular_sampling_weight(diffuse: &Texture, specular: &Texture) -> f32 {
    let d = diffuse.mean_estimate().element_sum() / 3.0;
    let s = specular.mean_estimate().element_sum() / 3.0;
    if d + s > 0.0 {
        s / (d + s)
    } else {
        0.5
    }
}

/// Diffuse albedo after internal re-reflection at the coating: ρ/(1 − Fdr) (linear), or
/// ρ/(1 − ρ·Fdr) per channel when `nonlinear`.
pub(super) fn internal_scattering(rho: Rgb, fdr_int: f32, nonlinear: bool) -> Rgb {
    if nonlinear {
        rho / (Rgb::ONE - rho * fdr_int)
    } else {
        rho / (1.0 - fdr_int)
    }
}

impl Plastic {
    /// Probability of choosing the specular lobe for an outgoing cosine.
    fn prob_specular(&self, f_o: f32) -> f32 {
        let ssw = specular_sampling_weight(&self.diffuse_reflectance, &self.specular_reflectance);
        let ps = f_o * ssw;
        let pd = (1.0 - f_o) * (1.0 - ssw);
        if ps + pd > 0.0 {
            ps / (ps + pd)
        } else {
            1.0
        }
    }

    /// Probability that [`Plastic::sample`] picks the specular coating for `wo`.
    pub(super) fn delta_probability(&self, wo: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        self.prob_specular(fresnel_dielectric(wo.z, self.eta).r)
    }

    fn diffuse_value(&self, tp: TexPoint, f_o: f32, f_i: f32) -> Rgb {
        let fdr_int = fresnel_diffuse_reflectance(1.0 / self.eta);
        let rho = internal_scattering(self.diffuse_reflectance.eval(tp), fdr_int, self.nonlinear);
        rho * ((1.0 - f_o) * (1.0 - f_i) / (self.eta * self.eta))
    }

    pub(super) fn sample(
        &self,
        wo: Vec3,
        tp: TexPoint,
        u_lobe: f32,
        u: Vec2,
    ) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let f_o = fresnel_dielectric(wo.z, self.eta).r;
        let p_spec = self.prob_specular(f_o);
        if u_lobe < p_spec {
            let weight = self.specular_reflectance.eval(tp) * (f_o / p_spec);
            Some(BsdfSample {
                wi: reflect(wo),
                weight,
                pdf: p_spec,
                delta: true,
                eta: 1.0,
            })
        } else {
            let p_diff = 1.0 - p_spec;
            let wi = square_to_cosine_hemisphere(u);
            let pdf = p_diff * cosine_hemisphere_pdf(wi);
            if pdf.is_nan() || pdf <= 0.0 {
                return None;
            }
            let f_i = fresnel_dielectric(wi.z, self.eta).r;
            let weight = self.diffuse_value(tp, f_o, f_i) / p_diff;
            Some(BsdfSample {
                wi,
                weight,
                pdf,
                delta: false,
                eta: 1.0,
            })
        }
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let f_o = fresnel_dielectric(wo.z, self.eta).r;
        let f_i = fresnel_dielectric(wi.z, self.eta).r;
        self.diffuse_value(tp, f_o, f_i) * FRAC_1_PI
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let f_o = fresnel_dielectric(wo.z, self.eta).r;
        (1.0 - self.prob_specular(f_o)) * cosine_hemisphere_pdf(wi)
    }
}
