//! Per-scene results on disk, so that `evaluate --resume` continues a killed evaluation: every
//! finished scene is written to `<output>/scenes/<name>.json` with a fingerprint of what its
//! numbers depend on (the settings, the model files, the scene's files and the reference), and a
//! resumed run takes a scene from there when the fingerprint matches and its pictures are on
//! disk; anything else is evaluated again.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::config::{EvalConfig, EvalScene};
use crate::SceneResult;
use renderer::integrators::sppm::DEFAULT_EMITTER_SAMPLES_MULTI_LEVEL;

/// Format tag of a per-scene result file.
const FORMAT: &str = "sppm-ml-eval-scene/1";

/// A per-scene result file.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SavedScene {
    /// [`FORMAT`].
    format: String,
    /// [`scene_fingerprint`] of the run that wrote it.
    fingerprint: String,
    /// The scene's result.
    result: SceneResult,
}

/// Where a scene's result is kept.
pub fn result_path(output: &Path, stem: &str) -> PathBuf {
    output.join("scenes").join(format!("{stem}.json"))
}

/// Adds `path`'s length and bytes to `h` (an error names the file).
fn hash_file(h: &mut Sha256, path: &Path) -> Result<()> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    h.update((bytes.len() as u64).to_le_bytes());
    h.update(&bytes);
    Ok(())
}

/// SHA-256 over what every scene's measurements depend on: the settings that reach the renders
/// and the reconstruction (photons, passes, seed, threads, tile, backend, engine, depth) and
/// every file of the model directories (main and ablation). Computed once per evaluation.
pub fn run_fingerprint(config: &EvalConfig) -> Result<String> {
    let mut settings = serde_json::json!({
        "photons_per_pass": config.photons_per_pass,
        "passes": config.pass_counts(),
        "seed": config.seed,
        "threads": config.threads,
        "tile": config.tile,
        "backend": config.backend,
        "engine": config.engine,
        "max_depth": config.max_depth,
    });
    // Only when there are peers, so that results saved before peers existed still match.
    if !config.peers.is_empty() {
        settings["peers"] = serde_json::json!(config.peers);
    }
    // Light samples per visible point of our runs: named unless one, the only count there was
    // before the option existed.
    let emitter_samples = config
        .emitter_samples
        .unwrap_or(DEFAULT_EMITTER_SAMPLES_MULTI_LEVEL);
    if emitter_samples != 1 {
        settings["emitter_samples"] = serde_json::json!(emitter_samples);
    }
    if let Some(n) = config.standard_emitter_samples.filter(|&n| n != 1) {
        settings["standard_emitter_samples"] = serde_json::json!(n);
    }
    // Where ours gathers ỹ's photons is named unless at subpath A, the only place there was
    // before the option: results saved with A-only bundles are not resumed as both.
    let sharp_level = config.sharp_level.unwrap_or_default();
    if sharp_level != renderer::integrators::sppm::SharpLevel::SubpathA {
        settings["sharp_level"] = serde_json::json!(sharp_level);
    }
    // The eye sampler is named unless independent, the only one there was before the option.
    if let Some(s) = config
        .sampler
        .filter(|&s| s != renderer::integrators::sppm::EyeSampler::Independent)
    {
        settings["sampler"] = serde_json::json!(s);
    }
    // The photon focus is named unless zero, the only share there was before the option.
    if let Some(f) = config.photon_focus.filter(|&f| f != 0.0) {
        settings["photon_focus"] = serde_json::json!(f);
    }
    // Only CPPM is named: the fingerprints of SPPM evaluations stay what they were before
    // the option existed.
    if config.schedule != renderer::integrators::sppm::RadiusSchedule::Sppm {
        settings["schedule"] = serde_json::json!(config.schedule.name());
    }
    let mut h = Sha256::new();
    h.update(settings.to_string().as_bytes());
    let models =
        std::iter::once(&config.model).chain(config.ablation.iter().flat_map(|a| &a.dual_models));
    for dir in models {
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .with_context(|| format!("reading {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file())
            .collect();
        files.sort();
        for f in files {
            h.update(f.file_name().unwrap_or_default().as_encoded_bytes());
            hash_file(&mut h, &f)?;
        }
    }
    Ok(hex(h))
}

/// SHA-256 over what one scene's measurements depend on: the evaluation's [`run_fingerprint`]
/// `run`, the scene's name and reference, and its scene fingerprint (its defines and the
/// contents of the scene file and every file it reads: includes, meshes, textures). The
/// toolkit's own code is not hashed: do not resume across an update of the toolkit.
pub fn scene_fingerprint(run: &str, scene: &EvalScene) -> Result<String> {
    let mut h = Sha256::new();
    h.update(run.as_bytes());
    h.update(
        serde_json::json!({ "scene": scene.name })
            .to_string()
            .as_bytes(),
    );
    let files = renderer::state_file::scene_fingerprint(&scene.xml, &scene.defines)
        .with_context(|| format!("scene {}", scene.name))?;
    h.update(files.as_bytes());
    hash_file(&mut h, &scene.reference)?;
    Ok(hex(h))
}

/// The digest as lower-case hex.
fn hex(h: Sha256) -> String {
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Writes a scene's result atomically.
pub fn save(path: &Path, fingerprint: &str, result: &SceneResult) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let saved = SavedScene {
        format: FORMAT.into(),
        fingerprint: fingerprint.into(),
        result: result.clone(),
    };
    let json = serde_json::to_string_pretty(&saved)?;
    crate::images::write_atomic(path, json.as_bytes())
}

/// The saved result of a scene if it can be reused: written by a run with the same
/// `fingerprint`, successful, with its pictures in `output`. `Err` only for a file that exists
/// but cannot be read or parsed (named); a mismatch is `Ok(None)` with the reason.
pub fn load(
    path: &Path,
    fingerprint: &str,
    output: &Path,
) -> Result<std::result::Result<SceneResult, String>> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Ok(Err("not evaluated yet".into()))
        }
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let saved: SavedScene = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a per-scene result of evaluate", path.display()))?;
    if saved.format != FORMAT {
        return Ok(Err(format!("format {} (expected {FORMAT})", saved.format)));
    }
    if saved.fingerprint != fingerprint {
        return Ok(Err(
            "settings, model, scene or reference changed since it was saved".into(),
        ));
    }
    let r = saved.result;
    if r.error.is_some() || r.eval.is_none() {
        return Ok(Err("it failed last time".into()));
    }
    let pictures = [&r.plot, &r.comparison, &r.inputs];
    if let Some(missing) = pictures
        .iter()
        .map(|p| p.as_ref().map(|p| output.join(p)))
        .find(|p| !p.as_ref().is_some_and(|p| p.is_file()))
    {
        return Ok(Err(format!(
            "picture {} is missing",
            missing.map_or_else(|| "(none)".into(), |p| p.display().to_string())
        )));
    }
    Ok(Ok(r))
}

#[cfg(test)]
mod tests {
    use super::*;
    use renderer::integrators::sppm::{EyeSampler, SharpLevel};

    /// Where ours gathers ỹ's photons is part of what a saved scene depends on: results of
    /// A-only bundles are never resumed as both's, and the default is both.
    #[test]
    fn the_sharp_level_and_the_sampler_are_in_the_fingerprint() {
        let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/default");
        let config = |sharp: Option<SharpLevel>| -> EvalConfig {
            let mut c: EvalConfig = toml::from_str(&format!(
                "model = {:?}\noutput = \"o\"\nphotons_per_pass = 10\npasses = [2]\nseed = 1\n\
                 [[scenes]]\nname = \"s\"\nxml = \"s.xml\"\nreference = \"r.exr\"\n",
                model.display().to_string()
            ))
            .unwrap();
            c.sharp_level = sharp;
            c
        };
        let absent = run_fingerprint(&config(None)).unwrap();
        let both = run_fingerprint(&config(Some(SharpLevel::BothSubpaths))).unwrap();
        let a = run_fingerprint(&config(Some(SharpLevel::SubpathA))).unwrap();
        assert_eq!(absent, both);
        assert_ne!(a, both);
        // The eye sampler likewise: independent is what there was before the option.
        let sampled = |s: Option<EyeSampler>| {
            let mut c = config(None);
            c.sampler = s;
            run_fingerprint(&c).unwrap()
        };
        assert_eq!(sampled(None), absent);
        assert_eq!(sampled(Some(EyeSampler::Independent)), absent);
        assert_ne!(sampled(Some(EyeSampler::LowDiscrepancy)), absent);
    }
}
