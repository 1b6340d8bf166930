//! `roughdielectric`: microfacet glass (Walter et al. 2007) with visible-normal sampling,
//! usable from both sides; radiance is scaled by 1/η² on refraction.

use super::fresnel::{fresnel_dielectric, reflect_about, refract_about};
use super::{BsdfSample, RoughDielectric, TransportMode};
use crate::spectrum::Rgb;
use crate::texture::TexPoint;
use glam::{Vec2, Vec3};

impl RoughDielectric {
    pub(super) fn sample(
        &self,
        wo: Vec3,
        tp: TexPoint,
        u_lobe: f32,
        u: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let cos_o = wo.z;
        if cos_o == 0.0 {
            return None;
        }
        let distr = super::distribution_at(&self.roughness, &self.alpha_texture, tp);
        // Sample a normal visible from the side `wo` is on (the distribution is symmetric).
        let (m, pdf_m) = distr.sample(wo * cos_o.signum(), u);
        if pdf_m.is_nan() || pdf_m <= 0.0 {
            return None;
        }
        let f = fresnel_dielectric(wo.dot(m), self.eta);
        let (wi, mut weight, lobe_pdf, eta, dwh_dwi) = if u_lobe <= f.r {
            let wi = reflect_about(wo, m);
            (
                wi,
                self.specular_reflectance.eval(tp),
                f.r,
                1.0,
                1.0 / (4.0 * wi.dot(m)),
            )
        } else {
            let wi = refract_about(wo, m, f.cos_theta_t, f.eta_ti);
            let mut w = self.specular_transmittance.eval(tp);
            if mode == TransportMode::Radiance {
                w *= f.eta_ti * f.eta_ti;
            }
            let denom = wo.dot(m) + f.eta_it * wi.dot(m);
            let jac = f.eta_it * f.eta_it * wi.dot(m) / (denom * denom);
            (wi, w, 1.0 - f.r, f.eta_it, jac)
        };
        // G1(wi, m) also rejects directions that end up on the wrong side of the macro-surface.
        let g1 = distr.smith_g1(wi, m);
        weight *= g1;
        let pdf = pdf_m * lobe_pdf * dwh_dwi.abs();
        if g1 <= 0.0 || (pdf.is_nan() || pdf <= 0.0) || !pdf.is_finite() {
            return None;
        }
        Some(BsdfSample {
            wi,
            weight,
            pdf,
            delta: false,
            eta,
        })
    }

    /// The generalised half vector of (wo, wi), oriented to +z, and the relative IOR η seen from
    /// the side of `wo` (None for degenerate configurations).
    fn half_vector(&self, wo: Vec3, wi: Vec3, reflect: bool) -> Option<(Vec3, f32)> {
        let eta = if wo.z > 0.0 { self.eta } else { 1.0 / self.eta };
        let h = wo + wi * if reflect { 1.0 } else { eta };
        let len2 = h.length_squared();
        if len2.is_nan() || len2 <= 0.0 {
            return None;
        }
        let m = h / len2.sqrt();
        Some((if m.z < 0.0 { -m } else { m }, eta))
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, tp: TexPoint, mode: TransportMode) -> Rgb {
        let (cos_o, cos_i) = (wo.z, wi.z);
        if cos_o == 0.0 || cos_i == 0.0 {
            return Rgb::ZERO;
        }
        let reflect = cos_o * cos_i > 0.0;
        let Some((m, eta)) = self.half_vector(wo, wi, reflect) else {
            return Rgb::ZERO;
        };
        let distr = super::distribution_at(&self.roughness, &self.alpha_texture, tp);
        let d = distr.eval(m);
        if d == 0.0 {
            return Rgb::ZERO;
        }
        let f = fresnel_dielectric(wo.dot(m), self.eta).r;
        let g = distr.g(wo, wi, m);
        if reflect {
            self.specular_reflectance.eval(tp) * (f * d * g / (4.0 * (cos_o * cos_i).abs()))
        } else {
            let scale = if mode == TransportMode::Radiance {
                1.0 / (eta * eta)
            } else {
                1.0
            };
            let denom = wo.dot(m) + eta * wi.dot(m);
            let value = scale * (1.0 - f) * d * g * eta * eta * wo.dot(m) * wi.dot(m)
                / (cos_o * cos_i * denom * denom);
            self.specular_transmittance.eval(tp) * value.abs()
        }
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> f32 {
        let (cos_o, cos_i) = (wo.z, wi.z);
        if cos_o == 0.0 || cos_i == 0.0 {
            return 0.0;
        }
        let reflect = cos_o * cos_i > 0.0;
        let Some((m, eta)) = self.half_vector(wo, wi, reflect) else {
            return 0.0;
        };
        // Micro- and macro-surface must agree on the sides (as smith_g1 enforces in sample()).
        if wo.dot(m) * cos_o <= 0.0 || wi.dot(m) * cos_i <= 0.0 {
            return 0.0;
        }
        let dwh_dwi = if reflect {
            1.0 / (4.0 * wi.dot(m))
        } else {
            let denom = wo.dot(m) + eta * wi.dot(m);
            eta * eta * wi.dot(m) / (denom * denom)
        };
        let distr = super::distribution_at(&self.roughness, &self.alpha_texture, tp);
        let f = fresnel_dielectric(wo.dot(m), self.eta).r;
        let prob = distr.pdf(wo * cos_o.signum(), m) * if reflect { f } else { 1.0 - f };
        let pdf = prob * dwh_dwi.abs();
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }
}
