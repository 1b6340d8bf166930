//! Surface scattering models (Mitsuba 3's BSDF plugins), one file per plugin.
//!
//! Conventions shared by every BSDF (the contract the integrators rely on):
//! - directions are in the local shading frame: +z is the shading normal, `wo` (towards the
//!   viewer / where light leaves) and `wi` (towards the light / sampled) both point away from
//!   the surface;
//! - [`Bsdf::eval`] returns the BSDF value f(wo, wi) **without** the cosine factor and is zero
//!   for delta (specular) components; [`Bsdf::pdf`] is the solid-angle density with which
//!   [`Bsdf::sample`] produces `wi` through its non-delta components (lobe selection included);
//! - [`BsdfSample::weight`] is f·|cos θi| / pdf (for a delta lobe: the full throughput of that
//!   lobe divided by the probability of having chosen it);
//! - one-sided models (diffuse, conductors, plastics) are black when `wo.z <= 0` or
//!   `wi.z <= 0`, as in Mitsuba; `twosided` mirrors the frame for the back side;
//! - for a delta sample, [`BsdfSample::pdf`] is the probability of having chosen that lobe (as
//!   Mitsuba's `bs.pdf`), not a density: never use it for MIS;
//! - `sample` returns `None` where Mitsuba returns a zero-weight sample (the path ends).
//!
//! Everything follows Mitsuba 3's plugins (`src/bsdfs/*.cpp`) term by term; the rough models
//! always use visible-normal sampling (Mitsuba's default `sample_visible = true`).

mod blend;
mod bumpmap;
mod conductor;
mod dielectric;
mod diffuse;
pub mod fresnel;
mod mask;
pub mod microfacet;
mod normalmap;
mod perturbed;
mod plastic;
mod principled;
mod principledthin;
mod roughconductor;
mod roughdielectric;
mod roughplastic;
mod thindielectric;

#[cfg(test)]
mod tests;

use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use glam::{Vec2, Vec3};

pub use blend::Blend;
pub use bumpmap::BumpMap;
pub use mask::Mask;
pub use normalmap::NormalMap;
pub use perturbed::TiltedModel;
pub use principled::{Principled, PrincipledIor, PrincipledParams};
pub use principledthin::{PrincipledThin, PrincipledThinParams};

/// Roughness below which a rough conductor/dielectric counts as [`Lobe::Glossy`] (the larger of
/// `alpha_u`, `alpha_v` is compared): SPPM continues eye paths through such surfaces instead of
/// storing a visible point, because a photon-density estimate on a sharp lobe is very noisy.
pub const GLOSSY_ALPHA_THRESHOLD: f32 = 0.25;

/// Roughness below which a lobe of a model SPPM classifies [`Lobe::Diffuse`] (because of its
/// broad parts) counts as *sharp* — a near-mirror: the eye path follows it
/// ([`Bsdf::sharp_share`], [`Bsdf::eval_split`]) because a photon density estimate can hardly
/// resolve it. Broader glossy lobes stay with the photons: splitting every lobe below
/// [`GLOSSY_ALPHA_THRESHOLD`] was measured to make the smooth levels of glossy-floored rooms
/// (α 0.07–0.13) 12–55 % worse (docs/sppm.md).
pub const SHARP_ALPHA_THRESHOLD: f32 = 0.01;

/// Where a BSDF is evaluated: the texture coordinates and the surface's differential geometry
/// there, in the local shading frame (what Mitsuba's BSDFs read from their
/// `SurfaceInteraction`). Only `bumpmap` reads the geometry; every other model reads `tex`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadingPoint {
    /// Where textures are looked up: uv, and the triangle and barycentrics that
    /// `mesh_attribute` textures interpolate.
    pub tex: TexPoint,
    /// ∂p/∂u in the shading frame (world length per unit of u; Mitsuba's `dp_du`).
    pub dpdu: Vec3,
    /// ∂p/∂v in the shading frame (Mitsuba's `dp_dv`).
    pub dpdv: Vec3,
    /// The unit geometric normal in the shading frame.
    pub ng: Vec3,
}

impl ShadingPoint {
    /// The point at `uv` of a flat surface parameterised along its shading frame:
    /// ∂p/∂u = +x, ∂p/∂v = +y, geometric normal +z.
    pub const fn flat(uv: Vec2) -> Self {
        Self {
            tex: TexPoint::at_uv(uv),
            dpdu: Vec3::X,
            dpdv: Vec3::Y,
            ng: Vec3::Z,
        }
    }

    /// The same point seen from a tilted frame (`frame`, given in this point's shading frame):
    /// what a model nested in a normal or bump map reads.
    pub fn in_frame(&self, frame: &crate::frame::Frame) -> Self {
        Self {
            tex: self.tex,
            dpdu: frame.to_local(self.dpdu),
            dpdv: frame.to_local(self.dpdv),
            ng: frame.to_local(self.ng),
        }
    }
}

/// A direction sampled from a BSDF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BsdfSample {
    /// Sampled direction (local frame), pointing away from the surface.
    pub wi: Vec3,
    /// f·|cos θi| / pdf (delta lobes: throughput / lobe probability).
    pub weight: Rgb,
    /// Solid-angle density of `wi` (delta lobes: the lobe's selection probability).
    pub pdf: f32,
    /// Whether the sample came from a delta (specular) lobe.
    pub delta: bool,
    /// Relative IOR crossed by the sample (1 for reflection), for Russian roulette.
    pub eta: f32,
}

impl BsdfSample {
    /// Whether the sample passes straight through the surface (`wi = −wo` exactly: a mask's
    /// pass-through, a thin dielectric's transmission — Mitsuba's "null" interactions), so
    /// that what lies beyond is seen as if the surface were not there.
    #[inline]
    pub fn passes_through(&self, wo: Vec3) -> bool {
        self.delta && self.wi == -wo
    }
}

/// How an SPPM eye path treats a surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lobe {
    /// Only specular components: the eye path must continue.
    Delta,
    /// Narrow glossy lobes (α < [`GLOSSY_ALPHA_THRESHOLD`]): the eye path continues.
    Glossy,
    /// Broad lobes: the eye path stops and a visible point is stored.
    Diffuse,
}

/// Which quantity a path carries: radiance from the camera, or importance/flux from lights.
/// Refraction scales radiance by 1/η² but not flux, so photon tracing passes `Importance`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TransportMode {
    /// Camera paths.
    Radiance,
    /// Light (photon) paths.
    Importance,
}

/// Microfacet normal distribution (Mitsuba's `distribution` parameter).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MicrofacetKind {
    /// Beckmann (Mitsuba's default).
    Beckmann,
    /// Trowbridge–Reitz / GGX.
    Ggx,
}

/// Microfacet roughness parameters shared by the rough plugins.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Roughness {
    /// The distribution.
    pub kind: MicrofacetKind,
    /// Roughness along the tangent (Mitsuba `alpha_u`, or `alpha`).
    pub alpha_u: f32,
    /// Roughness along the bitangent (Mitsuba `alpha_v`, or `alpha`).
    pub alpha_v: f32,
}

/// Complex index of refraction of a conductor, per RGB channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConductorIor {
    /// Real part η.
    pub eta: Rgb,
    /// Imaginary part k (absorption).
    pub k: Rgb,
}

/// `diffuse`: Lambertian reflection.
#[derive(Debug, Clone)]
pub struct Diffuse {
    /// `reflectance` (default 0.5).
    pub reflectance: Texture,
}

/// `conductor`: smooth metal mirror.
#[derive(Debug, Clone)]
pub struct Conductor {
    /// `material`/`eta`/`k`; `None` is Mitsuba's `material="none"`, a perfect mirror.
    pub ior: Option<ConductorIor>,
    /// `specular_reflectance` multiplier (default 1).
    pub specular_reflectance: Texture,
}

/// `roughconductor`: microfacet metal.
#[derive(Debug, Clone)]
pub struct RoughConductor {
    /// `distribution`, `alpha`/`alpha_u`/`alpha_v` (Mitsuba defaults: beckmann, 0.1).
    pub roughness: Roughness,
    /// `alpha` given as a texture (isotropic): replaces `roughness`'s alphas at each uv, while
    /// `roughness` holds the texture's mean alpha, which classifies the surface for SPPM.
    pub alpha_texture: Option<Texture>,
    /// Complex IOR; `None` is a perfect reflector.
    pub ior: Option<ConductorIor>,
    /// `specular_reflectance` multiplier (default 1).
    pub specular_reflectance: Texture,
}

/// `dielectric`: smooth glass interface.
#[derive(Debug, Clone)]
pub struct Dielectric {
    /// Relative index of refraction `int_ior / ext_ior` (default 1.5046 / 1.000277).
    pub eta: f32,
    /// `specular_reflectance` multiplier (default 1).
    pub specular_reflectance: Texture,
    /// `specular_transmittance` multiplier (default 1).
    pub specular_transmittance: Texture,
}

/// `thindielectric`: a thin glass sheet (no refraction offset, internal bounces summed).
#[derive(Debug, Clone)]
pub struct ThinDielectric {
    /// Relative index of refraction `int_ior / ext_ior`.
    pub eta: f32,
    /// `specular_reflectance` multiplier (default 1).
    pub specular_reflectance: Texture,
    /// `specular_transmittance` multiplier (default 1).
    pub specular_transmittance: Texture,
}

/// `roughdielectric`: microfacet glass interface.
#[derive(Debug, Clone)]
pub struct RoughDielectric {
    /// `distribution`, `alpha`/`alpha_u`/`alpha_v` (defaults: beckmann, 0.1).
    pub roughness: Roughness,
    /// `alpha` given as a texture (isotropic): replaces `roughness`'s alphas at each uv, while
    /// `roughness` holds the texture's mean alpha, which classifies the surface for SPPM.
    pub alpha_texture: Option<Texture>,
    /// Relative index of refraction `int_ior / ext_ior`.
    pub eta: f32,
    /// `specular_reflectance` multiplier (default 1).
    pub specular_reflectance: Texture,
    /// `specular_transmittance` multiplier (default 1).
    pub specular_transmittance: Texture,
}

/// `plastic`: diffuse base under a smooth dielectric coating.
#[derive(Debug, Clone)]
pub struct Plastic {
    /// Relative index of refraction of the coating (default 1.49 / 1.000277).
    pub eta: f32,
    /// `diffuse_reflectance` (default 0.5).
    pub diffuse_reflectance: Texture,
    /// `specular_reflectance` multiplier (default 1).
    pub specular_reflectance: Texture,
    /// `nonlinear` (default false): account for colour shifts from internal scattering.
    pub nonlinear: bool,
}

/// `roughplastic`: diffuse base under a rough dielectric coating. Built by
/// [`RoughPlastic::new`], which precomputes the coating's tables; the coating parameters are
/// therefore read-only.
#[derive(Debug, Clone)]
pub struct RoughPlastic {
    /// `distribution`, `alpha` (defaults: beckmann, 0.1; isotropic).
    roughness: Roughness,
    /// Relative index of refraction of the coating (default 1.49 / 1.000277).
    eta: f32,
    /// `diffuse_reflectance` (default 0.5).
    pub diffuse_reflectance: Texture,
    /// `specular_reflectance` multiplier (default 1).
    pub specular_reflectance: Texture,
    /// `nonlinear` (default false).
    pub nonlinear: bool,
    /// The coating's transmittance table and internal reflectance for (`roughness`, `eta`),
    /// computed when the BSDF is built so that no render pays for them (shared between equal
    /// coatings).
    coating: std::sync::Arc<roughplastic::CoatingTables>,
}

/// A surface scattering model: Mitsuba 3's BSDF plugins.
#[derive(Debug, Clone)]
pub enum Bsdf {
    /// `diffuse`
    Diffuse(Diffuse),
    /// `conductor`
    Conductor(Conductor),
    /// `roughconductor`
    RoughConductor(RoughConductor),
    /// `dielectric`
    Dielectric(Dielectric),
    /// `thindielectric`
    ThinDielectric(ThinDielectric),
    /// `roughdielectric`
    RoughDielectric(RoughDielectric),
    /// `plastic`
    Plastic(Plastic),
    /// `roughplastic`
    RoughPlastic(RoughPlastic),
    /// `principled`: Disney-style layered model (diffuse, metal, rough glass, sheen, clearcoat).
    Principled(Principled),
    /// `principledthin`: the thin-sheet principled model (diffuse, sheen, glossy reflection and
    /// transmission without refraction, diffuse transmission).
    PrincipledThin(PrincipledThin),
    /// `normalmap`: a nested model in a shading frame perturbed by a texture.
    NormalMap(NormalMap),
    /// `bumpmap`: a nested model in a shading frame tilted by a height field's gradient.
    BumpMap(BumpMap),
    /// `blendbsdf`: a linear blend of two models.
    Blend(Blend),
    /// `mask`: a nested model behind an opacity (the rest passes straight through).
    Mask(Mask),
    /// `twosided`: `front` on the front side, `back` (default: the same model) on the back.
    TwoSided {
        /// Model for the side the normal points to.
        front: Box<Bsdf>,
        /// Model for the other side.
        back: Box<Bsdf>,
    },
}

impl Bsdf {
    /// Sample an incident direction `wi` for the outgoing direction `wo` (local frame).
    /// `u_lobe` chooses among components, `u` drives the direction warp.
    pub fn sample(
        &self,
        wo: Vec3,
        sp: &ShadingPoint,
        u_lobe: f32,
        u: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let tp = sp.tex;
        let s = match self {
            Bsdf::Diffuse(b) => b.sample(wo, tp, u),
            Bsdf::Conductor(b) => b.sample(wo, tp),
            Bsdf::RoughConductor(b) => b.sample(wo, tp, u),
            Bsdf::Dielectric(b) => b.sample(wo, tp, u_lobe, mode),
            Bsdf::ThinDielectric(b) => b.sample(wo, tp, u_lobe),
            Bsdf::RoughDielectric(b) => b.sample(wo, tp, u_lobe, u, mode),
            Bsdf::Plastic(b) => b.sample(wo, tp, u_lobe, u),
            Bsdf::RoughPlastic(b) => b.sample(wo, tp, u_lobe, u),
            Bsdf::Principled(b) => b.sample(wo, tp, u_lobe, u, mode),
            Bsdf::PrincipledThin(b) => b.sample(wo, tp, u_lobe, u),
            Bsdf::NormalMap(b) => b.sample(wo, sp, u_lobe, u, mode),
            Bsdf::BumpMap(b) => b.sample(wo, sp, u_lobe, u, mode),
            Bsdf::Blend(b) => b.sample(wo, sp, u_lobe, u, mode),
            Bsdf::Mask(b) => b.sample(wo, sp, u_lobe, u, mode),
            Bsdf::TwoSided { front, back } => {
                if wo.z > 0.0 {
                    front.sample(wo, sp, u_lobe, u, mode)
                } else if wo.z < 0.0 {
                    back.sample(flip(wo), sp, u_lobe, u, mode)
                        .map(|s| BsdfSample {
                            wi: flip(s.wi),
                            ..s
                        })
                } else {
                    None
                }
            }
        }?;
        // A zero-throughput sample ends the path, as Mitsuba's zero weight does.
        (s.weight.max_element() > 0.0 && s.weight.is_finite() && s.pdf > 0.0).then_some(s)
    }

    /// BSDF value f(wo, wi) without the cosine; zero for delta components.
    pub fn eval(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint, mode: TransportMode) -> Rgb {
        let tp = sp.tex;
        match self {
            Bsdf::Diffuse(b) => b.eval(wo, wi, tp),
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) => Rgb::ZERO,
            Bsdf::RoughConductor(b) => b.eval(wo, wi, tp),
            Bsdf::RoughDielectric(b) => b.eval(wo, wi, tp, mode),
            Bsdf::Plastic(b) => b.eval(wo, wi, tp),
            Bsdf::RoughPlastic(b) => b.eval(wo, wi, tp),
            Bsdf::Principled(b) => b.eval(wo, wi, tp, mode),
            // Nothing refracts: both modes evaluate alike, as in Mitsuba.
            Bsdf::PrincipledThin(b) => b.eval(wo, wi, tp),
            Bsdf::NormalMap(b) => b.eval(wo, wi, sp, mode),
            Bsdf::BumpMap(b) => b.eval(wo, wi, sp, mode),
            Bsdf::Blend(b) => b.eval(wo, wi, sp, mode),
            Bsdf::Mask(b) => b.eval(wo, wi, sp, mode),
            Bsdf::TwoSided { front, back } => {
                if wo.z > 0.0 {
                    front.eval(wo, wi, sp, mode)
                } else if wo.z < 0.0 {
                    back.eval(flip(wo), flip(wi), sp, mode)
                } else {
                    Rgb::ZERO
                }
            }
        }
    }

    /// Solid-angle density with which [`Bsdf::sample`] produces `wi` through non-delta lobes.
    pub fn pdf(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint) -> f32 {
        let tp = sp.tex;
        // Lobe-selection weights use texture means, not the local value (as Mitsuba); only a
        // normal or bump map (its frame), a blend (its weight), a mask (its opacity), a textured
        // alpha and the principled model (whose selection weights Mitsuba reads at the point)
        // read `uv`.
        match self {
            Bsdf::Diffuse(b) => b.pdf(wo, wi),
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) => 0.0,
            Bsdf::RoughConductor(b) => b.pdf(wo, wi, tp),
            Bsdf::RoughDielectric(b) => b.pdf(wo, wi, tp),
            Bsdf::Plastic(b) => b.pdf(wo, wi),
            Bsdf::RoughPlastic(b) => b.pdf(wo, wi),
            Bsdf::Principled(b) => b.pdf(wo, wi, tp),
            Bsdf::PrincipledThin(b) => b.pdf(wo, wi, tp),
            Bsdf::NormalMap(b) => b.pdf(wo, wi, sp),
            Bsdf::BumpMap(b) => b.pdf(wo, wi, sp),
            Bsdf::Blend(b) => b.pdf(wo, wi, sp),
            Bsdf::Mask(b) => b.pdf(wo, wi, sp),
            Bsdf::TwoSided { front, back } => {
                if wo.z > 0.0 {
                    front.pdf(wo, wi, sp)
                } else if wo.z < 0.0 {
                    back.pdf(flip(wo), flip(wi), sp)
                } else {
                    0.0
                }
            }
        }
    }

    /// How SPPM treats this surface (for `twosided` with different sides: the less diffuse of
    /// the two, so an eye path never stops on a mirror; see [`Bsdf::lobe_for`]).
    pub fn lobe(&self) -> Lobe {
        match self {
            Bsdf::Diffuse(_) | Bsdf::Plastic(_) | Bsdf::RoughPlastic(_) => Lobe::Diffuse,
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) => Lobe::Delta,
            Bsdf::RoughConductor(b) => rough_lobe(&b.roughness),
            Bsdf::RoughDielectric(b) => rough_lobe(&b.roughness),
            Bsdf::Principled(b) => b.lobe(),
            Bsdf::PrincipledThin(b) => b.lobe(),
            Bsdf::NormalMap(b) => b.nested.lobe(),
            Bsdf::BumpMap(b) => b.nested.lobe(),
            // The most diffuse of the two: a visible point is stored where either model has a
            // broad lobe (delta parts are split off by the eye path, glossy ones go to photons).
            Bsdf::Blend(b) => most_diffuse(b.nested[0].lobe(), b.nested[1].lobe()),
            // The pass-through is split off like a coating (delta_probability).
            Bsdf::Mask(b) => b.nested.lobe(),
            Bsdf::TwoSided { front, back } => {
                let (f, b) = (front.lobe(), back.lobe());
                if lobe_rank(f) <= lobe_rank(b) {
                    f
                } else {
                    b
                }
            }
        }
    }

    /// [`Bsdf::lobe`] for the side `wo` (local frame) is on: resolves `twosided` exactly.
    pub fn lobe_for(&self, wo: Vec3) -> Lobe {
        match self {
            Bsdf::TwoSided { front, back } => {
                if wo.z >= 0.0 {
                    front.lobe_for(wo)
                } else {
                    back.lobe_for(flip(wo))
                }
            }
            // The perturbed normal stays on the viewer's side (or nearly): the side is wo's.
            Bsdf::NormalMap(b) => b.nested.lobe_for(wo),
            Bsdf::BumpMap(b) => b.nested.lobe_for(wo),
            Bsdf::Blend(b) => most_diffuse(b.nested[0].lobe_for(wo), b.nested[1].lobe_for(wo)),
            Bsdf::Mask(b) => b.nested.lobe_for(wo),
            b => b.lobe(),
        }
    }

    /// Probability that [`Bsdf::sample`] picks a delta (specular) lobe for `wo`: 0 for models
    /// without one, 1 for purely specular ones, in between for models mixing both (`plastic`'s
    /// smooth coating over its diffuse base). SPPM eye paths split on it at visible points.
    pub fn delta_probability(&self, wo: Vec3, sp: &ShadingPoint) -> f32 {
        match self {
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) => 1.0,
            Bsdf::Plastic(b) => b.delta_probability(wo),
            Bsdf::NormalMap(b) => b.delta_probability(wo, sp),
            Bsdf::BumpMap(b) => b.delta_probability(wo, sp),
            Bsdf::Blend(b) => b.delta_probability(wo, sp),
            Bsdf::Mask(b) => b.delta_probability(wo, sp),
            Bsdf::TwoSided { front, back } => {
                if wo.z > 0.0 {
                    front.delta_probability(wo, sp)
                } else if wo.z < 0.0 {
                    back.delta_probability(flip(wo), sp)
                } else {
                    0.0
                }
            }
            _ => 0.0,
        }
    }

    /// The radiance-mode value f(wo, wi) split into its broad and its sharp part (lobes with
    /// α < [`SHARP_ALPHA_THRESHOLD`]); the two add up to [`Bsdf::eval`]. Models without a
    /// sharp part return (f, 0).
    pub fn eval_split(&self, wo: Vec3, wi: Vec3, sp: &ShadingPoint) -> (Rgb, Rgb) {
        let tp = sp.tex;
        match self {
            Bsdf::RoughConductor(b) if is_sharp(&b.roughness, &b.alpha_texture, tp) => {
                (Rgb::ZERO, b.eval(wo, wi, tp))
            }
            Bsdf::RoughDielectric(b) if is_sharp(&b.roughness, &b.alpha_texture, tp) => {
                (Rgb::ZERO, b.eval(wo, wi, tp, TransportMode::Radiance))
            }
            Bsdf::RoughPlastic(b) => b.eval_split(wo, wi, tp),
            Bsdf::Principled(b) => b.eval_split(wo, wi, tp),
            Bsdf::PrincipledThin(b) => b.eval_split(wo, wi, tp),
            Bsdf::NormalMap(b) => b.eval_split(wo, wi, sp),
            Bsdf::BumpMap(b) => b.eval_split(wo, wi, sp),
            Bsdf::Blend(b) => b.eval_split(wo, wi, sp),
            Bsdf::Mask(b) => b.eval_split(wo, wi, sp),
            Bsdf::TwoSided { front, back } => {
                if wo.z > 0.0 {
                    front.eval_split(wo, wi, sp)
                } else if wo.z < 0.0 {
                    back.eval_split(flip(wo), flip(wi), sp)
                } else {
                    (Rgb::ZERO, Rgb::ZERO)
                }
            }
            _ => (self.eval(wo, wi, sp, TransportMode::Radiance), Rgb::ZERO),
        }
    }

    /// `None` when the model has no sharp part at this point for viewer `wo` (see
    /// [`Bsdf::eval_split`]); otherwise `Some(s)`, `s` ∈ [0, 1] the share of its sampling
    /// that goes to sharp lobes — how often an SPPM eye path should follow them.
    pub fn sharp_share(&self, wo: Vec3, sp: &ShadingPoint) -> Option<f32> {
        let tp = sp.tex;
        match self {
            Bsdf::RoughConductor(b) if is_sharp(&b.roughness, &b.alpha_texture, tp) => Some(1.0),
            Bsdf::RoughDielectric(b) if is_sharp(&b.roughness, &b.alpha_texture, tp) => Some(1.0),
            Bsdf::RoughPlastic(b) => b.sharp_share(wo),
            Bsdf::Principled(b) => b.sharp_share(wo, tp),
            Bsdf::PrincipledThin(b) => b.sharp_share(wo, tp),
            Bsdf::NormalMap(b) => b.sharp_share(wo, sp),
            Bsdf::BumpMap(b) => b.sharp_share(wo, sp),
            Bsdf::Blend(b) => b.sharp_share(wo, sp),
            Bsdf::Mask(b) => b.nested.sharp_share(wo, sp),
            Bsdf::TwoSided { front, back } => {
                if wo.z > 0.0 {
                    front.sharp_share(wo, sp)
                } else if wo.z < 0.0 {
                    back.sharp_share(flip(wo), sp)
                } else {
                    None
                }
            }
            _ => None,
        }
    }

    /// The shading normal the model works with for viewer `wo`, in the shading frame: +z,
    /// except under a normal or bump map (also inside `twosided`, `mask` or `blendbsdf`: the first
    /// one found), where it is the perturbed normal (Mitsuba's `sh_frame` override), always
    /// oriented to the frame's +z side (a `twosided` back side is not flipped). The G-buffer
    /// records it.
    pub fn shading_normal(&self, wo: Vec3, sp: &ShadingPoint) -> Vec3 {
        match self {
            Bsdf::NormalMap(b) => b.perturbed_normal(wo, sp),
            Bsdf::BumpMap(b) => b.perturbed_normal(wo, sp),
            Bsdf::Mask(b) => b.nested.shading_normal(wo, sp),
            Bsdf::Blend(b) => {
                let (n0, n1) = (
                    b.nested[0].shading_normal(wo, sp),
                    b.nested[1].shading_normal(wo, sp),
                );
                if n0 != Vec3::Z {
                    n0
                } else {
                    n1
                }
            }
            Bsdf::TwoSided { front, back } => {
                if wo.z >= 0.0 {
                    front.shading_normal(wo, sp)
                } else {
                    // The back model's normal is on the back side; the G-buffer reports the
                    // same line oriented like the surface's own frame (+z for a plain model, as
                    // the networks were trained with).
                    -flip(back.shading_normal(flip(wo), sp))
                }
            }
            _ => Vec3::Z,
        }
    }

    /// Whether [`Bsdf::eval`] can be non-zero (next-event estimation is worthwhile).
    pub fn has_non_delta(&self) -> bool {
        match self {
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) => false,
            Bsdf::TwoSided { front, back } => front.has_non_delta() || back.has_non_delta(),
            Bsdf::NormalMap(b) => b.nested.has_non_delta(),
            Bsdf::BumpMap(b) => b.nested.has_non_delta(),
            Bsdf::Blend(b) => b.nested.iter().any(Bsdf::has_non_delta),
            Bsdf::Mask(b) => b.nested.has_non_delta(),
            _ => true,
        }
    }

    /// The fraction of light that passes straight through the surface, for outgoing direction
    /// `wo` (local frame) — Mitsuba's `eval_null_transmission`, what a volumetric path
    /// tracer's shadow ray carries through the surface: a mask's 1 − opacity (plus its nested
    /// model's share), a thin dielectric's transmission, zero for every other model.
    pub fn null_transmission(&self, wo: Vec3, sp: &ShadingPoint) -> Rgb {
        let tp = sp.tex;
        match self {
            Bsdf::ThinDielectric(b) => {
                b.specular_transmittance.eval(tp) * (1.0 - b.slab_reflectance(wo.z))
            }
            Bsdf::Mask(b) => {
                let opacity = b.opacity_at(tp);
                Rgb::ONE - opacity * (Rgb::ONE - b.nested.null_transmission(wo, sp))
            }
            Bsdf::Blend(b) => {
                let w = b.weight_at(tp);
                b.nested[0].null_transmission(wo, sp) * (1.0 - w)
                    + b.nested[1].null_transmission(wo, sp) * w
            }
            // The perturbed frame changes no straight-through share (Mitsuba's normal and bump
            // maps report none; passing it on keeps shadow rays consistent with the paths
            // that sample the nested model's pass-through).
            Bsdf::NormalMap(b) => b.nested.null_transmission(wo, sp),
            Bsdf::BumpMap(b) => b.nested.null_transmission(wo, sp),
            Bsdf::TwoSided { front, back } => {
                if wo.z >= 0.0 {
                    front.null_transmission(wo, sp)
                } else {
                    back.null_transmission(flip(wo), sp)
                }
            }
            _ => Rgb::ZERO,
        }
    }

    /// Mitsuba's `eval_diffuse_reflectance` (the `albedo` AOV) seen from `wo` (shading frame,
    /// towards the viewer): the diffuse reflectance of `diffuse` and the plastics, the base
    /// colour of the principled models, the nested model's through masks and normal or bump
    /// maps, the two models' mix for `blendbsdf`, the side facing the viewer for `twosided`;
    /// for every other model Mitsuba's default, π·f(wo, n) — zero for the delta models.
    pub fn diffuse_reflectance(&self, wo: Vec3, sp: &ShadingPoint) -> Rgb {
        let tp = sp.tex;
        match self {
            Bsdf::Diffuse(b) => b.reflectance.eval(tp),
            Bsdf::Plastic(b) => b.diffuse_reflectance.eval(tp),
            Bsdf::RoughPlastic(b) => b.diffuse_reflectance.eval(tp),
            Bsdf::Principled(b) => b.albedo(tp),
            Bsdf::PrincipledThin(b) => b.albedo(tp),
            Bsdf::NormalMap(b) => b.nested.diffuse_reflectance(wo, sp),
            Bsdf::BumpMap(b) => b.nested.diffuse_reflectance(wo, sp),
            Bsdf::Mask(b) => b.nested.diffuse_reflectance(wo, sp),
            Bsdf::Blend(b) => {
                let w = b.weight_at(tp);
                b.nested[0].diffuse_reflectance(wo, sp) * (1.0 - w)
                    + b.nested[1].diffuse_reflectance(wo, sp) * w
            }
            Bsdf::TwoSided { front, back } => {
                if wo.z >= 0.0 {
                    front.diffuse_reflectance(wo, sp)
                } else {
                    back.diffuse_reflectance(flip(wo), sp)
                }
            }
            Bsdf::Conductor(_)
            | Bsdf::RoughConductor(_)
            | Bsdf::Dielectric(_)
            | Bsdf::ThinDielectric(_)
            | Bsdf::RoughDielectric(_) => {
                self.eval(wo, Vec3::Z, sp, TransportMode::Radiance) * std::f32::consts::PI
            }
        }
    }

    /// Albedo for the G-buffer: the diffuse reflectance of diffuse and plastic models; for
    /// conductors the specular tint times the normal-incidence Fresnel reflectance (the
    /// metal's colour); for dielectrics the transmittance tint; `principled`: its base colour
    /// (diffuse and metal colour alike, see [`Principled::albedo`]); `twosided`: the front side.
    pub fn albedo(&self, sp: &ShadingPoint) -> Rgb {
        let tp = sp.tex;
        match self {
            Bsdf::Diffuse(b) => b.reflectance.eval(tp),
            Bsdf::Plastic(b) => b.diffuse_reflectance.eval(tp),
            Bsdf::RoughPlastic(b) => b.diffuse_reflectance.eval(tp),
            Bsdf::Conductor(b) => {
                b.specular_reflectance.eval(tp) * conductor::conductor_reflectance(&b.ior, 1.0)
            }
            Bsdf::RoughConductor(b) => {
                b.specular_reflectance.eval(tp) * conductor::conductor_reflectance(&b.ior, 1.0)
            }
            Bsdf::Dielectric(b) => b.specular_transmittance.eval(tp),
            Bsdf::ThinDielectric(b) => b.specular_transmittance.eval(tp),
            Bsdf::RoughDielectric(b) => b.specular_transmittance.eval(tp),
            Bsdf::Principled(b) => b.albedo(tp),
            Bsdf::PrincipledThin(b) => b.albedo(tp),
            Bsdf::NormalMap(b) => b.nested.albedo(sp),
            Bsdf::BumpMap(b) => b.nested.albedo(sp),
            Bsdf::Mask(b) => b.nested.albedo(sp),
            Bsdf::Blend(b) => {
                let w = b.weight_at(tp);
                b.nested[0].albedo(sp) * (1.0 - w) + b.nested[1].albedo(sp) * w
            }
            Bsdf::TwoSided { front, .. } => front.albedo(sp),
        }
    }
}

/// The microfacet distribution at `tp`: `roughness`, or the isotropic alpha an `alpha`
/// texture gives there (Mitsuba's `eval_1`).
fn distribution_at(
    roughness: &Roughness,
    alpha_texture: &Option<Texture>,
    tp: TexPoint,
) -> microfacet::MicrofacetDistribution {
    match alpha_texture {
        None => microfacet::MicrofacetDistribution::new(roughness),
        Some(t) => {
            let a = t.eval_1(tp);
            microfacet::MicrofacetDistribution::new(&Roughness {
                kind: roughness.kind,
                alpha_u: a,
                alpha_v: a,
            })
        }
    }
}

/// Whether a rough model's lobe at `tp` is sharp (α below [`SHARP_ALPHA_THRESHOLD`]).
fn is_sharp(roughness: &Roughness, alpha_texture: &Option<Texture>, tp: TexPoint) -> bool {
    let alpha = match alpha_texture {
        None => roughness.alpha_u.max(roughness.alpha_v),
        Some(t) => t.eval_1(tp),
    };
    alpha < SHARP_ALPHA_THRESHOLD
}

/// A BSDF made ready to be evaluated for many light directions with one viewer direction at
/// one shading point — the photon gather, where every photon around a visible point costs an
/// evaluation. What depends only on the point and the viewer is done once: the side a
/// `twosided` model shows, and the tilted frame of a `normalmap` or `bumpmap` (a texture
/// lookup, and for a bump map its gradient, per evaluation otherwise). Its values are exactly
/// [`Bsdf::eval`]'s (radiance mode) and [`Bsdf::eval_split`]'s.
pub struct PointBsdf<'a> {
    /// The viewer direction the model sees (mirrored on a `twosided` model's back face).
    wo: Vec3,
    /// Whether light directions are mirrored too (the back face of a `twosided` model).
    flipped: bool,
    sp: &'a ShadingPoint,
    model: PointModel<'a>,
}

/// What [`PointBsdf`] evaluates.
enum PointModel<'a> {
    /// A `twosided` model seen edge-on: zero.
    Zero,
    /// A model evaluated as it is.
    Plain(&'a Bsdf),
    /// A normal- or bump-mapped model with its frame for this point and viewer.
    Tilted(perturbed::Perturbed<'a>),
}

impl Bsdf {
    /// This model at `sp` for viewer `wo`, ready for many light directions ([`PointBsdf`]).
    pub fn at_point<'a>(&'a self, wo: Vec3, sp: &'a ShadingPoint) -> PointBsdf<'a> {
        let (model, wo, flipped) = match self {
            Bsdf::TwoSided { front, back } => {
                if wo.z > 0.0 {
                    (front.as_ref(), wo, false)
                } else if wo.z < 0.0 {
                    (back.as_ref(), flip(wo), true)
                } else {
                    return PointBsdf {
                        wo,
                        flipped: false,
                        sp,
                        model: PointModel::Zero,
                    };
                }
            }
            _ => (self, wo, false),
        };
        let model = match model {
            Bsdf::NormalMap(b) => PointModel::Tilted(perturbed::perturbed(b, wo, sp)),
            Bsdf::BumpMap(b) => PointModel::Tilted(perturbed::perturbed(b, wo, sp)),
            other => PointModel::Plain(other),
        };
        PointBsdf {
            wo,
            flipped,
            sp,
            model,
        }
    }
}

impl PointBsdf<'_> {
    /// The light direction as the resolved model sees it.
    #[inline]
    fn light(&self, wi: Vec3) -> Vec3 {
        if self.flipped {
            flip(wi)
        } else {
            wi
        }
    }

    /// [`Bsdf::eval`] in radiance mode for light direction `wi`.
    pub fn eval(&self, wi: Vec3) -> Rgb {
        let wi = self.light(wi);
        match &self.model {
            PointModel::Zero => Rgb::ZERO,
            PointModel::Plain(b) => b.eval(self.wo, wi, self.sp, TransportMode::Radiance),
            PointModel::Tilted(p) => p.eval(self.wo, wi, TransportMode::Radiance),
        }
    }

    /// [`Bsdf::eval_split`] for light direction `wi`.
    pub fn eval_split(&self, wi: Vec3) -> (Rgb, Rgb) {
        let wi = self.light(wi);
        match &self.model {
            PointModel::Zero => (Rgb::ZERO, Rgb::ZERO),
            PointModel::Plain(b) => b.eval_split(self.wo, wi, self.sp),
            PointModel::Tilted(p) => p.eval_split(self.wo, wi),
        }
    }
}

/// Mirror a local direction to the other side of the surface (twosided's back face).
#[inline]
fn flip(w: Vec3) -> Vec3 {
    Vec3::new(w.x, w.y, -w.z)
}

/// The class of a rough model, by its larger alpha (a textured alpha's mean: see
/// `alpha_texture`).
fn rough_lobe(r: &Roughness) -> Lobe {
    if r.alpha_u.max(r.alpha_v) < GLOSSY_ALPHA_THRESHOLD {
        Lobe::Glossy
    } else {
        Lobe::Diffuse
    }
}

/// The more diffuse of two lobe classes.
fn most_diffuse(a: Lobe, b: Lobe) -> Lobe {
    if lobe_rank(a) >= lobe_rank(b) {
        a
    } else {
        b
    }
}

fn lobe_rank(l: Lobe) -> u8 {
    match l {
        Lobe::Delta => 0,
        Lobe::Glossy => 1,
        Lobe::Diffuse => 2,
    }
}
