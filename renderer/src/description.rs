//! The scene description: plain data produced by the XML importer (or by code), consumed by
//! [`crate::scene::Scene::build`]. Geometry is already in world space.

use crate::bsdf::Bsdf;
use crate::spectrum::Rgb;
use glam::{Mat3, Mat4, Vec2, Vec3};

/// A triangle mesh in world space.
#[derive(Debug, Clone, Default)]
pub struct TriangleMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (unit length), if any; absent = flat (face) normals.
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex texture coordinates, if any.
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles as vertex indices, counter-clockwise seen from the front (normal) side, or
    /// clockwise when `flipped`.
    pub indices: Vec<[u32; 3]>,
    /// `flip_normals`: the face normals point against the winding. Mitsuba keeps the vertex
    /// order of a flipped mesh and negates its normals, and a mesh without texture
    /// coordinates is parameterised by the vertex order (uv = barycentrics, ∂p/∂u = p₁ − p₀),
    /// so reversing the winding instead would move its textures and tangents.
    pub flipped: bool,
}

/// The geometry of one shape.
#[derive(Debug, Clone)]
pub enum Geometry {
    /// Triangles (`obj`, `ply`, `rectangle`, `cube` are all imported as meshes).
    Mesh(TriangleMesh),
    /// Analytic sphere (`sphere`); `flip_normals` makes its normal point inwards.
    Sphere {
        /// Centre in world space.
        center: Vec3,
        /// Radius in world units.
        radius: f32,
        /// Orientation (object to world, orthogonal): Mitsuba keeps the rotation of a sphere's
        /// `to_world`, and its uv parameterisation (textures) is in the rotated frame.
        rotation: Mat3,
        /// Normals point inwards.
        flip_normals: bool,
    },
    /// Analytic open cylinder (`cylinder`): the unit tube x² + y² = 1, 0 ≤ z ≤ 1, mapped by
    /// `to_world` (which includes p0, p1 and the radius).
    Cylinder {
        /// Object-to-world transform.
        to_world: Mat4,
        /// Normals point inwards.
        flip_normals: bool,
    },
    /// Analytic disk (`disk`): the unit disk in the local z = 0 plane, normal +z, mapped by `to_world`.
    Disk {
        /// Object-to-world transform.
        to_world: Mat4,
        /// Normal points along −z instead.
        flip_normals: bool,
    },
}

/// One shape with its material and, for area lights, its emission.
#[derive(Debug, Clone)]
pub struct ShapeDesc {
    /// The `id` attribute, or a generated name (for error messages and statistics).
    pub name: String,
    /// World-space geometry.
    pub geometry: Geometry,
    /// Index into [`SceneDescription::bsdfs`].
    pub bsdf: usize,
    /// Radiance of a nested `area` emitter, a colour or a texture over the shape's uvs (emits
    /// from the front side only, as Mitsuba).
    pub emission: Option<crate::texture::Texture>,
    /// The nested emitter is a `directionalarea`: its radiance leaves only along the surface
    /// normal (a collimated beam), which only photons can carry.
    pub collimated: bool,
    /// The participating media inside and outside the shape (`interior`, `exterior`).
    pub media: crate::parity::media::MediumInterface,
}

/// A light source that is not attached to a shape.
#[derive(Debug, Clone)]
pub enum EmitterDesc {
    /// `point`: radiant `intensity` (W/sr) at `position`.
    Point {
        /// World position.
        position: Vec3,
        /// Radiant intensity.
        intensity: Rgb,
    },
    /// `spot`: like Mitsuba's, pointing along the local +z of `to_world`.
    Spot {
        /// Object-to-world transform (position and orientation).
        to_world: Mat4,
        /// Radiant intensity at the beam's centre.
        intensity: Rgb,
        /// `cutoff_angle` in degrees (default 20).
        cutoff_angle: f32,
        /// `beam_width` in degrees (default 3/4 of the cutoff angle).
        beam_width: f32,
        /// `texture`: an image projected along the beam (the cutoff cone spans its uv square).
        texture: Option<crate::texture::Texture>,
    },
    /// `projector`: a pinhole at the origin of `to_world` projecting `irradiance` along its +z.
    Projector {
        /// Object-to-world transform (position and orientation).
        to_world: Mat4,
        /// Irradiance on the image plane at unit distance (a colour or an image).
        irradiance: crate::texture::Texture,
        /// `scale`: a factor on the irradiance.
        scale: f32,
        /// Horizontal field of view in degrees (from `fov`, `fov_axis` or `focal_length` and
        /// the image's aspect ratio).
        fov_x: f32,
    },
    /// `directional`: `irradiance` arriving along `direction` (the direction light travels).
    Directional {
        /// Unit direction of propagation.
        direction: Vec3,
        /// Irradiance on a surface facing the light.
        irradiance: Rgb,
    },
    /// `constant`: uniform environment radiance.
    Constant {
        /// Radiance from every direction.
        radiance: Rgb,
    },
    /// `envmap`: environment radiance from a latitude–longitude image.
    Envmap {
        /// The image (linear RGB).
        image: std::sync::Arc<crate::texture::Bitmap>,
        /// Map frame → world (a rotation; Mitsuba's `to_world`).
        to_world: glam::Mat3,
        /// Radiance multiplier.
        scale: f32,
        /// The image file, for error messages.
        filename: std::path::PathBuf,
    },
}

/// How a camera projects the scene onto its film.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Projection {
    /// Rays from one point (or from a thin lens) through the image plane: `fov` applies.
    Perspective,
    /// Parallel rays along local +z from the rectangle x ∈ [−1, 1], y ∈ [−1/aspect, 1/aspect]
    /// of the camera's (scaled) local frame, as Mitsuba's `orthographic`.
    Orthographic,
}

/// Which axis `fov` measures (Mitsuba's `fov_axis`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FovAxis {
    /// Horizontal.
    X,
    /// Vertical.
    Y,
    /// Diagonal.
    Diagonal,
    /// The smaller of the two image axes.
    Smaller,
    /// The larger of the two image axes.
    Larger,
}

/// The camera (`perspective` or `thinlens` sensor) and its film.
#[derive(Debug, Clone)]
pub struct CameraDesc {
    /// Camera-to-world; the camera looks along local +z with +y up (Mitsuba's convention).
    pub to_world: Mat4,
    /// Perspective (`perspective`, `thinlens`) or parallel (`orthographic`) projection.
    pub projection: Projection,
    /// Field of view in degrees.
    pub fov: f32,
    /// Which axis `fov` measures.
    pub fov_axis: FovAxis,
    /// `near_clip` (default 0.01).
    pub near_clip: f32,
    /// `far_clip` (default 10000).
    pub far_clip: f32,
    /// `aperture_radius` (0 for a pinhole, the `perspective` sensor).
    pub aperture_radius: f32,
    /// `focus_distance` (thin lens only).
    pub focus_distance: f32,
    /// Film width in pixels.
    pub width: u32,
    /// Film height in pixels.
    pub height: u32,
    /// The film's reconstruction filter (`<rfilter>`; Mitsuba's default is a Gaussian).
    pub filter: crate::filter::FilterDesc,
    /// The film's `sample_border`: edge pixels also take samples from outside the image.
    pub sample_border: bool,
    /// The film's crop window (`crop_offset_x/y`, `crop_width/height`): only these pixels are
    /// rendered, and the output image has the crop's size; `None` is the whole film.
    pub crop: Option<FilmCrop>,
    /// `principal_point_offset_x/y` (perspective only): the principal point's offset from the
    /// film centre, in fractions of the film's width and height.
    pub principal_point: glam::Vec2,
}

/// A film's crop window in pixels; it lies inside the film.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FilmCrop {
    /// Top-left pixel of the window.
    pub offset: glam::UVec2,
    /// Width and height of the window.
    pub size: glam::UVec2,
}

/// Integrator settings found in the file (the command line may override them).
#[derive(Debug, Clone, PartialEq)]
pub struct IntegratorDesc {
    /// Plugin name, e.g. `path`, `sppm`.
    pub kind: String,
    /// `max_depth` (−1 = unbounded; Mitsuba's default).
    pub max_depth: i32,
    /// `rr_depth` (Mitsuba's default 5).
    pub rr_depth: u32,
    /// `hide_emitters`: as in Mitsuba, the camera sees through area emitters to what lies
    /// behind them and sees the environment black, also through surfaces it passes straight
    /// through (masks, thin glass); reflections and the light they cast stay.
    pub hide_emitters: bool,
    /// `emitter_samples` of `direct`: light samples per camera ray (default `shading_samples`,
    /// else 1).
    pub emitter_samples: u32,
    /// `bsdf_samples` of `direct`: BSDF samples per camera ray (default `shading_samples`,
    /// else 1).
    pub bsdf_samples: u32,
    /// `aovs` of `aov`: the arbitrary output variables asked for, in order.
    pub aovs: Vec<AovSpec>,
    /// The integrators nested in an `aov`, each with the name its layer gets (its `name`, or
    /// Mitsuba's `_arg_<k>` for the k-th unnamed one).
    pub nested: Vec<(String, IntegratorDesc)>,
}

/// One arbitrary output variable of Mitsuba's `aov` integrator: `<name>:<kind>` in `aovs`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AovSpec {
    /// The layer name (the channels are `<name>.<suffix>`).
    pub name: String,
    /// What the layer holds.
    pub kind: AovKind,
}

/// What an AOV holds, at the surface the camera ray meets first (zero where it meets none).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AovKind {
    /// `albedo`: the BSDF's diffuse reflectance (Mitsuba's `eval_diffuse_reflectance`).
    Albedo,
    /// `depth`: the distance along the camera ray.
    Depth,
    /// `position`: the world-space position.
    Position,
    /// `uv`: the texture coordinates.
    Uv,
    /// `geo_normal`: the geometric normal.
    GeometricNormal,
    /// `sh_normal`: the shading normal (perturbed by a normal or bump map).
    ShadingNormal,
    /// `dp_du`: ∂p/∂u.
    DpDu,
    /// `dp_dv`: ∂p/∂v.
    DpDv,
    /// `duv_dx`: ∂uv/∂x, from the ray differential one pixel to the right.
    DuvDx,
    /// `duv_dy`: ∂uv/∂y, from the ray differential one pixel down.
    DuvDy,
    /// `prim_index`: the primitive's index in its shape (a triangle of a mesh; 0 otherwise).
    PrimIndex,
    /// `shape_index`: 1 + the shape's index in the scene (0 where nothing is hit).
    ShapeIndex,
}

impl AovKind {
    /// The kind named `name` in an `aovs` string (Mitsuba's spelling).
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "albedo" => AovKind::Albedo,
            "depth" => AovKind::Depth,
            "position" => AovKind::Position,
            "uv" => AovKind::Uv,
            "geo_normal" => AovKind::GeometricNormal,
            "sh_normal" => AovKind::ShadingNormal,
            "dp_du" => AovKind::DpDu,
            "dp_dv" => AovKind::DpDv,
            "duv_dx" => AovKind::DuvDx,
            "duv_dy" => AovKind::DuvDy,
            "prim_index" => AovKind::PrimIndex,
            "shape_index" => AovKind::ShapeIndex,
            _ => return None,
        })
    }

    /// Every kind's name, for messages.
    pub const NAMES: [&'static str; 12] = [
        "albedo",
        "depth",
        "position",
        "uv",
        "geo_normal",
        "sh_normal",
        "dp_du",
        "dp_dv",
        "duv_dx",
        "duv_dy",
        "prim_index",
        "shape_index",
    ];

    /// The channel suffixes of the layer, as Mitsuba names them.
    pub fn suffixes(self) -> &'static [&'static str] {
        match self {
            AovKind::Albedo => &["R", "G", "B"],
            AovKind::Depth => &["T"],
            AovKind::Uv | AovKind::DuvDx | AovKind::DuvDy => &["U", "V"],
            AovKind::Position
            | AovKind::GeometricNormal
            | AovKind::ShadingNormal
            | AovKind::DpDu
            | AovKind::DpDv => &["X", "Y", "Z"],
            AovKind::PrimIndex | AovKind::ShapeIndex => &["I"],
        }
    }
}

#[cfg(test)]
impl IntegratorDesc {
    /// Mitsuba's `path` with `hide_emitters` on (the integrators' tests of the flag).
    pub(crate) fn hiding_emitters() -> Self {
        IntegratorDesc {
            hide_emitters: true,
            ..Default::default()
        }
    }
}

impl Default for IntegratorDesc {
    /// Mitsuba's `path` with its defaults.
    fn default() -> Self {
        IntegratorDesc {
            kind: "path".into(),
            max_depth: -1,
            rr_depth: 5,
            hide_emitters: false,
            emitter_samples: 1,
            bsdf_samples: 1,
            aovs: Vec::new(),
            nested: Vec::new(),
        }
    }
}

/// A whole scene as data.
#[derive(Debug, Clone)]
pub struct SceneDescription {
    /// The sensor.
    pub camera: CameraDesc,
    /// The sampler's `sample_count`, if given.
    pub sample_count: Option<u32>,
    /// The integrator, if given.
    pub integrator: Option<IntegratorDesc>,
    /// All materials; shapes refer to them by index.
    pub bsdfs: Vec<Bsdf>,
    /// All shapes.
    pub shapes: Vec<ShapeDesc>,
    /// Emitters not attached to shapes.
    pub emitters: Vec<EmitterDesc>,
    /// Non-fatal messages from the importer (e.g. an ignored parameter).
    pub warnings: Vec<String>,
    /// Participating media; shapes and the camera refer to them by index.
    pub media: Vec<crate::parity::media::Medium>,
    /// The medium the camera sits in (the sensor's nested medium), if any.
    pub camera_medium: Option<u32>,
}

/// A square pinhole camera at `origin` looking at `target` (y up) with horizontal field of view
/// `fov` degrees and a box filter: the camera of the integrators' tests.
#[cfg(test)]
pub(crate) fn test_camera(
    origin: glam::Vec3,
    target: glam::Vec3,
    fov: f32,
    res: u32,
) -> CameraDesc {
    CameraDesc {
        to_world: crate::camera::look_at(origin, target, glam::Vec3::Y),
        projection: Projection::Perspective,
        fov,
        fov_axis: FovAxis::X,
        near_clip: 0.01,
        far_clip: 1000.0,
        aperture_radius: 0.0,
        focus_distance: 1.0,
        width: res,
        height: res,
        filter: crate::filter::FilterDesc::Box,
        sample_border: false,
        crop: None,
        principal_point: glam::Vec2::ZERO,
    }
}

/// A sphere of radius 1 at the origin with material `bsdf`, lit by `emitter` alone, seen by
/// [`test_camera`] from (0, 0, −4) at `res`²: the integrators' tests' furnace and light scenes.
#[cfg(test)]
pub(crate) fn test_sphere_scene(
    bsdf: crate::bsdf::Bsdf,
    emitter: EmitterDesc,
    res: u32,
) -> SceneDescription {
    SceneDescription {
        camera: test_camera(glam::Vec3::new(0.0, 0.0, -4.0), glam::Vec3::ZERO, 40.0, res),
        sample_count: None,
        integrator: None,
        bsdfs: vec![bsdf],
        shapes: vec![ShapeDesc {
            name: "ball".into(),
            geometry: Geometry::Sphere {
                center: glam::Vec3::ZERO,
                radius: 1.0,
                rotation: glam::Mat3::IDENTITY,
                flip_normals: false,
            },
            bsdf: 0,
            emission: None,
            collimated: false,
            media: Default::default(),
        }],
        emitters: vec![emitter],
        warnings: vec![],
        media: vec![],
        camera_medium: None,
    }
}

/// The unit sphere at the origin seen from inside (normals inward), emitting radiance 1, with
/// material `bsdf`: the furnace enclosure of the integrators' tests.
#[cfg(test)]
pub(crate) fn emitting_unit_enclosure(bsdf: usize) -> ShapeDesc {
    ShapeDesc {
        name: "enclosure".into(),
        geometry: Geometry::Sphere {
            center: Vec3::ZERO,
            radius: 1.0,
            rotation: glam::Mat3::IDENTITY,
            flip_normals: true,
        },
        bsdf,
        emission: Some(crate::texture::Texture::Constant(crate::spectrum::Rgb::ONE)),
        collimated: false,
        media: Default::default(),
    }
}
