//! Light sources (Mitsuba 3's emitters): area lights attached to shapes (front side only),
//! point, spot, projector, directional, constant-environment and environment-map lights, each with
//! - `sample_li`: a direction towards the light from a reference point, for next-event estimation,
//! - `pdf_li`: the solid-angle density of that strategy, for MIS with BSDF sampling,
//! - `sample_emission`: a ray leaving the light with its flux weight, for photon tracing,
//! - `power`: the emitted power, used to select lights proportionally to it,
//! - `bounds`: what bounds its emission ([`bounds`]), for choosing lights by what they can
//!   deliver to a point ([`selection`]).
//!
//! Densities and weights returned here do NOT include the light-selection probability; the
//! scene ([`crate::scene::Scene`]) folds that in.

pub mod area;
pub mod bounds;
pub mod constant;
pub mod directional;
pub mod emitter_tree;
pub mod envmap;
pub mod focus;
pub mod point;
pub mod projector;
pub mod selection;
pub mod spot;

pub use area::AreaLight;
pub use constant::ConstantLight;
pub use directional::DirectionalLight;
pub use envmap::{EnvmapError, EnvmapLight};
pub use focus::PhotonFocus;
pub use point::PointLight;
pub use projector::ProjectorLight;
pub use spot::SpotLight;

use crate::math::{coordinate_system, Ray};
use crate::sampling::square_to_uniform_disk_concentric;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// Bounding sphere of the scene, used by infinite lights to emit photons over it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneSphere {
    /// Centre.
    pub center: Vec3,
    /// Radius (> 0).
    pub radius: f32,
}

impl SceneSphere {
    /// Where a photon from infinity travelling along `d` (unit) starts: a point uniform (by
    /// `u`) on the disk of the sphere's radius that faces `d`, one radius behind the centre, so
    /// every such ray crosses the sphere with density 1/(πR²).
    pub fn photon_origin(&self, d: Vec3, u: Vec2) -> Vec3 {
        let (s, t) = coordinate_system(d);
        let q = square_to_uniform_disk_concentric(u) * self.radius;
        self.center - d * self.radius + s * q.x + t * q.y
    }
}

/// A direction sampled towards a light from a reference point.
#[derive(Debug, Clone, Copy)]
pub struct LightSample {
    /// Unit direction from the reference point towards the light.
    pub wi: Vec3,
    /// Point on the light (far away along `wi` for infinite lights; see [`Self::infinite`]).
    pub p: Vec3,
    /// Distance to `p` (+∞ for infinite lights).
    pub dist: f32,
    /// Radiance (area/environment) or intensity/irradiance-based contribution divided by `pdf`:
    /// the incident radiance estimate to multiply by f·|cos θ|.
    pub weight: Rgb,
    /// Solid-angle density of `wi` including the light-selection probability once the scene
    /// returns it; for delta lights the selection probability alone.
    pub pdf: f32,
    /// The light is a delta light (point, spot, directional): no MIS possible.
    pub delta: bool,
    /// The light is at infinity (shadow rays are unbounded).
    pub infinite: bool,
    /// Index of the light in the scene.
    pub light: u32,
}

/// A photon leaving a light.
#[derive(Debug, Clone, Copy)]
pub struct EmissionSample {
    /// The photon ray (origin already offset off emitting surfaces).
    pub ray: Ray,
    /// Flux carried by the photon: emitted power density divided by the sampling densities
    /// (including the light-selection probability once the scene returns it).
    pub flux: Rgb,
    /// Index of the light in the scene.
    pub light: u32,
}

/// One light of the scene.
#[derive(Debug, Clone)]
pub enum Light {
    /// Emission from the front side of a shape.
    Area(AreaLight),
    /// Isotropic point light.
    Point(PointLight),
    /// Spot light with Mitsuba's linear angular falloff.
    Spot(SpotLight),
    /// A pinhole projecting an image.
    Projector(ProjectorLight),
    /// Distant light.
    Directional(DirectionalLight),
    /// Uniform environment.
    Constant(ConstantLight),
    /// Environment from a latitude–longitude image (boxed: it owns the image and its tables).
    Envmap(Box<EnvmapLight>),
}

impl Light {
    /// Whether the light is at infinity (directional, constant, environment map): its power is
    /// measured through the whole scene's bounding disk.
    pub fn is_infinite(&self) -> bool {
        matches!(
            self,
            Light::Directional(_) | Light::Constant(_) | Light::Envmap(_)
        )
    }

    /// Whether the light is a collimated area light (`directionalarea`): it emits along its
    /// surface normals only, so next-event estimation and rays hitting it find nothing and only
    /// photons carry its light.
    pub fn is_collimated(&self) -> bool {
        matches!(self, Light::Area(a) if a.collimated)
    }

    /// Whether the light is a delta light (cannot be hit by rays).
    pub fn is_delta(&self) -> bool {
        matches!(
            self,
            Light::Point(_) | Light::Spot(_) | Light::Projector(_) | Light::Directional(_)
        )
    }
}

/// Mean of the three channels: the scalar used for power-proportional selection (luminance would
/// ignore blue lights almost entirely).
#[inline]
pub fn channel_mean(c: Rgb) -> f32 {
    (c.x + c.y + c.z) / 3.0
}

/// A red and blue Mitsuba checkerboard (2×2 cells over the unit square: red where u and v fall
/// in the same half, blue elsewhere), for the projected-image tests of spots and projectors.
#[cfg(test)]
pub(crate) fn test_checker() -> crate::texture::Texture {
    crate::texture::Texture::Checkerboard {
        color0: Rgb::new(1.0, 0.0, 0.0),
        color1: Rgb::new(0.0, 0.0, 1.0),
        to_uv: glam::Mat3::IDENTITY,
    }
}
