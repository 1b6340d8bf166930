//! `infer`'s command line and output paths through the real binary: an output named as another
//! image or clashing with an input is refused, an output that is a directory is refused before
//! the model is loaded, missing folders are created, `--scene`'s default output is named after
//! the scene file (its folder for `scene.xml`), neither `--input` nor `--scene` names both,
//! `--out` is `--output`, `--help` lists the backends, and a missing scene is named once.

use std::path::{Path, PathBuf};
use std::process::Output;

use burn::tensor::Device;
use model::weights::save_burnpack;
use model::{ModelConfig, Preset, Weighting};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("infer-outpaths-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes a model directory (`model.json` + `model.bpk`) of a random tiny network into `dir`.
fn write_tiny_model(dir: &Path) {
    let mut config = ModelConfig::preset(Preset::Tiny);
    config.weighting = Weighting::Relu;
    let network = config.init(5, &Device::flex());
    save_burnpack(&network, &dir.join("model.bpk")).unwrap();
    std::fs::write(
        dir.join("model.json"),
        serde_json::to_string(&config).unwrap(),
    )
    .unwrap();
}

/// Writes a small synthetic bundle to `dir/b.exr`.
fn write_bundle(dir: &Path) -> PathBuf {
    let (bundle, _) = model::synthetic::synthetic_bundle(12, 10, 0.1, 3);
    let path = dir.join("b.exr");
    bundle::write_bundle(&path, &bundle).unwrap();
    path
}

/// Runs `infer` in `cwd` with `args` and returns its output, whatever the status.
fn infer(cwd: &Path, args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_infer"))
        .current_dir(cwd)
        .args(args)
        .output()
        .expect("infer runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// Asserts that `args` fail with exit status `code` and an error containing every `needle`.
fn fails_naming(cwd: &Path, args: &[&str], code: i32, needles: &[&str]) -> String {
    let out = infer(cwd, args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(code), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    for needle in needles {
        assert!(err.contains(needle), "{args:?}: no {needle:?} in {err}");
    }
    err
}

/// A tiny scene (16×16): a diffuse floor under an area light (shared with `render`'s tests).
const SCENE: &str = include_str!("../../renderer/tests/fixtures/lit-floor.xml");

#[test]
fn outputs_named_as_another_image_or_clashing_with_an_input_are_refused() {
    let dir = temp_dir("clash");
    write_tiny_model(&dir);
    let bundle = write_bundle(&dir);
    let before = std::fs::read(&bundle).unwrap();
    let model = s(&dir);
    let cases: [(&[&str], &[&str]); 3] = [
        // An EXR named .png, whose PNG preview would then overwrite it.
        (
            &["--output", "z.png", "--png"],
            &["--output z.png", "OpenEXR", ".exr"],
        ),
        // The output is the bundle read.
        (
            &["--output", "./b.exr"],
            &["--output", "--input", "same file"],
        ),
        // The output is the reference read.
        (
            &["--output", "r.exr", "--reference", "r.exr"],
            &["--output", "--reference", "same file"],
        ),
    ];
    for (args, needles) in cases {
        let mut all = vec!["--model", model, "--input", "b.exr"];
        all.extend(args);
        fails_naming(&dir, &all, 1, needles);
        assert!(!dir.join("z.png").exists() && !dir.join("r.exr").exists());
        assert_eq!(std::fs::read(&bundle).unwrap(), before, "{all:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_directory_output_is_refused_before_any_work_and_missing_folders_are_created() {
    let dir = temp_dir("folders");
    write_tiny_model(&dir);
    write_bundle(&dir);
    std::fs::create_dir(dir.join("out")).unwrap();
    // Refused before the (missing) model or scene is looked at.
    for source in [["--input", "b.exr"], ["--scene", "missing.xml"]] {
        let mut args = vec!["--model", "no-model", "--output", "out"];
        args.extend(source);
        let err = fails_naming(&dir, &args, 1, &["--output out is a directory"]);
        assert!(
            !err.contains("no-model") && !err.contains("missing.xml"),
            "{err}"
        );
    }
    // `--out` is `--output`; missing folders are created.
    let out = infer(
        &dir,
        &[
            "--model",
            s(&dir),
            "--input",
            "b.exr",
            "--out",
            "new/deeper/o.exr",
            "--png",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    for name in ["o.exr", "o.png", "o_compare.png", "o_weights.png"] {
        assert!(dir.join("new/deeper").join(name).is_file(), "{name}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_default_output_is_named_after_the_scene_file() {
    let dir = temp_dir("default-name");
    write_tiny_model(&dir);
    std::fs::create_dir(dir.join("sc")).unwrap();
    for name in ["volpath.xml", "direct.xml", "scene.xml"] {
        std::fs::write(dir.join("sc").join(name), SCENE).unwrap();
    }
    for (scene, output) in [
        ("sc/volpath.xml", "out/volpath/ours.exr"),
        ("sc/direct.xml", "out/direct/ours.exr"),
        ("sc/scene.xml", "out/sc/ours.exr"),
    ] {
        let out = infer(
            &dir,
            &[
                "--model",
                s(&dir),
                "--scene",
                scene,
                "--passes",
                "1",
                "--photons",
                "1000",
                "--threads",
                "1",
            ],
        );
        assert!(out.status.success(), "{scene}: {}", stderr(&out));
        assert!(dir.join(output).is_file(), "{scene}: no {output}");
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(stdout.contains(output), "{stdout}");
        // The bundle it rendered is listed with the other files written.
        let bundle = output.replace("ours.exr", "ours_bundle.exr");
        assert!(
            stdout.contains(&bundle) && dir.join(&bundle).is_file(),
            "{stdout}"
        );
    }
    // A missing scene is named once.
    let err = fails_naming(
        &dir,
        &["--model", s(&dir), "--scene", "nope.xml", "--passes", "1"],
        1,
        &["nope.xml"],
    );
    assert_eq!(err.matches("nope.xml").count(), 1, "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn usage_names_input_or_scene_and_help_lists_the_backends() {
    let dir = temp_dir("usage");
    fails_naming(
        &dir,
        &["--output", "o.exr"],
        2,
        &["one of --input <bundle.exr> or --scene <scene.xml> is required"],
    );
    fails_naming(
        &dir,
        &[],
        2,
        &["--input <bundle.exr>", "--scene <scene.xml>"],
    );
    fails_naming(
        &dir,
        &["--input", "b.exr"],
        2,
        &["--output <out.exr> is required with --input"],
    );
    fails_naming(
        &dir,
        &["--input", "b.exr", "--output", "o.exr", "--backend", "cuda"],
        2,
        &["cuda", "flex", "ndarray", "wgpu"],
    );
    let help = infer(&dir, &["--help"]);
    assert!(help.status.success());
    let help = String::from_utf8_lossy(&help.stdout);
    for needle in [
        "--out",
        "--output",
        "--scene <scene.xml>",
        "flex",
        "ndarray",
        "wgpu",
    ] {
        assert!(help.contains(needle), "no {needle} in {help}");
    }
    assert!(
        help.contains("[possible values: flex, ndarray, wgpu]") || help.contains("- ndarray"),
        "{help}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--lenient` reaches the render (an unsupported plugin becomes a warning) and `--max-depth`
/// bounds it: a depth-1 render of a Cornell box loses the light that bounces between its walls.
#[test]
fn lenient_and_max_depth_reach_the_render() {
    let dir = temp_dir("lenient");
    write_tiny_model(&dir);
    let scene = SCENE.replace("</scene>", "<shape type=\"nonsense\"/>\n</scene>");
    std::fs::write(dir.join("odd.xml"), scene).unwrap();
    let base = [
        "--model",
        s(&dir),
        "--scene",
        "odd.xml",
        "--passes",
        "1",
        "--photons",
        "1000",
    ];
    let err = fails_naming(&dir, &base, 1, &["nonsense"]);
    assert!(err.contains("odd.xml"), "{err}");
    let mut lenient = base.to_vec();
    lenient.push("--lenient");
    let out = infer(&dir, &lenient);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("warning"), "{}", stderr(&out));

    let cbox = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes/validation/cornell-diffuse/scene.xml");
    let mean_of = |output: &str, extra: &[&str]| {
        let mut args = vec![
            "--model",
            s(&dir),
            "--scene",
            s(&cbox),
            "-D",
            "res=16",
            "--passes",
            "2",
            "--photons",
            "4000",
            "--output",
            output,
        ];
        args.extend_from_slice(extra);
        let out = infer(&dir, &args);
        assert!(out.status.success(), "{}", stderr(&out));
        let b = bundle::read_bundle(&dir.join(output.replace(".exr", "_bundle.exr"))).unwrap();
        b.levels[4].data.iter().map(|v| f64::from(*v)).sum::<f64>()
    };
    let deep = mean_of("deep.exr", &[]);
    let shallow = mean_of("shallow.exr", &["--max-depth", "1"]);
    assert!(shallow < 0.9 * deep, "depth 1: {shallow}, default: {deep}");
    let _ = std::fs::remove_dir_all(&dir);
}
