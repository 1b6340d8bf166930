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
use super::{BsdfSample, RoughPlastic, Roughness};
use crate::sampling::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
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

    /// Computes the tables: each μ entry on its own rayon task (the entries are independent and
    /// each sums in a fixed order, so the result does not depend on the thread count).
    fn compute(distr: &MicrofacetDistribution, eta: f32) -> Self {
        // The quadrature nodes, once for all 64 entries (finding them is an O(n²) Newton
        // iteration per node set: computed per entry it was a tenth of a table's time).
        let outside = gauss_legendre(quadrature_order(eta));
        let inside = gauss_legendre(quadrature_order(1.0 / eta));
        let entries: Vec<(f32, f32)> = (0..TABLE_RES)
            .into_par_iter()
            .map(|j| {
                let mu = (j as f32 / (TABLE_RES - 1) as f32).max(1e-6);
                let wi = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                (
                    coating_transmittance(distr, wi, eta, &outside),
                    coating_reflectance(distr, wi, 1.0 / eta, &inside) * wi.z,
                )
            })
            .collect();
        let mut external_transmittance = [0.0; TABLE_RES];
        let mut internal_sum = 0.0f32;
        for (t, (transmittance, reflectance)) in external_transmittance.iter_mut().zip(entries) {
            *t = transmittance;
            internal_sum += reflectance;
        }
        let internal_reflectance = internal_sum / TABLE_RES as f32 * 2.0;
        Self {
            external_transmittance,
            internal_reflectance,
        }
    }

    /// The tables of a coating, shared between equal coatings (a scene often repeats one
    /// material; each distinct coating costs ~10⁶ microfacet samples).
    fn shared(distr: &MicrofacetDistribution, eta: f32) -> Arc<CoatingTables> {
        type Cache = Vec<((u8, u32, u32), Arc<CoatingTables>)>;
        static SHARED: Mutex<Cache> = Mutex::new(Vec::new());
        let key = (distr.kind as u8, distr.alpha_u.to_bits(), eta.to_bits());
        if let Some((_, t)) = SHARED
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .find(|(k, _)| *k == key)
        {
            return t.clone();
        }
        // Computed outside the lock: two threads may both compute the same tables (identical
        // results); the first stored wins.
        let computed = Arc::new(CoatingTables::compute(distr, eta));
        let mut shared = SHARED.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, t)) = shared.iter().find(|(k, _)| *k == key) {
            return t.clone();
        }
        shared.push((key, computed.clone()));
        computed
    }
}

/// The coating's distribution: isotropic with `alpha_u`, as Mitsuba's rough plastic.
fn isotropic_distribution(r: &Roughness) -> MicrofacetDistribution {
    MicrofacetDistribution::new(&Roughness {
        kind: r.kind,
        alpha_u: r.alpha_u,
        alpha_v: r.alpha_u,
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

/// Gauss–Legendre order per axis of the coating integrals at relative index `eta` (Mitsuba's:
/// light entering a denser coating is smooth in m, total internal reflection inside is not).
fn quadrature_order(eta: f32) -> usize {
    if eta > 1.0 {
        32
    } else {
        128
    }
}

/// Integrates `f(m)` over normals visible from `wi` by tensor Gauss–Legendre quadrature with
/// `nodes` on each axis of the sample square (the visible-normal warp turns it into an
/// expectation).
fn visible_normal_quadrature(
    distr: &MicrofacetDistribution,
    wi: Vec3,
    nodes: &[(f64, f64)],
    f: impl Fn(Vec3) -> f32,
) -> f32 {
    let mut sum = 0.0f32;
    for &(y, wy) in nodes {
        for &(x, wx) in nodes {
            let u = Vec2::new((x * 0.5 + 0.5) as f32, (y * 0.5 + 0.5) as f32);
            let (m, _) = distr.sample(wi, u);
            sum += f(m) * (wx * wy * 0.25) as f32;
        }
    }
    sum
}

/// Fraction of light arriving from `wi` that is refracted into the coating (Fresnel and
/// masking of the refracted direction included).
fn coating_transmittance(
    distr: &MicrofacetDistribution,
    wi: Vec3,
    eta: f32,
    nodes: &[(f64, f64)],
) -> f32 {
    visible_normal_quadrature(distr, wi, nodes, |m| {
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
fn coating_reflectance(
    distr: &MicrofacetDistribution,
    wi: Vec3,
    eta: f32,
    nodes: &[(f64, f64)],
) -> f32 {
    visible_normal_quadrature(distr, wi, nodes, |m| {
        let wo = reflect_about(wi, m);
        if wo.z <= 0.0 || wi.z <= 0.0 {
            0.0
        } else {
            distr.smith_g1(wo, m) * fresnel_dielectric(wi.dot(m), eta).r
        }
    })
}

impl RoughPlastic {
    /// The BSDF with its coating tables (see the module note); `roughness` is isotropic
    /// (`alpha_u` is used), `eta` is the coating's relative index of refraction.
    pub fn new(
        roughness: Roughness,
        eta: f32,
        diffuse_reflectance: Texture,
        specular_reflectance: Texture,
        nonlinear: bool,
    ) -> Self {
        let distr = isotropic_distribution(&roughness);
        Self {
            coating: CoatingTables::shared(&distr, eta),
            roughness,
            eta,
            diffuse_reflectance,
            specular_reflectance,
            nonlinear,
        }
    }

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
        let p_spec = self.prob_specular(self.coating.transmittance(wo.z));
        let wi = if u_lobe < p_spec {
            let (m, _) = isotropic_distribution(&self.roughness).sample(wo, u);
            reflect_about(wo, m)
        } else {
            square_to_cosine_hemisphere(u)
        };
        let pdf = self.pdf(wo, wi);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let f = self.eval(wo, wi, tp);
        Some(BsdfSample {
            wi,
            weight: f * (wi.z / pdf),
            pdf,
            delta: false,
            eta: 1.0,
        })
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> Rgb {
        let (specular, diffuse) = self.terms(wo, wi, tp);
        specular + diffuse
    }

    /// Whether the coating is a sharp lobe (see [`super::SHARP_ALPHA_THRESHOLD`]).
    fn sharp_coating(&self) -> bool {
        self.roughness.alpha_u < super::SHARP_ALPHA_THRESHOLD
    }

    /// (broad, sharp): the diffuse base and, if it is sharp, the coating's reflection.
    pub(super) fn eval_split(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> (Rgb, Rgb) {
        let (specular, diffuse) = self.terms(wo, wi, tp);
        if self.sharp_coating() {
            (diffuse, specular)
        } else {
            (specular + diffuse, Rgb::ZERO)
        }
    }

    /// The coating's sampling probability for viewer `wo` when the coating is sharp.
    pub(super) fn sharp_share(&self, wo: Vec3) -> Option<f32> {
        (self.sharp_coating() && wo.z > 0.0)
            .then(|| self.prob_specular(self.coating.transmittance(wo.z)))
    }

    /// The coating's specular reflection and the diffuse base's term.
    fn terms(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> (Rgb, Rgb) {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Rgb::ZERO, Rgb::ZERO);
        }
        let distr = isotropic_distribution(&self.roughness);
        let h = (wo + wi).normalize();
        let d = distr.eval(h);
        let f = fresnel_dielectric(wo.dot(h), self.eta).r;
        let g = distr.g(wo, wi, h);
        let specular = self.specular_reflectance.eval(tp) * (f * d * g / (4.0 * wo.z * wi.z));
        let rho = internal_scattering(
            self.diffuse_reflectance.eval(tp),
            self.coating.internal_reflectance,
            self.nonlinear,
        );
        let t = self.coating.transmittance(wo.z) * self.coating.transmittance(wi.z);
        (specular, rho * (FRAC_1_PI * t / (self.eta * self.eta)))
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let p_spec = self.prob_specular(self.coating.transmittance(wo.z));
        let distr = isotropic_distribution(&self.roughness);
        let h = (wo + wi).normalize();
        let spec = distr.eval(h) * distr.smith_g1(wo, h) / (4.0 * wo.z);
        p_spec * spec + (1.0 - p_spec) * cosine_hemisphere_pdf(wi)
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
        let roughness = super::super::Roughness {
            kind: MicrofacetKind::Ggx,
            alpha_u: 0.3,
            alpha_v: 0.3,
        };
        let constant = |v| crate::texture::Texture::Constant(Rgb::splat(v));
        let rp = RoughPlastic::new(roughness, 1.5, constant(0.5), constant(1.0), false);
        // The tables are computed when built; the same coating shares them.
        let again = RoughPlastic::new(roughness, 1.5, constant(0.2), constant(1.0), true);
        assert!(Arc::ptr_eq(&rp.coating, &again.coating));
        let other = RoughPlastic::new(roughness, 1.4, constant(0.5), constant(1.0), false);
        assert!(!Arc::ptr_eq(&rp.coating, &other.coating));
        let t = &rp.coating;
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
    }
}
