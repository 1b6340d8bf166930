//! `principled`: Mitsuba 3's Disney-style principled BSDF (Burley 2012, 2015), term by term as
//! Mitsuba 3.9.1 evaluates, samples and weights it.
//!
//! Parameters, in the XML's words (defaults as Mitsuba's):
//! - `base_color` (colour or texture, 0.5): the diffuse colour, the metal's colour, the tint of
//!   transmission (√base_color) and of `spec_tint`/`sheen_tint`;
//! - `roughness` (float or texture, 0.5): GGX α = roughness² of the main specular lobes
//!   (reflection and transmission), at least 0.001;
//! - `anisotropic` (float or texture, 0): α_u = roughness²/a, α_v = roughness²·a with
//!   a = √(1 − 0.9·anisotropic);
//! - `metallic` (float or texture, 0): share of the Schlick metal (F₀ = base_color);
//! - `spec_trans` (float or texture, 0): share of the rough dielectric transmission lobe in the
//!   non-metallic part;
//! - `eta` (float) or `specular` (float, 0.5), not both: the relative IOR of the dielectric
//!   lobes, or Disney's `specular` with η = 2 / (1 − √(0.08·specular)) − 1; when `spec_trans`
//!   is given, η = 1 becomes 1.001 and specular = 0 becomes 0.001, as in Mitsuba;
//! - `spec_tint` (float or texture, 0): share of the dielectric reflection tinted towards the
//!   base colour's hue (Schlick);
//! - `sheen` (float or texture, 0) and `sheen_tint` (float or texture, 0): a grazing-angle
//!   reflection term, optionally tinted;
//! - `flatness` (float or texture, 0): blends the diffuse term towards Hanrahan–Krueger's fake
//!   subsurface term;
//! - `clearcoat` (float or texture, 0) and `clearcoat_gloss` (float or texture, 0): a second,
//!   isotropic GTR1 reflection lobe with α = lerp(0.1, 0.001, clearcoat_gloss) and a Schlick
//!   Fresnel of F₀ = 0.04;
//! - `diffuse_reflectance_sampling_rate` (1), `main_specular_sampling_rate` (1),
//!   `clearcoat_sampling_rate` (1; Mitsuba's documentation says 0, but its code and the
//!   installed 3.9.1 use 1): relative rates of the sampling strategies.
//!
//! The XML importer requires the scalar parameters in [0, 1] (Mitsuba's documentation asks
//! for it; outside it lobe weights turn negative), `base_color` non-negative, `eta` positive
//! and the sampling rates non-negative.
//!
//! Scalar parameters given as colour textures are read by luminance (Mitsuba's `eval_1`). As in
//! Mitsuba, a parameter given as the float 0 switches its lobe off entirely, which differs from
//! a lobe at weight 0 in two places only: the η adjustment above, and the back side's sampling
//! probabilities of a model with `spec_trans`.
//!
//! Behaviour of Mitsuba 3.9.1 kept on purpose (it is what its `llvm_ad_rgb` variant, the one
//! the references are rendered with, computes):
//! - the clearcoat term is clearcoat/4 · F·D·G without the 1/(4 cos θi cos θo) of a
//!   microfacet model, and its masking uses a fixed GGX α of 0.25;
//! - sheen is added wherever it is non-zero on the front side, also where the diffuse weight
//!   (1 − metallic)(1 − spec_trans) is zero (the scalar variants skip it there; the vectorised
//!   ones, whose branches are masks, add it);
//! - sampling picks a strategy with probabilities proportional, from the front, to
//!   (1 − metallic)(1 − spec_trans)·diffuse rate (cosine hemisphere), clearcoat/4·clearcoat
//!   rate (GTR1 normals), and the main rate split by the sampled microfacet's Fresnel F into
//!   (1 − bsdf·(1 − F)) for reflection and bsdf·(1 − F) for transmission (GGX visible
//!   normals), with bsdf = (1 − metallic)·spec_trans; from the back, F and 1 − F. The sample's
//!   pdf and weight are those of the whole model (`pdf`, `eval`), as in Mitsuba;
//! - refraction scales radiance by 1/η² (radiance transport) and not importance.
//!
//! Reflection is reciprocal on each side and transmission is adjoint between the transport
//! modes, but the model does not conserve energy: its retro-reflection, sheen and clearcoat
//! terms can return more than they receive, exactly as Mitsuba's do (tests).

use super::fresnel::{fresnel_dielectric, reflect_about, refract_about};
use super::microfacet::MicrofacetDistribution;
use super::{BsdfSample, Lobe, MicrofacetKind, Roughness, TransportMode};
use crate::sampling::square_to_cosine_hemisphere;
use crate::spectrum::{luminance, Rgb};
use crate::texture::{TexPoint, Texture};
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// How the dielectric lobes' index of refraction was given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PrincipledIor {
    /// `eta`: the relative IOR (interior / exterior).
    Eta(f32),
    /// `specular`: Disney's specular amount in [0, 1] (0.5 is η = 1.5).
    Specular(f32),
}

/// The parameters of a [`Principled`] model, as the XML names them; a lobe given as the float 0
/// (or not at all) is `None` (see the module note).
#[derive(Debug, Clone)]
pub struct PrincipledParams {
    /// `base_color`.
    pub base_color: Texture,
    /// `roughness`.
    pub roughness: Texture,
    /// `anisotropic`.
    pub anisotropic: Option<Texture>,
    /// `metallic`.
    pub metallic: Option<Texture>,
    /// `spec_trans`.
    pub spec_trans: Option<Texture>,
    /// `eta` or `specular`.
    pub ior: PrincipledIor,
    /// `spec_tint`.
    pub spec_tint: Option<Texture>,
    /// `sheen`.
    pub sheen: Option<Texture>,
    /// `sheen_tint`.
    pub sheen_tint: Option<Texture>,
    /// `flatness`.
    pub flatness: Option<Texture>,
    /// `clearcoat`.
    pub clearcoat: Option<Texture>,
    /// `clearcoat_gloss`.
    pub clearcoat_gloss: Texture,
    /// `diffuse_reflectance_sampling_rate`.
    pub diffuse_reflectance_sampling_rate: f32,
    /// `main_specular_sampling_rate`.
    pub main_specular_sampling_rate: f32,
    /// `clearcoat_sampling_rate`.
    pub clearcoat_sampling_rate: f32,
}

impl Default for PrincipledParams {
    /// Mitsuba's defaults: a grey dielectric-coated diffuse of roughness 0.5 and η = 1.5.
    fn default() -> Self {
        let grey = |v: f32| Texture::Constant(Rgb::splat(v));
        Self {
            base_color: grey(0.5),
            roughness: grey(0.5),
            anisotropic: None,
            metallic: None,
            spec_trans: None,
            ior: PrincipledIor::Specular(0.5),
            spec_tint: None,
            sheen: None,
            sheen_tint: None,
            flatness: None,
            clearcoat: None,
            clearcoat_gloss: grey(0.0),
            diffuse_reflectance_sampling_rate: 1.0,
            main_specular_sampling_rate: 1.0,
            clearcoat_sampling_rate: 1.0,
        }
    }
}

/// `principled`: built by [`Principled::new`], which resolves η and classifies the model for
/// SPPM once.
#[derive(Debug, Clone)]
pub struct Principled {
    /// Boxed: the parameters are large, and every [`super::Bsdf`] is as large as its largest
    /// variant.
    params: Box<PrincipledParams>,
    /// Relative IOR of the dielectric lobes, after Mitsuba's adjustments.
    eta: f32,
    /// SPPM class, from the textures' means (computed once: a bitmap's mean visits every texel).
    lobe: Lobe,
}

/// The parameters read at one surface point.
struct Local {
    base_color: Rgb,
    roughness: f32,
    anisotropic: f32,
    metallic: f32,
    spec_trans: f32,
    spec_tint: f32,
    sheen: f32,
    sheen_tint: f32,
    flatness: f32,
    clearcoat: f32,
    clearcoat_gloss: f32,
}

impl Local {
    /// Weight of the diffuse (and retro-reflection, fake subsurface) part.
    fn brdf(&self) -> f32 {
        (1.0 - self.metallic) * (1.0 - self.spec_trans)
    }

    /// Weight of the transmission part.
    fn bsdf(&self) -> f32 {
        (1.0 - self.metallic) * self.spec_trans
    }
}

/// Normalised probabilities of the four sampling strategies for one side and Fresnel value.
struct Strategies {
    diffuse: f32,
    clearcoat: f32,
    transmission: f32,
    reflection: f32,
}

/// 5th power Schlick weight (1 − cos)⁵ with the cosine clamped to [0, 1].
pub(super) fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// a + (b − a)·t, in the same operation order as Dr.Jit's `lerp`.
pub(super) fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a - a * t + b * t
}

/// Schlick's Fresnel with reflectance `r0` at normal incidence for the cosine `cos_i` against
/// the microfacet normal, through an interface of relative IOR `eta`: from the denser side the
/// transmitted cosine drives the weight (0 beyond the critical angle: total reflection).
pub(super) fn schlick(r0: Rgb, cos_i: f32, eta: f32) -> Rgb {
    let (eta_it, eta_ti) = if cos_i >= 0.0 {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    let w = if eta_it > 1.0 {
        schlick_weight(cos_i.abs())
    } else {
        let cos_t_sqr = 1.0 - (1.0 - cos_i * cos_i) * (eta_ti * eta_ti);
        schlick_weight(cos_t_sqr.max(0.0).sqrt())
    };
    Rgb::splat(w) * (Rgb::ONE - r0) + r0
}

/// Normal-incidence reflectance ((η − 1)/(η + 1))².
pub(super) fn r0_of_eta(eta: f32) -> f32 {
    let r = (eta - 1.0) / (eta + 1.0);
    r * r
}

/// Whether the microfacet `m` can carry light between `wo` and `wi` (for reflection both on
/// the side of `m` that faces `wo`'s hemisphere; for refraction `wi` on the other side).
fn microfacet_compatible(m: Vec3, wo: Vec3, wi: Vec3, reflection: bool) -> bool {
    let m = if wo.z < 0.0 { -m } else { m };
    let side = if reflection { 1.0 } else { -1.0 };
    wo.dot(m) > 0.0 && side * wi.dot(m) > 0.0
}

/// Smith's G1 for an isotropic GGX of roughness `alpha` (the clearcoat's masking).
fn smith_ggx1(v: Vec3, m: Vec3, alpha: f32) -> f32 {
    if v.dot(m) * v.z <= 0.0 {
        return 0.0;
    }
    if v.z == 1.0 {
        return 1.0;
    }
    let c2 = v.z * v.z;
    let tan2 = (1.0 - c2) / c2;
    2.0 / (1.0 + (1.0 + alpha * alpha * tan2).sqrt())
}

/// Burley's GTR1 distribution (the clearcoat's), normalised by projected area.
#[derive(Debug, Clone, Copy)]
struct Gtr1 {
    alpha: f32,
}

impl Gtr1 {
    fn eval(&self, m: Vec3) -> f32 {
        let a2 = self.alpha * self.alpha;
        let d = (a2 - 1.0) / (PI * a2.ln() * (1.0 + (a2 - 1.0) * m.z * m.z));
        if d * m.z > 1e-20 {
            d
        } else {
            0.0
        }
    }

    /// Density of [`Gtr1::sample`] (D(m)·cos θm: whole normals, not visible ones).
    fn pdf(&self, m: Vec3) -> f32 {
        if m.z < 0.0 {
            0.0
        } else {
            m.z * self.eval(m)
        }
    }

    fn sample(&self, u: Vec2) -> Vec3 {
        let (sin_phi, cos_phi) = (2.0 * PI * u.x).sin_cos();
        let a2 = self.alpha * self.alpha;
        let cos2 = (1.0 - a2.powf(1.0 - u.y)) / (1.0 - a2);
        let sin_t = (1.0 - cos2).max(0.0).sqrt();
        let cos_t = cos2.max(0.0).sqrt();
        Vec3::new(cos_phi * sin_t, sin_phi * sin_t, cos_t)
    }
}

/// η from Disney's `specular` (s = 0.08·F₀ with F₀ = ((η − 1)/(η + 1))²), in f32 as Mitsuba.
pub fn eta_from_specular(specular: f32) -> f32 {
    2.0 / (1.0 - (0.08 * specular).sqrt()) - 1.0
}

/// Reads a lobe parameter at `tp`, 0 when the lobe is off.
pub(super) fn scalar_at(t: &Option<Texture>, tp: TexPoint) -> f32 {
    t.as_ref().map_or(0.0, |t| t.eval_1(tp))
}

/// A lobe parameter's mean (for the SPPM class), 0 when the lobe is off.
pub(super) fn scalar_mean(t: &Option<Texture>) -> f32 {
    t.as_ref().map_or(0.0, Texture::mean_1)
}

/// Main-lobe roughness (α_u, α_v) from `roughness` and `anisotropic`, as Disney's notes map them.
pub(super) fn alphas(roughness: f32, anisotropic: f32, has_anisotropic: bool) -> (f32, f32) {
    let r2 = roughness * roughness;
    if !has_anisotropic {
        let a = r2.max(0.001);
        return (a, a);
    }
    let aspect = (1.0 - 0.9 * anisotropic).sqrt();
    ((r2 / aspect).max(0.001), (r2 * aspect).max(0.001))
}

impl Principled {
    /// The model for `params`: η resolved (with Mitsuba's nudges away from index matching when
    /// there is transmission) and the SPPM class computed from the textures' means.
    pub fn new(params: PrincipledParams) -> Self {
        let has_trans = params.spec_trans.is_some();
        let eta = match params.ior {
            PrincipledIor::Eta(eta) if has_trans && eta == 1.0 => 1.001,
            PrincipledIor::Eta(eta) => eta,
            PrincipledIor::Specular(s) if has_trans && s == 0.0 => eta_from_specular(1e-3),
            PrincipledIor::Specular(s) => eta_from_specular(s),
        };
        let lobe = classify(&params);
        Self {
            params: Box::new(params),
            eta,
            lobe,
        }
    }

    /// The parameters the model was built from.
    pub fn params(&self) -> &PrincipledParams {
        &self.params
    }

    /// Whether the model has a transmission lobe (`spec_trans` given and not the float 0).
    pub fn transmits(&self) -> bool {
        self.params.spec_trans.is_some()
    }

    /// Relative IOR of the dielectric lobes (after the adjustments of [`Principled::new`]).
    pub fn eta(&self) -> f32 {
        self.eta
    }

    /// How SPPM treats the surface: [`Lobe::Diffuse`] when it has a broad part (a diffuse or
    /// sheen weight), otherwise the class of the main specular lobe's roughness (the clearcoat,
    /// α ≤ 0.1, is always narrow).
    pub fn lobe(&self) -> Lobe {
        self.lobe
    }

    /// The G-buffer albedo: `base_color`. It is the diffuse colour and equally the metal's
    /// colour at normal incidence (Schlick F₀ = base_color), so no rule depends on `metallic`;
    /// Mitsuba's `eval_diffuse_reflectance` returns the same.
    pub fn albedo(&self, tp: TexPoint) -> Rgb {
        self.params.base_color.eval(tp)
    }

    fn at(&self, tp: TexPoint) -> Local {
        let p = &self.params;
        Local {
            base_color: p.base_color.eval(tp),
            roughness: p.roughness.eval_1(tp),
            anisotropic: scalar_at(&p.anisotropic, tp),
            metallic: scalar_at(&p.metallic, tp),
            spec_trans: scalar_at(&p.spec_trans, tp),
            spec_tint: scalar_at(&p.spec_tint, tp),
            sheen: scalar_at(&p.sheen, tp),
            sheen_tint: scalar_at(&p.sheen_tint, tp),
            flatness: scalar_at(&p.flatness, tp),
            clearcoat: scalar_at(&p.clearcoat, tp),
            clearcoat_gloss: p.clearcoat_gloss.eval_1(tp),
        }
    }

    fn distribution(&self, l: &Local) -> MicrofacetDistribution {
        let (alpha_u, alpha_v) = alphas(
            l.roughness,
            l.anisotropic,
            self.params.anisotropic.is_some(),
        );
        MicrofacetDistribution::new(&Roughness {
            kind: MicrofacetKind::Ggx,
            alpha_u,
            alpha_v,
        })
    }

    fn clearcoat_distribution(l: &Local) -> Gtr1 {
        Gtr1 {
            alpha: lerp(0.1, 0.001, l.clearcoat_gloss),
        }
    }

    /// The sampling strategies' probabilities for a viewer on the `front` side, given the
    /// dielectric Fresnel reflectance `f` of the microfacet involved; `None` if none can be
    /// sampled. From inside only the dielectric lobes are sampled, by Fresnel.
    fn strategies(&self, l: &Local, front: bool, f: f32) -> Option<Strategies> {
        let p = &self.params;
        let bsdf = l.bsdf();
        let has_trans = p.spec_trans.is_some();
        let (reflection, transmission, clearcoat, diffuse) = if front {
            let rate = p.main_specular_sampling_rate;
            (
                rate * (1.0 - bsdf * (1.0 - f)),
                if has_trans {
                    rate * bsdf * (1.0 - f)
                } else {
                    0.0
                },
                if p.clearcoat.is_some() {
                    0.25 * l.clearcoat * p.clearcoat_sampling_rate
                } else {
                    0.0
                },
                l.brdf() * p.diffuse_reflectance_sampling_rate,
            )
        } else {
            (f, if has_trans { 1.0 - f } else { 0.0 }, 0.0, 0.0)
        };
        let total = reflection + transmission + clearcoat + diffuse;
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        Some(Strategies {
            diffuse: diffuse / total,
            clearcoat: clearcoat / total,
            transmission: transmission / total,
            reflection: reflection / total,
        })
    }

    /// The main lobes' Fresnel factor for reflection: on the front side the dielectric
    /// Fresnel, partly replaced by Schlick metal and tinted-dielectric terms; on the back side
    /// the transmission weight times the dielectric Fresnel.
    fn main_fresnel(&self, l: &Local, f_dielectric: f32, cos_i: f32, front: bool) -> Rgb {
        if !front {
            return Rgb::splat(l.bsdf() * f_dielectric);
        }
        let p = &self.params;
        let mut f = Rgb::splat((1.0 - l.metallic) * (1.0 - l.spec_tint) * f_dielectric);
        if p.metallic.is_some() {
            f += l.metallic * schlick(l.base_color, cos_i, self.eta);
        }
        if p.spec_tint.is_some() {
            let eta_it = if cos_i >= 0.0 {
                self.eta
            } else {
                1.0 / self.eta
            };
            let r0 = tint_colour(l.base_color) * r0_of_eta(eta_it);
            f += (1.0 - l.metallic) * l.spec_tint * schlick(r0, cos_i, self.eta);
        }
        f
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, tp: TexPoint, mode: TransportMode) -> Rgb {
        self.eval_parts(wo, wi, tp, mode, false).0
    }

    /// (broad, sharp) in radiance mode: the main specular lobes and the clearcoat count as
    /// sharp where their α is below [`super::SHARP_ALPHA_THRESHOLD`] (see `Bsdf::eval_split`).
    pub(super) fn eval_split(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> (Rgb, Rgb) {
        self.eval_parts(wo, wi, tp, TransportMode::Radiance, true)
    }

    /// Whether the main lobes and the clearcoat are sharp at `l`.
    fn sharp_lobes(&self, l: &Local) -> (bool, bool) {
        let (alpha_u, alpha_v) = alphas(
            l.roughness,
            l.anisotropic,
            self.params.anisotropic.is_some(),
        );
        let main = alpha_u.max(alpha_v) < super::SHARP_ALPHA_THRESHOLD;
        let clearcoat = self.params.clearcoat.is_some()
            && l.clearcoat > 0.0
            && Self::clearcoat_distribution(l).alpha < super::SHARP_ALPHA_THRESHOLD;
        (main, clearcoat)
    }

    /// The sampling share of the sharp lobes for viewer `wo` (see `Bsdf::sharp_share`), taken
    /// at the Fresnel reflectance of the normal; `None` without a sharp lobe.
    pub(super) fn sharp_share(&self, wo: Vec3, tp: TexPoint) -> Option<f32> {
        if wo.z == 0.0 {
            return None;
        }
        let l = self.at(tp);
        let (main, clearcoat) = self.sharp_lobes(&l);
        if !main && !clearcoat {
            return None;
        }
        let f = fresnel_dielectric(wo.z.abs(), self.eta).r;
        let Some(s) = self.strategies(&l, wo.z > 0.0, f) else {
            return Some(0.0);
        };
        let mut share = 0.0;
        if main {
            share += s.reflection + s.transmission;
        }
        if clearcoat {
            share += s.clearcoat;
        }
        Some(share)
    }

    /// The value, its terms summed into (broad, sharp): everything broad unless `split`, else
    /// the sharp lobes (see [`Principled::sharp_lobes`]) into the second.
    fn eval_parts(
        &self,
        wo: Vec3,
        wi: Vec3,
        tp: TexPoint,
        mode: TransportMode,
        split: bool,
    ) -> (Rgb, Rgb) {
        let (cos_o, cos_i) = (wo.z, wi.z);
        if cos_o == 0.0 {
            return (Rgb::ZERO, Rgb::ZERO);
        }
        let reflect = cos_o * cos_i > 0.0;
        let refract = cos_o * cos_i < 0.0;
        if !reflect && !refract {
            return (Rgb::ZERO, Rgb::ZERO);
        }
        let l = self.at(tp);
        let (main_sharp, clearcoat_sharp) = if split {
            self.sharp_lobes(&l)
        } else {
            (false, false)
        };
        let mut sharp = Rgb::ZERO;
        let p = &self.params;
        let (brdf, bsdf) = (l.brdf(), l.bsdf());
        let front = cos_o > 0.0;
        let eta_path = if front { self.eta } else { 1.0 / self.eta };
        let Some(wh) = half_vector(wo, wi, if reflect { 1.0 } else { eta_path }) else {
            return (Rgb::ZERO, Rgb::ZERO);
        };
        let fresnel = fresnel_dielectric(wo.dot(wh), self.eta);
        let f_dielectric = fresnel.r;
        let reflection_ok = reflect && microfacet_compatible(wh, wo, wi, true);
        let refraction_ok = refract && microfacet_compatible(wh, wo, wi, false);
        let distr = self.distribution(&l);
        let d = distr.eval(wh);
        let g = distr.g(wo, wi, wh);
        let mut value = Rgb::ZERO;

        if reflection_ok && f_dielectric > 0.0 {
            let f = self.main_fresnel(&l, f_dielectric, wo.dot(wh), front);
            let term = f * (d * g / (4.0 * (cos_o * cos_i).abs()));
            if main_sharp {
                sharp += term;
            } else {
                value += term;
            }
        }

        if refraction_ok && p.spec_trans.is_some() && bsdf > 0.0 && f_dielectric < 1.0 {
            let scale = match mode {
                TransportMode::Radiance => 1.0 / (eta_path * eta_path),
                TransportMode::Importance => 1.0,
            };
            let (o_h, i_h) = (wo.dot(wh), wi.dot(wh));
            let denom = o_h + eta_path * i_h;
            let t = scale * (1.0 - f_dielectric) * d * g * eta_path * eta_path * o_h * i_h
                / (cos_o * denom * denom);
            let term = sqrt_rgb(l.base_color) * (bsdf * t.abs() / cos_i.abs());
            if main_sharp {
                sharp += term;
            } else {
                value += term;
            }
        }

        if reflection_ok && front && p.clearcoat.is_some() && l.clearcoat > 0.0 {
            let f_cc = schlick(Rgb::splat(0.04), wo.dot(wh), self.eta).x;
            let d_cc = Self::clearcoat_distribution(&l).eval(wh);
            let g_cc = smith_ggx1(wo, wh, 0.25) * smith_ggx1(wi, wh, 0.25);
            let term = Rgb::splat(l.clearcoat * 0.25 * f_cc * d_cc * g_cc);
            if clearcoat_sharp {
                sharp += term;
            } else {
                value += term;
            }
        }

        if reflect && front {
            let f_o = schlick_weight(cos_i.abs());
            let f_i = schlick_weight(cos_o.abs());
            let cos_d = wh.dot(wi);
            if brdf > 0.0 {
                let f_diff = (1.0 - 0.5 * f_i) * (1.0 - 0.5 * f_o);
                let rr = 2.0 * l.roughness * cos_d * cos_d;
                let f_retro = rr * (f_o + f_i + f_o * f_i * (rr - 1.0));
                let shape = if p.flatness.is_some() {
                    let fss90 = rr / 2.0;
                    let fss = lerp(1.0, fss90, f_o) * lerp(1.0, fss90, f_i);
                    let f_ss = 1.25 * (fss * (1.0 / (cos_o.abs() + cos_i.abs()) - 0.5) + 0.5);
                    lerp(f_diff + f_retro, f_ss, l.flatness)
                } else {
                    f_diff + f_retro
                };
                value += l.base_color * (brdf * FRAC_1_PI * shape);
            }
            // Not gated by the diffuse weight: see the module note.
            if p.sheen.is_some() && l.sheen > 0.0 && 1.0 - l.metallic > 0.0 {
                let f_d = schlick_weight(cos_d.abs());
                let tint = if p.sheen_tint.is_some() {
                    let c = tint_colour(l.base_color);
                    Rgb::ONE - Rgb::ONE * l.sheen_tint + c * l.sheen_tint
                } else {
                    Rgb::ONE
                };
                value += tint * (l.sheen * (1.0 - l.metallic) * f_d);
            }
        }
        (value, sharp)
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3, tp: TexPoint) -> f32 {
        let (cos_o, cos_i) = (wo.z, wi.z);
        if cos_o == 0.0 {
            return 0.0;
        }
        let reflect = cos_o * cos_i > 0.0;
        let refract = cos_o * cos_i < 0.0;
        if !reflect && !refract {
            return 0.0;
        }
        let l = self.at(tp);
        let p = &self.params;
        let front = cos_o > 0.0;
        let eta_path = if front { self.eta } else { 1.0 / self.eta };
        let Some(wh) = half_vector(wo, wi, if reflect { 1.0 } else { eta_path }) else {
            return 0.0;
        };
        let f = fresnel_dielectric(wo.dot(wh), self.eta).r;
        let Some(s) = self.strategies(&l, front, f) else {
            return 0.0;
        };
        let (o_h, i_h) = (wo.dot(wh), wi.dot(wh));
        let dwh_dwi = if reflect {
            1.0 / (4.0 * i_h)
        } else {
            let denom = o_h + eta_path * i_h;
            eta_path * eta_path * i_h / (denom * denom)
        }
        .abs();
        let distr = self.distribution(&l);
        let wo_up = if front { wo } else { -wo };
        let mut pdf = 0.0;
        if reflect {
            if microfacet_compatible(wh, wo, wi, true) {
                pdf += s.reflection * distr.pdf(wo_up, wh) * dwh_dwi;
                if p.clearcoat.is_some() {
                    pdf += s.clearcoat * Self::clearcoat_distribution(&l).pdf(wh) * dwh_dwi;
                }
            }
            pdf += s.diffuse * cos_i * FRAC_1_PI;
        } else if p.spec_trans.is_some() && microfacet_compatible(wh, wo, wi, false) {
            pdf += s.transmission * distr.pdf(wo_up, wh) * dwh_dwi;
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
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let cos_o = wo.z;
        if cos_o == 0.0 {
            return None;
        }
        let l = self.at(tp);
        let front = cos_o > 0.0;
        // From inside only transmission-capable models scatter.
        if !front && l.bsdf() <= 0.0 {
            return None;
        }
        let wo_up = if front { wo } else { -wo };
        let (m, _) = self.distribution(&l).sample(wo_up, u);
        let fresnel = fresnel_dielectric(wo.dot(m), self.eta);
        let s = self.strategies(&l, front, fresnel.r)?;
        let (wi, eta) = if u_lobe < s.diffuse {
            let wi = square_to_cosine_hemisphere(u);
            if wi.z <= 0.0 {
                return None;
            }
            (wi, 1.0)
        } else if u_lobe < s.diffuse + s.clearcoat {
            let m_cc = Self::clearcoat_distribution(&l).sample(u);
            let wi = reflect_about(wo, m_cc);
            if !(cos_o * wi.z > 0.0 && microfacet_compatible(m_cc, wo, wi, true)) {
                return None;
            }
            (wi, 1.0)
        } else if u_lobe < s.diffuse + s.clearcoat + s.transmission {
            let wi = refract_about(wo, m, fresnel.cos_theta_t, fresnel.eta_ti);
            if !(cos_o * wi.z < 0.0 && microfacet_compatible(m, wo, wi, false)) {
                return None;
            }
            (wi, fresnel.eta_it)
        } else {
            let wi = reflect_about(wo, m);
            if !(cos_o * wi.z > 0.0 && microfacet_compatible(m, wo, wi, true)) {
                return None;
            }
            (wi, 1.0)
        };
        let pdf = self.pdf(wo, wi, tp);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let weight = self.eval(wo, wi, tp, mode) * (wi.z.abs() / pdf);
        Some(BsdfSample {
            wi,
            weight,
            pdf,
            delta: false,
            eta,
        })
    }
}

/// The base colour normalised by its luminance (its hue), white for black.
pub(super) fn tint_colour(base: Rgb) -> Rgb {
    let lum = luminance(base);
    if lum > 0.0 {
        base / lum
    } else {
        Rgb::ONE
    }
}

fn sqrt_rgb(c: Rgb) -> Rgb {
    Rgb::new(c.x.sqrt(), c.y.sqrt(), c.z.sqrt())
}

/// The (generalised) half vector wo + k·wi, normalised and turned to +z; `None` if degenerate.
fn half_vector(wo: Vec3, wi: Vec3, k: f32) -> Option<Vec3> {
    let h = wo + wi * k;
    let len2 = h.length_squared();
    if len2.is_nan() || len2 <= 0.0 || len2.is_infinite() {
        return None;
    }
    let h = h / len2.sqrt();
    Some(if h.z < 0.0 { -h } else { h })
}

/// The SPPM class of `params` (see [`Principled::lobe`]).
fn classify(params: &PrincipledParams) -> Lobe {
    let metallic = scalar_mean(&params.metallic);
    let spec_trans = scalar_mean(&params.spec_trans);
    let broad_diffuse = (1.0 - metallic) * (1.0 - spec_trans) > 0.0;
    let broad_sheen = scalar_mean(&params.sheen) > 0.0 && 1.0 - metallic > 0.0;
    if broad_diffuse || broad_sheen {
        return Lobe::Diffuse;
    }
    let (au, av) = alphas(
        params.roughness.mean_1(),
        scalar_mean(&params.anisotropic),
        params.anisotropic.is_some(),
    );
    if au.max(av) < super::GLOSSY_ALPHA_THRESHOLD {
        Lobe::Glossy
    } else {
        Lobe::Diffuse
    }
}
