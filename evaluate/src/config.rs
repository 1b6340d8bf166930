//! The `evaluate` configuration file (TOML) and the list of scenes it resolves to: explicit
//! XML + reference pairs and/or the scenes of one split of a `datagen` dataset.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use bundle::manifest::Manifest;
use renderer::integrators::sppm::RadiusSchedule;
use serde::{Deserialize, Serialize};

/// `configs/eval/<name>.toml`. Relative paths are relative to the current directory (run from
/// the repository root), like the train and datagen configs.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct EvalConfig {
    /// Trained model directory (`model.json` + `model.bpk`).
    pub model: PathBuf,
    /// Where results.json, the plots, the images and index.html are written.
    pub output: PathBuf,
    /// Photons emitted per SPPM pass (both runs).
    pub photons_per_pass: u64,
    /// Pass counts at which the multi-level run is reconstructed, e.g. `[16, 32, 64, 128]`.
    pub passes: Vec<u32>,
    /// Render seed (both runs use it).
    pub seed: u64,
    /// Inference tile side in pixels (0 = whole image).
    #[serde(default = "default_tile")]
    pub tile: usize,
    /// Renderer worker threads (0 = all cores).
    #[serde(default)]
    pub threads: usize,
    /// Tensor backend name (`flex`, `ndarray`, `wgpu`).
    #[serde(default = "default_backend")]
    pub backend: String,
    /// Inference engine (`native`, `burn`); absent: native on `flex`, Burn otherwise.
    #[serde(default)]
    pub engine: Option<infer::Engine>,
    /// Bound on SPPM eye (delta/glossy) and photon bounces; default the renderer's (16).
    #[serde(default)]
    pub max_depth: Option<u32>,
    /// Light samples at each visible point of our multi-level runs (stratified); absent: the
    /// renderer's default for multi-level SPPM (two).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub emitter_samples: Option<u32>,
    /// Light samples at each visible point of the standard SPPM run, whose image the SPPM +
    /// OIDN peer denoises; absent: one, the paper's standard SPPM. Two makes both peers use
    /// the stratified direct-light estimate ours uses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub standard_emitter_samples: Option<u32>,
    /// Share of the infinite lights' photons aimed at what the camera sees, in both SPPM runs
    /// (renderer's `photon_focus`); absent: the renderer's default (none aimed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photon_focus: Option<f32>,
    /// Where our multi-level runs gather the sharp level's photons (renderer's `sharp_level`:
    /// `"both"` or `"a"`); absent: the renderer's default (both). The standard run has one
    /// subpath.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sharp_level: Option<renderer::integrators::sppm::SharpLevel>,
    /// Where the eye subpaths' random numbers come from across passes, in both SPPM runs alike
    /// (renderer's `sampler`: `"independent"` or `"ldsampler"`); absent: independent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampler: Option<renderer::integrators::sppm::EyeSampler>,
    /// Radius schedule of both runs: `sppm` (default) or `cppm`, which makes the study
    /// single-level CPPM against multi-level CPPM + reconstruction (the paper's "Ours + CPPM").
    /// Not written when `sppm`, so results saved before the option existed still match.
    #[serde(default, skip_serializing_if = "is_sppm")]
    pub schedule: RadiusSchedule,
    /// Evaluate only the first N scenes (explicit ones first, then the dataset's).
    #[serde(default)]
    pub limit: Option<usize>,
    /// Explicit scenes.
    #[serde(default)]
    pub scenes: Vec<ExplicitScene>,
    /// Scenes of a dataset split.
    #[serde(default)]
    pub dataset: Option<DatasetSource>,
    /// The dual-vs-multi ablation (paper Table 1), run when present.
    #[serde(default)]
    pub ablation: Option<AblationConfig>,
    /// Peers denoised by Intel Open Image Denoise at equal time, beside standard SPPM:
    /// `"sppm-oidn"`, `"pt-oidn"` (`crate::peers`; need Python with `pyoidn`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub peers: Vec<crate::peers::Peer>,
    /// Python interpreter running the OIDN peer script.
    #[serde(default = "default_python")]
    pub oidn_python: String,
    /// The OIDN peer script.
    #[serde(default = "default_oidn_script")]
    pub oidn_script: PathBuf,
}

fn default_python() -> String {
    "python3".into()
}

fn default_oidn_script() -> PathBuf {
    "scripts/oidn_denoise.py".into()
}

/// Whether `schedule` is the default, SPPM's.
fn is_sppm(schedule: &RadiusSchedule) -> bool {
    *schedule == RadiusSchedule::Sppm
}

/// `[ablation]`: networks combining fewer levels (e.g. Dual(ỹ, z̃2), trained with
/// `levels = [0, 2]`), each reconstructing the very bundles `model` reconstructs, at every
/// checkpoint; their relMSE is reported next to the main model's (paper Table 1).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AblationConfig {
    /// Model directories of the variants (`model.json` names the levels each combines).
    pub dual_models: Vec<PathBuf>,
}

/// One explicit scene.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ExplicitScene {
    /// Name shown in the report (default: the XML's parent directory name or file stem).
    #[serde(default)]
    pub name: Option<String>,
    /// Mitsuba 3 XML scene.
    pub xml: PathBuf,
    /// Reference RGB EXR of the same resolution.
    pub reference: PathBuf,
    /// `<default>` overrides of the scene file, as `render -D name=value`.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub defines: BTreeMap<String, String>,
    /// The reference's own noise (relMSE of the image against its expectation) where it was
    /// measured (`scenes/heldout` lists it): the report then warns where it is not small
    /// against the errors measured with it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_noise: Option<f64>,
}

/// The scenes of one split of a dataset written by `datagen`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetSource {
    /// Dataset directory (holds `manifest.json`).
    pub dir: PathBuf,
    /// Split to evaluate (`test` normally).
    #[serde(default = "default_split")]
    pub split: String,
    /// Only the scenes of these families (the manifest's `family`), e.g. the families a model
    /// never saw; absent: every family. A name the split does not have is an error.
    #[serde(default)]
    pub families: Option<Vec<String>>,
    /// Evaluate only the first N scenes of the split (in manifest order).
    #[serde(default)]
    pub limit: Option<usize>,
    /// Directory inside the dataset holding `<scene id>.exr` references that replace the
    /// manifest's (e.g. the averaged runs of `datagen average-references`; `references` for the
    /// training references). Absent: each scene's converged evaluation reference where the
    /// manifest lists one (`datagen evaluation-references`), else its training reference.
    #[serde(default)]
    pub references: Option<PathBuf>,
}

fn default_tile() -> usize {
    128
}

fn default_backend() -> String {
    "flex".into()
}

fn default_split() -> String {
    "test".into()
}

/// A scene to evaluate, with resolved paths.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalScene {
    /// Name used in the report and for file names.
    pub name: String,
    /// Mitsuba 3 XML scene.
    pub xml: PathBuf,
    /// Reference RGB EXR.
    pub reference: PathBuf,
    /// `<default>` overrides of the scene file (`-D name=value`).
    pub defines: Vec<(String, String)>,
    /// The reference's own noise (relMSE of the image against its expectation) where the
    /// dataset measured it: an evaluation reference's, or a training reference averaged from
    /// several runs.
    pub reference_noise: Option<f64>,
}

impl EvalConfig {
    /// Reads and checks a config file; errors name the file.
    pub fn load(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut config: EvalConfig =
            toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        // Checkpoints are rendered in increasing order once each: record them so.
        config.passes = config.pass_counts();
        config
            .validate()
            .with_context(|| format!("config {}", path.display()))?;
        Ok(config)
    }

    /// Checks values the run cannot use.
    pub fn validate(&self) -> Result<()> {
        if self.output.exists() && !self.output.is_dir() {
            bail!(
                "output = {}: exists and is not a directory",
                self.output.display()
            );
        }
        if self.threads > renderer::threads::MAX_THREADS {
            bail!(
                "threads = {}: at most {} worker threads are supported",
                self.threads,
                renderer::threads::MAX_THREADS
            );
        }
        if self.photons_per_pass == 0 {
            bail!("photons_per_pass must be positive");
        }
        if self.passes.is_empty() || self.passes.contains(&0) {
            bail!("passes must be a non-empty list of positive pass counts");
        }
        if self.scenes.is_empty() && self.dataset.is_none() {
            bail!("no scenes: give [[scenes]] entries and/or a [dataset]");
        }
        if self.limit == Some(0) {
            bail!("limit (--limit) must be at least 1");
        }
        for s in &self.scenes {
            if let Some(noise) = s.reference_noise.filter(|n| !(n.is_finite() && *n >= 0.0)) {
                bail!(
                    "[[scenes]] {}: reference_noise must be a finite relMSE ≥ 0, got {noise}",
                    s.xml.display()
                );
            }
        }
        if self.dataset.as_ref().is_some_and(|d| d.limit == Some(0)) {
            bail!("[dataset] limit must be at least 1");
        }
        if self.max_depth == Some(0) {
            bail!("max_depth must be positive");
        }
        if self.emitter_samples == Some(0) || self.standard_emitter_samples == Some(0) {
            bail!("emitter_samples and standard_emitter_samples must be positive");
        }
        if let Some(f) = self.photon_focus {
            if !(0.0..1.0).contains(&f) {
                bail!("photon_focus must lie in [0, 1), got {f}");
            }
        }
        for (i, peer) in self.peers.iter().enumerate() {
            if self.peers[..i].contains(peer) {
                bail!("peers lists {:?} twice", crate::peers::Peer::name(*peer));
            }
        }
        if let Some(a) = &self.ablation {
            if a.dual_models.is_empty() {
                bail!("[ablation] dual_models must name at least one model directory");
            }
        }
        Ok(())
    }

    /// Pass checkpoints, sorted and deduplicated.
    pub fn pass_counts(&self) -> Vec<u32> {
        let mut p = self.passes.clone();
        p.sort_unstable();
        p.dedup();
        p
    }

    /// All scenes: the explicit ones, then the dataset split's. Missing files are errors here,
    /// before anything is rendered.
    pub fn resolve_scenes(&self) -> Result<Vec<EvalScene>> {
        let mut out = Vec::new();
        for s in &self.scenes {
            let name = s.name.clone().unwrap_or_else(|| scene_name(&s.xml));
            out.push(EvalScene {
                name,
                xml: s.xml.clone(),
                reference: s.reference.clone(),
                defines: s.defines.clone().into_iter().collect(),
                reference_noise: s.reference_noise,
            });
        }
        if let Some(d) = &self.dataset {
            let path = d.dir.join(bundle::manifest::MANIFEST_FILE);
            let manifest: Manifest = Manifest::load(&d.dir)
                .with_context(|| format!("[dataset] dir = {}", d.dir.display()))?;
            if let Some(note) = manifest.partial_note(&d.dir) {
                eprintln!("note: {note}");
            }
            let all_splits: Vec<&str> = manifest.scenes.iter().map(|s| s.split.name()).collect();
            if let Some(families) = &d.families {
                let mut known: Vec<&str> = manifest
                    .scenes
                    .iter()
                    .filter(|s| s.split.name() == d.split)
                    .map(|s| s.family.as_str())
                    .collect();
                known.sort_unstable();
                known.dedup();
                let unknown: Vec<&str> = families
                    .iter()
                    .map(String::as_str)
                    .filter(|f| !known.contains(f))
                    .collect();
                if !unknown.is_empty() {
                    bail!(
                        "{}: split \"{}\" has no family {} (its families: {})",
                        path.display(),
                        d.split,
                        unknown.join(", "),
                        known.join(", ")
                    );
                }
            }
            let mut split_scenes: Vec<_> = manifest
                .scenes
                .into_iter()
                .filter(|s| s.split.name() == d.split)
                .filter(|s| d.families.as_ref().is_none_or(|f| f.contains(&s.family)))
                .collect();
            if let Some(n) = d.limit {
                split_scenes.truncate(n);
            }
            // Converged evaluation references (`datagen evaluation-references`) are measured
            // against where the manifest has them; a split where only some scenes have one
            // would mix two kinds of reference in one table, so it is refused.
            let converged = split_scenes
                .iter()
                .filter(|s| s.evaluation_reference.is_some())
                .count();
            if d.references.is_none() && converged > 0 && converged < split_scenes.len() {
                let missing: Vec<&str> = split_scenes
                    .iter()
                    .filter(|s| s.evaluation_reference.is_none())
                    .map(|s| s.id.as_str())
                    .collect();
                bail!(
                    "{}: {} of {} scenes of split \"{}\" have a converged evaluation reference, \
                     {} do not ({}): finish `datagen evaluation-references`, or measure against \
                     the training references with `references = \"references\"`",
                    path.display(),
                    converged,
                    split_scenes.len(),
                    d.split,
                    missing.len(),
                    missing.join(", ")
                );
            }
            for s in &split_scenes {
                if let Some(e) = s.evaluation_reference.as_ref().filter(|e| !e.converged) {
                    eprintln!(
                        "warning: scene {}: its evaluation reference did not reach its noise \
                         target (noise {:.2e} = {:.2} x the best input's error): differences \
                         below that are not measured",
                        s.id,
                        e.noise,
                        e.noise / e.input_relmse
                    );
                }
            }
            let chosen: Vec<EvalScene> = split_scenes
                .into_iter()
                .map(|s| {
                    // The reference measured against, with its recorded noise where known.
                    let (reference, reference_noise) =
                        match (&d.references, &s.evaluation_reference) {
                            (Some(dir), _) => {
                                (bundle::scene_reference_path(&d.dir.join(dir), &s.id), None)
                            }
                            (None, Some(e)) => (d.dir.join(&e.path), Some(e.noise)),
                            (None, None) => (d.dir.join(&s.reference), s.reference_noise),
                        };
                    EvalScene {
                        reference,
                        reference_noise,
                        name: s.id,
                        xml: d.dir.join(s.xml),
                        defines: s.defines.into_iter().collect(),
                    }
                })
                .collect();
            if chosen.is_empty() {
                let mut splits = all_splits;
                splits.sort_unstable();
                splits.dedup();
                bail!(
                    "{}: no scene in split \"{}\" (the dataset's splits: {})",
                    path.display(),
                    d.split,
                    splits.join(", ")
                );
            }
            out.extend(chosen);
        }
        if let Some(n) = self.limit {
            out.truncate(n);
        }
        for s in &out {
            for p in [&s.xml, &s.reference] {
                if !p.is_file() {
                    bail!("scene {}: {} does not exist", s.name, p.display());
                }
            }
        }
        let mut names: Vec<&str> = out.iter().map(|s| s.name.as_str()).collect();
        names.sort_unstable();
        if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
            bail!(
                "two scenes are named \"{}\": give them distinct names",
                w[0]
            );
        }
        Ok(out)
    }
}

/// Default scene name: the XML's parent directory if the file is `scene.xml`, else its stem.
fn scene_name(xml: &Path) -> String {
    let stem = xml
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    if stem == "scene" {
        if let Some(parent) = xml.parent().and_then(|p| p.file_name()) {
            return parent.to_string_lossy().into_owned();
        }
    }
    stem
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_keys_are_rejected_and_defaults_apply() {
        let base =
            "model = \"m\"\noutput = \"o\"\nphotons_per_pass = 10\npasses = [4, 2, 4]\nseed = 1\n\
                    [[scenes]]\nxml = \"a/b/scene.xml\"\nreference = \"r.exr\"\n";
        let c: EvalConfig = toml::from_str(base).unwrap();
        c.validate().unwrap();
        assert_eq!(c.tile, 128);
        assert_eq!(c.backend, "flex");
        assert_eq!(c.pass_counts(), vec![2, 4]);
        assert_eq!(scene_name(&c.scenes[0].xml), "b");
        assert_eq!(scene_name(Path::new("x/cbox.xml")), "cbox");
        let bad = format!("{base}colour = 3\n");
        assert!(toml::from_str::<EvalConfig>(&bad).is_err());
        // The radius schedule: SPPM's by default and then not written back; CPPM taken; any
        // other value refused naming it.
        assert_eq!(c.schedule, RadiusSchedule::Sppm);
        assert!(!serde_json::to_string(&c).unwrap().contains("schedule"));
        let top = |extra: &str| base.replacen("seed = 1\n", &format!("seed = 1\n{extra}"), 1);
        let cppm: EvalConfig = toml::from_str(&top("schedule = \"cppm\"\n")).unwrap();
        assert_eq!(cppm.schedule, RadiusSchedule::Cppm);
        let e = toml::from_str::<EvalConfig>(&top("schedule = \"ppm\"\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("ppm"), "{e}");
        // Light samples per visible point: absent means the renderer's defaults (ours two,
        // the standard run one) and is not written back; zero is refused.
        assert_eq!(
            (c.emitter_samples, c.standard_emitter_samples),
            (None, None)
        );
        assert!(!serde_json::to_string(&c)
            .unwrap()
            .contains("emitter_samples"));
        let both: EvalConfig =
            toml::from_str(&top("emitter_samples = 3\nstandard_emitter_samples = 2\n")).unwrap();
        both.validate().unwrap();
        assert_eq!(
            (both.emitter_samples, both.standard_emitter_samples),
            (Some(3), Some(2))
        );
        for zero in ["emitter_samples = 0\n", "standard_emitter_samples = 0\n"] {
            let z: EvalConfig = toml::from_str(&top(zero)).unwrap();
            let e = z.validate().unwrap_err().to_string();
            assert!(e.contains("emitter_samples"), "{e}");
        }
        // The photon focus: absent is the renderer's default; a share outside [0, 1) is refused.
        assert_eq!(c.sampler, None);
        let ld: EvalConfig = toml::from_str(&top("sampler = \"ldsampler\"\n")).unwrap();
        assert_eq!(
            ld.sampler,
            Some(renderer::integrators::sppm::EyeSampler::LowDiscrepancy)
        );
        let e = toml::from_str::<EvalConfig>(&top("sampler = \"sobol\"\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sampler") || e.contains("variant"), "{e}");
        assert_eq!(c.sharp_level, None);
        let a: EvalConfig = toml::from_str(&top("sharp_level = \"a\"\n")).unwrap();
        assert_eq!(
            a.sharp_level,
            Some(renderer::integrators::sppm::SharpLevel::SubpathA)
        );
        let e = toml::from_str::<EvalConfig>(&top("sharp_level = \"b\"\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sharp_level") || e.contains("variant"), "{e}");
        assert_eq!(c.photon_focus, None);
        let aimed: EvalConfig = toml::from_str(&top("photon_focus = 0.5\n")).unwrap();
        aimed.validate().unwrap();
        assert_eq!(aimed.photon_focus, Some(0.5));
        for bad in ["photon_focus = 1.0\n", "photon_focus = -0.1\n"] {
            let b: EvalConfig = toml::from_str(&top(bad)).unwrap();
            let e = b.validate().unwrap_err().to_string();
            assert!(e.contains("photon_focus"), "{e}");
        }
        assert_eq!(c.engine, None);
        let native: EvalConfig = toml::from_str(&format!("engine = \"native\"\n{base}")).unwrap();
        assert_eq!(native.engine, Some(infer::Engine::Native));
        let err = toml::from_str::<EvalConfig>(&format!("engine = \"gpu\"\n{base}"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("gpu") && err.contains("native"), "{err}");
        let zero = base.replace("[4, 2, 4]", "[0, 2]");
        let c: EvalConfig = toml::from_str(&zero).unwrap();
        assert!(c.validate().is_err());
        assert!(c.ablation.is_none());
        let with = format!("{base}[ablation]\ndual_models = [\"runs/d\"]\n");
        let c: EvalConfig = toml::from_str(&with).unwrap();
        c.validate().unwrap();
        assert_eq!(
            c.ablation.unwrap().dual_models,
            vec![PathBuf::from("runs/d")]
        );
        let empty = format!("{base}[ablation]\ndual_models = []\n");
        assert!(toml::from_str::<EvalConfig>(&empty)
            .unwrap()
            .validate()
            .is_err());
        let typo = format!("{base}[ablation]\ndual_model = \"runs/d\"\n");
        assert!(toml::from_str::<EvalConfig>(&typo).is_err());
        // A scene's recorded reference noise: taken, and refused unless a finite relMSE ≥ 0.
        let noisy = |v: &str| format!("{base}reference_noise = {v}\n");
        let c: EvalConfig = toml::from_str(&noisy("2.5e-4")).unwrap();
        c.validate().unwrap();
        assert_eq!(c.scenes[0].reference_noise, Some(2.5e-4));
        for bad in ["-1.0", "nan", "inf"] {
            let e = toml::from_str::<EvalConfig>(&noisy(bad))
                .unwrap()
                .validate()
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("a/b/scene.xml") && e.contains("reference_noise"),
                "{e}"
            );
        }
    }

    #[test]
    fn every_shipped_config_loads() {
        let dir = PathBuf::from(
            std::env::var_os("CARGO_MANIFEST_DIR")
                .unwrap_or_else(|| env!("CARGO_MANIFEST_DIR").into()),
        )
        .join("../configs/eval");
        let mut count = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                EvalConfig::load(&path).unwrap_or_else(|e| panic!("{e:#}"));
                count += 1;
            }
        }
        assert!(
            count >= 4,
            "found only {count} configs in {}",
            dir.display()
        );
    }

    #[test]
    fn dataset_split_resolves_with_manifest_or_replacement_references() {
        let dir = std::env::temp_dir().join(format!("eval-config-refs-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for p in ["scenes/a", "scenes/b", "references", "avg"] {
            std::fs::create_dir_all(dir.join(p)).unwrap();
        }
        for f in [
            "scenes/a/scene.xml",
            "scenes/b/scene.xml",
            "references/a.exr",
            "references/b.exr",
            "avg/b.exr",
        ] {
            std::fs::write(dir.join(f), "x").unwrap();
        }
        let scene = |id: &str, split: &str| {
            serde_json::json!({
                "id": id, "family": "room", "split": split, "xml": format!("scenes/{id}/scene.xml"),
                "reference": format!("references/{id}.exr"), "reference_sha256": "",
                "reference_seed": 1, "reference_passes": 64, "reference_photons": 1000
            })
        };
        let manifest = serde_json::json!({
            "format": bundle::manifest::MANIFEST_FORMAT, "name": "t", "config_sha256": "",
            "width": 16, "height": 16, "reference_level": "y",
            "scenes": [scene("a", "train"), scene("b", "test")], "samples": [], "config": {}
        });
        std::fs::write(dir.join("manifest.json"), manifest.to_string()).unwrap();
        let config = |extra: &str| -> EvalConfig {
            toml::from_str(&format!(
                "model = \"m\"\noutput = \"o\"\nphotons_per_pass = 10\npasses = [2]\nseed = 1\n\
                 [dataset]\ndir = \"{}\"\n{extra}",
                dir.display()
            ))
            .unwrap()
        };
        let from_manifest = config("").resolve_scenes().unwrap();
        assert_eq!(from_manifest.len(), 1, "only the test split");
        assert_eq!(from_manifest[0].name, "b");
        assert_eq!(from_manifest[0].reference, dir.join("references/b.exr"));
        let replaced = config("references = \"avg\"\n").resolve_scenes().unwrap();
        assert_eq!(replaced[0].reference, dir.join("avg").join("b.exr"));
        // A replacement directory without the scene's file is an error naming it.
        let err = config("split = \"train\"\nreferences = \"avg\"\n")
            .resolve_scenes()
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("a.exr") && err.contains("does not exist"),
            "{err}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn converged_evaluation_references_are_used_and_a_partial_split_is_refused() {
        let dir = std::env::temp_dir().join(format!("eval-config-conv-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for p in [
            "scenes/a",
            "scenes/b",
            "references",
            "evaluation-references",
        ] {
            std::fs::create_dir_all(dir.join(p)).unwrap();
        }
        for f in [
            "scenes/a/scene.xml",
            "scenes/b/scene.xml",
            "references/a.exr",
            "references/b.exr",
            "evaluation-references/b.exr",
        ] {
            std::fs::write(dir.join(f), "x").unwrap();
        }
        let scene = |id: &str, converged: bool| {
            let mut s = serde_json::json!({
                "id": id, "family": "room", "split": "test",
                "xml": format!("scenes/{id}/scene.xml"),
                "reference": format!("references/{id}.exr"), "reference_sha256": "",
                "reference_seed": 1, "reference_passes": 64, "reference_photons": 1000
            });
            if converged {
                s["evaluation_reference"] = serde_json::json!({
                    "path": format!("evaluation-references/{id}.exr"), "sha256": "",
                    "passes": 1024, "photons": 1000, "seeds": [1, 2], "noise": 1e-4,
                    "input_relmse": 1e-2, "target": 0.1, "converged": true, "seconds": 1.0
                });
            }
            s
        };
        let write = |scenes: serde_json::Value| {
            let manifest = serde_json::json!({
                "format": bundle::manifest::MANIFEST_FORMAT, "name": "t", "config_sha256": "",
                "width": 16, "height": 16, "reference_level": "y",
                "scenes": scenes, "samples": [], "config": {}
            });
            std::fs::write(dir.join("manifest.json"), manifest.to_string()).unwrap();
        };
        let config = |extra: &str| -> EvalConfig {
            toml::from_str(&format!(
                "model = \"m\"\noutput = \"o\"\nphotons_per_pass = 10\npasses = [2]\nseed = 1\n\
                 [dataset]\ndir = \"{}\"\n{extra}",
                dir.display()
            ))
            .unwrap()
        };
        write(serde_json::json!([scene("b", true)]));
        let scenes = config("").resolve_scenes().unwrap();
        assert_eq!(scenes[0].reference, dir.join("evaluation-references/b.exr"));
        // Its recorded noise goes with it, to be weighed against the errors measured.
        assert_eq!(scenes[0].reference_noise, Some(1e-4));
        // A family filter keeps its families; a family the split lacks is named.
        assert_eq!(
            config("families = [\"room\"]\n")
                .resolve_scenes()
                .unwrap()
                .len(),
            1
        );
        let err = config("families = [\"room\", \"lamp\"]\n")
            .resolve_scenes()
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("no family lamp") && err.contains("its families: room"),
            "{err}"
        );
        // The training references on request (their noise is not recorded here).
        let scenes = config("references = \"references\"\n")
            .resolve_scenes()
            .unwrap();
        assert_eq!(scenes[0].reference, dir.join("references").join("b.exr"));
        assert_eq!(scenes[0].reference_noise, None);
        // One scene with, one without: refused, naming the one without.
        write(serde_json::json!([scene("a", false), scene("b", true)]));
        let err = config("").resolve_scenes().unwrap_err().to_string();
        assert!(
            err.contains("1 of 2") && err.contains("(a)") && err.contains("evaluation-references"),
            "{err}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
