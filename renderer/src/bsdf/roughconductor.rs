//! `roughconductor`: Cook–Torrance microfacet metal (Beckmann/GGX, anisotropic) with
//! visible-normal sampling.

use super::conductor::conductor_reflectance;
use super::fresnel::reflect_about;
use super::{BsdfSample, RoughConductor};
use crate::spectrum::Rgb;
use crate::texture::TexPoint;
use glam::{Vec2, Vec3};

impl RoughConductor {
    pub(super) fn sample(&self, wo: Vec3, tp: TexPoint, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let distr = super::distribution_at(&self.roughness, &self.alpha_texture, tp);
        let (m, pdf_m) = distr.sample(wo, u);
        let wi = reflect_about(wo, m);
        if pdf_m <= 0.0 || wi.z <= 0.0 {
            return None;
        }
        // With visible normals, f·cos/pdf collapses to F·G1(wi, m).
        let g1 = distr.smith_g1(wi, m);
        let weight =
            conductor_reflectance(&self.ior, wo.dot(m)) * g1 * self.specular_reflectance.eval(tp);
        let pdf = pdf_m / (4.0 * wi.dot(m));
        if g1 <= 0.0 || (pdf.is_nan() || pdf <= 0.0) {
            return None;
        }
        Some(BsdfSample {
            wi,
            weight,
            pdf,
            delta: false,
            eta: 1.0,
        })
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let h = (wo + wi).normalize();
        let distr = super::distribution_at(&self.roughness, &self.alpha_texture, tp);
        let d = distr.eval(h);
        if d == 0.0 {
            return Rgb::ZERO;
        }
        let g = distr.g(wo, wi, h);
        let f = conductor_reflectance(&self.ior, wo.dot(h));
        f * (d * g / (4.0 * wo.z * wi.z)) * self.specular_reflectance.eval(tp)
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let m = (wo + wi).normalize();
        // Same side filtering as smith_g1 inside eval/sample.
        if wo.dot(m) <= 0.0 || wi.dot(m) <= 0.0 {
            return 0.0;
        }
        let distr = super::distribution_at(&self.roughness, &self.alpha_texture, tp);
        distr.eval(m) * distr.smith_g1(wo, m) / (4.0 * wo.z)
    }
}
