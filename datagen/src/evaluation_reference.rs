//! Converged evaluation references (`datagen evaluation-references`): for each scene of the
//! evaluation splits, two independent SPPM runs with many more passes than its inputs, continued
//! until the noise of their mean is at most a fraction (`target`, 1/10 by default) of the best
//! input level's error, or a pass or time limit flags the scene.
//!
//! Why more passes and not more photons: a reference with the inputs' pass count keeps the
//! inputs' eye-path noise (glossy lobes, depth of field, anti-aliasing) however many photons
//! it traces — measured on the `large` dataset, 32× the photons left it 0.15–3.6× the best
//! input's error (docs/datagen.md). Each pass adds eye samples and shrinks SPPM's radius, so
//! both the noise and the bias fall. The noise is measured from the spread of the two runs
//! (their difference is noise only); the bias is not measured, it is the estimator's (SPEC §4)
//! at far more passes than any input.
//!
//! Photons per pass: at least `min_photons` (the scene's reference photons when more). The runs'
//! bias is SPPM's kernel bias, which falls with the photons per pass; a dataset's sparse regimes
//! have references of a few thousand photons per pass, and a reference that keeps them is as
//! blurred as the evaluation's 100 000-photon inputs on caustics (measured on seven frozen
//! held-out scenes, docs/journal/2026-12-06-photon-focus.md §4), which the noise measurement
//! cannot see (both runs share the bias).
//!
//! Every step resumes: each run keeps its SPPM state (`evaluation-references/runs/`), so a
//! killed call, or a later call with a stricter target or a higher limit, continues the runs
//! from where they stopped instead of starting again. A finished scene writes its mean
//! (`evaluation-references/<id>.exr`) and then its record (`records/<id>/evaluation.json`);
//! the manifest is re-assembled from the records and lists it as the scene's
//! `evaluation_reference`, which `evaluate`, validation and `train --evaluate` measure against.

use crate::average::{extra_reference_run, mean_and_noise, run_seed};
use crate::fsutil::{create_parent, sha256_file, write_atomic};
use crate::jobs::{SampleRenderer, StateSpec};
use crate::manifest::{to_json, Manifest, SceneEntry, MANIFEST_FORMAT};
use crate::plan::Split;
use anyhow::{bail, Context, Result};
use bundle::manifest::EvaluationReference;
use bundle::{read_bundle, read_rgb_exr_image, write_rgb_exr_image, Image};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Folder (in the dataset) of the evaluation references and, below it, their runs' states.
pub const DIR: &str = "evaluation-references";

/// The default noise limit: a tenth of the error the reference measures.
pub const DEFAULT_TARGET: f64 = 0.1;

/// The default floor on the runs' photons per pass: four times the 100 000 photons per pass the
/// project's evaluations render, so the reference's kernel bias stays below theirs.
pub const DEFAULT_MIN_PHOTONS: u64 = 400_000;

/// Runs averaged: two give the noise estimate (their spread) at the least cost per pass.
const RUNS: usize = 2;

/// Run indices of the evaluation runs in [`run_seed`]'s sequence: far past any
/// `render.reference_runs`, so their seeds never repeat a training reference's run.
const FIRST_RUN: usize = 1000;

/// Safety factor on the predicted pass count: the noise of SPPM falls between 1/passes (eye
/// paths) and passes^(-2/3) (photons, as the radius shrinks), the prediction assumes the former.
const MARGIN: f64 = 1.25;

/// Most growth of the runs' passes in one round (the first round: over the reference's passes).
/// The time limit is checked between rounds, at the rate the last round measured; a prediction
/// from a noisy first measurement could otherwise start one round that runs far past it
/// (measured: a dense `lamp` scene's first round asked 14× the reference's passes, ≈ 35 min).
/// Rounds continue the runs, so smaller steps cost only the noise measurement between them.
const MAX_GROWTH: u64 = 4;

/// Where the evaluation record of scene `id` lives, relative to the dataset root.
pub fn record_path(id: &str) -> String {
    format!("records/{id}/evaluation.json")
}

/// Where the evaluation reference of scene `id` lives, relative to the dataset root.
pub fn image_path(id: &str) -> String {
    format!("{DIR}/{id}.exr")
}

/// What `records/<id>/evaluation.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvaluationRecord {
    /// [`MANIFEST_FORMAT`].
    pub format: String,
    /// Fingerprint of the dataset's configuration.
    pub config_sha256: String,
    /// Scene id.
    pub scene: String,
    /// The reference.
    pub evaluation_reference: EvaluationReference,
}

/// The evaluation reference of scene `id` if its record exists, parses and belongs to the
/// configuration `fingerprint` (the manifest lists only those).
pub fn read_record(root: &Path, id: &str, fingerprint: &str) -> Option<EvaluationReference> {
    let text = std::fs::read_to_string(root.join(record_path(id))).ok()?;
    let record: EvaluationRecord = serde_json::from_str(&text).ok()?;
    (record.format == MANIFEST_FORMAT && record.config_sha256 == fingerprint && record.scene == id)
        .then_some(record.evaluation_reference)
}

/// What to render.
#[derive(Debug, Clone, PartialEq)]
pub struct EvaluationOptions {
    /// Scenes of these splits.
    pub splits: Vec<Split>,
    /// Only these scene ids (all of the splits when empty).
    pub scenes: Vec<String>,
    /// Noise limit as a fraction of the best input's error.
    pub target: f64,
    /// Most passes per run, as a multiple of the scene's reference passes.
    pub max_factor: u32,
    /// Photons per pass of the runs at least this many (the scene's reference photons when
    /// more; an earlier call's runs with more are continued with theirs).
    pub min_photons: u64,
    /// Most seconds of rendering per scene (both runs); `None`: no limit.
    pub max_seconds: Option<f64>,
    /// Worker threads per render (0 = all cores; results do not depend on it).
    pub threads: usize,
    /// Seconds of rendering between saves of a run's state.
    pub state_interval: f64,
}

/// One scene's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneOutcome {
    /// Scene id.
    pub id: String,
    /// Its reference as recorded.
    pub reference: EvaluationReference,
    /// False when an earlier call's record already met this call's target and limits.
    pub rendered: bool,
}

/// The levels of one input bundle, with the bundle's path (for errors).
pub type InputLevels = (PathBuf, Vec<Image>);

/// The scene's largest input pass count and its bundles' levels there (one per input seed);
/// `None` when the scene has no inputs.
pub fn largest_pass_inputs(
    root: &Path,
    manifest: &Manifest,
    scene: &SceneEntry,
) -> Result<Option<(u32, Vec<InputLevels>)>> {
    let samples: Vec<_> = manifest
        .samples
        .iter()
        .filter(|e| e.scene == scene.id)
        .collect();
    let Some(passes) = samples.iter().map(|e| e.passes).max() else {
        return Ok(None);
    };
    let mut inputs = Vec::new();
    for e in samples.iter().filter(|e| e.passes == passes) {
        let path = root.join(&e.bundle);
        let bundle = read_bundle(&path)?;
        inputs.push((path, bundle.levels));
    }
    Ok(Some((passes, inputs)))
}

/// The best input level's relMSE against `reference`: the mean over the input seeds of the
/// smallest relMSE over the levels. Errors name the file whose size differs.
pub fn best_level_relmse(
    inputs: &[InputLevels],
    scene: &SceneEntry,
    reference: &Image,
) -> Result<f64> {
    let mut sum = 0.0;
    for (path, levels) in inputs {
        let mut level_best = f64::INFINITY;
        for level in levels {
            if (level.width, level.height) != (reference.width, reference.height) {
                bail!(
                    "{}: {}x{}, the reference of scene {} is {}x{}",
                    path.display(),
                    level.width,
                    level.height,
                    scene.id,
                    reference.width,
                    reference.height
                );
            }
            level_best = level_best.min(level.relmse(reference));
        }
        sum += level_best;
    }
    Ok(sum / inputs.len() as f64)
}

/// The scene's largest input pass count and the best input level's relMSE there against
/// `reference` ([`largest_pass_inputs`], [`best_level_relmse`]); `None` when the scene has no
/// inputs.
pub fn best_input_relmse(
    root: &Path,
    manifest: &Manifest,
    scene: &SceneEntry,
    reference: &Image,
) -> Result<Option<(u32, f64)>> {
    match largest_pass_inputs(root, manifest, scene)? {
        Some((passes, inputs)) => Ok(Some((
            passes,
            best_level_relmse(&inputs, scene, reference)?,
        ))),
        None => Ok(None),
    }
}

/// The pass count whose noise is predicted to meet `target`, from a measurement of `noise`
/// against an input error `input` at `passes` (noise ∝ 1/passes, with [`MARGIN`]); at least
/// 1.5× `passes` so that each round makes progress, rounded up to a multiple of 16.
pub fn predicted_passes(passes: u32, noise: f64, input: f64, target: f64) -> u64 {
    let factor = if input > 0.0 {
        (noise / (target * input) * MARGIN).max(1.5)
    } else {
        // All the measured error is the reference's own noise: grow fast.
        4.0
    };
    let wanted = (f64::from(passes) * factor).ceil().min(1e9) as u64;
    wanted.div_ceil(16) * 16
}

/// The state file of run `seed` of scene `id`.
/// The state of run `seed` of scene `id` at `photons` per pass: runs at the scene's reference
/// photons keep the name they have always had, others carry the count, so runs of two photon
/// counts never continue each other.
fn state_path(root: &Path, scene: &SceneEntry, seed: u64, photons: u64) -> PathBuf {
    let id = &scene.id;
    let name = if photons == scene.reference_photons {
        format!("{id}.s{seed}.state")
    } else {
        format!("{id}.s{seed}.n{photons}.state")
    };
    root.join(DIR).join("runs").join(name)
}

/// The round a scene's runs are in (`evaluation-references/runs/<id>.json`), written before
/// the round starts: a killed call resumes the same round, whose target the run states have
/// not passed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Progress {
    /// Passes the runs are being rendered to.
    passes: u64,
    /// Seconds of rendering spent on the scene before this round.
    seconds: f64,
    /// Photons per pass of the round's runs; absent in files written before the floor existed,
    /// whose runs had the scene's reference photons.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    photons: Option<u64>,
}

/// Where scene `id`'s [`Progress`] lives.
fn progress_path(root: &Path, id: &str) -> PathBuf {
    root.join(DIR).join("runs").join(format!("{id}.json"))
}

/// Renders (or continues) the evaluation references of the dataset at `root` for the scenes
/// `options` selects; returns each scene's outcome in manifest order. `on_scene` reports each
/// finished scene; `on_pass(scene id, run, pass, target pass)` the progress of a run.
pub fn evaluation_references(
    root: &Path,
    manifest: &Manifest,
    renderer: &dyn SampleRenderer,
    options: &EvaluationOptions,
    mut on_scene: impl FnMut(&SceneOutcome),
    on_pass: &mut (dyn FnMut(&str, usize, u32, u32) + Send),
) -> Result<Vec<SceneOutcome>> {
    if !(options.target > 0.0 && options.target.is_finite()) {
        bail!("--target must be a positive fraction, e.g. 0.1");
    }
    if options.max_factor < 2 {
        bail!("--max-factor must be at least 2 (the runs need more passes than the inputs)");
    }
    if options.max_seconds.is_some_and(|s| s.is_nan() || s <= 0.0) {
        bail!("--max-seconds must be positive");
    }
    let manifest_path = root.join(crate::manifest::MANIFEST_FILE);
    for id in &options.scenes {
        if !manifest.scenes.iter().any(|s| &s.id == id) {
            bail!("{}: no scene `{id}`", manifest_path.display());
        }
    }
    let scenes: Vec<&SceneEntry> = manifest
        .scenes
        .iter()
        .filter(|s| options.splits.contains(&s.split))
        .filter(|s| options.scenes.is_empty() || options.scenes.contains(&s.id))
        .collect();
    if scenes.is_empty() {
        bail!(
            "{}: no scene of the splits {:?}{}",
            manifest_path.display(),
            options.splits,
            if options.scenes.is_empty() {
                ""
            } else {
                " among the scenes named"
            }
        );
    }
    let fingerprint = &manifest.config_sha256;
    let mut outcomes = Vec::new();
    for scene in scenes {
        let max_passes = (u64::from(scene.reference_passes) * u64::from(options.max_factor))
            .min(u64::from(u32::MAX));
        // An earlier call's record; kept only with its image intact, but its runs' states are at
        // its passes either way, so a redo never asks them for fewer.
        let recorded = read_record(root, &scene.id, fingerprint);
        // The runs' photons per pass: the floor, or an earlier call's runs where they have at
        // least as many (they are continued); runs below the floor are started again.
        let floor = scene.reference_photons.max(options.min_photons);
        let recorded = recorded.filter(|r| r.photons >= floor);
        let photons = recorded.as_ref().map_or(floor, |r| r.photons);
        let earlier = recorded
            .clone()
            .filter(|r| sha256_file(&root.join(&r.path)).is_ok_and(|sha| sha == r.sha256));
        if let Some(r) = &earlier {
            let meets = r.noise <= options.target * r.input_relmse;
            let at_limit = u64::from(r.passes) >= max_passes
                || options.max_seconds.is_some_and(|s| r.seconds >= s);
            if meets || (!r.converged && at_limit) {
                let outcome = SceneOutcome {
                    id: scene.id.clone(),
                    reference: r.clone(),
                    rendered: false,
                };
                on_scene(&outcome);
                outcomes.push(outcome);
                continue;
            }
        }
        // The inputs are read once per scene; every round measures against its new mean.
        let Some((_, inputs)) = largest_pass_inputs(root, manifest, scene)? else {
            bail!(
                "{}: scene {} has no input bundles to measure against",
                manifest_path.display(),
                scene.id
            );
        };
        let (width, height) = scene.size_in(manifest);
        let xml = root.join(&scene.xml);
        let seeds: Vec<u64> = (0..RUNS)
            .map(|r| run_seed(scene.reference_seed, FIRST_RUN + r))
            .collect();
        // Where to start: a round a killed call left, an earlier call's passes, else the
        // prediction from the training reference's measured noise (the mean of its runs, as
        // many passes as the inputs).
        let progress_file = progress_path(root, &scene.id);
        let progress: Option<Progress> = std::fs::read(&progress_file)
            .ok()
            .and_then(|b| serde_json::from_slice::<Progress>(&b).ok())
            .filter(|p| p.photons.unwrap_or(scene.reference_photons) == photons);
        let (mut passes, mut seconds): (u64, f64) = match (&progress, &recorded) {
            // The runs' states may be anywhere up to the round's target: never ask for less.
            (Some(p), _) => (p.passes, p.seconds),
            (None, Some(r)) => (u64::from(r.passes), r.seconds),
            (None, None) => {
                let start = match scene.reference_noise {
                    Some(noise) => {
                        let reference = read_rgb_exr_image(&root.join(&scene.reference))?;
                        let runs = f64::from(scene.reference_runs.unwrap_or(1));
                        let measured = best_level_relmse(&inputs, scene, &reference)?;
                        // The runs' mean here has RUNS runs, the training one `runs`.
                        predicted_passes(
                            scene.reference_passes,
                            noise * runs / RUNS as f64,
                            measured - noise,
                            options.target,
                        )
                    }
                    None => u64::from(scene.reference_passes) * 4,
                };
                let reference_passes = u64::from(scene.reference_passes);
                (
                    start
                        .clamp(2 * reference_passes, MAX_GROWTH * reference_passes)
                        .min(max_passes),
                    0.0,
                )
            }
        };
        let result = loop {
            create_parent(&progress_file)
                .with_context(|| format!("creating the folder of {}", progress_file.display()))?;
            let round_progress = Progress {
                passes,
                seconds,
                photons: Some(photons),
            };
            write_atomic(&progress_file, &to_json(&round_progress))
                .with_context(|| format!("writing {}", progress_file.display()))?;
            let round = Instant::now();
            let mut images = Vec::with_capacity(RUNS);
            // Passes rendered in this round, over its runs: a run continues from its state, whose
            // first reported pass is the one after the saved one (a resumed round's states may be
            // anywhere below its target), so the round's rate counts only what it rendered.
            let mut rendered: u64 = 0;
            for (run, &seed) in seeds.iter().enumerate() {
                // The state is kept after the run: a later round or call continues from it.
                let state = StateSpec {
                    path: state_path(root, scene, seed, photons),
                    interval: options.state_interval,
                };
                let spec = extra_reference_run(
                    manifest,
                    scene,
                    seed,
                    photons,
                    passes as u32,
                    state,
                    options.threads,
                );
                let id = scene.id.as_str();
                let target = passes as u32;
                let mut first: Option<u32> = None;
                let image = renderer.reference(&xml, &spec, &mut |p| {
                    first.get_or_insert(p);
                    on_pass(id, run, p, target)
                })?;
                rendered += first.map_or(0, |f| u64::from(target.saturating_sub(f) + 1));
                if (image.width, image.height) != (width as usize, height as usize) {
                    bail!(
                        "{}: rendered {}x{}, the dataset's scene is {width}x{height}",
                        xml.display(),
                        image.width,
                        image.height
                    );
                }
                images.push(image);
            }
            let round_seconds = round.elapsed().as_secs_f64();
            seconds += round_seconds;
            let (mean, one_run) = mean_and_noise(&images);
            let noise = one_run / RUNS as f64;
            let measured = best_level_relmse(&inputs, scene, &mean)?;
            let input = measured - noise;
            let converged = input > 0.0 && noise <= options.target * input;
            let next = predicted_passes(passes as u32, noise, input, options.target)
                .min(MAX_GROWTH * passes)
                .min(max_passes);
            // The time a round of `next` passes would take, from this round's rate (a round
            // continues the runs, so it renders only the new passes): seconds per pass of all
            // runs.
            let rate = round_seconds * RUNS as f64 / rendered.max(1) as f64;
            let out_of_time = options
                .max_seconds
                .is_some_and(|limit| seconds + rate * (next - passes) as f64 > limit);
            if converged || next <= passes || out_of_time {
                break (mean, noise, input, converged);
            }
            passes = next;
        };
        let (mean, noise, input, converged) = result;
        let rel = image_path(&scene.id);
        let path = root.join(&rel);
        create_parent(&path)
            .with_context(|| format!("creating the folder of {}", path.display()))?;
        write_rgb_exr_image(&path, &mean).with_context(|| format!("writing {}", path.display()))?;
        let reference = EvaluationReference {
            path: rel,
            sha256: sha256_file(&path)?,
            passes: passes as u32,
            photons,
            seeds: seeds.clone(),
            noise,
            input_relmse: input,
            target: options.target,
            converged,
            seconds,
        };
        let record = EvaluationRecord {
            format: MANIFEST_FORMAT.into(),
            config_sha256: fingerprint.clone(),
            scene: scene.id.clone(),
            evaluation_reference: reference.clone(),
        };
        let record_file = root.join(record_path(&scene.id));
        write_atomic(&record_file, &to_json(&record))
            .with_context(|| format!("writing {}", record_file.display()))?;
        // The record holds the passes now; the states stay for a later call to continue.
        crate::fsutil::remove_if_present(&progress_file)?;
        let outcome = SceneOutcome {
            id: scene.id.clone(),
            reference,
            rendered: true,
        };
        on_scene(&outcome);
        outcomes.push(outcome);
    }
    Ok(outcomes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prediction_scales_with_the_noise_ratio() {
        // Noise 4× the target at 100 passes: 4 × 1.25 = 5× the passes, rounded up to 16.
        assert_eq!(predicted_passes(100, 0.04, 0.1, 0.1), 512);
        // Already below the target: still at least 1.5× (callers stop before asking).
        assert_eq!(predicted_passes(64, 0.001, 0.1, 0.1), 96);
        // No input error left after the noise: a fixed growth.
        assert_eq!(predicted_passes(64, 0.01, -0.001, 0.1), 256);
    }

    #[test]
    fn paths_are_inside_the_dataset() {
        assert_eq!(record_path("007-room"), "records/007-room/evaluation.json");
        assert_eq!(image_path("007-room"), "evaluation-references/007-room.exr");
    }
}
