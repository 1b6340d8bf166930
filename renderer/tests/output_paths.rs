//! `render`'s output paths through the real binary: an output named as another kind of image,
//! an output and a preview that are one file, and an output that is a directory are refused
//! before the scene is even loaded; missing folders are created before rendering; an SPPM
//! prefix `b.exr` gives `b_p0001.exr`; `--output` is `--out`; a missing scene is named once.

use std::path::{Path, PathBuf};
use std::process::Output;

/// A scratch directory unique to this test process and test name.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("renderer-outpaths-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs `render` with `args` (paths as given) and returns its output, whatever the status.
fn render(args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_render"))
        .args(args)
        .output()
        .expect("render runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A tiny scene (16×16 by default): a diffuse floor under an area light.
fn write_scene(dir: &Path) -> PathBuf {
    let path = dir.join("scene.xml");
    std::fs::write(&path, include_str!("fixtures/lit-floor.xml")).unwrap();
    path
}

/// The files in `dir`, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Asserts that `args` fail with exit status 1 and an error containing every one of `needles`.
fn fails_naming(args: &[&str], needles: &[&str]) -> String {
    let out = render(args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    for needle in needles {
        assert!(err.contains(needle), "{args:?}: no {needle:?} in {err}");
    }
    err
}

#[test]
fn wrong_extensions_and_clashing_outputs_are_refused_before_loading_the_scene() {
    let dir = temp_dir("clash");
    let scene = write_scene(&dir);
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let (q_png, q2_exr, b) = (p("q.png"), p("q2.exr"), p("b"));
    let via_missing = p("sub/../q2.exr");
    let (b1, q2_jpg) = (p("b_p0001.exr"), p("q2.jpg"));
    let missing_scene = dir.join("missing.xml");
    // (arguments after the scene, what the error must name)
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        // The path tracer's EXR named .png.
        (vec!["--out", &q_png], vec!["--out", "q.png", ".exr"]),
        (
            vec!["--out", &q2_exr, "--png", &q2_jpg],
            vec!["--png", "q2.jpg", ".png"],
        ),
        // The output and the preview are one file, however spelt.
        (
            vec!["--out", &q2_exr, "--png", &q2_exr],
            vec!["--out", "--png", "q2.exr", "same file"],
        ),
        (
            vec!["--out", &q2_exr, "--png", &via_missing],
            vec!["same file"],
        ),
        // SPPM: the preview is one of the bundles.
        (
            vec![
                "--integrator",
                "sppm-ml",
                "--passes",
                "1",
                "--out",
                &b,
                "--png",
                &b1,
            ],
            vec![
                "--png",
                "b_p0001.exr",
                "pass-1 bundle of --out",
                "same file",
            ],
        ),
        // SPPM: a prefix naming a PNG.
        (
            vec!["--integrator", "sppm", "--passes", "1", "--out", &q_png],
            vec!["--out", "q.png", "EXR bundles"],
        ),
    ];
    for (args, needles) in &cases {
        // With a scene that does not exist: the outputs are checked first.
        let mut missing = vec![s(&missing_scene)];
        missing.extend(args);
        let err = fails_naming(&missing, needles);
        assert!(!err.contains("missing.xml"), "{missing:?}: {err}");
        // With the real scene: nothing is written.
        let mut real = vec![s(&scene), "--spp", "1", "--threads", "1"];
        if args.contains(&"--integrator") {
            real = vec![s(&scene), "--photons", "1000", "--threads", "1"];
        }
        real.extend(args);
        fails_naming(&real, needles);
        assert_eq!(listing(&dir), ["scene.xml"], "{real:?}");
    }
    // The scene file is not an output either.
    fails_naming(
        &[
            s(&scene),
            "--spp",
            "1",
            "--out",
            s(&dir.join("x.exr")),
            "--png",
            s(&scene),
        ],
        &["--png", "the scene", "same file"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_output_folders_are_created_and_a_directory_output_is_refused() {
    let dir = temp_dir("folders");
    let scene = write_scene(&dir);
    let scene = s(&scene);
    let (exr, png) = (dir.join("nodir/a.exr"), dir.join("nodir2/deeper/a.png"));
    let out = render(&[
        scene,
        "--spp",
        "1",
        "--threads",
        "1",
        "--out",
        s(&exr),
        "--png",
        s(&png),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(exr.is_file() && png.is_file());
    // SPPM, by passes and by time only.
    for (sub, stop) in [
        ("nodir3", ["--passes", "1"]),
        ("nodir4", ["--time", "0.01"]),
    ] {
        let prefix = dir.join(sub).join("b");
        let mut args = vec![
            scene,
            "--integrator",
            "sppm-ml",
            "--photons",
            "1000",
            "--threads",
            "1",
            "--out",
            s(&prefix),
        ];
        args.extend(stop);
        let out = render(&args);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        let written = listing(&dir.join(sub));
        assert!(
            written.len() == 1 && written[0].starts_with("b_p") && written[0].ends_with(".exr"),
            "{written:?}"
        );
    }
    // An output that is a directory: refused before the scene is read.
    let folder = dir.join("folder");
    std::fs::create_dir(&folder).unwrap();
    let missing = dir.join("missing.xml");
    fails_naming(
        &[s(&missing), "--out", s(&folder)],
        &[&format!("--out {} is a directory", folder.display())],
    );
    fails_naming(
        &[
            s(&missing),
            "--out",
            s(&dir.join("c.exr")),
            "--png",
            s(&folder),
        ],
        &[&format!("--png {} is a directory", folder.display())],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_sppm_prefix_ending_in_exr_loses_it_and_other_prefixes_are_kept() {
    let dir = temp_dir("prefix");
    let scene = write_scene(&dir);
    for (prefix, bundles) in [
        ("b.exr", ["b_p0001.exr", "b_p0002.exr"]),
        ("c.v2", ["c.v2_p0001.exr", "c.v2_p0002.exr"]),
        ("d", ["d_p0001.exr", "d_p0002.exr"]),
    ] {
        let out = render(&[
            s(&scene),
            "--integrator",
            "sppm",
            "--photons",
            "1000",
            "--threads",
            "1",
            "--passes",
            "1,2",
            "--out",
            s(&dir.join(prefix)),
        ]);
        assert!(out.status.success(), "{prefix}: {}", stderr(&out));
        for bundle in bundles {
            assert!(dir.join(bundle).is_file(), "{prefix}: {:?}", listing(&dir));
        }
    }
    assert!(!dir.join("b.exr_p0001.exr").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn output_is_an_alias_of_out_and_a_missing_scene_is_named_once() {
    let dir = temp_dir("alias");
    let scene = write_scene(&dir);
    let exr = dir.join("alias.exr");
    let out = render(&[
        s(&scene),
        "--spp",
        "1",
        "--threads",
        "1",
        "--output",
        s(&exr),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(exr.is_file());
    let help = render(&["--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("--output"), "{help}");

    let err = fails_naming(&["nope.xml", "--out", s(&dir.join("n.exr"))], &["nope.xml"]);
    assert_eq!(err.matches("nope.xml").count(), 1, "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
