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

use super::perturbed::{tilted_frame, TiltedModel};
use super::{Bsdf, ShadingPoint};
use crate::frame::Frame;
use crate::texture::Texture;
use glam::Vec3;

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

impl NormalMap {
    /// Whether `flip_invalid_normals` mirrors the map's normal for a path arriving from `wo`.
    #[cfg(test)]
    pub(crate) fn flips(&self, wo: Vec3, uv: glam::Vec2) -> bool {
        let n = self.normalmap.eval(uv) * 2.0 - Vec3::ONE;
        self.flip_invalid_normals && wo.z * wo.dot(n) <= 0.0
    }
}

impl TiltedModel for NormalMap {
    fn tilted(&self, wo: Vec3, sp: &ShadingPoint) -> Frame {
        let mut n = self.normalmap.eval(sp.tex) * 2.0 - Vec3::ONE;
        if self.flip_invalid_normals && wo.z * wo.dot(n) <= 0.0 {
            n = Vec3::new(-n.x, -n.y, n.z);
        }
        let len2 = n.length_squared();
        let n = if len2 > 0.0 && len2.is_finite() {
            n / len2.sqrt()
        } else {
            Vec3::Z
        };
        tilted_frame(n, Vec3::X)
    }

    fn nested_model(&self) -> &Bsdf {
        &self.nested
    }

    fn uses_shadowing(&self) -> bool {
        self.use_shadowing_function
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Diffuse;
    use crate::bsdf::TransportMode;
    use crate::spectrum::Rgb;
    use glam::Vec2;

    const FLAT: ShadingPoint = ShadingPoint::flat(Vec2::ZERO);

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
            let value = nm.eval(wo, wi, &FLAT, TransportMode::Radiance).x * wi.z;
            let pdf = nm.pdf(wo, wi, &FLAT);
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
            if let Some(s) = nm.sample(wo, &FLAT, ul, u, TransportMode::Radiance) {
                let f = nm.eval(wo, s.wi, &FLAT, TransportMode::Radiance);
                let expected = f * s.wi.z.abs() / s.pdf;
                assert!((s.weight - expected).abs().max_element() < 1e-4 * expected.x.max(1.0));
                assert!((s.pdf - nm.pdf(wo, s.wi, &FLAT)).abs() < 1e-4 * s.pdf.max(1.0));
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
                let f = nm.eval(wo, wi, &FLAT, TransportMode::Radiance).x;
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
        let direct = nm.nested.eval(wo, wi, &FLAT, TransportMode::Radiance);
        let mapped = nm.eval(wo, wi, &FLAT, TransportMode::Radiance);
        assert!((direct - mapped).abs().max_element() < 1e-6);
    }

    /// The shading normal the G-buffer records: the perturbed one under a normal map (also
    /// seen from the back through `twosided`: the same line, front-oriented), +z for plain models
    /// on either side.
    #[test]
    fn shading_normal_is_the_perturbed_one() {
        let nm = Bsdf::NormalMap(diffuse_under(Rgb::new(0.8, 0.5, 0.9)));
        let wo = Vec3::new(0.1, 0.2, 0.97).normalize();
        let n = nm.shading_normal(wo, &FLAT);
        assert!((n - Vec3::new(0.6, 0.0, 0.8)).length() < 1e-6, "{n}");
        let two = Bsdf::TwoSided {
            front: Box::new(nm.clone()),
            back: Box::new(nm),
        };
        let below = Vec3::new(wo.x, wo.y, -wo.z);
        let n = two.shading_normal(below, &FLAT);
        // The same line as the back model's perturbed normal (0.6, 0, −0.8), front-oriented.
        assert!((n - Vec3::new(-0.6, 0.0, 0.8)).length() < 1e-6, "{n}");
        let plain = diffuse_under(Rgb::new(0.8, 0.5, 0.9)).nested;
        assert_eq!(plain.shading_normal(wo, &FLAT), Vec3::Z);
        // A plain two-sided model reports its frame's normal from both sides (the networks'
        // training data has it so; the tenth session's version flipped it on the back side).
        let plain_two = Bsdf::TwoSided {
            front: plain.clone(),
            back: plain,
        };
        assert_eq!(plain_two.shading_normal(below, &FLAT), Vec3::Z);
    }
}
