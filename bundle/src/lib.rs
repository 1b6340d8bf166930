//! The sample-bundle format (docs/method.md §4): the contract between the renderer and the network side.
//!
//! A bundle is one single-part, multi-layer float32 OpenEXR file holding the five multi-level
//! SPPM estimates (`y`, `z1`..`z4`), their variances of the mean, the G-buffer (albedo, normal,
//! depth) and optionally the per-level kernel radii. Layers follow the OpenEXR "layer.channel"
//! naming convention, so OpenImageIO, Python `OpenEXR`, `exrheader` etc. read them directly.
//! Metadata ([`BundleMeta`]) lives in the EXR header as a JSON string attribute
//! ([`META_ATTRIBUTE`]); there is no sidecar file. The exact layout is documented in
//! `docs/formats.md`.
//!
//! References (long renders) are plain RGB EXRs with channels `R`, `G`, `B`
//! ([`write_rgb_exr_image`], [`read_rgb_exr_image`]).

pub mod manifest;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use exr::prelude::{AttributeValue, Text};
use fileio::exr::{ExrError, ExrReadError};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Names of the five estimate levels, sharpest first: `y` is the sharpest (independent)
/// estimate, `z1`..`z4` the progressively smoother (correlated) ones.
pub const LEVEL_NAMES: [&str; 5] = ["y", "z1", "z2", "z3", "z4"];

/// Header attribute holding the JSON-serialised [`BundleMeta`].
pub const META_ATTRIBUTE: &str = "bundleMeta";

/// Header attribute holding the format identifier [`FORMAT_VERSION`].
pub const FORMAT_ATTRIBUTE: &str = "bundleFormat";

/// Format identifier written to [`FORMAT_ATTRIBUTE`]; bumped on incompatible changes.
pub const FORMAT_VERSION: &str = "sppm-ml-bundle/1";

/// What [`BundleMeta::integrator`] may say: multi-level SPPM, single-level SPPM (every level
/// layer holds the one estimate), or a synthetic test bundle (`model::synthetic`).
pub const INTEGRATORS: [&str; 3] = ["sppm-ml", "sppm", "synthetic"];

/// What [`BundleMeta::schedule`] may say: SPPM's radius shrink after every pass, or CPPM's
/// χ² test per level (docs/sppm.md).
pub const SCHEDULES: [&str; 2] = ["sppm", "cppm"];

/// The schedule of a bundle whose metadata names none (every bundle written before CPPM).
pub const DEFAULT_SCHEDULE: &str = "sppm";

/// What [`BundleMeta::sharp_level`] may say: the sharp level's photons gathered at eye subpath
/// A's visible point, or the mean of A's and B's (docs/sppm.md).
pub const SHARP_LEVELS: [&str; 2] = ["a", "both"];

/// The sharp level of a bundle whose metadata names none (every bundle written before the
/// option).
pub const SHARP_LEVEL_A: &str = "a";

/// What [`BundleMeta::sampler`] may say: how the eye subpaths' random numbers relate across
/// passes (docs/sppm.md, "Eye samples across passes").
pub const SAMPLERS: [&str; 2] = ["independent", "ldsampler"];

/// The sampler of a bundle whose metadata names none (every bundle written before the option).
pub const SAMPLER_INDEPENDENT: &str = "independent";

/// Channel names of an RGB layer.
const RGB: [&str; 3] = ["R", "G", "B"];
/// Channel names of the normal layer.
const XYZ: [&str; 3] = ["X", "Y", "Z"];

/// Errors of reading and writing bundles and reference images; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// The file could not be created, renamed or opened.
    // The cause is part of the message, not a `source`: error chains printed with `{:#}`
    // would otherwise repeat it.
    #[error("{path}: {error}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The underlying I/O error.
        error: std::io::Error,
    },
    /// The EXR library rejected the file (truncated, corrupt, not an EXR).
    #[error("{path}: invalid or truncated EXR: {error}")]
    Exr {
        /// The file concerned.
        path: PathBuf,
        /// The underlying EXR error.
        error: exr::error::Error,
    },
    /// A required channel is absent from the file.
    #[error("{path}: missing channel `{channel}`")]
    MissingChannel {
        /// The file concerned.
        path: PathBuf,
        /// The full channel name, e.g. `z3.G`.
        channel: String,
    },
    /// A channel or image has the wrong size or shape.
    #[error("{path}: bad channel `{channel}`: {reason}")]
    BadChannel {
        /// The file concerned.
        path: PathBuf,
        /// The channel or layer name.
        channel: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The metadata attribute is missing or malformed.
    #[error("{path}: bad metadata attribute `{attribute}`: {reason}")]
    Metadata {
        /// The file concerned.
        path: PathBuf,
        /// The attribute name.
        attribute: String,
        /// What is wrong with it.
        reason: String,
    },
}

/// A dense float image: row-major, channels interleaved (`data[(y*width + x)*channels + c]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Channels per pixel.
    pub channels: usize,
    /// `width * height * channels` samples.
    pub data: Vec<f32>,
}

impl Image {
    /// A zero-filled image.
    pub fn new(width: usize, height: usize, channels: usize) -> Self {
        Self {
            width,
            height,
            channels,
            data: vec![0.0; width * height * channels],
        }
    }

    /// The sample at pixel (x, y), channel c.
    pub fn get(&self, x: usize, y: usize, c: usize) -> f32 {
        self.data[(y * self.width + x) * self.channels + c]
    }

    /// Sets the sample at pixel (x, y), channel c.
    pub fn set(&mut self, x: usize, y: usize, c: usize, value: f32) {
        self.data[(y * self.width + x) * self.channels + c] = value;
    }

    /// The channels of pixel (x, y).
    pub fn pixel(&self, x: usize, y: usize) -> &[f32] {
        let start = (y * self.width + x) * self.channels;
        &self.data[start..start + self.channels]
    }

    /// Relative MSE against `reference` (docs/method.md §5.6): mean over pixels and the first
    /// three channels of (x − r)² / (mean_RGB(r)² + 0.01), summed in f64. Both must be RGB
    /// (or RGB-first) images of the same size.
    pub fn relmse(&self, reference: &Image) -> f64 {
        assert_eq!(
            (self.width, self.height),
            (reference.width, reference.height),
            "image sizes differ"
        );
        let (a, b) = (self.channels, reference.channels);
        assert!(a >= 3 && b >= 3, "relMSE needs RGB images");
        let pixels = self.width * self.height;
        let mut sum = 0.0f64;
        for p in 0..pixels {
            let r = &reference.data[p * b..p * b + 3];
            let mean = r.iter().map(|&v| f64::from(v)).sum::<f64>() / 3.0;
            let weight = 1.0 / (mean * mean + 0.01);
            for (c, &rc) in r.iter().enumerate() {
                let e = f64::from(self.data[p * a + c]) - f64::from(rc);
                sum += e * e * weight;
            }
        }
        sum / (3 * pixels.max(1)) as f64
    }

    /// Copies channel `c` out as a row-major plane.
    pub fn plane(&self, c: usize) -> Vec<f32> {
        // Whole pixels, then the channel: `step_by` compiles to a slow loop.
        self.data
            .chunks_exact(self.channels)
            .map(|pixel| pixel[c])
            .collect()
    }

    /// First non-finite sample as (x, y, channel index).
    pub fn find_non_finite(&self) -> Option<(usize, usize, usize)> {
        // Blocks without a NaN/Inf are passed by a branch-free test the compiler vectorises
        // (an exponent of all ones); `position` goes one value at a time.
        const BLOCK: usize = 256;
        let non_finite = |v: &f32| v.to_bits() & 0x7f80_0000 == 0x7f80_0000;
        let block = self
            .data
            .chunks(BLOCK)
            .position(|block| block.iter().fold(false, |any, v| any | non_finite(v)))?;
        let i = block * BLOCK
            + self.data[block * BLOCK..]
                .iter()
                .position(non_finite)
                .expect("the block holds one");
        let pixel = i / self.channels;
        Some((pixel % self.width, pixel / self.width, i % self.channels))
    }

    /// Checks the shape against the expected one.
    fn check_shape(
        &self,
        path: &Path,
        layer: &str,
        width: usize,
        height: usize,
        channels: usize,
    ) -> Result<(), BundleError> {
        let bad = |reason: String| BundleError::BadChannel {
            path: path.to_owned(),
            channel: layer.to_owned(),
            reason,
        };
        if self.width != width || self.height != height || self.channels != channels {
            return Err(bad(format!(
                "expected {width}x{height}x{channels}, got {}x{}x{}",
                self.width, self.height, self.channels
            )));
        }
        if self.data.len() != width * height * channels {
            return Err(bad(format!(
                "data holds {} samples, expected {}",
                self.data.len(),
                width * height * channels
            )));
        }
        Ok(())
    }
}

/// Metadata of a bundle, stored as JSON in the EXR header attribute [`META_ATTRIBUTE`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BundleMeta {
    /// Scene identifier (file stem or procedural scene id).
    pub scene: String,
    /// Render seed.
    pub seed: u64,
    /// SPPM passes accumulated.
    pub passes: u32,
    /// Photons emitted per pass.
    pub photons_per_pass: u64,
    /// Wall-clock render time in seconds up to this bundle.
    pub seconds: f64,
    /// Integrator name (`sppm-ml` or `sppm`).
    pub integrator: String,
    /// Radius schedule ([`SCHEDULES`]). Not written for `sppm`, so SPPM bundles keep the
    /// metadata they always had; a bundle without it is an SPPM one.
    #[serde(
        default = "default_schedule",
        skip_serializing_if = "is_default_schedule"
    )]
    pub schedule: String,
    /// Light samples of next-event estimation at each visible point (docs/sppm.md). Not
    /// written when one, so bundles rendered before the option keep their metadata; a bundle
    /// without it took one.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub emitter_samples: u32,
    /// Where multi-level SPPM gathered the sharp level's photons: `a` (eye subpath A's visible
    /// point, the paper's) or `both` (the mean of A's and B's; docs/sppm.md). Not written for
    /// `a`, so bundles rendered before the option keep their metadata.
    #[serde(default = "sharp_level_a", skip_serializing_if = "is_sharp_level_a")]
    pub sharp_level: String,
    /// Where the eye subpaths' random numbers came from across passes: `independent` draws or
    /// the `ldsampler` sequence (docs/sppm.md). Not written for `independent`, so bundles
    /// rendered before the option keep their metadata.
    #[serde(
        default = "sampler_independent",
        skip_serializing_if = "is_sampler_independent"
    )]
    pub sampler: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

/// [`DEFAULT_SCHEDULE`] as a `String` (serde's default of [`BundleMeta::schedule`]).
fn default_schedule() -> String {
    DEFAULT_SCHEDULE.into()
}

/// [`SHARP_LEVEL_A`] as a `String` (serde's default of [`BundleMeta::sharp_level`]).
fn sharp_level_a() -> String {
    SHARP_LEVEL_A.into()
}

/// Whether `name` is [`SHARP_LEVEL_A`] (then [`BundleMeta::sharp_level`] is not written).
fn is_sharp_level_a(name: &str) -> bool {
    name == SHARP_LEVEL_A
}

/// [`SAMPLER_INDEPENDENT`] as a `String` (serde's default of [`BundleMeta::sampler`]).
fn sampler_independent() -> String {
    SAMPLER_INDEPENDENT.into()
}

/// Whether `name` is [`SAMPLER_INDEPENDENT`] (then [`BundleMeta::sampler`] is not written).
fn is_sampler_independent(name: &str) -> bool {
    name == SAMPLER_INDEPENDENT
}

/// One (serde's default of [`BundleMeta::emitter_samples`]).
fn one() -> u32 {
    1
}

/// Whether `n` is one (then [`BundleMeta::emitter_samples`] is not written).
fn is_one(n: &u32) -> bool {
    *n == 1
}

/// Whether `schedule` is [`DEFAULT_SCHEDULE`] (then it is not written).
fn is_default_schedule(schedule: &str) -> bool {
    schedule == DEFAULT_SCHEDULE
}

/// The radiance each eye subpath gathered without photons — emission seen directly or through
/// specular bounces, next-event estimation — averaged over passes: the part of ỹ (path A) and
/// of every z̃ level (path B) that is not a photon-density estimate (docs/method.md §4).
#[derive(Debug, Clone, PartialEq)]
pub struct DirectLight {
    /// Path A's part of ỹ, RGB (layer `ydirect`).
    pub y: Image,
    /// Path B's part of z̃1..z̃4, RGB (layer `zdirect`).
    pub z: Image,
    /// Variance of the mean of each, averaged over RGB: 2 channels in [`DIRECT_NAMES`] order
    /// (layer `directvariance`).
    pub variance: Image,
}

/// Channel names of the `directvariance` layer: path A's part (in `y`), path B's (in the z̃).
pub const DIRECT_NAMES: [&str; 2] = ["y", "z"];

/// One rendered sample: five estimates, their variances and the G-buffer.
#[derive(Debug, Clone, PartialEq)]
pub struct Bundle {
    /// Metadata written to the EXR header.
    pub meta: BundleMeta,
    /// Five RGB images in [`LEVEL_NAMES`] order.
    pub levels: Vec<Image>,
    /// Variance of the mean, averaged over RGB: 5 channels in [`LEVEL_NAMES`] order.
    pub variance: Image,
    /// Albedo at path A's visible point, RGB.
    pub albedo: Image,
    /// World-space shading normal at path A's visible point, XYZ.
    pub normal: Image,
    /// Camera distance along path A to its visible point, 1 channel.
    pub depth: Image,
    /// Current kernel radius per level, 5 channels in [`LEVEL_NAMES`] order.
    pub radius: Option<Image>,
    /// The photon-free part of the levels (bundles rendered before it existed have none).
    pub direct: Option<DirectLight>,
}

impl Bundle {
    /// All layers as (layer name, channel names, image), in file-documentation order.
    fn layers(&self) -> Vec<(&'static str, Vec<&'static str>, &Image)> {
        let mut out: Vec<(&'static str, Vec<&'static str>, &Image)> = Vec::new();
        for (name, img) in LEVEL_NAMES.iter().zip(&self.levels) {
            out.push((name, RGB.to_vec(), img));
        }
        out.push(("variance", LEVEL_NAMES.to_vec(), &self.variance));
        out.push(("albedo", RGB.to_vec(), &self.albedo));
        out.push(("normal", XYZ.to_vec(), &self.normal));
        out.push(("depth", vec!["Z"], &self.depth));
        if let Some(radius) = &self.radius {
            out.push(("radius", LEVEL_NAMES.to_vec(), radius));
        }
        if let Some(direct) = &self.direct {
            out.push(("ydirect", RGB.to_vec(), &direct.y));
            out.push(("zdirect", RGB.to_vec(), &direct.z));
            out.push(("directvariance", DIRECT_NAMES.to_vec(), &direct.variance));
        }
        out
    }

    /// The first non-finite sample as (layer, channel, x, y), or `None` if all are finite.
    pub fn find_non_finite(&self) -> Option<(&'static str, &'static str, usize, usize)> {
        // Every layer scanned on every core at once; the first one in layer order is reported.
        self.layers()
            .into_par_iter()
            .find_map_first(|(layer, channels, img)| {
                img.find_non_finite()
                    .map(|(x, y, c)| (layer, channels[c], x, y))
            })
    }

    /// Checks level count and that every layer matches the metadata's resolution.
    fn validate(&self, path: &Path) -> Result<(), BundleError> {
        if self.levels.len() != LEVEL_NAMES.len() {
            return Err(BundleError::BadChannel {
                path: path.to_owned(),
                channel: "levels".into(),
                reason: format!("expected 5 levels, got {}", self.levels.len()),
            });
        }
        let (w, h) = (self.meta.width as usize, self.meta.height as usize);
        for (layer, channels, img) in self.layers() {
            img.check_shape(path, layer, w, h, channels.len())?;
        }
        Ok(())
    }
}

/// Writes (full channel name, plane) pairs and text attributes as one EXR through
/// [`fileio::exr`], the error naming `path`.
fn write_exr(
    path: &Path,
    width: usize,
    height: usize,
    channels: Vec<(String, Vec<f32>)>,
    attributes: &[(&str, &[u8])],
) -> Result<(), BundleError> {
    fileio::exr::write_channels(path, width, height, channels, attributes).map_err(|e| {
        let path = path.to_owned();
        match e {
            ExrError::Io(error) => BundleError::Io { path, error },
            ExrError::Exr(error) => BundleError::Exr { path, error },
            ExrError::ChannelName { name, why } => BundleError::BadChannel {
                path,
                channel: name,
                reason: format!("the name {why}"),
            },
            ExrError::Size { name, len, .. } => BundleError::BadChannel {
                path,
                channel: name,
                reason: format!("{len} values for a {width}x{height} image"),
            },
            ExrError::Header(reason) => BundleError::Metadata {
                path,
                attribute: "header".into(),
                reason,
            },
        }
    })
}

/// Writes a bundle as one multi-layer float32 EXR, atomically (temp file + rename).
pub fn write_bundle(path: &Path, b: &Bundle) -> Result<(), BundleError> {
    b.validate(path)?;
    let mut channels = Vec::new();
    for (layer, names, img) in b.layers() {
        for (c, name) in names.iter().enumerate() {
            channels.push((format!("{layer}.{name}"), img.plane(c)));
        }
    }
    let json = serde_json::to_string(&b.meta).map_err(|e| BundleError::Metadata {
        path: path.to_owned(),
        attribute: META_ATTRIBUTE.into(),
        reason: e.to_string(),
    })?;
    // OpenEXR string attributes are byte strings; UTF-8 passes through unchanged.
    write_exr(
        path,
        b.meta.width as usize,
        b.meta.height as usize,
        channels,
        &[
            (META_ATTRIBUTE, json.as_bytes()),
            (FORMAT_ATTRIBUTE, FORMAT_VERSION.as_bytes()),
        ],
    )
}

/// A decoded EXR: resolution, channel planes by full name, header attributes.
struct Decoded {
    width: usize,
    height: usize,
    planes: HashMap<String, Vec<f32>>,
    attributes: HashMap<Text, AttributeValue>,
}

impl Decoded {
    /// Reads the first layer of an EXR with all channels and attributes ([`fileio::exr`]).
    fn read(path: &Path) -> Result<Self, BundleError> {
        let read = fileio::exr::read_channels(path).map_err(|e| {
            let path = path.to_owned();
            match e {
                ExrReadError::Io(error) => BundleError::Io { path, error },
                ExrReadError::Exr(error) => BundleError::Exr { path, error },
                ExrReadError::DataWindow(reason) => BundleError::Metadata {
                    path,
                    attribute: "dataWindow".into(),
                    reason,
                },
            }
        })?;
        Ok(Self {
            width: read.width,
            height: read.height,
            planes: read.planes,
            attributes: read.attributes,
        })
    }

    /// Assembles an interleaved image from the channels `layer.name` (or bare `name` if `layer`
    /// is empty).
    fn image(&self, path: &Path, layer: &str, names: &[&str]) -> Result<Image, BundleError> {
        let mut img = Image::new(self.width, self.height, names.len());
        for (c, name) in names.iter().enumerate() {
            let full = if layer.is_empty() {
                (*name).to_owned()
            } else {
                format!("{layer}.{name}")
            };
            let plane = self
                .planes
                .get(&full)
                .ok_or_else(|| BundleError::MissingChannel {
                    path: path.to_owned(),
                    channel: full.clone(),
                })?;
            if plane.len() != self.width * self.height {
                return Err(BundleError::BadChannel {
                    path: path.to_owned(),
                    channel: full,
                    reason: format!(
                        "{} samples for a {}x{} image",
                        plane.len(),
                        self.width,
                        self.height
                    ),
                });
            }
            for (i, v) in plane.iter().enumerate() {
                img.data[i * names.len() + c] = *v;
            }
        }
        Ok(img)
    }

    /// The UTF-8 text of a string attribute.
    fn text_attribute(&self, path: &Path, name: &str) -> Result<String, BundleError> {
        let bad = |reason: &str| BundleError::Metadata {
            path: path.to_owned(),
            attribute: name.to_owned(),
            reason: reason.to_owned(),
        };
        match self.attributes.get(&Text::from(name)) {
            Some(AttributeValue::Text(text)) => {
                String::from_utf8(text.as_slice().to_vec()).map_err(|_| bad("not valid UTF-8"))
            }
            Some(_) => Err(bad("not a string attribute")),
            None => Err(bad("missing")),
        }
    }
}

/// Checks what a bundle's header says about its origin: the format version this code reads,
/// and metadata a render can write (a known integrator, at least one pass).
fn check_meta(path: &Path, decoded: &Decoded, meta: &BundleMeta) -> Result<(), BundleError> {
    let format = decoded
        .text_attribute(path, FORMAT_ATTRIBUTE)
        .map_err(|e| match e {
            BundleError::Metadata { attribute, .. } => BundleError::Metadata {
                path: path.to_owned(),
                attribute,
                reason: format!(
                    "missing or unreadable: not a bundle written by this toolkit (expected \
                     \"{FORMAT_VERSION}\")"
                ),
            },
            other => other,
        })?;
    let bad = |attribute: &str, reason: String| BundleError::Metadata {
        path: path.to_owned(),
        attribute: attribute.into(),
        reason,
    };
    if format != FORMAT_VERSION {
        return Err(bad(
            FORMAT_ATTRIBUTE,
            format!("\"{format}\", but this build reads \"{FORMAT_VERSION}\""),
        ));
    }
    // The metadata strings that name one of a fixed set, in the order they are reported.
    let named: [(&str, &str, &[&str]); 4] = [
        ("integrator", &meta.integrator, &INTEGRATORS),
        ("sharp_level", &meta.sharp_level, &SHARP_LEVELS),
        ("sampler", &meta.sampler, &SAMPLERS),
        ("schedule", &meta.schedule, &SCHEDULES),
    ];
    for (key, value, allowed) in named {
        if !allowed.contains(&value) {
            return Err(bad(
                META_ATTRIBUTE,
                format!("{key} \"{value}\" (expected one of {allowed:?})"),
            ));
        }
    }
    if meta.passes == 0 {
        return Err(bad(META_ATTRIBUTE, "passes is 0".into()));
    }
    if meta.emitter_samples == 0 {
        return Err(bad(META_ATTRIBUTE, "emitter_samples is 0".into()));
    }
    Ok(())
}

/// The first negative sample of `img` as (x, y, channel index): variances, radii and depths
/// are never negative.
fn find_negative(img: &Image) -> Option<(usize, usize, usize)> {
    let i = img.data.iter().position(|v| *v < 0.0)?;
    let pixel = i / img.channels;
    Some((pixel % img.width, pixel / img.width, i % img.channels))
}

/// Reads a bundle written by [`write_bundle`]; errors name the file and the missing or bad
/// channel or attribute.
pub fn read_bundle(path: &Path) -> Result<Bundle, BundleError> {
    let decoded = Decoded::read(path)?;
    // No metadata at all: most likely an ordinary image (a reference, a render) given where a
    // bundle belongs; say so rather than only that an attribute is missing.
    if !decoded.attributes.contains_key(&Text::from(META_ATTRIBUTE)) {
        return Err(BundleError::Metadata {
            path: path.to_owned(),
            attribute: META_ATTRIBUTE.into(),
            reason: "missing: this EXR is not a sample bundle (bundles are written by `render \
                     --integrator sppm-ml` or `sppm`, `infer --scene` and `datagen render`; \
                     docs/formats.md)"
                .into(),
        });
    }
    let json = decoded.text_attribute(path, META_ATTRIBUTE)?;
    let meta: BundleMeta = serde_json::from_str(&json).map_err(|e| BundleError::Metadata {
        path: path.to_owned(),
        attribute: META_ATTRIBUTE.into(),
        reason: e.to_string(),
    })?;
    check_meta(path, &decoded, &meta)?;
    if meta.width as usize != decoded.width || meta.height as usize != decoded.height {
        return Err(BundleError::Metadata {
            path: path.to_owned(),
            attribute: META_ATTRIBUTE.into(),
            reason: format!(
                "metadata says {}x{}, image is {}x{}",
                meta.width, meta.height, decoded.width, decoded.height
            ),
        });
    }
    let levels = LEVEL_NAMES
        .iter()
        .map(|level| decoded.image(path, level, &RGB))
        .collect::<Result<Vec<_>, _>>()?;
    let radius = if decoded.planes.keys().any(|k| k.starts_with("radius.")) {
        Some(decoded.image(path, "radius", &LEVEL_NAMES)?)
    } else {
        None
    };
    let has_layer = |layer: &str| {
        decoded
            .planes
            .keys()
            .any(|k| k.strip_prefix(layer).is_some_and(|c| c.starts_with('.')))
    };
    // All photon-free layers or none: some alone cannot be used and mean a damaged file.
    let direct = if ["ydirect", "zdirect", "directvariance"]
        .iter()
        .any(|l| has_layer(l))
    {
        Some(DirectLight {
            y: decoded.image(path, "ydirect", &RGB)?,
            z: decoded.image(path, "zdirect", &RGB)?,
            variance: decoded.image(path, "directvariance", &DIRECT_NAMES)?,
        })
    } else {
        None
    };
    let bundle = Bundle {
        meta,
        levels,
        variance: decoded.image(path, "variance", &LEVEL_NAMES)?,
        albedo: decoded.image(path, "albedo", &RGB)?,
        normal: decoded.image(path, "normal", &XYZ)?,
        depth: decoded.image(path, "depth", &["Z"])?,
        radius,
        direct,
    };
    let non_negative: [(&str, &[&str], Option<&Image>); 6] = [
        ("variance", &LEVEL_NAMES, Some(&bundle.variance)),
        ("radius", &LEVEL_NAMES, bundle.radius.as_ref()),
        ("depth", &["Z"], Some(&bundle.depth)),
        ("ydirect", &RGB, bundle.direct.as_ref().map(|d| &d.y)),
        ("zdirect", &RGB, bundle.direct.as_ref().map(|d| &d.z)),
        (
            "directvariance",
            &DIRECT_NAMES,
            bundle.direct.as_ref().map(|d| &d.variance),
        ),
    ];
    for (layer, names, img) in non_negative {
        if let Some((x, y, c)) = img.and_then(find_negative) {
            return Err(BundleError::BadChannel {
                path: path.to_owned(),
                channel: format!("{layer}.{}", names[c]),
                reason: format!("negative value at pixel ({x}, {y})"),
            });
        }
    }
    Ok(bundle)
}

/// The reference of scene `scene_id` in a directory of references: `<dir>/<scene id>.exr`, the
/// layout of a dataset's `references/` and of the averaged references that may replace them.
pub fn scene_reference_path(dir: &Path, scene_id: &str) -> PathBuf {
    dir.join(format!("{scene_id}.exr"))
}

/// Writes a plain RGB float32 EXR (channels `R`, `G`, `B`), atomically (temp file + rename).
pub fn write_rgb_exr_image(path: &Path, img: &Image) -> Result<(), BundleError> {
    img.check_shape(path, "RGB", img.width, img.height, 3)?;
    let channels = RGB
        .iter()
        .enumerate()
        .map(|(c, name)| ((*name).to_owned(), img.plane(c)))
        .collect();
    write_exr(path, img.width, img.height, channels, &[])
}

/// Reads the `R`, `G`, `B` channels of an EXR (other channels, e.g. `A`, are ignored).
pub fn read_rgb_exr_image(path: &Path) -> Result<Image, BundleError> {
    Decoded::read(path)?.image(path, "", &RGB)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relmse_of_an_image_is_the_method_metric() {
        // Pixel 0: reference (1, 1, 1), image off by 0.5 in red: 0.25 / 1.01 / 3.
        // Pixel 1: reference black, image (0, 0.2, 0): 0.04 / 0.01 / 3.
        let mut reference = Image::new(2, 1, 3);
        reference.data[..3].copy_from_slice(&[1.0, 1.0, 1.0]);
        let mut image = reference.clone();
        image.data[0] = 1.5;
        image.data[4] = 0.2;
        let expected = (0.25 / 1.01 + 0.04 / 0.01) / 6.0;
        assert!((image.relmse(&reference) - expected).abs() < 1e-6);
        assert_eq!(reference.relmse(&reference), 0.0);
    }

    /// The value [`sample_bundle`] puts at interleaved index `i` of the layer with `salt`.
    fn sample_value(salt: f32, i: usize) -> f32 {
        salt + i as f32 * 0.25 - (i % 7) as f32 * 1e-3
    }

    /// A bundle with distinct, position-dependent values in every channel: sample `i` of a
    /// layer is [`sample_value`]`(salt, i)`, salts y 0, z1 100, z2 200, z3 300, z4 400,
    /// variance 1000, albedo 2000, normal −3000, depth 4000, radius 5000, ydirect 6000,
    /// zdirect 7000, directvariance 8000; `with_optional` adds the optional layers.
    fn sample_bundle(width: usize, height: usize, with_optional: bool) -> Bundle {
        let fill = |channels: usize, salt: f32| {
            let mut img = Image::new(width, height, channels);
            for (i, v) in img.data.iter_mut().enumerate() {
                *v = sample_value(salt, i);
            }
            img
        };
        Bundle {
            meta: BundleMeta {
                scene: "cornell-box ü".into(),
                seed: 42,
                passes: 128,
                photons_per_pass: 100_000,
                seconds: 12.5,
                integrator: "sppm-ml".into(),
                schedule: DEFAULT_SCHEDULE.into(),
                emitter_samples: 1,
                sharp_level: "a".into(),
                sampler: SAMPLER_INDEPENDENT.into(),
                width: width as u32,
                height: height as u32,
            },
            levels: (0..5).map(|l| fill(3, l as f32 * 100.0)).collect(),
            variance: fill(5, 1000.0),
            albedo: fill(3, 2000.0),
            normal: fill(3, -3000.0),
            depth: fill(1, 4000.0),
            radius: with_optional.then(|| fill(5, 5000.0)),
            direct: with_optional.then(|| DirectLight {
                y: fill(3, 6000.0),
                z: fill(3, 7000.0),
                variance: fill(2, 8000.0),
            }),
        }
    }

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("bundle-test-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn bundle_round_trip_is_exact() {
        let dir = temp_dir("roundtrip");
        for with_optional in [false, true] {
            let b = sample_bundle(7, 5, with_optional);
            let path = dir.join(format!("b{with_optional}.exr"));
            write_bundle(&path, &b).unwrap();
            let back = read_bundle(&path).unwrap();
            assert_eq!(back, b);
        }
        // No temp files are left behind.
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
            .collect();
        assert!(leftovers.is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A metadata string with a default: a bundle at the default has no `key` in its metadata
    /// JSON (what bundles from before the option held, so they read as the default), one set to
    /// `other` says so and reads back, and an unknown value is refused naming it.
    fn assert_written_unless_default(
        key: &str,
        default: &str,
        other: &str,
        unknown: &str,
        set: impl Fn(&mut BundleMeta, &str),
        get: impl Fn(&BundleMeta) -> &str,
    ) {
        let dir = temp_dir(key);
        let plain = sample_bundle(4, 3, false);
        let path = dir.join("plain.exr");
        write_bundle(&path, &plain).unwrap();
        let json = Decoded::read(&path)
            .unwrap()
            .text_attribute(&path, META_ATTRIBUTE)
            .unwrap();
        assert!(!json.contains(key), "{json}");
        assert_eq!(get(&read_bundle(&path).unwrap().meta), default);
        let mut changed = plain.clone();
        set(&mut changed.meta, other);
        let path = dir.join("changed.exr");
        write_bundle(&path, &changed).unwrap();
        assert_eq!(read_bundle(&path).unwrap(), changed);
        let mut bytes = std::fs::read(&path).unwrap();
        patch(
            &mut bytes,
            format!("\"{other}\"").as_bytes(),
            format!("\"{unknown}\"").as_bytes(),
        );
        std::fs::write(&path, &bytes).unwrap();
        let err = read_bundle(&path).unwrap_err().to_string();
        assert!(
            err.contains("changed.exr") && err.contains(&format!("{key} \"{unknown}\"")),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The radius schedule is written for CPPM only (old bundles read as SPPM) and checked.
    #[test]
    fn schedule_is_written_for_cppm_only_and_checked() {
        assert_written_unless_default(
            "schedule",
            "sppm",
            "cppm",
            "xppm",
            |m, v| m.schedule = v.into(),
            |m| &m.schedule,
        );
    }

    /// Where the sharp level was gathered is written for both subpaths only (old bundles read
    /// as gathered at A) and checked.
    #[test]
    fn sharp_level_is_written_for_both_only_and_checked() {
        assert_written_unless_default(
            "sharp_level",
            "a",
            "both",
            "bath",
            |m, v| m.sharp_level = v.into(),
            |m| &m.sharp_level,
        );
    }

    /// The eye sampler is written for the low-discrepancy sequence only (old bundles read as
    /// independent) and checked.
    #[test]
    fn sampler_is_written_for_ldsampler_only_and_checked() {
        assert_written_unless_default(
            "sampler",
            "independent",
            "ldsampler",
            "xdsampler",
            |m, v| m.sampler = v.into(),
            |m| &m.sampler,
        );
    }

    /// The written EXR has exactly the documented `layer.channel` names, each holding the
    /// values of the layer and channel it names (swapped layers or channels fail).
    #[test]
    fn channel_names_follow_the_documented_layout() {
        let dir = temp_dir("names");
        let path = dir.join("b.exr");
        write_bundle(&path, &sample_bundle(3, 2, true)).unwrap();
        let decoded = Decoded::read(&path).unwrap();
        let mut names: Vec<_> = decoded.planes.keys().cloned().collect();
        names.sort();
        let mut expected: Vec<String> = Vec::new();
        for l in LEVEL_NAMES {
            for c in RGB {
                expected.push(format!("{l}.{c}"));
            }
            expected.push(format!("variance.{l}"));
            expected.push(format!("radius.{l}"));
        }
        for c in RGB {
            expected.push(format!("albedo.{c}"));
        }
        for c in XYZ {
            expected.push(format!("normal.{c}"));
        }
        for c in RGB {
            expected.push(format!("ydirect.{c}"));
            expected.push(format!("zdirect.{c}"));
        }
        expected.push("directvariance.y".into());
        expected.push("directvariance.z".into());
        expected.push("depth.Z".into());
        expected.sort();
        assert_eq!(names, expected);
        // Each named channel holds the layer it names: (channel, salt of that layer in
        // `sample_bundle`, channels of the layer, index of the channel within it), written out
        // here from docs/formats.md rather than taken from the writer's layer table.
        let (width, height) = (3, 2);
        let mut layout: Vec<(String, f32, usize, usize)> = Vec::new();
        for (l, level) in ["y", "z1", "z2", "z3", "z4"].into_iter().enumerate() {
            for (c, channel) in ["R", "G", "B"].into_iter().enumerate() {
                layout.push((format!("{level}.{channel}"), l as f32 * 100.0, 3, c));
            }
            layout.push((format!("variance.{level}"), 1000.0, 5, l));
            layout.push((format!("radius.{level}"), 5000.0, 5, l));
        }
        for (c, channel) in ["R", "G", "B"].into_iter().enumerate() {
            layout.push((format!("albedo.{channel}"), 2000.0, 3, c));
        }
        for (c, channel) in ["X", "Y", "Z"].into_iter().enumerate() {
            layout.push((format!("normal.{channel}"), -3000.0, 3, c));
        }
        for (c, channel) in ["R", "G", "B"].into_iter().enumerate() {
            layout.push((format!("ydirect.{channel}"), 6000.0, 3, c));
            layout.push((format!("zdirect.{channel}"), 7000.0, 3, c));
        }
        layout.push(("directvariance.y".into(), 8000.0, 2, 0));
        layout.push(("directvariance.z".into(), 8000.0, 2, 1));
        layout.push(("depth.Z".into(), 4000.0, 1, 0));
        assert_eq!(layout.len(), names.len());
        for (name, salt, channels, c) in &layout {
            let plane = &decoded.planes[name];
            assert_eq!(plane.len(), width * height, "channel {name}: plane size");
            for (pixel, &got) in plane.iter().enumerate() {
                let want = sample_value(*salt, pixel * channels + c);
                assert!(
                    got == want,
                    "channel {name} at pixel ({}, {}): {got}, but its layer holds {want}",
                    pixel % width,
                    pixel / width
                );
            }
        }
        assert_eq!(
            decoded.text_attribute(&path, FORMAT_ATTRIBUTE).unwrap(),
            FORMAT_VERSION
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn truncated_file_is_an_error_naming_the_file() {
        let dir = temp_dir("truncated");
        let path = dir.join("b.exr");
        write_bundle(&path, &sample_bundle(16, 16, false)).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let cut = dir.join("cut.exr");
        for keep in [bytes.len() / 2, bytes.len() - 10, 40] {
            std::fs::write(&cut, &bytes[..keep]).unwrap();
            let err = read_bundle(&cut).unwrap_err();
            assert!(err.to_string().contains("cut.exr"), "{err}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Writes `sample_bundle(16, 16)` to `dir/name`, lets `edit` change its bytes, and returns
    /// the error of reading it back.
    fn read_edited(dir: &Path, name: &str, edit: impl FnOnce(&mut Vec<u8>)) -> String {
        let path = dir.join(name);
        write_bundle(&path, &sample_bundle(16, 16, true)).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        edit(&mut bytes);
        std::fs::write(&path, &bytes).unwrap();
        let err = read_bundle(&path).unwrap_err().to_string();
        assert!(err.contains(name), "{err}");
        err
    }

    /// Replaces the first occurrence of `from` in `bytes` by `to` (same length).
    fn patch(bytes: &mut [u8], from: &[u8], to: &[u8]) {
        assert_eq!(from.len(), to.len());
        let at = bytes
            .windows(from.len())
            .position(|w| w == from)
            .expect("pattern in file");
        bytes[at..at + to.len()].copy_from_slice(to);
    }

    /// A corrupt data window (one number of the header) is an error naming the attribute, not
    /// an abort on a failed multi-gigabyte allocation; so is a window not starting at (0, 0).
    #[test]
    fn a_corrupt_data_window_is_an_error_not_an_abort() {
        let dir = temp_dir("window");
        // The attribute: name, type, size 16, then xMin, yMin, xMax, yMax as i32.
        let window = |x0: i32, y0: i32, x1: i32, y1: i32| {
            let mut v = b"dataWindow\0box2i\0".to_vec();
            v.extend_from_slice(&16i32.to_le_bytes());
            for n in [x0, y0, x1, y1] {
                v.extend_from_slice(&n.to_le_bytes());
            }
            v
        };
        let original = window(0, 0, 15, 15);
        for (name, edited, value) in [
            ("tall.exr", window(0, 0, 15, 4_194_303), "16x4194304 pixels"),
            (
                "wide.exr",
                window(0, 0, 1 << 30, 15),
                "1073741825x16 pixels",
            ),
            ("offset.exr", window(-10, 0, 5, 15), "starts at (-10, 0)"),
        ] {
            let err = read_edited(&dir, name, |b| patch(b, &original, &edited));
            assert!(
                err.contains("`dataWindow`") && err.contains(value),
                "{name}: the error must name the attribute and \"{value}\": {err}"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The header must be this format's: another version, an unknown integrator, zero passes
    /// and negative variances, radii or depths are errors naming what is wrong.
    #[test]
    fn bundle_headers_and_non_negative_layers_are_checked() {
        let dir = temp_dir("header");
        let err = read_edited(&dir, "v2.exr", |b| {
            patch(b, FORMAT_VERSION.as_bytes(), b"sppm-ml-bundle/2")
        });
        assert!(
            err.contains("sppm-ml-bundle/2") && err.contains("this build reads"),
            "{err}"
        );
        let err = read_edited(&dir, "noformat.exr", |b| {
            patch(b, FORMAT_ATTRIBUTE.as_bytes(), b"bundleFormaX")
        });
        assert!(
            err.contains("not a bundle written by this toolkit"),
            "{err}"
        );
        let err = read_edited(&dir, "banana.exr", |b| {
            patch(b, b"\"sppm-ml\"", b"\"banana!\"")
        });
        assert!(err.contains("integrator \"banana!\""), "{err}");
        let err = read_edited(&dir, "passes.exr", |b| {
            patch(b, b"\"passes\":128", b"\"passes\":0  ")
        });
        assert!(err.contains("passes is 0"), "{err}");
        for (layer, channel, pixel) in [
            ("variance", 3, (2, 1)),
            ("radius", 0, (0, 0)),
            ("depth", 0, (5, 3)),
        ] {
            let mut b = sample_bundle(16, 16, true);
            let img = match layer {
                "variance" => &mut b.variance,
                "radius" => b.radius.as_mut().unwrap(),
                _ => &mut b.depth,
            };
            let i = (pixel.1 * 16 + pixel.0) * img.channels + channel;
            img.data[i] = -1.0;
            let path = dir.join(format!("neg-{layer}.exr"));
            write_bundle(&path, &b).unwrap();
            let err = read_bundle(&path).unwrap_err().to_string();
            assert!(
                err.contains(&format!("{layer}."))
                    && err.contains(&format!(
                        "negative value at pixel ({}, {})",
                        pixel.0, pixel.1
                    )),
                "{err}"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_channel_is_an_error_naming_it() {
        let dir = temp_dir("missing");
        let path = dir.join("partial.exr");
        let b = sample_bundle(4, 3, true);
        // Every documented channel but one: a level's, or one of the photon-free layers (the
        // other layer of the pair being there, the file is damaged, not an older bundle).
        for missing in ["z3.G", "zdirect.B", "ydirect.R", "directvariance.z"] {
            let mut channels = Vec::new();
            for (layer, names, img) in b.layers() {
                for (c, name) in names.iter().enumerate() {
                    let full = format!("{layer}.{name}");
                    if full != missing {
                        channels.push((full, img.plane(c)));
                    }
                }
            }
            let json = serde_json::to_string(&b.meta).unwrap();
            let attributes = [
                (META_ATTRIBUTE, json.as_bytes()),
                (FORMAT_ATTRIBUTE, FORMAT_VERSION.as_bytes()),
            ];
            write_exr(&path, 4, 3, channels, &attributes).unwrap();
            let err = read_bundle(&path).unwrap_err();
            let msg = err.to_string();
            assert!(matches!(err, BundleError::MissingChannel { .. }), "{msg}");
            assert!(
                msg.contains(missing) && msg.contains("partial.exr"),
                "{msg}"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_metadata_is_an_error() {
        let dir = temp_dir("nometa");
        let path = dir.join("ref.exr");
        write_rgb_exr_image(&path, &Image::new(2, 2, 3)).unwrap();
        let err = read_bundle(&path).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains(META_ATTRIBUTE) && msg.contains("not a sample bundle"),
            "{msg}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn wrong_shape_is_rejected_on_write() {
        let dir = temp_dir("shape");
        let mut b = sample_bundle(4, 3, false);
        b.albedo = Image::new(3, 3, 3);
        let err = write_bundle(&dir.join("b.exr"), &b).unwrap_err();
        assert!(err.to_string().contains("albedo"), "{err}");
        assert!(!dir.join("b.exr").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn non_finite_detection_names_layer_channel_and_pixel() {
        let mut b = sample_bundle(6, 4, true);
        assert_eq!(b.find_non_finite(), None);
        b.variance.set(5, 2, 3, f32::NAN);
        assert_eq!(b.find_non_finite(), Some(("variance", "z3", 5, 2)));
        b.levels[2].set(1, 3, 2, f32::INFINITY);
        assert_eq!(b.find_non_finite(), Some(("z2", "B", 1, 3)));
    }

    #[test]
    fn the_first_non_finite_value_is_found_in_any_block() {
        let mut img = Image::new(100, 30, 3);
        assert_eq!(img.find_non_finite(), None);
        img.data.fill(f32::MAX);
        assert_eq!(img.find_non_finite(), None);
        for (x, y, c, v) in [
            (99, 29, 2, f32::NAN),
            (40, 17, 1, f32::NEG_INFINITY),
            (85, 0, 0, -f32::NAN),
            (3, 0, 1, f32::INFINITY),
        ] {
            img.set(x, y, c, v);
            assert_eq!(img.find_non_finite(), Some((x, y, c)), "{v} at {x},{y},{c}");
        }
    }

    #[test]
    fn rgb_reference_round_trip() {
        let dir = temp_dir("rgb");
        let path = dir.join("ref.exr");
        let mut img = Image::new(5, 4, 3);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i as f32).sqrt() * 0.1;
        }
        write_rgb_exr_image(&path, &img).unwrap();
        assert_eq!(read_rgb_exr_image(&path).unwrap(), img);
        let err = read_rgb_exr_image(&dir.join("absent.exr")).unwrap_err();
        assert!(err.to_string().contains("absent.exr"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
