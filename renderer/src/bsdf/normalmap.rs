//! `normalmap`: a nested BSDF evaluated in a shading frame tilted by a normal-map texture, as
//! Mitsuba 3's `normalmap` (its `PerturbedBSDF` base).
//!
//! Parameters, in the XML's words: `normalmap` (a texture whose RGB encodes the perturbed
//! normal in the shading frame as (n + 1)/2, usually a `bitmap` with `raw` = true), one nested
//! `<bsdf>`, `flip_invalid_normals` (default true: a perturbed normal facing away from the
//! viewer is mirrored about the shading normal, after Schüssler et al. 2017) and
//! `use_shadowing_function` (default true: the response is attenuated by the microfacet-based
//! shadowing term of Estévez et al. 2019 against the bump terminator problem).
//!
//! The perturbed frame is n' = normalize(2·texel − 1) with tangent s' = the shading tangent
//! made orthogonal to n' (Gram–Schmidt), both relative to the shading frame. A direction whose
//! side of the surface differs between the shading frame and the perturbed one contributes
//! nothing (Mitsuba's check on the sampled/evaluated direction).

use super::{Bsdf, BsdfSample, TransportMode};
use crate::frame::Frame;
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// `normalmap`: the nested model seen through a perturbed shading frame.
#[derive(Debug, Clone)]
pub struct NormalMap {
    /// `normalmap`: RGB = (n + 1)/2 of the perturbed normal in the shading frame.
    pub normalmap: Texture,
    /// The nested BSDF.
    pub nested: Box<Bsdf>,
    /// `flip_invalid_normals` (default true).
    pub flip_invalid_normals: bool,
    /// `use_shadowing_function` (default true).
    pub use_shadowing_function: bool,
}

/// Estévez et al.'s shadowing term for a perturbed normal `n` and direction `w`, both in the
/// shading frame: 2 / (1 + √(1 + α²·tan²θ_w)) with α² = min(tan²θ_n / 8, 1).
fn shadow_terminator(n: Vec3, w: Vec3) -> f32 {
    let tan2 = |v: Vec3| (1.0 - v.z * v.z).max(0.0) / (v.z * v.z);
    let alpha2 = (0.125 * tan2(n)).min(1.0);
    2.0 / (1.0 + (1.0 + alpha2 * tan2(w)).sqrt())
}

impl NormalMap {
    /// The perturbed frame relative to the shading frame, for viewer direction `wo`.
    fn frame(&self, wo: Vec3, uv: Vec2) -> Frame {
        let mut n = self.normalmap.eval(uv) * 2.0 - Vec3::ONE;
        if self.flip_invalid_normals && wo.z * wo.dot(n) <= 0.0 {
            n = Vec3::new(-n.x, -n.y, n.z);
        }
        let len2 = n.length_squared();
        let n = if len2 > 0.0 && len2.is_finite() {
            n / len2.sqrt()
        } else {
            Vec3::Z
        };
        let s = Vec3::X - n * n.x;
        let s_len2 = s.length_squared();
        let s = if s_len2 > 0.0 && s_len2.is_finite() {
            s / s_len2.sqrt()
        } else {
            Vec3::Y
        };
        Frame {
            s,
            t: n.cross(s),
            n,
        }
    }

    /// The shadowing factor for direction `wi` (1 when switched off).
    fn shadowing(&self, frame: &Frame, wi: Vec3) -> f32 {
        if self.use_shadowing_function {
            shadow_terminator(frame.n, wi)
        } else {
            1.0
        }
    }

    /// Radiance-mode f(viewer, light) in `frame`, without the cosine of the shading frame: the
    /// nested model's f·cos in the perturbed frame (what Mitsuba's `eval` returns), times the
    /// shadowing term, divided by |cos θ| of the shading frame that integrators multiply back.
    /// Zero where either direction changes sides between the two frames.
    fn eval_in(&self, frame: &Frame, viewer: Vec3, light: Vec3, uv: Vec2) -> Rgb {
        let (pv, pl) = (frame.to_local(viewer), frame.to_local(light));
        if light.z * pl.z <= 0.0 {
            return Rgb::ZERO;
        }
        let f = self.nested.eval(pv, pl, uv, TransportMode::Radiance);
        if f == Rgb::ZERO {
            return f;
        }
        f * (pl.z.abs() / light.z.abs() * self.shadowing(frame, light))
    }

    /// Whether `flip_invalid_normals` mirrors the map's normal for a path arriving from `wo`.
    #[cfg(test)]
    pub(crate) fn flips(&self, wo: Vec3, uv: Vec2) -> bool {
        let n = self.normalmap.eval(uv) * 2.0 - Vec3::ONE;
        self.flip_invalid_normals && wo.z * wo.dot(n) <= 0.0
    }

    /// f(wo, wi) without the cosine of the shading frame. Radiance: viewer `wo`, light `wi`.
    /// Importance (photons arriving from `wo`, leaving along `wi`): the adjoint, f(wi, wo) —
    /// the model is not reciprocal — in the frame `wo` selects (the flip of an invalid normal
    /// is decided by the arriving direction, as the photon's sampling must).
    pub fn eval(&self, wo: Vec3, wi: Vec3, uv: Vec2, mode: TransportMode) -> Rgb {
        let frame = self.frame(wo, uv);
        if wi.z * frame.to_local(wi).z <= 0.0 {
            return Rgb::ZERO;
        }
        match mode {
            TransportMode::Radiance => self.eval_in(&frame, wo, wi, uv),
            TransportMode::Importance => self.eval_in(&frame, wi, wo, uv),
        }
    }

    /// The nested model's density of `wi`, seen through the perturbed frame (a rotation, so
    /// solid-angle densities carry over), zero where [`NormalMap::sample`] rejects.
    pub fn pdf(&self, wo: Vec3, wi: Vec3, uv: Vec2) -> f32 {
        let frame = self.frame(wo, uv);
        let pwi = frame.to_local(wi);
        if wi.z * pwi.z <= 0.0 {
            return 0.0;
        }
        self.nested.pdf(frame.to_local(wo), pwi, uv)
    }

    /// The perturbed shading normal for viewer `wo`, in the shading frame.
    pub fn perturbed_normal(&self, wo: Vec3, uv: Vec2) -> Vec3 {
        self.frame(wo, uv).n
    }

    /// Probability that the nested model picks a delta lobe, seen from `wo` in the perturbed
    /// frame.
    pub fn delta_probability(&self, wo: Vec3, uv: Vec2) -> f32 {
        let frame = self.frame(wo, uv);
        self.nested.delta_probability(frame.to_local(wo), uv)
    }

    /// Samples the nested model in the perturbed frame. Radiance: the nested weight times the
    /// shadowing term (f·|cos θi| / pdf as [`NormalMap::eval`]). Importance: the adjoint's
    /// weight, which also covers delta lobes: w'·|cos′ θo|·|cos θi| / (|cos θo|·|cos′ θi|)·G(wo)
    /// with w' the nested importance weight (cos′: in the perturbed frame).
    pub fn sample(
        &self,
        wo: Vec3,
        uv: Vec2,
        u_lobe: f32,
        u: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let frame = self.frame(wo, uv);
        let pwo = frame.to_local(wo);
        let s = self.nested.sample(pwo, uv, u_lobe, u, mode)?;
        let wi = frame.to_world(s.wi);
        if s.wi.z * wi.z <= 0.0 {
            return None;
        }
        let weight = match mode {
            TransportMode::Radiance => s.weight * self.shadowing(&frame, wi),
            TransportMode::Importance => {
                if wo.z * pwo.z <= 0.0 {
                    return None;
                }
                s.weight
                    * (pwo.z.abs() * wi.z.abs() / (wo.z.abs() * s.wi.z.abs())
                        * self.shadowing(&frame, wo))
            }
        };
        Some(BsdfSample { wi, weight, ..s })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Diffuse;

    fn diffuse_under(texel: Rgb) -> NormalMap {
        NormalMap {
            normalmap: Texture::Constant(texel),
            nested: Box::new(Bsdf::Diffuse(Diffuse {
                reflectance: Texture::Constant(Rgb::splat(0.5)),
            })),
            flip_invalid_normals: true,
            use_shadowing_function: true,
        }
    }

    /// Values Mitsuba 3.9.1 (`scalar_rgb`) gives for `normalmap` over `diffuse` (reflectance
    /// 0.5) with texel (0.8, 0.5, 0.9) (n' = (0.6, 0, 0.8)), viewer on the normal, shading frame
    /// = identity: its `eval` (f·cos) and `pdf`.
    #[test]
    fn matches_mitsuba_values() {
        let nm = diffuse_under(Rgb::new(0.8, 0.5, 0.9));
        let wo = Vec3::Z;
        let cases = [
            (Vec3::new(0.0, 0.0, 1.0), 0.127324, 0.254648),
            (
                Vec3::new(0.6, 0.0, 0.8),
                0.157612,
                std::f32::consts::FRAC_1_PI,
            ),
            (Vec3::new(-0.6, 0.0, 0.8), 0.0441313, 0.0891268),
            (Vec3::new(0.8, 0.0, 0.6), 0.148291, 0.305578),
            (Vec3::new(-0.99, 0.0, 0.141), 0.0, 0.0),
            (Vec3::new(0.0, 0.6, 0.8), 0.100871, 0.203718),
        ];
        for (wi, mitsuba_eval, mitsuba_pdf) in cases {
            let wi = wi.normalize();
            let value = nm.eval(wo, wi, Vec2::ZERO, TransportMode::Radiance).x * wi.z;
            let pdf = nm.pdf(wo, wi, Vec2::ZERO);
            assert!(
                (value - mitsuba_eval).abs() < 2e-6,
                "{wi}: {value} vs {mitsuba_eval}"
            );
            assert!(
                (pdf - mitsuba_pdf).abs() < 2e-6,
                "{wi}: {pdf} vs {mitsuba_pdf}"
            );
        }
    }

    /// Sampling agrees with eval/pdf: the weight is eval·cos/pdf, and the mean weight is the
    /// directional albedo ∫ f cos dω (by quadrature of eval).
    #[test]
    fn sampling_matches_eval_and_pdf() {
        use crate::sampling::{rng_for, UniformSource};
        let nm = diffuse_under(Rgb::new(0.75, 0.35, 0.85));
        let wo = Vec3::new(0.3, -0.2, 0.9).normalize();
        let mut rng = rng_for(1, 2, 3);
        let n = 200_000;
        let mut mean = 0.0f64;
        for _ in 0..n {
            let (ul, u) = (rng.next_f32(), rng.next_2d());
            if let Some(s) = nm.sample(wo, Vec2::ZERO, ul, u, TransportMode::Radiance) {
                let f = nm.eval(wo, s.wi, Vec2::ZERO, TransportMode::Radiance);
                let expected = f * s.wi.z.abs() / s.pdf;
                assert!((s.weight - expected).abs().max_element() < 1e-4 * expected.x.max(1.0));
                assert!((s.pdf - nm.pdf(wo, s.wi, Vec2::ZERO)).abs() < 1e-4 * s.pdf.max(1.0));
                mean += s.weight.x as f64;
            }
        }
        mean /= n as f64;
        // ∫ f cos dω over the hemisphere by a midpoint rule in (cos θ, φ).
        let (nt, np) = (400, 400);
        let mut integral = 0.0f64;
        for i in 0..nt {
            let cos_t = (i as f32 + 0.5) / nt as f32;
            let sin_t = (1.0 - cos_t * cos_t).sqrt();
            for j in 0..np {
                let phi = (j as f32 + 0.5) / np as f32 * std::f32::consts::TAU;
                let wi = Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t);
                let f = nm.eval(wo, wi, Vec2::ZERO, TransportMode::Radiance).x;
                integral += (f * cos_t) as f64;
            }
        }
        integral *= std::f64::consts::TAU / (nt * np) as f64;
        assert!((mean - integral).abs() < 3e-3, "{mean} vs {integral}");
        assert!(
            integral < 0.5,
            "reflects at most the nested albedo: {integral}"
        );
    }

    /// A flat normal map (texel (½, ½, 1)) without the shadowing term is the nested model.
    #[test]
    fn flat_map_is_the_nested_model() {
        let mut nm = diffuse_under(Rgb::new(0.5, 0.5, 1.0));
        nm.use_shadowing_function = false;
        let wo = Vec3::new(0.2, 0.1, 0.9).normalize();
        let wi = Vec3::new(-0.5, 0.3, 0.4).normalize();
        let direct = nm.nested.eval(wo, wi, Vec2::ZERO, TransportMode::Radiance);
        let mapped = nm.eval(wo, wi, Vec2::ZERO, TransportMode::Radiance);
        assert!((direct - mapped).abs().max_element() < 1e-6);
    }

    /// The shading normal the G-buffer records: the perturbed one under a normal map (also
    /// seen from the back through `twosided`, mirrored), +z for plain models.
    #[test]
    fn shading_normal_is_the_perturbed_one() {
        let nm = Bsdf::NormalMap(diffuse_under(Rgb::new(0.8, 0.5, 0.9)));
        let wo = Vec3::new(0.1, 0.2, 0.97).normalize();
        let n = nm.shading_normal(wo, Vec2::ZERO);
        assert!((n - Vec3::new(0.6, 0.0, 0.8)).length() < 1e-6, "{n}");
        let two = Bsdf::TwoSided {
            front: Box::new(nm.clone()),
            back: Box::new(nm),
        };
        let below = Vec3::new(wo.x, wo.y, -wo.z);
        let n = two.shading_normal(below, Vec2::ZERO);
        assert!((n - Vec3::new(0.6, 0.0, -0.8)).length() < 1e-6, "{n}");
        let plain = diffuse_under(Rgb::new(0.8, 0.5, 0.9)).nested;
        assert_eq!(plain.shading_normal(wo, Vec2::ZERO), Vec3::Z);
    }
}
