//! The saved state of an SPPM run (`render --state FILE`): everything one pass hands to the
//! next — each pixel's radius, Welford accumulators and G-buffer sums, the pass count and the
//! run's timing — so a run that is killed resumes from its last save and ends bit-identical to
//! one that never stopped (every random stream is keyed by seed, pass and pixel, and the photon
//! grid's cell size is a function of the saved radii).
//!
//! The file ([`crate::state_file`] framing, first line `sppm-run-state 2`): the header
//! ([`StateHeader`]: the run's identity, pass count and totals), then per pixel, little-endian:
//! r² (f32), the pass that set it (u32), for each stored level the Welford count (u32), mean
//! (3 × f64) and sum of squared deviations (3 × f64), the G-buffer sums: albedo (3 × f64),
//! normal (3 × f64), depth (f64), and the Welford accumulators (count, mean, sum of squared
//! deviations) of the photon-free radiance of subpaths A and B.
//! `sppm` stores one level, `sppm-ml` five. A CPPM run (`schedule` in the header) appends to
//! each pixel's record its levels' CPPM states (one for `sppm`, five for `sppm-ml`): r² (f32),
//! stage (u32), the 12 cell counts (u32). SPPM files have neither, exactly as before CPPM.
//! (Version 1 had no photon-free sums: such a file is refused by its first line.)

use anyhow::{bail, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::accumulate::{GBufferSum, Welford};
use super::cppm::{self, CppmLevel, CELLS};
use super::radius::{RadiusSchedule, LEVELS};
use super::{PixelState, RenderSummary, SppmMode, SppmSettings};
use crate::state_file::{self, check_identity, Cursor, StateFile};

/// First line of an SPPM state file.
const MAGIC: &str = "sppm-run-state 2";

/// The settings that decide what a run computes; a state is resumed only under equal ones.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RunIdentity {
    /// `sppm` or `sppm-ml`.
    integrator: String,
    /// The caller's scene fingerprint.
    scene_fingerprint: String,
    /// Image width (pixels).
    width: u32,
    /// Image height (pixels).
    height: u32,
    /// Photons per pass.
    photons_per_pass: u64,
    /// Seed of every random stream.
    seed: u64,
    /// The initial-radius cap in world units, as resolved for the scene.
    max_radius: f32,
    /// k of the k-nearest-photon initial radius.
    knn: usize,
    /// α of the shrink rule.
    alpha: f32,
    /// Bound on eye and photon bounces.
    max_depth: u32,
    /// Light samples at each visible point; not written when one, so the files of runs from
    /// before the option (which took one) read as such.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    emitter_samples: u32,
    /// The radius schedule; not written for SPPM runs, so their files are what they were
    /// before CPPM existed (and such files read as SPPM).
    #[serde(default, skip_serializing_if = "is_sppm")]
    schedule: RadiusSchedule,
    /// CPPM's parameters, for CPPM runs: a build with other ones refuses to resume.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cppm: Option<CppmParameters>,
    /// Share of the infinite lights' photons aimed at what the camera sees; not written when
    /// zero, so files from before the option (which aimed none) read as such.
    #[serde(default, skip_serializing_if = "is_zero")]
    photon_focus: f32,
    /// Where ỹ's photons are gathered ([`super::SharpLevel::name`]); not written for subpath A,
    /// so files from before the option (which gathered there) read as such.
    #[serde(default = "subpath_a", skip_serializing_if = "is_subpath_a")]
    sharp_level: String,
    /// Where the eye subpaths' random numbers come from across passes; not written for
    /// independent draws, so files from before the option (which drew so) read as such.
    #[serde(default, skip_serializing_if = "is_independent")]
    sampler: super::EyeSampler,
}

/// Whether the eye sampler is the independent one (then it is left out of the header).
fn is_independent(sampler: &super::EyeSampler) -> bool {
    *sampler == super::EyeSampler::Independent
}

/// [`super::SharpLevel::SubpathA`]'s name (serde's default of [`RunIdentity::sharp_level`]).
fn subpath_a() -> String {
    super::SharpLevel::SubpathA.name().into()
}

/// Whether `name` is [`super::SharpLevel::SubpathA`]'s (then it is left out of the header).
fn is_subpath_a(name: &str) -> bool {
    name == super::SharpLevel::SubpathA.name()
}

/// One (serde's default of [`RunIdentity::emitter_samples`]).
fn one() -> u32 {
    1
}

/// Whether `x` is zero (then it is left out of the header).
fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

/// Whether `n` is one (then it is left out of the header).
fn is_one(n: &u32) -> bool {
    *n == 1
}

/// Whether `schedule` is SPPM's (the default, left out of the header).
fn is_sppm(schedule: &RadiusSchedule) -> bool {
    *schedule == RadiusSchedule::Sppm
}

/// The constants of the CPPM rule ([`cppm`]) a CPPM run was saved under.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CppmParameters {
    /// Rings × sectors of the disk partition.
    cells: [usize; 2],
    /// n₀: the first count threshold.
    min_photons: f64,
    /// β: threshold growth per shrink.
    threshold_growth: f64,
    /// k: r² factor when neither disk looks uniform.
    area_factor: f32,
    /// r² factor when only the inner disk looks uniform.
    inner_area_factor: f32,
    /// Significance level of the tests.
    significance: f64,
}

impl CppmParameters {
    /// This build's.
    fn current() -> Self {
        CppmParameters {
            cells: [cppm::RINGS, cppm::SECTORS],
            min_photons: cppm::MIN_PHOTONS,
            threshold_growth: cppm::THRESHOLD_GROWTH,
            area_factor: cppm::AREA_FACTOR,
            inner_area_factor: cppm::INNER_AREA_FACTOR,
            significance: cppm::SIGNIFICANCE,
        }
    }
}

/// The JSON header of an SPPM state file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct StateHeader {
    /// What the run computes.
    run: RunIdentity,
    /// Passes done.
    passes: u32,
    /// Seconds of rendering so far (all sessions of the run).
    seconds: f64,
    /// Seconds spent in photon passes so far.
    photon_seconds: f64,
    /// Of those, seconds spent building photon grids.
    grid_seconds: f64,
    /// Seconds spent on eye subpaths and gathering so far.
    gather_seconds: f64,
    /// Photons emitted so far.
    photons_emitted: u64,
    /// Photons stored so far.
    photons_stored: u64,
    /// Visible points found so far.
    visible_points: u64,
}

/// A run's state as saved or loaded: the pass count, the totals so far and every pixel.
#[derive(Debug, Clone)]
pub(super) struct RunState {
    /// Passes done.
    pub passes: u32,
    /// Totals so far (`seconds` = rendering seconds over all sessions of the run).
    pub summary: RenderSummary,
    /// Per-pixel state, row-major.
    pub pixels: Vec<PixelState>,
    /// CPPM runs: each pixel's CPPM levels, pixel after pixel; empty for SPPM runs.
    pub cppm: Vec<CppmLevel>,
}

/// Bytes of one CPPM level's record.
const CPPM_LEVEL_BYTES: usize = 8 + 4 * CELLS;

/// Bytes of one pixel's record with `levels` accumulators and `cppm_levels` CPPM levels.
fn pixel_bytes(levels: usize, cppm_levels: usize) -> usize {
    8 + (levels + 2) * (4 + 48) + 56 + cppm_levels * CPPM_LEVEL_BYTES
}

/// Appends a vector of three f64.
fn put_dvec3(out: &mut Vec<u8>, v: DVec3) {
    for c in v.to_array() {
        out.extend_from_slice(&c.to_le_bytes());
    }
}

/// Serialises the pixels with `levels` accumulators each and their `cppm` levels
/// (`cppm_levels` per pixel).
fn encode_pixels(
    pixels: &[PixelState],
    levels: usize,
    cppm: &[CppmLevel],
    cppm_levels: usize,
) -> Vec<u8> {
    let mut out = Vec::with_capacity(pixels.len() * pixel_bytes(levels, cppm_levels));
    for (i, p) in pixels.iter().enumerate() {
        out.extend_from_slice(&p.r2.to_le_bytes());
        out.extend_from_slice(&p.init_pass.to_le_bytes());
        for w in &p.levels[..levels] {
            out.extend_from_slice(&w.count.to_le_bytes());
            put_dvec3(&mut out, w.mean);
            put_dvec3(&mut out, w.m2);
        }
        put_dvec3(&mut out, p.gbuffer.albedo);
        put_dvec3(&mut out, p.gbuffer.normal);
        out.extend_from_slice(&p.gbuffer.depth.to_le_bytes());
        for w in &p.direct {
            out.extend_from_slice(&w.count.to_le_bytes());
            put_dvec3(&mut out, w.mean);
            put_dvec3(&mut out, w.m2);
        }
        for level in &cppm[i * cppm_levels..(i + 1) * cppm_levels] {
            out.extend_from_slice(&level.r2.to_le_bytes());
            out.extend_from_slice(&level.stage.to_le_bytes());
            for c in level.cells {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    out
}

/// Reads the pixels and their CPPM levels back (`body` holds whole records only).
fn decode_pixels(
    body: &[u8],
    levels: usize,
    cppm_levels: usize,
) -> (Vec<PixelState>, Vec<CppmLevel>) {
    let mut cppm = Vec::with_capacity(body.len() / pixel_bytes(levels, cppm_levels) * cppm_levels);
    let pixels = body
        .chunks_exact(pixel_bytes(levels, cppm_levels))
        .map(|record| {
            let mut c = Cursor::new(record);
            let mut p = PixelState {
                r2: c.f32(),
                init_pass: c.u32(),
                ..PixelState::default()
            };
            for w in &mut p.levels[..levels] {
                *w = Welford {
                    count: c.u32(),
                    mean: c.dvec3(),
                    m2: c.dvec3(),
                };
            }
            p.gbuffer = GBufferSum {
                albedo: c.dvec3(),
                normal: c.dvec3(),
                depth: c.f64(),
            };
            for w in &mut p.direct {
                *w = Welford {
                    count: c.u32(),
                    mean: c.dvec3(),
                    m2: c.dvec3(),
                };
            }
            for _ in 0..cppm_levels {
                cppm.push(CppmLevel {
                    r2: c.f32(),
                    stage: c.u32(),
                    cells: std::array::from_fn(|_| c.u32()),
                });
            }
            p
        })
        .collect();
    (pixels, cppm)
}

/// The state file of one run, with what that run computes.
pub(super) struct StateStore<'a> {
    /// Where and how often.
    pub file: &'a StateFile,
    /// What this run computes.
    run: RunIdentity,
    /// Accumulators stored per pixel.
    levels: usize,
    /// CPPM levels stored per pixel (0 for SPPM runs).
    cppm_levels: usize,
}

impl<'a> StateStore<'a> {
    /// The store of a run of `settings` on a `width`×`height` image with the resolved radius
    /// cap `max_radius`.
    pub fn new(
        file: &'a StateFile,
        settings: &SppmSettings,
        width: u32,
        height: u32,
        max_radius: f32,
    ) -> Self {
        StateStore {
            file,
            run: RunIdentity {
                integrator: settings.mode.name().into(),
                scene_fingerprint: file.scene_fingerprint.clone(),
                width,
                height,
                photons_per_pass: settings.photons_per_pass,
                seed: settings.seed,
                max_radius,
                knn: settings.knn,
                alpha: settings.alpha,
                max_depth: settings.max_depth,
                emitter_samples: settings.emitter_samples(),
                schedule: settings.schedule,
                cppm: (settings.schedule == RadiusSchedule::Cppm).then(CppmParameters::current),
                photon_focus: settings.photon_focus,
                sharp_level: settings.sharp_level().name().into(),
                sampler: settings.sampler,
            },
            levels: match settings.mode {
                SppmMode::MultiLevel => LEVELS,
                SppmMode::Single => 1,
            },
            cppm_levels: settings.cppm_levels(),
        }
    }

    /// Writes the state after `passes` passes atomically: the totals `s`, the `pixels` and
    /// their `cppm` levels (empty for SPPM runs).
    pub fn save(
        &self,
        passes: u32,
        s: &RenderSummary,
        pixels: &[PixelState],
        cppm: &[CppmLevel],
    ) -> Result<()> {
        debug_assert_eq!(cppm.len(), pixels.len() * self.cppm_levels);
        let header = StateHeader {
            run: self.run.clone(),
            passes,
            seconds: s.seconds,
            photon_seconds: s.photon_seconds,
            grid_seconds: s.grid_seconds,
            gather_seconds: s.gather_seconds,
            photons_emitted: s.photons_emitted,
            photons_stored: s.photons_stored,
            visible_points: s.visible_points,
        };
        let body = encode_pixels(pixels, self.levels, cppm, self.cppm_levels);
        state_file::save(&self.file.path, MAGIC, &header, &body)
    }

    /// The saved state, if the file exists; an error naming the file when it is not an SPPM
    /// state, is damaged, or was saved by a run with other settings.
    pub fn load(&self) -> Result<Option<RunState>> {
        let path = &self.file.path;
        let Some((header, body)) = state_file::load::<StateHeader>(path, MAGIC)? else {
            return Ok(None);
        };
        if header.run.schedule != self.run.schedule {
            bail!(
                "{}: the saved run used the {} radius schedule, this one {}; resume with \
                 --schedule {}, or give --state a new file name",
                path.display(),
                header.run.schedule.name(),
                self.run.schedule.name(),
                header.run.schedule.name()
            );
        }
        check_identity(path, &header.run, &self.run)?;
        let pixels = self.run.width as usize * self.run.height as usize;
        let record = pixel_bytes(self.levels, self.cppm_levels);
        if body.len() != pixels * record || header.passes == 0 {
            bail!(
                "{}: damaged run state: {} bytes of pixel data at pass {}, expected {} for \
                 {pixels} pixels",
                path.display(),
                body.len(),
                header.passes,
                pixels * record
            );
        }
        let (pixels, cppm) = decode_pixels(&body, self.levels, self.cppm_levels);
        Ok(Some(RunState {
            passes: header.passes,
            summary: RenderSummary {
                passes: header.passes,
                seconds: header.seconds,
                photon_seconds: header.photon_seconds,
                grid_seconds: header.grid_seconds,
                gather_seconds: header.gather_seconds,
                photons_emitted: header.photons_emitted,
                photons_stored: header.photons_stored,
                visible_points: header.visible_points,
                resumed_from: 0,
            },
            pixels,
            cppm,
        }))
    }
}
