//! The peers a user gets for free beside ours, at equal time: standard SPPM denoised by Intel
//! Open Image Denoise ("SPPM + OIDN") and path tracing denoised by it ("PT + OIDN").
//!
//! OIDN is a development-side peer, like Mitsuba: it runs in Python (`pyoidn`) through
//! `scripts/oidn_denoise.py`, never linked into the toolkit. Each peer gets **at least** ours'
//! total time: its render goes to the first of its dense checkpoints at or past ours' total
//! minus the denoiser's own time, so a win of ours is never an artefact of a shorter peer run.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};
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

/// The OIDN runner: a Python interpreter and `scripts/oidn_denoise.py`.
#[derive(Clone, Debug)]
pub struct Denoiser {
    /// Python interpreter.
    pub python: String,
    /// The script.
    pub script: PathBuf,
}

/// Auxiliary images for OIDN: albedo and normal, planar RGB like the color.
pub struct Guides<'a> {
    /// Albedo.
    pub albedo: &'a [f32],
    /// Normal.
    pub normal: &'a [f32],
}

impl Denoiser {
    /// Checks that the script runs and `pyoidn` imports; returns its version.
    pub fn check(&self) -> Result<String> {
        let out = Command::new(&self.python)
            .arg(&self.script)
            .arg("--version")
            .output()
            .with_context(|| format!("running {} {}", self.python, self.script.display()))?;
        if !out.status.success() {
            bail!(
                "the OIDN peers need {} {} to run: {}",
                self.python,
                self.script.display(),
                String::from_utf8_lossy(&out.stderr).trim()
            );
        }
        Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
    }

    /// Denoises planar RGB `color` (`width`×`height`); returns the result (planar) and the
    /// denoiser's seconds per image.
    pub fn denoise(
        &self,
        width: usize,
        height: usize,
        color: &[f32],
        guides: &Guides,
    ) -> Result<(Vec<f32>, f64)> {
        let dir = tempfile::tempdir().context("creating a temporary folder for OIDN")?;
        let path = |name: &str| dir.path().join(name);
        write_interleaved(&path("color.f32"), color, width * height)?;
        write_interleaved(&path("albedo.f32"), guides.albedo, width * height)?;
        write_interleaved(&path("normal.f32"), guides.normal, width * height)?;
        let out = Command::new(&self.python)
            .arg(&self.script)
            .args([
                "--width",
                &width.to_string(),
                "--height",
                &height.to_string(),
            ])
            .arg("--color")
            .arg(path("color.f32"))
            .arg("--albedo")
            .arg(path("albedo.f32"))
            .arg("--normal")
            .arg(path("normal.f32"))
            .arg("--output")
            .arg(path("out.f32"))
            .output()
            .with_context(|| format!("running {} {}", self.python, self.script.display()))?;
        if !out.status.success() {
            bail!(
                "{}: {}",
                self.script.display(),
                String::from_utf8_lossy(&out.stderr).trim()
            );
        }
        let report: serde_json::Value = serde_json::from_slice(&out.stdout)
            .with_context(|| format!("{}: its output", self.script.display()))?;
        let seconds = report["seconds"]
            .as_f64()
            .with_context(|| format!("{}: no `seconds` in {report}", self.script.display()))?;
        let image = read_interleaved(&path("out.f32"), width * height)?;
        Ok((image, seconds))
    }
}

/// Writes planar RGB as interleaved little-endian f32 (the script's format).
fn write_interleaved(path: &Path, planar: &[f32], pixels: usize) -> Result<()> {
    if planar.len() != 3 * pixels {
        bail!(
            "{}: {} values for {pixels} pixels",
            path.display(),
            planar.len()
        );
    }
    let mut bytes = Vec::with_capacity(planar.len() * 4);
    for i in 0..pixels {
        for c in 0..3 {
            bytes.extend_from_slice(&planar[c * pixels + i].to_le_bytes());
        }
    }
    std::fs::write(path, bytes).with_context(|| path.display().to_string())
}

/// Reads the script's interleaved output back as planar RGB.
fn read_interleaved(path: &Path, pixels: usize) -> Result<Vec<f32>> {
    let bytes = std::fs::read(path).with_context(|| path.display().to_string())?;
    if bytes.len() != pixels * 12 {
        bail!(
            "{}: {} bytes, expected {}",
            path.display(),
            bytes.len(),
            pixels * 12
        );
    }
    let mut planar = vec![0.0f32; 3 * pixels];
    for (k, chunk) in bytes.chunks_exact(4).enumerate() {
        let v = f32::from_le_bytes(chunk.try_into().expect("4 bytes"));
        planar[(k % 3) * pixels + k / 3] = v;
    }
    Ok(planar)
}

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
    fn interleaving_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let planar: Vec<f32> = (0..12).map(|v| v as f32 * 0.5).collect();
        let p = dir.path().join("x.f32");
        write_interleaved(&p, &planar, 4).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        // Pixel 1's green (planar index 4 + 1 = 5) is the 5th interleaved value (1·3 + 1).
        let v = f32::from_le_bytes(bytes[16..20].try_into().unwrap());
        assert_eq!(v, planar[5]);
        assert_eq!(read_interleaved(&p, 4).unwrap(), planar);
        assert!(
            read_interleaved(&p, 5).is_err(),
            "a size mismatch is an error"
        );
        assert!(write_interleaved(&p, &planar, 3).is_err());
    }

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
