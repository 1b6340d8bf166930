//! The renderer's command-line tools through their real binaries: each `--help` describes that
//! tool, `render` writes its outputs (path tracer EXR + PNG, SPPM bundles at the listed passes),
//! `bundle_info` reads a bundle back, and bad input ends with an error naming the file and line
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
    std::fs::write(
        &path,
        r#"<scene version="3.0.0">
    <default name="res" value="16"/>
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 3, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="$res"/><integer name="height" value="$res"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="2"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="90"/><translate y="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="4, 4, 4"/></emitter>
    </shape>
</scene>
"#,
    )
    .unwrap();
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
        (
            env!("CARGO_BIN_EXE_bundle_info"),
            "Inspect a multi-level SPPM sample bundle",
        ),
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
fn render_writes_images_and_bundles_that_bundle_info_reads() {
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
        let pngs = dir.join(format!("levels{passes}"));
        let out = run(
            env!("CARGO_BIN_EXE_bundle_info"),
            &[bundle.to_str().unwrap(), "--png", pngs.to_str().unwrap()],
        );
        assert!(out.status.success(), "{}", stderr(&out));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains(&format!("\"passes\": {passes}")), "{text}");
        for layer in ["y", "z1", "z2", "z3", "z4", "albedo", "normal", "depth"] {
            let png = dir.join(format!("levels{passes}_{layer}.png"));
            assert!(png.exists(), "{} missing", png.display());
        }
    }
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
    let missing = run(
        env!("CARGO_BIN_EXE_bundle_info"),
        &[dir.join("none.exr").to_str().unwrap()],
    );
    assert_ne!(missing.status.code(), Some(0));
    assert!(
        stderr(&missing).contains("none.exr"),
        "{}",
        stderr(&missing)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
