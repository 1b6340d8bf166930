//! `bumpmap`: a nested BSDF evaluated in a shading frame tilted by the gradient of a height
//! field, as Mitsuba 3's `bumpmap`.
//!
//! Parameters, in the XML's words: one nested `<texture>` (the height field, a `bitmap` —
//! Mitsuba implements the gradient for bitmaps only — usually with `raw` = true; a colour map
//! is read by its luminance), one nested `<bsdf>`, `scale` (default 1: multiplies the height
//! gradient), `flip_invalid_normals` (default true) and `use_shadowing_function` (default
//! true), the last two as in `normalmap`.
//!
//! With (h_u, h_v) = scale·∇h at the point's uv, the surface's tangents become
//! ∂p/∂u' = ∂p/∂u + n·(h_u − n·∂p/∂u) and ∂p/∂v' likewise (n the shading normal: the height
//! displaces along it, its own variation neglected), the tilted normal is ∂p/∂u' × ∂p/∂v' turned
//! to the geometric normal's side, and the tilted tangent is ∂p/∂u made orthogonal to it. So the
//! bump's strength depends on the surface's parameterisation — world units per unit of uv —
//! exactly as in Mitsuba; a constant height offset changes nothing.
//!
//! Mitsuba 3.9.1 orthogonalises the *world-space* ∂p/∂u against the tilted normal expressed in
//! the shading frame. That mixes two frames and only changes the tangent about the normal, so
//! isotropic nested models are unaffected; here the tangent is built in one frame, as intended.

use super::perturbed::{tilted_frame, TiltedModel};
use super::{Bsdf, ShadingPoint};
use crate::frame::Frame;
use crate::texture::Texture;
use glam::Vec3;

/// `bumpmap`: the nested model seen through the frame a height field's gradient tilts.
#[derive(Debug, Clone)]
pub struct BumpMap {
    /// The height field (a bitmap; [`Texture::eval_1_grad`] gives its gradient).
    pub height: Texture,
    /// `scale`: gradient multiplier (default 1).
    pub scale: f32,
    /// The nested BSDF.
    pub nested: Box<Bsdf>,
    /// `flip_invalid_normals` (default true).
    pub flip_invalid_normals: bool,
    /// `use_shadowing_function` (default true).
    pub use_shadowing_function: bool,
}

impl BumpMap {
    /// Whether `flip_invalid_normals` mirrors the tilted normal for a path arriving from `wo`.
    #[cfg(test)]
    pub(crate) fn flips(&self, wo: Vec3, sp: &ShadingPoint) -> bool {
        let unflipped = BumpMap {
            flip_invalid_normals: false,
            ..self.clone()
        };
        self.tilted(wo, sp).n != unflipped.tilted(wo, sp).n
    }
}

impl TiltedModel for BumpMap {
    fn tilted(&self, wo: Vec3, sp: &ShadingPoint) -> Frame {
        let grad = self.height.eval_1_grad(sp.tex.uv) * self.scale;
        // In the shading frame n = +z, so adding n·(h − n·∂p) replaces the z component by h.
        let dpdu = Vec3::new(sp.dpdu.x, sp.dpdu.y, grad.x);
        let dpdv = Vec3::new(sp.dpdv.x, sp.dpdv.y, grad.y);
        let mut n = dpdu.cross(dpdv).normalize_or(Vec3::Z);
        if sp.ng.dot(n) < 0.0 {
            n = -n;
        }
        if self.flip_invalid_normals && wo.z * wo.dot(n) <= 0.0 {
            n = Vec3::new(-n.x, -n.y, n.z);
        }
        tilted_frame(n, sp.dpdu)
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
    use crate::bsdf::{
        Diffuse, MicrofacetKind, RoughConductor, Roughness, ShadingPoint, TransportMode,
    };
    use crate::spectrum::Rgb;
    use crate::texture::{Bitmap, BitmapFilter, BitmapWrap};
    use glam::Vec2;
    use std::sync::Arc;

    /// The 3×2 height field of the Mitsuba probe (rows top to bottom), bilinear, repeating.
    fn heights() -> Texture {
        Texture::Bitmap {
            image: Arc::new(Bitmap {
                width: 3,
                height: 2,
                texels: [0.4, 0.1, 0.25, 0.6, 0.3, 0.9].map(Rgb::splat).to_vec(),
            }),
            filter: BitmapFilter::Bilinear,
            wrap: BitmapWrap::Repeat,
            to_uv: glam::Mat3::IDENTITY,
        }
    }

    /// The probe's shading point: uv (0.3, 0.7), sheared and scaled ∂p/∂u = (2, 0, 0),
    /// ∂p/∂v = (0.5, 1.5, 0), geometric normal = shading normal = +z.
    fn point() -> ShadingPoint {
        ShadingPoint {
            tex: Vec2::new(0.3, 0.7).into(),
            dpdu: Vec3::new(2.0, 0.0, 0.0),
            dpdv: Vec3::new(0.5, 1.5, 0.0),
            ng: Vec3::Z,
        }
    }

    fn bump(nested: &str, scale: f32, flip: bool, shadow: bool) -> BumpMap {
        let nested = match nested {
            "roughconductor" => Bsdf::RoughConductor(RoughConductor {
                roughness: Roughness {
                    kind: MicrofacetKind::Ggx,
                    alpha_u: 0.3,
                    alpha_v: 0.3,
                },
                alpha_texture: None,
                ior: None,
                specular_reflectance: Texture::Constant(Rgb::ONE),
            }),
            _ => Bsdf::Diffuse(Diffuse {
                reflectance: Texture::Constant(Rgb::splat(0.5)),
            }),
        };
        BumpMap {
            height: heights(),
            scale,
            nested: Box::new(nested),
            flip_invalid_normals: flip,
            use_shadowing_function: shadow,
        }
    }

    /// Mitsuba 3.9.1 (`scalar_rgb`) on the same height field and shading point: the texture's
    /// `eval_1_grad` is (−0.9, 0.4); `bumpmap`'s `eval` (f·cos) and `pdf` for a diffuse and a
    /// GGX conductor, with and without flip and shadowing, a negative scale, two viewers.
    /// Printed by `renderer/tests/data/bumpmap_reference.py`.
    /// Model, scale, flip, shadowing, wo, wi, Mitsuba's eval (f·cos) and pdf.
    type ProbeCase = (&'static str, f32, bool, bool, [f32; 3], [f32; 3], f32, f32);

    #[test]
    #[allow(clippy::excessive_precision)] // Mitsuba's values as printed, digit for digit
    fn matches_mitsuba_values() {
        let grad = heights().eval_1_grad(point().tex.uv);
        assert!((grad - Vec2::new(-0.9, 0.4)).length() < 1e-5, "{grad}");
        #[rustfmt::skip]
        let cases: [ProbeCase; 30] = [
            ("diffuse", 2.5, true, true, [0.2009162, 0.1004581, 0.9744438], [0.0000000, 0.0000000, 1.0000000], 8.6946614e-02, 1.7389323e-01),
            ("diffuse", 2.5, true, true, [0.2009162, 0.1004581, 0.9744438], [0.5184758, -0.2073903, 0.8295614], 1.3720120e-01, 2.8325090e-01),
            ("diffuse", 2.5, true, true, [0.2009162, 0.1004581, 0.9744438], [-0.6000000, 0.0000000, 0.8000000], 1.0452912e-02, 2.1736650e-02),
            ("diffuse", 2.5, true, true, [0.2009162, 0.1004581, 0.9744438], [0.1048285, 0.9434564, 0.3144855], 0.0000000e+00, 0.0000000e+00),
            ("diffuse", 2.5, true, true, [0.2009162, 0.1004581, 0.9744438], [0.9824666, 0.1034175, 0.1551263], 4.3631490e-02, 2.0044233e-01),
            ("diffuse", 2.5, true, true, [-0.8137335, 0.3487429, 0.4649906], [0.0000000, 0.0000000, 1.0000000], 8.6946614e-02, 1.7389323e-01),
            ("diffuse", 2.5, true, true, [-0.8137335, 0.3487429, 0.4649906], [0.5184758, -0.2073903, 0.8295614], 2.5475034e-03, 5.2593024e-03),
            ("diffuse", 2.5, true, true, [-0.8137335, 0.3487429, 0.4649906], [-0.6000000, 0.0000000, 0.8000000], 1.2334438e-01, 2.5649253e-01),
            ("diffuse", 2.5, true, true, [-0.8137335, 0.3487429, 0.4649906], [0.1048285, 0.9434564, 0.3144855], 7.0289299e-02, 2.0507587e-01),
            ("diffuse", 2.5, true, true, [-0.8137335, 0.3487429, 0.4649906], [0.9824666, 0.1034175, 0.1551263], 0.0000000e+00, 0.0000000e+00),
            ("roughconductor", 1.0, true, true, [0.2009162, 0.1004581, 0.9744438], [0.0000000, 0.0000000, 1.0000000], 8.1680536e-02, 8.2365997e-02),
            ("roughconductor", 1.0, true, true, [0.2009162, 0.1004581, 0.9744438], [0.5184758, -0.2073903, 0.8295614], 2.6399288e-01, 2.6564094e-01),
            ("roughconductor", 1.0, true, true, [0.2009162, 0.1004581, 0.9744438], [-0.6000000, 0.0000000, 0.8000000], 2.7786631e-02, 3.0238613e-02),
            ("roughconductor", 1.0, true, true, [0.2009162, 0.1004581, 0.9744438], [0.1048285, 0.9434564, 0.3144855], 0.0000000e+00, 0.0000000e+00),
            ("roughconductor", 1.0, true, true, [0.2009162, 0.1004581, 0.9744438], [0.9824666, 0.1034175, 0.1551263], 3.6054913e-02, 5.2322101e-02),
            ("roughconductor", 1.0, true, true, [-0.8137335, 0.3487429, 0.4649906], [0.0000000, 0.0000000, 1.0000000], 6.0344535e-01, 6.0850948e-01),
            ("roughconductor", 1.0, true, true, [-0.8137335, 0.3487429, 0.4649906], [0.5184758, -0.2073903, 0.8295614], 2.3844069e-01, 2.6097584e-01),
            ("roughconductor", 1.0, true, true, [-0.8137335, 0.3487429, 0.4649906], [-0.6000000, 0.0000000, 0.8000000], 1.2897335e-01, 1.3040771e-01),
            ("roughconductor", 1.0, true, true, [-0.8137335, 0.3487429, 0.4649906], [0.1048285, 0.9434564, 0.3144855], 5.6419756e-02, 6.4794227e-02),
            ("roughconductor", 1.0, true, true, [-0.8137335, 0.3487429, 0.4649906], [0.9824666, 0.1034175, 0.1551263], 0.0000000e+00, 0.0000000e+00),
            ("diffuse noflip noshadow", -3.0, false, false, [0.2009162, 0.1004581, 0.9744438], [0.0000000, 0.0000000, 1.0000000], 7.6003797e-02, 1.5200759e-01),
            ("diffuse noflip noshadow", -3.0, false, false, [0.2009162, 0.1004581, 0.9744438], [0.5184758, -0.2073903, 0.8295614], 0.0000000e+00, 0.0000000e+00),
            ("diffuse noflip noshadow", -3.0, false, false, [0.2009162, 0.1004581, 0.9744438], [-0.6000000, 0.0000000, 0.8000000], 1.2236612e-01, 2.4473223e-01),
            ("diffuse noflip noshadow", -3.0, false, false, [0.2009162, 0.1004581, 0.9744438], [0.1048285, 0.9434564, 0.3144855], 1.0277898e-01, 2.0555796e-01),
            ("diffuse noflip noshadow", -3.0, false, false, [0.2009162, 0.1004581, 0.9744438], [0.9824666, 0.1034175, 0.1551263], 0.0000000e+00, 0.0000000e+00),
            ("diffuse noflip noshadow", -3.0, false, false, [-0.8137335, 0.3487429, 0.4649906], [0.0000000, 0.0000000, 1.0000000], 7.6003797e-02, 1.5200759e-01),
            ("diffuse noflip noshadow", -3.0, false, false, [-0.8137335, 0.3487429, 0.4649906], [0.5184758, -0.2073903, 0.8295614], 0.0000000e+00, 0.0000000e+00),
            ("diffuse noflip noshadow", -3.0, false, false, [-0.8137335, 0.3487429, 0.4649906], [-0.6000000, 0.0000000, 0.8000000], 1.2236612e-01, 2.4473223e-01),
            ("diffuse noflip noshadow", -3.0, false, false, [-0.8137335, 0.3487429, 0.4649906], [0.1048285, 0.9434564, 0.3144855], 1.0277898e-01, 2.0555796e-01),
            ("diffuse noflip noshadow", -3.0, false, false, [-0.8137335, 0.3487429, 0.4649906], [0.9824666, 0.1034175, 0.1551263], 0.0000000e+00, 0.0000000e+00),
        ];
        for (name, scale, flip, shadow, wo, wi, mitsuba_eval, mitsuba_pdf) in cases {
            let b = bump(name, scale, flip, shadow);
            let (wo, wi) = (Vec3::from(wo), Vec3::from(wi));
            let value = b.eval(wo, wi, &point(), TransportMode::Radiance).x * wi.z;
            let pdf = b.pdf(wo, wi, &point());
            let tol = |m: f32| 1e-5 + 1e-4 * m.abs();
            assert!(
                (value - mitsuba_eval).abs() < tol(mitsuba_eval),
                "{name} {wo} {wi}: eval {value} vs {mitsuba_eval}"
            );
            assert!(
                (pdf - mitsuba_pdf).abs() < tol(mitsuba_pdf),
                "{name} {wo} {wi}: pdf {pdf} vs {mitsuba_pdf}"
            );
        }
    }

    /// A constant height field tilts nothing: without the shadowing term the adapter is the
    /// nested model (a constant offset of the heights changes nothing, as Mitsuba documents).
    #[test]
    fn flat_heights_are_the_nested_model() {
        let mut b = bump("diffuse", 1.0, true, false);
        b.height = Texture::Bitmap {
            image: Arc::new(Bitmap {
                width: 2,
                height: 2,
                texels: vec![Rgb::splat(0.7); 4],
            }),
            filter: BitmapFilter::Bilinear,
            wrap: BitmapWrap::Repeat,
            to_uv: glam::Mat3::IDENTITY,
        };
        let wo = Vec3::new(0.2, 0.1, 0.9).normalize();
        let wi = Vec3::new(-0.5, 0.3, 0.4).normalize();
        let sp = point();
        let direct = b.nested.eval(wo, wi, &sp, TransportMode::Radiance);
        let bumped = b.eval(wo, wi, &sp, TransportMode::Radiance);
        assert!((direct - bumped).abs().max_element() < 1e-6);
        assert!((b.perturbed_normal(wo, &sp) - Vec3::Z).length() < 1e-6);
    }

    /// The tilted normal is the height field's: for a surface parameterised along its frame
    /// (∂p/∂u = s·x, ∂p/∂v = s·y) it is (−h_u/s, −h_v/s, 1) normalised, so doubling the
    /// parameterisation's scale halves the tilt, and it stays on the geometric normal's side.
    #[test]
    fn tilt_follows_gradient_and_parameterisation() {
        let b = bump("diffuse", 1.0, false, false);
        let wo = Vec3::Z;
        for s in [1.0f32, 2.0] {
            let sp = ShadingPoint {
                dpdu: Vec3::X * s,
                dpdv: Vec3::Y * s,
                ..point()
            };
            let n = b.perturbed_normal(wo, &sp);
            let want = Vec3::new(0.9 / s, -0.4 / s, 1.0).normalize();
            assert!((n - want).length() < 1e-5, "scale {s}: {n} vs {want}");
            // Flipped parameterisation (∂p/∂v reversed): the cross product points down, and
            // the normal is turned back to the geometric normal's side.
            let flipped = ShadingPoint {
                dpdv: -sp.dpdv,
                ..sp
            };
            assert!(b.perturbed_normal(wo, &flipped).z > 0.0);
        }
    }
}
