//! Screen-space filtered levels (docs/method.md §9, "More correlated levels"): a correlated level
//! z̃ʲ smoothed across pixels by a cross-bilateral filter guided by the G-buffer, put in the
//! place of one of the bundle's levels before packing, its spatial bandwidth shrinking as passes
//! grow: σ(N) = σ₀ · (N / 64)^(−1/6), the rate at which SPPM's radii shrink.
//!
//! Why: Eq. 6 keeps z̃ʲ_c — the level at the pixel itself — in the output with weight one, and
//! every z̃ level carries eye subpath B's ray-tracing noise (glossy lobes, depth of field, the
//! pixel footprint), so no choice of weights removes it: the floor of the method. Averaged over
//! neighbouring pixels that see the same surface (same albedo, normal and depth), that noise
//! falls; the filter's blur is a bias that Eq. 6's difference terms z̃ʲ_c − z̃ʲ_i partly cancel and
//! the network can weigh against the unfiltered levels.
//!
//! Consistency: the filter's weight on any other pixel is at most exp(−1/(2σ²)), which vanishes
//! as σ(N) → 0, so the filtered level tends to the level itself, which converges to the true
//! image; Eq. 6 converges whatever its weights when all its levels do (§5.4). Beyond
//! [`MIN_SIGMA`] the filter is the identity exactly.
//!
//! With the photon-free layers (`ydirect`, `zdirect`), only the photon part of the level is
//! filtered (z̃ − d_B, then d_B added back): the combination takes d_B out of every z̃ level and
//! adds the fused direct light after Eq. 6, which must not be spread across pixels (a light seen
//! in one pixel would halo).
//!
//! The **direct filter** ([`DirectFilter`]) smooths that fused photon-free part itself with the
//! same cross-bilateral before it is added back: next-event estimation and emission through two
//! eye subpaths per pass are path-tracing noise that Eq. 6 never sees (47–79 % of the output's
//! error on glass, shelf and table-top scenes, docs/results.md). Its range term compares a
//! neighbour's difference with twice the *smaller* of the two pixels' variances, so a light or a
//! rare bright sample next to a calm pixel (large variance, large difference) is never averaged
//! into it: no halo. Same bandwidth rule, so it vanishes as passes grow like the screen levels.

use bundle::{Bundle, Image};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Pass count at which σ = σ₀.
pub const SIGMA_PASSES: f64 = 64.0;

/// Exponent of σ's decay with passes: SPPM's radii shrink as N^(−(1−α)/2) = N^(−1/6) with
/// α = 2/3, so the filter's bias falls as the kernel estimate's own.
pub const SIGMA_DECAY: f64 = 1.0 / 6.0;

/// Below this σ the filter is the identity (a neighbour's weight would be below e^−12.5).
pub const MIN_SIGMA: f64 = 0.2;

/// Widest filter radius in pixels.
pub const MAX_RADIUS: usize = 8;

/// The filter's radius in pixels at bandwidth `sigma`: ⌈2.5σ⌉, at most [`MAX_RADIUS`]. The
/// window is the disc of that radius, dx² + dy² ≤ r² (the isotropic cut of the Gaussian): the
/// square's corners beyond it carry a spatial weight of at most e^−3.1 before the guide's terms
/// and cost a third of the square's neighbours.
fn radius(sigma: f64) -> usize {
    ((2.5 * sigma).ceil() as usize).min(MAX_RADIUS)
}

/// Half-widths of the disc of radius `r`, row by row: entry |dy| is the largest dx with
/// dx² + dy² ≤ r².
fn disc_reach(r: usize) -> Vec<usize> {
    (0..=r)
        .map(|dy| {
            (0..=r)
                .rev()
                .find(|dx| dx * dx + dy * dy <= r * r)
                .unwrap_or(0)
        })
        .collect()
}

/// Guide tolerances: albedo difference (Euclidean, RGB in [0, 1]), shading-normal difference
/// (Euclidean between unit vectors: 0.3 ≈ 17°), difference of the log depths (≈ the relative
/// difference, the same read from either pixel).
const ALBEDO_SIGMA: f32 = 0.1;
const NORMAL_SIGMA: f32 = 0.3;
const DEPTH_SIGMA: f32 = 0.05;

/// One screen-space level: level `source` (1..4 = z̃1..z̃4) filtered with bandwidth `sigma` (in
/// pixels at [`SIGMA_PASSES`] passes), put in the place of level `slot` (1..4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScreenLevel {
    /// The level slot it replaces (1..4).
    pub slot: usize,
    /// The level it filters (1..4).
    pub source: usize,
    /// σ₀ in pixels at [`SIGMA_PASSES`] passes.
    pub sigma: f32,
    /// Strength k of the range term: a neighbour whose colour differs from the pixel's by more
    /// than their noise explains loses weight as exp(−max(0, d² − V) / (k² V)), with d² the
    /// squared difference (mean over RGB) and V the sum of the two pixels' variances. 0: no
    /// range term (the G-buffer alone).
    #[serde(default = "default_range")]
    pub range: f32,
}

/// The range strength of screen levels that name none: on a glossy shelf (data/small
/// 032-shelf, 100 000 photons, 64 and 256 passes) Eq. 6 with uniform guided weights over the
/// filtered z̃4 had 0.40× and 0.62× the error of the unfiltered one with k = 2, against 0.44× and
/// 0.88× with the G-buffer alone at its best σ (docs/results.md).
pub const DEFAULT_RANGE: f32 = 2.0;

/// Serde default of [`ScreenLevel::range`].
fn default_range() -> f32 {
    DEFAULT_RANGE
}

/// The direct filter's parameters: the fused photon-free part (emission and next-event
/// estimation of eye subpaths A and B) filtered across pixels before it is added to Eq. 6's
/// output, with bandwidth σ(N) = σ₀ (N/64)^(−1/6) like the screen levels.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DirectFilter {
    /// σ₀ in pixels at [`SIGMA_PASSES`] passes.
    pub sigma: f32,
    /// Strength k of the range term: a neighbour loses weight as exp(−max(0, d² − V) / (k² V))
    /// with V twice the smaller of the two pixels' variances (0: the G-buffer alone).
    #[serde(default = "default_direct_range")]
    pub range: f32,
}

/// The direct filter of `models/default`: σ₀ = 1 px, k = 4, chosen on 30 training scenes of
/// `large` (three per family, 64 passes of 100 000 photons, the shipped weights) from σ₀ ∈
/// {1, 2, 3} × k ∈ {1, 2, 4} × three range variances (sum, twice the smaller, twice the
/// centre's): the best geometric mean with no scene above 1.02× the unfiltered output
/// (docs/results.md, "The direct filter").
pub const DEFAULT_DIRECT_FILTER: DirectFilter = DirectFilter {
    sigma: 1.0,
    range: 4.0,
};

/// Serde default of [`DirectFilter::range`].
fn default_direct_range() -> f32 {
    DEFAULT_DIRECT_FILTER.range
}

/// Every screen-space filter a model applies to a bundle before its combination.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScreenFilters {
    /// Filtered levels put in the place of some of the bundle's.
    pub levels: Vec<ScreenLevel>,
    /// The direct filter, if any.
    pub direct: Option<DirectFilter>,
}

impl ScreenFilters {
    /// No filter at all: the bundle as rendered.
    pub fn none() -> Self {
        Self::default()
    }

    /// Whether the bundle is packed as rendered.
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty() && self.direct.is_none()
    }
}

/// σ at `passes` for a σ₀ of `sigma`.
pub fn sigma_at(sigma: f32, passes: u32) -> f64 {
    f64::from(sigma) * (f64::from(passes.max(1)) / SIGMA_PASSES).powf(-SIGMA_DECAY)
}

/// Checks a list of screen levels: slots and sources in 1..4, slots distinct, σ₀ positive and
/// finite.
pub fn validate(levels: &[ScreenLevel]) -> Result<(), String> {
    let mut slots = Vec::new();
    for (i, l) in levels.iter().enumerate() {
        if !(1..=4).contains(&l.slot) || !(1..=4).contains(&l.source) {
            return Err(format!(
                "screen_levels[{i}]: slot and source must be 1..4 (z1..z4), got slot {} source {}",
                l.slot, l.source
            ));
        }
        if !(l.sigma.is_finite() && l.sigma > 0.0) {
            return Err(format!(
                "screen_levels[{i}]: sigma must be a positive number of pixels, got {}",
                l.sigma
            ));
        }
        if !(l.range.is_finite() && l.range >= 0.0) {
            return Err(format!(
                "screen_levels[{i}]: range must be 0 (off) or positive, got {}",
                l.range
            ));
        }
        if slots.contains(&l.slot) {
            return Err(format!(
                "screen_levels[{i}]: slot {} is replaced twice",
                l.slot
            ));
        }
        slots.push(l.slot);
    }
    Ok(())
}

/// Checks a direct filter: σ₀ positive and finite, the range 0 or positive.
pub fn validate_direct(filter: &DirectFilter) -> Result<(), String> {
    if !(filter.sigma.is_finite() && filter.sigma > 0.0) {
        return Err(format!(
            "direct_filter: sigma must be a positive number of pixels, got {}",
            filter.sigma
        ));
    }
    if !(filter.range.is_finite() && filter.range >= 0.0) {
        return Err(format!(
            "direct_filter: range must be 0 (off) or positive, got {}",
            filter.range
        ));
    }
    Ok(())
}

/// One screen level's output: the filtered colour (interleaved RGB) and its variance plane,
/// for level slot `slot`.
pub struct FilteredLevel {
    /// The level slot it replaces (1..4).
    pub slot: usize,
    /// The filtered level, RGB.
    pub colour: Image,
    /// Its variance, one value per pixel.
    pub variance: Vec<f32>,
}

/// The screen levels of a bundle, each filtered from the original levels (so one level can
/// feed several slots). The caller has checked the bundle's shapes.
pub fn filtered(bundle: &Bundle, levels: &[ScreenLevel]) -> Vec<FilteredLevel> {
    levels
        .iter()
        .map(|l| {
            let sigma = sigma_at(l.sigma, bundle.meta.passes);
            let source = &bundle.levels[l.source];
            let direct = bundle.direct.as_ref().map(|d| &d.z);
            let (colour, variance) = filter(bundle, source, l.source, direct, sigma, l.range);
            FilteredLevel {
                slot: l.slot,
                colour,
                variance,
            }
        })
        .collect()
}

/// The bundle with its screen levels in place (a copy; `levels` empty: the bundle unchanged).
/// The caller has checked the bundle's shapes ([`crate::features::pack`] does it again).
pub fn apply(bundle: &Bundle, levels: &[ScreenLevel]) -> Bundle {
    let mut out = bundle.clone();
    for f in filtered(bundle, levels) {
        out.levels[f.slot] = f.colour;
        let channels = out.variance.channels;
        for (p, v) in f.variance.into_iter().enumerate() {
            out.variance.data[p * channels + f.slot] = v;
        }
    }
    out
}

/// Filters `level` (its variance: plane `index` of the bundle's variance layer) with bandwidth
/// `sigma` and range strength `range`, guided by the bundle's G-buffer; `direct`, when present,
/// is left unfiltered. Returns the filtered level and its variance Σ k² v / (Σ k)² (pixels taken
/// as independent).
fn filter(
    bundle: &Bundle,
    level: &Image,
    index: usize,
    direct: Option<&Image>,
    sigma: f64,
    range: f32,
) -> (Image, Vec<f32>) {
    let (w, h) = (level.width, level.height);
    let variance: Vec<f32> = bundle
        .variance
        .data
        .par_chunks_exact(bundle.variance.channels)
        .map(|pixel| pixel[index])
        .collect();
    debug_assert_eq!(variance.len(), w * h);
    if sigma < MIN_SIGMA {
        return (level.clone(), variance);
    }
    // Without photon-free layers the level itself is averaged (no copy).
    let photon = direct.map(|d| Image {
        data: level
            .data
            .par_iter()
            .zip(d.data.par_iter())
            .map(|(v, b)| v - b)
            .collect(),
        ..*level
    });
    cross_bilateral(
        bundle,
        level,
        photon.as_ref(),
        direct,
        variance,
        sigma,
        range,
        RangeNoise::Sum,
    )
}

/// How the range term reads the noise of a pixel pair.
#[derive(Clone, Copy, PartialEq)]
enum RangeNoise {
    /// v_c + v_n: the variance of the difference of two independent pixels.
    Sum,
    /// 2 · min(v_c, v_n): a neighbour whose own variance is large (a light, a rare bright
    /// sample) cannot use it to enter a calm pixel.
    TwiceMin,
}

/// The cross-bilateral of docs/method.md §9 at bandwidth `sigma` (≥ [`MIN_SIGMA`]): the
/// weights compare `colour` (with `variance`, one value per pixel) and the bundle's G-buffer;
/// `photon` (default `colour`) is what is averaged and `back` what is added afterwards. Returns
/// the filtered image and its variance Σ k² v / (Σ k)² (pixels taken as independent).
#[allow(clippy::too_many_arguments)]
fn cross_bilateral(
    bundle: &Bundle,
    colour: &Image,
    photon: Option<&Image>,
    back: Option<&Image>,
    variance: Vec<f32>,
    sigma: f64,
    range: f32,
    noise: RangeNoise,
) -> (Image, Vec<f32>) {
    let (w, h) = (colour.width, colour.height);
    let radius = radius(sigma);
    // Planar copies: each neighbour offset then runs along a row as one loop over contiguous
    // slices, which the compiler turns into vector instructions. Copied on every core at once.
    let sources: Vec<&Image> = [&bundle.albedo, &bundle.normal, colour]
        .into_iter()
        .chain(photon)
        .collect();
    let mut planes = sources
        .par_iter()
        .flat_map(|image| (0..3).into_par_iter().map(|k| image.plane(k)))
        .collect::<Vec<_>>()
        .into_iter();
    let mut three = || -> [Vec<f32>; 3] {
        std::array::from_fn(|_| planes.next().expect("three planes per source"))
    };
    // In the order of `sources`.
    let (albedo, normal, colour) = (three(), three(), three());
    let photon = photon.map(|_| three());
    let guides = Guides {
        width: w,
        height: h,
        albedo,
        normal,
        log_depth: bundle
            .depth
            .data
            .par_iter()
            .map(|d| d.max(1e-6).ln())
            .collect(),
        colour,
        photon,
        variance,
        reach: disc_reach(radius),
        radius,
        inv_space: (1.0 / (2.0 * sigma * sigma)) as f32,
        range,
        twice_min: noise == RangeNoise::TwiceMin,
    };
    let (mut out, mut out_var) = zeroed_rgb_and_plane(w, h);
    if w == 0 {
        return (out, out_var);
    }
    out.data
        .par_chunks_mut(3 * w * BAND_ROWS)
        .zip(out_var.par_chunks_mut(w * BAND_ROWS))
        .enumerate()
        .for_each_init(BandSums::default, |sums, (band, (colour, var))| {
            let y0 = band * BAND_ROWS;
            let y1 = (y0 + BAND_ROWS).min(h);
            guides.accumulate_band(y0, y1, sums);
            for (i, (rgb, var)) in colour.chunks_exact_mut(3).zip(var).enumerate() {
                let c = y0 * w + i;
                // The centre's own weight is 1, so the sum is ≥ 1.
                let sum = sums.weight[i];
                let back = back.map_or([0.0; 3], |d| {
                    [d.data[3 * c], d.data[3 * c + 1], d.data[3 * c + 2]]
                });
                for k in 0..3 {
                    rgb[k] = sums.colour[k][i] / sum + back[k];
                }
                *var = sums.variance[i] / (sum * sum);
            }
        });
    (out, out_var)
}

/// A zero RGB image and a zero plane of `w`×`h`, written on every core.
fn zeroed_rgb_and_plane(w: usize, h: usize) -> (Image, Vec<f32>) {
    let zeros = crate::native::zeros;
    let image = Image {
        width: w,
        height: h,
        channels: 3,
        data: zeros(3 * w * h),
    };
    (image, zeros(w * h))
}

/// The fused photon-free part of `bundle` (paths A and B weighted by the inverse of their
/// variances, as [`crate::features::split_direct`] fuses them), filtered by `filter` at the
/// bundle's pass count, interleaved RGB. `None` where there is nothing to filter: a bundle
/// without photon-free layers, or σ(N) below [`MIN_SIGMA`] (the filter is then the identity and
/// the combination fuses the layers itself).
pub fn filtered_direct(bundle: &Bundle, filter: &DirectFilter) -> Option<Image> {
    let direct = bundle.direct.as_ref()?;
    let sigma = sigma_at(filter.sigma, bundle.meta.passes);
    if sigma < MIN_SIGMA {
        return None;
    }
    let (w, h) = (direct.y.width, direct.y.height);
    let (mut fused, mut variance) = zeroed_rgb_and_plane(w, h);
    fused
        .data
        .par_chunks_exact_mut(3)
        .zip(variance.par_iter_mut())
        .enumerate()
        .for_each(|(p, (rgb, var))| {
            let (va, vb) = (direct.variance.data[2 * p], direct.variance.data[2 * p + 1]);
            let weight_a = crate::features::subpath_a_weight(va, vb);
            for (k, v) in rgb.iter_mut().enumerate() {
                let i = 3 * p + k;
                *v = weight_a * direct.y.data[i] + (1.0 - weight_a) * direct.z.data[i];
            }
            // The variance of the fused mean: weights a, 1 − a on independent estimates.
            *var = weight_a * weight_a * va + (1.0 - weight_a) * (1.0 - weight_a) * vb;
        });
    let (out, _) = cross_bilateral(
        bundle,
        &fused,
        None,
        None,
        variance,
        sigma,
        filter.range,
        RangeNoise::TwiceMin,
    );
    Some(out)
}

/// What the filter reads, planar (`plane[y·w + x]`), and its parameters.
struct Guides {
    width: usize,
    height: usize,
    albedo: [Vec<f32>; 3],
    normal: [Vec<f32>; 3],
    /// ln max(depth, 10⁻⁶): the depth term compares log depths, a relative difference that
    /// reads the same from either pixel (so one weight serves both of a pair).
    log_depth: Vec<f32>,
    /// The level filtered (the range term compares it).
    colour: [Vec<f32>; 3],
    /// What is averaged when the bundle has photon-free layers: the level less that part
    /// (`None`: the level, `colour`).
    photon: Option<[Vec<f32>; 3]>,
    variance: Vec<f32>,
    radius: usize,
    /// The disc window's half-width at each |dy| ([`disc_reach`]).
    reach: Vec<usize>,
    /// 1 / (2σ²).
    inv_space: f32,
    range: f32,
    /// The range term's noise is 2 · min(v_c, v_n) instead of v_c + v_n ([`RangeNoise`]).
    twice_min: bool,
}

/// Rows of output a band sums together: pairs reaching into the band from the r rows above
/// it are weighed again by it (≈ 7 % more pairs at r = 5), the price of bands summed apart.
const BAND_ROWS: usize = 32;

/// One band's running sums over the neighbours, band-local `i = (y − y0)·w + x`: Σ k,
/// Σ k·photon (per channel), Σ k²·v.
#[derive(Default)]
struct BandSums {
    weight: Vec<f32>,
    colour: [Vec<f32>; 3],
    variance: Vec<f32>,
}

impl BandSums {
    /// Adds the terms of pixels i .. i + L: Σ k, Σ k·photon, Σ k²·v.
    #[inline(always)]
    fn add<const L: usize>(
        &mut self,
        i: usize,
        weight: &[f32; L],
        colour: &[[f32; L]; 3],
        variance: &[f32; L],
    ) {
        #[inline(always)]
        fn add_run<const L: usize>(sum: &mut [f32], values: &[f32; L]) {
            for (s, v) in sum.iter_mut().zip(values) {
                *s += v;
            }
        }
        add_run(&mut self.weight[i..i + L], weight);
        for (sum, values) in self.colour.iter_mut().zip(colour) {
            add_run(&mut sum[i..i + L], values);
        }
        add_run(&mut self.variance[i..i + L], variance);
    }

    /// Zero sums for `len` pixels.
    fn reset(&mut self, len: usize) {
        for plane in std::iter::once(&mut self.weight)
            .chain(self.colour.iter_mut())
            .chain(std::iter::once(&mut self.variance))
        {
            plane.clear();
            plane.resize(len, 0.0);
        }
    }
}

impl Guides {
    /// Writes the sums of the band of rows `y0..y1`. The weight of a pair of pixels is the
    /// same from either side, so each pair within the window is weighed once — the upper (or,
    /// in one row, the left) pixel as centre, the other one of the forward half of the disc —
    /// and added to both. Rows, centre pixels and offsets are visited in one fixed order, so
    /// every pixel's sum is added up in the same order whatever the thread count, the
    /// instruction set or where a band starts.
    fn accumulate_band(&self, y0: usize, y1: usize, sums: &mut BandSums) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F (checked just above).
                return unsafe { self.accumulate_band_avx512(y0, y1, sums) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (checked just above).
                return unsafe { self.accumulate_band_avx2(y0, y1, sums) };
            }
        }
        self.accumulate_band_portable(y0, y1, sums)
    }

    /// [`Guides::accumulate_band`] compiled for AVX-512. Rust never fuses a multiply and an
    /// add, so every build computes the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn accumulate_band_avx512(&self, y0: usize, y1: usize, sums: &mut BandSums) {
        self.accumulate_band_portable(y0, y1, sums)
    }

    /// [`Guides::accumulate_band`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn accumulate_band_avx2(&self, y0: usize, y1: usize, sums: &mut BandSums) {
        self.accumulate_band_portable(y0, y1, sums)
    }

    /// Centre pixels in blocks of 16 (one AVX-512 vector, two AVX2 ones) whose neighbours all
    /// lie inside the row, their values and own sums held in registers; pixels near the row's
    /// ends one by one, over the offsets inside. Rows above the band only give to it.
    #[inline(always)]
    fn accumulate_band_portable(&self, y0: usize, y1: usize, sums: &mut BandSums) {
        const L: usize = 16;
        let (w, r) = (self.width, self.radius);
        sums.reset((y1 - y0) * w);
        for y in y0.saturating_sub(r)..y1 {
            let mut x = 0;
            while x < w {
                if x >= r && x + L + r <= w {
                    self.pair_block::<L>(y, x, (-(r as isize), r as isize), (y0, y1), sums);
                    x += L;
                } else {
                    // Offsets whose neighbour x + dx lies inside the row.
                    let lo = -(x.min(r) as isize);
                    let hi = (w - 1 - x).min(r) as isize;
                    self.pair_block::<1>(y, x, (lo, hi), (y0, y1), sums);
                    x += 1;
                }
            }
        }
    }

    /// Weighs centre pixels (x + l, y), l < L, against their neighbours of the forward half
    /// disc — rows y + 1 ..= y + r (inside the image), and in row y the offsets dx > 0 — at
    /// columns x + l + dx, dx ∈ `dx_range` (inside the row for every l); adds each weight to
    /// the centre's sums if row y is in the band `y0..y1` and to the neighbour's if its row
    /// is. The centre's own term (weight 1) is added with its sums.
    #[inline(always)]
    fn pair_block<const L: usize>(
        &self,
        y: usize,
        x: usize,
        dx_range: (isize, isize),
        (y0, y1): (usize, usize),
        sums: &mut BandSums,
    ) {
        let albedo_scale = 1.0 / (2.0 * ALBEDO_SIGMA * ALBEDO_SIGMA);
        let normal_scale = 1.0 / (2.0 * NORMAL_SIGMA * NORMAL_SIGMA);
        let depth_scale = 1.0 / (2.0 * DEPTH_SIGMA * DEPTH_SIGMA);
        let range2 = self.range * self.range;
        let use_range = self.range > 0.0;
        let (w, r) = (self.width, self.radius);
        let at = |plane: &[f32], i: usize| -> [f32; L] {
            plane[i..i + L].try_into().expect("block inside the row")
        };
        let three = |planes: &[Vec<f32>; 3], i: usize| planes.each_ref().map(|p| at(p, i));
        let photon = self.photon.as_ref().unwrap_or(&self.colour);
        let c = y * w + x;
        let (ac, nc, lc, pc) = (
            three(&self.albedo, c),
            three(&self.normal, c),
            three(&self.colour, c),
            three(photon, c),
        );
        let (dc, vc) = (at(&self.log_depth, c), at(&self.variance, c));
        let centre_in = y >= y0;
        // The centre's own term: k = 1.
        let mut weight = [1.0f32; L];
        let mut colour = pc;
        let mut variance = vc;
        for dy in 0..=r.min(self.height - 1 - y) {
            let ny = y + dy;
            let neighbour_in = (y0..y1).contains(&ny);
            if !centre_in && !neighbour_in {
                continue;
            }
            let reach = self.reach[dy] as isize;
            let first = if dy == 0 { 1 } else { -reach };
            let spatial_dy = (dy * dy) as f32;
            for dx in first.max(dx_range.0)..=reach.min(dx_range.1) {
                let n = (ny * w + x).wrapping_add_signed(dx);
                let spatial = (dx as f32 * dx as f32 + spatial_dy) * self.inv_space;
                let (an, nn, ln, pn) = (
                    three(&self.albedo, n),
                    three(&self.normal, n),
                    three(&self.colour, n),
                    three(photon, n),
                );
                let (dn, vn) = (at(&self.log_depth, n), at(&self.variance, n));
                let mut k = [0.0f32; L];
                for l in 0..L {
                    let sq = |a: &[[f32; L]; 3], b: &[[f32; L]; 3]| {
                        let d0 = b[0][l] - a[0][l];
                        let d1 = b[1][l] - a[1][l];
                        let d2 = b[2][l] - a[2][l];
                        d0 * d0 + d1 * d1 + d2 * d2
                    };
                    let dd = dn[l] - dc[l];
                    let mut e = spatial
                        + sq(&ac, &an) * albedo_scale
                        + sq(&nc, &nn) * normal_scale
                        + dd * dd * depth_scale;
                    if use_range {
                        // Differences the noise explains cost nothing; zero variance (a
                        // converged or empty pixel) admits equal colours only.
                        let v = if self.twice_min {
                            2.0 * vn[l].min(vc[l])
                        } else {
                            vn[l] + vc[l]
                        };
                        let excess = (sq(&lc, &ln) / 3.0 - v).max(0.0);
                        e += excess / (range2 * v).max(f32::MIN_POSITIVE);
                    }
                    k[l] = exp_neg(e);
                }
                if centre_in {
                    for l in 0..L {
                        weight[l] += k[l];
                        for ch in 0..3 {
                            colour[ch][l] += k[l] * pn[ch][l];
                        }
                        variance[l] += k[l] * k[l] * vn[l];
                    }
                }
                if neighbour_in {
                    sums.add(
                        ((ny - y0) * w + x).wrapping_add_signed(dx),
                        &k,
                        &pc.map(|p| std::array::from_fn(|l| k[l] * p[l])),
                        &std::array::from_fn(|l| k[l] * k[l] * vc[l]),
                    );
                }
            }
        }
        if centre_in {
            sums.add((y - y0) * w + x, &weight, &colour, &variance);
        }
    }
}

/// exp(−e) for e ≥ 0 (+∞ included), in plain arithmetic the compiler vectorises (the C
/// library's `expf` is one call per value): 2ⁿ · exp(r) with n = round(−e / ln 2) and
/// |r| ≤ ln 2 / 2, exp(r) by Cephes' degree-6 polynomial (within 3·2⁻²³ of `expf`, relative); 0 below
/// e^−87, where `expf` is below 2⁻¹²⁵. exp_neg(0) = 1 exactly.
#[inline(always)]
fn exp_neg(e: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // 1.5 · 2²³: adding it rounds to an integer held in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    let x = (-e).max(-87.0);
    let t = x * LOG2E + ROUND;
    let whole = t - ROUND;
    let n = t.to_bits() as i32 - ROUND.to_bits() as i32;
    let r = x - whole * LN2_HI - whole * LN2_LO;
    let p = ((((1.987_569_2e-4 * r + 1.398_2e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r
        + 1.666_666_5e-1)
        * r
        + 0.5;
    let poly = p * r * r + r + 1.0;
    let scale = f32::from_bits(((n + 127) as u32) << 23);
    if e > 87.0 {
        0.0
    } else {
        poly * scale
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::synthetic_bundle;

    fn screen(slot: usize, source: usize, sigma: f32) -> ScreenLevel {
        ScreenLevel {
            slot,
            source,
            sigma,
            range: 0.0,
        }
    }

    #[test]
    fn exp_neg_matches_the_c_library() {
        assert_eq!(exp_neg(0.0), 1.0);
        assert_eq!(exp_neg(f32::INFINITY), 0.0);
        assert_eq!(exp_neg(88.0), 0.0);
        let mut e = 0.0f32;
        while e < 87.0 {
            let (ours, libm) = (exp_neg(e), (-e).exp());
            assert!(
                (ours - libm).abs() <= 3.0 * f32::EPSILON * libm,
                "exp(-{e}): {ours} vs {libm}"
            );
            e = e * 1.01 + 1e-4;
        }
    }

    /// The filter as one loop per pixel over its window (with the C library's `expf`): what
    /// the vectorised, pair-once [`filter`] must compute.
    fn filter_per_pixel(b: &Bundle, index: usize, sigma: f64, range: f32) -> (Vec<f32>, Vec<f32>) {
        let (w, h) = (b.meta.width as usize, b.meta.height as usize);
        let level = &b.levels[index];
        let variance: Vec<f32> = (0..w * h).map(|p| b.variance.data[p * 5 + index]).collect();
        let direct = b.direct.as_ref().map(|d| &d.z);
        let photon: Vec<f32> = match direct {
            Some(d) => level.data.iter().zip(&d.data).map(|(a, b)| a - b).collect(),
            None => level.data.clone(),
        };
        let radius = ((2.5 * sigma).ceil() as usize).min(MAX_RADIUS);
        let inv_space = (1.0 / (2.0 * sigma * sigma)) as f32;
        let (albedo, normal, depth) = (&b.albedo.data, &b.normal.data, &b.depth.data);
        let (mut colour, mut var) = (vec![0.0f32; 3 * w * h], vec![0.0f32; w * h]);
        for y in 0..h {
            for x in 0..w {
                let c = y * w + x;
                let (mut sum, mut acc, mut acc_var) = (0.0f32, [0.0f32; 3], 0.0f32);
                for ny in y.saturating_sub(radius)..(y + radius + 1).min(h) {
                    for nx in x.saturating_sub(radius)..(x + radius + 1).min(w) {
                        let (adx, ady) = (nx.abs_diff(x), ny.abs_diff(y));
                        if adx * adx + ady * ady > radius * radius {
                            continue;
                        }
                        let n = ny * w + nx;
                        let (dx, dy) = (nx as f32 - x as f32, ny as f32 - y as f32);
                        let d2 = |v: &[f32]| {
                            (0..3)
                                .map(|k| (v[3 * n + k] - v[3 * c + k]).powi(2))
                                .sum::<f32>()
                        };
                        let dd = (depth[n].max(1e-6).ln() - depth[c].max(1e-6).ln()).powi(2);
                        let mut e = (dx * dx + dy * dy) * inv_space
                            + d2(albedo) / (2.0 * ALBEDO_SIGMA * ALBEDO_SIGMA)
                            + d2(normal) / (2.0 * NORMAL_SIGMA * NORMAL_SIGMA)
                            + dd / (2.0 * DEPTH_SIGMA * DEPTH_SIGMA);
                        if range > 0.0 {
                            let v = variance[n] + variance[c];
                            let excess = (d2(&level.data) / 3.0 - v).max(0.0);
                            if excess > 0.0 {
                                e += excess / (range * range * v).max(f32::MIN_POSITIVE);
                            }
                        }
                        let k = (-e).exp();
                        sum += k;
                        for (a, p) in acc.iter_mut().zip(&photon[3 * n..3 * n + 3]) {
                            *a += k * p;
                        }
                        acc_var += k * k * variance[n];
                    }
                }
                for k in 0..3 {
                    colour[3 * c + k] = acc[k] / sum + direct.map_or(0.0, |d| d.data[3 * c + k]);
                }
                var[c] = acc_var / (sum * sum);
            }
        }
        (colour, var)
    }

    #[test]
    fn pair_once_filter_equals_the_per_pixel_loop() {
        // A G-buffer with edges (albedo steps, a depth ramp and a step, tilted normals), noisy
        // levels, zero-variance pixels, photon-free layers; with and without the range term,
        // at a radius wider than the image's narrow side and at a small one; an image of one
        // band of rows and one of three (pairs across band borders).
        for (w, h) in [(37, 9), (23, 2 * BAND_ROWS + 7)] {
            vectorised_equals_per_pixel(w, h);
        }
    }

    fn vectorised_equals_per_pixel(w: usize, h: usize) {
        let (mut b, _) = synthetic_bundle(w, h, 0.3, 11);
        for p in 0..w * h {
            let (x, y) = (p % w, p / w);
            b.albedo.data[3 * p] = if x < 20 { 0.2 } else { 0.7 };
            b.albedo.data[3 * p + 1] = 0.5 + 0.01 * (y as f32);
            b.depth.data[p] = if x < 12 { 1.0 + 0.02 * x as f32 } else { 3.0 };
            let t = 0.05 * (x as f32 - 18.0);
            b.normal.data[3 * p] = t.sin();
            b.normal.data[3 * p + 2] = t.cos();
            if (x * 7 + y * 3) % 11 == 0 {
                b.variance.data[p * 5 + 4] = 0.0;
            }
        }
        let mut with_direct = b.clone();
        let mut direct = crate::synthetic::synthetic_bundle(w, h, 0.1, 12).0.levels[0].clone();
        for (d, z) in direct.data.iter_mut().zip(&b.levels[4].data) {
            *d = d.min(*z) * 0.5;
        }
        with_direct.direct = Some(bundle::DirectLight {
            y: direct.clone(),
            z: direct,
            variance: Image::new(w, h, 2),
        });
        for bundle in [&b, &with_direct] {
            for (sigma, range) in [(4.0, 2.0), (4.0, 0.0), (0.7, 2.0)] {
                let direct = bundle.direct.as_ref().map(|d| &d.z);
                let (colour, var) = filter(bundle, &bundle.levels[4], 4, direct, sigma, range);
                let (want, want_var) = filter_per_pixel(bundle, 4, sigma, range);
                for (i, (a, e)) in colour.data.iter().zip(&want).enumerate() {
                    assert!(
                        (a - e).abs() <= 1e-5 * e.abs().max(1e-3),
                        "σ {sigma} k {range} value {i}: {a} vs {e}"
                    );
                }
                for (i, (a, e)) in var.iter().zip(&want_var).enumerate() {
                    assert!(
                        (a - e).abs() <= 1e-5 * e.abs().max(1e-6),
                        "σ {sigma} k {range} variance {i}: {a} vs {e}"
                    );
                }
            }
        }
    }

    #[test]
    fn sigma_shrinks_like_the_sppm_radii() {
        assert!((sigma_at(2.0, 64) - 2.0).abs() < 1e-12);
        // 64× the passes: 64^(−1/6) = 1/2.
        assert!((sigma_at(2.0, 4096) - 1.0).abs() < 1e-12);
        assert!(sigma_at(2.0, 1 << 30) < MIN_SIGMA);
    }

    #[test]
    fn bad_screen_levels_are_rejected() {
        assert!(validate(&[screen(4, 4, 1.5)]).is_ok());
        assert!(validate(&[screen(0, 4, 1.5)]).is_err());
        assert!(validate(&[screen(4, 5, 1.5)]).is_err());
        assert!(validate(&[screen(4, 4, 0.0)]).is_err());
        assert!(validate(&[screen(4, 4, f32::NAN)]).is_err());
        assert!(validate(&[screen(3, 4, 1.0), screen(3, 2, 2.0)]).is_err());
    }

    #[test]
    fn a_flat_surface_is_averaged_and_variance_falls() {
        // One surface (constant G-buffer), the level alternating 1 ± 0.5 from pixel to pixel:
        // the filter averages it towards 1 and its variance plane falls below the input's.
        let (mut b, _) = synthetic_bundle(16, 16, 0.1, 1);
        b.meta.passes = 64;
        for p in 0..256 {
            for k in 0..3 {
                b.albedo.data[3 * p + k] = 0.5;
                b.normal.data[3 * p + k] = [0.0, 0.0, 1.0][k];
                b.levels[4].data[3 * p + k] = if (p + p / 16) % 2 == 0 { 1.5 } else { 0.5 };
            }
            b.depth.data[p] = 2.0;
            b.variance.data[p * 5 + 4] = 0.25;
        }
        b.direct = None;
        let out = apply(&b, &[screen(4, 4, 1.5)]);
        let centre = 8 * 16 + 8;
        for k in 0..3 {
            let v = out.levels[4].data[3 * centre + k];
            assert!((v - 1.0).abs() < 0.05, "{v}");
        }
        assert!(out.variance.data[centre * 5 + 4] < 0.25 / 10.0);
        // The other levels and variance planes are untouched.
        assert_eq!(out.levels[..4], b.levels[..4]);
        for p in 0..256 {
            assert_eq!(
                out.variance.data[p * 5..p * 5 + 4],
                b.variance.data[p * 5..p * 5 + 4]
            );
        }
    }

    #[test]
    fn the_range_term_keeps_edges_the_g_buffer_misses() {
        // One surface for the G-buffer, but a highlight (10) on the right half over a dim (1)
        // left half, variance 0.01: the G-buffer alone spreads the highlight across the edge, the
        // range term keeps it; within a half the noise-sized differences are still averaged.
        let (mut b, _) = synthetic_bundle(16, 16, 0.1, 5);
        b.meta.passes = 64;
        b.direct = None;
        for p in 0..256 {
            let right = p % 16 >= 8;
            for k in 0..3 {
                b.albedo.data[3 * p + k] = 0.5;
                b.normal.data[3 * p + k] = [0.0, 0.0, 1.0][k];
                let noise = if (p + p / 16) % 2 == 0 { 0.05 } else { -0.05 };
                b.levels[4].data[3 * p + k] = if right { 10.0 } else { 1.0 } + noise;
            }
            b.depth.data[p] = 2.0;
            b.variance.data[p * 5 + 4] = 0.01;
        }
        let plain = apply(&b, &[screen(4, 4, 2.0)]);
        let ranged = apply(
            &b,
            &[ScreenLevel {
                range: 2.0,
                ..screen(4, 4, 2.0)
            }],
        );
        let edge_left = 8 * 16 + 7;
        assert!(plain.levels[4].data[3 * edge_left] > 2.0);
        let v = ranged.levels[4].data[3 * edge_left];
        assert!((v - 1.0).abs() < 0.03, "{v}");
        let inner = 8 * 16 + 3;
        let v = ranged.levels[4].data[3 * inner];
        assert!((v - 1.0).abs() < 0.02, "noise averaged: {v}");
        let mut bad = screen(4, 4, 2.0);
        bad.range = -1.0;
        assert!(validate(&[bad]).is_err());
    }

    #[test]
    fn edges_of_the_g_buffer_are_kept() {
        // Two surfaces (left and right halves, different albedo and depth) of different
        // brightness: the filter does not carry one across the edge.
        let (mut b, _) = synthetic_bundle(16, 16, 0.1, 2);
        b.meta.passes = 64;
        for p in 0..256 {
            let left = p % 16 < 8;
            for k in 0..3 {
                b.albedo.data[3 * p + k] = if left { 0.2 } else { 0.8 };
                b.normal.data[3 * p + k] = [0.0, 0.0, 1.0][k];
                b.levels[4].data[3 * p + k] = if left { 0.1 } else { 4.0 };
            }
            b.depth.data[p] = if left { 1.0 } else { 3.0 };
        }
        b.direct = None;
        let out = apply(&b, &[screen(4, 4, 3.0)]);
        for y in 0..16 {
            let l = out.levels[4].data[3 * (y * 16 + 7)];
            let r = out.levels[4].data[3 * (y * 16 + 8)];
            assert!((l - 0.1).abs() < 1e-3 && (r - 4.0).abs() < 1e-3, "{l} {r}");
        }
    }

    /// A bundle of `w`×`h` whose photon-free parts are a flat 1.0 plus independent noise of
    /// variance `var` in paths A and B (variances of their means: `var`).
    fn noisy_direct(w: usize, h: usize, var: f32, seed: u64) -> Bundle {
        use rand_core::{RngCore, SeedableRng};
        let (mut b, _) = synthetic_bundle(w, h, 0.1, seed);
        b.meta.passes = 64;
        // One flat surface: the G-buffer lets every neighbour in.
        b.albedo.data.fill(0.5);
        for n in b.normal.data.chunks_exact_mut(3) {
            n.copy_from_slice(&[0.0, 0.0, 1.0]);
        }
        b.depth.data.fill(2.0);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let mut noisy = || {
            let mut img = Image::new(w, h, 3);
            for p in img.data.chunks_exact_mut(3) {
                // A uniform of variance `var`, the same in R, G and B.
                let u = (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32 - 0.5;
                p.fill(1.0 + u * (12.0 * var).sqrt());
            }
            img
        };
        let (y, z) = (noisy(), noisy());
        let mut variance = Image::new(w, h, 2);
        variance.data.fill(var);
        b.direct = Some(bundle::DirectLight { y, z, variance });
        b
    }

    #[test]
    fn the_direct_filter_averages_noise_keeps_a_light_and_vanishes() {
        let filter = DirectFilter {
            sigma: 1.0,
            range: 4.0,
        };
        let mut b = noisy_direct(24, 20, 0.01, 7);
        let direct = b.direct.clone().unwrap();
        let fused: Vec<f32> = (0..direct.y.data.len())
            .map(|i| 0.5 * (direct.y.data[i] + direct.z.data[i]))
            .collect();
        let error = |x: &[f32]| x.iter().map(|v| (v - 1.0).powi(2)).sum::<f32>();
        let out = filtered_direct(&b, &filter).expect("σ(64) = 1 px filters");
        // σ = 1 px on a flat surface averages ≈ 2πσ² pixels: the error falls well below half.
        assert!(
            error(&out.data) < 0.3 * error(&fused),
            "{} vs {}",
            error(&out.data),
            error(&fused)
        );
        // A light seen in one pixel by both subpaths (bright, its variance large) is not spread
        // into its calm neighbours, and keeps most of its value.
        let light = 10 * 24 + 12;
        let d = b.direct.as_mut().unwrap();
        for k in 0..3 {
            d.y.data[3 * light + k] = 100.0;
            d.z.data[3 * light + k] = 100.0;
        }
        d.variance.data[2 * light..2 * light + 2].fill(2000.0);
        let lit = filtered_direct(&b, &filter).unwrap();
        for p in (0..24 * 20).filter(|&p| p != light) {
            let moved = (lit.data[3 * p] - out.data[3 * p]).abs();
            assert!(moved < 1e-3, "pixel {p} moved by {moved}");
        }
        assert!(lit.data[3 * light] > 99.0, "{}", lit.data[3 * light]);
        // σ(N) below MIN_SIGMA: nothing to filter, the combination fuses the layers itself.
        b.meta.passes = 64 * 64 * 64 * 64;
        assert!(filtered_direct(&b, &filter).is_none());
        b.meta.passes = 64;
        b.direct = None;
        assert!(filtered_direct(&b, &filter).is_none());
    }

    #[test]
    fn packing_with_a_direct_filter_changes_only_the_added_part() {
        let b = noisy_direct(16, 12, 0.01, 9);
        let plain = crate::features::pack(&b).unwrap();
        let screen = ScreenFilters {
            levels: Vec::new(),
            direct: Some(DEFAULT_DIRECT_FILTER),
        };
        let packing = crate::features::Packing {
            screen,
            extra: Vec::new(),
        };
        let filtered = crate::features::pack_with(&b, &packing).unwrap();
        let (plain_levels, plain_added) = plain.combination_inputs();
        let (levels, added) = filtered.combination_inputs();
        assert_eq!(plain_levels, levels);
        assert_eq!(plain.features, filtered.features);
        let expected = filtered_direct(&b, &DEFAULT_DIRECT_FILTER).unwrap();
        let planar: Vec<f32> = (0..3).flat_map(|k| expected.plane(k)).collect();
        assert_eq!(added.unwrap(), planar);
        assert_ne!(plain_added.unwrap(), planar);
    }

    #[test]
    fn the_filter_vanishes_as_passes_grow_and_direct_light_is_not_spread() {
        let (mut b, _) = synthetic_bundle(12, 10, 0.1, 3);
        b.meta.passes = 64;
        let out = apply(&b, &[screen(4, 4, 1.5)]);
        assert_ne!(out.levels[4], b.levels[4]);
        // At 64^4 passes σ = 1.5/16 < MIN_SIGMA: the identity.
        b.meta.passes = 64 * 64 * 64 * 64;
        let out = apply(&b, &[screen(4, 4, 1.5)]);
        assert_eq!(out.levels[4], b.levels[4]);
        // Direct light of one bright pixel stays at that pixel: only the photon part spreads.
        let (mut b, _) = synthetic_bundle(12, 10, 0.1, 4);
        b.meta.passes = 64;
        b.direct = Some(bundle::DirectLight {
            y: Image::new(12, 10, 3),
            z: Image::new(12, 10, 3),
            variance: Image::new(12, 10, 2),
        });
        let d = b.direct.as_mut().unwrap();
        let bright = 5 * 12 + 6;
        for k in 0..3 {
            d.z.data[3 * bright + k] = 100.0;
        }
        let base = b.levels[4].clone();
        for k in 0..3 {
            b.levels[4].data[3 * bright + k] += 100.0;
        }
        let with = apply(&b, &[screen(4, 4, 1.5)]);
        b.levels[4] = base;
        b.direct.as_mut().unwrap().z.data[3 * bright..3 * bright + 3].fill(0.0);
        let without = apply(&b, &[screen(4, 4, 1.5)]);
        for p in 0..120 {
            for k in 0..3 {
                let extra = if p == bright { 100.0 } else { 0.0 };
                let diff = with.levels[4].data[3 * p + k] - without.levels[4].data[3 * p + k];
                assert!((diff - extra).abs() < 1e-3, "pixel {p}: {diff}");
            }
        }
    }
}
