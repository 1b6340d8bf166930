//! The peers a user gets for free beside ours, at equal time: standard SPPM denoised by Intel
//! Open Image Denoise ("SPPM + OIDN") and path tracing denoised by it ("PT + OIDN").
//!
//! OIDN is a development-side peer, like Mitsuba: it runs in Python (`pyoidn`) through
//! `scripts/oidn_denoise.py`, never linked into the toolkit. Each peer gets **at least** ours'
//! total time: its render goes to the first of its dense checkpoints at or past ours' total
//! minus the denoiser's own time, so a win of ours is never an artefact of a shorter peer run.

use std::time::Instant;

use renderer::film::render_pixels;
use renderer::integrators::path::PathTracer;
use renderer::integrators::RayIntegrator;
use renderer::scene::Scene;
use serde::{Deserialize, Serialize};

/// A peer method of the equal-time comparison.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Peer {
    /// Standard single-level SPPM, then OIDN.
    SppmOidn,
    /// The path tracer (`renderer::integrators::path`), then OIDN.
    PtOidn,
}

impl Peer {
    /// The name in configs, results.json and the report.
    pub fn name(self) -> &'static str {
        match self {
            Peer::SppmOidn => "SPPM + OIDN",
            Peer::PtOidn => "PT + OIDN",
        }
    }
}

/// A peer's result at one of ours' checkpoints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PeerResult {
    /// SPPM passes or path-tracing samples per pixel of the denoised image.
    pub samples: u32,
    /// Render seconds of that image.
    pub render_seconds: f64,
    /// The render time it was given: ours' total less the denoiser's time measured before the
    /// peer ran; `render_seconds` is at least this unless the peer hit its sample cap.
    pub render_budget_seconds: f64,
    /// OIDN seconds (median of the timed calls).
    pub denoise_seconds: f64,
    /// render + denoise: at least ours' total.
    pub total_seconds: f64,
    /// relMSE of the denoised image.
    pub relmse: f64,
    /// ours / this peer (< 1: ours is better).
    pub ratio: f64,
}

pub use infer::oidn::{Denoiser, Guides};

/// The first of `checkpoints` (sorted by time, `(samples, seconds)`) at or past `target`
/// seconds, or the last one if none gets there (its time is then below the target: the
/// caller reports what it got).
pub fn first_at_or_past(checkpoints: &[(u32, f64)], target: f64) -> Option<usize> {
    if checkpoints.is_empty() {
        return None;
    }
    Some(
        checkpoints
            .iter()
            .position(|&(_, s)| s >= target)
            .unwrap_or(checkpoints.len() - 1),
    )
}

/// Progressive path tracing: independent batches of samples (batch k uses the tracer's pass
/// index k, so no sample repeats), accumulated into one mean; `keep(spp, seconds, image)` sees
/// the running image after every batch, whose sizes grow by 2^(1/8) (eight checkpoints per
/// doubling of the samples). Stops after the first batch whose accumulated render time reaches
/// `until_seconds`, or at `max_spp`.
pub fn path_trace_progressive(
    scene: &Scene,
    tracer: &PathTracer,
    seed: u64,
    until_seconds: f64,
    max_spp: u32,
    mut keep: impl FnMut(u32, f64, &[f32]),
) {
    let res = scene.camera.resolution();
    let pixels = (res.x * res.y) as usize;
    let mut sum = vec![0.0f64; 3 * pixels];
    let mut spp_done = 0u32;
    let mut seconds = 0.0f64;
    let mut k = 0u32;
    while spp_done < max_spp {
        let target = (2f64.powf(k as f64 / 8.0).round() as u32).max(spp_done + 1);
        let batch = target.min(max_spp) - spp_done;
        let t = Instant::now();
        let film = render_pixels(res.x, res.y, None, batch as u64, |x, y| {
            tracer.pixel(scene, x, y, batch, seed, u64::from(k) + 1)
        });
        seconds += t.elapsed().as_secs_f64();
        for (i, p) in film.pixels.iter().enumerate() {
            for (c, v) in p.to_array().into_iter().enumerate() {
                sum[c * pixels + i] += f64::from(v) * f64::from(batch);
            }
        }
        spp_done += batch;
        let n = f64::from(spp_done);
        let image: Vec<f32> = sum.iter().map(|&s| (s / n) as f32).collect();
        keep(spp_done, seconds, &image);
        if seconds >= until_seconds {
            break;
        }
        k += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peers_get_at_least_equal_time() {
        let cps = [(1, 0.5), (2, 1.0), (3, 1.6), (4, 2.2)];
        assert_eq!(first_at_or_past(&cps, 1.0), Some(1));
        assert_eq!(first_at_or_past(&cps, 1.1), Some(2));
        assert_eq!(first_at_or_past(&cps, 0.1), Some(0));
        // Never got there: the last one, below the target (reported as such).
        assert_eq!(first_at_or_past(&cps, 9.0), Some(3));
        assert_eq!(first_at_or_past(&[], 1.0), None);
    }
}
