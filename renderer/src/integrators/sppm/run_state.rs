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
//! `sppm` stores one level, `sppm-ml` five. (Version 1 had no photon-free sums: such a file is
//! refused by its first line.)

use anyhow::{bail, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::accumulate::{GBufferSum, Welford};
use super::radius::LEVELS;
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
}

/// Bytes of one pixel's record with `levels` accumulators.
fn pixel_bytes(levels: usize) -> usize {
    8 + (levels + 2) * (4 + 48) + 56
}

/// Appends a vector of three f64.
fn put_dvec3(out: &mut Vec<u8>, v: DVec3) {
    for c in v.to_array() {
        out.extend_from_slice(&c.to_le_bytes());
    }
}

/// Serialises the pixels with `levels` accumulators each.
fn encode_pixels(pixels: &[PixelState], levels: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(pixels.len() * pixel_bytes(levels));
    for p in pixels {
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
    }
    out
}

/// Reads the pixels back (`body` holds whole records only).
fn decode_pixels(body: &[u8], levels: usize) -> Vec<PixelState> {
    body.chunks_exact(pixel_bytes(levels))
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
            p
        })
        .collect()
}

/// The state file of one run, with what that run computes.
pub(super) struct StateStore<'a> {
    /// Where and how often.
    pub file: &'a StateFile,
    /// What this run computes.
    run: RunIdentity,
    /// Accumulators stored per pixel.
    levels: usize,
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
            },
            levels: match settings.mode {
                SppmMode::MultiLevel => LEVELS,
                SppmMode::Single => 1,
            },
        }
    }

    /// Writes the state after `passes` passes atomically: the totals `s` and the `pixels`.
    pub fn save(&self, passes: u32, s: &RenderSummary, pixels: &[PixelState]) -> Result<()> {
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
        let body = encode_pixels(pixels, self.levels);
        state_file::save(&self.file.path, MAGIC, &header, &body)
    }

    /// The saved state, if the file exists; an error naming the file when it is not an SPPM
    /// state, is damaged, or was saved by a run with other settings.
    pub fn load(&self) -> Result<Option<RunState>> {
        let path = &self.file.path;
        let Some((header, body)) = state_file::load::<StateHeader>(path, MAGIC)? else {
            return Ok(None);
        };
        check_identity(path, &header.run, &self.run)?;
        let pixels = self.run.width as usize * self.run.height as usize;
        if body.len() != pixels * pixel_bytes(self.levels) || header.passes == 0 {
            bail!(
                "{}: damaged run state: {} bytes of pixel data at pass {}, expected {} for \
                 {pixels} pixels",
                path.display(),
                body.len(),
                header.passes,
                pixels * pixel_bytes(self.levels)
            );
        }
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
            pixels: decode_pixels(&body, self.levels),
        }))
    }
}
