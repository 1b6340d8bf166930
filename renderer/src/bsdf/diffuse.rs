//! `diffuse`: Lambertian reflection with cosine-weighted sampling.

use super::{BsdfSample, Diffuse};
use crate::sampling::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use crate::spectrum::Rgb;
use crate::texture::TexPoint;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

impl Diffuse {
    pub(super) fn sample(&self, wo: Vec3, tp: TexPoint, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = square_to_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wi);
        if pdf <= 0.0 {
            return None;
        }
        // f·cos/pdf = (ρ/π)·cos / (cos/π) = ρ.
        Some(BsdfSample {
            wi,
            weight: self.reflectance.eval(tp),
            pdf,
            delta: false,
            eta: 1.0,
        })
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        self.reflectance.eval(tp) * FRAC_1_PI
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        cosine_hemisphere_pdf(wi)
    }
}
