//! `roughplastic`: a diffuse base under a rough dielectric coating (Mitsuba 3's rough plastic).
//!
//! The diffuse term needs the coating's directional transmittance t(μ) and its internal diffuse
//! reflectance. Mitsuba precomputes both by Gauss–Legendre quadrature over visible microfacet
//! normals (a 64-entry table in μ = cos θ, linearly interpolated); we compute the same tables the
//! same way, once per (distribution, α, η) per process, and cache them. Like Mitsuba the model is
//! isotropic: `alpha_u` is used.

use super::fresnel::{fresnel_dielectric, reflect_about, refract_about};
use super::microfacet::MicrofacetDistribution;
use super::plastic::{internal_scattering, specular_sampling_weight};
use super::warp::{square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf};
use super::{BsdfSample, RoughPlastic};
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use std::cell::RefCell;
use std::f32::consts::FRAC_1_PI;
use std::sync::{Arc, Mutex};

/// Resolution of the transmittance table in μ (Mitsuba's `MI_ROUGH_TRANSMITTANCE_RES`).
const TABLE_RES: usize = 64;

/// Precomputed coating quantities of one (distribution, α, η).
#[derive(Debug)]
pub(super) struct CoatingTables {
    /// t(μ_j), μ_j = max(j/63, 1e-6): the fraction of light from direction μ that enters.
    external_transmittance: [f32; TABLE_RES],
    /// Internal diffuse reflectance of the coating seen from inside.
    pub(super) internal_reflectance: f32,
}

impl CoatingTables {
    /// Linear interpolation of the transmittance table at cosine `mu` ∈ [0, 1].
    pub(super) fn transmittance(&self, mu: f32) -> f32 {
        let x = mu * (TABLE_RES - 1) as f32;
        let i = (x.max(0.0) as usize).min(TABLE_RES - 2);
        let t = x - i as f32;
        let (a, b) = (
            self.external_transmittance[i],
            self.external_transmittance[i + 1],
        );
        a + (b - a) * t
    }

    fn compute(distr: &MicrofacetDistribution, eta: f32) -> Self {
        let mut external_transmittance = [0.0; TABLE_RES];
        let mut internal_sum = 0.0f32;
        for (j, t) in external_transmittance.iter_mut().enumerate() {
            let mu = (j as f32 / (TABLE_RES - 1) as f32).max(1e-6);
            let wi = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            *t = coating_transmittance(distr, wi, eta);
            internal_sum += coating_reflectance(distr, wi, 1.0 / eta) * wi.z;
        }
        let internal_reflectance = internal_sum / TABLE_RES as f32 * 2.0;
        Self {
            external_transmittance,
            internal_reflectance,
        }
    }

    /// The (cached) tables of a rough plastic.
    pub(super) fn get(bsdf: &RoughPlastic) -> Arc<CoatingTables> {
        type Cache = Vec<((u8, u32, u32), Arc<CoatingTables>)>;
        static SHARED: Mutex<Cache> = Mutex::new(Vec::new());
        thread_local! {
            static LOCAL: RefCell<Cache> = const { RefCell::new(Vec::new()) };
        }
        let distr = coating_distribution(bsdf);
        let key = (
            distr.kind as u8,
            distr.alpha_u.to_bits(),
            bsdf.eta.to_bits(),
        );
        if let Some(t) = LOCAL.with(|l| {
            l.borrow()
                .iter()
                .find(|(k, _)| *k == key)
                .map(|(_, t)| t.clone())
        }) {
            return t;
        }
        let tables = {
            let mut shared = SHARED.lock().unwrap_or_else(|e| e.into_inner());
            match shared.iter().find(|(k, _)| *k == key) {
                Some((_, t)) => t.clone(),
                None => {
                    let t = Arc::new(CoatingTables::compute(&distr, bsdf.eta));
                    shared.push((key, t.clone()));
                    t
                }
            }
        };
        LOCAL.with(|l| l.borrow_mut().push((key, tables.clone())));
        tables
    }
}

fn coating_distribution(bsdf: &RoughPlastic) -> MicrofacetDistribution {
    let a = bsdf.roughness.alpha_u;
    MicrofacetDistribution::new(&super::Roughness {
        kind: bsdf.roughness.kind,
        alpha_u: a,
        alpha_v: a,
    })
}

/// Gauss–Legendre nodes and weights on [−1, 1] (Newton iteration on Pₙ, in f64).
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = -(std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // Legendre recurrence for Pₙ(x) and its derivative.
            let (mut p0, mut p1) = (1.0f64, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        out.push((x, 2.0 / ((1.0 - x * x) * dp * dp)));
    }
    out
}

/// Integrates `f(m)` over normals visible from `wi` by tensor Gauss–Legendre quadrature on the
/// sample square (the visible-normal warp turns it into an expectation).
fn visible_normal_quadrature(
    distr: &MicrofacetDistribution,
    wi: Vec3,
    eta: f32,
    f: impl Fn(Vec3) -> f32,
) -> f32 {
    let n = if eta > 1.0 { 32 } else { 128 };
    let nodes = gauss_legendre(n);
    let mut sum = 0.0f32;
    for &(y, wy) in &nodes {
        for &(x, wx) in &nodes {
            let u = Vec2::new((x * 0.5 + 0.5) as f32, (y * 0.5 + 0.5) as f32);
            let (m, _) = distr.sample(wi, u);
            sum += f(m) * (wx * wy * 0.25) as f32;
        }
    }
    sum
}

/// Fraction of light arriving from `wi` that is refracted into the coating (Fresnel and
/// masking of the refracted direction included).
fn coating_transmittance(distr: &MicrofacetDistribution, wi: Vec3, eta: f32) -> f32 {
    visible_normal_quadrature(distr, wi, eta, |m| {
        let f = fresnel_dielectric(wi.dot(m), eta);
        let wo = refract_about(wi, m, f.cos_theta_t, f.eta_ti);
        if wo.z * wi.z >= 0.0 {
            0.0
        } else {
            distr.smith_g1(wo, m) * (1.0 - f.r)
        }
    })
}

/// Single-scattering microfacet reflectance for light arriving from `wi`.
fn coating_reflectance(distr: &MicrofacetDistribution, wi: Vec3, eta: f32) -> f32 {
    visible_normal_quadrature(distr, wi, eta, |m| {
        let wo = reflect_about(wi, m);
        if wo.z <= 0.0 || wi.z <= 0.0 {
            0.0
        } else {
            distr.smith_g1(wo, m) * fresnel_dielectric(wi.dot(m), eta).r
        }
    })
}

impl RoughPlastic {
    fn prob_specular(&self, t_o: f32) -> f32 {
        let ssw = specular_sampling_weight(&self.diffuse_reflectance, &self.specular_reflectance);
        let ps = (1.0 - t_o) * ssw;
        let pd = t_o * (1.0 - ssw);
        if ps + pd > 0.0 {
            ps / (ps + pd)
        } else {
            1.0
        }
    }

    pub(super) fn sample(&self, wo: Vec3, uv: Vec2, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let tables = CoatingTables::get(self);
        let p_spec = self.prob_specular(tables.transmittance(wo.z));
        let wi = if u_lobe < p_spec {
            let (m, _) = coating_distribution(self).sample(wo, u);
            reflect_about(wo, m)
        } else {
            square_to_cosine_hemisphere(u)
        };
        let pdf = self.pdf_with(&tables, wo, wi);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let f = self.eval_with(&tables, wo, wi, uv);
        Some(BsdfSample {
            wi,
            weight: f * (wi.z / pdf),
            pdf,
            delta: false,
            eta: 1.0,
        })
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, uv: Vec2) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        self.eval_with(&CoatingTables::get(self), wo, wi, uv)
    }

    fn eval_with(&self, tables: &CoatingTables, wo: Vec3, wi: Vec3, uv: Vec2) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let distr = coating_distribution(self);
        let h = (wo + wi).normalize();
        let d = distr.eval(h);
        let f = fresnel_dielectric(wo.dot(h), self.eta).r;
        let g = distr.g(wo, wi, h);
        let specular = self.specular_reflectance.eval(uv) * (f * d * g / (4.0 * wo.z * wi.z));
        let rho = internal_scattering(
            self.diffuse_reflectance.eval(uv),
            tables.internal_reflectance,
            self.nonlinear,
        );
        let t = tables.transmittance(wo.z) * tables.transmittance(wi.z);
        specular + rho * (FRAC_1_PI * t / (self.eta * self.eta))
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        self.pdf_with(&CoatingTables::get(self), wo, wi)
    }

    fn pdf_with(&self, tables: &CoatingTables, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let p_spec = self.prob_specular(tables.transmittance(wo.z));
        let distr = coating_distribution(self);
        let h = (wo + wi).normalize();
        let spec = distr.eval(h) * distr.smith_g1(wo, h) / (4.0 * wo.z);
        p_spec * spec + (1.0 - p_spec) * square_to_cosine_hemisphere_pdf(wi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::MicrofacetKind;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        for n in [32, 128] {
            let q = gauss_legendre(n);
            let w: f64 = q.iter().map(|(_, w)| w).sum();
            assert!((w - 2.0).abs() < 1e-12, "{n}: {w}");
            // ∫ x⁴ = 2/5 on [−1, 1].
            let i: f64 = q.iter().map(|(x, w)| w * x.powi(4)).sum();
            assert!((i - 0.4).abs() < 1e-12);
        }
    }

    #[test]
    fn coating_tables_are_physical() {
        let rp = RoughPlastic {
            roughness: super::super::Roughness {
                kind: MicrofacetKind::Ggx,
                alpha_u: 0.3,
                alpha_v: 0.3,
            },
            eta: 1.5,
            diffuse_reflectance: crate::texture::Texture::Constant(Rgb::splat(0.5)),
            specular_reflectance: crate::texture::Texture::Constant(Rgb::ONE),
            nonlinear: false,
        };
        let t = CoatingTables::get(&rp);
        // Near normal incidence the rough coating transmits about 1 − 0.04.
        assert!(
            (t.transmittance(1.0) - 0.96).abs() < 0.01,
            "{}",
            t.transmittance(1.0)
        );
        for j in 0..=20 {
            let v = t.transmittance(j as f32 / 20.0);
            assert!((0.0..=1.0).contains(&v), "{v}");
        }
        // Internal reflectance is close to the smooth diffuse Fresnel reflectance (≈ 0.6 for
        // 1/1.5) but must lie in (0, 1).
        let ri = t.internal_reflectance;
        assert!(ri > 0.4 && ri < 0.8, "{ri}");
        // Cached: same Arc the second time.
        assert!(Arc::ptr_eq(&t, &CoatingTables::get(&rp)));
    }
}
