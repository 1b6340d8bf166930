//! Writing the dataset manifest (`manifest.json`; its types are `bundle::manifest`'s, shared
//! with the readers) and the per-job completion records (`records/<scene>/<job>.json`) it is
//! assembled from. A record is written last, after all of its job's outputs, so its presence
//! means the job finished; the manifest is the sorted union of all records (with each scene's
//! evaluation record, where `datagen evaluation-references` wrote one) and is identical however
//! the jobs were sharded. A partial manifest (`datagen manifest --partial`) is the same union over
//! the scenes whose every job is done.

use crate::config::Config;
use crate::fsutil::{sha256_bytes, sha256_file, write_if_changed};
use crate::plan::{Job, Plan};
pub use bundle::manifest::{
    PartialDataset, SampleEntry, SceneEntry, MANIFEST_FILE, MANIFEST_FORMAT,
};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The manifest written for a dataset of this config.
pub type Manifest = bundle::manifest::Manifest<Config>;

/// What a finished job produced (`records/<scene>/<job>.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JobRecord {
    /// [`MANIFEST_FORMAT`].
    pub format: String,
    /// Fingerprint of the configuration the job ran under.
    pub config_sha256: String,
    /// The scene entry (reference jobs).
    pub scene: Option<SceneEntry>,
    /// The sample entries (input jobs), ascending passes.
    pub samples: Vec<SampleEntry>,
    /// Fingerprint of the scene the job rendered, for scenes the user brings (as
    /// [`SceneEntry::scene_sha256`]): the job is redone when the scene file or a file it reads
    /// changes.
    #[serde(
        default,
        alias = "scene_xml_sha256",
        skip_serializing_if = "Option::is_none"
    )]
    pub scene_sha256: Option<String>,
}

impl JobRecord {
    /// (relative path, sha256) of every output file of the job.
    pub fn outputs(&self) -> Vec<(&str, &str)> {
        let mut out: Vec<(&str, &str)> = self
            .samples
            .iter()
            .map(|s| (s.bundle.as_str(), s.sha256.as_str()))
            .collect();
        if let Some(s) = &self.scene {
            out.push((s.reference.as_str(), s.reference_sha256.as_str()));
        }
        out
    }
}

/// Fingerprint of a configuration: SHA-256 of its canonical JSON.
pub fn config_fingerprint(config: &Config) -> String {
    // Serialising plain structs cannot fail.
    sha256_bytes(serde_json::to_string(config).unwrap_or_default().as_bytes())
}

/// Reads a job record if it exists, parses and belongs to `fingerprint`.
pub fn read_record(root: &Path, plan: &Plan, job: &Job, fingerprint: &str) -> Option<JobRecord> {
    let text = std::fs::read_to_string(root.join(plan.record_path(job))).ok()?;
    let record: JobRecord = serde_json::from_str(&text).ok()?;
    (record.format == MANIFEST_FORMAT && record.config_sha256 == fingerprint).then_some(record)
}

/// Jobs of `plan` whose record in `root` was written under a config other than `fingerprint`
/// (rendering them again replaces their files): a sign that the directory holds another
/// config's dataset.
pub fn jobs_of_other_config(root: &Path, plan: &Plan, jobs: &[usize], fingerprint: &str) -> usize {
    jobs.iter()
        .filter(|&&j| {
            std::fs::read_to_string(root.join(plan.record_path(&plan.jobs[j])))
                .ok()
                .and_then(|text| serde_json::from_str::<JobRecord>(&text).ok())
                .is_some_and(|r| r.config_sha256 != fingerprint)
        })
        .count()
}

/// True when every output of the record exists with the recorded checksum.
pub fn outputs_intact(root: &Path, record: &JobRecord) -> bool {
    record
        .outputs()
        .iter()
        .all(|(path, sha)| sha256_file(&root.join(path)).is_ok_and(|s| s == *sha))
}

/// Pretty JSON with a trailing newline.
pub fn to_json<T: Serialize>(value: &T) -> Vec<u8> {
    let mut text = serde_json::to_string_pretty(value).unwrap_or_default();
    text.push('\n');
    text.into_bytes()
}

/// Assembles `manifest.json` from the records if every job of the plan has a record of this
/// config; writes it atomically (only when its bytes change) and returns it. Returns `None`
/// (writing nothing) while jobs are missing. Concurrent callers write identical bytes.
///
/// With `partial`, a dataset still rendering gets a manifest of the scenes whose every job is
/// done, marked [`PartialDataset`] (complete scenes only: a scene's inputs are never listed
/// without their reference); `None` while no scene is done. A finished dataset's manifest is
/// the complete one either way.
pub fn assemble_manifest(
    root: &Path,
    config: &Config,
    plan: &Plan,
    partial: bool,
) -> anyhow::Result<Option<Manifest>> {
    let fingerprint = config_fingerprint(config);
    let mut scenes = Vec::new();
    let mut samples = Vec::new();
    let mut missing = vec![false; plan.scenes.len()];
    let mut records = Vec::new();
    for job in &plan.jobs {
        match read_record(root, plan, job, &fingerprint) {
            Some(record) => records.push((job.scene(), record)),
            None if partial => missing[job.scene()] = true,
            None => return Ok(None),
        }
    }
    for (scene, record) in records {
        if !missing[scene] {
            scenes.extend(record.scene);
            samples.extend(record.samples);
        }
    }
    if scenes.is_empty() {
        return Ok(None);
    }
    let partial = missing.iter().any(|&m| m).then_some(PartialDataset {
        planned_scenes: plan.scenes.len(),
    });
    // Converged evaluation references are made later, by their own command, with records of
    // their own (`datagen evaluation-references`).
    for scene in &mut scenes {
        scene.evaluation_reference =
            crate::evaluation_reference::read_record(root, &scene.id, &fingerprint);
    }
    scenes.sort_by(|a, b| a.id.cmp(&b.id));
    samples.sort_by(|a, b| {
        (&a.scene, a.seed_index, a.passes).cmp(&(&b.scene, b.seed_index, b.passes))
    });
    let manifest = Manifest {
        format: MANIFEST_FORMAT.into(),
        name: config.name.clone(),
        config_sha256: fingerprint,
        width: config.width,
        height: config.height,
        reference_level: "y".into(),
        scenes,
        samples,
        config: config.clone(),
        partial,
    };
    let path = root.join(MANIFEST_FILE);
    write_if_changed(&path, &to_json(&manifest))
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(Some(manifest))
}
