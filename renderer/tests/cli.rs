//! The renderer's command-line tools through their real binaries: each `--help` describes that
//! tool, `render` writes its outputs (path tracer EXR + PNG, SPPM bundles at the listed passes),
//! the bundles read back, and bad input ends with an error naming the file and line
//! and a non-zero exit status instead of a panic.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A scratch directory unique to this test process and test name.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("renderer-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs a binary and returns its output (whatever the exit status).
fn run(bin: &str, args: &[&str]) -> Output {
    Command::new(bin).args(args).output().expect("binary runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A tiny scene: a diffuse floor under an area light, seen by a perspective camera.
fn write_scene(dir: &Path) -> PathBuf {
    let path = dir.join("scene.xml");
    std::fs::write(&path, include_str!("fixtures/lit-floor.xml")).unwrap();
    path
}

#[test]
fn every_tool_describes_itself_in_its_help() {
    for (bin, about) in [
        (env!("CARGO_BIN_EXE_render"), "Render a Mitsuba 3 XML scene"),
        (
            env!("CARGO_BIN_EXE_bench_path"),
            "path-tracing samples per second",
        ),
        (env!("CARGO_BIN_EXE_bench_sppm"), "`sppm-ml` over `sppm`"),
    ] {
        let out = run(bin, &["--help"]);
        assert!(out.status.success(), "{bin} --help failed");
        let text = String::from_utf8_lossy(&out.stdout);
        let first = text.lines().next().unwrap_or_default();
        assert!(first.contains(about), "{bin}: first help line {first:?}");
        assert!(text.contains("Usage:"), "{bin}: {text}");
    }
}

#[test]
fn render_writes_images_and_bundles_that_read_back() {
    let dir = temp_dir("outputs");
    let scene = write_scene(&dir);
    let scene = scene.to_str().unwrap();
    let (exr, png) = (dir.join("path.exr"), dir.join("path.png"));
    let out = run(
        env!("CARGO_BIN_EXE_render"),
        &[
            scene,
            "--spp",
            "4",
            "--threads",
            "2",
            "--out",
            exr.to_str().unwrap(),
            "--png",
            png.to_str().unwrap(),
            "-D",
            "res=12",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let (width, height, pixels) = renderer::image_io::read_rgb_image(&exr).unwrap();
    assert_eq!((width, height), (12, 12), "-D res=12 applies");
    assert!(pixels
        .iter()
        .all(|v| v.is_finite() && v.min_element() >= 0.0));
    assert!(
        pixels.iter().any(|v| v.max_element() > 0.0),
        "the lit floor is visible"
    );
    assert!(std::fs::metadata(&png).unwrap().len() > 0);

    let prefix = dir.join("ml");
    let out = run(
        env!("CARGO_BIN_EXE_render"),
        &[
            scene,
            "--integrator",
            "sppm-ml",
            "--photons",
            "2000",
            "--passes",
            "1,3",
            "--out",
            prefix.to_str().unwrap(),
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    for passes in [1, 3] {
        let bundle = dir.join(format!("ml_p{passes:04}.exr"));
        assert!(bundle.exists(), "{} missing", bundle.display());
        let b = bundle::read_bundle(&bundle).unwrap();
        assert_eq!(b.meta.passes, passes);
        // (the fixture's default `res`)
        assert_eq!((b.meta.width, b.meta.height), (16, 16));
        assert_eq!(b.find_non_finite(), None);
        assert_eq!(b.meta.schedule, "sppm");
    }
    // `--schedule cppm` is recorded in the bundle.
    let prefix = dir.join("cppm");
    let out = run(
        env!("CARGO_BIN_EXE_render"),
        &[
            scene,
            "--integrator",
            "sppm",
            "--schedule",
            "cppm",
            "--photons",
            "2000",
            "--passes",
            "2",
            "--out",
            prefix.to_str().unwrap(),
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let b = bundle::read_bundle(&dir.join("cppm_p0002.exr")).unwrap();
    assert_eq!(
        (b.meta.integrator.as_str(), b.meta.schedule.as_str()),
        ("sppm", "cppm")
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_names_the_file_and_line_and_fails() {
    let dir = temp_dir("errors");
    let good = std::fs::read_to_string(write_scene(&dir)).unwrap();
    let cases = [
        ("unknown-plugin.xml", good.replace("type=\"diffuse\"", "type=\"velvet\""), "velvet"),
        (
            "bad-number.xml",
            good.replace("value=\"45\"", "value=\"4five\""),
            "4five",
        ),
        (
            "missing-mesh.xml",
            good.replace(
                "<shape type=\"rectangle\">\n        <transform name=\"to_world\"><rotate x=\"1\" angle=\"-90\"/>",
                "<shape type=\"obj\"><string name=\"filename\" value=\"nowhere.obj\"/>\n        <transform name=\"to_world\"><rotate x=\"1\" angle=\"-90\"/>",
            ),
            "nowhere.obj",
        ),
    ];
    for (name, text, detail) in cases {
        assert_ne!(text, good, "{name}: the case must change the scene");
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let out = run(
            env!("CARGO_BIN_EXE_render"),
            &[
                path.to_str().unwrap(),
                "--out",
                dir.join("x.exr").to_str().unwrap(),
            ],
        );
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
        assert!(err.contains(name) && err.contains(detail), "{name}: {err}");
        // file:line:column
        let located = err.split(name).skip(1).any(|rest| {
            rest.starts_with(':') && rest[1..].starts_with(|c: char| c.is_ascii_digit())
        });
        assert!(located, "{name}: no line number in {err}");
        assert!(!dir.join("x.exr").exists(), "{name}: no image on failure");
    }
    // A resolution whose SPPM state cannot fit in any machine's memory (1.5 TB): an error
    // saying so before anything is allocated, not an abort.
    let scene = write_scene(&dir);
    let huge = [
        scene.to_str().unwrap(),
        "--integrator",
        "sppm-ml",
        "--passes",
        "1",
        "-D",
        "res=60000",
        "--out",
        dir.join("huge").to_str().unwrap(),
    ]
    .map(String::from);
    render_fails_naming(&huge, &["needs", "GB of memory"]);
    // So does a photon count whose per-pass bookkeeping alone cannot fit (10^13 photons).
    let photons = [
        scene.to_str().unwrap(),
        "--integrator",
        "sppm-ml",
        "--passes",
        "1",
        "--photons",
        "10000000000000",
        "--out",
        dir.join("photons").to_str().unwrap(),
    ]
    .map(String::from);
    render_fails_naming(
        &photons,
        &["10000000000000 photons per pass needs", "GB of memory"],
    );
    // A light so strong that the variance of its estimates overflows float32: an error naming
    // the layer and pixel, and no bundle (not a bundle of infinities that only readers refuse).
    let blinding = dir.join("blinding.xml");
    std::fs::write(
        &blinding,
        std::fs::read_to_string(&scene)
            .unwrap()
            .replace("value=\"4, 4, 4\"", "value=\"4, 1e30, 4\""),
    )
    .unwrap();
    let args = [
        blinding.to_str().unwrap(),
        "--integrator",
        "sppm-ml",
        "--passes",
        "2",
        "--photons",
        "2000",
        "--out",
        dir.join("blinding").to_str().unwrap(),
    ]
    .map(String::from);
    render_fails_naming(&args, &["is not finite at pixel", "no bundle written"]);
    assert!(!dir.join("blinding_p0002.exr").exists());
    // An infinite time limit would never end a run without checkpoints.
    let endless = [
        scene.to_str().unwrap(),
        "--integrator",
        "sppm",
        "--time",
        "inf",
        "--out",
        dir.join("endless").to_str().unwrap(),
    ]
    .map(String::from);
    render_fails_naming(&endless, &["time limit", "finite", "got inf"]);
    // A define the scene never reads (a misspelt name) is an error naming it and the scene,
    // with every integrator (renderer::scene_file), and nothing is written.
    for integrator in [&["path"][..], &["sppm-ml", "--passes", "1"]] {
        let mut misspelt: Vec<String> = vec![scene.to_str().unwrap().into(), "--integrator".into()];
        misspelt.extend(integrator.iter().map(|a| a.to_string()));
        misspelt.extend(
            [
                "-D",
                "rez=12",
                "--out",
                dir.join("misspelt.exr").to_str().unwrap(),
            ]
            .map(String::from),
        );
        render_fails_naming(&misspelt, &["-D rez=12", "scene.xml"]);
        assert!(!dir.join("misspelt.exr").exists() && !dir.join("misspelt_p0001.exr").exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_option_the_chosen_integrator_would_ignore_is_refused() {
    let dir = temp_dir("ignored-options");
    let scene = write_scene(&dir);
    let scene = scene.to_str().unwrap();
    let out = dir.join("out");
    let out = out.to_str().unwrap();
    // (integrator, the option, what the error must name)
    let cases: [(&str, &[&str], &str); 12] = [
        ("path", &["--time", "5"], "--time"),
        ("path", &["--emitter-samples", "2"], "--emitter-samples"),
        ("direct", &["--max-depth", "3"], "--max-depth"),
        ("direct", &["--rr-depth", "3"], "--rr-depth"),
        (
            "sppm",
            &["--passes", "1", "--bsdf-samples", "2"],
            "--bsdf-samples",
        ),
        ("path", &["--passes", "4"], "--passes"),
        ("path", &["--photons", "1000"], "--photons"),
        ("path", &["--knn", "10"], "--knn"),
        ("path", &["--max-radius", "0.1"], "--max-radius"),
        ("path", &["--schedule", "cppm"], "--schedule"),
        ("sppm", &["--passes", "1", "--spp", "4"], "--spp"),
        (
            "sppm-ml",
            &["--passes", "1", "--rr-depth", "3"],
            "--rr-depth",
        ),
    ];
    for (integrator, options, flag) in cases {
        let mut args = vec![scene, "--out", out, "--integrator", integrator];
        args.extend_from_slice(options);
        let result = run(env!("CARGO_BIN_EXE_render"), &args);
        let err = stderr(&result);
        assert_eq!(result.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains(flag) && err.contains(integrator),
            "{args:?}: {err}"
        );
        assert!(err.contains("Usage: render "), "{args:?}: {err}");
        assert!(
            std::fs::read_dir(&dir).unwrap().count() == 1,
            "{args:?}: no output"
        );
    }
    // The defaults of the other integrator's options are not "given": these render.
    let ok = run(
        env!("CARGO_BIN_EXE_render"),
        &[scene, "--out", out, "--spp", "1", "--max-depth", "3"],
    );
    assert!(ok.status.success(), "{}", stderr(&ok));
    // A negative number is read as a value, not as an unknown option (clap's advice to write
    // `-- -1` would be wrong here), and `--max-depth -1` (unbounded) needs no `=`.
    let negative = run(
        env!("CARGO_BIN_EXE_render"),
        &[scene, "--out", out, "--spp", "-1"],
    );
    let err = stderr(&negative);
    assert_eq!(negative.status.code(), Some(2), "{err}");
    assert!(
        err.contains("invalid value '-1' for '--spp") && !err.contains("-- -1"),
        "{err}"
    );
    let unbounded = run(
        env!("CARGO_BIN_EXE_render"),
        &[scene, "--out", out, "--spp", "1", "--max-depth", "-1"],
    );
    assert!(unbounded.status.success(), "{}", stderr(&unbounded));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--integrator direct` renders direct light only; a scene file whose integrator is `direct`
/// is rendered with it (and its sample counts) when no `--integrator` is given, and an option
/// that integrator would ignore is then refused naming the file.
#[test]
fn the_direct_integrator_from_the_command_line_and_from_the_scene_file() {
    let dir = temp_dir("direct");
    let scene = write_scene(&dir);
    let render = |scene: &Path, extra: &[&str], out: &str| {
        let out = dir.join(out);
        let mut args = vec![
            scene.to_str().unwrap(),
            "--spp",
            "16",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let result = run(env!("CARGO_BIN_EXE_render"), &args);
        (result, out)
    };
    let (result, direct) = render(
        &scene,
        &["--integrator", "direct", "--emitter-samples", "2"],
        "direct.exr",
    );
    let err = stderr(&result);
    assert!(result.status.success(), "{err}");
    assert!(
        err.contains("direct: 16x16 at 16 spp, 2 emitter and 1 BSDF samples"),
        "{err}"
    );
    // Path tracing at max_depth 2 estimates the same direct light.
    let (result, path2) = render(&scene, &["--max-depth", "2"], "path2.exr");
    assert!(result.status.success(), "{}", stderr(&result));
    let mean = |p: &Path| {
        let (_, _, px) = renderer::image_io::read_rgb_image(p).unwrap();
        px.iter().map(|v| v.x as f64).sum::<f64>() / px.len() as f64
    };
    let (d, p) = (mean(&direct), mean(&path2));
    assert!(
        d > 0.05 && ((d - p) / p).abs() < 0.05,
        "direct {d}, path at depth 2 {p}"
    );

    // The same scene with `<integrator type="direct">`: chosen without --integrator.
    let text = std::fs::read_to_string(&scene).unwrap().replace(
        r#"<integrator type="path"><integer name="max_depth" value="4"/></integrator>"#,
        r#"<integrator type="direct"><integer name="bsdf_samples" value="3"/></integrator>"#,
    );
    let file_direct = dir.join("direct.xml");
    std::fs::write(&file_direct, text).unwrap();
    let (result, _) = render(&file_direct, &[], "from-file.exr");
    let err = stderr(&result);
    assert!(result.status.success(), "{err}");
    assert!(
        err.contains("direct: 16x16 at 16 spp, 1 emitter and 3 BSDF samples"),
        "{err}"
    );
    assert!(!err.contains("warning"), "{err}");
    // The command line overrides the file.
    let (result, _) = render(&file_direct, &["--integrator", "path"], "path.exr");
    let err = stderr(&result);
    assert!(
        result.status.success() && err.contains("path: 16x16"),
        "{err}"
    );
    let (result, _) = render(&file_direct, &["--bsdf-samples", "1"], "override.exr");
    let err = stderr(&result);
    assert!(err.contains("1 emitter and 1 BSDF samples"), "{err}");
    // A path-tracer option with the file's direct integrator: refused, naming the file.
    let (result, _) = render(&file_direct, &["--rr-depth", "3"], "refused.exr");
    let err = stderr(&result);
    assert_eq!(result.status.code(), Some(1), "{err}");
    assert!(
        err.contains("--rr-depth is read by the path tracer only, not by --integrator direct")
            && err.contains("direct.xml"),
        "{err}"
    );
    assert!(!dir.join("refused.exr").exists());
    let (result, _) = render(
        &scene,
        &[
            "--integrator",
            "direct",
            "--emitter-samples",
            "0",
            "--bsdf-samples",
            "0",
        ],
        "none.exr",
    );
    let err = stderr(&result);
    assert_eq!(result.status.code(), Some(1), "{err}");
    assert!(err.contains("at least one emitter or BSDF sample"), "{err}");
    // A path tracer's run state is not resumed by the direct integrator: refused, naming the
    // integrator (not a setting that differs because of it).
    let state = dir.join("run.state");
    let state = state.to_str().unwrap();
    let (result, _) = render(&scene, &["--state", state], "state-path.exr");
    assert!(result.status.success(), "{}", stderr(&result));
    let (result, _) = render(
        &scene,
        &["--integrator", "direct", "--state", state],
        "state-direct.exr",
    );
    let err = stderr(&result);
    assert_eq!(result.status.code(), Some(1), "{err}");
    assert!(
        err.contains(r#"integrator: "path" in the file, "direct" in this run"#),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A field of the `state` object in a run-state file's JSON line, if it can be read now.
fn saved_field(state: &Path, field: &str) -> Option<u64> {
    let text = std::fs::read(state).ok()?;
    let line = text.split(|&b| b == b'\n').nth(1)?;
    let header: serde_json::Value = serde_json::from_slice(line).ok()?;
    header["state"][field].as_u64()
}

/// The pass count saved in an SPPM run-state file.
fn saved_passes(state: &Path) -> Option<u64> {
    saved_field(state, "passes")
}

/// Runs `render` with `args`, which must fail (no panic) with every one of `needles` in its
/// error.
fn render_fails_naming(args: &[String], needles: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_render"))
        .args(args)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(needles.iter().all(|n| e.contains(n)), "{e}");
    assert!(!e.contains("panicked"), "{e}");
}

/// Starts `render` with `args` and kills it (SIGKILL) as soon as `ready()` holds; the moment is
/// read from the run's own state file, so it lands mid-run however loaded the machine is.
fn kill_render_when(args: &[String], ready: impl Fn() -> bool) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_render"))
        .args(args)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let finished = loop {
        let done = child.try_wait().unwrap().is_some();
        if done || ready() {
            break done;
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    };
    let _ = child.kill();
    let _ = child.wait();
    assert!(!finished, "the render had finished before the kill");
}

/// Every float of a bundle's layers as bits, and its pass count.
fn bundle_bits(path: &Path) -> (u32, Vec<u32>) {
    let b = bundle::read_bundle(path).unwrap();
    let mut bits = Vec::new();
    for img in b
        .levels
        .iter()
        .chain([&b.variance, &b.albedo, &b.normal, &b.depth])
        .chain(b.radius.as_ref())
    {
        bits.extend(img.data.iter().map(|x| x.to_bits()));
    }
    (b.meta.passes, bits)
}

#[test]
fn a_killed_sppm_render_resumes_from_its_state_file_bit_identically() {
    let dir = temp_dir("resume");
    let scene = write_scene(&dir);
    let scene = scene.to_str().unwrap();
    let args = |prefix: &Path, extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = [
            scene,
            "--integrator",
            "sppm-ml",
            "--photons",
            "20000",
            "--passes",
            "2,150",
            "--threads",
            "1",
            "--out",
            prefix.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let whole = dir.join("whole");
    let out = Command::new(env!("CARGO_BIN_EXE_render"))
        .args(args(&whole, &[]))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));

    // Killed (SIGKILL) once the state has been saved past pass 2's bundle.
    let state = dir.join("run.state");
    let killed = dir.join("killed");
    let with_state = args(
        &killed,
        &[
            "--state",
            state.to_str().unwrap(),
            "--state-interval",
            "0.001",
        ],
    );
    kill_render_when(&with_state, || saved_passes(&state).is_some_and(|p| p >= 4));
    let at_kill = saved_passes(&state).unwrap();
    assert!((4..150).contains(&at_kill), "saved at pass {at_kill}");
    assert!(!dir.join("killed_p0150.exr").exists());

    let out = Command::new(env!("CARGO_BIN_EXE_render"))
        .args(&with_state)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("resuming from the run state"));
    for passes in [2, 150] {
        let name = |p: &str| dir.join(format!("{p}_p{passes:04}.exr"));
        let (a, b) = (bundle_bits(&name("whole")), bundle_bits(&name("killed")));
        assert_eq!(a.0, passes);
        assert!(a == b, "bundle at pass {passes} differs after the resume");
    }
    assert_eq!(saved_passes(&state), Some(150));

    // The same state with another seed is refused, naming the file and the setting.
    let mut other = with_state.clone();
    other.extend(["--seed".to_string(), "7".to_string()]);
    render_fails_naming(&other, &["run.state", "seed: 0 in the file, 7 in this run"]);
}

#[test]
fn a_killed_path_render_resumes_from_its_finished_rows_bit_identically() {
    let dir = temp_dir("resume-path");
    let scene = write_scene(&dir);
    let scene = scene.to_str().unwrap();
    let args = |out: &Path, extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = [scene, "-D", "res=24", "--threads", "2"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        a.extend(["--out".to_string(), out.to_str().unwrap().to_string()]);
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let whole = dir.join("whole.exr");
    let out = Command::new(env!("CARGO_BIN_EXE_render"))
        .args(args(&whole, &["--spp", "3000"]))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));

    let state = dir.join("rows.state");
    let killed = dir.join("killed.exr");
    let state_args = [
        "--state",
        state.to_str().unwrap(),
        "--state-interval",
        "0.001",
    ];
    let with_state = args(&killed, &[&["--spp", "3000"][..], &state_args].concat());
    let rows_done = |state: &Path| saved_field(state, "rows_done");
    kill_render_when(&with_state, || rows_done(&state).is_some_and(|r| r >= 3));
    assert!(rows_done(&state).is_some_and(|r| r < 24));
    assert!(!killed.exists());

    let out = Command::new(env!("CARGO_BIN_EXE_render"))
        .args(&with_state)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("resuming from the run state"));
    let read = |p: &Path| -> Vec<u32> {
        let (_, _, pixels) = renderer::image_io::read_rgb_image(p).unwrap();
        pixels
            .iter()
            .flat_map(|v| v.to_array())
            .map(f32::to_bits)
            .collect()
    };
    assert!(read(&whole) == read(&killed), "the resumed image differs");
    assert_eq!(rows_done(&state), Some(24));

    // Other samples per pixel with the same state: refused, naming the file and the setting.
    let other = args(&killed, &[&["--spp", "5"][..], &state_args].concat());
    render_fails_naming(
        &other,
        &["rows.state", "spp: 3000 in the file, 5 in this run"],
    );
}

#[test]
fn a_state_file_is_refused_once_a_mesh_the_scene_reads_changed() {
    let dir = temp_dir("resume-mesh");
    let xml = write_scene(&dir);
    let text = std::fs::read_to_string(&xml).unwrap().replace(
        "</scene>",
        "<shape type=\"obj\"><string name=\"filename\" value=\"box.obj\"/></shape>\n</scene>",
    );
    std::fs::write(&xml, text).unwrap();
    let mesh = dir.join("box.obj");
    let triangle = "v -0.5 0.2 0\nv 0.5 0.2 0\nv 0 1 0\nf 1 2 3\n";
    std::fs::write(&mesh, triangle).unwrap();
    let state = dir.join("run.state");
    let args: Vec<String> = [
        xml.to_str().unwrap(),
        "--spp",
        "2",
        "--out",
        dir.join("img.exr").to_str().unwrap(),
        "--state",
        state.to_str().unwrap(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let render = || {
        Command::new(env!("CARGO_BIN_EXE_render"))
            .args(&args)
            .output()
            .unwrap()
    };
    let out = render();
    assert!(out.status.success(), "{}", stderr(&out));
    // The same scene resumes (here: a finished run, written again) …
    let out = render();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("resuming from the run state"));
    // … but after an edit of the mesh alone, with the XML untouched, the state is another
    // scene's: refused, naming the state file and what changed.
    std::fs::write(&mesh, triangle.replace("v 0 1 0", "v 0 1.5 0")).unwrap();
    render_fails_naming(
        &args,
        &["run.state", "scene_fingerprint", "a file it reads"],
    );
}

/// A scene with participating media renders with `volpath` — chosen by its file's
/// `<integrator type="volpath">` — and every other integrator refuses it, naming the medium and
/// the file, with exit status 1.
#[test]
fn media_render_with_volpath_and_other_integrators_refuse_them() {
    let dir = temp_dir("media");
    let scene = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenes/validation/media/scene.xml"
    );
    let exr = dir.join("media.exr");
    let out = run(
        env!("CARGO_BIN_EXE_render"),
        &[
            scene,
            "--spp",
            "2",
            "-D",
            "res=8",
            "--out",
            exr.to_str().unwrap(),
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("volpath: 8x8"), "{}", stderr(&out));
    let (w, _, pixels) = renderer::image_io::read_rgb_image(&exr).unwrap();
    assert_eq!(w, 8);
    assert!(pixels.iter().all(|v| v.is_finite()));
    for integrator in ["path", "direct", "sppm-ml"] {
        let out_path = dir.join(integrator);
        let mut args = vec![
            scene,
            "--integrator",
            integrator,
            "-D",
            "res=8",
            "--out",
            out_path.to_str().unwrap(),
        ];
        if integrator == "sppm-ml" {
            args.extend(["--passes", "1"]);
        }
        let out = run(env!("CARGO_BIN_EXE_render"), &args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{integrator}: {err}");
        assert!(
            err.contains("participating media (medium 'fog'")
                && err.contains("scenes/validation/media/scene.xml")
                && err.contains(&format!("the {integrator} integrator")),
            "{integrator}: {err}"
        );
    }
}

/// The channels of a multi-channel EXR by name.
fn exr_channels(path: &Path) -> std::collections::HashMap<String, Vec<f32>> {
    let image = exr::prelude::read_all_flat_layers_from_file(path).expect("readable EXR");
    let layer = &image.layer_data[0];
    layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            (
                c.name.to_string(),
                c.sample_data.values_as_f32().collect::<Vec<f32>>(),
            )
        })
        .collect()
}

#[test]
fn the_aov_and_depth_integrators_write_mitsubas_channels() {
    let dir = temp_dir("aov");
    let floor = write_scene(&dir);
    // The lit floor with an `aov` integrator: a named path tracer, an unnamed depth integrator
    // and five variables.
    let text = std::fs::read_to_string(&floor).unwrap().replace(
        r#"<integrator type="path"><integer name="max_depth" value="4"/></integrator>"#,
        r#"<integrator type="aov">
            <string name="aovs" value="dd.y:depth,pos:position,n:geo_normal,alb:albedo,s:shape_index"/>
            <integrator type="path" name="image"><integer name="max_depth" value="4"/></integrator>
            <integrator type="depth"/>
        </integrator>"#,
    );
    let scene = dir.join("aov.xml");
    std::fs::write(&scene, text).unwrap();
    let scene = scene.to_str().unwrap();
    let render = |extra: &[&str], out: &str| {
        let out = dir.join(out);
        let mut args = vec![scene, "--spp", "16", "--out", out.to_str().unwrap()];
        args.extend_from_slice(extra);
        (run(env!("CARGO_BIN_EXE_render"), &args), out)
    };
    let png = dir.join("aov.png");
    let (result, out) = render(
        &["--threads", "1", "--png", png.to_str().unwrap()],
        "aov.exr",
    );
    let err = stderr(&result);
    assert!(result.status.success(), "{err}");
    assert!(
        err.contains("aov: 16x16 at 16 spp, 2 nested images and 5 variables (22 channels)"),
        "{err}"
    );
    let c = exr_channels(&out);
    let mut names: Vec<_> = c.keys().cloned().collect();
    names.sort();
    let expected = [
        "B", "G", "R", "_arg_0.A", "_arg_0.B", "_arg_0.G", "_arg_0.R", "alb.B", "alb.G", "alb.R",
        "dd.y.T", "image.A", "image.B", "image.G", "image.R", "n.X", "n.Y", "n.Z", "pos.X",
        "pos.Y", "pos.Z", "s.I",
    ];
    assert_eq!(names, expected);
    assert!(png.exists());
    // The main image is the first nested one.
    for ch in ["R", "G", "B"] {
        assert_eq!(c[ch], c[&format!("image.{ch}")], "{ch}");
    }
    // Pixels wholly on the floor (every sample met it, none the light above it, shape 2): its
    // normal, albedo, height and index.
    let covered: Vec<usize> = (0..256)
        .filter(|&i| c["image.A"][i] == 1.0 && c["s.I"][i] == 1.0)
        .collect();
    assert!(covered.len() > 100, "{} covered pixels", covered.len());
    for &i in &covered {
        assert!(
            (c["n.Y"][i] - 1.0).abs() < 1e-5 && c["n.X"][i].abs() < 1e-5,
            "pixel {i}"
        );
        assert!((c["alb.R"][i] - 0.5).abs() < 1e-5, "pixel {i}");
        assert!(c["pos.Y"][i].abs() < 1e-4, "pixel {i}");
        // The distance from the camera at (0, 3, 3) to the point on the floor, less the near
        // clip distance the ray starts at (0.01 along the optical axis).
        let p = [c["pos.X"][i], c["pos.Y"][i], c["pos.Z"][i]];
        let d = (p[0].powi(2) + (p[1] - 3.0).powi(2) + (p[2] - 3.0).powi(2)).sqrt();
        assert!(
            (c["dd.y.T"][i] - d).abs() < 0.03 * d,
            "pixel {i}: {} vs {d}",
            c["dd.y.T"][i]
        );
    }
    // The nested depth integrator measures the same distances with its own samples.
    let mean =
        |name: &str| covered.iter().map(|&i| c[name][i] as f64).sum::<f64>() / covered.len() as f64;
    let (integrator, variable) = (mean("_arg_0.R"), mean("dd.y.T"));
    assert!(
        (integrator / variable - 1.0).abs() < 0.01,
        "{integrator} vs {variable}"
    );
    // Pixels that see no surface: zero everywhere, alpha zero (no environment light).
    let empty: Vec<usize> = (0..256).filter(|&i| c["image.A"][i] == 0.0).collect();
    assert!(!empty.is_empty());
    for &i in &empty {
        for name in ["dd.y.T", "alb.R", "s.I", "_arg_0.R", "R"] {
            assert_eq!(c[name][i], 0.0, "{name} at pixel {i}");
        }
    }
    // Bit-identical on two threads.
    let (result, two) = render(&["--threads", "2"], "aov2.exr");
    assert!(result.status.success(), "{}", stderr(&result));
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&two).unwrap());
    // Killed or not, a run with --state resumes its nested images from `<state>.<name>`.
    let state = dir.join("run.state");
    let (result, first) = render(&["--state", state.to_str().unwrap()], "state.exr");
    assert!(result.status.success(), "{}", stderr(&result));
    assert!(dir.join("run.state.image").exists() && dir.join("run.state._arg_0").exists());
    let (result, again) = render(&["--state", state.to_str().unwrap()], "state2.exr");
    assert!(stderr(&result).contains("resuming"), "{}", stderr(&result));
    assert_eq!(std::fs::read(first).unwrap(), std::fs::read(again).unwrap());

    // `--integrator depth` on the plain floor scene: the distance as every colour channel.
    let depth = dir.join("depth.exr");
    let result = run(
        env!("CARGO_BIN_EXE_render"),
        &[
            floor.to_str().unwrap(),
            "--integrator",
            "depth",
            "--spp",
            "4",
            "--out",
            depth.to_str().unwrap(),
        ],
    );
    assert!(result.status.success(), "{}", stderr(&result));
    let (_, _, px) = renderer::image_io::read_rgb_image(&depth).unwrap();
    // The four pixels around the optical axis, which meets the floor at √18 from the camera.
    let centre = [7 * 16 + 7, 7 * 16 + 8, 8 * 16 + 7, 8 * 16 + 8].map(|i| px[i]);
    let mean = centre.iter().map(|p| p.x).sum::<f32>() / 4.0;
    assert!((mean / 18f32.sqrt() - 1.0).abs() < 0.02, "{centre:?}");
    assert!(
        centre.iter().all(|p| p.x == p.y && p.y == p.z),
        "{centre:?}"
    );

    // Refusals, each naming what is wrong, before anything is written.
    // (exit status 1: a bad scene or output; 2: a usage error)
    let refused = |args: &[&str], code: i32, needle: &str| {
        let result = run(env!("CARGO_BIN_EXE_render"), args);
        let err = stderr(&result);
        assert_eq!(result.status.code(), Some(code), "{err}");
        assert!(err.contains(needle), "{err}");
    };
    let nope = dir.join("nope.exr");
    let nope = nope.to_str().unwrap();
    refused(
        &[
            floor.to_str().unwrap(),
            "--integrator",
            "aov",
            "--out",
            nope,
        ],
        1,
        "has no aov integrator",
    );
    let only_aovs = std::fs::read_to_string(scene).unwrap().replace(
        r#"<integrator type="path" name="image"><integer name="max_depth" value="4"/></integrator>
            <integrator type="depth"/>"#,
        "",
    );
    let only = dir.join("only.xml");
    std::fs::write(&only, only_aovs).unwrap();
    let png = dir.join("nope.png");
    refused(
        &[
            only.to_str().unwrap(),
            "--out",
            nope,
            "--png",
            png.to_str().unwrap(),
        ],
        1,
        "nests no integrator",
    );
    refused(
        &[
            floor.to_str().unwrap(),
            "--integrator",
            "depth",
            "--max-depth",
            "3",
            "--out",
            nope,
        ],
        2,
        "--max-depth is read by path and SPPM only, not by --integrator depth",
    );
    assert!(!Path::new(nope).exists() && !png.exists());
    let _ = std::fs::remove_dir_all(&dir);
}
