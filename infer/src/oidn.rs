//! Intel Open Image Denoise as a development-side peer: `scripts/oidn_denoise.py` run through a
//! Python interpreter (`pyoidn`), never linked into the toolkit. One home for calling it: the
//! equal-time peers of `evaluate` ("SPPM + OIDN", "PT + OIDN") and `bench_infer`'s speed
//! comparison. Images travel as raw interleaved little-endian f32 RGB files in a temporary
//! folder; the script reports its own median time per image.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

/// The OIDN runner: a Python interpreter and `scripts/oidn_denoise.py`.
#[derive(Clone, Debug)]
pub struct Denoiser {
    /// Python interpreter.
    pub python: String,
    /// The script.
    pub script: PathBuf,
    /// Timed calls per image after the warm-up (the reported time is their median).
    pub repeats: u32,
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
        let (image, report) = self.denoise_with_report(width, height, color, guides)?;
        let seconds = report["seconds"]
            .as_f64()
            .with_context(|| format!("{}: no `seconds` in {report}", self.script.display()))?;
        Ok((image, seconds))
    }

    /// [`Denoiser::denoise`] with the script's whole JSON report (its timings and version).
    pub fn denoise_with_report(
        &self,
        width: usize,
        height: usize,
        color: &[f32],
        guides: &Guides,
    ) -> Result<(Vec<f32>, serde_json::Value)> {
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
            .args(["--repeats", &self.repeats.max(1).to_string()])
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
        let image = read_interleaved(&path("out.f32"), width * height)?;
        Ok((image, report))
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
}
