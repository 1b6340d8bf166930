//! End-to-end test of `train`: a tiny on-disk dataset with bad samples, one run, a resume.

use std::path::{Path, PathBuf};
use std::process::Command;

use model::synthetic::synthetic_bundle;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("train-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs `train --config <config> <args…>`.
fn train(config: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_train"))
        .arg("--config")
        .arg(config)
        .args(args)
        .output()
        .unwrap()
}

/// A fresh test directory `name` and its empty dataset folder `<dir>/data`.
fn dir_with_data(name: &str) -> (PathBuf, PathBuf) {
    let dir = temp_dir(name);
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    (dir, data)
}

/// Writes `dir/<name>.toml`: one epoch of the `tiny` preset on `data` with `extra` keys,
/// output `dir/<name>-out`; returns its path.
fn tiny_config(dir: &Path, name: &str, data: &Path, extra: &str) -> PathBuf {
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(
        &path,
        format!(
            "dataset = {data:?}\npreset = \"tiny\"\npatch = 16\nstride = 8\nbatch = 4\nepochs = 1\nseed = 3\n{extra}output = {:?}\n",
            dir.join(format!("{name}-out"))
        ),
    )
    .unwrap();
    path
}

/// Writes a dataset: 2 good train samples, 1 good val sample, and three bad train samples
/// (NaN in a level, missing reference, reference of the wrong size).
fn write_dataset(root: &Path) {
    let mut samples = Vec::new();
    let mut add = |name: &str, split: &str, seed: u64, corrupt: &str| {
        let (mut b, mut reference) = synthetic_bundle(24, 24, 0.3, seed);
        if corrupt == "nan" {
            b.levels[2].data[17] = f32::NAN;
        }
        if corrupt == "size" {
            reference = bundle::Image::new(20, 24, 3);
        }
        let bundle_rel = format!("{name}.exr");
        let reference_rel = format!("{name}_ref.exr");
        bundle::write_bundle(&root.join(&bundle_rel), &b).unwrap();
        if corrupt != "missing" {
            bundle::write_rgb_exr_image(&root.join(&reference_rel), &reference).unwrap();
        }
        samples.push(serde_json::json!({
            "bundle": bundle_rel, "scene": name, "family": "synthetic", "split": split,
            "seed": seed, "seed_index": 0, "passes": 16, "photons": 1000,
            "reference": reference_rel, "sha256": ""
        }));
    };
    add("good0", "train", 1, "");
    add("good1", "train", 2, "");
    add("val0", "val", 3, "");
    add("nan", "train", 4, "nan");
    add("noref", "train", 5, "missing");
    add("badsize", "train", 6, "size");
    let manifest = serde_json::json!({
        "format": bundle::manifest::MANIFEST_FORMAT, "name": "test", "config_sha256": "",
        "width": 24, "height": 24, "reference_level": "y", "scenes": [], "samples": samples,
        "config": {}
    });
    std::fs::write(root.join("manifest.json"), manifest.to_string()).unwrap();
}

#[test]
fn trains_reports_bad_data_and_resumes() {
    let (dir, data) = dir_with_data("run");
    write_dataset(&data);
    let out = dir.join("out");
    let config = dir.join("tiny.toml");
    let write_config = |epochs: usize| {
        std::fs::write(
            &config,
            format!(
                "dataset = {:?}\npreset = \"tiny\"\npatch = 16\nstride = 8\nbatch = 4\nepochs = {epochs}\nseed = 3\noutput = {:?}\n",
                data, out
            ),
        )
        .unwrap();
    };
    write_config(1);
    // The first run on one thread, the resumed one on all cores (the files do not depend on
    // it: model/tests/network.rs).
    let run = |resume: bool| {
        train(
            &config,
            if resume {
                &["--resume"]
            } else {
                &["--threads", "1"]
            },
        )
    };
    let first = run(false);
    let stderr = String::from_utf8_lossy(&first.stderr);
    assert!(first.status.success(), "{stderr}");
    assert!(stderr.contains("3 bad sample(s)"), "{stderr}");
    for name in ["nan.exr", "noref_ref.exr", "badsize_ref.exr"] {
        assert!(stderr.contains(name), "bad file {name} not named: {stderr}");
    }
    assert!(stderr.contains("missing reference"), "{stderr}");
    for f in [
        "model.bpk",
        "model.safetensors",
        "model.json",
        "metrics.csv",
        "train.toml",
        "checkpoint/state.json",
        "curves.png",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), 2, "{csv}");
    assert!(csv.lines().nth(1).unwrap().starts_with("1,"), "{csv}");

    write_config(2);
    let second = run(true);
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert!(second.status.success(), "{stderr}");
    assert!(stderr.contains("resuming after epoch 1"), "{stderr}");
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    // Fewer epochs than the checkpoint has done cannot be honoured: refused, nothing recorded.
    write_config(1);
    let fewer = run(true);
    let stderr = String::from_utf8_lossy(&fewer.stderr);
    assert_eq!(fewer.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("epochs 1 (config) is fewer than the 2 the checkpoint has done"),
        "{stderr}"
    );
    assert!(
        std::fs::read_to_string(out.join("train.toml"))
            .unwrap()
            .contains("epochs = 2"),
        "the refused config was recorded"
    );
    write_config(2);

    // `--plot` redraws the training curves from metrics.json alone.
    std::fs::remove_file(out.join("curves.png")).unwrap();
    let plot = train(&config, &["--plot"]);
    assert!(
        plot.status.success(),
        "{}",
        String::from_utf8_lossy(&plot.stderr)
    );
    assert!(
        String::from_utf8_lossy(&plot.stdout).contains("(2 epochs)"),
        "{}",
        String::from_utf8_lossy(&plot.stdout)
    );
    let png = std::fs::read(out.join("curves.png")).unwrap();
    assert!(
        png.starts_with(b"\x89PNG\r\n\x1a\n"),
        "curves.png is not a PNG"
    );
    let untrained = tiny_config(&dir, "untrained", &data, "");
    let nothing = train(&untrained, &["--plot"]);
    let stderr = String::from_utf8_lossy(&nothing.stderr);
    assert_eq!(nothing.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("metrics.json (train first)"), "{stderr}");

    // Fine-tuning: `init` starts a new run (own output, epoch 1) from those weights, here with
    // a decaying learning rate; an architecture mismatch is a clear error.
    let tuned = dir.join("tuned");
    let tune_config = dir.join("tune.toml");
    let write_tune = |preset: &str, output: &Path| {
        std::fs::write(
            &tune_config,
            format!(
                "dataset = {:?}\npreset = \"{preset}\"\npatch = 16\nstride = 8\nbatch = 4\nepochs = 1\nseed = 3\nlr = 1e-3\nlr_end = 1e-5\ninit = {:?}\noutput = {:?}\n",
                data, out, output
            ),
        )
        .unwrap();
    };
    write_tune("tiny", &tuned);
    let tune = train(&tune_config, &[]);
    let stderr = String::from_utf8_lossy(&tune.stderr);
    assert!(tune.status.success(), "{stderr}");
    assert!(stderr.contains("starting from the weights of"), "{stderr}");
    let csv = std::fs::read_to_string(tuned.join("metrics.csv")).unwrap();
    assert!(csv.lines().nth(1).unwrap().starts_with("1,"), "{csv}");
    assert_ne!(
        std::fs::read(tuned.join("model.bpk")).unwrap(),
        std::fs::read(out.join("model.bpk")).unwrap(),
        "fine-tuning changed nothing"
    );
    // (A fresh output: `tuned` holds a run that a new one must not overwrite.)
    let tuned_small = dir.join("tuned-small");
    write_tune("small", &tuned_small);
    let mismatch = train(&tune_config, &[]);
    assert!(!mismatch.status.success());
    let stderr = String::from_utf8_lossy(&mismatch.stderr);
    assert!(stderr.contains("architecture"), "{stderr}");
    assert!(
        !tuned_small.join("train.toml").exists(),
        "a refused run recorded its config"
    );

    // `--evaluate val` scores the final weights on whole images of the split.
    let eval = train(&config, &["--evaluate", "val"]);
    let stdout = String::from_utf8_lossy(&eval.stdout);
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    assert!(stdout.contains("1 images of 24x24"), "{stdout}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval_val.json")).unwrap()).unwrap();
    let output = report["relmse_output"].as_f64().unwrap();
    let best = report["best_level_relmse"].as_f64().unwrap();
    assert!(output.is_finite() && output > 0.0, "{report}");
    assert!((report["ratio_to_best_level"].as_f64().unwrap() - output / best).abs() < 1e-12);
    // A split the manifest does not have (a typo): an error naming it and the manifest's
    // splits, not a panic, and not an empty split (for `val_split`: training unvalidated).
    let none = train(&config, &["--evaluate", "nosuchsplit"]);
    let stderr = String::from_utf8_lossy(&none.stderr);
    assert_eq!(none.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("no sample in split `nosuchsplit`")
            && stderr.contains("splits: train, val"),
        "{stderr}"
    );
    let typo = tiny_config(&dir, "typo", &data, "val_split = \"vall\"\n");
    let typo_run = train(&typo, &[]);
    let stderr = String::from_utf8_lossy(&typo_run.stderr);
    assert_eq!(typo_run.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("no sample in split `vall`"), "{stderr}");

    // Unknown keys are rejected with the file name and the key's line.
    std::fs::write(&config, "dataset = \"x\"\npreset = \"tiny\"\npatch = 16\nstride = 8\nbatch = 4\nepochs = 1\nseed = 3\noutput = \"o\"\nlearning_rate = 1\n").unwrap();
    let bad = run(false);
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(bad.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&config.display().to_string())
            && stderr.contains("line 9")
            && stderr.contains("unknown field `learning_rate`"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// The output files of a run, by name, to show that a refused command changed none.
fn snapshot(out: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    for dir in [out.to_path_buf(), out.join("checkpoint")] {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_file() {
                let name = path.strip_prefix(out).unwrap().display().to_string();
                files.push((name, std::fs::read(&path).unwrap()));
            }
        }
    }
    files.sort();
    files
}

#[test]
fn refuses_to_overwrite_a_run_or_resume_it_with_other_settings() {
    let (dir, data) = dir_with_data("refuse");
    write_dataset(&data);
    let out = dir.join("run-out");
    // An output directory that exists but holds no run is fine.
    std::fs::create_dir_all(&out).unwrap();
    let config = tiny_config(&dir, "run", &data, "");
    let text = std::fs::read_to_string(&config).unwrap();
    let first = train(&config, &[]);
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let before = snapshot(&out);
    assert!(before.iter().any(|(n, _)| n == "train.toml"), "{before:?}");

    // Training again into it (no `--resume`): refused, naming the directory and `--resume`.
    let again = train(&config, &[]);
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert_eq!(again.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!("{} already holds a training run", out.display()))
            && stderr.contains("checkpoint/state.json")
            && stderr.contains("pass --resume to continue it")
            && stderr.contains("another `output`"),
        "{stderr}"
    );
    assert_eq!(snapshot(&out), before, "a refused run changed the output");

    // Final weights without a checkpoint are a run too, but not one `--resume` continues.
    let weights_only = dir.join("weights-only");
    std::fs::create_dir_all(&weights_only).unwrap();
    std::fs::copy(out.join("model.bpk"), weights_only.join("model.bpk")).unwrap();
    let other = dir.join("other.toml");
    std::fs::write(
        &other,
        text.replace(&format!("{:?}", out), &format!("{:?}", weights_only)),
    )
    .unwrap();
    let onto_weights = train(&other, &[]);
    let stderr = String::from_utf8_lossy(&onto_weights.stderr);
    assert_eq!(onto_weights.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("already holds a training run (model.bpk)")
            && stderr.contains("no checkpoint to resume")
            && !stderr.contains("pass --resume"),
        "{stderr}"
    );
    assert!(!weights_only.join("train.toml").exists());

    // `--resume` with settings the checkpoint cannot continue: each differing TOML key listed
    // (no Rust structs), nothing written, not even the rejected config as train.toml.
    for (change, expected) in [
        (
            ("lr", "lr = 0.01\n"),
            vec!["lr 0.0001 (checkpoint) vs 0.01 (config)"],
        ),
        (
            ("preset", "preset = \"small\"\n"),
            vec![
                "preset tiny (checkpoint) vs small (config)",
                "window 5 (checkpoint) vs 11 (config)",
            ],
        ),
        (
            ("levels", "levels = [0, 2]\nweighting = \"softmax\"\n"),
            vec![
                "weighting relu (checkpoint) vs softmax (config)",
                "levels [0, 1, 2, 3, 4] (checkpoint) vs [0, 2] (config)",
            ],
        ),
        (
            ("batch", "batch = 2\nseed = 4\nloss = \"relmse\"\n"),
            vec![
                "batch 4 (checkpoint) vs 2 (config)",
                "seed 3 (checkpoint) vs 4 (config)",
                "loss relative-log-l1 (checkpoint) vs relmse (config)",
            ],
        ),
    ] {
        let (key, lines) = change;
        // Replace the key's line(s) of the base config, or add them.
        let mut changed: String = text
            .lines()
            .filter(|l| {
                !lines
                    .lines()
                    .any(|n| n.split(' ').next() == l.split(' ').next())
            })
            .map(|l| format!("{l}\n"))
            .collect();
        changed.push_str(lines);
        std::fs::write(&config, &changed).unwrap();
        let resumed = train(&config, &["--resume"]);
        let stderr = String::from_utf8_lossy(&resumed.stderr);
        assert_eq!(resumed.status.code(), Some(1), "{key}: {stderr}");
        let expected = format!(
            "checkpoint settings differ from the config: {}",
            expected.join("; ")
        );
        assert!(stderr.contains(&expected), "{key}: {stderr}");
        assert!(!stderr.contains("TrainSettings {"), "{key}: {stderr}");
        assert_eq!(
            snapshot(&out),
            before,
            "{key}: a refused resume changed the output"
        );
    }
    // The same config resumes (one epoch done, one asked: nothing to train) and records it.
    std::fs::write(&config, &text).unwrap();
    let resumed = train(&config, &["--resume"]);
    let stderr = String::from_utf8_lossy(&resumed.stderr);
    assert!(resumed.status.success(), "{stderr}");
    assert!(stderr.contains("resuming after epoch 1"), "{stderr}");
    assert_eq!(
        std::fs::read_to_string(out.join("train.toml")).unwrap(),
        text
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn resume_without_a_checkpoint_creates_nothing() {
    let (dir, data) = dir_with_data("nockpt");
    let config = tiny_config(&dir, "fresh", &data, "");
    let out = dir.join("fresh-out");
    let resumed = train(&config, &["--resume"]);
    let stderr = String::from_utf8_lossy(&resumed.stderr);
    assert_eq!(resumed.status.code(), Some(1), "{stderr}");
    let expected = format!(
        "no checkpoint to resume in {} (start without --resume)",
        out.join("checkpoint").display()
    );
    assert!(stderr.contains(&expected), "{stderr}");
    assert!(!out.exists(), "a refused resume created {}", out.display());
    // An output directory without a checkpoint (only a run's config): the same, untouched.
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("train.toml"), "old").unwrap();
    let resumed = train(&config, &["--resume"]);
    let stderr = String::from_utf8_lossy(&resumed.stderr);
    assert_eq!(resumed.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains(&expected), "{stderr}");
    assert_eq!(
        std::fs::read_to_string(out.join("train.toml")).unwrap(),
        "old"
    );
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 1);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A `dataset` that is a file or does not exist is refused naming the config and the key,
/// before anything is written.
#[test]
fn a_dataset_that_is_no_directory_is_named_with_its_key() {
    let dir = temp_dir("nodata");
    let file = dir.join("file");
    std::fs::write(&file, "not a dataset").unwrap();
    for (data, why) in [
        (file.clone(), "not a directory"),
        (dir.join("missing"), "no such directory"),
    ] {
        let config = tiny_config(&dir, "run", &data, "");
        let out = train(&config, &[]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        let expected = format!("{}: dataset = {}: {why}", config.display(), data.display());
        assert!(stderr.contains(&expected), "{stderr}");
        assert!(!dir.join("run-out").exists(), "{stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_split_nothing_can_be_trained_on_says_why() {
    let (dir, data) = dir_with_data("unusable");
    write_dataset(&data);
    // A patch larger than every image: the error itself names the reason, not only the list of
    // screened-out samples before it.
    let config = tiny_config(&dir, "huge", &data, "");
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(&config, text.replace("patch = 16", "patch = 64")).unwrap();
    let run = train(&config, &[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    let last = stderr.lines().last().unwrap_or_default();
    assert!(
        last.contains("no usable samples in split `train`")
            && last.contains("smaller than the 64x64 patch"),
        "{stderr}"
    );
    // An empty dataset path is named as such.
    let config = tiny_config(&dir, "nodata", Path::new(""), "");
    let run = train(&config, &[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("dataset must name a dataset directory"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn references_key_replaces_the_manifest_references() {
    let dir = temp_dir("refs");
    let data = dir.join("data");
    std::fs::create_dir_all(data.join("avg")).unwrap();
    write_dataset(&data);
    // The replacement reference of `val0` is its own level z2: that input level's error against
    // it is exactly zero, the others' are not.
    let b = bundle::read_bundle(&data.join("val0.exr")).unwrap();
    bundle::write_rgb_exr_image(&data.join("avg/val0.exr"), &b.levels[2]).unwrap();
    for name in ["good0", "good1"] {
        std::fs::copy(
            data.join(format!("{name}_ref.exr")),
            data.join(format!("avg/{name}.exr")),
        )
        .unwrap();
    }
    let out = dir.join("out");
    let config = dir.join("refs.toml");
    std::fs::write(
        &config,
        format!(
            "dataset = {:?}\nreferences = \"avg\"\npreset = \"tiny\"\npatch = 16\nstride = 8\nbatch = 4\nepochs = 1\nseed = 3\noutput = {:?}\n",
            data, out
        ),
    )
    .unwrap();
    let trained = train(&config, &[]);
    let stderr = String::from_utf8_lossy(&trained.stderr);
    assert!(trained.status.success(), "{stderr}");
    // The bad samples of the manifest have no file in `avg`: named with the replacement's path.
    for name in ["nan.exr", "avg/noref.exr", "avg/badsize.exr"] {
        assert!(stderr.contains(name), "bad file {name} not named: {stderr}");
    }
    let eval = train(&config, &["--evaluate", "val"]);
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval_val.json")).unwrap()).unwrap();
    assert_eq!(
        report["relmse_levels"]["z2"].as_f64(),
        Some(0.0),
        "{report}"
    );
    assert!(
        report["relmse_levels"]["z4"].as_f64().unwrap() > 0.0,
        "{report}"
    );

    // A references directory that does not exist is named before anything is trained.
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(&config, text.replace("\"avg\"", "\"avgg\"")).unwrap();
    let missing = train(&config, &[]);
    assert!(!missing.status.success());
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(
        stderr.contains("avgg") && stderr.contains("does not exist"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_time_budget_stops_between_epochs_and_resume_finishes_the_same_run() {
    let (dir, data) = dir_with_data("time");
    write_dataset(&data);
    let budgeted = tiny_config(&dir, "budgeted", &data, "");
    let whole = tiny_config(&dir, "whole", &data, "");
    for config in [&budgeted, &whole] {
        let text = std::fs::read_to_string(config).unwrap();
        std::fs::write(config, text.replace("epochs = 1\n", "epochs = 3\n")).unwrap();
    }
    // A budget far below one epoch: the first epoch still runs, no second one starts.
    let first = train(&budgeted, &["--time", "1e-6"]);
    let stderr = String::from_utf8_lossy(&first.stderr);
    assert!(first.status.success(), "{stderr}");
    assert!(
        stderr.contains("stopping after epoch 1 of 3") && stderr.contains("--resume"),
        "{stderr}"
    );
    let out = dir.join("budgeted-out");
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), 2, "one epoch expected: {csv}");
    assert!(out.join("model.bpk").is_file() && out.join("checkpoint/state.json").is_file());
    // A generous budget: the resumed run finishes all epochs, bit-identical to one run.
    let resumed = train(&budgeted, &["--resume", "--time", "3600"]);
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    let once = train(&whole, &[]);
    assert!(
        once.status.success(),
        "{}",
        String::from_utf8_lossy(&once.stderr)
    );
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "{csv}");
    assert_eq!(
        std::fs::read(out.join("model.bpk")).unwrap(),
        std::fs::read(dir.join("whole-out/model.bpk")).unwrap(),
        "a run stopped by --time and resumed differs from an uninterrupted one"
    );
    // Budgets that are not a positive number of seconds are refused before anything runs.
    for bad in ["0", "-5", "soon", "inf"] {
        let refused = train(&whole, &["--time", bad]);
        let stderr = String::from_utf8_lossy(&refused.stderr);
        assert_eq!(refused.status.code(), Some(2), "--time {bad}: {stderr}");
        assert!(stderr.contains("--time"), "--time {bad}: {stderr}");
    }
}

#[test]
fn a_family_left_out_of_training_is_evaluated_on_its_own() {
    let (dir, data) = dir_with_data("families");
    let mut samples = Vec::new();
    for (i, (family, split)) in [
        ("room", "train"),
        ("room", "train"),
        ("lamp", "train"),
        ("room", "val"),
        ("lamp", "val"),
        ("lamp", "val"),
    ]
    .into_iter()
    .enumerate()
    {
        let (b, reference) = synthetic_bundle(24, 24, 0.3, i as u64 + 1);
        let name = format!("s{i}");
        bundle::write_bundle(&data.join(format!("{name}.exr")), &b).unwrap();
        bundle::write_rgb_exr_image(&data.join(format!("{name}_ref.exr")), &reference).unwrap();
        samples.push(serde_json::json!({
            "bundle": format!("{name}.exr"), "scene": name, "family": family, "split": split,
            "seed": i, "seed_index": 0, "passes": 16, "photons": 1000,
            "reference": format!("{name}_ref.exr"), "sha256": ""
        }));
    }
    let manifest = serde_json::json!({
        "format": bundle::manifest::MANIFEST_FORMAT, "name": "test", "config_sha256": "",
        "width": 24, "height": 24, "reference_level": "y", "scenes": [], "samples": samples,
        "config": {}
    });
    std::fs::write(data.join("manifest.json"), manifest.to_string()).unwrap();

    let config = tiny_config(&dir, "no-lamp", &data, "exclude_families = [\"lamp\"]\n");
    let run = train(&config, &[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(
        stderr.contains("2 train images") && stderr.contains("1 val images"),
        "{stderr}"
    );
    let eval = train(
        &config,
        &["--evaluate", "val", "--evaluate-families", "lamp"],
    );
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    let stdout = String::from_utf8_lossy(&eval.stdout);
    assert!(stdout.contains("2 images of 24x24"), "{stdout}");
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("no-lamp-out").join("eval_val_lamp.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(report["families"], serde_json::json!(["lamp"]));
    assert_eq!(report["images"], 2);
    // Per image, each against its own best level; the pooled figure is their pixel-weighted
    // mean (equal sizes here: the plain mean).
    let per_image = report["per_image"].as_array().unwrap();
    assert_eq!(per_image.len(), 2);
    let mean = per_image
        .iter()
        .map(|e| e["relmse_output"].as_f64().unwrap())
        .sum::<f64>()
        / 2.0;
    let pooled = report["relmse_output"].as_f64().unwrap();
    assert!((mean - pooled).abs() <= 1e-9 * pooled, "{mean} vs {pooled}");
    for e in per_image {
        let ratio = e["relmse_output"].as_f64().unwrap() / e["best_level_relmse"].as_f64().unwrap();
        assert!((ratio - e["ratio_to_best_level"].as_f64().unwrap()).abs() < 1e-12);
        assert!(e["bundle"].as_str().unwrap().ends_with(".exr"));
    }

    // `--weights`: another run's config measures these weights (copied elsewhere) on the same
    // images alike, into its own output under a name that says whose weights they are.
    let mine = dir.join("mine");
    std::fs::create_dir_all(&mine).unwrap();
    for f in ["model.json", "model.bpk"] {
        std::fs::copy(dir.join("no-lamp-out").join(f), mine.join(f)).unwrap();
    }
    let other = tiny_config(&dir, "other", &data, "");
    let untrained = train(&other, &["--evaluate", "val"]);
    assert_eq!(untrained.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&untrained.stderr).contains("train first"));
    let weights = mine.to_string_lossy().into_owned();
    let eval = train(
        &other,
        &[
            "--evaluate",
            "val",
            "--evaluate-families",
            "lamp",
            "--weights",
            &weights,
        ],
    );
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    let theirs: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("other-out").join("eval_val_lamp_mine.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(theirs["weights"], serde_json::json!(weights));
    assert_eq!(theirs["relmse_output"], report["relmse_output"]);

    // A misspelt family is an error naming it and the dataset's families.
    let typo = tiny_config(&dir, "typo", &data, "families = [\"lmap\"]\n");
    let run = train(&typo, &[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("no family lmap") && stderr.contains("lamp, room"),
        "{stderr}"
    );
}

#[test]
fn validation_measures_against_converged_evaluation_references() {
    let (dir, data) = dir_with_data("evaluation-references");
    std::fs::create_dir_all(data.join("evaluation-references")).unwrap();
    let mut samples = Vec::new();
    let mut scenes = Vec::new();
    for (i, split) in ["train", "train", "val", "val"].into_iter().enumerate() {
        let (b, reference) = synthetic_bundle(24, 24, 0.3, i as u64 + 1);
        let name = format!("s{i}");
        bundle::write_bundle(&data.join(format!("{name}.exr")), &b).unwrap();
        bundle::write_rgb_exr_image(&data.join(format!("{name}_ref.exr")), &reference).unwrap();
        samples.push(serde_json::json!({
            "bundle": format!("{name}.exr"), "scene": name, "family": "room", "split": split,
            "seed": i, "seed_index": 0, "passes": 16, "photons": 1000,
            "reference": format!("{name}_ref.exr"), "sha256": ""
        }));
        let mut scene = serde_json::json!({
            "id": name, "family": "room", "split": split, "xml": "x.xml",
            "reference": format!("{name}_ref.exr"), "reference_sha256": "",
            "reference_seed": 1, "reference_passes": 16, "reference_photons": 1000
        });
        if split == "val" {
            let path = format!("evaluation-references/{name}.exr");
            // s2's evaluation reference exists, s3's file is missing: a bad sample naming it.
            if i == 2 {
                bundle::write_rgb_exr_image(&data.join(&path), &reference).unwrap();
            }
            scene["evaluation_reference"] = serde_json::json!({
                "path": path, "sha256": "", "passes": 256, "photons": 1000, "seeds": [7, 8],
                "noise": 1e-5, "input_relmse": 1e-2, "target": 0.1, "converged": true,
                "seconds": 1.0
            });
        }
        scenes.push(scene);
    }
    let write = |scenes: &serde_json::Value| {
        let manifest = serde_json::json!({
            "format": bundle::manifest::MANIFEST_FORMAT, "name": "test", "config_sha256": "",
            "width": 24, "height": 24, "reference_level": "y", "scenes": scenes,
            "samples": samples, "config": {}
        });
        std::fs::write(data.join("manifest.json"), manifest.to_string()).unwrap();
    };
    write(&serde_json::Value::from(scenes.clone()));
    let config = tiny_config(&dir, "conv", &data, "");
    let run = train(&config, &[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    // Training read its two training references; validation read the evaluation ones.
    assert!(
        stderr.contains("2 train images") && stderr.contains("1 val images"),
        "{stderr}"
    );
    assert!(stderr.contains("evaluation-references/s3.exr"), "{stderr}");
    // `--evaluate` reports the recorded noise of the references it measured against (the one
    // usable image's), beside the errors.
    let eval = train(&config, &["--evaluate", "val"]);
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    assert!(String::from_utf8_lossy(&eval.stdout).contains("reference noise     1.00000e-5"));
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("conv-out").join("eval_val.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(report["reference_noise"], serde_json::json!(1e-5));
    // With the training references named, both validation samples are read.
    let named = tiny_config(&dir, "named", &data, "references = \"references\"\n");
    std::fs::create_dir_all(data.join("references")).unwrap();
    for i in 0..4 {
        std::fs::copy(
            data.join(format!("s{i}_ref.exr")),
            data.join(format!("references/s{i}.exr")),
        )
        .unwrap();
    }
    let run = train(&named, &[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(stderr.contains("2 val images"), "{stderr}");
    // Their noise is not recorded: none reported.
    let eval = train(&named, &["--evaluate", "val"]);
    assert!(eval.status.success());
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("named-out").join("eval_val.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(report["reference_noise"], serde_json::Value::Null);
    // One validation scene with an evaluation reference, one without: refused, naming it.
    scenes[3]
        .as_object_mut()
        .unwrap()
        .remove("evaluation_reference");
    write(&serde_json::Value::from(scenes));
    let partial = tiny_config(&dir, "partial", &data, "");
    let run = train(&partial, &[]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("1 scene(s) of split `val` have a converged evaluation reference")
            && stderr.contains("(s3)"),
        "{stderr}"
    );
}
