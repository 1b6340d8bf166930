//! What `normalmap` and `bumpmap` share, Mitsuba 3's perturbed-frame adapter: the nested model
//! evaluated in a shading frame tilted away from the surface's, with Mitsuba's side checks and
//! its optional shadowing term (Estévez et al. 2019) against the bump terminator problem.
//!
//! A direction whose side of the surface differs between the shading frame and the tilted one
//! contributes nothing (Mitsuba's check on the sampled / evaluated direction). The tilted
//! frame is a rotation, so solid-angle densities carry over unchanged.

use super::{Bsdf, BsdfSample, ShadingPoint, TransportMode};
use crate::frame::Frame;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// Estévez et al.'s shadowing term for a perturbed normal `n` and direction `w`, both in the
/// shading frame: 2 / (1 + √(1 + α²·tan²θ_w)) with α² = min(tan²θ_n / 8, 1).
fn shadow_terminator(n: Vec3, w: Vec3) -> f32 {
    let tan2 = |v: Vec3| (1.0 - v.z * v.z).max(0.0) / (v.z * v.z);
    let alpha2 = (0.125 * tan2(n)).min(1.0);
    2.0 / (1.0 + (1.0 + alpha2 * tan2(w)).sqrt())
}

/// A nested model seen through a tilted frame at one shading point.
pub(super) struct Perturbed<'a> {
    /// The nested model.
    pub nested: &'a Bsdf,
    /// The tilted frame, in the shading frame.
    pub frame: Frame,
    /// The shading point as the nested model sees it (in the tilted frame).
    pub sp: ShadingPoint,
    /// Whether the shadowing term applies (`use_shadowing_function`).
    pub shadowing: bool,
}

impl Perturbed<'_> {
    /// The shadowing factor for direction `w` (1 when switched off).
    fn shadowing(&self, w: Vec3) -> f32 {
        if self.shadowing {
            shadow_terminator(self.frame.n, w)
        } else {
            1.0
        }
    }

    /// Radiance-mode f(viewer, light) without the cosine of the shading frame: the nested
    /// model's f·cos in the tilted frame (what Mitsuba's `eval` returns), times the shadowing
    /// term, divided by |cos θ| of the shading frame that integrators multiply back. Zero where
    /// the light direction changes sides between the two frames.
    fn eval_in(&self, viewer: Vec3, light: Vec3) -> Rgb {
        let (pv, pl) = (self.frame.to_local(viewer), self.frame.to_local(light));
        if light.z * pl.z <= 0.0 {
            return Rgb::ZERO;
        }
        let f = self.nested.eval(pv, pl, &self.sp, TransportMode::Radiance);
        if f == Rgb::ZERO {
            return f;
        }
        f * (pl.z.abs() / light.z.abs() * self.shadowing(light))
    }

    /// The radiance-mode value split into its broad and sharp parts (see
    /// [`Bsdf::eval_split`]): the nested model's parts, each scaled as in [`Perturbed::eval`].
    pub fn eval_split(&self, wo: Vec3, wi: Vec3) -> (Rgb, Rgb) {
        let (pv, pl) = (self.frame.to_local(wo), self.frame.to_local(wi));
        if wi.z * pl.z <= 0.0 {
            return (Rgb::ZERO, Rgb::ZERO);
        }
        let (broad, sharp) = self.nested.eval_split(pv, pl, &self.sp);
        let scale = pl.z.abs() / wi.z.abs() * self.shadowing(wi);
        (broad * scale, sharp * scale)
    }

    /// The nested model's sharp share (see [`Bsdf::sharp_share`]), seen from `wo` in the
    /// tilted frame.
    pub fn sharp_share(&self, wo: Vec3) -> Option<f32> {
        self.nested.sharp_share(self.frame.to_local(wo), &self.sp)
    }

    /// f(wo, wi) without the cosine of the shading frame. Radiance: viewer `wo`, light `wi`.
    /// Importance (photons arriving from `wo`, leaving along `wi`): the adjoint, f(wi, wo) —
    /// the adapter is not reciprocal — in the frame `wo` selected (the flip of an invalid
    /// normal is decided by the arriving direction, as the photon's sampling must).
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        if wi.z * self.frame.to_local(wi).z <= 0.0 {
            return Rgb::ZERO;
        }
        match mode {
            TransportMode::Radiance => self.eval_in(wo, wi),
            TransportMode::Importance => self.eval_in(wi, wo),
        }
    }

    /// The nested model's density of `wi`, zero where [`Perturbed::sample`] rejects.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let pwi = self.frame.to_local(wi);
        if wi.z * pwi.z <= 0.0 {
            return 0.0;
        }
        self.nested.pdf(self.frame.to_local(wo), pwi, &self.sp)
    }

    /// Probability that the nested model picks a delta lobe, seen from `wo` in the tilted frame.
    pub fn delta_probability(&self, wo: Vec3) -> f32 {
        self.nested
            .delta_probability(self.frame.to_local(wo), &self.sp)
    }

    /// Samples the nested model in the tilted frame. Radiance: the nested weight times the
    /// shadowing term (f·|cos θi| / pdf as [`Perturbed::eval`]). Importance: the adjoint's
    /// weight, which also covers delta lobes: w'·|cos′ θo|·|cos θi| / (|cos θo|·|cos′ θi|)·G(wo)
    /// with w' the nested importance weight (cos′: in the tilted frame).
    pub fn sample(
        &self,
        wo: Vec3,
        u_lobe: f32,
        u: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let pwo = self.frame.to_local(wo);
        let s = self.nested.sample(pwo, &self.sp, u_lobe, u, mode)?;
        let wi = self.frame.to_world(s.wi);
        if s.wi.z * wi.z <= 0.0 {
            return None;
        }
        let weight = match mode {
            TransportMode::Radiance => s.weight * self.shadowing(wi),
            TransportMode::Importance => {
                if wo.z * pwo.z <= 0.0 {
                    return None;
                }
                s.weight
                    * (pwo.z.abs() * wi.z.abs() / (wo.z.abs() * s.wi.z.abs()) * self.shadowing(wo))
            }
        };
        Some(BsdfSample { wi, weight, ..s })
    }
}

/// A model seen through a tilted shading frame (`normalmap`, `bumpmap`): each says how it
/// tilts the frame; the rest — evaluation, sampling and the SPPM queries — is this trait's and
/// the same for both.
pub trait TiltedModel {
    /// The tilted frame relative to the shading frame at `sp`, for viewer direction `wo`.
    fn tilted(&self, wo: Vec3, sp: &ShadingPoint) -> Frame;
    /// The nested model.
    fn nested_model(&self) -> &Bsdf;
    /// Whether the shadowing term applies (`use_shadowing_function`).
    fn uses_shadowing(&self) -> bool;

    /// f(wo, wi) without the cosine of the shading frame (the adjoint in Importance mode; see
    /// [`Perturbed::eval`]).
    fn eval(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint, mode: TransportMode) -> Rgb {
        perturbed(self, wo, sp).eval(wo, wi, mode)
    }

    /// [`Bsdf::eval_split`] through the tilted frame.
    fn eval_split(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint) -> (Rgb, Rgb) {
        perturbed(self, wo, sp).eval_split(wo, wi)
    }

    /// [`Bsdf::sharp_share`] through the tilted frame.
    fn sharp_share(&self, wo: Vec3, sp: &ShadingPoint) -> Option<f32> {
        perturbed(self, wo, sp).sharp_share(wo)
    }

    /// The nested model's density of `wi`, seen through the tilted frame.
    fn pdf(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint) -> f32 {
        perturbed(self, wo, sp).pdf(wo, wi)
    }

    /// The tilted shading normal for viewer `wo`, in the shading frame.
    fn perturbed_normal(&self, wo: Vec3, sp: &ShadingPoint) -> Vec3 {
        self.tilted(wo, sp).n
    }

    /// Probability that the nested model picks a delta lobe, seen from `wo` in the tilted frame.
    fn delta_probability(&self, wo: Vec3, sp: &ShadingPoint) -> f32 {
        perturbed(self, wo, sp).delta_probability(wo)
    }

    /// Samples the nested model in the tilted frame (see [`Perturbed::sample`]).
    fn sample(
        &self,
        wo: Vec3,
        sp: &ShadingPoint,
        u_lobe: f32,
        u: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        perturbed(self, wo, sp).sample(wo, u_lobe, u, mode)
    }
}

/// `model`'s nested model in the frame `wo` selects at `sp`.
pub(super) fn perturbed<'a, M: TiltedModel + ?Sized>(
    model: &'a M,
    wo: Vec3,
    sp: &ShadingPoint,
) -> Perturbed<'a> {
    let frame = model.tilted(wo, sp);
    Perturbed {
        nested: model.nested_model(),
        sp: sp.in_frame(&frame),
        frame,
        shadowing: model.uses_shadowing(),
    }
}

/// The tilted frame with normal `n` (unit, shading frame) whose tangent is `tangent` made
/// orthogonal to `n` (Gram–Schmidt; any tangent where that degenerates).
pub(super) fn tilted_frame(n: Vec3, tangent: Vec3) -> Frame {
    Frame::from_normal_tangent(n, tangent)
}
