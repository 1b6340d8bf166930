//! `blendbsdf`: (1 − w)·f₀ + w·f₁, a linear blend of two nested BSDFs, as Mitsuba 3's
//! `blendbsdf`.
//!
//! Parameters, in the XML's words: `weight` (a float or texture in [0, 1], clamped; a colour
//! texture counts by its luminance; default 0.5) and two nested `<bsdf>`s, the first at weight
//! 0, the second at weight 1.
//!
//! Sampling picks the second model with probability w, the first otherwise. Unlike Mitsuba,
//! whose sample reports the chosen model's own density, a non-delta sample here carries the
//! density of the whole blend, (1 − w)·p₀ + w·p₁, and the weight f·|cos θi| / that density
//! (one-sample MIS over the two models): that is the density [`Bsdf::pdf`] reports, which the
//! integrators' MIS needs to be consistent. A delta sample keeps its model's weight, with the
//! choice probability folded into its `pdf`.

use super::{Bsdf, BsdfSample, ShadingPoint, TransportMode};
use crate::sampling::ONE_MINUS_EPSILON;
use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use glam::{Vec2, Vec3};

/// `blendbsdf`: two models mixed by a weight.
#[derive(Debug, Clone)]
pub struct Blend {
    /// `weight`: the share of the second model.
    pub weight: Texture,
    /// The model at weight 0 and the one at weight 1.
    pub nested: Box<[Bsdf; 2]>,
}

impl Blend {
    /// The blend weight at `tp`, clamped to [0, 1] (grey values as they are, colours by
    /// luminance, as Mitsuba's `eval_1`).
    pub fn weight_at(&self, tp: TexPoint) -> f32 {
        self.weight.eval_1(tp).clamp(0.0, 1.0)
    }

    /// (1 − w)·f₀ + w·f₁.
    pub fn eval(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint, mode: TransportMode) -> Rgb {
        let w = self.weight_at(sp.tex);
        let [a, b] = &*self.nested;
        let mut f = Rgb::ZERO;
        if w < 1.0 {
            f += a.eval(wo, wi, sp, mode) * (1.0 - w);
        }
        if w > 0.0 {
            f += b.eval(wo, wi, sp, mode) * w;
        }
        f
    }

    /// [`Bsdf::eval_split`]: each model's parts, weighted as in [`Blend::eval`].
    pub fn eval_split(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint) -> (Rgb, Rgb) {
        let w = self.weight_at(sp.tex);
        let [a, b] = &*self.nested;
        let (mut broad, mut sharp) = (Rgb::ZERO, Rgb::ZERO);
        if w < 1.0 {
            let (fb, fs) = a.eval_split(wo, wi, sp);
            broad += fb * (1.0 - w);
            sharp += fs * (1.0 - w);
        }
        if w > 0.0 {
            let (fb, fs) = b.eval_split(wo, wi, sp);
            broad += fb * w;
            sharp += fs * w;
        }
        (broad, sharp)
    }

    /// [`Bsdf::sharp_share`]: the models' shares, weighted like their sampling.
    pub fn sharp_share(&self, wo: Vec3, sp: &ShadingPoint) -> Option<f32> {
        let w = self.weight_at(sp.tex);
        let [a, b] = &*self.nested;
        let (sa, sb) = (a.sharp_share(wo, sp), b.sharp_share(wo, sp));
        if sa.is_none() && sb.is_none() {
            return None;
        }
        Some(sa.unwrap_or(0.0) * (1.0 - w) + sb.unwrap_or(0.0) * w)
    }

    /// (1 − w)·p₀ + w·p₁.
    pub fn pdf(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint) -> f32 {
        let w = self.weight_at(sp.tex);
        let [a, b] = &*self.nested;
        let mut p = 0.0;
        if w < 1.0 {
            p += a.pdf(wo, wi, sp) * (1.0 - w);
        }
        if w > 0.0 {
            p += b.pdf(wo, wi, sp) * w;
        }
        p
    }

    /// Picks a model (the second with probability w, reusing `u_lobe` rescaled), samples it;
    /// non-delta samples are weighted against the whole blend.
    pub fn sample(
        &self,
        wo: Vec3,
        sp: &ShadingPoint,
        u_lobe: f32,
        u: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let w = self.weight_at(sp.tex);
        let [a, b] = &*self.nested;
        let (chosen, p_choice, u_lobe) = if u_lobe < w {
            (b, w, u_lobe / w)
        } else {
            (a, 1.0 - w, (u_lobe - w) / (1.0 - w))
        };
        let s = chosen.sample(wo, sp, u_lobe.min(ONE_MINUS_EPSILON), u, mode)?;
        if s.delta {
            return Some(BsdfSample {
                pdf: s.pdf * p_choice,
                ..s
            });
        }
        let pdf = self.pdf(wo, s.wi, sp);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let f = self.eval(wo, s.wi, sp, mode);
        Some(BsdfSample {
            weight: f * (s.wi.z.abs() / pdf),
            pdf,
            ..s
        })
    }

    /// Probability of a delta sample: (1 − w)·d₀ + w·d₁.
    pub fn delta_probability(&self, wo: Vec3, sp: &ShadingPoint) -> f32 {
        let w = self.weight_at(sp.tex);
        let [a, b] = &*self.nested;
        a.delta_probability(wo, sp) * (1.0 - w) + b.delta_probability(wo, sp) * w
    }
}
