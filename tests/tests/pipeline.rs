//! End to end, through the real binaries: a tiny procedural dataset (`datagen scenes` +
//! `datagen render` + `datagen check`), a short training run (`train --config`), then
//! reconstruction of a test bundle with the trained weights (`infer`), checking files, shapes
//! and finite values, and that the relMSE report covers every level.

use std::path::{Path, PathBuf};
use std::process::Command;

use e2e::{workspace_bin, workspace_root};

fn run(cmd: &mut Command) -> String {
    let out = cmd.output().expect("binary runs");
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{cmd:?} failed:\n{text}");
    text
}

fn temp_dir() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("e2e-pipeline-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn manifest(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn datagen_train_infer() {
    let dir = temp_dir();
    let data = dir.join("data");
    let config = workspace_root().join("configs/datagen/tiny.toml");
    let datagen = workspace_bin("datagen");
    run(Command::new(&datagen)
        .args(["scenes", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&data));
    run(Command::new(&datagen)
        .args(["render", "--quiet", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&data));
    run(Command::new(&datagen).arg("check").arg(&data));

    let m = manifest(&data);
    let samples = m["samples"].as_array().unwrap();
    assert!(!samples.is_empty());
    for split in ["train", "val", "test"] {
        assert!(
            samples.iter().any(|s| s["split"] == split),
            "tiny dataset has no `{split}` sample"
        );
    }

    let runs = dir.join("run");
    let train_config = dir.join("train.toml");
    std::fs::write(
        &train_config,
        format!(
            "dataset = {:?}\npreset = \"tiny\"\npatch = 16\nstride = 16\nbatch = 4\nepochs = 1\nseed = 1\noutput = {:?}\n",
            data, runs
        ),
    )
    .unwrap();
    run(Command::new(workspace_bin("train"))
        .arg("--config")
        .arg(&train_config));
    for file in [
        "model.json",
        "model.bpk",
        "model.safetensors",
        "metrics.csv",
    ] {
        assert!(runs.join(file).exists(), "train wrote no {file}");
    }

    let test_sample = samples
        .iter()
        .find(|s| s["split"] == "test")
        .expect("a test sample");
    let bundle_path = data.join(test_sample["bundle"].as_str().unwrap());
    let reference = data.join(test_sample["reference"].as_str().unwrap());
    let output = dir.join("infer/ours.exr");
    let text = run(Command::new(workspace_bin("infer"))
        .arg("--model")
        .arg(&runs)
        .arg("--input")
        .arg(&bundle_path)
        .arg("--reference")
        .arg(&reference)
        .arg("--output")
        .arg(&output)
        .args(["--png", "--tile", "12"]));
    assert!(text.contains("output"), "no report printed:\n{text}");

    let input = bundle::read_bundle(&bundle_path).unwrap();
    let ours = bundle::read_rgb_exr_image(&output).unwrap();
    assert_eq!(
        (ours.width, ours.height, ours.channels),
        (input.meta.width as usize, input.meta.height as usize, 3)
    );
    assert!(ours.data.iter().all(|v| v.is_finite()), "non-finite output");
    for png in ["ours.png", "ours_compare.png", "ours_weights.png"] {
        let p = dir.join("infer").join(png);
        assert!(
            std::fs::metadata(&p).map(|m| m.len() > 0).unwrap_or(false),
            "{png} missing"
        );
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("infer/ours_report.json")).unwrap())
            .unwrap();
    assert_eq!(report["levels"].as_array().unwrap().len(), 5);
    assert!(report["output"].as_f64().unwrap().is_finite());
    let _ = std::fs::remove_dir_all(&dir);
}
