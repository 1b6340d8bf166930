//! Dataset bookkeeping with a deterministic stand-in renderer (fast): sharding gives the same
//! files as one process, reruns skip valid work and redo damaged work, the manifest is complete
//! (or, asked for while shards are missing, partial and saying so) and `check` names truncated
//! and non-finite files and manifests missing scenes.

mod common;

use anyhow::Result;
use bundle::{read_bundle, write_bundle, Bundle, Image};
use common::{assert_same, fresh_dir, snapshot, stand_in_bundle, test_config};
use datagen::check::check_dataset;
use datagen::jobs::{render_dataset, RenderOptions, RunSpec, SampleRenderer};
use datagen::manifest::{assemble_manifest, Manifest};
use datagen::plan::Shard;
use datagen::rng::hash_seq;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Images are hashes of (seed, passes, pixel): deterministic, distinct per sample.
#[derive(Default)]
struct StandIn {
    runs: AtomicUsize,
}

fn value(seed: u64, passes: u32, i: usize, c: usize) -> f32 {
    (hash_seq(&[seed, u64::from(passes), i as u64, c as u64]) % 1000) as f32 / 1000.0
}

fn image(spec: &RunSpec, w: usize, h: usize, channels: usize, passes: u32, salt: usize) -> Image {
    let mut img = Image::new(w, h, channels);
    for (i, v) in img.data.iter_mut().enumerate() {
        *v = value(spec.sppm.seed, passes, i, salt);
    }
    img
}

fn size(xml: &Path) -> (usize, usize) {
    let text = std::fs::read_to_string(xml).unwrap();
    let grab = |name: &str| -> usize {
        let key = format!("name=\"{name}\" value=\"");
        let at = text.find(&key).unwrap() + key.len();
        text[at..].split('"').next().unwrap().parse().unwrap()
    };
    (grab("width"), grab("height"))
}

impl SampleRenderer for StandIn {
    fn reference(
        &self,
        xml: &Path,
        spec: &RunSpec,
        on_pass: &mut (dyn FnMut(u32) + Send),
    ) -> Result<Image> {
        self.runs.fetch_add(1, Ordering::SeqCst);
        let (w, h) = size(xml);
        // A run resumes after the pass its state file holds (here as text), as SPPM does.
        let saved: u32 = spec
            .state
            .as_ref()
            .and_then(|s| std::fs::read_to_string(&s.path).ok())
            .and_then(|t| t.trim().parse().ok())
            .unwrap_or(0);
        for p in saved + 1..=spec.passes[0] {
            on_pass(p);
        }
        Ok(image(spec, w, h, 3, spec.passes[0], 0))
    }

    fn inputs(
        &self,
        xml: &Path,
        spec: &RunSpec,
        on_bundle: &mut (dyn FnMut(Bundle) -> Result<()> + Send),
        on_pass: &mut (dyn FnMut(u32) + Send),
    ) -> Result<()> {
        self.runs.fetch_add(1, Ordering::SeqCst);
        let (w, h) = size(xml);
        for &p in &spec.passes {
            on_pass(p);
            on_bundle(stand_in_bundle(spec, p, (w, h), true, |channels, salt| {
                image(spec, w, h, channels, p, salt)
            }))?;
        }
        Ok(())
    }
}

fn options(shard: Shard) -> RenderOptions {
    RenderOptions {
        shard,
        selection: Default::default(),
        kinds: Default::default(),
        threads: 1,
        progress: false,
        state_interval: 60.0,
    }
}

#[test]
fn three_concurrent_shards_equal_one_process_and_reruns_skip() {
    let config = test_config(16, &[2, 4], 2, 8);
    let single = fresh_dir("fake-single");
    let r = StandIn::default();
    let report = render_dataset(&config, &single, options(Shard::ALL), &r).unwrap();
    assert!(report.manifest_complete);
    assert_eq!(report.rendered, 5 * 3);
    let manifest = Manifest::load(&single).unwrap();
    assert_eq!(manifest.scenes.len(), 5);
    assert_eq!(manifest.samples.len(), 5 * 2 * 2);
    assert!(check_dataset(&single, |_, _| {}).ok());

    let sharded = fresh_dir("fake-sharded");
    std::thread::scope(|s| {
        for i in 0..3 {
            let (config, dir) = (&config, &sharded);
            s.spawn(move || {
                let r = StandIn::default();
                render_dataset(config, dir, options(Shard::new(i, 3).unwrap()), &r).unwrap();
            });
        }
    });
    assert_same(&snapshot(&single), &snapshot(&sharded));

    // A rerun finds everything valid and renders nothing.
    let again = StandIn::default();
    let report = render_dataset(&config, &single, options(Shard::ALL), &again).unwrap();
    assert_eq!((report.rendered, report.skipped), (0, 15));
    assert_eq!(again.runs.load(Ordering::SeqCst), 0);
    std::fs::remove_dir_all(&single).unwrap();
    std::fs::remove_dir_all(&sharded).unwrap();
}

#[test]
fn damaged_outputs_are_named_by_check_and_redone_by_render() {
    let config = test_config(16, &[2, 4], 1, 8);
    let dir = fresh_dir("fake-damage");
    render_dataset(&config, &dir, options(Shard::ALL), &StandIn::default()).unwrap();
    let clean = snapshot(&dir);
    let manifest = Manifest::load(&dir).unwrap();

    // Truncate one bundle; put a NaN into another (a valid EXR, new checksum).
    let truncated = manifest.samples[0].bundle.clone();
    let bytes = std::fs::read(dir.join(&truncated)).unwrap();
    std::fs::write(dir.join(&truncated), &bytes[..bytes.len() / 2]).unwrap();
    let nan = manifest.samples[3].bundle.clone();
    let mut b = read_bundle(&dir.join(&nan)).unwrap();
    b.levels[2].set(3, 5, 1, f32::NAN);
    write_bundle(&dir.join(&nan), &b).unwrap();
    // Delete a reference.
    let missing = manifest.scenes[2].reference.clone();
    std::fs::remove_file(dir.join(&missing)).unwrap();

    let report = check_dataset(&dir, |_, _| {});
    assert!(!report.ok());
    let text = report.problems.join("\n");
    assert!(
        report
            .problems
            .iter()
            .any(|p| p.starts_with(&truncated) && p.contains("truncated")),
        "{text}"
    );
    assert!(
        report
            .problems
            .iter()
            .any(|p| p.starts_with(&nan) && p.contains("NaN") && p.contains("z2")),
        "{text}"
    );
    assert!(
        report.problems.iter().any(|p| p.starts_with(&missing)),
        "{text}"
    );
    // Exactly the three damaged files are named, each on one line (a truncated file is both
    // unreadable and of another checksum; a missing one is not "unreadable" besides).
    let named: std::collections::BTreeSet<&str> = report
        .problems
        .iter()
        .map(|p| p.split(':').next().unwrap())
        .collect();
    assert_eq!(named.len(), 3, "{text}");
    assert_eq!(report.problems.len(), 3, "{text}");
    let line = |file: &str| {
        report
            .problems
            .iter()
            .find(|p| p.starts_with(file))
            .unwrap()
    };
    assert!(
        line(&truncated).contains("unreadable") && line(&truncated).contains("checksum mismatch"),
        "{text}"
    );
    assert!(
        line(&missing).contains("missing") && !line(&missing).contains("; unreadable"),
        "{text}"
    );

    // Rendering again redoes exactly the three damaged jobs and restores the dataset.
    let r = StandIn::default();
    let report = render_dataset(&config, &dir, options(Shard::ALL), &r).unwrap();
    assert_eq!(report.rendered, 3);
    assert_same(&clean, &snapshot(&dir));
    assert!(check_dataset(&dir, |_, _| {}).ok());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A scene or sample listed twice in the manifest (it would be trained on twice) is named by
/// `check`.
#[test]
fn check_names_repeated_manifest_entries() {
    let config = test_config(16, &[2], 1, 4);
    let dir = fresh_dir("fake-repeated");
    render_dataset(&config, &dir, options(Shard::ALL), &StandIn::default()).unwrap();
    assert!(check_dataset(&dir, |_, _| {}).ok());
    let path = dir.join("manifest.json");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    for list in ["scenes", "samples"] {
        let first = manifest[list][0].clone();
        manifest[list].as_array_mut().unwrap().push(first);
    }
    std::fs::write(&path, serde_json::to_string_pretty(&manifest).unwrap()).unwrap();
    let report = check_dataset(&dir, |_, _| {});
    let text = report.problems.join("\n");
    let scene = manifest["scenes"][0]["id"].as_str().unwrap();
    let bundle = manifest["samples"][0]["bundle"].as_str().unwrap();
    assert!(
        text.contains(&format!("scene `{scene}` is listed more than once")),
        "{text}"
    );
    assert!(
        text.contains(&format!("sample {bundle} is listed more than once")),
        "{text}"
    );
    assert_eq!(report.problems.len(), 2, "{text}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn manifest_waits_for_all_shards() {
    let config = test_config(16, &[2], 1, 4);
    let dir = fresh_dir("fake-partial");
    let report = render_dataset(
        &config,
        &dir,
        options(Shard::new(0, 2).unwrap()),
        &StandIn::default(),
    )
    .unwrap();
    assert!(!report.manifest_complete);
    assert!(!dir.join("manifest.json").exists());
    let report = render_dataset(
        &config,
        &dir,
        options(Shard::new(1, 2).unwrap()),
        &StandIn::default(),
    )
    .unwrap();
    assert!(report.manifest_complete);
    assert!(check_dataset(&dir, |_, _| {}).ok());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `datagen manifest --partial` while shards are missing: the scenes whose every job is done,
/// marked partial, which `check` accepts and reports as partial; a manifest that lists fewer
/// scenes than its config plans without saying so is named by `check`; the last shard writes
/// the complete manifest, which a partial assembly then equals.
#[test]
fn partial_manifest_lists_finished_scenes_only() {
    let config = test_config(16, &[2], 1, 4);
    let plan = datagen::plan::Plan::new(&config);
    let dir = fresh_dir("fake-partial-list");
    let shard = |i| options(Shard::new(i, 3).unwrap());
    render_dataset(&config, &dir, shard(0), &StandIn::default()).unwrap();
    render_dataset(&config, &dir, shard(1), &StandIn::default()).unwrap();
    assert!(!dir.join("manifest.json").exists());
    assert!(assemble_manifest(&dir, &config, &plan, false)
        .unwrap()
        .is_none());
    // Jobs (reference, input) per scene; shards 0 and 1 of 3 ran jobs 0, 1, 3, 4, 6, 7, 9: the
    // scenes of jobs 0–1 and 6–7 are done.
    let finished: Vec<String> = [0, 6]
        .iter()
        .map(|&j| plan.scenes[plan.jobs[j].scene()].id.clone())
        .collect();
    let partial = assemble_manifest(&dir, &config, &plan, true)
        .unwrap()
        .expect("two scenes are done");
    let mut listed: Vec<String> = partial.scenes.iter().map(|s| s.id.clone()).collect();
    listed.sort();
    let mut expected = finished.clone();
    expected.sort();
    assert_eq!(listed, expected);
    assert!(partial.samples.iter().all(|e| finished.contains(&e.scene)));
    assert_eq!(partial.samples.len(), 2);
    assert_eq!(partial.partial.map(|p| p.planned_scenes), Some(5));
    assert_eq!(Manifest::load(&dir).unwrap(), partial);
    let report = check_dataset(&dir, |_, _| {});
    assert!(report.ok(), "{:?}", report.problems);
    assert_eq!(report.partial, Some((2, 5)));

    // The last shard writes the complete manifest; a partial assembly of a finished dataset is
    // the complete one.
    let report = render_dataset(&config, &dir, shard(2), &StandIn::default()).unwrap();
    assert!(report.manifest_complete);
    let complete = Manifest::load(&dir).unwrap();
    assert_eq!((complete.scenes.len(), complete.partial), (5, None));
    let bytes = std::fs::read(dir.join("manifest.json")).unwrap();
    assert_eq!(
        assemble_manifest(&dir, &config, &plan, true).unwrap(),
        Some(complete.clone())
    );
    assert_eq!(std::fs::read(dir.join("manifest.json")).unwrap(), bytes);
    assert_eq!(check_dataset(&dir, |_, _| {}).partial, None);

    // A scene dropped from a complete manifest by hand is named.
    let path = dir.join("manifest.json");
    let mut json: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    json["scenes"].as_array_mut().unwrap().pop();
    std::fs::write(&path, serde_json::to_string_pretty(&json).unwrap()).unwrap();
    let text = check_dataset(&dir, |_, _| {}).problems.join("\n");
    assert!(
        text.contains("lists 4 scenes, its config plans 5"),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A terminal stand-in for the progress bars: records what is written and where the cursor
/// is left (column 0 = at the start of a line, where the next output begins cleanly).
#[derive(Debug, Default, Clone)]
struct Term {
    text: std::sync::Arc<std::sync::Mutex<(String, usize)>>,
}

const TERM_WIDTH: u16 = 100;

impl indicatif::TermLike for Term {
    fn width(&self) -> u16 {
        TERM_WIDTH
    }
    fn move_cursor_up(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_down(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }
    fn move_cursor_right(&self, n: usize) -> std::io::Result<()> {
        self.text.lock().unwrap().1 += n;
        Ok(())
    }
    fn move_cursor_left(&self, n: usize) -> std::io::Result<()> {
        let mut t = self.text.lock().unwrap();
        t.1 = t.1.saturating_sub(n);
        Ok(())
    }
    fn write_line(&self, s: &str) -> std::io::Result<()> {
        let mut t = self.text.lock().unwrap();
        t.0.push_str(s);
        t.0.push('\n');
        t.1 = 0;
        Ok(())
    }
    fn write_str(&self, s: &str) -> std::io::Result<()> {
        let mut t = self.text.lock().unwrap();
        t.0.push_str(s);
        t.1 = match s.rfind('\n') {
            Some(at) => s[at + 1..].chars().count(),
            None => t.1 + s.chars().count(),
        };
        Ok(())
    }
    fn clear_line(&self) -> std::io::Result<()> {
        let mut t = self.text.lock().unwrap();
        t.0.push('\n');
        t.1 = 0;
        Ok(())
    }
    fn flush(&self) -> std::io::Result<()> {
        Ok(())
    }
}

/// On a terminal: a job resumed from a state of a killed session says so; the overall bar
/// counts files; and no finished bar is left standing (the summary line printed after
/// `render_dataset` would be glued to it).
#[test]
fn progress_says_resuming_counts_files_and_leaves_a_clean_line() {
    use datagen::manifest::config_fingerprint;
    use datagen::plan::{Job, Plan};
    let config = test_config(16, &[2], 1, 8);
    let dir = fresh_dir("fake-progress");
    // A killed session's state of the first reference job, saved at pass 5 of 8.
    let plan = Plan::new(&config);
    let job = Job::Reference { scene: 0 };
    let state = dir.join(plan.state_path(&job, &config_fingerprint(&config)));
    std::fs::create_dir_all(state.parent().unwrap()).unwrap();
    std::fs::write(&state, "5").unwrap();
    let term = Term::default();
    let target = indicatif::ProgressDrawTarget::term_like(Box::new(term.clone()));
    let mut o = options(Shard::ALL);
    o.progress = true;
    let report =
        datagen::jobs::render_dataset_to(&config, &dir, o, &StandIn::default(), target).unwrap();
    assert_eq!(report.rendered, 10);
    assert!(!state.exists());
    let (text, column) = std::mem::take(&mut *term.text.lock().unwrap());
    let resumed = format!("{} reference: resuming at pass 5 of 8", plan.scenes[0].id);
    assert_eq!(text.matches("resuming at pass").count(), 1, "{text}");
    assert!(text.contains(&resumed), "{text}");
    assert!(
        text.contains("/10 files") && !text.contains("samples"),
        "{text}"
    );
    assert!(
        text.contains("passes/s") || text.contains("s/pass"),
        "{text}"
    );
    assert_eq!(column, 0, "the last bar was left standing:\n{text}");
    // The resumed job's rate counts this session's passes only: none measured at its first.
    let first = text
        .split('\n')
        .find(|l| l.contains(" 6/8 passes"))
        .expect("the resumed job's bar at its first pass");
    assert!(first.contains("\u{2014} passes/s"), "{first}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn pass_rates_have_three_significant_digits() {
    use datagen::jobs::format_pass_rate;
    assert_eq!(format_pass_rate(20752.0366), "20752 passes/s");
    assert_eq!(format_pass_rate(103.9879), "104 passes/s");
    assert_eq!(format_pass_rate(12.345), "12.3 passes/s");
    assert_eq!(format_pass_rate(2.3456), "2.35 passes/s");
    assert_eq!(format_pass_rate(0.08), "12.5 s/pass");
    assert_eq!(format_pass_rate(0.0), "\u{2014} passes/s");
    assert_eq!(format_pass_rate(f64::NAN), "\u{2014} passes/s");
}

/// `datagen render --families/--splits/--scenes/--per-family`: a selection renders exactly the
/// jobs of its scenes; slices rendered one after another add up to the files of the whole
/// dataset (the last one writes the complete manifest); names the config does not have, and a
/// selection that keeps nothing, are errors that render nothing.
#[test]
fn scene_selections_render_their_scenes_and_add_up_to_the_whole() {
    use datagen::plan::{Plan, SceneSelection};
    let config = test_config(16, &[2], 1, 4);
    let plan = Plan::new(&config);
    let whole = fresh_dir("fake-select-whole");
    render_dataset(&config, &whole, options(Shard::ALL), &StandIn::default()).unwrap();

    let dir = fresh_dir("fake-select");
    let with = |selection: SceneSelection| RenderOptions {
        selection,
        ..options(Shard::ALL)
    };
    // The first scene of the first scene's family and split: exactly that scene's two jobs.
    let first = &plan.scenes[0];
    let one = with(SceneSelection {
        splits: vec![first.split],
        families: vec![first.family.name().into()],
        per_family: Some((1, 1)),
        ..Default::default()
    });
    let r = StandIn::default();
    let report = render_dataset(&config, &dir, one, &r).unwrap();
    assert_eq!((report.rendered, report.skipped), (2, 0));
    assert!(!report.manifest_complete);
    assert!(dir
        .join(format!("records/{}/reference.json", first.id))
        .exists());
    let records = std::fs::read_dir(dir.join("records")).unwrap().count();
    assert_eq!(records, 1, "only the selected scene is rendered");

    // Bad names and empty selections: errors, nothing rendered.
    for (bad, says) in [
        (
            SceneSelection {
                families: vec!["nope".into()],
                ..Default::default()
            },
            "family `nope` is not in this config",
        ),
        (
            SceneSelection {
                scenes: vec!["999-room".into()],
                ..Default::default()
            },
            "scene `999-room` is not in this config",
        ),
        (
            SceneSelection {
                per_family: Some((90, 99)),
                ..Default::default()
            },
            "keeps no scene",
        ),
    ] {
        let r = StandIn::default();
        let e = render_dataset(&config, &dir, with(bad), &r).unwrap_err();
        assert!(format!("{e:#}").contains(says), "{e:#}");
        assert_eq!(r.runs.load(Ordering::SeqCst), 0);
    }

    // The rest, split by split and then by scene id: the whole dataset, byte for byte.
    for split in [datagen::plan::Split::Test, datagen::plan::Split::Val] {
        if plan.scenes.iter().any(|s| s.split == split) {
            let selection = SceneSelection {
                splits: vec![split],
                ..Default::default()
            };
            render_dataset(&config, &dir, with(selection), &StandIn::default()).unwrap();
        }
    }
    let rest = SceneSelection {
        scenes: plan.scenes.iter().map(|s| s.id.clone()).collect(),
        ..Default::default()
    };
    let report = render_dataset(&config, &dir, with(rest), &StandIn::default()).unwrap();
    assert!(report.manifest_complete);
    assert_same(&snapshot(&whole), &snapshot(&dir));
    std::fs::remove_dir_all(&whole).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `datagen render --jobs`: the references of a dataset, then its inputs (in two shards, on
/// other machines in practice), are the whole dataset byte for byte; each call runs only its
/// kind, skips nothing of the other, and the manifest is complete only after both.
#[test]
fn reference_and_input_jobs_rendered_apart_add_up_to_the_whole() {
    use datagen::plan::{Job, JobKinds, Plan};
    let config = test_config(16, &[2, 4], 2, 4);
    let plan = Plan::new(&config);
    let references = plan
        .jobs
        .iter()
        .filter(|j| matches!(j, Job::Reference { .. }))
        .count();
    let inputs = plan.jobs.len() - references;
    assert!(references > 0 && inputs > references);
    let whole = fresh_dir("fake-kinds-whole");
    render_dataset(&config, &whole, options(Shard::ALL), &StandIn::default()).unwrap();

    let dir = fresh_dir("fake-kinds");
    let refs_only = RenderOptions {
        kinds: JobKinds::References,
        ..options(Shard::ALL)
    };
    let report = render_dataset(&config, &dir, refs_only.clone(), &StandIn::default()).unwrap();
    assert_eq!((report.rendered, report.skipped), (references, 0));
    assert!(!report.manifest_complete);
    assert!(!dir.join("bundles").exists(), "no input was rendered");
    // Again: everything of its kind is done.
    let report = render_dataset(&config, &dir, refs_only, &StandIn::default()).unwrap();
    assert_eq!((report.rendered, report.skipped), (0, references));

    let mut rendered = 0;
    for i in 0..2 {
        let inputs_only = RenderOptions {
            kinds: JobKinds::Inputs,
            ..options(Shard::new(i, 2).unwrap())
        };
        let report = render_dataset(&config, &dir, inputs_only, &StandIn::default()).unwrap();
        assert_eq!(report.skipped, 0, "the references are not the inputs' jobs");
        rendered += report.rendered;
        assert_eq!(report.manifest_complete, i == 1);
    }
    assert_eq!(rendered, inputs);
    assert_same(&snapshot(&whole), &snapshot(&dir));
    std::fs::remove_dir_all(&whole).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn per_family_ranges_parse_and_bad_ones_are_refused() {
    use datagen::plan::SceneSelection;
    assert_eq!(SceneSelection::parse_range("1-4"), Ok((1, 4)));
    assert_eq!(SceneSelection::parse_range("3"), Ok((3, 3)));
    for bad in ["0-2", "4-1", "a-b", "", "1-"] {
        assert!(SceneSelection::parse_range(bad).is_err(), "{bad}");
    }
}

/// `render.sharp_level` reaches the input runs only: references gather ỹ at subpath A whatever
/// it says (so a dataset's references do not depend on it), inputs as configured (absent: A,
/// as every dataset rendered before the option).
#[test]
fn the_sharp_level_reaches_the_input_runs_and_not_the_references() {
    use renderer::integrators::sppm::SharpLevel;
    use std::sync::Mutex;
    /// [`StandIn`] that notes each run's kind and sharp level.
    #[derive(Default)]
    struct Recorder {
        inner: StandIn,
        seen: Mutex<Vec<(&'static str, Option<SharpLevel>)>>,
    }
    impl SampleRenderer for Recorder {
        fn reference(
            &self,
            xml: &Path,
            spec: &RunSpec,
            on_pass: &mut (dyn FnMut(u32) + Send),
        ) -> Result<Image> {
            let kind = ("reference", spec.sppm.sharp_level);
            self.seen.lock().unwrap().push(kind);
            self.inner.reference(xml, spec, on_pass)
        }
        fn inputs(
            &self,
            xml: &Path,
            spec: &RunSpec,
            on_bundle: &mut (dyn FnMut(Bundle) -> Result<()> + Send),
            on_pass: &mut (dyn FnMut(u32) + Send),
        ) -> Result<()> {
            let kind = ("inputs", spec.sppm.sharp_level);
            self.seen.lock().unwrap().push(kind);
            self.inner.inputs(xml, spec, on_bundle, on_pass)
        }
    }
    for (configured, inputs) in [
        (None, SharpLevel::SubpathA),
        (Some(SharpLevel::BothSubpaths), SharpLevel::BothSubpaths),
    ] {
        let mut config = test_config(8, &[2], 1, 4);
        config.render.sharp_level = configured;
        let dir = fresh_dir(&format!("fake-sharp-{}", inputs.name()));
        let recorder = Recorder::default();
        render_dataset(&config, &dir, options(Shard::ALL), &recorder).unwrap();
        let seen = recorder.seen.lock().unwrap().clone();
        assert!(seen.iter().any(|(k, _)| *k == "reference"), "{seen:?}");
        assert!(seen.iter().any(|(k, _)| *k == "inputs"), "{seen:?}");
        for (kind, sharp) in &seen {
            let expected = if *kind == "inputs" {
                inputs
            } else {
                SharpLevel::SubpathA
            };
            assert_eq!(*sharp, Some(expected), "{kind}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
    // The key: absent leaves the fingerprint as it was; an unknown value is refused.
    let plain = test_config(8, &[2], 1, 4);
    let json = serde_json::to_string(&plain).unwrap();
    assert!(!json.contains("sharp_level"), "{json}");
    let mut both = plain.clone();
    both.render.sharp_level = Some(SharpLevel::BothSubpaths);
    assert_ne!(
        datagen::manifest::config_fingerprint(&both),
        datagen::manifest::config_fingerprint(&plain)
    );
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/datagen/tiny.toml"),
    )
    .unwrap();
    let edited = text.replacen("max_depth = 8", "max_depth = 8\nsharp_level = \"b\"", 1);
    assert_ne!(edited, text, "tiny.toml no longer has `max_depth = 8`");
    let e = datagen::config::Config::parse(&edited, "s.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("s.toml") && e.contains("sharp_level"), "{e}");
}
