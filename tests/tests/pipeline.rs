//! End to end, through the real binaries: a tiny procedural dataset (`datagen scenes` +
//! `datagen render` + `datagen check`), a short training run (`train --config`), then
//! reconstruction of a test bundle with the trained weights (`infer`), checking files, shapes
//! and finite values, a non-constant output, and that the relMSE report's numbers are those of
//! the bundle's levels and the output against the reference, the output below the worst level.

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
    // Not a constant image (e.g. all black): the reconstruction varies over the picture.
    let (lo, hi) = ours
        .data
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    assert!(
        hi > lo && hi > 0.0,
        "{}: constant output image (every value in [{lo}, {hi}])",
        output.display()
    );

    let report_path = dir.join("infer/ours_report.json");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    let levels: Vec<f64> = report["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(levels.len(), 5, "{}: {report}", report_path.display());
    // Each level's relMSE, recomputed from the bundle and the reference, is the report's (in
    // order: a report that scored other images or swapped levels fails).
    let reference_image = bundle::read_rgb_exr_image(&reference).unwrap();
    assert_eq!(reference_image.data.len(), ours.data.len());
    for (l, (level, reported)) in input.levels.iter().zip(&levels).enumerate() {
        let recomputed = relmse(&level.data, &reference_image.data);
        assert!(
            (recomputed - reported).abs() <= 1e-6 * recomputed.abs(),
            "{}: level {} relMSE {reported}, recomputed from {} and {}: {recomputed}",
            report_path.display(),
            bundle::LEVEL_NAMES[l],
            bundle_path.display(),
            reference.display()
        );
    }
    // So is the output's, from the written image.
    let output_relmse = report["output"].as_f64().unwrap();
    let recomputed = relmse(&ours.data, &reference_image.data);
    assert!(
        (recomputed - output_relmse).abs() <= 1e-6 * recomputed.abs(),
        "{}: output relMSE {output_relmse}, recomputed from {}: {recomputed}",
        report_path.display(),
        output.display()
    );
    // One epoch of the tiny network need not beat the best level, but it must beat the worst.
    let worst = levels.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    assert!(
        output_relmse.is_finite() && output_relmse < worst,
        "{}: output relMSE {output_relmse} is not below the worst input level's {worst}",
        report_path.display()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Relative MSE (docs/method.md §5.6) of interleaved RGB images: mean over pixels and channels of
/// (ŷ − y)² / (mean_c(y)² + 0.01), summed in f64 in pixel order like
/// `model::metrics::relmse_planar` (a dependency this crate does not have).
fn relmse(prediction: &[f32], reference: &[f32]) -> f64 {
    assert_eq!(prediction.len(), reference.len(), "image sizes differ");
    let mut sum = 0.0f64;
    for (p, y) in prediction.chunks_exact(3).zip(reference.chunks_exact(3)) {
        let mean = (y[0] as f64 + y[1] as f64 + y[2] as f64) / 3.0;
        let denominator = mean * mean + 0.01;
        for (&a, &b) in p.iter().zip(y) {
            let e = a as f64 - b as f64;
            sum += e * e / denominator;
        }
    }
    sum / reference.len().max(1) as f64
}
