//! The dataset manifest (`manifest.json`), the contract between dataset generation (`datagen`
//! writes it) and its readers (`train`, `evaluate`, `datagen check`): one set of types for both
//! sides, read strictly (unknown keys are errors), so a field the writer adds or renames cannot
//! be silently ignored by a reader. Paths in it are relative to the dataset folder.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// Format identifier of `manifest.json` (and of `datagen`'s job records).
pub const MANIFEST_FORMAT: &str = "sppm-ml-dataset/1";

/// File name of the manifest in the dataset folder.
pub const MANIFEST_FILE: &str = "manifest.json";

/// A manifest that cannot be read.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {reason}")]
pub struct ManifestError {
    /// The manifest file.
    pub path: PathBuf,
    /// What is wrong.
    pub reason: String,
}

/// Which part of the dataset a scene belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// Training scenes.
    Train,
    /// Validation scenes (model selection).
    Val,
    /// Held-out test scenes.
    Test,
}

impl Split {
    /// The name used in configs, manifests and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }
}

impl std::str::FromStr for Split {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        [Split::Train, Split::Val, Split::Test]
            .into_iter()
            .find(|s| s.name() == text)
            .ok_or_else(|| format!("unknown split `{text}` (train, val or test)"))
    }
}

/// One input bundle of the dataset.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleEntry {
    /// Bundle EXR path relative to the dataset root.
    pub bundle: String,
    /// Scene id.
    pub scene: String,
    /// Scene family (its name, e.g. `glass`).
    pub family: String,
    /// Split of the scene.
    pub split: Split,
    /// Render seed of the input run (< 2³²).
    pub seed: u64,
    /// Seed number 0..seeds within the scene.
    pub seed_index: u32,
    /// SPPM passes accumulated in this bundle.
    pub passes: u32,
    /// Photons per pass.
    pub photons: u64,
    /// Reference EXR path relative to the dataset root.
    pub reference: String,
    /// Lower-case hex SHA-256 of the bundle file.
    pub sha256: String,
}

/// One scene of the dataset with its reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneEntry {
    /// Scene id.
    pub id: String,
    /// Family (its name, e.g. `glass`).
    pub family: String,
    /// Split.
    pub split: Split,
    /// Scene XML path relative to the dataset root.
    pub xml: String,
    /// Reference EXR path relative to the dataset root.
    pub reference: String,
    /// Lower-case hex SHA-256 of the reference file.
    pub reference_sha256: String,
    /// Render seed of the reference run.
    pub reference_seed: u64,
    /// Passes of the reference run.
    pub reference_passes: u32,
    /// Photons per pass of the reference run.
    pub reference_photons: u64,
    /// Fingerprint of the scene as rendered, for scenes the user brings (`external`; generated
    /// scenes are a function of the config): lower-case hex SHA-256 over its `defines` and the
    /// contents of the scene file and every file it reads (`renderer::state_file::scene_fingerprint`).
    /// Datasets of the twelfth session wrote the scene file's hash alone, as `xml_sha256`.
    #[serde(default, alias = "xml_sha256", skip_serializing_if = "Option::is_none")]
    pub scene_sha256: Option<String>,
    /// `<default>` overrides the scene is rendered with (scenes the user brings).
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub defines: std::collections::BTreeMap<String, String>,
    /// The input regime the scene was rendered in (datasets with `[[render.regimes]]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub regime: Option<String>,
    /// Image size `[width, height]` of the scene's reference and bundles, where it is not the
    /// manifest's (a regime with its own side).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size: Option<[u32; 2]>,
    /// Independent runs averaged into the reference (absent: 1), each of `reference_passes` ×
    /// `reference_photons`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_runs: Option<u32>,
    /// The relMSE the reference carries from its own noise (docs/method.md §5.6 weights; from
    /// the spread of its runs; needs `reference_runs` ≥ 2): Σ s²/R / (ref² + 0.01) / (3·pixels).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_noise: Option<f64>,
    /// The converged reference that evaluation and validation measure against, where `datagen
    /// evaluation-references` made one (the training `reference` above stays the target).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evaluation_reference: Option<EvaluationReference>,
}

/// A reference converged well beyond the scene's inputs (`datagen evaluation-references`): the
/// mean of independent SPPM runs with many more passes than the inputs, grown until its own
/// noise is a small fraction of the best input's error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvaluationReference {
    /// EXR path relative to the dataset root.
    pub path: String,
    /// Lower-case hex SHA-256 of the file.
    pub sha256: String,
    /// Passes of each run.
    pub passes: u32,
    /// Photons per pass of each run.
    pub photons: u64,
    /// Render seeds of the runs averaged.
    pub seeds: Vec<u64>,
    /// The relMSE the mean carries from its own noise (docs/method.md §5.6 weights; from the
    /// spread of the runs): Σ s²/R / (ref² + 0.01) / (3·pixels).
    pub noise: f64,
    /// The best input level's relMSE at the scene's largest pass count against this reference
    /// (mean over input seeds), less `noise`: the error the reference is there to measure.
    pub input_relmse: f64,
    /// The noise limit it was rendered for, as a fraction of `input_relmse`.
    pub target: f64,
    /// `noise ≤ target · input_relmse`; false: the pass limit was reached first (flagged).
    pub converged: bool,
    /// Seconds of rendering spent on the runs (all passes, all runs).
    pub seconds: f64,
}

impl SceneEntry {
    /// The scene's image size: its own, or the manifest's (`width`, `height`).
    pub fn size_in<C>(&self, manifest: &Manifest<C>) -> (u32, u32) {
        self.size
            .map_or((manifest.width, manifest.height), |[w, h]| (w, h))
    }
}

/// The whole dataset description (`manifest.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest<C = serde_json::Value> {
    /// [`MANIFEST_FORMAT`].
    pub format: String,
    /// Config preset name.
    pub name: String,
    /// Fingerprint of the configuration.
    pub config_sha256: String,
    /// Image width of every bundle and reference.
    pub width: u32,
    /// Image height of every bundle and reference.
    pub height: u32,
    /// Which level of the reference run the reference image is (`y`).
    pub reference_level: String,
    /// Scenes in id order.
    pub scenes: Vec<SceneEntry>,
    /// Samples ordered by (scene, seed_index, passes).
    pub samples: Vec<SampleEntry>,
    /// The configuration the dataset was made with (`datagen`'s config; readers that do not
    /// need it take it as plain JSON).
    pub config: C,
    /// Present on the manifest of a dataset whose render has not finished (`datagen manifest
    /// --partial`): it lists only the scenes whose every job is done. Absent when complete.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub partial: Option<PartialDataset>,
}

/// How much of a dataset a partial manifest lists.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartialDataset {
    /// Scenes of the config's plan (the manifest lists fewer).
    pub planned_scenes: usize,
}

impl<C> Manifest<C> {
    /// A line for users of a partial dataset (`None` when complete): how many of the planned
    /// scenes it lists, so that nobody trains or reports on a part believing it the whole.
    pub fn partial_note(&self, root: &Path) -> Option<String> {
        self.partial.map(|p| {
            format!(
                "{}: a partial dataset, {} of {} scenes (its render has not finished; \
                 `datagen manifest --partial` lists the finished scenes)",
                root.join(MANIFEST_FILE).display(),
                self.scenes.len(),
                p.planned_scenes
            )
        })
    }
}

impl<C: DeserializeOwned> Manifest<C> {
    /// Reads `root/manifest.json`; every error names the file.
    pub fn load(root: &Path) -> Result<Self, ManifestError> {
        let path = root.join(MANIFEST_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| ManifestError {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        serde_json::from_str(&text).map_err(|e| ManifestError {
            path,
            reason: e.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_partial_manifest_says_how_much_it_lists_and_a_complete_one_nothing() {
        let mut manifest: Manifest = serde_json::from_value(serde_json::json!({
            "format": MANIFEST_FORMAT, "name": "t", "config_sha256": "", "width": 8,
            "height": 8, "reference_level": "y", "scenes": [], "samples": [], "config": {}
        }))
        .unwrap();
        assert_eq!(manifest.partial_note(Path::new("d")), None);
        manifest.partial = Some(PartialDataset { planned_scenes: 5 });
        let note = manifest.partial_note(Path::new("d")).unwrap();
        assert!(
            note.starts_with(&format!(
                "{}: a partial dataset, 0 of 5 scenes",
                Path::new("d").join(MANIFEST_FILE).display()
            )),
            "{note}"
        );
        assert!(!note.contains("  "), "{note}");
        // It round-trips; a complete manifest writes no `partial` key at all.
        let json = serde_json::to_value(&manifest).unwrap();
        assert_eq!(json["partial"]["planned_scenes"], 5);
        manifest.partial = None;
        assert!(serde_json::to_value(&manifest)
            .unwrap()
            .get("partial")
            .is_none());
    }
}
