//! Stochastic progressive photon mapping with five nested kernel bandwidths (docs/method.md §3), and
//! its single-level baseline; the result of a run is a series of [`bundle::Bundle`]s.
//!
//! One pass *i* (1-based):
//! 1. photon pass: `photons_per_pass` photons are traced and deposited ([`photon_trace`]),
//!    then sorted into a hash grid ([`photon_map::PhotonGrid`]);
//! 2. per pixel (in parallel, each pixel with its own random streams): eye subpaths A and B are
//!    traced to their visible points ([`visible_point`]); a pixel without radii yet gets
//!    r₅ = distance to the k-th nearest photon (capped) at its first visible point; A gathers
//!    level 1 (`y`) at r₁, B gathers levels 2..5 (`z1`..`z4`) with one query at r₅
//!    ([`gather`]); the per-pass estimates enter Welford accumulators ([`accumulate`]);
//!    then all radii shrink by r² ← r²·(i+α)/(i+1) ([`radius`]).
//!
//! Under the CPPM schedule ([`RadiusSchedule::Cppm`]) step 2 differs in the radii only: each
//! level starts from the same nested initial radius, counts the photons it gathers into 12
//! cells, and at the start of every pass a χ² test of those counts keeps or shrinks that
//! level's radius ([`cppm`]); the gather tests each level's radius on its own.
//!
//! Determinism: pixel `p` uses the streams `rng_for(seed, pass, 2p)` (A) and
//! `rng_for(seed, pass, 2p+1)` (B), photon `j` a stream of (seed, pass, j) in a separate domain;
//! photon deposits are concatenated in photon order and the grid is built by a stable counting
//! sort; every reduction is per pixel in a fixed order. Output is bit-identical for any thread
//! count.

pub mod accumulate;
pub mod cppm;
pub mod gather;
pub mod pass_sampler;
pub mod photon_focus;
pub mod photon_map;
pub mod photon_trace;
pub mod radius;
pub mod run_state;
pub mod visible_point;

#[cfg(test)]
mod tests;

use std::time::Instant;

use anyhow::{bail, Result};
use bundle::{Bundle, BundleMeta, DirectLight, Image};
use glam::UVec2;
use rayon::prelude::*;

use crate::sampling::UniformSource;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use crate::threads::with_threads;

use crate::state_file::StateFile;
use accumulate::{GBufferSum, Welford};
use cppm::CppmLevel;
pub use pass_sampler::EyeSampler;
use pass_sampler::PassSampler;
use photon_map::PhotonGrid;
pub use radius::RadiusSchedule;
use radius::{nested_radii, shrink_factor, LEVELS};
use run_state::StateStore;
use visible_point::{trace_eye_path, EyePath};

/// Default cap on the initial radius as a fraction of the scene's bounding-box diagonal
/// (1/50): keeps the kernel local in dark, photon-starved regions.
pub const DEFAULT_MAX_RADIUS_FRACTION: f32 = 0.02;

/// Default k of the k-nearest-photon initial radius (the paper's k = 20).
pub const DEFAULT_KNN: usize = 20;

/// Default α of the radius shrink rule.
pub const DEFAULT_ALPHA: f32 = 2.0 / 3.0;

/// Default bound on eye-path delta/glossy bounces and on photon bounces.
pub const DEFAULT_MAX_DEPTH: u32 = 16;

/// Light samples at each visible point of multi-level SPPM when the settings name none: two,
/// their light choices stratified. The fused photon-free part (emission and next-event
/// estimation of subpaths A and B) was most of the reconstruction's remaining variance on
/// shelves, table tops and glass; a second stratified sample halves it for ≈ 15 % more time
/// per pass (docs/sppm.md, "Light samples at the visible point"). Standard SPPM keeps one,
/// as in the paper.
pub const DEFAULT_EMITTER_SAMPLES_MULTI_LEVEL: u32 = 2;

/// Share of the infinite lights' photons aimed at what the camera sees when the settings name
/// none ([`SppmSettings::photon_focus`]): none. Aiming is unbiased but not yet measured better:
/// far photons then carry many times the flux of aimed ones, and the held-out references of
/// sunlit scenes are not converged enough to judge it (docs/sppm.md, "Photons from infinite
/// lights").
pub const DEFAULT_PHOTON_FOCUS: f32 = 0.0;

/// Where multi-level SPPM gathers the photon part of the sharp level ỹ.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
pub enum SharpLevel {
    /// At eye subpath A's visible point alone (the paper's method; every bundle before
    /// 2026-12-06).
    #[serde(rename = "a")]
    #[value(name = "a")]
    SubpathA,
    /// The mean of the gathers at r₁ around A's and B's visible points (B's query at r₅ already
    /// finds those photons, so it costs nothing): ỹ's photon noise falls to 0.67–0.96 of A's
    /// alone on caustic scenes, its expectation unchanged (docs/sppm.md, "The sharp level at
    /// both subpaths"). ỹ then shares half of B's photon gather with the z̃ levels; its direct
    /// part stays A's, so the emission split is unchanged.
    #[default]
    #[serde(rename = "both")]
    #[value(name = "both")]
    BothSubpaths,
}

impl SharpLevel {
    /// The name in bundle metadata, run states and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            SharpLevel::SubpathA => "a",
            SharpLevel::BothSubpaths => "both",
        }
    }
}

/// The warning for a bundle rendered with a reconstruction filter other than the box: its
/// pixels are smoother than those of the box-filtered bundles the networks are trained on
/// (the toolkit's scenes and datagen families name `box`). `None` for the box.
pub fn filter_warning(filter: crate::filter::FilterDesc) -> Option<String> {
    if filter == crate::filter::FilterDesc::Box {
        return None;
    }
    Some(format!(
        "the film's reconstruction filter is {} (Mitsuba's default when the film names none): \
         each pixel's samples spread over its neighbours' area, so the bundle is smoother than \
         the box-filtered bundles the networks were trained on; add <rfilter type=\"box\"/> to \
         the film to match them",
        filter.describe()
    ))
}

/// Which estimator to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SppmMode {
    /// Standard SPPM: one eye subpath, one level whose radius is initialised like level 2
    /// (r₅/√2³ with r₅ the k-NN distance). Its estimate fills all five bundle levels.
    Single,
    /// Multi-level SPPM: subpaths A (level 1) and B (levels 2..5), five nested radii.
    MultiLevel,
}

impl SppmMode {
    /// The integrator name written into bundle metadata and accepted by `render`.
    pub fn name(self) -> &'static str {
        match self {
            SppmMode::Single => "sppm",
            SppmMode::MultiLevel => "sppm-ml",
        }
    }

    /// The levels with a radius of their own: five, or the single level.
    fn radius_levels(self) -> usize {
        match self {
            SppmMode::MultiLevel => LEVELS,
            SppmMode::Single => 1,
        }
    }
}

impl SppmSettings {
    /// Light samples at each visible point: the setting, or the mode's default.
    pub fn emitter_samples(&self) -> u32 {
        self.emitter_samples.unwrap_or(match self.mode {
            SppmMode::MultiLevel => DEFAULT_EMITTER_SAMPLES_MULTI_LEVEL,
            SppmMode::Single => 1,
        })
    }

    /// Where ỹ's photons are gathered: the setting, or the mode's default.
    pub fn sharp_level(&self) -> SharpLevel {
        self.sharp_level.unwrap_or(match self.mode {
            SppmMode::MultiLevel => SharpLevel::default(),
            SppmMode::Single => SharpLevel::SubpathA,
        })
    }

    /// CPPM states per pixel: one per level with a radius of its own under the CPPM
    /// schedule, none under SPPM's (whose radii live in [`PixelState::r2`]).
    fn cppm_levels(&self) -> usize {
        match self.schedule {
            RadiusSchedule::Sppm => 0,
            RadiusSchedule::Cppm => self.mode.radius_levels(),
        }
    }
}

/// Settings of an SPPM run.
#[derive(Debug, Clone, PartialEq)]
pub struct SppmSettings {
    /// Photons emitted per pass (N_photon).
    pub photons_per_pass: u64,
    /// Seed of every random stream.
    pub seed: u64,
    /// Cap on the initial radius r₅ in world units; `None`: the scene's bounding diagonal
    /// times [`DEFAULT_MAX_RADIUS_FRACTION`].
    pub max_radius: Option<f32>,
    /// k of the k-nearest-photon initial radius.
    pub knn: usize,
    /// α of the shrink rule r² ← r²·(i+α)/(i+1).
    pub alpha: f32,
    /// Multi-level or single-level.
    pub mode: SppmMode,
    /// How the radii evolve: SPPM's shrink after every pass, or CPPM's χ² test per level.
    pub schedule: RadiusSchedule,
    /// Bound on delta/glossy eye bounces and on photon bounces.
    pub max_depth: u32,
    /// Light samples of next-event estimation at each visible point (Mitsuba's
    /// `emitter_samples`), their light choices stratified. `None`: the mode's default,
    /// [`DEFAULT_EMITTER_SAMPLES_MULTI_LEVEL`] for multi-level and one for single-level SPPM
    /// (the paper's standard SPPM); see [`SppmSettings::emitter_samples`].
    pub emitter_samples: Option<u32>,
    /// Share of the infinite lights' photons aimed at the region the camera sees (0: none,
    /// every photon starts on the scene's bounding disk); applied only where that region is
    /// small against the scene ([`photon_focus`]). The estimate's expectation does not depend
    /// on it ([`crate::lights::PhotonFocus`]).
    pub photon_focus: f32,
    /// Where multi-level SPPM gathers ỹ's photon part (single-level SPPM has no subpath B and
    /// refuses anything but [`SharpLevel::SubpathA`]). `None`: the mode's default, both
    /// subpaths for multi-level; see [`SppmSettings::sharp_level`].
    pub sharp_level: Option<SharpLevel>,
    /// Where the eye subpaths' random numbers come from across passes: independent draws, or
    /// a low-discrepancy sequence that stratifies each pixel's first draws over the passes
    /// (docs/sppm.md, "Eye samples across passes").
    pub sampler: EyeSampler,
    /// Worker threads (0: all cores). The output does not depend on it.
    pub threads: usize,
    /// Scene identifier written into bundle metadata.
    pub scene_name: String,
}

impl Default for SppmSettings {
    fn default() -> Self {
        SppmSettings {
            photons_per_pass: 100_000,
            seed: 0,
            max_radius: None,
            knn: DEFAULT_KNN,
            alpha: DEFAULT_ALPHA,
            mode: SppmMode::MultiLevel,
            schedule: RadiusSchedule::Sppm,
            max_depth: DEFAULT_MAX_DEPTH,
            emitter_samples: None,
            photon_focus: DEFAULT_PHOTON_FOCUS,
            sharp_level: None,
            sampler: EyeSampler::Independent,
            threads: 0,
            scene_name: String::new(),
        }
    }
}

/// Checks a wall-clock budget in seconds; the error completes a sentence naming the limit
/// ("… must be a positive, finite number of seconds, got inf"). An infinite limit would never
/// stop a run without checkpoints, nor write its bundle.
pub fn check_time_limit(seconds: f64) -> Result<(), String> {
    if seconds.is_finite() && seconds > 0.0 {
        Ok(())
    } else {
        Err(format!(
            "must be a positive, finite number of seconds, got {seconds}"
        ))
    }
}

/// When to emit bundles and when to stop.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StopCondition {
    /// Pass counts at which a bundle is produced (any order; duplicates ignored). The run stops
    /// after the largest one.
    pub checkpoints: Vec<u32>,
    /// Wall-clock budget in seconds: the run stops after the first pass that ends past it and
    /// produces a final bundle (unless that pass count was a checkpoint already).
    pub seconds: Option<f64>,
}

/// Progress report after each pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PassProgress {
    /// Passes done.
    pub pass: u32,
    /// The last checkpoint, if the run is pass-bounded.
    pub target_passes: Option<u32>,
    /// Seconds since the start.
    pub elapsed: f64,
    /// Photons emitted so far.
    pub photons_emitted: u64,
    /// Photons stored in this pass.
    pub photons_stored: u64,
    /// Visible points found in this pass (both subpaths).
    pub visible_points: u64,
}

/// Totals of a finished run, for reports and benchmarks.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RenderSummary {
    /// Passes rendered.
    pub passes: u32,
    /// Wall-clock seconds of the whole run (bundle assembly and callbacks included).
    pub seconds: f64,
    /// Seconds spent tracing photons and building the grid.
    pub photon_seconds: f64,
    /// Of `photon_seconds`, the seconds spent building the photon grid.
    pub grid_seconds: f64,
    /// Seconds spent on eye subpaths, gathering and accumulation.
    pub gather_seconds: f64,
    /// Photons emitted.
    pub photons_emitted: u64,
    /// Photons stored.
    pub photons_stored: u64,
    /// Visible points found.
    pub visible_points: u64,
    /// The pass a resumed run continued from (0: it started afresh). The totals above count
    /// every session of the run.
    pub resumed_from: u32,
}

/// The per-pixel state carried across passes. (A CPPM run keeps its per-level radii and
/// counts beside it, in a [`CppmLevel`] list of [`SppmSettings::cppm_levels`] per pixel, so
/// SPPM runs do not carry them.)
#[derive(Debug, Clone, Copy, Default)]
struct PixelState {
    /// Current r₅² of the pixel (multi-level) or the single level's r² (single); 0 until the
    /// pixel's first visible point. Under CPPM the initial value, kept (the levels' current
    /// radii are in their [`CppmLevel`]s).
    r2: f32,
    /// Pass in which the radius was initialised.
    init_pass: u32,
    /// Welford accumulators per level ([`SppmMode::Single`] uses index 0 only).
    levels: [Welford; LEVELS],
    /// G-buffer sums from path A.
    gbuffer: GBufferSum,
    /// Welford accumulators of the radiance each eye subpath gathered without photons
    /// (emission, next-event estimation): `[A, B]`; [`SppmMode::Single`] uses A only. Stored
    /// as the bundle's `ydirect`, `zdirect` and `directvariance` layers, so the reconstruction
    /// can leave this per-sample part out of the window filter (docs/method.md §5.4).
    direct: [Welford; 2],
}

impl PixelState {
    /// The current radii of the levels this pixel estimates (ascending).
    fn radii(&self, mode: SppmMode) -> [f32; LEVELS] {
        let r = self.r2.sqrt();
        match mode {
            SppmMode::MultiLevel => nested_radii(r),
            SppmMode::Single => [r; LEVELS],
        }
    }
}

/// Everything a pass needs that does not change within it.
struct PassContext<'a> {
    scene: &'a Scene,
    settings: &'a SppmSettings,
    grid: &'a PhotonGrid,
    max_radius: f32,
    pass: u32,
}

/// Initial radius at `p`: the k-NN distance, or the cap when fewer than k photons are within
/// it; for the single level scaled like level 2.
fn initial_r2(ctx: &PassContext, p: glam::Vec3) -> f32 {
    let r5 = ctx
        .grid
        .kth_nearest_distance(p, ctx.settings.knn, ctx.max_radius)
        .unwrap_or(ctx.max_radius);
    let r = match ctx.settings.mode {
        SppmMode::MultiLevel => r5,
        SppmMode::Single => nested_radii(r5)[1],
    };
    r * r
}

/// Renders one pass of pixel `index` and updates its state: `state`, and under CPPM its levels'
/// `cppm` states (empty under SPPM). Returns the visible-point count.
fn render_pixel(
    ctx: &PassContext,
    index: usize,
    state: &mut PixelState,
    cppm: &mut [CppmLevel],
) -> u64 {
    let scene = ctx.scene;
    let width = scene.camera.resolution().x as usize;
    let pixel = UVec2::new((index % width) as u32, (index / width) as u32);
    // Each subpath with the reconstruction filter's weight of its film position.
    let trace = |sub: u64| -> (EyePath, f32) {
        let stream = 2 * index as u64 + sub;
        let mut rng = PassSampler::new(ctx.settings.sampler, ctx.settings.seed, stream, ctx.pass);
        let u_film = rng.next_2d();
        let u_lens = rng.next_2d();
        let sample = scene.camera.sample_ray(pixel, u_film, u_lens);
        let path = trace_eye_path(
            scene,
            sample.ray,
            &mut rng,
            ctx.settings.max_depth,
            ctx.settings.emitter_samples(),
        );
        (path, sample.weight)
    };
    let (a, weight_a) = trace(0);
    let (b, weight_b) = match ctx.settings.mode {
        SppmMode::MultiLevel => {
            let (b, w) = trace(1);
            (Some(b), w)
        }
        SppmMode::Single => (None, 1.0),
    };
    if state.r2 == 0.0 {
        let first = a.vp.or(b.and_then(|b| b.vp));
        if let Some(vp) = first {
            state.r2 = initial_r2(ctx, vp.p);
            state.init_pass = ctx.pass;
            // CPPM levels start from the same nested radii as SPPM's.
            let initial = state.radii(ctx.settings.mode);
            for (level, r) in cppm.iter_mut().zip(initial) {
                *level = CppmLevel::new(r * r);
            }
        }
    }
    // CPPM: the test pending from the photons counted so far decides this pass's radii.
    for level in cppm.iter_mut() {
        level.test_and_update();
    }
    let radii = state.radii(ctx.settings.mode);
    let cppm_r1 = cppm.first().map(|level| level.r2.sqrt());
    let n = ctx.settings.photons_per_pass;
    // Gathers the levels `range` at `vp` into `out`: nested SPPM radii, or CPPM's own.
    let mut gather_levels =
        |vp: &visible_point::VisiblePoint, range: std::ops::Range<usize>, out: &mut [Rgb]| {
            if cppm.is_empty() {
                gather::gather(scene, ctx.grid, vp, &radii[range], n, out);
            } else {
                gather::gather_counting(scene, ctx.grid, vp, &mut cppm[range], n, out);
            }
        };
    let mut estimates = [Rgb::ZERO; LEVELS];
    let mut found = 0;
    match ctx.settings.mode {
        SppmMode::MultiLevel => {
            // ỹ's photon part at A's visible point, and (sharp level at both subpaths) at B's.
            let mut photons_a = [Rgb::ZERO];
            if let Some(vp) = &a.vp {
                gather_levels(vp, 0..1, &mut photons_a);
                found += 1;
            }
            let b = b.unwrap_or_default();
            for e in &mut estimates[1..] {
                *e = b.direct;
            }
            let both = ctx.settings.sharp_level() == SharpLevel::BothSubpaths;
            let mut photons_b = Rgb::ZERO;
            if let Some(vp) = &b.vp {
                if !both {
                    gather_levels(vp, 1..LEVELS, &mut estimates[1..]);
                } else if let Some(r1) = cppm_r1 {
                    // CPPM's level 1 counts A's photons for its test alone; B's are only added.
                    gather_levels(vp, 1..LEVELS, &mut estimates[1..]);
                    let mut photons = [Rgb::ZERO];
                    gather::gather(scene, ctx.grid, vp, &[r1], n, &mut photons);
                    photons_b = photons[0];
                } else {
                    // The radii are nested: one query at r₅ serves all five levels.
                    let mut photons = [Rgb::ZERO; LEVELS];
                    gather::gather(scene, ctx.grid, vp, &radii, n, &mut photons);
                    for (e, p) in estimates[1..].iter_mut().zip(&photons[1..]) {
                        *e += *p;
                    }
                    photons_b = photons[0];
                }
                found += 1;
            }
            estimates[0] = if both {
                a.direct * weight_a + (photons_a[0] * weight_a + photons_b * weight_b) * 0.5
            } else {
                (a.direct + photons_a[0]) * weight_a
            };
            for e in &mut estimates[1..] {
                *e *= weight_b;
            }
            let direct_a = sanitize_pair(&mut estimates[..1], a.direct * weight_a);
            let direct_b = sanitize_pair(&mut estimates[1..], b.direct * weight_b);
            for (w, e) in state.levels.iter_mut().zip(&estimates) {
                w.push(*e);
            }
            state.direct[0].push(direct_a);
            state.direct[1].push(direct_b);
        }
        SppmMode::Single => {
            estimates[0] = a.direct;
            if let Some(vp) = &a.vp {
                gather_levels(vp, 0..1, &mut estimates[..1]);
                found += 1;
            }
            estimates[0] *= weight_a;
            let direct = sanitize_pair(&mut estimates[..1], a.direct * weight_a);
            state.levels[0].push(estimates[0]);
            state.direct[0].push(direct);
        }
    }
    state.gbuffer.push(&a.gbuffer);
    if state.r2 > 0.0 && ctx.settings.schedule == RadiusSchedule::Sppm {
        state.r2 *= shrink_factor(ctx.pass, ctx.settings.alpha);
    }
    found
}

/// Replaces the per-pass estimates of one eye subpath, and the photon-free part they contain,
/// by zero if any of them is not finite (a numerical accident), so one bad sample cannot poison
/// a pixel's mean for the rest of the run. Returns the photon-free part as kept.
#[inline]
fn sanitize_pair(estimates: &mut [Rgb], direct: Rgb) -> Rgb {
    if direct.is_finite() && estimates.iter().all(|e| e.is_finite()) {
        direct
    } else {
        estimates.fill(Rgb::ZERO);
        Rgb::ZERO
    }
}

/// The bundle of the current state, or an error naming the first non-finite sample: every
/// per-pass estimate is finite (`sanitize_pair`), but a mean or variance of huge values can still
/// overflow float32, and a bundle of infinities would only be refused by whoever reads it.
fn finite_bundle(
    scene: &Scene,
    settings: &SppmSettings,
    states: &[PixelState],
    cppm: &[CppmLevel],
    passes: u32,
    seconds: f64,
) -> Result<Bundle> {
    let bundle = make_bundle(scene, settings, states, cppm, passes, seconds);
    if let Some((layer, channel, x, y)) = bundle.find_non_finite() {
        bail!(
            "pass {passes}: {layer}.{channel} is not finite at pixel ({x}, {y}): a value \
             overflowed float32 (an emitted radiance or a reflectance far too large, or a \
             scene too large?); no bundle written"
        );
    }
    Ok(bundle)
}

/// Assembles the bundle of the current state (`cppm`: the CPPM levels of every pixel, empty
/// under SPPM).
fn make_bundle(
    scene: &Scene,
    settings: &SppmSettings,
    states: &[PixelState],
    cppm: &[CppmLevel],
    passes: u32,
    seconds: f64,
) -> Bundle {
    let cppm_levels = settings.cppm_levels();
    let res = scene.camera.resolution();
    let (w, h) = (res.x as usize, res.y as usize);
    let mut levels: Vec<Image> = (0..LEVELS).map(|_| Image::new(w, h, 3)).collect();
    let mut variance = Image::new(w, h, LEVELS);
    let mut albedo = Image::new(w, h, 3);
    let mut normal = Image::new(w, h, 3);
    let mut depth = Image::new(w, h, 1);
    let mut radius = Image::new(w, h, LEVELS);
    let mut direct_y = Image::new(w, h, 3);
    let mut direct_z = Image::new(w, h, 3);
    let mut direct_variance = Image::new(w, h, 2);
    for (i, s) in states.iter().enumerate() {
        // The single level's one subpath is also what its z levels hold.
        let b = match settings.mode {
            SppmMode::MultiLevel => &s.direct[1],
            SppmMode::Single => &s.direct[0],
        };
        direct_y.data[3 * i..3 * i + 3].copy_from_slice(&s.direct[0].mean_rgb().to_array());
        direct_z.data[3 * i..3 * i + 3].copy_from_slice(&b.mean_rgb().to_array());
        direct_variance.data[2 * i] = s.direct[0].variance_of_mean();
        direct_variance.data[2 * i + 1] = b.variance_of_mean();
        for (l, level) in levels.iter_mut().enumerate() {
            // The single level fills every level layer (docs/formats.md).
            let acc = match settings.mode {
                SppmMode::MultiLevel => &s.levels[l],
                SppmMode::Single => &s.levels[0],
            };
            level.data[3 * i..3 * i + 3].copy_from_slice(&acc.mean_rgb().to_array());
            variance.data[LEVELS * i + l] = acc.variance_of_mean();
        }
        let g = s.gbuffer.average(passes);
        albedo.data[3 * i..3 * i + 3].copy_from_slice(&g.albedo.to_array());
        normal.data[3 * i..3 * i + 3].copy_from_slice(&g.normal.to_array());
        depth.data[i] = g.depth;
        // Radii used in the last pass (before its shrink). CPPM tests at the start of a pass,
        // so its current radii are the last pass's.
        let r = if cppm_levels > 0 {
            let own = &cppm[cppm_levels * i..cppm_levels * (i + 1)];
            std::array::from_fn(|l| own[l.min(cppm_levels - 1)].r2.sqrt())
        } else if s.r2 > 0.0 {
            let last_shrink = shrink_factor(passes, settings.alpha);
            let mut unshrunk = *s;
            unshrunk.r2 /= last_shrink;
            unshrunk.radii(settings.mode)
        } else {
            [0.0; LEVELS]
        };
        radius.data[LEVELS * i..LEVELS * i + LEVELS].copy_from_slice(&r);
    }
    Bundle {
        meta: BundleMeta {
            scene: settings.scene_name.clone(),
            seed: settings.seed,
            passes,
            photons_per_pass: settings.photons_per_pass,
            seconds,
            integrator: settings.mode.name().into(),
            schedule: settings.schedule.name().into(),
            emitter_samples: settings.emitter_samples(),
            sharp_level: settings.sharp_level().name().into(),
            sampler: settings.sampler.name().into(),
            width: res.x,
            height: res.y,
        },
        levels,
        variance,
        albedo,
        normal,
        depth,
        radius: Some(radius),
        direct: Some(DirectLight {
            y: direct_y,
            z: direct_z,
            variance: direct_variance,
        }),
    }
}

/// Grid cell edge over the mean current radius of the largest level, per mode. A query costs a
/// hash probe per cell it overlaps plus a distance test per photon in those cells; cells of
/// about 1.5 r₅ balance the two for `sppm-ml` (its dominant query is B's at r₅; A's at
/// r₁ = r₅/4 then mostly touches one cell) and cells of about 3 r for `sppm` (whose single query
/// at r ≈ r₅/2.8 holds few photons, so probes dominate). Tuned on the default scene (CPU time
/// per steady pass, factors 0.7–4 tried; docs/performance.md); the factor only changes speed
/// and the order in which a query visits photons, never which photons it finds.
fn cell_factor(mode: SppmMode) -> f32 {
    match mode {
        SppmMode::MultiLevel => 1.5,
        SppmMode::Single => 3.0,
    }
}

/// Grid cell edge in the first pass (no radii yet) over the radius cap: the k-NN searches of
/// that pass start at one cell and double, and the typical k-NN distance is well below the cap.
const FIRST_PASS_CELL_FRACTION: f32 = 0.5;

/// Cell size of this pass's photon grid from the radii the pixels will query:
/// [`cell_factor`] × the mean initialised radius, but at least a quarter of the largest (bounds
/// the cells a query visits); a fraction of the cap before any pixel has a radius.
/// Under CPPM the radius of a pixel is the largest of its levels' (`cppm`, empty under SPPM).
fn grid_cell_size(
    states: &[PixelState],
    cppm: &[CppmLevel],
    mode: SppmMode,
    max_radius: f32,
) -> f32 {
    let (mut sum, mut count, mut max) = (0.0f64, 0u64, 0.0f32);
    let cppm_levels = cppm.len() / states.len().max(1);
    for (i, s) in states.iter().enumerate().filter(|(_, s)| s.r2 > 0.0) {
        let r = if cppm_levels > 0 {
            let own = &cppm[cppm_levels * i..cppm_levels * (i + 1)];
            own.iter().fold(0.0f32, |m, l| m.max(l.r2)).sqrt()
        } else {
            s.radii(mode)[LEVELS - 1]
        };
        sum += r as f64;
        count += 1;
        max = max.max(r);
    }
    if count == 0 {
        return FIRST_PASS_CELL_FRACTION * max_radius;
    }
    (cell_factor(mode) * (sum / count as f64) as f32).max(0.25 * max)
}

/// Runs SPPM on `scene` and calls `on_checkpoint` with a bundle at every checkpoint of `stop`
/// (and at the time limit). `progress` is called after every pass. Everything runs in a
/// dedicated rayon pool of `settings.threads` workers.
pub fn render_sppm(
    scene: &Scene,
    settings: &SppmSettings,
    stop: &StopCondition,
    on_checkpoint: impl FnMut(Bundle) -> Result<()> + Send,
    progress: impl FnMut(&PassProgress) + Send,
) -> Result<RenderSummary> {
    render_sppm_resumable(scene, settings, stop, None, on_checkpoint, progress)
}

/// [`render_sppm`] that keeps its state in `state` (when given): a run whose state file exists
/// continues from the saved pass — its bundles and the final state are bit-identical to an
/// uninterrupted run's, except the wall-clock `seconds` — and the state is saved every
/// `state.interval` seconds, with every bundle, and at the end. A checkpoint at exactly the
/// saved pass gets its bundle again (from the saved state); time limits count the seconds of
/// every session of the run.
pub fn render_sppm_resumable(
    scene: &Scene,
    settings: &SppmSettings,
    stop: &StopCondition,
    state: Option<&StateFile>,
    mut on_checkpoint: impl FnMut(Bundle) -> Result<()> + Send,
    mut progress: impl FnMut(&PassProgress) + Send,
) -> Result<RenderSummary> {
    scene.refuse_media(settings.mode.name())?;
    if settings.photons_per_pass == 0 {
        bail!("photons per pass must be positive");
    }
    if settings.knn == 0 {
        bail!("k of the k-nearest-photon radius must be positive");
    }
    if settings.emitter_samples == Some(0) {
        bail!("emitter samples (light samples per visible point) must be positive");
    }
    if !(settings.photon_focus >= 0.0 && settings.photon_focus < 1.0) {
        bail!(
            "photon focus (the share of infinite lights' photons aimed at what the camera sees) \
             must lie in [0, 1), got {}",
            settings.photon_focus
        );
    }
    if settings.mode == SppmMode::Single && settings.sharp_level() != SharpLevel::SubpathA {
        bail!(
            "the sharp level at both subpaths needs multi-level SPPM (sppm-ml): standard SPPM \
             traces one eye subpath"
        );
    }
    if !(settings.alpha > 0.0 && settings.alpha < 1.0) {
        bail!("alpha must lie in (0, 1), got {}", settings.alpha);
    }
    let mut checkpoints = stop.checkpoints.clone();
    checkpoints.sort_unstable();
    checkpoints.dedup();
    checkpoints.retain(|&c| c > 0);
    if checkpoints.is_empty() && stop.seconds.is_none() {
        bail!("no stop condition: give pass checkpoints and/or a time limit");
    }
    if let Some(s) = stop.seconds {
        check_time_limit(s).map_err(|why| anyhow::anyhow!("time limit {why}"))?;
    }
    let max_radius = match settings.max_radius {
        Some(r) if r.is_finite() && r > 0.0 => r,
        Some(r) => bail!("max radius must be positive, got {r}"),
        None => (scene.diagonal() * DEFAULT_MAX_RADIUS_FRACTION).max(1e-6),
    };
    if let Some(f) = state {
        f.check_interval()?;
    }
    let res = scene.camera.resolution();
    let pixel_count = res.x as usize * res.y as usize;
    let target = checkpoints.last().copied();
    let store = state.map(|f| StateStore::new(f, settings, res.x, res.y, max_radius));
    let saved = match &store {
        Some(store) => store.load()?,
        None => None,
    };
    if let (Some(saved), Some(target)) = (&saved, target) {
        if saved.passes > target {
            bail!(
                "{}: the saved run is at pass {}, past the last requested pass {target}; ask for \
                 more passes, or give --state a new file name",
                store
                    .as_ref()
                    .map_or(String::new(), |s| s.file.path.display().to_string()),
                saved.passes
            );
        }
    }

    // Per pixel: the state, CPPM's levels, and the bundle assembled at checkpoints (f32 layers).
    let pixel_bytes = std::mem::size_of::<PixelState>() as u64
        + (settings.cppm_levels() * std::mem::size_of::<CppmLevel>()) as u64
        + 4 * 39;
    let state_bytes = pixel_count as u64 * pixel_bytes;
    crate::memory::check_fits(&format!("SPPM on a {}x{} image", res.x, res.y), state_bytes)?;
    crate::memory::check_fits(
        &format!("{} photons per pass", settings.photons_per_pass),
        state_bytes.saturating_add(photon_trace::chunk_list_bytes(settings.photons_per_pass)),
    )?;
    // What memory is left bounds the photons a pass may store.
    let max_stored = crate::memory::available_bytes().map_or(u64::MAX, |a| {
        a.saturating_sub(state_bytes) / photon_trace::BYTES_PER_STORED_PHOTON
    });

    with_threads(settings.threads, move || -> Result<RenderSummary> {
        let start = Instant::now();
        let (mut states, mut cppm, mut summary, mut pass) = match saved {
            Some(s) => {
                let summary = RenderSummary {
                    resumed_from: s.passes,
                    ..s.summary
                };
                (s.pixels, s.cppm, summary, s.passes)
            }
            None => (
                crate::memory::try_filled_vec(
                    pixel_count,
                    PixelState::default(),
                    "the SPPM pixel state",
                )?,
                crate::memory::try_filled_vec(
                    pixel_count * settings.cppm_levels(),
                    CppmLevel::default(),
                    "the CPPM level state",
                )?,
                RenderSummary::default(),
                0,
            ),
        };
        // Seconds of earlier sessions of this run; the time limit and the bundles count them.
        let earlier_seconds = summary.seconds;
        let seconds_so_far = || earlier_seconds + start.elapsed().as_secs_f64();
        let mut next_checkpoint = checkpoints.partition_point(|&c| c <= pass);
        let save = |states: &[PixelState],
                    cppm: &[CppmLevel],
                    summary: &RenderSummary,
                    pass: u32| match &store {
            Some(store) => {
                let summary = RenderSummary {
                    seconds: seconds_so_far(),
                    ..*summary
                };
                store.save(pass, &summary, states, cppm)
            }
            None => Ok(()),
        };
        if pass > 0 {
            // Resumed: the bundle of a checkpoint at the saved pass may not have been written
            // before the stop, and a time limit may already be spent.
            let at_checkpoint = checkpoints.contains(&pass);
            let timed_out = stop.seconds.is_some_and(|s| earlier_seconds >= s);
            if at_checkpoint || timed_out {
                on_checkpoint(finite_bundle(
                    scene,
                    settings,
                    &states,
                    &cppm,
                    pass,
                    earlier_seconds,
                )?)?;
            }
            if timed_out || (target.is_some() && next_checkpoint == checkpoints.len()) {
                return Ok(summary);
            }
        }
        let mut last_save = Instant::now();
        // Photon buffers and grid, reused across passes (no page faults on fresh memory).
        let mut chunks: Vec<Vec<photon_map::Photon>> = Vec::new();
        let mut grid = PhotonGrid::default();
        let focus = photon_focus::photon_focus(scene, settings, max_radius);
        loop {
            pass += 1;
            let t0 = Instant::now();
            photon_trace::trace_photons(
                scene,
                settings,
                pass as u64,
                focus.as_ref(),
                max_stored,
                &mut chunks,
            )?;
            let stored = chunks.iter().map(|c| c.len() as u64).sum();
            let t_traced = Instant::now();
            let cell = grid_cell_size(&states, &cppm, settings.mode, max_radius);
            grid.rebuild(&chunks, cell);
            let t1 = Instant::now();
            let ctx = PassContext {
                scene,
                settings,
                grid: &grid,
                max_radius,
                pass,
            };
            let cppm_levels = settings.cppm_levels();
            let visible_points: u64 = if cppm_levels == 0 {
                states
                    .par_iter_mut()
                    .enumerate()
                    .with_min_len(64)
                    .map(|(i, s)| render_pixel(&ctx, i, s, &mut []))
                    .sum()
            } else {
                states
                    .par_iter_mut()
                    .zip(cppm.par_chunks_mut(cppm_levels))
                    .enumerate()
                    .with_min_len(64)
                    .map(|(i, (s, levels))| render_pixel(&ctx, i, s, levels))
                    .sum()
            };
            let t2 = Instant::now();
            summary.passes = pass;
            summary.photon_seconds += (t1 - t0).as_secs_f64();
            summary.grid_seconds += (t1 - t_traced).as_secs_f64();
            summary.gather_seconds += (t2 - t1).as_secs_f64();
            summary.photons_emitted += settings.photons_per_pass;
            summary.photons_stored += stored;
            summary.visible_points += visible_points;
            let elapsed = seconds_so_far();
            progress(&PassProgress {
                pass,
                target_passes: target,
                elapsed,
                photons_emitted: summary.photons_emitted,
                photons_stored: stored,
                visible_points,
            });
            let timed_out = stop.seconds.is_some_and(|s| elapsed >= s);
            let at_checkpoint = checkpoints.get(next_checkpoint) == Some(&pass);
            if at_checkpoint {
                next_checkpoint += 1;
            }
            if at_checkpoint || timed_out {
                on_checkpoint(finite_bundle(
                    scene, settings, &states, &cppm, pass, elapsed,
                )?)?;
            }
            let done = timed_out || (target.is_some() && next_checkpoint == checkpoints.len());
            // The bundle first, then the state: a stop in between redoes a few passes and
            // rewrites the same bundle, instead of resuming past a bundle never written.
            if store.is_some()
                && (done
                    || at_checkpoint
                    || last_save.elapsed().as_secs_f64() >= state.map_or(0.0, |f| f.interval))
            {
                save(&states, &cppm, &summary, pass)?;
                last_save = Instant::now();
            }
            if done {
                break;
            }
        }
        summary.seconds = seconds_so_far();
        Ok(summary)
    })?
}
