//! `evaluation_references` with a stand-in renderer whose reference runs are the truth plus
//! noise that falls as 1/√passes (so their relMSE noise falls as 1/passes, as an eye-path-bound
//! SPPM run's does) and whose inputs miss the truth by a fixed amount: the runs grow until the
//! noise of their mean is at most the target fraction of the input's error, the manifest lists
//! the result and `check` verifies it, a repeated call renders nothing, a stricter target
//! continues the runs from where they stopped, a pass limit flags the scene, a killed round
//! resumes at its own target, and a photon floor starts runs below it again with more photons.

mod common;

use anyhow::{bail, Result};
use bundle::{Bundle, Image};
use common::{fresh_dir, stand_in_bundle, test_config};
use datagen::evaluation_reference::{
    evaluation_references, image_path, record_path, EvaluationOptions,
};
use datagen::jobs::{render_dataset, RenderOptions, RunSpec, SampleRenderer};
use datagen::manifest::{assemble_manifest, Manifest};
use datagen::plan::{Plan, Shard, Split};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

const SIDE: usize = 8;
/// The inputs' (and training reference runs') pass count.
const REFERENCE_PASSES: u32 = 4;

/// The true image at (x, y, c).
fn truth(x: usize, y: usize, c: usize) -> f32 {
    0.5 + 0.1 * x as f32 + 0.05 * y as f32 + 0.2 * c as f32
}

/// A reference run of this seed at `passes`: the truth plus ±0.4/√passes, the sign a function
/// of seed, pixel and channel.
fn run_image(seed: u64, passes: u32) -> Image {
    let mut img = Image::new(SIDE, SIDE, 3);
    let amplitude = 0.4 / f64::from(passes).sqrt();
    for y in 0..SIDE {
        for x in 0..SIDE {
            for c in 0..3 {
                let sign = if (seed as usize + 3 * x + 5 * y + 7 * c).is_multiple_of(2) {
                    1.0
                } else {
                    -1.0
                };
                img.set(
                    x,
                    y,
                    c,
                    (f64::from(truth(x, y, c)) + sign * amplitude) as f32,
                );
            }
        }
    }
    img
}

/// An input level: the truth plus a constant error that grows with the level's salt.
fn input_image(channels: usize, salt: usize) -> Image {
    let mut img = Image::new(SIDE, SIDE, channels);
    for y in 0..SIDE {
        for x in 0..SIDE {
            for c in 0..channels {
                img.set(x, y, c, truth(x, y, c.min(2)) + 0.05 * salt as f32);
            }
        }
    }
    img
}

/// The stand-in renderer: records every reference run asked for (seed, passes, state path)
/// and its photons per pass; `fail_at` makes a run to that many passes fail (a kill).
#[derive(Default)]
struct StandIn {
    runs: Mutex<Vec<(u64, u32, Option<PathBuf>)>>,
    photons: Mutex<Vec<u64>>,
    fail_at: Option<u32>,
}

impl SampleRenderer for StandIn {
    fn reference(
        &self,
        _: &Path,
        spec: &RunSpec,
        on_pass: &mut (dyn FnMut(u32) + Send),
    ) -> Result<Image> {
        let passes = *spec.passes.last().unwrap();
        self.runs.lock().unwrap().push((
            spec.sppm.seed,
            passes,
            spec.state.as_ref().map(|s| s.path.clone()),
        ));
        self.photons
            .lock()
            .unwrap()
            .push(spec.sppm.photons_per_pass);
        // Like the renderer: a run resumes from its state and refuses to go backwards.
        if let Some(state) = &spec.state {
            if let Ok(text) = std::fs::read_to_string(&state.path) {
                let saved: u32 = text.trim().parse().unwrap();
                if saved > passes {
                    bail!("the saved run is at pass {saved}, past the last requested {passes}");
                }
            }
        }
        if self.fail_at == Some(passes) {
            bail!("killed");
        }
        if let Some(state) = &spec.state {
            std::fs::create_dir_all(state.path.parent().unwrap()).unwrap();
            std::fs::write(&state.path, passes.to_string()).unwrap();
        }
        on_pass(passes);
        Ok(run_image(spec.sppm.seed, passes))
    }

    fn inputs(
        &self,
        _: &Path,
        spec: &RunSpec,
        on_bundle: &mut (dyn FnMut(Bundle) -> Result<()> + Send),
        _: &mut (dyn FnMut(u32) + Send),
    ) -> Result<()> {
        for &p in &spec.passes {
            on_bundle(stand_in_bundle(spec, p, (SIDE, SIDE), false, input_image))?;
        }
        Ok(())
    }
}

fn dataset(name: &str) -> (PathBuf, Manifest) {
    let dir = fresh_dir(name);
    let config = test_config(SIDE as u32, &[2, REFERENCE_PASSES], 1, REFERENCE_PASSES);
    let options = RenderOptions {
        shard: Shard::ALL,
        selection: Default::default(),
        kinds: Default::default(),
        threads: 1,
        progress: false,
        state_interval: 60.0,
    };
    render_dataset(&config, &dir, options, &StandIn::default()).unwrap();
    (dir.clone(), Manifest::load(&dir).unwrap())
}

/// Re-assembles the manifest from the records (as the command does after its scenes).
fn assign_manifest(dir: &Path, manifest: &Manifest) {
    let plan = Plan::new(&manifest.config);
    assemble_manifest(dir, &manifest.config, &plan, false)
        .unwrap()
        .unwrap();
}

/// The evaluation reference the re-assembled manifest lists for scene `id`.
fn listed_reference(
    dir: &Path,
    manifest: &Manifest,
    id: &str,
) -> Option<bundle::manifest::EvaluationReference> {
    let plan = Plan::new(&manifest.config);
    let assembled = assemble_manifest(dir, &manifest.config, &plan, false)
        .unwrap()
        .unwrap();
    let listed = assembled.scenes.iter().find(|s| s.id == id).unwrap();
    listed.evaluation_reference.clone()
}

fn options(manifest: &Manifest, target: f64, max_factor: u32) -> EvaluationOptions {
    EvaluationOptions {
        splits: vec![manifest.scenes[0].split],
        scenes: vec![manifest.scenes[0].id.clone()],
        target,
        max_factor,
        // The stand-in's runs do not depend on it; the floor's own test sets it.
        min_photons: 0,
        max_seconds: None,
        threads: 1,
        state_interval: 60.0,
    }
}

fn run(
    dir: &Path,
    manifest: &Manifest,
    options: &EvaluationOptions,
    renderer: &StandIn,
) -> Result<Vec<datagen::evaluation_reference::SceneOutcome>> {
    evaluation_references(
        dir,
        manifest,
        renderer,
        options,
        |_| {},
        &mut |_, _, _, _| {},
    )
}

#[test]
fn runs_grow_until_the_noise_meets_the_target_and_the_manifest_lists_them() {
    let (dir, manifest) = dataset("evalref-grow");
    let scene = manifest.scenes[0].clone();
    let renderer = StandIn::default();
    let outcomes = run(&dir, &manifest, &options(&manifest, 0.1, 4096), &renderer).unwrap();
    assert_eq!(outcomes.len(), 1);
    let r = &outcomes[0].reference;
    assert!(r.converged, "{r:?}");
    assert!(r.noise <= 0.1 * r.input_relmse, "{r:?}");
    assert!(r.passes > REFERENCE_PASSES, "{r:?}");
    assert_eq!(r.seeds.len(), 2);
    assert_ne!(r.seeds[0], r.seeds[1]);
    assert!(!r.seeds.contains(&scene.reference_seed));
    // Each run asked for increasing pass counts, with its own state file kept for later rounds.
    let runs = renderer.runs.lock().unwrap().clone();
    for seed in &r.seeds {
        let passes: Vec<u32> = runs
            .iter()
            .filter(|(s, _, _)| s == seed)
            .map(|&(_, p, _)| p)
            .collect();
        assert!(passes.windows(2).all(|w| w[0] < w[1]), "{passes:?}");
        assert_eq!(*passes.last().unwrap(), r.passes);
        // No round grows the runs more than 4×, the first not past 4× the reference's passes:
        // a time limit is checked between rounds, so no round may run away with it.
        assert!(passes.windows(2).all(|w| w[1] <= 4 * w[0]), "{passes:?}");
        assert!(passes[0] <= 4 * REFERENCE_PASSES, "{passes:?}");
    }
    assert!(runs.iter().all(|(_, _, state)| state
        .as_ref()
        .is_some_and(|p| p.starts_with(dir.join("evaluation-references/runs")))));
    // The noise is the measured spread. The two seeds differ by an odd step, so the runs sit
    // at truth ± a (a = 0.4/√passes) with opposite signs in every sample: the mean is the truth,
    // each sample's unbiased variance 2a², and the mean of two runs carries
    // a² · mean over pixels of 1/(grey² + 0.01), grey the truth's mean over RGB.
    let a2 = 0.16 / f64::from(r.passes);
    let mut weight = 0.0;
    for y in 0..SIDE {
        for x in 0..SIDE {
            let grey = (0..3).map(|c| f64::from(truth(x, y, c))).sum::<f64>() / 3.0;
            weight += 1.0 / (grey * grey + 0.01);
        }
    }
    let expected = a2 * weight / (SIDE * SIDE) as f64;
    assert!(
        (r.noise - expected).abs() <= 1e-4 * expected,
        "noise {} expected {expected}",
        r.noise
    );
    // The input's error is the best level's (+0.05 everywhere) relMSE, less that noise.
    let mut input = 0.0;
    for y in 0..SIDE {
        for x in 0..SIDE {
            let grey = (0..3).map(|c| f64::from(truth(x, y, c))).sum::<f64>() / 3.0;
            input += 3.0 * 0.05f64.powi(2) / (grey * grey + 0.01);
        }
    }
    let input = input / (3 * SIDE * SIDE) as f64 - expected;
    assert!(
        (r.input_relmse - input).abs() <= 1e-3 * input,
        "input {} expected {input}",
        r.input_relmse
    );
    // The manifest, re-assembled, lists it; check verifies its file.
    assert_eq!(
        listed_reference(&dir, &manifest, &scene.id).as_ref(),
        Some(r)
    );
    assert_eq!(r.path, image_path(&scene.id));
    assert!(dir.join(record_path(&scene.id)).is_file());
    let report = datagen::check::check_dataset(&dir, |_, _| {});
    assert!(report.ok(), "{:?}", report.problems);
    // A damaged evaluation reference is a problem naming it; a repeated call redoes it from the
    // runs' states (never asking them for fewer passes) and check passes again.
    std::fs::write(dir.join(&r.path), b"broken").unwrap();
    let report = datagen::check::check_dataset(&dir, |_, _| {});
    assert!(
        report.problems.iter().any(|p| p.starts_with(&r.path)),
        "{:?}",
        report.problems
    );
    let redone = run(
        &dir,
        &manifest,
        &options(&manifest, 0.1, 4096),
        &StandIn::default(),
    )
    .unwrap();
    assert_eq!(redone[0].reference.passes, r.passes);
    assign_manifest(&dir, &manifest);
    let report = datagen::check::check_dataset(&dir, |_, _| {});
    assert!(report.ok(), "{:?}", report.problems);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_repeat_renders_nothing_and_a_stricter_target_continues_the_runs() {
    let (dir, manifest) = dataset("evalref-continue");
    let first = run(
        &dir,
        &manifest,
        &options(&manifest, 0.1, 4096),
        &StandIn::default(),
    )
    .unwrap();
    let again = StandIn::default();
    let kept = run(&dir, &manifest, &options(&manifest, 0.1, 4096), &again).unwrap();
    assert!(again.runs.lock().unwrap().is_empty());
    assert!(!kept[0].rendered);
    assert_eq!(kept[0].reference, first[0].reference);
    let stricter = StandIn::default();
    let more = run(&dir, &manifest, &options(&manifest, 0.01, 4096), &stricter).unwrap();
    let r = &more[0].reference;
    assert!(r.converged && r.noise <= 0.01 * r.input_relmse, "{r:?}");
    assert!(r.passes > first[0].reference.passes);
    // It starts where the first call stopped (the runs resume from their states).
    let runs = stricter.runs.lock().unwrap().clone();
    assert_eq!(runs[0].1, first[0].reference.passes, "{runs:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_pass_limit_flags_the_scene_and_a_killed_round_resumes_at_its_target() {
    let (dir, manifest) = dataset("evalref-limit");
    let opts = options(&manifest, 0.001, 8);
    let limited = run(&dir, &manifest, &opts, &StandIn::default()).unwrap();
    let r = &limited[0].reference;
    assert!(!r.converged, "{r:?}");
    assert_eq!(r.passes, 8 * REFERENCE_PASSES);
    // Kill the next round (a higher limit) in its first run, then resume: the same target.
    let higher = options(&manifest, 0.001, 64);
    let all_runs = StandIn::default();
    run(&dir, &manifest, &higher, &all_runs).unwrap();
    let round = all_runs.runs.lock().unwrap()[2].1;
    assert!(round > r.passes);
    let (dir2, manifest2) = dataset("evalref-kill");
    run(&dir2, &manifest2, &opts, &StandIn::default()).unwrap();
    let killed = StandIn {
        fail_at: Some(round),
        ..StandIn::default()
    };
    assert!(run(&dir2, &manifest2, &higher, &killed).is_err());
    let resumed = StandIn::default();
    let done = run(&dir2, &manifest2, &higher, &resumed).unwrap();
    assert_eq!(resumed.runs.lock().unwrap()[0].1, round);
    assert_eq!(done[0].reference, {
        let mut r = run(&dir, &manifest, &higher, &StandIn::default()).unwrap()[0]
            .reference
            .clone();
        // Wall-clock seconds differ between the two histories.
        r.seconds = done[0].reference.seconds;
        r
    });
    // Bad requests are errors.
    let mut bad = options(&manifest, 0.0, 8);
    assert!(run(&dir, &manifest, &bad, &StandIn::default()).is_err());
    bad.target = 0.1;
    bad.scenes = vec!["999-nothing".into()];
    let err = run(&dir, &manifest, &bad, &StandIn::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("999-nothing"), "{err}");
    bad.scenes.clear();
    bad.splits = vec![Split::Train, Split::Val, Split::Test];
    bad.max_factor = 1;
    assert!(run(&dir, &manifest, &bad, &StandIn::default()).is_err());
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&dir2);
}

#[test]
fn a_photon_floor_starts_the_runs_again_with_more_photons_and_keeps_runs_above_it() {
    let (dir, manifest) = dataset("evalref-photons");
    let scene = manifest.scenes[0].clone();
    let mut opts = options(&manifest, 0.1, 4096);
    // Below the scene's reference photons the floor changes nothing: the runs keep the
    // reference's photons and the state names they always had.
    opts.min_photons = scene.reference_photons / 2;
    let plain = StandIn::default();
    let first = run(&dir, &manifest, &opts, &plain).unwrap();
    assert_eq!(first[0].reference.photons, scene.reference_photons);
    assert!(plain
        .photons
        .lock()
        .unwrap()
        .iter()
        .all(|&p| p == scene.reference_photons));
    let old_states: Vec<PathBuf> = plain
        .runs
        .lock()
        .unwrap()
        .iter()
        .map(|(_, _, s)| s.clone().unwrap())
        .collect();
    for state in &old_states {
        let name = state.file_name().unwrap().to_string_lossy().into_owned();
        assert!(name.ends_with(".state") && !name.contains(".n"), "{name}");
        assert!(state.is_file(), "{}", state.display());
    }
    // A floor above them: the record does not meet it, so the runs start again (from the
    // predicted first round, not from the old runs' passes) with the floor's photons, in states
    // of their own.
    let floor = 4 * scene.reference_photons;
    opts.min_photons = floor;
    let raised = StandIn::default();
    let second = run(&dir, &manifest, &opts, &raised).unwrap();
    assert!(second[0].rendered);
    let r = &second[0].reference;
    assert_eq!(r.photons, floor);
    assert!(r.converged, "{r:?}");
    assert!(raised.photons.lock().unwrap().iter().all(|&p| p == floor));
    let runs = raised.runs.lock().unwrap().clone();
    assert!(runs[0].1 <= 4 * REFERENCE_PASSES, "{runs:?}");
    for (_, _, state) in &runs {
        let state = state.as_ref().unwrap();
        assert!(!old_states.contains(state), "{}", state.display());
        assert!(state
            .to_string_lossy()
            .ends_with(&format!(".n{floor}.state")));
    }
    // The manifest lists the new reference with its photons.
    assert_eq!(
        listed_reference(&dir, &manifest, &scene.id).as_ref(),
        Some(r)
    );
    // A lower floor later keeps the reference with more photons; a stricter target continues
    // its runs with their photons.
    opts.min_photons = 0;
    let again = StandIn::default();
    let kept = run(&dir, &manifest, &opts, &again).unwrap();
    assert!(!kept[0].rendered);
    assert!(again.runs.lock().unwrap().is_empty());
    assert_eq!(&kept[0].reference, r);
    opts.target = 0.01;
    let stricter = StandIn::default();
    let more = run(&dir, &manifest, &opts, &stricter).unwrap();
    assert_eq!(more[0].reference.photons, floor);
    assert!(stricter.photons.lock().unwrap().iter().all(|&p| p == floor));
    assert_eq!(stricter.runs.lock().unwrap()[0].1, r.passes);
    let _ = std::fs::remove_dir_all(&dir);
}
