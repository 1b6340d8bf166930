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
            "bundle": bundle_rel, "scene": name, "split": split, "reference": reference_rel
        }));
    };
    add("good0", "train", 1, "");
    add("good1", "train", 2, "");
    add("val0", "val", 3, "");
    add("nan", "train", 4, "nan");
    add("noref", "train", 5, "missing");
    add("badsize", "train", 6, "size");
    let manifest = serde_json::json!({ "format": "test", "samples": samples });
    std::fs::write(root.join("manifest.json"), manifest.to_string()).unwrap();
}

#[test]
fn trains_reports_bad_data_and_resumes() {
    let dir = temp_dir("run");
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
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
    let run = |resume: bool| train(&config, if resume { &["--resume"] } else { &[] });
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
    let write_tune = |preset: &str| {
        std::fs::write(
            &tune_config,
            format!(
                "dataset = {:?}\npreset = \"{preset}\"\npatch = 16\nstride = 8\nbatch = 4\nepochs = 1\nseed = 3\nlr = 1e-3\nlr_end = 1e-5\ninit = {:?}\noutput = {:?}\n",
                data, out, tuned
            ),
        )
        .unwrap();
    };
    write_tune("tiny");
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
    write_tune("small");
    let mismatch = train(&tune_config, &[]);
    assert!(!mismatch.status.success());
    let stderr = String::from_utf8_lossy(&mismatch.stderr);
    assert!(stderr.contains("architecture"), "{stderr}");

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

    // Unknown keys are rejected with the file name.
    std::fs::write(&config, "dataset = \"x\"\npreset = \"tiny\"\npatch = 16\nstride = 8\nbatch = 4\nepochs = 1\nseed = 3\noutput = \"o\"\nlearning_rate = 1\n").unwrap();
    let bad = run(false);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("learning_rate"));
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
