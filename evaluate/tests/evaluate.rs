//! The `evaluate` binary end to end on a 16×16 open box lit by an area light, with a randomly
//! initialised tiny model: explicit scenes and a dataset split, every output file written,
//! finite numbers, every scene on the HTML page; bad configs fail naming the file.

use std::path::{Path, PathBuf};
use std::process::Command;

use burn::tensor::Device;
use model::weights::save_burnpack;
use model::{ModelConfig, Preset};
use renderer::integrators::sppm::{render_sppm, SppmMode, SppmSettings, StopCondition};

/// A diffuse box open towards the camera (a small Cornell box) with an area light under the
/// ceiling; its film is `$res` square, 24 by default, rendered here at 16 (`-D res=16`, the
/// `defines` of the configs and manifests below).
const BOX_XML: &str = r#"<scene version="3.0.0">
    <default name="res" value="24"/>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world">
            <lookat origin="0, 0, 3.9" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <film type="hdrfilm">
            <integer name="width" value="$res"/>
            <integer name="height" value="$res"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <bsdf type="diffuse" id="white">
        <rgb name="reflectance" value="0.7, 0.7, 0.7"/>
    </bsdf>
    <bsdf type="diffuse" id="red">
        <rgb name="reflectance" value="0.7, 0.1, 0.1"/>
    </bsdf>
    <shape type="rectangle">
        <transform name="to_world">
            <scale x="0.25" y="0.25" z="0.25"/>
            <rotate x="1" angle="90"/>
            <translate y="0.99"/>
        </transform>
        <ref id="white"/>
        <emitter type="area">
            <rgb name="radiance" value="15, 15, 15"/>
        </emitter>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/><translate y="-1"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="90"/><translate y="1"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><translate z="-1"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate y="1" angle="-90"/><translate x="1"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate y="1" angle="90"/><translate x="-1"/></transform>
        <ref id="red"/>
    </shape>
</scene>
"#;

/// A manifest scene entry: `id` of `split` read from `xml`, its reference `<id>.exr`.
fn manifest_scene(id: &str, split: &str, xml: &str) -> serde_json::Value {
    serde_json::json!({
        "id": id, "family": "external", "split": split, "xml": xml,
        "reference": format!("{id}.exr"), "reference_sha256": "", "reference_seed": 1,
        "reference_passes": 64, "reference_photons": 1000
    })
}

/// A dataset manifest (`bundle::manifest`) of 16×16 `scenes` and no samples.
fn dataset_manifest(scenes: Vec<serde_json::Value>) -> serde_json::Value {
    serde_json::json!({
        "format": bundle::manifest::MANIFEST_FORMAT, "name": "test", "config_sha256": "",
        "width": 16, "height": 16, "reference_level": "y", "scenes": scenes, "samples": [],
        "config": {}
    })
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("evaluate-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes the box scene to `dir/scene.xml` and a 48-pass reference to `dir/reference.exr`.
fn box_scene(dir: &Path) -> (PathBuf, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let xml = dir.join("scene.xml");
    std::fs::write(&xml, BOX_XML).unwrap();
    let at_16 = [("res".to_string(), "16".to_string())];
    let desc = renderer::xml::load_scene(&xml, &at_16, false).unwrap();
    let scene = renderer::scene::Scene::build(&desc).unwrap();
    let settings = SppmSettings {
        photons_per_pass: 4000,
        seed: 99,
        mode: SppmMode::MultiLevel,
        ..SppmSettings::default()
    };
    let stop = StopCondition {
        checkpoints: vec![48],
        seconds: None,
    };
    let mut reference = None;
    render_sppm(
        &scene,
        &settings,
        &stop,
        |b| {
            reference = Some(b.levels[0].clone());
            Ok(())
        },
        |_| {},
    )
    .unwrap();
    let path = dir.join("reference.exr");
    bundle::write_rgb_exr_image(&path, &reference.unwrap()).unwrap();
    (xml, path)
}

/// A randomly initialised tiny model directory.
fn tiny_model(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let config = ModelConfig::preset(Preset::Tiny);
    let network = config.init(3, &Device::flex());
    save_burnpack(&network, &dir.join("model.bpk")).unwrap();
    std::fs::write(
        dir.join("model.json"),
        serde_json::to_string(&config).unwrap(),
    )
    .unwrap();
}

fn toml_path(p: &Path) -> String {
    format!("{:?}", p.display().to_string())
}

fn evaluate(config: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_evaluate"))
        .arg("--config")
        .arg(config)
        .output()
        .unwrap()
}

fn finite(v: &serde_json::Value, what: &str) -> f64 {
    let x = v
        .as_f64()
        .unwrap_or_else(|| panic!("{what} is not a number: {v}"));
    assert!(x.is_finite(), "{what} = {x}");
    x
}

#[test]
fn evaluates_explicit_and_dataset_scenes() {
    let dir = temp_dir("run");
    let (xml, reference) = box_scene(&dir.join("box"));
    tiny_model(&dir.join("model"));
    // A two-scene dataset: only the test scene must be evaluated.
    let data = dir.join("data");
    for id in ["000-box", "001-box"] {
        std::fs::create_dir_all(data.join("scenes").join(id)).unwrap();
        std::fs::copy(&xml, data.join("scenes").join(id).join("scene.xml")).unwrap();
    }
    std::fs::create_dir_all(data.join("references")).unwrap();
    std::fs::copy(&reference, data.join("references/000-box.exr")).unwrap();
    std::fs::copy(&reference, data.join("references/001-box.exr")).unwrap();
    let scene = |id: &str, split: &str| {
        let mut s = manifest_scene(id, split, &format!("scenes/{id}/scene.xml"));
        s["reference"] = format!("references/{id}.exr").into();
        s["defines"] = serde_json::json!({"res": "16"});
        s
    };
    let manifest = dataset_manifest(vec![scene("000-box", "train"), scene("001-box", "test")]);
    std::fs::write(data.join("manifest.json"), manifest.to_string()).unwrap();

    let out = dir.join("out");
    let config = dir.join("eval.toml");
    std::fs::write(
        &config,
        format!(
            "model = {}\noutput = {}\nphotons_per_pass = 2000\npasses = [4, 2, 4]\nseed = 5\n\
             tile = 8\nthreads = 1\n\n[[scenes]]\nname = \"explicit-box\"\nxml = {}\n\
             reference = {}\ndefines = {{ res = \"16\" }}\n\n[dataset]\ndir = {}\n\
             split = \"test\"\n",
            toml_path(&dir.join("model")),
            toml_path(&out),
            toml_path(&xml),
            toml_path(&reference),
            toml_path(&data)
        ),
    )
    .unwrap();
    let run = evaluate(&config);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "evaluate failed:\n{stderr}");

    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let scenes = results["scenes"].as_array().unwrap();
    let names: Vec<&str> = scenes.iter().map(|s| s["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["explicit-box", "001-box"]);
    // The checkpoints as run: sorted, each once (the config lists 4, 2, 4).
    assert_eq!(results["config"]["passes"], serde_json::json!([2, 4]));
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    for s in scenes {
        let name = s["name"].as_str().unwrap();
        assert!(s["error"].is_null(), "{name}: {}", s["error"]);
        assert!(html.contains(name), "the page does not mention {name}");
        for key in ["plot", "comparison", "inputs"] {
            let file = out.join(s[key].as_str().unwrap());
            let bytes = std::fs::read(&file).unwrap();
            assert!(
                bytes.starts_with(b"\x89PNG"),
                "{} is not a PNG",
                file.display()
            );
        }
        let eval = &s["eval"];
        let checkpoints = eval["checkpoints"].as_array().unwrap();
        let passes: Vec<u64> = checkpoints
            .iter()
            .map(|c| c["passes"].as_u64().unwrap())
            .collect();
        assert_eq!(passes, [2, 4]);
        for c in checkpoints {
            let render = finite(&c["render_seconds"], "render_seconds");
            let inference = finite(&c["inference_seconds"], "inference_seconds");
            let total = finite(&c["total_seconds"], "total_seconds");
            assert!(render > 0.0 && inference > 0.0);
            assert!((total - render - inference).abs() < 1e-9);
            assert!(finite(&c["ours_relmse"], "ours_relmse") >= 0.0);
            let levels = c["level_relmse"].as_array().unwrap();
            assert_eq!(levels.len(), 5);
            for l in levels {
                assert!(finite(l, "level relMSE") > 0.0);
            }
            let std_eq = finite(
                &c["standard_equal_time"]["relmse"],
                "standard at equal time",
            );
            assert!(std_eq > 0.0);
            finite(&c["ratio_equal_time"], "ratio");
            // The standard run carries on past ours' total time, so a point is never
            // extrapolated beyond its end; it may be before its start, and only there, when
            // ours finished before standard SPPM's first pass did (timing on a loaded machine).
            let first_standard = finite(&eval["standard"][0]["seconds"], "standard seconds");
            if c["standard_equal_time"]["extrapolated"] == true {
                assert!(
                    total < first_standard,
                    "{total} s: extrapolated past the end"
                );
            }
            finite(&c["standard_equal_passes"], "standard at equal passes");
            finite(&c["overhead"], "overhead");
        }
        // Standard SPPM's curve: sorted by passes and time, and it reaches ours' last total.
        let curve = eval["standard"].as_array().unwrap();
        let times: Vec<f64> = curve
            .iter()
            .map(|p| finite(&p["seconds"], "standard seconds"))
            .collect();
        assert!(times.windows(2).all(|w| w[0] <= w[1]), "{times:?}");
        let last_total = finite(&checkpoints[1]["total_seconds"], "total");
        assert!(*times.last().unwrap() >= last_total);
    }
    assert!(html.contains("data:image/png;base64,"));
    // Footnotes only for marks the page carries: nothing reused in a first run, and the
    // extrapolation note only when a checkpoint was extrapolated.
    assert!(!html.contains("† taken from"));
    let extrapolated = scenes.iter().any(|s| {
        s["eval"]["checkpoints"]
            .as_array()
            .unwrap()
            .iter()
            .any(|c| c["standard_equal_time"]["extrapolated"] == true)
    });
    assert_eq!(html.contains("did not reach that time"), extrapolated);
    assert!(html.contains("dual-vs-multi"));
    let summary = &results["summary"];
    assert_eq!(summary["scenes"], 2);
    assert_eq!(summary["failed"], 0);
    assert_eq!(summary["passes"], 4);

    // `--combine` reads the finished evaluation back: the same scenes and aggregates.
    let combined_json = dir.join("combined.json");
    let combined = Command::new(env!("CARGO_BIN_EXE_evaluate"))
        .arg("--combine")
        .arg(&out)
        .arg("--output")
        .arg(&combined_json)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&combined.stdout);
    assert!(
        combined.status.success(),
        "{}",
        String::from_utf8_lossy(&combined.stderr)
    );
    assert!(
        stdout.contains("| explicit-box |") && stdout.contains("| 001-box |"),
        "{stdout}"
    );
    assert!(stdout.contains("At 4 passes"), "{stdout}");
    let back: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&combined_json).unwrap()).unwrap();
    assert_eq!(back["summary"], results["summary"]);
    // Evaluating and combining at once is refused by the argument parser.
    let both = Command::new(env!("CARGO_BIN_EXE_evaluate"))
        .arg("--config")
        .arg(&config)
        .arg("--combine")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(both.status.code(), Some(2));

    // `--resume` takes every finished scene from `out/scenes/`, with the same numbers.
    let resume = |config: &Path| {
        Command::new(env!("CARGO_BIN_EXE_evaluate"))
            .arg("--config")
            .arg(config)
            .arg("--resume")
            .output()
            .unwrap()
    };
    // One field of every scene of `out/results.json`.
    let field_of_scenes = |out: &Path, field: &str| -> Vec<serde_json::Value> {
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap())
                .unwrap();
        r["scenes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s[field].clone())
            .collect()
    };
    let evals = |out: &Path| field_of_scenes(out, "eval");
    let first = evals(&out);
    let again = resume(&config);
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{stderr}");
    assert_eq!(stderr.matches("taken from").count(), 2, "{stderr}");
    assert_eq!(evals(&out), first);
    // The report says which scenes were taken from the earlier run (their timings are its).
    let reused = |out: &Path| -> Vec<bool> {
        field_of_scenes(out, "reused")
            .iter()
            .map(|v| *v == true)
            .collect()
    };
    assert_eq!(reused(&out), [true, true]);
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(
        html.contains("† taken from an earlier run"),
        "no resume footnote"
    );
    // A changed reference makes its scene evaluated again; the other is still taken.
    let mut changed = bundle::read_rgb_exr_image(&data.join("references/001-box.exr")).unwrap();
    changed.data[0] += 0.5;
    bundle::write_rgb_exr_image(&data.join("references/001-box.exr"), &changed).unwrap();
    let partly = resume(&config);
    let stderr = String::from_utf8_lossy(&partly.stderr);
    assert!(partly.status.success(), "{stderr}");
    assert_eq!(stderr.matches("taken from").count(), 1, "{stderr}");
    assert!(stderr.contains("reference changed"), "{stderr}");
    let now = evals(&out);
    assert_eq!(now[0], first[0]);
    assert_ne!(now[1], first[1]);
    assert_eq!(reused(&out), [true, false]);
    // A damaged per-scene file is an error naming it, not silently replaced.
    let saved = out.join("scenes/explicit-box.json");
    std::fs::write(&saved, "{ not json").unwrap();
    let damaged = resume(&config);
    let stderr = String::from_utf8_lossy(&damaged.stderr);
    assert!(!damaged.status.success());
    assert!(stderr.contains("explicit-box.json"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_configs_fail_naming_the_problem() {
    let dir = temp_dir("bad");
    let config = dir.join("eval.toml");
    let base = format!(
        "model = \"m\"\noutput = {}\nphotons_per_pass = 100\npasses = [2]\nseed = 1\n",
        toml_path(&dir.join("out"))
    );
    // An unknown key.
    std::fs::write(&config, format!("{base}photons = 3\n")).unwrap();
    let run = evaluate(&config);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        stderr.contains("eval.toml") && stderr.contains("photons"),
        "{stderr}"
    );
    // A missing reference is found before anything is rendered.
    std::fs::write(
        &config,
        format!(
            "{base}[[scenes]]\nxml = {}\nreference = {}\n",
            toml_path(&config),
            toml_path(&dir.join("nope.exr"))
        ),
    )
    .unwrap();
    let run = evaluate(&config);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("nope.exr"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    // An output that is a file, and a dataset directory that does not exist: named by key.
    let file = dir.join("a-file");
    std::fs::write(&file, "x").unwrap();
    let as_output = base.replace(&toml_path(&dir.join("out")), &toml_path(&file));
    std::fs::write(&config, as_output).unwrap();
    let run = evaluate(&config);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("exists and is not a directory"), "{stderr}");
    std::fs::write(&config, format!("{base}[dataset]\ndir = \"nowhere\"\n")).unwrap();
    let run = evaluate(&config);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("[dataset] dir = nowhere"), "{stderr}");
    // More worker threads than any machine has: refused before anything runs.
    std::fs::write(&config, format!("{base}threads = 100000\n")).unwrap();
    let run = evaluate(&config);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        stderr.contains("threads = 100000: at most 1024"),
        "{stderr}"
    );
    // A split the dataset lacks: the error lists the splits it has.
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    let scene = |id: &str, split: &str| manifest_scene(id, split, &format!("{id}.xml"));
    std::fs::write(
        data.join("manifest.json"),
        dataset_manifest(vec![scene("a", "test"), scene("b", "val")]).to_string(),
    )
    .unwrap();
    std::fs::write(
        &config,
        format!(
            "{base}[dataset]\ndir = {}\nsplit = \"tset\"\n",
            toml_path(&data)
        ),
    )
    .unwrap();
    let run = evaluate(&config);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        stderr.contains("\"tset\"") && stderr.contains("splits: test, val"),
        "{stderr}"
    );
    assert!(!dir.join("out").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The OIDN peers (`scripts/oidn_denoise.py`, Python `pyoidn`: installed by `.ci/run`).
#[test]
fn oidn_peers_get_at_least_ours_time_and_are_reported() {
    let dir = temp_dir("peers");
    let (xml, reference) = box_scene(&dir.join("box"));
    tiny_model(&dir.join("model"));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/oidn_denoise.py");
    let write_config = |name: &str, python: &str| {
        let config = dir.join(format!("{name}.toml"));
        std::fs::write(
            &config,
            format!(
                "model = {}\noutput = {}\nphotons_per_pass = 2000\npasses = [2, 4]\nseed = 5\n\
                 tile = 8\nthreads = 1\npeers = [\"sppm-oidn\", \"pt-oidn\"]\n\
                 oidn_python = {python:?}\noidn_script = {}\n\n[[scenes]]\nname = \"box\"\n\
                 xml = {}\nreference = {}\ndefines = {{ res = \"16\" }}\n",
                toml_path(&dir.join("model")),
                toml_path(&dir.join(format!("{name}-out"))),
                toml_path(&script),
                toml_path(&xml),
                toml_path(&reference)
            ),
        )
        .unwrap();
        config
    };
    let run = evaluate(&write_config("ok", "python3"));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("ok-out/results.json")).unwrap())
            .unwrap();
    let checkpoints = results["scenes"][0]["eval"]["checkpoints"]
        .as_array()
        .unwrap();
    assert_eq!(checkpoints.len(), 2);
    for c in checkpoints {
        let ours = finite(&c["ours_relmse"], "ours");
        let total = finite(&c["total_seconds"], "ours' total");
        for peer in ["sppm_oidn", "pt_oidn"] {
            let p = &c[peer];
            let what = |f: &str| format!("{peer}.{f} at {} passes", c["passes"]);
            let relmse = finite(&p["relmse"], &what("relmse"));
            let render = finite(&p["render_seconds"], &what("render_seconds"));
            let budget = finite(&p["render_budget_seconds"], &what("render_budget_seconds"));
            let denoise = finite(&p["denoise_seconds"], &what("denoise_seconds"));
            // At least ours' time: the render reaches its budget, which is ours' total less
            // the denoiser's time (so never more than ours' total).
            assert!(render >= budget, "{}: {render} < {budget}", what("render"));
            assert!(budget <= total && denoise > 0.0, "{}", what("budget"));
            assert!(p["samples"].as_u64().unwrap() >= 1, "{}", what("samples"));
            let ratio = finite(&p["ratio"], &what("ratio"));
            assert!(
                (ratio - ours / relmse).abs() <= 1e-9 * ratio.abs(),
                "{}",
                what("ratio")
            );
        }
    }
    let peers = results["summary"]["peers"].as_array().unwrap();
    assert_eq!(peers.len(), 2, "{peers:?}");
    assert_eq!(peers[0]["peer"], "sppm-oidn");
    assert_eq!(peers[1]["scenes"], 1);
    let html = std::fs::read_to_string(dir.join("ok-out/index.html")).unwrap();
    assert!(
        html.contains("Peers at equal time") && html.contains("PT + OIDN ("),
        "the page shows the peers"
    );
    // The comparison row: 5 panels, then each peer's image and error map (9 panels).
    let row = image::open(dir.join("ok-out/box_compare.png")).unwrap();
    let five = image::open(dir.join("ok-out/box_inputs.png")).unwrap();
    assert!(
        row.width() > five.width() * 9 / 5 - 16,
        "{} vs {}",
        row.width(),
        five.width()
    );
    // The Markdown summary over it has the peers' columns and lines.
    let combine = Command::new(env!("CARGO_BIN_EXE_evaluate"))
        .arg("--combine")
        .arg(dir.join("ok-out"))
        .output()
        .unwrap();
    let table = String::from_utf8_lossy(&combine.stdout);
    assert!(
        combine.status.success(),
        "{}",
        String::from_utf8_lossy(&combine.stderr)
    );
    assert!(
        table.contains("ours / SPPM + OIDN |")
            && table.contains("Against PT + OIDN: ours better on"),
        "{table}"
    );
    // Without a working denoiser: one clear error before any scene is rendered.
    let broken = evaluate(&write_config("broken", "/nonexistent/python3"));
    let stderr = String::from_utf8_lossy(&broken.stderr);
    assert_eq!(broken.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("/nonexistent/python3") && stderr.contains("oidn_denoise.py"),
        "{stderr}"
    );
    assert!(!dir.join("broken-out/results.json").exists());
}
