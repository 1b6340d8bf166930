//! `bundle_info` through its real binary: it describes itself in `--help`, prints a bundle's
//! metadata, writes one PNG per layer (into a folder it makes), takes a negative exposure,
//! refuses an exposure without `--png`, writes one level as an RGB EXR (`--exr`), and ends with
//! an error instead of a panic on a missing file or an unwritable standard output.

use std::path::PathBuf;
use std::process::{Command, Output};

use bundle::{write_bundle, Bundle, BundleMeta, Image};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bundle-info-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bundle_info"))
        .args(args)
        .output()
        .expect("bundle_info runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A 6×4 bundle of `passes` passes with a gradient in every layer.
fn write_sample(path: &std::path::Path, passes: u32) {
    let (w, h) = (6, 4);
    let fill = |channels: usize, scale: f32| {
        let mut img = Image::new(w, h, channels);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = scale * i as f32 / (w * h * channels) as f32;
        }
        img
    };
    let b = Bundle {
        meta: BundleMeta {
            scene: "gradient".into(),
            seed: 1,
            passes,
            photons_per_pass: 1000,
            seconds: 0.5,
            integrator: "sppm-ml".into(),
            schedule: bundle::DEFAULT_SCHEDULE.into(),
            emitter_samples: 1,
            sharp_level: "a".into(),
            sampler: "independent".into(),
            width: w as u32,
            height: h as u32,
        },
        levels: (0..5).map(|l| fill(3, 1.0 + l as f32)).collect(),
        variance: fill(5, 0.1),
        albedo: fill(3, 1.0),
        normal: fill(3, 1.0),
        depth: fill(1, 3.0),
        radius: None,
        direct: None,
    };
    write_bundle(path, &b).unwrap();
}

#[test]
fn describes_itself_in_its_help() {
    let out = run(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let first = text.lines().next().unwrap_or_default();
    assert!(
        first.contains("Inspect a multi-level SPPM sample bundle"),
        "first help line {first:?}"
    );
    assert!(text.contains("Usage:"), "{text}");
}

#[test]
fn prints_the_metadata_and_writes_a_png_per_layer() {
    let dir = temp_dir("outputs");
    for passes in [1, 3] {
        let bundle = dir.join(format!("ml_p{passes:04}.exr"));
        write_sample(&bundle, passes);
        let pngs = dir.join(format!("levels{passes}"));
        let out = run(&[bundle.to_str().unwrap(), "--png", pngs.to_str().unwrap()]);
        assert!(out.status.success(), "{}", stderr(&out));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains(&format!("\"passes\": {passes}")), "{text}");
        for layer in ["y", "z1", "z2", "z3", "z4", "albedo", "normal", "depth"] {
            let png = dir.join(format!("levels{passes}_{layer}.png"));
            let img = image::open(&png).unwrap_or_else(|e| panic!("{}: {e}", png.display()));
            assert_eq!((img.width(), img.height()), (6, 4), "{layer}");
        }
    }
    // An exposure is for the PNGs: a negative one is a value, and without --png it is refused.
    let bundle = dir.join("ml_p0003.exr");
    let darker = dir.join("new/folder/darker");
    let out = run(&[
        bundle.to_str().unwrap(),
        "--exposure",
        "-2",
        "--png",
        darker.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    // (into a folder made for it)
    assert!(dir.join("new/folder/darker_y.png").exists());
    let out = run(&[bundle.to_str().unwrap(), "--exposure", "1"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--png"), "{}", stderr(&out));
    // Standard output that cannot be written (a full disk) is an error, not a panic.
    if let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") {
        let out = Command::new(env!("CARGO_BIN_EXE_bundle_info"))
            .arg(&bundle)
            .stdout(full)
            .output()
            .unwrap();
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(
            err.contains("failed printing to stdout") && !err.contains("panicked"),
            "{err}"
        );
    }
    // A missing bundle is an error naming it.
    let missing = run(&[dir.join("none.exr").to_str().unwrap()]);
    assert_ne!(missing.status.code(), Some(0));
    assert!(
        stderr(&missing).contains("none.exr"),
        "{}",
        stderr(&missing)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn writes_one_level_as_a_plain_rgb_exr() {
    let dir = temp_dir("exr");
    let bundle = dir.join("ml_p0002.exr");
    write_sample(&bundle, 2);
    let file = dir.join("made/z3.exr");
    let out = run(&[
        bundle.to_str().unwrap(),
        "--exr",
        "z3",
        file.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let level = bundle::read_bundle(&bundle).unwrap().levels[3].clone();
    assert_eq!(bundle::read_rgb_exr_image(&file).unwrap(), level);
    // A level that does not exist is refused by name, before anything is written.
    let other = dir.join("other.exr");
    let out = run(&[
        bundle.to_str().unwrap(),
        "--exr",
        "z5",
        other.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("z5"), "{}", stderr(&out));
    assert!(!other.exists());
    let _ = std::fs::remove_dir_all(&dir);
}
