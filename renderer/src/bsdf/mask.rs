//! `mask`: an opacity mask over a nested BSDF, as Mitsuba 3's `mask`: with probability
//! 1 − opacity light passes straight through the surface (a forward delta, weight 1), else it
//! meets the nested model.
//!
//! Parameters, in the XML's words: `opacity` (a float or texture in [0, 1], clamped; a colour
//! texture counts by its luminance; 1 = opaque; default 0.5) and one nested `<bsdf>`.
//!
//! The pass-through is a delta lobe like a mirror's: eye paths follow it (SPPM splits on it at a
//! visible point, docs/sppm.md) and shadow rays are blocked by the mask's geometry, as in
//! Mitsuba's `path` — light through the holes arrives by BSDF sampling (in SPPM by photons,
//! which are deposited behind a mask however many pass-throughs they took).
//! Unlike Mitsuba, the nested model's samples report the density of the whole mask,
//! opacity · p, which is what [`Bsdf::pdf`] returns and the integrators' MIS needs.

use super::{Bsdf, BsdfSample, ShadingPoint, TransportMode};
use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use glam::{Vec2, Vec3};

/// `mask`: a nested model seen through an opacity.
#[derive(Debug, Clone)]
pub struct Mask {
    /// `opacity`: 1 = the nested model everywhere, 0 = fully transparent.
    pub opacity: Texture,
    /// The nested BSDF.
    pub nested: Box<Bsdf>,
}

impl Mask {
    /// The opacity at `tp`.
    pub fn opacity_at(&self, tp: TexPoint) -> f32 {
        self.opacity.eval_1(tp).clamp(0.0, 1.0)
    }

    /// opacity · f (the pass-through is a delta: no value).
    pub fn eval(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint, mode: TransportMode) -> Rgb {
        let a = self.opacity_at(sp.tex);
        if a > 0.0 {
            self.nested.eval(wo, wi, sp, mode) * a
        } else {
            Rgb::ZERO
        }
    }

    /// [`Bsdf::eval_split`]: opacity · the nested model's parts.
    pub fn eval_split(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint) -> (Rgb, Rgb) {
        let a = self.opacity_at(sp.tex);
        if a > 0.0 {
            let (broad, sharp) = self.nested.eval_split(wo, wi, sp);
            (broad * a, sharp * a)
        } else {
            (Rgb::ZERO, Rgb::ZERO)
        }
    }

    /// opacity · p.
    pub fn pdf(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint) -> f32 {
        let a = self.opacity_at(sp.tex);
        if a > 0.0 {
            self.nested.pdf(wo, wi, sp) * a
        } else {
            0.0
        }
    }

    /// The nested model with probability opacity (`u_lobe` rescaled), else straight through.
    pub fn sample(
        &self,
        wo: Vec3,
        sp: &ShadingPoint,
        u_lobe: f32,
        u: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let a = self.opacity_at(sp.tex);
        if u_lobe < a {
            let u_nested = (u_lobe / a).min(1.0 - f32::EPSILON / 2.0);
            let s = self.nested.sample(wo, sp, u_nested, u, mode)?;
            return Some(BsdfSample {
                pdf: s.pdf * a,
                ..s
            });
        }
        Some(BsdfSample {
            wi: -wo,
            weight: Rgb::ONE,
            pdf: 1.0 - a,
            delta: true,
            eta: 1.0,
        })
    }

    /// Probability of a delta sample: the pass-through plus the nested model's delta share.
    pub fn delta_probability(&self, wo: Vec3, sp: &ShadingPoint) -> f32 {
        let a = self.opacity_at(sp.tex);
        (1.0 - a) + a * self.nested.delta_probability(wo, sp)
    }
}
