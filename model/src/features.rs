//! Feature packing: a sample bundle → the 27 network input planes and the 15 raw colour planes.
//!
//! Channel order of the features: log(1+x) of ỹ, z̃1..z̃4 (RGB each, 15), log(1+x) of the five
//! variances (5), albedo (3), shading normal (3), depth divided by the image's largest depth (1).
//! The log transform tames the HDR range for the network only; the combination itself uses the
//! raw linear colours. Depth is normalised per whole image, before any tiling, so tiles of an
//! image see the same values as the whole image.
//!
//! A bundle with the photon-free layers (`ydirect`, `zdirect`, `directvariance`) also packs
//! them: the combination filters the levels less their photon-free part and adds a weighted mean
//! of the two subpaths' parts back afterwards ([`split_direct`], docs/method.md §5.4), while the
//! features stay those of the whole levels.
//!
//! A network combining only some levels (the Dual(ỹ, z̃j) variant of paper Table 1) reads the
//! colour and variance planes of its levels plus the G-buffer, in the same order:
//! [`feature_channels`] and [`PackedImage::select_levels`] pick them out of the full packing.
//!
//! A model may read [`ExtraFeature`] planes after those 27 (docs/method.md §9, "Other weight
//! predictors"): how far ỹ and each z̃ʲ disagree against their noise, and the pass count —
//! what the first convolution cannot compute from log colours and log variances by itself.

use std::borrow::Cow;

use bundle::{Bundle, Image};
use serde::{Deserialize, Serialize};

use crate::network::{GBUFFER_CHANNELS, INPUT_CHANNELS, LEVELS};
use crate::screen_filter::ScreenFilters;

/// Number of raw colour planes: five RGB estimates.
pub const COLOUR_CHANNELS: usize = 3 * LEVELS;

/// Number of photon-free planes: path A's RGB (part of ỹ), path B's RGB (part of every z̃), the
/// variance of the mean of A's and of B's.
pub const DIRECT_CHANNELS: usize = 8;

/// A whole image's network input in planar layout (`plane[c][y * width + x]`).
#[derive(Clone, Debug, PartialEq)]
pub struct PackedImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// [`INPUT_CHANNELS`] transformed feature planes, then those of each of `extra`
    /// ([`ExtraFeature::planes`] of [`LEVELS`]).
    pub features: Vec<f32>,
    /// The extra feature planes packed after the 27, in this order.
    pub extra: Vec<ExtraFeature>,
    /// [`COLOUR_CHANNELS`] raw linear colour planes: ỹ RGB, z̃1 RGB, …, z̃4 RGB.
    pub levels: Vec<f32>,
    /// [`DIRECT_CHANNELS`] planes of the photon-free part: path A's (in ỹ) RGB, path B's (in
    /// every z̃ level) RGB, then the variance of the mean of A's and of B's; `None` for a bundle
    /// rendered without it.
    pub direct: Option<Vec<f32>>,
    /// The photon-free part to add to the combination's output when the model filters it
    /// ([`crate::screen_filter::DirectFilter`]): 3 planes, RGB. `None`: the fused `direct`
    /// layers as [`split_direct`] computes them.
    pub direct_added: Option<Vec<f32>>,
}

impl PackedImage {
    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// Raw planar RGB of level `level` (0 = ỹ, 1..4 = z̃1..z̃4).
    pub fn level(&self, level: usize) -> &[f32] {
        &self.levels[3 * level * self.pixels()..3 * (level + 1) * self.pixels()]
    }

    /// The network input of a model combining `levels` (indices into ỹ, z̃1..z̃4, as checked by
    /// [`crate::network::validate_levels`]): the feature planes of [`feature_channels`] and the raw
    /// colours of [`colour_channels`], in that order.
    pub fn select_levels(&self, levels: &[usize]) -> PackedImage {
        let pixels = self.pixels();
        let gather = |data: &[f32], planes: Vec<usize>| -> Vec<f32> {
            planes
                .into_iter()
                .flat_map(|c| data[c * pixels..(c + 1) * pixels].iter().copied())
                .collect()
        };
        PackedImage {
            width: self.width,
            height: self.height,
            features: gather(&self.features, feature_channels(levels, &self.extra)),
            extra: self.extra.clone(),
            levels: gather(&self.levels, colour_channels(levels)),
            direct: self.direct.clone(),
            direct_added: self.direct_added.clone(),
        }
    }

    /// The variances of the means of the image's `m` levels (the planes after their colours,
    /// [`feature_channels`]), undone from log(1 + v): planar `[m][pixels]`, the safeguard's input.
    pub fn variances(&self, m: usize) -> Vec<f32> {
        use rayon::prelude::*;
        let pixels = self.pixels();
        self.features[3 * m * pixels..4 * m * pixels]
            .par_iter()
            .map(|x| x.exp_m1())
            .collect()
    }

    /// The combination's inputs: the colour planes less their photon-free part (the planes
    /// themselves, not copied, when the image has none), and what is added to the combined
    /// image afterwards.
    pub fn combination_inputs(&self) -> (Cow<'_, [f32]>, Option<Vec<f32>>) {
        match &self.direct {
            None => (Cow::Borrowed(&self.levels), None),
            Some(direct) => {
                let pixels = self.pixels();
                let levels = without_direct(&self.levels, direct, pixels);
                let added = match &self.direct_added {
                    Some(added) => added.clone(),
                    None => fused_direct(direct, pixels),
                };
                (Cow::Owned(levels), Some(added))
            }
        }
    }
}

/// Takes the photon-free part out of planar colour planes `levels` (ỹ RGB first, then any
/// number of z̃ levels, `pixels` values per plane) in place, given `direct`
/// ([`DIRECT_CHANNELS`] planes: path A's RGB, path B's RGB, their variances of the mean), and
/// returns the three planes to add to the combined image: the two subpaths' parts weighted by
/// the inverse of their variances (equal weights where both variances are zero).
///
/// Why (docs/method.md §5.4): emission and next-event estimation are known per sample, and A and
/// B estimate them independently and alike. Left in the levels, Eq. 6 carries them through its
/// window (Σ_i w_i (ỹ_i − z̃_i): a light that path A saw in one pixel lights the whole window)
/// and never averages them (the output holds B's part at the pixel with weight one). Taken out,
/// the two estimates are fused per pixel; inverse-variance weights make that the mean where the
/// two agree in spread (their expected variances are equal) and trust the calm one where a
/// single rare sample — a sub-pixel light, a light seen through glass — made the other's
/// variance explode. Any weights in [0, 1] keep the sum between two estimates that converge, so
/// the output still converges.
pub fn split_direct(levels: &mut [f32], direct: &[f32], pixels: usize) -> Vec<f32> {
    check_direct_shapes(levels, direct, pixels);
    for (plane, level) in levels.chunks_exact_mut(pixels).enumerate() {
        for (v, d) in level
            .iter_mut()
            .zip(photon_free_part(direct, plane, pixels))
        {
            *v -= d;
        }
    }
    fused_direct(direct, pixels)
}

/// [`split_direct`]'s first half on a copy: the colour planes `levels` less their photon-free
/// part, computed plane by plane on every core (the same values).
pub fn without_direct(levels: &[f32], direct: &[f32], pixels: usize) -> Vec<f32> {
    use rayon::prelude::*;
    check_direct_shapes(levels, direct, pixels);
    let mut out = crate::native::zeros(levels.len());
    if pixels == 0 {
        return out;
    }
    out.par_chunks_mut(pixels)
        .zip(levels.par_chunks(pixels))
        .enumerate()
        .for_each(|(plane, (out, level))| {
            let part = photon_free_part(direct, plane, pixels);
            for ((o, v), d) in out.iter_mut().zip(level).zip(part) {
                *o = v - d;
            }
        });
    out
}

/// The photon-free part that colour plane `plane` (channel plane % 3 of level plane / 3)
/// carries: path A's for ỹ, path B's for every z̃.
fn photon_free_part(direct: &[f32], plane: usize, pixels: usize) -> &[f32] {
    let path = if plane < 3 { 0 } else { 3 };
    &direct[(path + plane % 3) * pixels..][..pixels]
}

/// [`split_direct`]'s second half: the two subpaths' photon-free parts weighted by the inverse
/// of their variances, three planes.
pub fn fused_direct(direct: &[f32], pixels: usize) -> Vec<f32> {
    use rayon::prelude::*;
    assert_eq!(direct.len(), DIRECT_CHANNELS * pixels, "direct planes");
    let (a, rest) = direct.split_at(3 * pixels);
    let (b, variances) = rest.split_at(3 * pixels);
    let (var_a, var_b) = variances.split_at(pixels);
    (0..3 * pixels)
        .into_par_iter()
        .map(|i| {
            let weight_a = subpath_a_weight(var_a[i % pixels], var_b[i % pixels]);
            weight_a * a[i] + (1.0 - weight_a) * b[i]
        })
        .collect()
}

/// The shapes [`split_direct`] needs.
fn check_direct_shapes(levels: &[f32], direct: &[f32], pixels: usize) {
    assert_eq!(direct.len(), DIRECT_CHANNELS * pixels, "direct planes");
    assert!(
        levels.len().is_multiple_of(3 * pixels) && levels.len() >= 6 * pixels,
        "colour planes of ỹ and at least one z level"
    );
}

/// The weight of path A's photon-free part in the fused one, given the variances of the means
/// of A's and B's: inverse-variance weights, equal where both are zero.
pub fn subpath_a_weight(var_a: f32, var_b: f32) -> f32 {
    if var_a + var_b > 0.0 {
        var_b / (var_a + var_b)
    } else {
        0.5
    }
}

/// Planes of the full feature packing (with the `extra` planes) that a network combining
/// `levels` reads: the log colours of its levels (RGB each), their log variances, the seven
/// G-buffer planes, then each extra feature's planes for those levels.
pub fn feature_channels(levels: &[usize], extra: &[ExtraFeature]) -> Vec<usize> {
    let colours = levels.iter().flat_map(|&l| 3 * l..3 * l + 3);
    let variances = levels.iter().map(|&l| COLOUR_CHANNELS + l);
    let gbuffer = COLOUR_CHANNELS + LEVELS..COLOUR_CHANNELS + LEVELS + GBUFFER_CHANNELS;
    let mut planes: Vec<usize> = colours.chain(variances).chain(gbuffer).collect();
    let mut start = INPUT_CHANNELS;
    for feature in extra {
        match feature {
            // Plane j − 1 is ỹ against z̃ʲ.
            ExtraFeature::Disagreement => {
                planes.extend(levels.iter().filter(|&&l| l > 0).map(|&l| start + l - 1))
            }
            ExtraFeature::Passes => planes.push(start),
        }
        start += feature.planes(LEVELS);
    }
    planes
}

/// Input planes a network may read beyond the paper's 27 (docs/method.md §9, "Other weight
/// predictors"), packed after them in the order a model lists them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ExtraFeature {
    /// One plane per correlated level z̃ʲ: log(1 + d² / (v_ỹ + v_j + ε·m²)), with d² the squared
    /// difference of ỹ and z̃ʲ (mean over RGB), v the variances of their means, m their mean
    /// and ε = [`DISAGREEMENT_FLOOR`]. Large where z̃ʲ's wider kernel is biased (a caustic line,
    /// a shadow edge) rather than noisy: the cue for weighing ỹ's side there. The network
    /// sees log colours and log variances, from which a few ReLU convolutions approximate this
    /// ratio only poorly.
    Disagreement,
    /// One plane, constant: log₂(passes) / 10. The levels' bias and noise shrink at different
    /// rates as passes grow (the radii as N^(−1/6), the variances as N^(−2/3)), so the best
    /// weights depend on the pass count, which the variances alone do not reveal.
    Passes,
}

/// Relative tolerance of [`ExtraFeature::Disagreement`]: a difference of 1 % of the levels'
/// mean counts as one standard deviation where the variances are zero (a converged or
/// noise-free pixel), so the plane stays finite and calm there.
pub const DISAGREEMENT_FLOOR: f32 = 1e-4;

impl ExtraFeature {
    /// Planes this feature gives a network combining `levels` estimates (ỹ and levels − 1
    /// correlated ones); with [`LEVELS`], what it adds to the full packing.
    pub fn planes(self, levels: usize) -> usize {
        match self {
            ExtraFeature::Disagreement => levels.saturating_sub(1),
            ExtraFeature::Passes => 1,
        }
    }
}

/// How a model packs a bundle: the screen-space filters applied to it first, and the extra
/// feature planes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Packing {
    /// Filtered levels and photon-free part ([`crate::screen_filter`]).
    pub screen: ScreenFilters,
    /// Extra planes after the 27 ([`ExtraFeature`]).
    pub extra: Vec<ExtraFeature>,
}

impl Packing {
    /// The bundle as rendered, the paper's 27 planes.
    pub fn none() -> Self {
        Self::default()
    }
}

/// Planes of the raw colours ([`PackedImage::levels`]) of `levels`, RGB each: the combination's
/// input, ỹ first.
pub fn colour_channels(levels: &[usize]) -> Vec<usize> {
    levels.iter().flat_map(|&l| 3 * l..3 * l + 3).collect()
}

/// Why a bundle cannot be packed; the caller adds the file name.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FeatureError {
    /// A layer's shape disagrees with the bundle's resolution or channel count.
    #[error("layer `{layer}`: expected {expected}, got {got}")]
    Shape {
        /// Layer name.
        layer: String,
        /// Expected `WxHxC`.
        expected: String,
        /// Found `WxHxC`.
        got: String,
    },
    /// A sample is NaN or infinite.
    #[error("non-finite value in layer `{layer}` channel `{channel}` at pixel ({x}, {y})")]
    NonFinite {
        /// Layer name.
        layer: String,
        /// Channel name.
        channel: String,
        /// Pixel column.
        x: usize,
        /// Pixel row.
        y: usize,
    },
}

/// Checks that `image` is `width`×`height`×`channels`.
fn check(
    image: &Image,
    layer: &str,
    width: usize,
    height: usize,
    channels: usize,
) -> Result<(), FeatureError> {
    if image.width != width
        || image.height != height
        || image.channels != channels
        || image.data.len() != width * height * channels
    {
        return Err(FeatureError::Shape {
            layer: layer.to_owned(),
            expected: format!("{width}x{height}x{channels}"),
            got: format!(
                "{}x{}x{} ({} samples)",
                image.width,
                image.height,
                image.channels,
                image.data.len()
            ),
        });
    }
    Ok(())
}

/// Appends the planes of an interleaved image, transformed by `f`.
fn push_planes(out: &mut Vec<f32>, image: &Image, f: impl Fn(f32) -> f32) {
    for c in 0..image.channels {
        out.extend(
            image
                .data
                .iter()
                .skip(c)
                .step_by(image.channels)
                .map(|&v| f(v)),
        );
    }
}

/// log(1+x) of a radiance or variance, clamped at zero first (estimates are non-negative; a
/// tiny negative from float round-off must not become NaN); `v` finite. In plain arithmetic the
/// compiler vectorises (the C library's `log1pf` is one call per value; 20 of the 27 feature
/// planes go through here): u = 1 + x rounded, log u = e·ln 2 + log m with m ∈ [√½, √2) by
/// Cephes' `logf` polynomial, plus (x − (u − 1)) / u for what the rounding of u lost. Within
/// 2⁻²³ of `ln_1p`, relative (tested).
#[inline(always)]
fn log_transform(v: f32) -> f32 {
    const SQRT_HALF: f32 = std::f32::consts::FRAC_1_SQRT_2;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let x = v.max(0.0);
    let u = 1.0 + x;
    let bits = u.to_bits();
    // u = m·2^e with m ∈ [½, 1); u ≥ 1, so it is normal and its sign bit clear.
    let mut e = ((bits >> 23) as i32 - 126) as f32;
    let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f00_0000);
    let small = m < SQRT_HALF;
    let f = if small { m + m - 1.0 } else { m - 1.0 };
    e = if small { e - 1.0 } else { e };
    let z = f * f;
    let p = ((((((((7.037_683_6e-2 * f - 1.151_461e-1) * f + 1.167_699_9e-1) * f
        - 1.242_014_1e-1)
        * f
        + 1.424_932_3e-1)
        * f
        - 1.666_805_8e-1)
        * f
        + 2.000_071_5e-1)
        * f
        - 2.499_999_4e-1)
        * f
        + 3.333_333e-1)
        * f
        * z;
    let log_u = (f + (p + e * LN2_LO - 0.5 * z)) + e * LN2_HI;
    log_u + (x - (u - 1.0)) / u
}

/// [`log_transform`] of every value of `plane`, in place: blocks of 16 (one AVX-512 vector,
/// two AVX2 ones) compiled for the best instruction set the CPU has. Rust never fuses a multiply
/// and an add, so every build computes the same bits.
fn log_transform_plane(plane: &mut [f32]) {
    #[inline(always)]
    fn portable(plane: &mut [f32]) {
        let mut blocks = plane.chunks_exact_mut(16);
        for block in &mut blocks {
            let block: &mut [f32; 16] = block.try_into().expect("a block of 16");
            for v in block.iter_mut() {
                *v = log_transform(*v);
            }
        }
        for v in blocks.into_remainder() {
            *v = log_transform(*v);
        }
    }
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f")]
        fn avx512(plane: &mut [f32]) {
            portable(plane)
        }
        #[target_feature(enable = "avx2")]
        fn avx2(plane: &mut [f32]) {
            portable(plane)
        }
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has AVX-512F (checked just above).
            return unsafe { avx512(plane) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { avx2(plane) };
        }
    }
    portable(plane)
}

/// Packs a bundle as a model's `packing` says: its screen filters ([`crate::screen_filter`]:
/// filtered levels in the place of some of the bundle's, a filtered photon-free part) applied
/// first, its extra planes after the 27; the bundle is checked as [`pack`] does.
pub fn pack_with(bundle: &Bundle, packing: &Packing) -> Result<PackedImage, FeatureError> {
    let screen = &packing.screen;
    // Shapes and values first: the filter reads the layers as the packing would.
    check_bundle(bundle)?;
    if screen.is_empty() {
        return Ok(pack_checked(bundle, &[], &packing.extra));
    }
    let filtered = crate::screen_filter::filtered(bundle, &screen.levels);
    let width = bundle.meta.width as usize;
    // Finite inputs can still overflow float32 in the filter's sums (values near f32::MAX).
    for f in &filtered {
        let name = bundle::LEVEL_NAMES[f.slot];
        let bad = |x: usize, y: usize, channel: &str| FeatureError::NonFinite {
            layer: format!("{name} (screen-filtered)"),
            channel: channel.into(),
            x,
            y,
        };
        if let Some((x, y, c)) = f.colour.find_non_finite() {
            return Err(bad(x, y, ["R", "G", "B"][c]));
        }
        if let Some(i) = f.variance.iter().position(|v| !v.is_finite()) {
            return Err(bad(i % width, i / width, "variance"));
        }
    }
    let direct = screen
        .direct
        .as_ref()
        .and_then(|d| crate::screen_filter::filtered_direct(bundle, d));
    if let Some((x, y, c)) = direct.as_ref().and_then(|d| d.find_non_finite()) {
        return Err(FeatureError::NonFinite {
            layer: "ydirect + zdirect (direct-filtered)".into(),
            channel: ["R", "G", "B"][c].into(),
            x,
            y,
        });
    }
    let mut packed = pack_checked(bundle, &filtered, &packing.extra);
    packed.direct_added = direct.map(|d| {
        use rayon::prelude::*;
        (0..3)
            .into_par_iter()
            .flat_map_iter(|k| d.plane(k))
            .collect()
    });
    Ok(packed)
}

/// Packs a bundle into network features and raw colours, rejecting bad shapes and NaN/Inf.
pub fn pack(bundle: &Bundle) -> Result<PackedImage, FeatureError> {
    check_bundle(bundle)?;
    Ok(pack_checked(bundle, &[], &[]))
}

/// Rejects a bundle whose layers have the wrong shape or hold NaN/Inf.
fn check_bundle(bundle: &Bundle) -> Result<(), FeatureError> {
    let width = bundle.meta.width as usize;
    let height = bundle.meta.height as usize;
    if bundle.levels.len() != LEVELS {
        return Err(FeatureError::Shape {
            layer: "levels".into(),
            expected: format!("{LEVELS} levels"),
            got: format!("{} levels", bundle.levels.len()),
        });
    }
    for (name, level) in bundle::LEVEL_NAMES.iter().zip(&bundle.levels) {
        check(level, name, width, height, 3)?;
    }
    check(&bundle.variance, "variance", width, height, LEVELS)?;
    check(&bundle.albedo, "albedo", width, height, 3)?;
    check(&bundle.normal, "normal", width, height, 3)?;
    check(&bundle.depth, "depth", width, height, 1)?;
    if let Some(d) = &bundle.direct {
        check(&d.y, "ydirect", width, height, 3)?;
        check(&d.z, "zdirect", width, height, 3)?;
        check(&d.variance, "directvariance", width, height, 2)?;
    }
    if let Some((layer, channel, x, y)) = bundle.find_non_finite() {
        return Err(FeatureError::NonFinite {
            layer: layer.into(),
            channel: channel.into(),
            x,
            y,
        });
    }
    Ok(())
}

/// How a packed plane is made from its source channel.
#[derive(Clone, Copy)]
enum Transform {
    Identity,
    Log,
    /// max(d, 0) · scale (depth over the image's largest depth).
    Scale(f32),
}

/// One value per pixel: a channel of an interleaved image, or a plane.
#[derive(Clone, Copy)]
enum Scalar<'a> {
    Channel(&'a Image, usize),
    Plane(&'a [f32]),
}

impl Scalar<'_> {
    /// The value at pixel `i`.
    #[inline(always)]
    fn at(self, i: usize) -> f32 {
        match self {
            Scalar::Channel(image, c) => image.data[i * image.channels + c],
            Scalar::Plane(plane) => plane[i],
        }
    }
}

/// Where a packed plane comes from.
#[derive(Clone, Copy)]
enum Source<'a> {
    /// Copied (and transformed).
    Value(Scalar<'a>),
    /// [`ExtraFeature::Disagreement`]'s ratio of ỹ (RGB, the variance of its mean) and a
    /// correlated level (the same).
    Disagreement {
        y: (&'a Image, Scalar<'a>),
        z: (&'a Image, Scalar<'a>),
    },
    /// The same value everywhere.
    Constant(f32),
}

/// [`ExtraFeature::Disagreement`]'s ratio at pixel `i` before its log: d² / (v_ỹ + v_z + ε·m²),
/// at most 10³⁰ (a finite plane whatever the inputs).
#[inline(always)]
fn disagreement(y: (&Image, Scalar), z: (&Image, Scalar), i: usize) -> f32 {
    let (mut d2, mut sum) = (0.0f32, 0.0f32);
    for c in 0..3 {
        let (a, b) = (y.0.data[3 * i + c], z.0.data[3 * i + c]);
        d2 += (a - b) * (a - b);
        sum += a + b;
    }
    let mean = sum / 6.0;
    let noise = y.1.at(i) + z.1.at(i) + DISAGREEMENT_FLOOR * mean * mean;
    (d2 / 3.0 / noise.max(f32::MIN_POSITIVE)).min(1e30)
}

/// Pixels per run of [`pack_checked`]'s planes: a run of every source and every plane (≈ 1 MiB
/// with photon-free layers) stays in a core's cache while its planes are filled.
const PACK_RUN: usize = 4096;

/// One packed plane's source and transform.
type PlaneJob<'a> = (Source<'a>, Transform);

/// [`pack`] of a checked bundle with `screen` levels in place of its own and the `extra`
/// planes after the 27. Every value is independent, so runs of pixels are filled in parallel
/// (the same values on any thread count).
fn pack_checked(
    bundle: &Bundle,
    screen: &[crate::screen_filter::FilteredLevel],
    extra: &[ExtraFeature],
) -> PackedImage {
    use rayon::prelude::*;
    let width = bundle.meta.width as usize;
    let height = bundle.meta.height as usize;
    let pixels = width * height;
    fn channels(image: &Image, t: Transform) -> impl Iterator<Item = (Source<'_>, Transform)> {
        (0..image.channels).map(move |c| (Source::Value(Scalar::Channel(image, c)), t))
    }
    let level = |i: usize| {
        screen
            .iter()
            .find(|f| f.slot == i)
            .map_or(&bundle.levels[i], |f| &f.colour)
    };
    let variance = |i: usize| {
        screen
            .iter()
            .find(|f| f.slot == i)
            .map_or(Scalar::Channel(&bundle.variance, i), |f| {
                Scalar::Plane(&f.variance)
            })
    };
    // Every buffer's planes, filled together in runs of pixels: a run of an interleaved image
    // read for one plane is still in the cache for the others taken from it (whole planes
    // read each image from memory once per channel and buffer).
    let fill = |buffers: Vec<Vec<PlaneJob>>| -> Vec<Vec<f32>> {
        let mut outs: Vec<Vec<f32>> = buffers
            .iter()
            .map(|planes| crate::native::zeros(planes.len() * pixels))
            .collect();
        // runs[i]: run i of every plane, with where its values come from.
        let mut runs: Vec<Vec<(&mut [f32], PlaneJob)>> = Vec::new();
        for (out, planes) in outs.iter_mut().zip(&buffers) {
            for (plane, &job) in out.chunks_mut(pixels.max(1)).zip(planes) {
                for (i, run) in plane.chunks_mut(PACK_RUN).enumerate() {
                    if runs.len() <= i {
                        runs.push(Vec::new());
                    }
                    runs[i].push((run, job));
                }
            }
        }
        runs.into_par_iter().enumerate().for_each(|(i, run)| {
            let start = i * PACK_RUN;
            for (values, (source, t)) in run {
                // The log is taken afterwards over the contiguous run (vectorised).
                let apply = |v: &mut f32, s: f32| {
                    *v = match t {
                        Transform::Identity | Transform::Log => s,
                        Transform::Scale(scale) => s.max(0.0) * scale,
                    }
                };
                let end = start + values.len();
                match source {
                    Source::Value(Scalar::Channel(image, c)) => {
                        // Whole pixels, then the channel: `step_by` compiles to a slow loop.
                        let n = image.channels;
                        let pixels = image.data[n * start..n * end].chunks_exact(n);
                        values
                            .iter_mut()
                            .zip(pixels)
                            .for_each(|(v, p)| apply(v, p[c]));
                    }
                    Source::Value(Scalar::Plane(plane)) => {
                        values
                            .iter_mut()
                            .zip(&plane[start..end])
                            .for_each(|(v, &s)| apply(v, s));
                    }
                    Source::Disagreement { y, z } => values
                        .iter_mut()
                        .enumerate()
                        .for_each(|(k, v)| apply(v, disagreement(y, z, start + k))),
                    Source::Constant(value) => values.fill(value),
                }
                if let Transform::Log = t {
                    log_transform_plane(values);
                }
            }
        });
        outs
    };
    let max_depth = bundle.depth.data.iter().fold(0.0f32, |m, &d| m.max(d));
    let scale = if max_depth > 0.0 {
        1.0 / max_depth
    } else {
        0.0
    };
    let mut buffers = vec![
        (0..LEVELS)
            .flat_map(|i| channels(level(i), Transform::Identity))
            .collect(),
        (0..LEVELS)
            .flat_map(|i| channels(level(i), Transform::Log))
            .chain((0..LEVELS).map(|i| (Source::Value(variance(i)), Transform::Log)))
            .chain(channels(&bundle.albedo, Transform::Identity))
            .chain(channels(&bundle.normal, Transform::Identity))
            .chain(channels(&bundle.depth, Transform::Scale(scale)))
            .chain(extra.iter().flat_map(|feature| -> Vec<PlaneJob> {
                match feature {
                    ExtraFeature::Disagreement => (1..LEVELS)
                        .map(|j| {
                            let y = (level(0), variance(0));
                            let z = (level(j), variance(j));
                            (Source::Disagreement { y, z }, Transform::Log)
                        })
                        .collect(),
                    ExtraFeature::Passes => {
                        let passes = bundle.meta.passes.max(1) as f32;
                        vec![(Source::Constant(passes.log2() / 10.0), Transform::Identity)]
                    }
                }
            }))
            .collect(),
    ];
    if let Some(d) = &bundle.direct {
        buffers.push(
            channels(&d.y, Transform::Identity)
                .chain(channels(&d.z, Transform::Identity))
                .chain(channels(&d.variance, Transform::Identity))
                .collect(),
        );
    }
    let mut filled = fill(buffers).into_iter();
    let (levels, features) = (
        filled.next().expect("the levels' buffer"),
        filled.next().expect("the features' buffer"),
    );
    let direct = filled.next();
    debug_assert_eq!(
        features.len(),
        (INPUT_CHANNELS + extra.iter().map(|f| f.planes(LEVELS)).sum::<usize>()) * pixels
    );
    debug_assert_eq!(levels.len(), COLOUR_CHANNELS * pixels);
    debug_assert!(direct
        .as_ref()
        .is_none_or(|d| d.len() == DIRECT_CHANNELS * pixels));
    PackedImage {
        width,
        height,
        features,
        extra: extra.to_vec(),
        levels,
        direct,
        direct_added: None,
    }
}

/// Converts an interleaved RGB reference image to planar layout, checking its size and values.
pub fn planar_reference(
    reference: &Image,
    width: usize,
    height: usize,
) -> Result<Vec<f32>, FeatureError> {
    check(reference, "reference", width, height, 3)?;
    if let Some(i) = reference.data.iter().position(|v| !v.is_finite()) {
        return Err(FeatureError::NonFinite {
            layer: "reference".into(),
            channel: ["R", "G", "B"][i % 3].into(),
            x: (i / 3) % width,
            y: (i / 3) / width,
        });
    }
    let mut out = Vec::with_capacity(3 * width * height);
    push_planes(&mut out, reference, |v| v);
    Ok(out)
}

/// Planar channels (`plane[c][y·w + x]`) → an interleaved bundle [`Image`]: the inverse of the
/// planar layout used for packing.
pub fn interleaved(planes: &[f32], w: usize, h: usize, channels: usize) -> Image {
    let mut img = Image::new(w, h, channels);
    for c in 0..channels {
        for p in 0..w * h {
            img.data[p * channels + c] = planes[c * w * h + p];
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::{all_levels, input_channels};

    /// A 2×1 packed image whose plane `c` holds `100·c + pixel`, so a value names its plane.
    fn labelled() -> PackedImage {
        let plane = |c: usize| [100.0 * c as f32, 100.0 * c as f32 + 1.0];
        PackedImage {
            width: 2,
            height: 1,
            features: (0..INPUT_CHANNELS).flat_map(plane).collect(),
            extra: Vec::new(),
            levels: (0..COLOUR_CHANNELS).flat_map(plane).collect(),
            direct: Some((0..DIRECT_CHANNELS).flat_map(|c| plane(50 + c)).collect()),
            direct_added: None,
        }
    }

    #[test]
    fn packing_with_screen_levels_equals_packing_the_filtered_bundle() {
        use crate::screen_filter::{apply, ScreenLevel};
        let (mut b, _) = crate::synthetic::synthetic_bundle(23, 11, 0.3, 3);
        b.meta.passes = 16;
        let screen = [
            ScreenLevel {
                slot: 4,
                source: 4,
                sigma: 2.0,
                range: 2.0,
            },
            ScreenLevel {
                slot: 2,
                source: 3,
                sigma: 1.0,
                range: 0.0,
            },
        ];
        let mut with_direct = b.clone();
        with_direct.direct = Some(bundle::DirectLight {
            y: b.levels[0].clone(),
            z: b.levels[1].clone(),
            variance: Image::new(23, 11, 2),
        });
        for bundle in [&b, &with_direct] {
            let filters = Packing {
                screen: ScreenFilters {
                    levels: screen.to_vec(),
                    direct: None,
                },
                extra: Vec::new(),
            };
            let packed = pack_with(bundle, &filters).unwrap();
            assert_eq!(packed, pack(&apply(bundle, &screen)).unwrap());
            assert_ne!(packed, pack(bundle).unwrap());
        }
        // A filtered value past float32's range is an error naming the screen level.
        let mut huge = b.clone();
        huge.levels[4].data.fill(f32::MAX);
        let first = Packing {
            screen: ScreenFilters {
                levels: screen[..1].to_vec(),
                direct: None,
            },
            extra: Vec::new(),
        };
        let err = pack_with(&huge, &first).unwrap_err().to_string();
        assert!(err.contains("screen-filtered"), "{err}");
    }

    /// The extra planes: the disagreement plane of each correlated level is log(1 + d² / (v_ỹ +
    /// v_j + ε m²)) from the (screen-filtered) levels and variances, zero where the two agree;
    /// the pass plane is log₂(passes) / 10; the 27 planes before them are `pack`'s; a Dual
    /// network's selection takes its level's disagreement plane.
    #[test]
    fn extra_planes_are_the_disagreement_and_the_pass_count() {
        let (mut b, _) = crate::synthetic::synthetic_bundle(9, 7, 0.3, 5);
        b.meta.passes = 256;
        // Pixel 3: ỹ equals z̃2 exactly.
        for c in 0..3 {
            b.levels[2].data[9 + c] = b.levels[0].data[9 + c];
        }
        let extra = vec![ExtraFeature::Passes, ExtraFeature::Disagreement];
        let packing = Packing {
            screen: ScreenFilters::none(),
            extra: extra.clone(),
        };
        let packed = pack_with(&b, &packing).unwrap();
        let pixels = 63;
        assert_eq!(packed.extra, extra);
        assert_eq!(packed.features.len(), (INPUT_CHANNELS + 5) * pixels);
        let plain = pack(&b).unwrap();
        assert_eq!(
            packed.features[..INPUT_CHANNELS * pixels],
            plain.features[..]
        );
        let plane = |k: usize| &packed.features[(INPUT_CHANNELS + k) * pixels..][..pixels];
        assert!(plane(0).iter().all(|&v| v == 0.8));
        for j in 1..LEVELS {
            for p in 0..pixels {
                let (y, z) = (
                    &b.levels[0].data[3 * p..3 * p + 3],
                    &b.levels[j].data[3 * p..3 * p + 3],
                );
                let d2: f64 = (0..3).map(|c| f64::from(y[c] - z[c]).powi(2)).sum::<f64>() / 3.0;
                let m: f64 = (0..3).map(|c| f64::from(y[c] + z[c])).sum::<f64>() / 6.0;
                let v = f64::from(b.variance.data[5 * p] + b.variance.data[5 * p + j]);
                let want = (d2 / (v + f64::from(DISAGREEMENT_FLOOR) * m * m)).ln_1p();
                let got = f64::from(plane(j)[p]);
                assert!(
                    (got - want).abs() <= 1e-5 * want.max(1.0),
                    "level {j} pixel {p}: {got} vs {want}"
                );
            }
        }
        assert_eq!(plane(2)[3], 0.0);
        assert!(plane(2).iter().filter(|&&v| v > 0.1).count() > pixels / 2);
        // A Dual(ỹ, z̃3) network reads its level's planes, the G-buffer, then the pass plane
        // and z̃3's disagreement plane, in the order of the model's list.
        let dual = packed.select_levels(&[0, 3]);
        assert_eq!(dual.features.len(), (input_channels(2) + 2) * pixels);
        let tail = &dual.features[input_channels(2) * pixels..];
        assert_eq!(&tail[..pixels], plane(0));
        assert_eq!(&tail[pixels..], plane(3));
        // The planes follow the screen-filtered level in its slot.
        let filtered = Packing {
            screen: ScreenFilters {
                levels: vec![crate::screen_filter::ScreenLevel {
                    slot: 4,
                    source: 4,
                    sigma: 2.0,
                    range: 0.0,
                }],
                direct: None,
            },
            extra: vec![ExtraFeature::Disagreement],
        };
        let with_screen = pack_with(&b, &filtered).unwrap();
        let last = |p: &PackedImage, k: usize| -> Vec<f32> {
            p.features[(INPUT_CHANNELS + k) * pixels..][..pixels].to_vec()
        };
        assert_eq!(last(&with_screen, 0), plane(1));
        assert_ne!(last(&with_screen, 3), plane(4));
    }

    /// Zero variances (a converged or empty pixel) leave the disagreement finite: equal black
    /// levels give 0, a difference with zero variance a large finite value.
    #[test]
    fn disagreement_stays_finite_without_noise() {
        let (mut b, _) = crate::synthetic::synthetic_bundle(4, 3, 0.3, 6);
        b.variance.data.fill(0.0);
        for level in &mut b.levels {
            level.data[..3].fill(0.0);
        }
        // Pixel 1: z̃1 at 1000 against ỹ at 0; pixel 2: near float32's range (d² overflows).
        b.levels[0].data[3..9].fill(0.0);
        b.levels[1].data[3..6].fill(1000.0);
        b.levels[1].data[6..9].fill(f32::MAX / 4.0);
        let packing = Packing {
            screen: ScreenFilters::none(),
            extra: vec![ExtraFeature::Disagreement],
        };
        let packed = pack_with(&b, &packing).unwrap();
        let plane = &packed.features[INPUT_CHANNELS * 12..][..12];
        assert_eq!(plane[0], 0.0);
        assert!(plane.iter().all(|v| v.is_finite()));
        assert!(plane[1] > 10.0 && plane[2] > plane[1], "{plane:?}");
    }

    #[test]
    fn log_transform_matches_the_c_library() {
        let mut values = vec![0.0f32, -0.0, -1e-7, f32::MIN_POSITIVE, 1e-45, f32::MAX];
        // Every 4093rd positive float, subnormals to f32::MAX (≈ 520 000 values).
        values.extend((0..0x7f7f_ffffu32).step_by(4093).map(f32::from_bits));
        values.extend((0..20_000).map(|i| i as f32 * 1e-4));
        values.extend((0..20_000).map(|i| 1.0 - i as f32 * 2.5e-5));
        let mut plane = values.clone();
        log_transform_plane(&mut plane);
        for (&v, &got) in values.iter().zip(&plane) {
            let want = v.max(0.0).ln_1p();
            assert!(
                (got - want).abs() <= want * 2f32.powi(-23) + f32::from_bits(1),
                "log1p({v:e}) = {got:e}, the C library {want:e}"
            );
            assert_eq!(got.to_bits(), log_transform(v).to_bits(), "at {v:e}");
        }
        assert_eq!(log_transform(0.0).to_bits(), 0);
    }

    #[test]
    fn all_levels_select_the_full_packing_unchanged() {
        assert_eq!(
            feature_channels(&all_levels(), &[]),
            (0..27).collect::<Vec<_>>()
        );
        assert_eq!(colour_channels(&all_levels()), (0..15).collect::<Vec<_>>());
        let p = labelled();
        assert_eq!(p.select_levels(&all_levels()), p);
    }

    #[test]
    fn dual_selection_picks_its_colours_variances_and_the_gbuffer() {
        // Dual(ỹ, z̃2): colours of ỹ (planes 0..3) and z̃2 (6..9), variances of ỹ (15) and z̃2
        // (17), then albedo, normal, depth (20..27).
        let want = vec![0, 1, 2, 6, 7, 8, 15, 17, 20, 21, 22, 23, 24, 25, 26];
        assert_eq!(feature_channels(&[0, 2], &[]), want);
        assert_eq!(want.len(), input_channels(2));
        assert_eq!(colour_channels(&[0, 2]), vec![0, 1, 2, 6, 7, 8]);
        let s = labelled().select_levels(&[0, 2]);
        let expect = |planes: &[usize]| -> Vec<f32> {
            planes
                .iter()
                .flat_map(|&c| [100.0 * c as f32, 100.0 * c as f32 + 1.0])
                .collect()
        };
        assert_eq!(s.features, expect(&want));
        assert_eq!(s.levels, expect(&[0, 1, 2, 6, 7, 8]));
        assert_eq!((s.width, s.height), (2, 1));
        assert_eq!(s.direct, labelled().direct);
    }

    #[test]
    fn split_direct_takes_each_subpaths_part_and_adds_their_weighted_mean() {
        // Two pixels; ỹ = 10 + pixel in every channel, z̃ levels 20 + …; path A's photon-free
        // part 4 (pixel 0) and 6 (pixel 1), path B's 2 and 0. Variances: equal at pixel 0 (the
        // mean, 3), A's three times B's at pixel 1 (B weighs 3/4: 1.5).
        let mut levels = Vec::new();
        for base in [10.0f32, 20.0, 30.0] {
            for _ in 0..3 {
                levels.extend([base, base + 1.0]);
            }
        }
        let mut direct = Vec::new();
        for part in [[4.0f32, 6.0], [2.0, 0.0]] {
            for _ in 0..3 {
                direct.extend(part);
            }
        }
        direct.extend([0.5, 3.0, 0.5, 1.0]);
        let added = split_direct(&mut levels, &direct, 2);
        assert_eq!(added, [3.0, 1.5].repeat(3));
        assert_eq!(&levels[..6], &[6.0, 5.0].repeat(3)[..]);
        assert_eq!(&levels[6..12], &[18.0, 21.0].repeat(3)[..]);
        assert_eq!(&levels[12..], &[28.0, 31.0].repeat(3)[..]);
        // No variance at all (a constant or no photon-free part): the plain mean.
        let mut levels = vec![1.0f32; 12];
        let mut direct = vec![0.0f32; 16];
        direct[..6].fill(1.0);
        assert_eq!(split_direct(&mut levels, &direct, 2), vec![0.5; 6]);
    }

    #[test]
    fn the_copying_halves_equal_split_direct() {
        // Every plane and pixel distinct, so a channel or level mixed up shows.
        let pixels = 3;
        let levels: Vec<f32> = (0..15 * pixels)
            .map(|i| 100.0 + (i * i % 17) as f32)
            .collect();
        let mut direct: Vec<f32> = (0..6 * pixels).map(|i| (i * 7 % 11) as f32).collect();
        direct.extend([0.5, 0.0, 2.0, 1.5, 0.0, 0.25]);
        let mut split = levels.clone();
        let added = split_direct(&mut split, &direct, pixels);
        assert_eq!(without_direct(&levels, &direct, pixels), split);
        assert_eq!(fused_direct(&direct, pixels), added);
    }
}
