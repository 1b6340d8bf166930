//! `principledthin`: Mitsuba 3's thin principled BSDF (Burley 2015's thin-surface variant of
//! the Disney model), term by term as Mitsuba 3.9.1 evaluates, samples and weights it.
//!
//! A sheet without thickness: both sides look the same (the model folds the viewer to the
//! front), light passes without bending (η only shapes the Fresnel terms and the roughness of
//! transmission), and nothing is refracted, so both transport modes evaluate alike.
//!
//! Parameters, in the XML's words (defaults as Mitsuba's):
//! - `base_color` (colour or texture, 0.5): the diffuse colour and the tint of both
//!   transmission lobes;
//! - `roughness` (float or texture, 0.5): GGX α = roughness² of the specular reflection;
//!   the specular transmission's is ((0.65·η − 0.35)·roughness)² (Burley 2015, Fig. 15);
//! - `anisotropic` (float or texture, 0): α_u = r²/a, α_v = r²·a with a = √(1 − 0.9·anisotropic);
//! - `spec_trans` (float or texture, 0): share of the specular part — GGX reflection weighted by
//!   the dielectric Fresnel and GGX transmission by its complement; without it (or as the
//!   float 0) the sheet has **no** specular lobe at all, as in Mitsuba;
//! - `eta` (float or texture, 1.5): the sheet's relative IOR;
//! - `spec_tint` (float or texture, 0): share of the specular reflection's Fresnel replaced by
//!   a Schlick term tinted towards the base colour's hue;
//! - `sheen` (float or texture, 0), `sheen_tint` (float or texture, 0): a grazing-angle term;
//! - `flatness` (float or texture, 0): blends the diffuse term towards Hanrahan–Krueger's
//!   fake subsurface term;
//! - `diff_trans` (float or texture in [0, 2], 0): how much of the diffuse part is transmitted
//!   (0 none, 1 half, 2 all);
//! - `diffuse_reflectance_sampling_rate`, `specular_reflectance_sampling_rate`,
//!   `specular_transmittance_sampling_rate`, `diffuse_transmittance_sampling_rate` (all 1):
//!   relative rates of the four sampling strategies.
//!
//! As in Mitsuba, a lobe parameter given as the float 0 switches its lobe off (which only
//! changes the sampling probabilities); scalar parameters given as colour textures are read by
//! luminance. The retro-reflection and sheen terms can return more than they receive, exactly
//! as Mitsuba's do.

use super::fresnel::{fresnel_dielectric, reflect_about};
use super::microfacet::MicrofacetDistribution;
use super::principled::{
    alphas, lerp, r0_of_eta, scalar_at, scalar_mean, schlick, schlick_weight, tint_colour,
};
use super::{BsdfSample, Lobe, MicrofacetKind, Roughness};
use crate::sampling::square_to_cosine_hemisphere;
use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// The parameters of a [`PrincipledThin`] model, as the XML names them; a lobe given as the
/// float 0 (or not at all) is `None`.
#[derive(Debug, Clone)]
pub struct PrincipledThinParams {
    /// `base_color`.
    pub base_color: Texture,
    /// `roughness`.
    pub roughness: Texture,
    /// `anisotropic`.
    pub anisotropic: Option<Texture>,
    /// `spec_trans`.
    pub spec_trans: Option<Texture>,
    /// `eta`.
    pub eta: Texture,
    /// `spec_tint`.
    pub spec_tint: Option<Texture>,
    /// `sheen`.
    pub sheen: Option<Texture>,
    /// `sheen_tint`.
    pub sheen_tint: Option<Texture>,
    /// `flatness`.
    pub flatness: Option<Texture>,
    /// `diff_trans` (in [0, 2]).
    pub diff_trans: Option<Texture>,
    /// `diffuse_reflectance_sampling_rate`.
    pub diffuse_reflectance_sampling_rate: f32,
    /// `specular_reflectance_sampling_rate`.
    pub specular_reflectance_sampling_rate: f32,
    /// `specular_transmittance_sampling_rate`.
    pub specular_transmittance_sampling_rate: f32,
    /// `diffuse_transmittance_sampling_rate`.
    pub diffuse_transmittance_sampling_rate: f32,
}

impl Default for PrincipledThinParams {
    /// Mitsuba's defaults: a grey diffuse sheet of roughness 0.5 and η = 1.5.
    fn default() -> Self {
        let grey = |v: f32| Texture::Constant(Rgb::splat(v));
        Self {
            base_color: grey(0.5),
            roughness: grey(0.5),
            anisotropic: None,
            spec_trans: None,
            eta: grey(1.5),
            spec_tint: None,
            sheen: None,
            sheen_tint: None,
            flatness: None,
            diff_trans: None,
            diffuse_reflectance_sampling_rate: 1.0,
            specular_reflectance_sampling_rate: 1.0,
            specular_transmittance_sampling_rate: 1.0,
            diffuse_transmittance_sampling_rate: 1.0,
        }
    }
}

/// `principledthin`: built by [`PrincipledThin::new`], which classifies the model for SPPM once.
#[derive(Debug, Clone)]
pub struct PrincipledThin {
    /// Boxed: the parameters are large, and every [`super::Bsdf`] is as large as its largest
    /// variant.
    params: Box<PrincipledThinParams>,
    /// SPPM class, from the textures' means.
    lobe: Lobe,
}

/// The parameters read at one surface point (`diff_trans` already halved to [0, 1]).
struct Local {
    base_color: Rgb,
    roughness: f32,
    anisotropic: f32,
    spec_trans: f32,
    eta: f32,
    spec_tint: f32,
    sheen: f32,
    sheen_tint: f32,
    flatness: f32,
    diff_trans: f32,
}

/// Normalised probabilities of the four sampling strategies.
struct Strategies {
    spec_reflect: f32,
    spec_trans: f32,
    diffuse_reflect: f32,
    diffuse_trans: f32,
}

/// Whether microfacet `m` joins the front-folded viewer `v` and direction `w`: both on its
/// front for reflection; `w` behind it for transmission (Mitsuba's `mac_mic_compatibility`).
fn compatible(m: Vec3, v: Vec3, w: Vec3, reflection: bool) -> bool {
    let side = if reflection { 1.0 } else { -1.0 };
    v.dot(m) > 0.0 && side * w.dot(m) > 0.0
}

/// The GGX distribution of roughness `roughness` (α = roughness², see [`alphas`]).
fn ggx(roughness: f32, anisotropic: f32, has_anisotropic: bool) -> MicrofacetDistribution {
    let (alpha_u, alpha_v) = alphas(roughness, anisotropic, has_anisotropic);
    MicrofacetDistribution::new(&Roughness {
        kind: MicrofacetKind::Ggx,
        alpha_u,
        alpha_v,
    })
}

/// The transmission lobe's roughness, scaled by IOR (Burley 2015, Fig. 15).
fn transmission_roughness(l: &Local) -> f32 {
    (0.65 * l.eta - 0.35) * l.roughness
}

/// The viewer `wo` and direction `wi` folded so that the viewer is on the front side (the sheet
/// is the same from both), with the half vector of `wi` mirrored to the front: (v, w, wh).
/// `None` for a grazing viewer or a degenerate half vector.
fn fold(wo: Vec3, wi: Vec3) -> Option<(Vec3, Vec3, Vec3)> {
    if wo.z == 0.0 {
        return None;
    }
    let s = wo.z.signum();
    let (v, w) = (wo * s, wi * s);
    let h = v + Vec3::new(w.x, w.y, w.z.abs());
    let len = h.length();
    (len > 0.0 && len.is_finite()).then(|| (v, w, h / len))
}

impl PrincipledThin {
    /// The model for `params`, with its SPPM class computed from the textures' means.
    pub fn new(params: PrincipledThinParams) -> Self {
        let lobe = classify(&params);
        Self {
            params: Box::new(params),
            lobe,
        }
    }

    /// The parameters the model was built from.
    pub fn params(&self) -> &PrincipledThinParams {
        &self.params
    }

    /// Whether light passes the sheet through a non-delta lobe (`spec_trans` or `diff_trans`
    /// given): photons on its other side then count.
    pub fn transmits(&self) -> bool {
        self.params.spec_trans.is_some() || self.params.diff_trans.is_some()
    }

    /// How SPPM treats the surface: [`Lobe::Diffuse`] when it has a broad part (every diffuse,
    /// sheen and diffuse-transmission term is weighted by 1 − spec_trans), otherwise the class
    /// of the rougher of its two specular lobes.
    pub fn lobe(&self) -> Lobe {
        self.lobe
    }

    /// The G-buffer albedo: `base_color` (Mitsuba's `eval_diffuse_reflectance`).
    pub fn albedo(&self, tp: TexPoint) -> Rgb {
        self.params.base_color.eval(tp)
    }

    fn at(&self, tp: TexPoint) -> Local {
        let p = &self.params;
        Local {
            base_color: p.base_color.eval(tp),
            roughness: p.roughness.eval_1(tp),
            anisotropic: scalar_at(&p.anisotropic, tp),
            spec_trans: scalar_at(&p.spec_trans, tp),
            eta: p.eta.eval_1(tp),
            spec_tint: scalar_at(&p.spec_tint, tp),
            sheen: scalar_at(&p.sheen, tp),
            sheen_tint: scalar_at(&p.sheen_tint, tp),
            flatness: scalar_at(&p.flatness, tp),
            diff_trans: scalar_at(&p.diff_trans, tp) / 2.0,
        }
    }

    /// The specular reflection's and transmission's distributions at `l`.
    fn distributions(&self, l: &Local) -> (MicrofacetDistribution, MicrofacetDistribution) {
        let aniso = self.params.anisotropic.is_some();
        (
            ggx(l.roughness, l.anisotropic, aniso),
            ggx(transmission_roughness(l), l.anisotropic, aniso),
        )
    }

    /// The four strategies' probabilities; `None` if none can be sampled.
    fn strategies(&self, l: &Local) -> Option<Strategies> {
        let p = &self.params;
        let (spec_reflect, spec_trans) = if p.spec_trans.is_some() {
            (
                l.spec_trans * p.specular_reflectance_sampling_rate / 2.0,
                l.spec_trans * p.specular_transmittance_sampling_rate / 2.0,
            )
        } else {
            (0.0, 0.0)
        };
        let diffuse_reflect =
            p.diffuse_reflectance_sampling_rate * (1.0 - l.spec_trans) * (1.0 - l.diff_trans);
        let diffuse_trans = if p.diff_trans.is_some() {
            p.diffuse_transmittance_sampling_rate * (1.0 - l.spec_trans) * l.diff_trans
        } else {
            0.0
        };
        let total = spec_reflect + spec_trans + diffuse_reflect + diffuse_trans;
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        Some(Strategies {
            spec_reflect: spec_reflect / total,
            spec_trans: spec_trans / total,
            diffuse_reflect: diffuse_reflect / total,
            diffuse_trans: diffuse_trans / total,
        })
    }

    /// Whether the specular reflection and transmission lobes are sharp (α below
    /// [`super::SHARP_ALPHA_THRESHOLD`]) at `l`.
    fn sharp_lobes(&self, l: &Local) -> (bool, bool) {
        if self.params.spec_trans.is_none() {
            return (false, false);
        }
        let aniso = self.params.anisotropic.is_some();
        let sharp = |r: f32| {
            let (au, av) = alphas(r, l.anisotropic, aniso);
            au.max(av) < super::SHARP_ALPHA_THRESHOLD
        };
        (sharp(l.roughness), sharp(transmission_roughness(l)))
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> Rgb {
        self.eval_parts(wo, wi, tp, false).0
    }

    /// (broad, sharp): the specular lobes count as sharp where their α is below
    /// [`super::SHARP_ALPHA_THRESHOLD`] (see `Bsdf::eval_split`).
    pub(super) fn eval_split(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> (Rgb, Rgb) {
        self.eval_parts(wo, wi, tp, true)
    }

    /// The sampling share of the sharp lobes (see `Bsdf::sharp_share`); `None` without one.
    pub(super) fn sharp_share(&self, wo: Vec3, tp: TexPoint) -> Option<f32> {
        if wo.z == 0.0 {
            return None;
        }
        let l = self.at(tp);
        let (reflect, trans) = self.sharp_lobes(&l);
        if !reflect && !trans {
            return None;
        }
        let Some(s) = self.strategies(&l) else {
            return Some(0.0);
        };
        Some(if reflect { s.spec_reflect } else { 0.0 } + if trans { s.spec_trans } else { 0.0 })
    }

    /// The value without the cosine, its terms summed into (broad, sharp): everything broad
    /// unless `split` (see [`PrincipledThin::sharp_lobes`]).
    fn eval_parts(&self, wo: Vec3, wi: Vec3, tp: TexPoint, split: bool) -> (Rgb, Rgb) {
        let zero = (Rgb::ZERO, Rgb::ZERO);
        let Some((v, w, wh)) = fold(wo, wi) else {
            return zero;
        };
        let (cos_i, cos_o) = (v.z, w.z);
        let (reflect, refract) = (cos_o > 0.0, cos_o < 0.0);
        if !reflect && !refract {
            return zero;
        }
        let l = self.at(tp);
        let p = &self.params;
        let (reflect_sharp, trans_sharp) = if split {
            self.sharp_lobes(&l)
        } else {
            (false, false)
        };
        let (mut value, mut sharp) = (Rgb::ZERO, Rgb::ZERO);
        let cos_abs = cos_i * cos_o.abs();

        if p.spec_trans.is_some() && l.spec_trans > 0.0 {
            let cos_ih = v.dot(wh);
            let f_dielectric = fresnel_dielectric(cos_ih, l.eta).r;
            let (distr_r, distr_t) = self.distributions(&l);
            if reflect && compatible(wh, v, w, true) {
                let f_schlick = if p.spec_tint.is_some() {
                    schlick(tint_colour(l.base_color) * r0_of_eta(l.eta), cos_ih, l.eta)
                } else {
                    Rgb::ZERO
                };
                // Dr.Jit's lerp(F_dielectric, F_schlick, spec_tint).
                let f_thin =
                    Rgb::splat(f_dielectric - f_dielectric * l.spec_tint) + f_schlick * l.spec_tint;
                let dg = distr_r.eval(wh) * distr_r.g(v, w, wh);
                let term = f_thin * (l.spec_trans * dg / (4.0 * cos_abs));
                if reflect_sharp {
                    sharp += term;
                } else {
                    value += term;
                }
            }
            if refract && compatible(wh, v, w, false) {
                let dg = distr_t.eval(wh) * distr_t.g(v, w, wh);
                let term =
                    l.base_color * (l.spec_trans * (1.0 - f_dielectric) * dg / (4.0 * cos_abs));
                if trans_sharp {
                    sharp += term;
                } else {
                    value += term;
                }
            }
        }

        if reflect && l.spec_trans < 1.0 && l.diff_trans < 1.0 {
            let f_o = schlick_weight(cos_o.abs());
            let f_i = schlick_weight(cos_i);
            let f_diff = (1.0 - 0.5 * f_i) * (1.0 - 0.5 * f_o);
            let cos_d = wh.dot(w);
            let rr = 2.0 * l.roughness * cos_d * cos_d;
            let f_retro = rr * (f_o + f_i + f_o * f_i * (rr - 1.0));
            let shape = if p.flatness.is_some() {
                let fss90 = rr / 2.0;
                let fss = lerp(1.0, fss90, f_o) * lerp(1.0, fss90, f_i);
                let f_ss = 1.25 * (fss * (1.0 / (cos_o.abs() + cos_i) - 0.5) + 0.5);
                lerp(f_diff + f_retro, f_ss, l.flatness)
            } else {
                f_diff + f_retro
            };
            let share = (1.0 - l.spec_trans) * (1.0 - l.diff_trans);
            value += l.base_color * (share * FRAC_1_PI * shape);
            if p.sheen.is_some() && l.sheen > 0.0 {
                let f_d = schlick_weight(cos_d.abs());
                let tint = if p.sheen_tint.is_some() {
                    let c = tint_colour(l.base_color);
                    Rgb::ONE - Rgb::ONE * l.sheen_tint + c * l.sheen_tint
                } else {
                    Rgb::ONE
                };
                value += tint * (l.sheen * share * f_d);
            }
        }

        if refract && p.diff_trans.is_some() && l.spec_trans < 1.0 && l.diff_trans > 0.0 {
            value += l.base_color * ((1.0 - l.spec_trans) * l.diff_trans * FRAC_1_PI);
        }
        (value, sharp)
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> f32 {
        let Some((v, w, wh)) = fold(wo, wi) else {
            return 0.0;
        };
        let (reflect, refract) = (w.z > 0.0, w.z < 0.0);
        let l = self.at(tp);
        let Some(s) = self.strategies(&l) else {
            return 0.0;
        };
        let mut pdf = 0.0;
        if self.params.spec_trans.is_some() {
            // The transmitted direction is the reflection mirrored through the sheet: the same
            // Jacobian 1/(4 |w_r·h|) with w_r = w mirrored to the front.
            let w_r = Vec3::new(w.x, w.y, w.z.abs());
            let dwh_dwi = (1.0 / (4.0 * w_r.dot(wh))).abs();
            let (distr_r, distr_t) = self.distributions(&l);
            if reflect && compatible(wh, v, w, true) {
                pdf += s.spec_reflect * distr_r.pdf(v, wh) * dwh_dwi;
            }
            if refract && compatible(wh, v, w, false) {
                pdf += s.spec_trans * distr_t.pdf(v, wh) * dwh_dwi;
            }
        }
        if reflect {
            pdf += s.diffuse_reflect * w.z * FRAC_1_PI;
        }
        if refract && self.params.diff_trans.is_some() {
            pdf += s.diffuse_trans * -w.z * FRAC_1_PI;
        }
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }

    pub(super) fn sample(
        &self,
        wo: Vec3,
        tp: TexPoint,
        u_lobe: f32,
        u: Vec2,
    ) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let side = wo.z.signum();
        let v = wo * side;
        let l = self.at(tp);
        let s = self.strategies(&l)?;
        let (distr_r, distr_t) = self.distributions(&l);
        let w = if u_lobe < s.spec_reflect {
            let (m, _) = distr_r.sample(v, u);
            let w = reflect_about(v, m);
            if !(compatible(m, v, w, true) && w.z > 0.0) {
                return None;
            }
            w
        } else if u_lobe < s.spec_reflect + s.spec_trans {
            // Reflect on a microfacet of the scaled distribution, then pass to the other side.
            let (m, _) = distr_t.sample(v, u);
            let r = reflect_about(v, m);
            let w = Vec3::new(r.x, r.y, -r.z);
            if !(compatible(m, v, w, false) && w.z < 0.0) {
                return None;
            }
            w
        } else if u_lobe < s.spec_reflect + s.spec_trans + s.diffuse_reflect {
            square_to_cosine_hemisphere(u)
        } else if self.params.diff_trans.is_some() {
            -square_to_cosine_hemisphere(u)
        } else {
            return None;
        };
        let wi = w * side;
        let pdf = self.pdf(wo, wi, tp);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let weight = self.eval(wo, wi, tp) * (wi.z.abs() / pdf);
        Some(BsdfSample {
            wi,
            weight,
            pdf,
            delta: false,
            eta: 1.0,
        })
    }
}

/// The SPPM class of `params` (see [`PrincipledThin::lobe`]).
fn classify(params: &PrincipledThinParams) -> Lobe {
    let spec_trans = scalar_mean(&params.spec_trans);
    if 1.0 - spec_trans > 0.0 {
        return Lobe::Diffuse;
    }
    let roughness = params.roughness.mean_1();
    let anisotropic = scalar_mean(&params.anisotropic);
    let has_aniso = params.anisotropic.is_some();
    let eta = params.eta.mean_1();
    let widest = [roughness, (0.65 * eta - 0.35) * roughness]
        .into_iter()
        .map(|r| {
            let (au, av) = alphas(r, anisotropic, has_aniso);
            au.max(av)
        })
        .fold(0.0f32, f32::max);
    if widest < super::GLOSSY_ALPHA_THRESHOLD {
        Lobe::Glossy
    } else {
        Lobe::Diffuse
    }
}
