//! The dataset configuration (`configs/datagen/*.toml`): resolution, render settings, split
//! fractions and, per scene family, the scene count and every parameter range. Parsing denies
//! unknown fields so typos are errors naming the field.

use crate::plan::Split;
use renderer::integrators::sppm::RadiusSchedule;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A whole dataset configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Preset name (recorded in the manifest).
    pub name: String,
    /// Master seed: scenes, splits and render seeds all derive from it.
    pub seed: u64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// How references and input bundles are rendered.
    pub render: RenderConfig,
    /// Train/validation/test fractions (by scene).
    pub split: SplitConfig,
    /// Scene families, counts and parameter ranges.
    pub families: Families,
}

/// Render settings of the dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderConfig {
    /// Photons per SPPM pass of the input bundles (without regimes; a regime has its own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photons_per_pass: Option<u64>,
    /// Pass counts at which one continuing input run writes a bundle, ascending (without
    /// regimes; a regime has its own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub passes: Option<Vec<u32>>,
    /// Independent input runs (render seeds) per scene.
    pub seeds: u32,
    /// Passes of the reference run.
    pub reference_passes: u32,
    /// Photons per pass of the reference run.
    pub reference_photons_per_pass: u64,
    /// Maximum path depth for eye and photon paths.
    pub max_depth: u32,
    /// Radius schedule of the input runs (`sppm` or `cppm`; absent: `sppm`). References are
    /// rendered with SPPM's whatever this says. Not serialised when `sppm`, so the
    /// fingerprint of a config without it is what it was before the option existed.
    #[serde(default, skip_serializing_if = "is_sppm")]
    pub schedule: RadiusSchedule,
    /// Light samples at each visible point of the input runs (absent: one, as every dataset
    /// rendered before the option; `infer --scene` and `evaluate` render with two, the
    /// multi-level default). References take one whatever this says. Not serialised when
    /// absent, so older configs keep their fingerprints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub emitter_samples: Option<u32>,
    /// Where the input runs gather the sharp level's photons (`"a"` or `"both"`; absent: `a`,
    /// as every dataset rendered before the option; `infer --scene` and `evaluate` render with
    /// `both`, the multi-level default). References gather at A whatever this says. Not
    /// serialised when absent, so older configs keep their fingerprints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sharp_level: Option<renderer::integrators::sppm::SharpLevel>,
    /// Where the input runs' eye subpaths take their random numbers across passes
    /// (`"independent"` or `"ldsampler"`; absent: independent, as every dataset rendered before
    /// the option). References draw independently whatever this says. Not serialised when
    /// absent, so older configs keep their fingerprints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampler: Option<renderer::integrators::sppm::EyeSampler>,
    /// Input regimes (`[[render.regimes]]`): each scene is rendered in one of them — its own
    /// photon density, pass counts, seeds and image side — instead of `photons_per_pass`,
    /// `passes`, `seeds` and the config's size. Absent: every scene as above. Every optional
    /// key below is left out of the fingerprint when absent, so older configs keep theirs.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub regimes: Vec<Regime>,
    /// Independent reference runs per scene, averaged (absent: 1). With two or more the
    /// reference's own noise is measured and recorded in the manifest.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_runs: Option<u32>,
    /// Photons of all reference runs together ÷ photons of one input run at its largest pass
    /// count, for validation and test scenes: their reference photons per pass follow from it
    /// (`reference_photons_per_pass` is then a lower bound). Absent: the fixed count alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_photon_factor: Option<f64>,
    /// The same for training scenes (cheaper, noisier targets; absent: as validation/test).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train_reference_photon_factor: Option<f64>,
}

/// One input regime of `[[render.regimes]]`: a photon density, pass counts and image side that
/// a share of the scenes is rendered at.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Regime {
    /// Name recorded with each scene (manifest `regime`).
    pub name: String,
    /// Relative share of the scenes (the shares are normalised over the regimes).
    pub share: f64,
    /// Square image side of its scenes (absent: the config's `width` × `height`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub side: Option<u32>,
    /// Photons per pixel per pass, `[lo, hi]`, drawn log-uniformly per scene.
    pub photons_per_pixel: [f64; 2],
    /// Pass counts at which the input runs write bundles (ascending).
    pub passes: Vec<u32>,
    /// Input runs per scene (absent: `render.seeds`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seeds: Option<u32>,
    /// Passes of each reference run of its scenes (absent: `render.reference_passes`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_passes: Option<u32>,
}

/// Whether `schedule` is the default, SPPM's.
fn is_sppm(schedule: &RadiusSchedule) -> bool {
    *schedule == RadiusSchedule::Sppm
}

/// Fractions of scenes per split; they must sum to 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplitConfig {
    /// Training fraction.
    pub train: f32,
    /// Validation fraction.
    pub val: f32,
    /// Test fraction.
    pub test: f32,
}

/// The generated families and the user's scenes; an absent table means no scenes of that family.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Families {
    /// Rooms lit mostly indirectly.
    pub room: Option<RoomConfig>,
    /// Refractive caustics from glass objects.
    pub glass: Option<GlassConfig>,
    /// Water height fields over textured floors.
    pub water: Option<WaterConfig>,
    /// Reflective caustics from metal rings and curved mirrors.
    pub metal: Option<MetalConfig>,
    /// Depth-of-field shelves.
    pub shelf: Option<ShelfConfig>,
    /// Furnished rooms lit by small visible lamps with shades. (Like `external`, left out of
    /// the serialised config when absent, so older configs keep their fingerprints.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lamp: Option<LampConfig>,
    /// Glass and liquid objects on a table, optionally before a mirror. (Left out when
    /// absent, like `lamp`.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tabletop: Option<TabletopConfig>,
    /// Sun- and sky-lit exteriors with glass, a pool or a slab casting caustics on the ground.
    /// (Left out when absent, like `lamp`.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exterior: Option<ExteriorConfig>,
    /// Procedural meshes with random materials of every BSDF kind. (Left out when absent,
    /// like `lamp`.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<MaterialConfig>,
    /// Bitmap-textured, bump- and normal-mapped surfaces: room corners and table tops. (Left
    /// out when absent, like `lamp`.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub textured: Option<TexturedConfig>,
    /// Scenes the user brings (Mitsuba 3 XML files), rendered like the generated ones.
    /// (Left out of the serialised config when absent, so the fingerprints of configs
    /// without it, and of the datasets made with them, are what they were.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub external: Option<ExternalConfig>,
}

/// `[families.external]`: the user's own scenes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExternalConfig {
    /// The scenes, in the order they get their ids.
    pub scenes: Vec<ExternalScene>,
}

/// One scene the user brings (`[[families.external.scenes]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExternalScene {
    /// The Mitsuba 3 XML file, relative to the directory `datagen` runs in (or absolute). Its
    /// film must be the dataset's `width` × `height` (after `defines`).
    pub xml: PathBuf,
    /// Name in the scene id `NNN-<name>` (letters, digits, `-`, `_`); default: the name of
    /// the XML's folder.
    #[serde(default)]
    pub name: Option<String>,
    /// Split of this scene; absent: assigned with the generated scenes by the split fractions.
    #[serde(default)]
    pub split: Option<Split>,
    /// `<default>` overrides of the scene file, as `render -D name=value`.
    #[serde(default)]
    pub defines: BTreeMap<String, String>,
}

impl ExternalScene {
    /// The name used in the scene id.
    pub fn id_name(&self) -> String {
        self.name.clone().unwrap_or_else(|| {
            let folder = self
                .xml
                .parent()
                .and_then(|p| p.file_name())
                .or_else(|| self.xml.file_stem())
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let safe: String = folder
                .chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                        c
                    } else {
                        '_'
                    }
                })
                .collect();
            if safe.is_empty() {
                "external".into()
            } else {
                safe
            }
        })
    }

    /// The `defines` as `render -D` pairs (in name order).
    pub fn define_pairs(&self) -> Vec<(String, String)> {
        self.defines
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect()
    }
}

/// A compact light used by several families.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SmallLight {
    /// A small rectangular area light facing the scene centre.
    Area,
    /// A spot light aimed at the scene centre.
    Spot,
    /// A point light.
    Point,
}

/// How a room is lit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RoomLight {
    /// Area lights just below the ceiling facing up (cove lighting).
    Cove,
    /// An area light behind a free-standing panel, facing a wall.
    Panel,
}

/// Objects of the glass family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GlassShape {
    /// Analytic sphere.
    Sphere,
    /// Randomly displaced sphere (PLY).
    Blob,
    /// Wine glass as a lathe mesh with wall thickness (PLY).
    WineGlass,
}

/// Lights of the water family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WaterLight {
    /// Directional sun.
    Sun,
    /// Spot light from above.
    Spot,
}

/// Objects of the metal family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MetalObject {
    /// A closed annular ring (its concave inside focuses a cardioid caustic).
    Ring,
    /// A standing cylindrical mirror section.
    Mirror,
}

/// Lamps of the lamp family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LampKind {
    /// A shade on a pole standing on the floor.
    Floor,
    /// A smaller shade on a side table.
    Table,
    /// A shade hanging from the ceiling on a cord.
    Pendant,
}

/// Objects of the tabletop family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TabletopObject {
    /// Analytic glass sphere.
    Sphere,
    /// Solid glass cylinder with rounded-off rims (PLY).
    Cylinder,
    /// Drinking glass with a thick bottom, possibly holding a liquid (PLY).
    Tumbler,
}

/// Caustic casters of the exterior family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExteriorGlass {
    /// Analytic glass sphere lying on the ground.
    Sphere,
    /// Glass cube standing on the ground.
    Block,
    /// Thick glass slab on short legs, a little above the ground.
    Slab,
    /// Raised pool: low walls round a tiled bottom, with a wavy water surface (PLY).
    Pool,
}

/// Object shapes of the material family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaterialShape {
    /// Closed vase-like surface of revolution (PLY).
    Vase,
    /// Displaced (noisy) sphere (PLY).
    Blob,
    /// Torus standing on its rim or lying flat (PLY).
    Torus,
    /// Analytic box.
    Box,
}

/// BSDF kinds of the material family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaterialKind {
    /// `diffuse` (plain or checkered).
    Diffuse,
    /// Smooth `plastic`.
    Plastic,
    /// `roughplastic`.
    RoughPlastic,
    /// Smooth `conductor`.
    Conductor,
    /// `roughconductor`.
    RoughConductor,
    /// Smooth `dielectric`.
    Dielectric,
    /// `roughdielectric`.
    RoughDielectric,
    /// `principled` (plain or checkered base colour).
    Principled,
}

/// Settings of the textured family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TexturedLayout {
    /// A room corner: floor, back wall and one side wall.
    Corner,
    /// A table top before a wall, on legs over a plain floor.
    Table,
}

/// Procedural texture patterns of the textured family (albedo and height field).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TexturePattern {
    /// Square tiles with grout joints and bevelled edges.
    Tiles,
    /// Bricks in running bond with mortar joints.
    Bricks,
    /// Wooden planks with grain and butt joints.
    Wood,
    /// Veined stone.
    Stone,
    /// Rough plaster.
    Plaster,
}

/// Most scenes one dataset config may list (every scene's id and jobs are listed up front).
pub const MAX_SCENES: u64 = 100_000;

/// Largest image side of a dataset (a bundle of 8192² pixels is already ~8 GB).
pub const MAX_SIDE: u32 = 8192;

/// Most objects a scene may get from an object-count range (`objects`, `objects_per_shelf`,
/// `shelves`, `waves`, `lamps`, `light_count`).
pub const MAX_OBJECTS: u64 = 1000;

/// Checks every `[lo, hi]` range under `value` (the families' parameters, serialised; `path`
/// names where): finite numbers with lo ≤ hi, and object counts within [`MAX_OBJECTS`]. A range
/// like `[35, 1e300]` (infinite as f32) would otherwise only fail inside a generated scene.
fn check_ranges(path: &str, value: &serde_json::Value) -> Result<(), String> {
    match value {
        serde_json::Value::Object(map) => {
            for (key, v) in map {
                check_ranges(&format!("{path}.{key}"), v)?;
            }
            Ok(())
        }
        serde_json::Value::Array(items) if items.len() == 2 => {
            // Ranges are the pairs of numbers; serde_json writes a non-finite f32 as null.
            let numeric = items.iter().all(|v| v.is_number() || v.is_null());
            if !numeric {
                // A two-entry choice list (light kinds, external scenes): look inside.
                for (i, v) in items.iter().enumerate() {
                    check_ranges(&format!("{path}[{i}]"), v)?;
                }
                return Ok(());
            }
            let (Some(lo), Some(hi)) = (items[0].as_f64(), items[1].as_f64()) else {
                return Err(format!("{path}: range values must be finite numbers"));
            };
            if !(lo.is_finite() && hi.is_finite()) {
                return Err(format!("{path}: range values must be finite numbers"));
            }
            if lo > hi {
                return Err(format!("{path}: the range [{lo}, {hi}] has lo > hi"));
            }
            let counts = [
                "objects",
                "objects_per_shelf",
                "shelves",
                "waves",
                "lamps",
                "light_count",
                "glass_objects",
            ];
            if counts.iter().any(|c| path.ends_with(&format!(".{c}"))) && hi > MAX_OBJECTS as f64 {
                return Err(format!("{path}: at most {MAX_OBJECTS} (got {hi})"));
            }
            Ok(())
        }
        serde_json::Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                check_ranges(&format!("{path}[{i}]"), v)?;
            }
            Ok(())
        }
        _ => Ok(()),
    }
}

/// Parameter ranges of the room family; `[lo, hi]` pairs are sampled uniformly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoomConfig {
    /// Number of scenes.
    pub count: u32,
    /// Room width (x).
    pub size_x: [f32; 2],
    /// Room depth (z).
    pub size_z: [f32; 2],
    /// Ceiling height.
    pub height: [f32; 2],
    /// Per-channel wall albedo.
    pub wall_albedo: [f32; 2],
    /// Per-channel floor albedo (under a glossy coat).
    pub floor_albedo: [f32; 2],
    /// GGX alpha of the floor coat (below 0.01: smooth `plastic`).
    pub floor_alpha: [f32; 2],
    /// Lighting variants, chosen uniformly.
    pub lights: Vec<RoomLight>,
    /// Radiance of the hidden area lights.
    pub light_radiance: [f32; 2],
    /// Number of furniture objects.
    pub objects: [u32; 2],
    /// Object size.
    pub object_size: [f32; 2],
    /// Probability that an object is metallic.
    pub metal_probability: f32,
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Parameter ranges of the glass family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GlassConfig {
    /// Number of scenes.
    pub count: u32,
    /// Number of glass objects.
    pub objects: [u32; 2],
    /// Object kinds, chosen uniformly per object.
    pub shapes: Vec<GlassShape>,
    /// Object size (sphere/blob radius, glass height / 2).
    pub object_size: [f32; 2],
    /// Index of refraction.
    pub ior: [f32; 2],
    /// Light kinds, chosen uniformly.
    pub lights: Vec<SmallLight>,
    /// Half-size of area lights.
    pub light_size: [f32; 2],
    /// Emitted power (W) of the light.
    pub light_power: [f32; 2],
    /// Light elevation above the floor plane, degrees.
    pub light_elevation: [f32; 2],
    /// Light distance from the scene centre.
    pub light_distance: [f32; 2],
    /// Per-channel floor albedo.
    pub floor_albedo: [f32; 2],
    /// Probability of a checkerboard floor.
    pub checker_probability: f32,
    /// Constant environment radiance (0 = none).
    pub env_radiance: [f32; 2],
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Parameter ranges of the water family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WaterConfig {
    /// Number of scenes.
    pub count: u32,
    /// Pool half-size (x and z).
    pub pool_size: [f32; 2],
    /// Water surface height above the floor.
    pub water_height: [f32; 2],
    /// Number of waves.
    pub waves: [u32; 2],
    /// Wave amplitude.
    pub wave_amplitude: [f32; 2],
    /// Wavelength.
    pub wavelength: [f32; 2],
    /// Height-field grid resolution (quads per side).
    pub grid: u32,
    /// Checker squares across the pool.
    pub checks: [f32; 2],
    /// Per-channel albedo of the light checks.
    pub check_light: [f32; 2],
    /// Per-channel albedo of the dark checks.
    pub check_dark: [f32; 2],
    /// Index of refraction of the water.
    pub ior: [f32; 2],
    /// Light kinds, chosen uniformly.
    pub lights: Vec<WaterLight>,
    /// Sun elevation, degrees.
    pub sun_elevation: [f32; 2],
    /// Sun irradiance.
    pub sun_irradiance: [f32; 2],
    /// Spot light emitted power (W).
    pub spot_power: [f32; 2],
    /// Spot cutoff angle, degrees.
    pub spot_cutoff: [f32; 2],
    /// Camera elevation, degrees.
    pub camera_elevation: [f32; 2],
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Parameter ranges of the metal family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MetalConfig {
    /// Number of scenes.
    pub count: u32,
    /// Number of metal objects.
    pub objects: [u32; 2],
    /// Object kinds, chosen uniformly per object.
    pub kinds: Vec<MetalObject>,
    /// Ring / mirror radius of curvature.
    pub radius: [f32; 2],
    /// Ring / mirror height.
    pub object_height: [f32; 2],
    /// Wall thickness.
    pub thickness: [f32; 2],
    /// Angular extent of mirror sections, degrees.
    pub mirror_angle: [f32; 2],
    /// Named conductors (Mitsuba `material`), chosen uniformly.
    pub materials: Vec<String>,
    /// GGX alpha (below 0.01: smooth `conductor`).
    pub alpha: [f32; 2],
    /// Light kinds, chosen uniformly.
    pub lights: Vec<SmallLight>,
    /// Half-size of area lights.
    pub light_size: [f32; 2],
    /// Emitted power (W) of the light.
    pub light_power: [f32; 2],
    /// Light elevation, degrees (low light gives long caustics).
    pub light_elevation: [f32; 2],
    /// Light distance from the scene centre.
    pub light_distance: [f32; 2],
    /// Per-channel floor albedo.
    pub floor_albedo: [f32; 2],
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Parameter ranges of the depth-of-field shelf family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShelfConfig {
    /// Number of scenes.
    pub count: u32,
    /// Number of shelf boards.
    pub shelves: [u32; 2],
    /// Objects per board.
    pub objects_per_shelf: [u32; 2],
    /// Object size.
    pub object_size: [f32; 2],
    /// Probability that an object is glossy (rough plastic).
    pub glossy_probability: f32,
    /// Probability that an object is metallic (rough conductor).
    pub metal_probability: f32,
    /// GGX alpha of glossy and metal objects.
    pub alpha: [f32; 2],
    /// Thin-lens aperture radius.
    pub aperture_radius: [f32; 2],
    /// Camera distance from the shelf front.
    pub camera_distance: [f32; 2],
    /// Radiance of the area light.
    pub light_radiance: [f32; 2],
    /// Constant environment radiance (0 = none).
    pub env_radiance: [f32; 2],
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Parameter ranges of the lamp family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LampConfig {
    /// Number of scenes.
    pub count: u32,
    /// Room width (x).
    pub size_x: [f32; 2],
    /// Room depth (z).
    pub size_z: [f32; 2],
    /// Ceiling height.
    pub height: [f32; 2],
    /// Per-channel wall albedo.
    pub wall_albedo: [f32; 2],
    /// Per-channel floor albedo (under a glossy coat).
    pub floor_albedo: [f32; 2],
    /// GGX alpha of the floor coat (below 0.01: smooth `plastic`).
    pub floor_alpha: [f32; 2],
    /// Number of lamps.
    pub lamps: [u32; 2],
    /// Lamp kinds, chosen uniformly per lamp.
    pub kinds: Vec<LampKind>,
    /// Emitted power (W) of each bulb.
    pub lamp_power: [f32; 2],
    /// Bulb (emitting sphere) radius.
    pub bulb_radius: [f32; 2],
    /// Warmth of the bulb colour: 0 is white, 1 drops green by half and blue to nothing.
    pub bulb_warmth: [f32; 2],
    /// Height of the bulb centre in the shade: 0 at the lower rim, 1 at the upper; negative
    /// values hang the bulb below the shade, where it is seen from the side.
    pub bulb_position: [f32; 2],
    /// Radius of the shade's lower opening (pendant and table shades are scaled down).
    pub shade_radius: [f32; 2],
    /// Shade height as a multiple of its lower radius.
    pub shade_height: [f32; 2],
    /// Upper over lower shade radius (below 1: the usual tapered shade).
    pub shade_taper: [f32; 2],
    /// Per-channel shade albedo (opaque diffuse; light leaves through the openings only).
    pub shade_albedo: [f32; 2],
    /// Number of furniture objects (boxes and tables).
    pub objects: [u32; 2],
    /// Furniture size.
    pub object_size: [f32; 2],
    /// Probability that a piece of furniture is a table rather than a box.
    pub table_probability: f32,
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Parameter ranges of the tabletop family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TabletopConfig {
    /// Number of scenes.
    pub count: u32,
    /// Table top half-width (x).
    pub table_size_x: [f32; 2],
    /// Table top half-depth (z).
    pub table_size_z: [f32; 2],
    /// Per-channel albedo of the table top.
    pub table_albedo: [f32; 2],
    /// Probability of a checkered table cloth (else plain diffuse or glossy).
    pub checker_probability: f32,
    /// Probability that a plain top is glossy (rough plastic) rather than diffuse.
    pub plastic_probability: f32,
    /// GGX alpha of a glossy top (below 0.01: smooth `plastic`).
    pub table_alpha: [f32; 2],
    /// Number of glass objects.
    pub objects: [u32; 2],
    /// Object kinds, chosen uniformly per object.
    pub shapes: Vec<TabletopObject>,
    /// Object size (sphere radius, cylinder and tumbler radius).
    pub object_size: [f32; 2],
    /// Height of cylinders and tumblers as a multiple of their radius.
    pub object_height: [f32; 2],
    /// Index of refraction of the glass.
    pub ior: [f32; 2],
    /// Probability that a tumbler holds a liquid.
    pub liquid_probability: f32,
    /// Liquid level as a fraction of the tumbler's inner height.
    pub liquid_fill: [f32; 2],
    /// Index of refraction of the liquid.
    pub liquid_ior: [f32; 2],
    /// Probability of a mirror standing behind the objects.
    pub mirror_probability: f32,
    /// Mirror half-width.
    pub mirror_width: [f32; 2],
    /// Mirror height.
    pub mirror_height: [f32; 2],
    /// Mirror yaw away from facing the camera side, degrees.
    pub mirror_yaw: [f32; 2],
    /// Named conductors of the mirror (Mitsuba `material`), chosen uniformly.
    pub mirror_materials: Vec<String>,
    /// Light kinds, chosen uniformly per light.
    pub lights: Vec<SmallLight>,
    /// Number of lights.
    pub light_count: [u32; 2],
    /// Half-size of area lights.
    pub light_size: [f32; 2],
    /// Emitted power (W) of each light.
    pub light_power: [f32; 2],
    /// Light elevation above the table plane, degrees.
    pub light_elevation: [f32; 2],
    /// Light distance from the table centre.
    pub light_distance: [f32; 2],
    /// Constant environment radiance (0 = none).
    pub env_radiance: [f32; 2],
    /// Camera elevation above the table plane, degrees.
    pub camera_elevation: [f32; 2],
    /// Camera distance from the table centre.
    pub camera_distance: [f32; 2],
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Parameter ranges of the exterior family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExteriorConfig {
    /// Number of scenes.
    pub count: u32,
    /// Half-size of the (square) ground plane.
    pub ground_size: [f32; 2],
    /// Per-channel ground albedo.
    pub ground_albedo: [f32; 2],
    /// Probability of checkered paving rather than a plain ground.
    pub checker_probability: f32,
    /// Size of one paving check.
    pub check_size: [f32; 2],
    /// Constant sky radiance.
    pub sky_radiance: [f32; 2],
    /// Sun irradiance (directional emitter).
    pub sun_irradiance: [f32; 2],
    /// Sun elevation above the horizon, degrees.
    pub sun_elevation: [f32; 2],
    /// Number of caustic casters.
    pub glass_objects: [u32; 2],
    /// Caster kinds, chosen uniformly per caster.
    pub glass_shapes: Vec<ExteriorGlass>,
    /// Caster size (sphere radius, block and slab half-size).
    pub glass_size: [f32; 2],
    /// Index of refraction of the glass.
    pub ior: [f32; 2],
    /// Half-size of a pool.
    pub pool_size: [f32; 2],
    /// Amplitude of the pool's waves.
    pub wave_amplitude: [f32; 2],
    /// Number of diffuse or metal objects.
    pub objects: [u32; 2],
    /// Their size.
    pub object_size: [f32; 2],
    /// Probability that such an object is metal rather than diffuse.
    pub metal_probability: f32,
    /// Named conductors (Mitsuba `material`) of the metal objects, chosen uniformly.
    pub metals: Vec<String>,
    /// Eye height of the camera above the ground.
    pub camera_height: [f32; 2],
    /// Horizontal distance of the camera from the objects' centre.
    pub camera_distance: [f32; 2],
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Parameter ranges of the material family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialConfig {
    /// Number of scenes.
    pub count: u32,
    /// Number of objects.
    pub objects: [u32; 2],
    /// Object shapes, chosen uniformly per object.
    pub shapes: Vec<MaterialShape>,
    /// Object size (about its radius).
    pub object_size: [f32; 2],
    /// BSDF kinds, chosen uniformly per object.
    pub kinds: Vec<MaterialKind>,
    /// Per-channel albedo / base colour.
    pub albedo: [f32; 2],
    /// GGX alpha of the rough kinds (also the principled roughness).
    pub alpha: [f32; 2],
    /// Index of refraction of the dielectrics.
    pub ior: [f32; 2],
    /// Named conductors (Mitsuba `material`), chosen uniformly.
    pub metals: Vec<String>,
    /// Probability that a diffuse or principled object is checkered.
    pub texture_probability: f32,
    /// Per-channel floor albedo.
    pub floor_albedo: [f32; 2],
    /// Probability of a simple room (floor, three walls and a ceiling) rather than an open
    /// floor under the environment.
    pub room_probability: f32,
    /// Emitted power (W) of the area light above the objects.
    pub light_power: [f32; 2],
    /// Half-size of the area light.
    pub light_size: [f32; 2],
    /// Height of the area light above the floor.
    pub light_height: [f32; 2],
    /// Constant environment radiance (0 = none).
    pub env_radiance: [f32; 2],
    /// Camera elevation above the floor plane, degrees.
    pub camera_elevation: [f32; 2],
    /// Camera distance from the objects' centre.
    pub camera_distance: [f32; 2],
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Parameter ranges of the textured family.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TexturedConfig {
    /// Number of scenes.
    pub count: u32,
    /// Settings, chosen uniformly: `corner` or `table`.
    pub layouts: Vec<TexturedLayout>,
    /// Patterns of the floor or table top, chosen uniformly.
    pub floor_patterns: Vec<TexturePattern>,
    /// Patterns of the walls, chosen uniformly.
    pub wall_patterns: Vec<TexturePattern>,
    /// Patterns of textured objects, chosen uniformly.
    pub object_patterns: Vec<TexturePattern>,
    /// World size covered by one texture image (it repeats across a surface).
    pub pattern_size: [f32; 2],
    /// Side of each generated image in pixels.
    pub texture_size: [u32; 2],
    /// Per-channel albedo of the patterns and plain objects (wood and bricks tinted).
    pub albedo: [f32; 2],
    /// Relief depth in world units (height map 0 → 1).
    pub bump_depth: [f32; 2],
    /// Probability that a relief is a normal map rather than a bump map.
    pub normalmap_probability: f32,
    /// Probability of a glossy coat (rough plastic) on the floor or table top.
    pub glossy_floor_probability: f32,
    /// GGX alpha of coats and metals (below 0.01: smooth).
    pub alpha: [f32; 2],
    /// Number of objects (spheres and boxes).
    pub objects: [u32; 2],
    /// Object size (sphere radius, box half-width).
    pub object_size: [f32; 2],
    /// Probability that a non-metal object has a bitmap albedo.
    pub texture_probability: f32,
    /// Probability that a non-metal object is glossy (rough plastic).
    pub glossy_probability: f32,
    /// Probability that an object is metal.
    pub metal_probability: f32,
    /// Named conductors (Mitsuba `material`), chosen uniformly.
    pub metals: Vec<String>,
    /// Emitted power (W) of the area light above the objects.
    pub light_power: [f32; 2],
    /// Half-size of the area light.
    pub light_size: [f32; 2],
    /// Height of the area light above the floor or table top.
    pub light_height: [f32; 2],
    /// Probability of a second, small light.
    pub small_light_probability: f32,
    /// Kinds of that light, chosen uniformly.
    pub small_lights: Vec<SmallLight>,
    /// Its emitted power (W).
    pub small_light_power: [f32; 2],
    /// Constant environment radiance (0 = none).
    pub env_radiance: [f32; 2],
    /// Camera elevation, degrees.
    pub camera_elevation: [f32; 2],
    /// Camera distance from the objects' centre.
    pub camera_distance: [f32; 2],
    /// Horizontal field of view in degrees.
    pub fov: [f32; 2],
}

/// Configuration errors; each names the file and the problem.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{path}: {cause}")]
    Io {
        /// Config path.
        path: String,
        /// Cause (part of the message, not a separate `source`, so chains print it once).
        cause: std::io::Error,
    },
    /// TOML syntax or schema error (the message names line, column and field).
    #[error("{path}: {message}")]
    Parse {
        /// Config path.
        path: String,
        /// Parser message.
        message: String,
    },
    /// A value is out of its valid domain.
    #[error("{path}: invalid value: {message}")]
    Invalid {
        /// Config path.
        path: String,
        /// What is wrong.
        message: String,
    },
}

impl Config {
    /// Reads, parses and validates a configuration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let p = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|cause| ConfigError::Io {
            path: p.clone(),
            cause,
        })?;
        Self::parse(&text, &p)
    }

    /// Parses and validates configuration text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let config: Config = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: origin.to_owned(),
            message: e.to_string(),
        })?;
        config.validate().map_err(|message| ConfigError::Invalid {
            path: origin.to_owned(),
            message,
        })?;
        Ok(config)
    }

    /// Checks domains that the type system does not.
    fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err("width and height must be positive".into());
        }
        if self.width.max(self.height) > MAX_SIDE {
            return Err(format!(
                "width and height must be at most {MAX_SIDE} (got {}x{})",
                self.width, self.height
            ));
        }
        check_ranges(
            "families",
            &serde_json::to_value(&self.families).map_err(|e| e.to_string())?,
        )?;
        let r = &self.render;
        match (&r.passes, r.photons_per_pass, r.regimes.is_empty()) {
            (Some(passes), Some(photons), true) => {
                if passes.is_empty() || passes.contains(&0) {
                    return Err(
                        "render.passes must be a non-empty list of positive pass counts".into(),
                    );
                }
                if passes.windows(2).any(|w| w[0] >= w[1]) {
                    return Err("render.passes must be strictly ascending".into());
                }
                if photons == 0 {
                    return Err("photons per pass must be positive".into());
                }
            }
            (_, _, true) => {
                return Err(
                    "render.passes and render.photons_per_pass are required (or give \
                     [[render.regimes]])"
                        .into(),
                )
            }
            (None, None, false) => {}
            (_, _, false) => {
                return Err(
                    "render.passes and render.photons_per_pass are not used with \
                     [[render.regimes]] (each regime has its own): remove them"
                        .into(),
                )
            }
        }
        if r.emitter_samples == Some(0) {
            return Err("render.emitter_samples must be positive".into());
        }
        if r.seeds == 0 || r.reference_passes == 0 {
            return Err("render.seeds and render.reference_passes must be positive".into());
        }
        if r.reference_photons_per_pass == 0 {
            return Err("photons per pass must be positive".into());
        }
        if r.reference_runs == Some(0) {
            return Err("render.reference_runs must be at least 1".into());
        }
        for (key, factor) in [
            ("reference_photon_factor", r.reference_photon_factor),
            (
                "train_reference_photon_factor",
                r.train_reference_photon_factor,
            ),
        ] {
            if factor.is_some_and(|f| !(f.is_finite() && f > 0.0)) {
                return Err(format!("render.{key} must be a positive number"));
            }
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, g) in r.regimes.iter().enumerate() {
            let at = format!("render.regimes[{i}] (`{}`)", g.name);
            if g.name.is_empty() || !names.insert(g.name.as_str()) {
                return Err(format!("{at}: every regime needs a name of its own"));
            }
            if !(g.share.is_finite() && g.share > 0.0) {
                return Err(format!("{at}.share must be a positive number"));
            }
            if g.side.is_some_and(|s| s == 0 || s > MAX_SIDE) {
                return Err(format!("{at}.side must lie in 1..={MAX_SIDE}"));
            }
            let [lo, hi] = g.photons_per_pixel;
            if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
                return Err(format!(
                    "{at}.photons_per_pixel must be [lo, hi] with 0 < lo ≤ hi"
                ));
            }
            if g.passes.is_empty() || g.passes.contains(&0) {
                return Err(format!(
                    "{at}.passes must be a non-empty list of positive counts"
                ));
            }
            if g.passes.windows(2).any(|w| w[0] >= w[1]) {
                return Err(format!("{at}.passes must be strictly ascending"));
            }
            if g.seeds == Some(0) || g.reference_passes == Some(0) {
                return Err(format!(
                    "{at}: seeds and reference_passes must be at least 1"
                ));
            }
        }
        let s = &self.split;
        if [s.train, s.val, s.test]
            .iter()
            .any(|f| !(0.0..=1.0).contains(f))
            || (s.train + s.val + s.test - 1.0).abs() > 1e-4
        {
            return Err("split fractions must lie in [0, 1] and sum to 1".into());
        }
        let f = &self.families;
        let empty = |name: &str, len: usize| {
            if len == 0 {
                Err(format!("families.{name}: choice lists must not be empty"))
            } else {
                Ok(())
            }
        };
        if let Some(c) = &f.room {
            empty("room.lights", c.lights.len())?;
        }
        if let Some(c) = &f.glass {
            empty("glass.shapes", c.shapes.len())?;
            empty("glass.lights", c.lights.len())?;
        }
        if let Some(c) = &f.water {
            empty("water.lights", c.lights.len())?;
            if c.grid < 2 {
                return Err("families.water.grid must be at least 2".into());
            }
        }
        if let Some(c) = &f.metal {
            empty("metal.kinds", c.kinds.len())?;
            empty("metal.materials", c.materials.len())?;
            empty("metal.lights", c.lights.len())?;
        }
        if let Some(c) = &f.lamp {
            empty("lamp.kinds", c.kinds.len())?;
            // A lamp scene is lit by its lamps alone, and a bulb needs a size to emit from.
            if c.lamps[0] == 0 {
                return Err("families.lamp.lamps: at least one lamp per scene".into());
            }
            if c.bulb_radius[0] <= 0.0 || c.shade_radius[0] <= 0.0 || c.shade_taper[0] <= 0.0 {
                return Err(
                    "families.lamp: bulb_radius, shade_radius and shade_taper must be positive"
                        .into(),
                );
            }
        }
        if let Some(c) = &f.tabletop {
            empty("tabletop.shapes", c.shapes.len())?;
            empty("tabletop.lights", c.lights.len())?;
            empty("tabletop.mirror_materials", c.mirror_materials.len())?;
            if c.objects[0] == 0 || c.light_count[0] == 0 {
                return Err("families.tabletop: objects and light_count must be at least 1".into());
            }
            if c.object_size[0] <= 0.0 || c.object_height[0] <= 0.0 {
                return Err(
                    "families.tabletop: object_size and object_height must be positive".into(),
                );
            }
            if c.liquid_fill[0] < 0.0 || c.liquid_fill[1] > 1.0 {
                return Err("families.tabletop.liquid_fill must lie in [0, 1]".into());
            }
        }
        if let Some(c) = &f.exterior {
            empty("exterior.glass_shapes", c.glass_shapes.len())?;
            empty("exterior.metals", c.metals.len())?;
            // The family's point: at least one caustic under a visible sun.
            if c.glass_objects[0] == 0 {
                return Err("families.exterior.glass_objects: at least one per scene".into());
            }
            if c.sun_irradiance[0] <= 0.0 {
                return Err("families.exterior.sun_irradiance must be positive".into());
            }
            if c.sun_elevation[0] <= 0.0 || c.sun_elevation[1] > 90.0 {
                return Err("families.exterior.sun_elevation must lie in (0, 90]".into());
            }
            for (name, r) in [
                ("ground_size", c.ground_size),
                ("check_size", c.check_size),
                ("glass_size", c.glass_size),
                ("pool_size", c.pool_size),
                ("object_size", c.object_size),
                ("camera_height", c.camera_height),
                ("ior", c.ior),
            ] {
                if r[0] <= 0.0 {
                    return Err(format!("families.exterior.{name} must be positive"));
                }
            }
        }
        if let Some(c) = &f.material {
            empty("material.shapes", c.shapes.len())?;
            empty("material.kinds", c.kinds.len())?;
            empty("material.metals", c.metals.len())?;
            if c.objects[0] == 0 {
                return Err("families.material.objects: at least one per scene".into());
            }
            if c.alpha[0] < 0.0 || c.alpha[1] > 1.0 {
                return Err("families.material.alpha must lie in [0, 1]".into());
            }
            if c.albedo[0] < 0.0 || c.albedo[1] > 1.0 {
                return Err("families.material.albedo must lie in [0, 1]".into());
            }
            for (name, r) in [
                ("object_size", c.object_size),
                ("light_size", c.light_size),
                ("light_power", c.light_power),
                ("ior", c.ior),
            ] {
                if r[0] <= 0.0 {
                    return Err(format!("families.material.{name} must be positive"));
                }
            }
        }
        if let Some(c) = &f.textured {
            empty("textured.layouts", c.layouts.len())?;
            empty("textured.floor_patterns", c.floor_patterns.len())?;
            empty("textured.wall_patterns", c.wall_patterns.len())?;
            empty("textured.object_patterns", c.object_patterns.len())?;
            empty("textured.metals", c.metals.len())?;
            empty("textured.small_lights", c.small_lights.len())?;
            if c.texture_size[0] < 8 || c.texture_size[1] > 4096 {
                return Err("families.textured.texture_size must lie in [8, 4096] pixels".into());
            }
            for (name, r) in [("albedo", c.albedo), ("alpha", c.alpha)] {
                if r[0] < 0.0 || r[1] > 1.0 {
                    return Err(format!("families.textured.{name} must lie in [0, 1]"));
                }
            }
            for (name, p) in [
                ("normalmap_probability", c.normalmap_probability),
                ("glossy_floor_probability", c.glossy_floor_probability),
                ("texture_probability", c.texture_probability),
                ("glossy_probability", c.glossy_probability),
                ("metal_probability", c.metal_probability),
                ("small_light_probability", c.small_light_probability),
            ] {
                if !(0.0..=1.0).contains(&p) {
                    return Err(format!("families.textured.{name} must lie in [0, 1]"));
                }
            }
            // The family's point: visible relief on a surface of a measurable size.
            for (name, r) in [
                ("pattern_size", c.pattern_size),
                ("bump_depth", c.bump_depth),
                ("object_size", c.object_size),
                ("light_size", c.light_size),
                ("light_power", c.light_power),
                ("light_height", c.light_height),
                ("camera_distance", c.camera_distance),
            ] {
                if r[0] <= 0.0 {
                    return Err(format!("families.textured.{name} must be positive"));
                }
            }
        }
        if let Some(c) = &f.external {
            if c.scenes.is_empty() {
                return Err("families.external.scenes must not be empty".into());
            }
            for (i, s) in c.scenes.iter().enumerate() {
                let name = s.id_name();
                if name.is_empty()
                    || !name
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
                {
                    return Err(format!(
                        "families.external.scenes[{i}].name `{name}`: use letters, digits, `-` \
                         and `_` only"
                    ));
                }
                if s.xml.as_os_str().is_empty() {
                    return Err(format!("families.external.scenes[{i}].xml is empty"));
                }
            }
        }
        let f = &self.families;
        let total: u64 = [
            f.room.as_ref().map_or(0, |c| c.count),
            f.glass.as_ref().map_or(0, |c| c.count),
            f.water.as_ref().map_or(0, |c| c.count),
            f.metal.as_ref().map_or(0, |c| c.count),
            f.shelf.as_ref().map_or(0, |c| c.count),
            f.lamp.as_ref().map_or(0, |c| c.count),
            f.tabletop.as_ref().map_or(0, |c| c.count),
            f.exterior.as_ref().map_or(0, |c| c.count),
            f.material.as_ref().map_or(0, |c| c.count),
            f.textured.as_ref().map_or(0, |c| c.count),
        ]
        .iter()
        .map(|&c| u64::from(c))
        .sum::<u64>()
            + f.external.as_ref().map_or(0, |c| c.scenes.len() as u64);
        if total > MAX_SCENES {
            return Err(format!(
                "the families' counts add up to {total} scenes; at most {MAX_SCENES}"
            ));
        }
        if total == 0 {
            return Err("no scenes: give at least one family a positive count".into());
        }
        Ok(())
    }

    /// Total number of scenes over all families.
    pub fn scene_count(&self) -> u32 {
        let f = &self.families;
        f.room.as_ref().map_or(0, |c| c.count)
            + f.glass.as_ref().map_or(0, |c| c.count)
            + f.water.as_ref().map_or(0, |c| c.count)
            + f.metal.as_ref().map_or(0, |c| c.count)
            + f.shelf.as_ref().map_or(0, |c| c.count)
            + f.lamp.as_ref().map_or(0, |c| c.count)
            + f.tabletop.as_ref().map_or(0, |c| c.count)
            + f.exterior.as_ref().map_or(0, |c| c.count)
            + f.material.as_ref().map_or(0, |c| c.count)
            + f.textured.as_ref().map_or(0, |c| c.count)
            + f.external.as_ref().map_or(0, |c| c.scenes.len() as u32)
    }

    /// The external scene of scene index `index`, if that scene is one (scenes are numbered
    /// over the families in order, the external ones last).
    pub fn external_scene(&self, index: usize) -> Option<&ExternalScene> {
        let generated = (self.scene_count()
            - self
                .families
                .external
                .as_ref()
                .map_or(0, |c| c.scenes.len() as u32)) as usize;
        let external = self.families.external.as_ref()?;
        index
            .checked_sub(generated)
            .and_then(|k| external.scenes.get(k))
    }
}
