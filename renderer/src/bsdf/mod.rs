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
//!   `wi.z <= 0`, as in Mitsuba; `twosided` mirrors the frame for the back side.

use crate::texture::Texture;

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
    pub eta: crate::spectrum::Rgb,
    /// Imaginary part k (absorption).
    pub k: crate::spectrum::Rgb,
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

/// `roughplastic`: diffuse base under a rough dielectric coating.
#[derive(Debug, Clone)]
pub struct RoughPlastic {
    /// `distribution`, `alpha` (defaults: beckmann, 0.1; isotropic).
    pub roughness: Roughness,
    /// Relative index of refraction of the coating (default 1.49 / 1.000277).
    pub eta: f32,
    /// `diffuse_reflectance` (default 0.5).
    pub diffuse_reflectance: Texture,
    /// `specular_reflectance` multiplier (default 1).
    pub specular_reflectance: Texture,
    /// `nonlinear` (default false).
    pub nonlinear: bool,
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
    /// `twosided`: `front` on the front side, `back` (default: the same model) on the back.
    TwoSided {
        /// Model for the side the normal points to.
        front: Box<Bsdf>,
        /// Model for the other side.
        back: Box<Bsdf>,
    },
}
