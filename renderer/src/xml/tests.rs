//! Tests of the XML importer: error reporting, parameters, transforms, meshes, includes, and
//! the external validation scenes.

use super::*;
use crate::bsdf::MicrofacetKind;
use crate::description::{EmitterDesc, FovAxis, Geometry, TriangleMesh};
use crate::filter::FilterDesc;
use glam::{Mat4, Vec2, Vec3, Vec4};
use std::path::PathBuf;

/// A fresh temporary directory for one test.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("renderer-xml-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes `body` wrapped in a `<scene>` (the first body line is line 2 of the file).
fn write_scene(dir: &Path, file: &str, body: &str) -> PathBuf {
    let path = dir.join(file);
    std::fs::write(
        &path,
        format!("<scene version=\"3.0.0\">\n{body}\n</scene>\n"),
    )
    .unwrap();
    path
}

/// The 1-based line of the first line of `body` containing `marker`, in a file written by
/// [`write_scene`].
fn line_of(body: &str, marker: &str) -> usize {
    body.lines()
        .position(|l| l.contains(marker))
        .expect("marker in body")
        + 2
}

fn load(path: &Path) -> Result<SceneDescription, SceneError> {
    load_scene(path, &[], false)
}

/// Asserts that loading fails with an error at `file:line` whose message contains `needle`.
fn assert_error_at(path: &Path, line: usize, needle: &str) -> SceneError {
    let err = load(path).expect_err("the scene must not load");
    let msg = err.to_string();
    let file = path.file_name().unwrap().to_string_lossy();
    let loc = err
        .location()
        .unwrap_or_else(|| panic!("no location in: {msg}"));
    assert_eq!(loc.line as usize, line, "wrong line in: {msg}");
    assert!(
        msg.contains(&format!("{file}:{line}:")),
        "no file:line in: {msg}"
    );
    assert!(msg.contains(needle), "\"{needle}\" missing in: {msg}");
    err
}

/// Writes `body` as scene `file` in `dir` and asserts that loading it fails at the line of the
/// first body line containing `marker`, with a message containing `needle`.
fn assert_body_error_at(
    dir: &Path,
    file: &str,
    body: &str,
    marker: &str,
    needle: &str,
) -> SceneError {
    let path = write_scene(dir, file, body);
    assert_error_at(&path, line_of(body, marker), needle)
}

const SENSOR: &str = r#"<sensor type="perspective"><float name="fov" value="40"/>
<film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="8"/></film></sensor>"#;

#[test]
fn error_unknown_plugin_names_file_line_and_element() {
    let dir = temp_dir("unknown-plugin");
    let body = format!("{SENSOR}\n<shape type=\"sphere\">\n    <bsdf type=\"foo\"/>\n</shape>");
    let path = write_scene(&dir, "scene.xml", &body);
    let err = assert_error_at(&path, line_of(&body, "\"foo\""), "unknown plugin \"foo\"");
    assert!(err.to_string().contains("<bsdf type=\"foo\">"), "{err}");
    // Column of the element start is reported too.
    assert_eq!(err.location().unwrap().column, 5);
    let body = format!("{SENSOR}\n<shape type=\"teapot\"/>");
    let path = write_scene(&dir, "shape.xml", &body);
    assert_error_at(&path, line_of(&body, "teapot"), "unknown plugin \"teapot\"");
}

#[test]
fn error_bad_attribute_value() {
    let dir = temp_dir("bad-attribute");
    let body = format!("{SENSOR}\n<shape type=\"sphere\">\n<boolean name=\"flip_normals\" value=\"maybe\"/>\n</shape>");
    let path = write_scene(&dir, "scene.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "maybe"),
        "could not parse boolean value \"maybe\"",
    );
    let body = format!("{SENSOR}\n<bsdf type=\"roughconductor\"><string name=\"distribution\" value=\"phong\"/></bsdf>");
    let path = write_scene(&dir, "dist.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "phong"),
        "unknown microfacet distribution \"phong\"",
    );
    let body = format!("{SENSOR}\n<bsdf type=\"dielectric\">\n<string name=\"int_ior\" value=\"kryptonite\"/></bsdf>");
    let path = write_scene(&dir, "ior.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "kryptonite"),
        "unknown IOR name \"kryptonite\"",
    );
    // An unknown attribute on a known element.
    let body = format!("{SENSOR}\n<shape type=\"sphere\" colour=\"red\"/>");
    let path = write_scene(&dir, "attr.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "colour"),
        "unknown attribute \"colour\"",
    );
}

#[test]
fn error_missing_mesh_file() {
    let dir = temp_dir("missing-mesh");
    let body = format!("{SENSOR}\n<shape type=\"obj\">\n  <string name=\"filename\" value=\"meshes/nope.obj\"/>\n</shape>");
    let path = write_scene(&dir, "scene.xml", &body);
    let err = assert_error_at(&path, line_of(&body, "nope.obj"), "cannot load mesh");
    assert!(err.to_string().contains("meshes/nope.obj"), "{err}");
    let body = format!("{SENSOR}\n<shape type=\"ply\">\n  <string name=\"filename\" value=\"nope.ply\"/>\n</shape>");
    let path = write_scene(&dir, "ply.xml", &body);
    assert_error_at(&path, line_of(&body, "nope.ply"), "nope.ply");
}

/// A scene file that cannot be read is named, with its cause stated once (the cause is not
/// also a `source`, which the binaries' `{:#}` error chains would print a second time).
#[test]
fn error_unreadable_scene_file_states_the_cause_once() {
    use std::error::Error;
    let path = temp_dir("unreadable").join("absent.xml");
    let err = load_scene(&path, &[], false).unwrap_err();
    let message = err.to_string();
    assert!(message.contains("absent.xml"), "{message}");
    assert!(message.contains("No such file"), "{message}");
    assert!(err.source().is_none());
    assert_eq!(format!("{:#}", anyhow::Error::from(err)), message);
}

#[test]
fn error_malformed_number() {
    let dir = temp_dir("malformed-number");
    let body = format!(
        "{SENSOR}\n<shape type=\"sphere\">\n<float name=\"radius\" value=\"1.0.0\"/>\n</shape>"
    );
    let path = write_scene(&dir, "scene.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "1.0.0"),
        "could not parse floating point value \"1.0.0\"",
    );
    let body = format!(
        "{SENSOR}\n<bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.5, x, 0.2\"/></bsdf>"
    );
    let path = write_scene(&dir, "rgb.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "0.5, x"),
        "could not parse floating point value \"x\"",
    );
    let body = "<sensor type=\"perspective\"><film type=\"hdrfilm\">\n<integer name=\"width\" value=\"12.5\"/></film></sensor>";
    let path = write_scene(&dir, "int.xml", body);
    assert_error_at(
        &path,
        line_of(body, "12.5"),
        "could not parse integer value \"12.5\"",
    );
    let body = format!("{SENSOR}\n<shape type=\"rectangle\"><transform name=\"to_world\">\n<matrix value=\"1 0 0\"/></transform></shape>");
    let path = write_scene(&dir, "matrix.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "<matrix"),
        "needs 16 (or 9) values, got 3",
    );
    let body = format!("{SENSOR}\n<bsdf type=\"diffuse\">\n<spectrum name=\"reflectance\" value=\"500:0.3, 400:0.2\"/></bsdf>");
    let path = write_scene(&dir, "spectrum.xml", &body);
    assert_error_at(&path, line_of(&body, "500:0.3"), "strictly increasing");
}

#[test]
fn error_dangling_ref() {
    let dir = temp_dir("dangling-ref");
    let body = format!("{SENSOR}\n<shape type=\"sphere\">\n    <ref id=\"nothing\"/>\n</shape>");
    let path = write_scene(&dir, "scene.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "nothing"),
        "reference to unknown id \"nothing\"",
    );
    // A reference to an object of the wrong kind.
    let body = format!(
        "{SENSOR}\n<texture type=\"checkerboard\" id=\"tex\"/>\n<shape type=\"sphere\">\n<ref id=\"tex\"/>\n</shape>"
    );
    let path = write_scene(&dir, "kind.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "<ref id=\"tex\""),
        "unexpected <texture type=\"checkerboard\" id=\"tex\">",
    );
    // A reference cycle.
    let body = format!("{SENSOR}\n<bsdf type=\"twosided\" id=\"a\">\n<ref id=\"a\"/></bsdf>");
    let path = write_scene(&dir, "cycle.xml", &body);
    assert_error_at(&path, line_of(&body, "id=\"a\">"), "reference cycle");
}

#[test]
fn other_errors_are_located_too() {
    let dir = temp_dir("other-errors");
    // Unknown parameter.
    let body = format!(
        "{SENSOR}\n<bsdf type=\"diffuse\">\n<float name=\"roughness\" value=\"0.3\"/></bsdf>"
    );
    let path = write_scene(&dir, "param.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "roughness"),
        "unknown parameter \"roughness\" of <bsdf type=\"diffuse\">",
    );
    // Wrong value type.
    let body = format!(
        "{SENSOR}\n<shape type=\"sphere\">\n<string name=\"radius\" value=\"big\"/></shape>"
    );
    let path = write_scene(&dir, "type.xml", &body);
    assert_error_at(
        &path,
        line_of(&body, "big"),
        "wrong type (expected float, got string)",
    );
    // Undefined $parameter.
    let body =
        format!("{SENSOR}\n<shape type=\"sphere\">\n<float name=\"radius\" value=\"$r\"/></shape>");
    let path = write_scene(&dir, "param-undefined.xml", &body);
    assert_error_at(&path, line_of(&body, "$r"), "undefined parameter \"$r\"");
    // Malformed XML.
    let path = dir.join("syntax.xml");
    std::fs::write(
        &path,
        "<scene version=\"3.0.0\">\n<shape type=\"sphere\">\n</scene>\n",
    )
    .unwrap();
    let err = load(&path).unwrap_err();
    assert!(matches!(err, SceneError::Syntax { .. }), "{err}");
    assert!(err.to_string().contains("syntax.xml:3:"), "{err}");
    // Missing scene file.
    let err = load(&dir.join("absent.xml")).unwrap_err();
    assert!(err.to_string().contains("absent.xml"), "{err}");
    // Missing version.
    let path = dir.join("version.xml");
    std::fs::write(&path, "<scene>\n</scene>\n").unwrap();
    assert!(load(&path)
        .unwrap_err()
        .to_string()
        .contains("missing attribute \"version\""));
}

/// A value element (`<float>`, `<rgb>`, `<lookat>`, `<ref>`, `<default>` …) with a child element
/// is an error at the child, not a silently ignored child; lenient mode warns instead.
#[test]
fn children_of_value_elements_are_errors() {
    let dir = temp_dir("leaf-children");
    let cases = [
        ("float", "<shape type=\"sphere\"><float name=\"radius\" value=\"1\">\n<rgb name=\"x\" value=\"1\"/></float></shape>"),
        ("lookat", "<shape type=\"sphere\"><transform name=\"to_world\"><lookat origin=\"0,0,1\" target=\"0,0,0\">\n<shape type=\"bogus\"/></lookat></transform></shape>"),
        ("ref", "<bsdf type=\"diffuse\" id=\"b\"/><shape type=\"sphere\"><ref id=\"b\">\n<float name=\"x\" value=\"1\"/></ref></shape>"),
        ("default", "<default name=\"r\" value=\"1\">\n<float name=\"x\" value=\"1\"/></default>"),
    ];
    for (i, (tag, xml)) in cases.iter().enumerate() {
        let body = format!("{SENSOR}\n{xml}");
        let path = write_scene(&dir, &format!("leaf{i}.xml"), &body);
        // The child sits on the line after the value element.
        let line = body.lines().count() + 1;
        assert_error_at(&path, line, &format!("<{tag}> takes no child elements"));
        let lenient = load_scene(&path, &[], true);
        if *tag != "lookat" {
            let scene = lenient.unwrap_or_else(|e| panic!("lenient {tag}: {e}"));
            assert!(
                scene
                    .warnings
                    .iter()
                    .any(|w| w.contains("takes no child elements")),
                "{:?}",
                scene.warnings
            );
        }
    }
}

/// Elements nested absurdly deep are an error naming the file and line, not a stack overflow.
#[test]
fn absurdly_deep_nesting_is_an_error() {
    let dir = temp_dir("deep-nesting");
    let depth = 5000;
    let body = format!(
        "{SENSOR}\n{}{}",
        "<bsdf type=\"twosided\">".repeat(depth),
        "</bsdf>".repeat(depth)
    );
    let err = load(&write_scene(&dir, "deep.xml", &body)).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("deep.xml:") && msg.contains("nested deeper than"),
        "{msg}"
    );
    // Realistic nesting (a blend of two-sided BSDFs with textures) still loads.
    let body = format!(
        "{SENSOR}\n<shape type=\"sphere\"><bsdf type=\"blendbsdf\"><float name=\"weight\" value=\"0.5\"/>\
         <bsdf type=\"twosided\"><bsdf type=\"diffuse\"><texture type=\"checkerboard\" name=\"reflectance\">\
         <transform name=\"to_uv\"><scale x=\"2\" y=\"2\"/></transform></texture></bsdf></bsdf>\
         <bsdf type=\"diffuse\"/></bsdf></shape>"
    );
    load(&write_scene(&dir, "ok.xml", &body)).unwrap();
}

/// Unknown plugins are errors at their element in strict mode and warnings naming file and line
/// in lenient mode; malformed values stay errors naming file, line, element and value.
#[test]
fn lenient_turns_unknown_plugins_and_parameters_into_warnings() {
    let dir = temp_dir("lenient");
    let body = format!(
        "{SENSOR}\n<bsdf type=\"foo\" id=\"m\"/>\n<shape type=\"sphere\"><ref id=\"m\"/>\n<float name=\"wobble\" value=\"1\"/></shape>\n<shape type=\"teapot\"/>"
    );
    let path = write_scene(&dir, "scene.xml", &body);
    // Strict: the first unknown plugin is an error at its own element.
    assert_error_at(
        &path,
        line_of(&body, "type=\"foo\""),
        "<bsdf type=\"foo\" id=\"m\">: unknown plugin \"foo\"",
    );
    let scene = load_scene(&path, &[], true).expect("lenient load");
    assert_eq!(scene.shapes.len(), 1);
    assert_eq!(scene.warnings.len(), 3, "{:?}", scene.warnings);
    assert!(scene.warnings[0].contains("scene.xml:4:") && scene.warnings[0].contains("\"foo\""));
    // Malformed values stay errors even in lenient mode.
    let body =
        format!("{SENSOR}\n<shape type=\"sphere\"><float name=\"radius\" value=\"x\"/></shape>");
    let path = write_scene(&dir, "bad.xml", &body);
    let err = load_scene(&path, &[], true).expect_err("a malformed radius must not load");
    let msg = err.to_string();
    let line = line_of(&body, "name=\"radius\"");
    assert_eq!(
        err.location().map(|l| l.line as usize),
        Some(line),
        "wrong line in: {msg}"
    );
    assert!(
        msg.contains(&format!("bad.xml:{line}:"))
            && msg.contains("<float name=\"radius\">")
            && msg.contains("could not parse floating point value \"x\""),
        "no file:line, element or value in: {msg}"
    );
}

#[test]
fn default_parameters_and_command_line_overrides() {
    let dir = temp_dir("defaults");
    let body = r#"<default name="res" value="32"/>
<default name="spp" value="64"/>
<default name="col" value="0.25"/>
<sensor type="perspective"><float name="fov" value="$fov_deg"/>
  <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
  <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="${res}"/></film>
</sensor>
<bsdf type="diffuse" id="d"><rgb name="reflectance" value="$col, 0.5, $col"/></bsdf>"#;
    // `${res}` is not Mitsuba syntax: "$" must be followed by a name.
    let path = write_scene(&dir, "scene.xml", body);
    let fov = [("fov_deg".to_owned(), "30".to_owned())];
    assert!(load_scene(&path, &fov, false)
        .unwrap_err()
        .to_string()
        .contains("must be followed by a parameter name"));
    let body = body.replace("${res}", "$res");
    let path = write_scene(&dir, "scene.xml", &body);
    // Without -D fov_deg the file does not load.
    assert!(load(&path)
        .unwrap_err()
        .to_string()
        .contains("undefined parameter \"$fov_deg\""));
    let scene = load_scene(&path, &fov, false).unwrap();
    assert_eq!((scene.camera.width, scene.camera.height), (32, 32));
    assert_eq!(scene.camera.fov, 30.0);
    assert_eq!(scene.sample_count, Some(64));
    let Bsdf::Diffuse(d) = &scene.bsdfs[0] else {
        panic!("diffuse expected")
    };
    assert_eq!(d.reflectance.mean(), Vec3::new(0.25, 0.5, 0.25));
    // Command-line values override the file's defaults.
    let overrides = [
        fov[0].clone(),
        ("res".to_owned(), "8".to_owned()),
        ("spp".to_owned(), "4".to_owned()),
    ];
    let scene = load_scene(&path, &overrides, false).unwrap();
    assert_eq!(
        (scene.camera.width, scene.camera.height, scene.sample_count),
        (8, 8, Some(4))
    );
    // A longer parameter name is not confused with a shorter one.
    let params: HashMap<String, String> =
        [("a".into(), "1".into()), ("ab".into(), "2".into())].into();
    let mut used = std::collections::HashSet::new();
    assert_eq!(substitute("$ab-$a", &params, &mut used).unwrap(), "2-1");
    assert_eq!(used.len(), 2);
    // A define no `$name` reads is reported (a misspelt name would otherwise go unnoticed).
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let typo = [fov[0].clone(), ("rez".to_owned(), "64".to_owned())];
    let scene = load_scene(&path, &typo, false).unwrap();
    assert_eq!(scene.warnings.len(), 1, "{:?}", scene.warnings);
    assert!(
        scene.warnings[0].contains("-D rez=64") && scene.warnings[0].contains("changes nothing"),
        "{:?}",
        scene.warnings
    );
}

/// Parses `<transform>` children given as text.
fn transform_of(ops: &str) -> Mat4 {
    let dir = temp_dir(&format!(
        "transform-{:x}",
        ops.len() * 31 + ops.bytes().map(|b| b as usize).sum::<usize>()
    ));
    let body = format!(
        "<sensor type=\"perspective\"><transform name=\"to_world\">{ops}</transform></sensor>\n<emitter type=\"point\"><transform name=\"to_world\">{ops}</transform></emitter>"
    );
    let path = write_scene(&dir, "t.xml", &body);
    let scene = load_scene(&path, &[], false);
    // Sensors reject scaling, so read the matrix through a rectangle too.
    let rect =
        format!("<shape type=\"rectangle\"><transform name=\"to_world\">{ops}</transform></shape>");
    let path2 = write_scene(&dir, "r.xml", &format!("{SENSOR}\n{rect}"));
    let rs = load(&path2).unwrap();
    let Geometry::Mesh(m) = &rs.shapes[0].geometry else {
        panic!()
    };
    // Recover the affine matrix from the rectangle's corners (-1,-1,0), (1,-1,0), (-1,1,0) and
    // the camera/point light when available.
    let origin = (m.positions[0] + m.positions[2]) * 0.5;
    let x = (m.positions[1] - m.positions[0]) * 0.5;
    let y = (m.positions[3] - m.positions[0]) * 0.5;
    match scene {
        Ok(s) => {
            assert!(
                (s.camera.to_world.w_axis.truncate() - origin)
                    .abs()
                    .max_element()
                    < 1e-4
            );
            s.camera.to_world
        }
        Err(_) => Mat4::from_cols(x.extend(0.0), y.extend(0.0), Vec4::ZERO, origin.extend(1.0)),
    }
}

fn assert_mat_close(a: Mat4, b: Mat4) {
    assert!(a.abs_diff_eq(b, 1e-5), "\n{a}\n!=\n{b}");
}

#[test]
fn transforms_compose_in_file_order() {
    let mut diag = Diagnostics::default();
    let parse = |ops: &str, diag: &mut Diagnostics| {
        let dir = temp_dir("compose");
        let path = dir.join("t.xml");
        std::fs::write(
            &path,
            format!("<transform name=\"to_world\">{ops}</transform>"),
        )
        .unwrap();
        let mut params = HashMap::new();
        let el = read_file(&path, &mut params, 0, diag).unwrap();
        transform::parse_transform(&el, diag).unwrap()
    };
    // translate then scale: S·T, so the translation is scaled too.
    let m = parse(
        r#"<translate x="1" y="2" z="3"/><scale value="2"/>"#,
        &mut diag,
    );
    #[rustfmt::skip]
    let expected = Mat4::from_cols_array(&[
        2.0, 0.0, 0.0, 0.0,
        0.0, 2.0, 0.0, 0.0,
        0.0, 0.0, 2.0, 0.0,
        2.0, 4.0, 6.0, 1.0,
    ]);
    assert_mat_close(m, expected);
    // scale then translate: T·S.
    let m = parse(
        r#"<scale x="2" y="3"/><translate value="1, 2, 3"/>"#,
        &mut diag,
    );
    let expected = Mat4::from_cols(
        Vec4::new(2.0, 0.0, 0.0, 0.0),
        Vec4::new(0.0, 3.0, 0.0, 0.0),
        Vec4::Z,
        Vec4::new(1.0, 2.0, 3.0, 1.0),
    );
    assert_mat_close(m, expected);
    // rotate 90° about z, then translate x: (1,0,0) → (0,1,0) → (1,1,0).
    let m = parse(r#"<rotate z="1" angle="90"/><translate x="1"/>"#, &mut diag);
    assert!((m.transform_point3(Vec3::X) - Vec3::new(1.0, 1.0, 0.0)).length() < 1e-6);
    // translate then rotate: (1,0,0) → (2,0,0) → (0,2,0).
    let m = parse(
        r#"<translate x="1"/><rotate value="0 0 1" angle="90"/>"#,
        &mut diag,
    );
    assert!((m.transform_point3(Vec3::X) - Vec3::new(0.0, 2.0, 0.0)).length() < 1e-6);
    // matrix is row-major.
    let m = parse(
        r#"<matrix value="1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1"/>"#,
        &mut diag,
    );
    assert_mat_close(m, Mat4::from_translation(Vec3::new(5.0, 6.0, 7.0)));
    // lookat: looking from (0,0,-5) at the origin with y up gives left = +x... as Mitsuba:
    // dir = +z, left = up × dir = y × z = +x, up' = dir × left = z × x = +y.
    let m = parse(
        r#"<lookat origin="0, 0, -5" target="0, 0, 0" up="0, 1, 0"/>"#,
        &mut diag,
    );
    assert_mat_close(m, Mat4::from_translation(Vec3::new(0.0, 0.0, -5.0)));
    // Looking along −x from (3, 0, 0): dir = −x, left = y × (−x) = +z, up' = (−x) × z = +y.
    let m = parse(
        r#"<lookat origin="3, 0, 0" target="0, 0, 0" up="0, 1, 0"/>"#,
        &mut diag,
    );
    let expected = Mat4::from_cols(Vec4::Z, Vec4::Y, -Vec4::X, Vec4::new(3.0, 0.0, 0.0, 1.0));
    assert_mat_close(m, expected);
    // lookat, then translate: the camera moves in world space.
    let m = parse(
        r#"<lookat origin="3, 0, 0" target="0, 0, 0" up="0, 1, 0"/><translate y="1"/>"#,
        &mut diag,
    );
    assert_mat_close(m, Mat4::from_translation(Vec3::Y) * expected);
    // Without `up`, or with a zero one, Mitsuba's parser completes the view direction with its
    // coordinate_system: the frame (and so a camera's picture, a spot's slide) is Mitsuba's.
    // Rows of the 3×4 part as Mitsuba 3.9.1 loads them (`sensor.world_transform()`).
    for (op, rows) in [
        (
            r#"<lookat origin="0.374, 2.820, 0.452" target="0, 0, 0"/>"#,
            [
                [-0.10988, 0.985427, -0.129844, 0.374],
                [0.171496, -0.10988, -0.979038, 2.82],
                [-0.979038, -0.129844, -0.156924, 0.452],
            ],
        ),
        (
            r#"<lookat origin="1, -2, 3" target="0.5, 0.5, -1"/>"#,
            [
                [0.03014, 0.993972, -0.105409, 1.0],
                [0.849302, 0.03014, 0.527046, -2.0],
                [0.527046, -0.105409, -0.843274, 3.0],
            ],
        ),
        (
            r#"<lookat origin="0, 0, 0" target="0.2, 0.3, -5" up="0, 0, 0"/>"#,
            [
                [-0.001195, 0.999203, 0.039896, 0.0],
                [0.998207, -0.001195, 0.059845, 0.0],
                [0.059845, 0.039896, -0.99741, 0.0],
            ],
        ),
    ] {
        let m = parse(op, &mut diag);
        for (r, row) in rows.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                assert!(
                    (m.col(c)[r] - v).abs() < 2e-6,
                    "{op}: [{r}][{c}] {} vs {v}",
                    m.col(c)[r]
                );
            }
        }
    }
    assert!(diag.warnings.is_empty());
    // Through a whole scene: the camera's to_world and a rectangle's corners agree.
    let m = transform_of(r#"<rotate x="1" angle="30"/><translate x="1" y="-2"/>"#);
    let expected = Mat4::from_translation(Vec3::new(1.0, -2.0, 0.0))
        * Mat4::from_rotation_x(30f32.to_radians());
    assert_mat_close(m, expected);
}

/// Writes a mesh file and loads it as the only shape of a scene.
fn load_mesh(dir: &Path, file: &str, contents: &str, extra: &str) -> TriangleMesh {
    std::fs::write(dir.join(file), contents).unwrap();
    let kind = if file.ends_with(".obj") { "obj" } else { "ply" };
    let body = format!("{SENSOR}\n<shape type=\"{kind}\"><string name=\"filename\" value=\"{file}\"/>{extra}</shape>");
    let scene = load(&write_scene(dir, "scene.xml", &body)).unwrap();
    match &scene.shapes[0].geometry {
        Geometry::Mesh(m) => m.clone(),
        other => panic!("mesh expected, got {other:?}"),
    }
}

/// A quad with a lifted corner: v0 is shared by both triangles, whose normals are +z and
/// (1, −1, 1)/√3 with corner angles 45° and 60° at v0 (hand-computed below).
const QUAD_OBJ: &str =
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 0.75\nf 1/1 2/2 3/3 4/4\n";

#[test]
fn obj_without_normals_gets_angle_weighted_smooth_normals() {
    let dir = temp_dir("obj-smooth");
    let m = load_mesh(&dir, "quad.obj", QUAD_OBJ, "");
    assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
    let n = m.normals.as_ref().expect("smooth normals");
    // v0: (π/4)·ẑ + (π/3)·(1, −1, 1)/√3, normalised (Mitsuba prints 0.3705, −0.3705, 0.8518).
    let a = std::f32::consts::FRAC_PI_4 * Vec3::Z
        + std::f32::consts::FRAC_PI_3 * Vec3::new(1.0, -1.0, 1.0) / 3f32.sqrt();
    assert!((n[0] - a.normalize()).length() < 1e-5, "{}", n[0]);
    assert!((n[0] - Vec3::new(0.3705, -0.3705, 0.8518)).length() < 1e-3);
    assert!((n[1] - Vec3::Z).length() < 1e-6);
    assert!((n[3] - Vec3::new(1.0, -1.0, 1.0).normalize()).length() < 1e-6);
    // OBJ texture coordinates are stored as (u, 1 − v).
    let uv = m.uvs.as_ref().unwrap();
    assert_eq!(uv[0], Vec2::new(0.0, 1.0));
    assert_eq!(uv[3], Vec2::new(0.0, 0.25));
    // face_normals: no vertex normals at all.
    let m = load_mesh(
        &dir,
        "quad.obj",
        QUAD_OBJ,
        r#"<boolean name="face_normals" value="true"/>"#,
    );
    assert!(m.normals.is_none());
    // flip_normals negates the normals and keeps the vertex order, as Mitsuba (the order
    // parameterises meshes without uvs: shapes::mesh's `flipped_mesh_keeps_its_parameterisation`).
    let m = load_mesh(
        &dir,
        "quad.obj",
        QUAD_OBJ,
        r#"<boolean name="flip_normals" value="true"/>"#,
    );
    assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
    assert!(m.flipped);
    assert!((m.normals.unwrap()[1] + Vec3::Z).length() < 1e-6);
}

#[test]
fn obj_with_normals_keeps_them_and_transforms_by_inverse_transpose() {
    let dir = temp_dir("obj-normals");
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 1 0 1\nvn 0 0 1\nvn 0 0 1\nf 1//1 2//2 3//3\n";
    let m = load_mesh(&dir, "tri.obj", obj, "");
    let n = m.normals.as_ref().unwrap();
    assert!((n[0] - Vec3::new(1.0, 0.0, 1.0).normalize()).length() < 1e-6);
    assert!(m.uvs.is_none());
    // Non-uniform scale: positions scale by (2, 1, 1); normals by the inverse transpose
    // (1/2, 1, 1), renormalised: (1, 0, 1) → (0.5, 0, 1)/|…|.
    let m = load_mesh(
        &dir,
        "tri.obj",
        obj,
        r#"<transform name="to_world"><scale x="2"/></transform>"#,
    );
    assert_eq!(m.positions[1], Vec3::new(2.0, 0.0, 0.0));
    let n = m.normals.as_ref().unwrap();
    assert!(
        (n[0] - Vec3::new(0.5, 0.0, 1.0).normalize()).length() < 1e-6,
        "{}",
        n[0]
    );
    // face_normals drops file normals too.
    let m = load_mesh(
        &dir,
        "tri.obj",
        obj,
        r#"<boolean name="face_normals" value="true"/>"#,
    );
    assert!(m.normals.is_none());
    // Malformed OBJ: an error naming the mesh file, its line and the XML line.
    std::fs::write(dir.join("bad.obj"), "v 0 0 0\n# only one vertex\nf 1 2 3\n").unwrap();
    let body = format!(
        "{SENSOR}\n<shape type=\"obj\"><string name=\"filename\" value=\"bad.obj\"/></shape>"
    );
    let err = load(&write_scene(&dir, "bad.xml", &body))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("bad.xml:4:")
            && err.contains("bad.obj")
            && err.contains("line 3: face vertex index out of bounds: `f 1 2 3`"),
        "{err}"
    );
}

#[test]
fn ply_ascii_and_binary_with_and_without_normals() {
    let dir = temp_dir("ply");
    let header = |props: &str, nv: usize, nf: usize, fmt: &str| {
        format!("ply\nformat {fmt} 1.0\nelement vertex {nv}\n{props}element face {nf}\nproperty list uchar int vertex_indices\nend_header\n")
    };
    let xyz = "property float x\nproperty float y\nproperty float z\n";
    // A quad (4 corners → 2 triangles) with uv, no normals: smooth normals, uv kept as is.
    let ply = header(
        &format!("{xyz}property float u\nproperty float v\n"),
        4,
        1,
        "ascii",
    ) + "0 0 0 0 0.25\n1 0 0 1 0.25\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n";
    let m = load_mesh(&dir, "quad.ply", &ply, "");
    assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
    assert!(m
        .normals
        .as_ref()
        .unwrap()
        .iter()
        .all(|n| (*n - Vec3::Z).length() < 1e-6));
    assert_eq!(m.uvs.as_ref().unwrap()[0], Vec2::new(0.0, 0.25));
    let m = load_mesh(
        &dir,
        "quad.ply",
        &ply,
        r#"<boolean name="face_normals" value="true"/>"#,
    );
    assert!(m.normals.is_none());
    // With normals, binary little-endian.
    let mut bin = header(
        &format!("{xyz}property float nx\nproperty float ny\nproperty float nz\n"),
        3,
        1,
        "binary_little_endian",
    )
    .into_bytes();
    for v in [
        [0.0f32, 0.0, 0.0, 0.0, 1.0, 0.0],
        [1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, -1.0, 0.0, 1.0, 0.0],
    ] {
        for x in v {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    bin.push(3);
    for i in [0i32, 1, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(dir.join("tri.ply"), &bin).unwrap();
    let body = format!("{SENSOR}\n<shape type=\"ply\"><string name=\"filename\" value=\"tri.ply\"/><transform name=\"to_world\"><translate y=\"2\"/></transform></shape>");
    let scene = load(&write_scene(&dir, "bin.xml", &body)).unwrap();
    let Geometry::Mesh(m) = &scene.shapes[0].geometry else {
        panic!()
    };
    assert_eq!(m.positions[2], Vec3::new(0.0, 2.0, -1.0));
    assert_eq!(m.normals.as_ref().unwrap()[1], Vec3::Y);
    // An out-of-range face index is an error, not a panic.
    let bad = header(xyz, 3, 1, "ascii") + "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n";
    std::fs::write(dir.join("bad.ply"), bad).unwrap();
    let body = format!(
        "{SENSOR}\n<shape type=\"ply\"><string name=\"filename\" value=\"bad.ply\"/></shape>"
    );
    let err = load(&write_scene(&dir, "bad.xml", &body))
        .unwrap_err()
        .to_string();
    assert!(err.contains("vertex 7") && err.contains("bad.ply"), "{err}");
    // A binary file cut short names the element it ends in.
    std::fs::write(dir.join("cut.ply"), &bin[..bin.len() - 30]).unwrap();
    let body = format!(
        "{SENSOR}\n<shape type=\"ply\"><string name=\"filename\" value=\"cut.ply\"/></shape>"
    );
    let err = load(&write_scene(&dir, "cut.xml", &body))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("cut.ply") && err.contains("unexpected end of file in element"),
        "{err}"
    );
}

/// Writes the triangle mesh `parts/meshes/tri.obj` under `dir`.
fn write_part_triangle(dir: &Path) {
    std::fs::create_dir_all(dir.join("parts/meshes")).unwrap();
    std::fs::write(
        dir.join("parts/meshes/tri.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
}

#[test]
fn include_and_references_across_files() {
    let dir = temp_dir("include");
    write_part_triangle(&dir);
    // A name in the included file that only its own folder has is found there (as a last
    // resort: names_in_included_files_resolve_against_the_scene_folder).
    std::fs::write(
        dir.join("parts/materials.xml"),
        "<scene version=\"3.0.0\">\n<bsdf type=\"conductor\" id=\"gold\"><string name=\"material\" value=\"Au\"/></bsdf>\n<shape type=\"obj\"><string name=\"filename\" value=\"meshes/tri.obj\"/><ref id=\"gold\"/></shape>\n</scene>\n",
    )
    .unwrap();
    let body = format!("{SENSOR}\n<include filename=\"parts/materials.xml\"/>\n<shape type=\"sphere\"><ref id=\"gold\"/></shape>");
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert_eq!(scene.shapes.len(), 2);
    assert_eq!(scene.shapes[0].bsdf, scene.shapes[1].bsdf);
    let Bsdf::Conductor(c) = &scene.bsdfs[scene.shapes[1].bsdf] else {
        panic!("conductor expected")
    };
    assert_eq!(c.ior, ior::conductor_ior("Au"));
    // A missing include and an error inside an included file are both located.
    let body = format!("{SENSOR}\n<include filename=\"nope.xml\"/>");
    assert_body_error_at(&dir, "missing.xml", &body, "nope", "included file");
    std::fs::write(
        dir.join("parts/broken.xml"),
        "<scene version=\"3.0.0\">\n\n<bsdf type=\"velvet\"/>\n</scene>\n",
    )
    .unwrap();
    let body = format!("{SENSOR}\n<include filename=\"parts/broken.xml\"/>");
    let err = load(&write_scene(&dir, "broken.xml", &body))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("broken.xml:3:") && err.contains("velvet"),
        "{err}"
    );
    // An include cycle ends with an error.
    std::fs::write(
        dir.join("self.xml"),
        "<scene version=\"3.0.0\">\n<include filename=\"self.xml\"/>\n</scene>\n",
    )
    .unwrap();
    assert!(load(&dir.join("self.xml"))
        .unwrap_err()
        .to_string()
        .contains("nested deeper"));
}

#[test]
fn scene_files_lists_the_xml_its_includes_and_every_named_file() {
    let dir = temp_dir("scene-files");
    write_part_triangle(&dir);
    // An included file with nothing but a <default> still decides the image.
    std::fs::write(
        dir.join("parts/defaults.xml"),
        "<scene version=\"3.0.0\">\n<default name=\"mesh\" value=\"tri\"/>\n</scene>\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("parts/shapes.xml"),
        "<scene version=\"3.0.0\">\n<shape type=\"obj\"><string name=\"filename\" value=\"meshes/$mesh.obj\"/></shape>\n</scene>\n",
    )
    .unwrap();
    let body = format!(
        "{SENSOR}\n<include filename=\"parts/defaults.xml\"/>\n<include filename=\"parts/shapes.xml\"/>\n\
         <bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\"><string name=\"filename\" value=\"wood.png\"/></texture></bsdf>\n\
         <bsdf type=\"diffuse\"><spectrum name=\"reflectance\" filename=\"paint.spd\"/></bsdf>\n\
         <shape type=\"obj\"><string name=\"filename\" value=\"parts/meshes/tri.obj\"/></shape>"
    );
    let xml = write_scene(&dir, "scene.xml", &body);
    let files = scene_files(&xml, &[]).unwrap();
    let expected: Vec<PathBuf> = [
        "scene.xml",
        "parts/defaults.xml",
        "parts/shapes.xml",
        // Resolved against the file that names it; the second mention is not repeated.
        "parts/meshes/tri.obj",
        // Named files that do not exist are listed all the same.
        "wood.png",
        "paint.spd",
    ]
    .iter()
    .map(|f| dir.join(f))
    .collect();
    assert_eq!(files, expected);
    // `-D` overrides reach the names.
    let files = scene_files(&xml, &[("mesh".into(), "quad".into())]).unwrap();
    assert_eq!(files[3], dir.join("parts/meshes/quad.obj"));
    // An unreadable scene file is an error naming it.
    let err = scene_files(&dir.join("nope.xml"), &[])
        .unwrap_err()
        .to_string();
    assert!(err.contains("nope.xml"), "{err}");
}

#[test]
fn bsdf_defaults_follow_mitsuba() {
    let dir = temp_dir("bsdf-defaults");
    let body = format!(
        "{SENSOR}
<bsdf type=\"diffuse\"/>
<bsdf type=\"dielectric\"/>
<bsdf type=\"roughconductor\"/>
<bsdf type=\"plastic\"/>
<bsdf type=\"roughdielectric\"><string name=\"distribution\" value=\"ggx\"/><float name=\"alpha_u\" value=\"0.2\"/><float name=\"alpha_v\" value=\"0.3\"/><string name=\"int_ior\" value=\"water\"/><float name=\"ext_ior\" value=\"1\"/></bsdf>
<bsdf type=\"twosided\"><bsdf type=\"roughplastic\"><float name=\"alpha\" value=\"0.4\"/></bsdf></bsdf>
<bsdf type=\"conductor\"><rgb name=\"eta\" value=\"0.2, 0.9, 1.1\"/><rgb name=\"k\" value=\"3.9, 2.4, 2.1\"/></bsdf>
<bsdf type=\"diffuse\"><texture type=\"checkerboard\" name=\"reflectance\"><transform name=\"to_uv\"><scale x=\"4\" y=\"2\"/></transform></texture></bsdf>
<shape type=\"sphere\"><bsdf type=\"thindielectric\" name=\"bsdf\"/></shape>"
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    let b = &scene.bsdfs;
    let Bsdf::Diffuse(d) = &b[0] else { panic!() };
    assert_eq!(d.reflectance.mean(), Vec3::splat(0.5));
    let Bsdf::Dielectric(d) = &b[1] else { panic!() };
    assert!((d.eta - 1.5046 / 1.000_277).abs() < 1e-6);
    let Bsdf::RoughConductor(c) = &b[2] else {
        panic!()
    };
    assert_eq!(
        (c.roughness.kind, c.roughness.alpha_u, c.roughness.alpha_v),
        (MicrofacetKind::Beckmann, 0.1, 0.1)
    );
    assert!(
        c.ior.is_none(),
        "material defaults to \"none\": a perfect mirror"
    );
    let Bsdf::Plastic(p) = &b[3] else { panic!() };
    assert!((p.eta - 1.49 / 1.000_277).abs() < 1e-6);
    assert_eq!(p.diffuse_reflectance.mean(), Vec3::splat(0.5));
    let Bsdf::RoughDielectric(r) = &b[4] else {
        panic!()
    };
    assert_eq!(
        (r.roughness.kind, r.roughness.alpha_u, r.roughness.alpha_v),
        (MicrofacetKind::Ggx, 0.2, 0.3)
    );
    assert!((r.eta - 1.333).abs() < 1e-6);
    // The twosided wraps its anonymous roughplastic (which is no scene material itself).
    let Bsdf::TwoSided { front, back } = &b[5] else {
        panic!("{:?}", b[5])
    };
    assert!(matches!(**front, Bsdf::RoughPlastic(_)) && matches!(**back, Bsdf::RoughPlastic(_)));
    let Bsdf::Conductor(c) = &b[6] else { panic!() };
    assert_eq!(c.ior.unwrap().eta, Vec3::new(0.2, 0.9, 1.1));
    // A nested BSDF may carry a name attribute.
    assert!(matches!(b[scene.shapes[0].bsdf], Bsdf::ThinDielectric(_)));
    let Bsdf::Diffuse(d) = &b[7] else { panic!() };
    let Texture::Checkerboard {
        color0,
        color1,
        to_uv,
    } = &d.reflectance
    else {
        panic!()
    };
    assert_eq!((*color0, *color1), (Vec3::splat(0.4), Vec3::splat(0.2)));
    assert_eq!(*to_uv * Vec3::new(1.0, 1.0, 1.0), Vec3::new(4.0, 2.0, 1.0));
}

#[test]
fn spectra_emitters_and_cameras() {
    let dir = temp_dir("spectra");
    let body = r#"<sensor type="thinlens">
  <float name="fov" value="30"/><string name="fov_axis" value="smaller"/>
  <float name="aperture_radius" value="0.1"/><float name="focus_distance" value="4"/>
  <transform name="to_world"><lookat origin="0, 0, -5" target="0, 0, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><rfilter type="gaussian"/></film>
</sensor>
<integrator type="path"><integer name="max_depth" value="8"/></integrator>
<shape type="sphere">
  <bsdf type="diffuse"><spectrum name="reflectance" value="400:1, 700:1"/></bsdf>
  <emitter type="area"><spectrum name="radiance" value="3"/></emitter>
</shape>
<emitter type="spot"><rgb name="intensity" value="5"/><float name="cutoff_angle" value="40"/></emitter>
<emitter type="directional"><vector name="direction" value="0, -2, 0"/></emitter>
<emitter type="point"><point name="position" x="1" y="2" z="3"/><spectrum name="intensity" value="400:1, 700:1"/></emitter>"#;
    let scene = load(&write_scene(&dir, "scene.xml", body)).unwrap();
    let c = &scene.camera;
    assert_eq!(
        (c.width, c.height, c.fov, c.fov_axis),
        (768, 576, 30.0, FovAxis::Smaller)
    );
    assert_eq!((c.aperture_radius, c.focus_distance), (0.1, 4.0));
    assert_eq!(
        scene.integrator.as_ref().map(|i| (i.max_depth, i.rr_depth)),
        Some((8, 5))
    );
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    // `volpath` and `volpathmis` (the volumetric path tracer), `prb` and `prb_basic` (`path`
    // when rendering forward), `direct`: all known, no warnings.
    for kind in ["volpath", "volpathmis", "prb", "prb_basic", "direct"] {
        let other = body.replace(
            r#"<integrator type="path">"#,
            &format!(r#"<integrator type="{kind}">"#),
        );
        let scene = load(&write_scene(&dir, &format!("{kind}.xml"), &other)).unwrap();
        let integrator = scene.integrator.as_ref().unwrap();
        assert_eq!((integrator.kind.as_str(), integrator.max_depth), (kind, 8));
        assert_eq!(
            (integrator.emitter_samples, integrator.bsdf_samples),
            (1, 1)
        );
        assert!(scene.warnings.is_empty(), "{kind}: {:?}", scene.warnings);
    }
    assert_eq!(c.filter, FilterDesc::Gaussian { stddev: 0.5 });
    // A constant reflectance spectrum of one is white.
    let Bsdf::Diffuse(d) = &scene.bsdfs[0] else {
        panic!()
    };
    assert!((d.reflectance.mean() - Vec3::ONE).abs().max_element() < 1e-2);
    // A uniform emission spectrum is D65-unbalanced (Mitsuba: 3.614, 2.845, 2.727).
    let e = scene.shapes[0].emission.as_ref().unwrap().mean();
    assert!(
        (e - Vec3::new(3.61438, 2.84487, 2.72675))
            .abs()
            .max_element()
            < 1e-3,
        "{e}"
    );
    match &scene.emitters[..] {
        [EmitterDesc::Spot {
            intensity,
            cutoff_angle,
            beam_width,
            ..
        }, EmitterDesc::Directional {
            direction,
            irradiance,
        }, EmitterDesc::Point {
            position,
            intensity: pi,
        }] => {
            assert_eq!(
                (*intensity, *cutoff_angle, *beam_width),
                (Vec3::splat(5.0), 40.0, 30.0)
            );
            assert_eq!((*direction, *irradiance), (-Vec3::Y, Vec3::ONE));
            assert_eq!(*position, Vec3::new(1.0, 2.0, 3.0));
            // An emission spectrum of one over 400–700 nm (Mitsuba: 1.1997, 0.9495, 0.9034).
            assert!(
                (*pi - Vec3::new(1.19969, 0.94952, 0.903443))
                    .abs()
                    .max_element()
                    < 1e-3,
                "{pi}"
            );
        }
        other => panic!("unexpected emitters {other:?}"),
    }
}

#[test]
fn never_panics_on_garbage() {
    let dir = temp_dir("garbage");
    let cases = [
        "",
        "<",
        "<scene/>",
        "<scene version=\"3.0.0\"><shape/></scene>",
        "<scene version=\"3.0.0\"><shape type=\"sphere\"><float/></shape></scene>",
        "<scene version=\"3.0.0\"><shape type=\"cube\"><transform name=\"to_world\"><scale value=\"0\"/></transform></shape></scene>",
        "<scene version=\"3.0.0\"><sensor type=\"perspective\"><float name=\"fov\" value=\"inf\"/></sensor></scene>",
        "<scene version=\"3.0.0\"><sensor type=\"perspective\"><film type=\"hdrfilm\"><integer name=\"width\" value=\"-4\"/></film></sensor></scene>",
        "<scene version=\"3.0.0\"><shape type=\"sphere\"><transform name=\"to_world\"><lookat origin=\"0,0,0\" target=\"0,0,0\"/></transform></shape></scene>",
        "<scene version=\"3.0.0\"><bsdf type=\"twosided\"/></scene>",
        "<scene version=\"3.0.0\"><bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\"><string name=\"filename\" value=\"none.png\"/></texture></bsdf></scene>",
        "<scene version=\"3.0.0\"><shape type=\"obj\"><string name=\"filename\" value=\".\"/></shape></scene>",
        "<scene version=\"x\"></scene>",
        "<scene version=\"3.0.0\"><default name=\"\" value=\"1\"/></scene>",
        "<scene version=\"3.0.0\"><emitter type=\"area\"/></scene>",
    ];
    for (i, text) in cases.iter().enumerate() {
        let path = dir.join(format!("g{i}.xml"));
        std::fs::write(&path, text).unwrap();
        let result = std::panic::catch_unwind(|| load_scene(&path, &[], false));
        match result {
            Ok(Ok(_)) if i == 5 => {} // a flat cube is legal
            Ok(Ok(_)) => panic!("case {i} should fail: {text}"),
            Ok(Err(e)) => assert!(
                e.to_string().contains(&format!("g{i}.xml")),
                "case {i}: {e}"
            ),
            Err(_) => panic!("case {i} panicked: {text}"),
        }
    }
}

#[test]
fn bitmap_texture_loads_relative_to_the_xml_file() {
    let dir = temp_dir("bitmap");
    std::fs::create_dir_all(dir.join("tex")).unwrap();
    let pixels = [Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
    crate::image_io::write_png_srgb(&dir.join("tex/a.png"), 2, 1, &pixels).unwrap();
    crate::image_io::write_rgb_exr(
        &dir.join("tex/b.exr"),
        2,
        1,
        &[Vec3::splat(2.0), Vec3::splat(4.0)],
    )
    .unwrap();
    let body = format!(
        "{SENSOR}
<texture type=\"bitmap\" id=\"a\"><string name=\"filename\" value=\"tex/a.png\"/><string name=\"filter_type\" value=\"nearest\"/></texture>
<bsdf type=\"diffuse\"><ref name=\"reflectance\" id=\"a\"/></bsdf>
<bsdf type=\"plastic\"><texture type=\"bitmap\" name=\"diffuse_reflectance\"><string name=\"filename\" value=\"tex/b.exr\"/></texture></bsdf>"
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    let Bsdf::Diffuse(d) = &scene.bsdfs[0] else {
        panic!()
    };
    let Texture::Bitmap { image, filter, .. } = &d.reflectance else {
        panic!()
    };
    assert_eq!(
        (image.width, image.height, *filter),
        (2, 1, crate::texture::BitmapFilter::Nearest)
    );
    assert_eq!(image.texels[0], Vec3::new(1.0, 0.0, 0.0));
    let Bsdf::Plastic(p) = &scene.bsdfs[1] else {
        panic!()
    };
    assert_eq!(p.diffuse_reflectance.mean(), Vec3::splat(3.0));
}

/// The external validation scenes (`<dir>/*/scene.xml`) must load, at least 3 of them. With
/// the environment variable `SPPM_EXTERNAL_SCENES` set (as CI does), `<dir>` is its value and a
/// missing directory or fewer than 3 scenes fail the test; without it, `<dir>` is
/// `<CARGO_MANIFEST_DIR>/../../shared/scenes/external`, and only a missing directory there
/// skips the test (with a message on stderr).
#[test]
fn external_scenes_load() {
    let (root, required) = match std::env::var_os("SPPM_EXTERNAL_SCENES") {
        Some(dir) => (PathBuf::from(dir), true),
        None => (
            PathBuf::from(
                std::env::var_os("CARGO_MANIFEST_DIR")
                    .unwrap_or_else(|| env!("CARGO_MANIFEST_DIR").into()),
            )
            .join("../../shared/scenes/external"),
            false,
        ),
    };
    let entries = match std::fs::read_dir(&root) {
        Ok(entries) => entries,
        Err(e) if required => panic!(
            "SPPM_EXTERNAL_SCENES={}: cannot read the external scenes: {e}",
            root.display()
        ),
        Err(_) => {
            eprintln!(
                "skipped: {} not present (set SPPM_EXTERNAL_SCENES to require it)",
                root.display()
            );
            return;
        }
    };
    let mut loaded = 0;
    for entry in entries.flatten() {
        let path = entry.path().join("scene.xml");
        if !path.is_file() {
            continue;
        }
        let scene = load(&path).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            scene.warnings.is_empty(),
            "{}: {:?}",
            path.display(),
            scene.warnings
        );
        assert_eq!((scene.camera.width, scene.camera.height), (128, 128));
        let name = entry.file_name().to_string_lossy().into_owned();
        match name.as_str() {
            "cbox" => {
                assert_eq!(scene.shapes.len(), 8);
                // Mitsuba 3.9 scalar_rgb: the light's spectrum → (20.7108, 10.8546, 2.77115).
                let e = scene.shapes[0].emission.as_ref().unwrap().mean();
                assert!(
                    (e - Vec3::new(20.7108, 10.8546, 2.77115))
                        .abs()
                        .max_element()
                        < 2e-3,
                    "{e}"
                );
                assert_eq!(scene.camera.fov_axis, FovAxis::Smaller);
                // The light is translated by −0.5 in y (its OBJ sits at y = 548.8).
                let Geometry::Mesh(m) = &scene.shapes[0].geometry else {
                    panic!()
                };
                assert!(m.positions.iter().all(|p| (p.y - 548.3).abs() < 1e-3));
            }
            "veach-mis" => {
                assert_eq!(scene.shapes.len(), 10);
                // The two mirroring scales cancel.
                assert!((scene.camera.to_world.x_axis.truncate().length() - 1.0).abs() < 1e-6);
            }
            "water-caustic" => {
                let water = scene.shapes.iter().find(|s| s.name == "Water").unwrap();
                let Geometry::Mesh(m) = &water.geometry else {
                    panic!()
                };
                assert_eq!((m.positions.len(), m.indices.len()), (63_768, 102_938));
            }
            _ => {}
        }
        loaded += 1;
    }
    assert!(
        loaded >= 3,
        "only {loaded} external scenes (*/scene.xml) found in {}",
        root.display()
    );
}

/// `envmap`: the image is found relative to the scene file, `scale` and `to_world` are read
/// (the rotation part; a translation is irrelevant at infinity), `mis_compensation` is ignored
/// with a warning; bad values are reported at their own element's line.
#[test]
fn envmap_loads_and_reports_bad_parameters_by_line() {
    use crate::texture::Bitmap;
    let dir = temp_dir("envmap");
    let texels = vec![Rgb::new(1.0, 2.0, 3.0); 8];
    crate::image_io::write_rgb_exr(&dir.join("sky.exr"), 4, 2, &texels).unwrap();
    let body = format!(
        "{SENSOR}\n<emitter type=\"envmap\">\n<string name=\"filename\" value=\"sky.exr\"/>\n\
         <float name=\"scale\" value=\"2\"/>\n<boolean name=\"mis_compensation\" value=\"true\"/>\n\
         <transform name=\"to_world\"><rotate y=\"1\" angle=\"90\"/><translate x=\"5\"/></transform>\n\
         </emitter>"
    );
    let desc = load(&write_scene(&dir, "ok.xml", &body)).unwrap();
    let [EmitterDesc::Envmap {
        image,
        to_world,
        scale,
        filename,
    }] = &desc.emitters[..]
    else {
        panic!("{:?}", desc.emitters);
    };
    let expect: &Bitmap = image;
    assert_eq!((expect.width, expect.height), (4, 2));
    assert_eq!(expect.texels, texels);
    assert_eq!(*scale, 2.0);
    assert!(filename.ends_with("sky.exr"));
    // rotate y 90 takes +x to −z.
    assert!((*to_world * Vec3::X - Vec3::NEG_Z).length() < 1e-6);
    assert!(desc.warnings.iter().any(|w| w.contains("mis_compensation")));
    // Scene::build accepts it.
    crate::scene::Scene::build(&desc).unwrap();

    let bad = |name: &str, param: &str, marker: &str, needle: &str| {
        let body = format!(
            "{SENSOR}\n<emitter type=\"envmap\">\n<string name=\"filename\" value=\"sky.exr\"/>\n{param}\n</emitter>"
        );
        assert_body_error_at(&dir, name, &body, marker, needle);
    };
    bad(
        "scale.xml",
        "<float name=\"scale\" value=\"-1\"/>",
        "scale",
        "scale -1",
    );
    bad(
        "shear.xml",
        "<transform name=\"to_world\"><scale x=\"2\"/></transform>",
        "to_world",
        "must be a rotation",
    );
    bad(
        "filter.xml",
        "<string name=\"filter_type\" value=\"nearest\"/>",
        "filter_type",
        "filter_type",
    );
    let body = format!(
        "{SENSOR}\n<emitter type=\"envmap\">\n<string name=\"filename\" value=\"nope.exr\"/>\n</emitter>"
    );
    assert_body_error_at(&dir, "missing.xml", &body, "nope.exr", "nope.exr");
    let body = format!("{SENSOR}\n<emitter type=\"envmap\">\n</emitter>");
    assert_body_error_at(
        &dir,
        "nofile.xml",
        &body,
        "envmap",
        "missing parameter \"filename\"",
    );
    // A NaN texel: the image file is named.
    let mut nan = texels.clone();
    nan[5] = Rgb::new(f32::NAN, 0.0, 0.0);
    crate::image_io::write_rgb_exr(&dir.join("nan.exr"), 4, 2, &nan).unwrap();
    let body = format!(
        "{SENSOR}\n<emitter type=\"envmap\">\n<string name=\"filename\" value=\"nan.exr\"/>\n</emitter>"
    );
    let err = assert_body_error_at(&dir, "nan.xml", &body, "nan.exr", "texel (1, 1)");
    assert!(err.to_string().contains("nan.exr"), "{err}");
}

/// A shape without a BSDF gets Mitsuba 3's default: diffuse 0.5 — but black when the shape
/// emits (a light without a BSDF reflects nothing; with 0.5 a floor under a rectangle light
/// came out 0.4 % too bright against Mitsuba and the analytic irradiance).
#[test]
fn default_bsdf_is_black_for_emitters() {
    let dir = temp_dir("default-bsdf");
    let body = format!(
        "{SENSOR}\n<shape type=\"rectangle\"/>\n<shape type=\"sphere\"><emitter type=\"area\"/></shape>\n<shape type=\"disk\"/>"
    );
    let desc = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    let reflectance = |shape: usize| match &desc.bsdfs[desc.shapes[shape].bsdf] {
        Bsdf::Diffuse(d) => d.reflectance.eval(Vec2::ZERO),
        other => panic!("{other:?}"),
    };
    assert_eq!(reflectance(0), Rgb::splat(0.5));
    assert_eq!(reflectance(1), Rgb::ZERO);
    assert_eq!(reflectance(2), Rgb::splat(0.5));
    assert_eq!(
        desc.shapes[0].bsdf, desc.shapes[2].bsdf,
        "one shared default"
    );
}

/// `shapegroup` + `instance`: each instance builds the group's shapes with its `to_world`
/// applied after theirs; a group alone builds nothing; misuse is reported at its line.
#[test]
fn mirroring_instances_keep_the_side_their_meshes_face() {
    // Mitsuba transforms an instanced mesh's normals by the instance's inverse transpose, so a
    // mirrored copy faces the way the group's mesh does: its face normal is not the world-space
    // winding's. Both normals of the group are +z: a uv-less triangle (normals computed from
    // the winding) and a cube's +z face (normals from the cube's own list).
    use crate::math::Ray;
    use crate::shapes::Mesh;
    let dir = temp_dir("instancing-mirror");
    std::fs::write(dir.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let group = "<shape type=\"shapegroup\" id=\"g\">\n\
                 <shape type=\"obj\"><string name=\"filename\" value=\"tri.obj\"/></shape>\n\
                 <shape type=\"cube\"><transform name=\"to_world\"><translate z=\"-3\"/></transform></shape>\n\
                 </shape>";
    for (scale, flipped) in [("x=\"-1\"", true), ("x=\"-1\" y=\"-1\"", false)] {
        let body = format!(
            "{SENSOR}\n{group}\n<shape type=\"instance\"><ref id=\"g\"/><transform name=\"to_world\"><scale {scale}/></transform></shape>"
        );
        let desc = load(&write_scene(&dir, "mirror.xml", &body)).unwrap();
        let meshes: Vec<&TriangleMesh> = desc
            .shapes
            .iter()
            .map(|s| match &s.geometry {
                Geometry::Mesh(m) => m,
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(
            meshes.iter().map(|m| m.flipped).collect::<Vec<_>>(),
            [flipped; 2]
        );
        // The triangle: both normals +z (scale keeps z).
        let tri = Mesh::new(meshes[0]);
        let centre = tri.triangle(0).iter().sum::<Vec3>() / 3.0;
        let ray = Ray::new(centre + Vec3::Z, -Vec3::Z);
        let g = tri.hit_geometry(0, &ray, 1.0);
        assert!((g.ng - Vec3::Z).length() < 1e-6, "{}", g.ng);
        assert!((g.ns - Vec3::Z).length() < 1e-6, "{}", g.ns);
        // The cube's top face (z = −2) faces +z.
        let cube = Mesh::new(meshes[1]);
        let top = (0..cube.triangle_count() as u32)
            .find(|&t| cube.triangle(t).iter().all(|p| (p.z + 2.0).abs() < 1e-6))
            .unwrap();
        let centre = cube.triangle(top).iter().sum::<Vec3>() / 3.0;
        let ray = Ray::new(centre + Vec3::Z, -Vec3::Z);
        let g = cube.hit_geometry(top, &ray, 1.0);
        assert!((g.ng - Vec3::Z).length() < 1e-6, "{}", g.ng);
        assert!((g.ns - Vec3::Z).length() < 1e-6, "{}", g.ns);
    }
}

#[test]
fn instances_copy_their_group_with_the_instance_transform() {
    let dir = temp_dir("instancing");
    let group = "<shape type=\"shapegroup\" id=\"g\">\n\
                 <shape type=\"sphere\"><point name=\"center\" x=\"1\" y=\"0\" z=\"0\"/><float name=\"radius\" value=\"0.5\"/></shape>\n\
                 <shape type=\"rectangle\" id=\"r\"><transform name=\"to_world\"><translate z=\"-1\"/></transform></shape>\n\
                 </shape>";
    let body = format!(
        "{SENSOR}\n{group}\n<shape type=\"instance\" id=\"a\"><ref id=\"g\"/></shape>\n\
         <shape type=\"instance\"><ref id=\"g\"/><transform name=\"to_world\"><scale value=\"2\"/><translate y=\"3\"/></transform></shape>"
    );
    let desc = load(&write_scene(&dir, "ok.xml", &body)).unwrap();
    assert_eq!(desc.shapes.len(), 4, "two instances of two shapes");
    let spheres: Vec<(Vec3, f32)> = desc
        .shapes
        .iter()
        .filter_map(|s| match s.geometry {
            Geometry::Sphere { center, radius, .. } => Some((center, radius)),
            _ => None,
        })
        .collect();
    assert_eq!(
        spheres,
        vec![(Vec3::X, 0.5), (Vec3::new(2.0, 3.0, 0.0), 1.0)]
    );
    // The rectangle of the second instance: z = −1 scaled by 2, then lifted by 3.
    let Geometry::Mesh(m) = &desc.shapes[3].geometry else {
        panic!("{:?}", desc.shapes[3].geometry);
    };
    assert!(m.positions.iter().all(|p| (p.z + 2.0).abs() < 1e-6));
    assert!(m.positions.iter().all(|p| (p.y - 3.0).abs() <= 2.0 + 1e-6));
    assert_eq!(desc.shapes[1].name, "a/r");
    // A group that is never instanced builds nothing.
    let desc = load(&write_scene(
        &dir,
        "alone.xml",
        &format!("{SENSOR}\n{group}"),
    ))
    .unwrap();
    assert!(desc.shapes.is_empty());

    let bad = |name: &str, body: String, marker: &str, needle: &str| {
        assert_body_error_at(&dir, name, &body, marker, needle);
    };
    bad(
        "emitter.xml",
        format!("{SENSOR}\n<shape type=\"shapegroup\" id=\"g\"><shape type=\"sphere\">\n<emitter type=\"area\"/></shape></shape>\n<shape type=\"instance\"><ref id=\"g\"/></shape>"),
        "emitter type",
        "emitters cannot be instanced",
    );
    bad(
        "not-a-group.xml",
        format!("{SENSOR}\n<shape type=\"sphere\" id=\"s\"/>\n<shape type=\"instance\">\n<ref id=\"s\"/></shape>"),
        "<ref id=\"s\"/>",
        "an instance refers to a shapegroup",
    );
    bad(
        "nested.xml",
        format!(
            "{SENSOR}\n<shape type=\"shapegroup\" id=\"g\">\n<shape type=\"instance\"/></shape>"
        ),
        "type=\"instance\"",
        "plain shapes only",
    );
    bad(
        "empty.xml",
        format!("{SENSOR}\n<shape type=\"instance\">\n</shape>"),
        "type=\"instance\"",
        "needs a <ref",
    );
}

/// Every scene bundled in `scenes/` (the default scene and the validation scenes) loads
/// without warnings and builds: the README, `validate_pt.py` and the docs rely on them.
#[test]
fn bundled_scenes_load_and_build() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut dirs = vec![root.join("default")];
    let mut validation: Vec<PathBuf> = std::fs::read_dir(root.join("validation"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    validation.sort();
    dirs.extend(validation);
    for dir in &dirs {
        let path = dir.join("scene.xml");
        let desc = load(&path).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            desc.warnings.is_empty(),
            "{}: {:?}",
            path.display(),
            desc.warnings
        );
        crate::scene::Scene::build(&desc).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
    }
    assert!(dirs.len() >= 10, "{dirs:?}");
}

/// A Mitsuba `.serialized` file with the given meshes (positions, triangles), format version
/// `version` (3: u32 offsets and no names; 4: u64 offsets and names), f32, no normals.
fn serialized_file(version: u16, meshes: &[(Vec<Vec3>, Vec<[u32; 3]>)]) -> Vec<u8> {
    use std::io::Write;
    let mut out = Vec::new();
    let mut offsets = Vec::new();
    for (i, (pos, tris)) in meshes.iter().enumerate() {
        let mut body = 0x1000u32.to_le_bytes().to_vec();
        if version == 4 {
            body.extend(format!("mesh{i}\0").bytes());
        }
        body.extend((pos.len() as u64).to_le_bytes());
        body.extend((tris.len() as u64).to_le_bytes());
        for p in pos {
            body.extend(p.to_array().iter().flat_map(|c| c.to_le_bytes()));
        }
        for t in tris {
            body.extend(t.iter().flat_map(|c| c.to_le_bytes()));
        }
        offsets.push(out.len() as u64);
        out.extend(0x041Cu16.to_le_bytes());
        out.extend(version.to_le_bytes());
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&body).unwrap();
        out.extend(z.finish().unwrap());
    }
    for o in offsets {
        if version == 4 {
            out.extend(o.to_le_bytes());
        } else {
            out.extend((o as u32).to_le_bytes());
        }
    }
    out.extend((meshes.len() as u32).to_le_bytes());
    out
}

/// `serialized` meshes load by `shape_index` from version 3 and 4 files; bad files and
/// indices are reported at the parameter's line.
#[test]
fn serialized_meshes_load_by_index_and_report_bad_files() {
    let dir = temp_dir("serialized");
    let tri = (vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0u32, 1, 2]]);
    let quad = (
        vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        vec![[0u32, 1, 2], [0, 2, 3]],
    );
    for version in [3u16, 4] {
        std::fs::write(
            dir.join("m.serialized"),
            serialized_file(version, &[tri.clone(), quad.clone()]),
        )
        .unwrap();
        let body = format!(
            "{SENSOR}\n<shape type=\"serialized\"><string name=\"filename\" value=\"m.serialized\"/>\n\
             <integer name=\"shape_index\" value=\"1\"/><transform name=\"to_world\"><translate z=\"2\"/></transform></shape>"
        );
        let desc = load(&write_scene(&dir, "ok.xml", &body)).unwrap();
        let Geometry::Mesh(m) = &desc.shapes[0].geometry else {
            panic!("{:?}", desc.shapes[0].geometry);
        };
        assert_eq!(m.indices.len(), 2, "version {version}");
        assert_eq!(
            m.positions[2],
            Vec3::new(1.0, 1.0, 2.0),
            "version {version}"
        );
    }
    let bad = |name: &str, param: &str, marker: &str, needle: &str| {
        let body = format!(
            "{SENSOR}\n<shape type=\"serialized\">\n<string name=\"filename\" value=\"{name}\"/>\n{param}\n</shape>"
        );
        assert_body_error_at(&dir, &format!("{name}.xml"), &body, marker, needle);
    };
    bad(
        "m.serialized",
        "<integer name=\"shape_index\" value=\"2\"/>",
        "m.serialized",
        "shape_index 2, but the file holds 2 mesh(es)",
    );
    std::fs::write(dir.join("garbage.serialized"), b"not a mesh at all").unwrap();
    bad("garbage.serialized", "", "garbage.serialized", "0x041C");
    let mut cut = serialized_file(4, std::slice::from_ref(&tri));
    cut.drain(12..20); // damage the zlib stream
    std::fs::write(dir.join("cut.serialized"), cut).unwrap();
    bad("cut.serialized", "", "cut.serialized", "cut.serialized");
}

/// `cylinder`: p0, p1 and radius compose with `to_world` as in Mitsuba; a degenerate axis or an
/// elliptic section is reported at its line.
#[test]
fn cylinder_parameters_and_errors() {
    let dir = temp_dir("cylinder");
    let body = format!(
        "{SENSOR}\n<shape type=\"cylinder\"><point name=\"p0\" x=\"1\" y=\"0\" z=\"0\"/>\n\
         <point name=\"p1\" x=\"1\" y=\"2\" z=\"0\"/><float name=\"radius\" value=\"0.5\"/>\n\
         <transform name=\"to_world\"><translate z=\"3\"/></transform></shape>"
    );
    let desc = load(&write_scene(&dir, "ok.xml", &body)).unwrap();
    let Geometry::Cylinder { to_world, .. } = desc.shapes[0].geometry else {
        panic!("{:?}", desc.shapes[0].geometry);
    };
    // Local (0, 0, 1) is p1 moved by to_world; local (1, 0, 0) is half a unit off the axis.
    assert!((to_world.transform_point3(Vec3::Z) - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-5);
    let rim = to_world.transform_point3(Vec3::X) - Vec3::new(1.0, 0.0, 3.0);
    assert!((rim.length() - 0.5).abs() < 1e-5 && rim.y.abs() < 1e-5);
    let scene = crate::scene::Scene::build(&desc).unwrap();
    assert!((scene.shapes[0].area() - 2.0 * std::f32::consts::PI).abs() < 1e-4);

    let bad = |name: &str, param: &str, marker: &str, needle: &str| {
        let body = format!("{SENSOR}\n<shape type=\"cylinder\">\n{param}\n</shape>");
        assert_body_error_at(&dir, name, &body, marker, needle);
    };
    bad(
        "degenerate.xml",
        "<point name=\"p1\" x=\"0\" y=\"0\" z=\"0\"/>",
        "p1",
        "p1 != p0",
    );
    bad(
        "elliptic.xml",
        "<transform name=\"to_world\"><scale x=\"2\"/></transform>",
        "to_world",
        "circular",
    );
}

/// `orthographic`: parsed with the scale of its to_world (which perspective cameras refuse);
/// a `fov` is not one of its parameters.
#[test]
fn orthographic_sensor_keeps_its_scale_and_has_no_fov() {
    use crate::description::Projection;
    let dir = temp_dir("orthographic");
    let sensor = |extra: &str| {
        format!(
            "<sensor type=\"orthographic\">{extra}<transform name=\"to_world\"><scale x=\"2\" y=\"2\"/></transform>\n\
             <film type=\"hdrfilm\"><integer name=\"width\" value=\"16\"/><integer name=\"height\" value=\"8\"/></film></sensor>"
        )
    };
    let desc = load(&write_scene(&dir, "ok.xml", &sensor(""))).unwrap();
    assert_eq!(desc.camera.projection, Projection::Orthographic);
    assert!((desc.camera.to_world.transform_vector3(Vec3::X).length() - 2.0).abs() < 1e-6);
    let body = sensor("\n<float name=\"fov\" value=\"40\"/>");
    assert_body_error_at(&dir, "fov.xml", &body, "fov", "fov");
}

#[test]
fn reconstruction_filters_with_mitsubas_defaults() {
    let dir = temp_dir("rfilters");
    let film = |inner: &str| {
        format!(
            r#"<sensor type="perspective"><float name="fov" value="40"/>
<film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="8"/>{inner}</film></sensor>"#
        )
    };
    let camera = |body: &str| {
        let scene = load(&write_scene(&dir, "scene.xml", body)).unwrap();
        let sensorless = !body.contains("<sensor");
        assert_eq!(
            scene.warnings.len(),
            sensorless as usize,
            "{:?}",
            scene.warnings
        );
        (scene.camera.filter, scene.camera.sample_border)
    };
    // Mitsuba's default is a Gaussian of standard deviation ½, with or without a film.
    let gaussian = FilterDesc::Gaussian { stddev: 0.5 };
    assert_eq!(camera(&film("")), (gaussian, false));
    assert_eq!(camera(r#"<sensor type="perspective"/>"#), (gaussian, false));
    assert_eq!(camera("<shape type=\"sphere\"/>").0, gaussian);
    let cases = [
        (r#"<rfilter type="box"/>"#, FilterDesc::Box),
        (
            r#"<rfilter type="gaussian"><float name="stddev" value="0.25"/></rfilter>"#,
            FilterDesc::Gaussian { stddev: 0.25 },
        ),
        (
            r#"<rfilter type="tent"/>"#,
            FilterDesc::Tent { radius: 1.0 },
        ),
        (
            r#"<rfilter type="tent"><float name="radius" value="1.5"/></rfilter>"#,
            FilterDesc::Tent { radius: 1.5 },
        ),
        (
            r#"<rfilter type="mitchell"/>"#,
            FilterDesc::Mitchell {
                b: 1.0 / 3.0,
                c: 1.0 / 3.0,
            },
        ),
        (
            r#"<rfilter type="mitchell"><float name="B" value="0.2"/><float name="C" value="0.4"/></rfilter>"#,
            FilterDesc::Mitchell { b: 0.2, c: 0.4 },
        ),
        (
            r#"<rfilter type="catmullrom"/>"#,
            FilterDesc::Mitchell { b: 0.0, c: 0.5 },
        ),
        (
            r#"<rfilter type="lanczos"/>"#,
            FilterDesc::Lanczos { lobes: 3 },
        ),
        (
            r#"<rfilter type="lanczos"><integer name="lobes" value="2"/></rfilter>"#,
            FilterDesc::Lanczos { lobes: 2 },
        ),
    ];
    for (xml, expected) in cases {
        assert_eq!(camera(&film(xml)), (expected, false), "{xml}");
    }
    let border = film(r#"<boolean name="sample_border" value="true"/><rfilter type="tent"/>"#);
    assert_eq!(camera(&border), (FilterDesc::Tent { radius: 1.0 }, true));
    // Bad parameters and unknown filters name their line.
    for (inner, marker, needle) in [
        (
            "\n<rfilter type=\"gaussian\">\n<float name=\"stddev\" value=\"-1\"/></rfilter>",
            "stddev",
            "\"stddev\" must be in (0, 8]",
        ),
        (
            "\n<rfilter type=\"lanczos\">\n<integer name=\"lobes\" value=\"0\"/></rfilter>",
            "lobes",
            "\"lobes\" must be in 1..=32",
        ),
        (
            "\n<rfilter type=\"tent\">\n<float name=\"width\" value=\"2\"/></rfilter>",
            "width\" value=\"2",
            "width",
        ),
        (
            "\n<rfilter type=\"sinc\"/>",
            "sinc",
            "unknown plugin \"sinc\"",
        ),
    ] {
        assert_body_error_at(&dir, "bad.xml", &film(inner), marker, needle);
    }
}

#[test]
fn normalmap_wraps_one_bsdf_and_reports_misuse_by_line() {
    let dir = temp_dir("normalmap");
    let body = format!(
        r#"{SENSOR}
<texture type="checkerboard" id="map"/>
<bsdf type="normalmap" id="a">
  <ref name="normalmap" id="map"/>
  <bsdf type="roughconductor"/>
</bsdf>
<bsdf type="normalmap" id="b">
  <rgb name="normalmap" value="0.5, 0.5, 1"/>
  <boolean name="flip_invalid_normals" value="false"/>
  <boolean name="use_shadowing_function" value="false"/>
  <bsdf type="twosided"><bsdf type="diffuse"/></bsdf>
</bsdf>
<shape type="sphere"><ref id="a"/></shape>
<shape type="sphere"><ref id="b"/></shape>"#
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let [Bsdf::NormalMap(a), Bsdf::NormalMap(b)] = &scene.bsdfs[..] else {
        panic!("{:?}", scene.bsdfs)
    };
    assert!(matches!(a.normalmap, Texture::Checkerboard { .. }));
    assert!(matches!(*a.nested, Bsdf::RoughConductor(_)));
    assert!(a.flip_invalid_normals && a.use_shadowing_function);
    assert!(matches!(*b.nested, Bsdf::TwoSided { .. }));
    assert!(!b.flip_invalid_normals && !b.use_shadowing_function);
    assert!(matches!(b.normalmap, Texture::Constant(c) if c == Vec3::new(0.5, 0.5, 1.0)));
    for (inner, marker, needle) in [
        (
            "<bsdf type=\"normalmap\">\n<bsdf type=\"diffuse\"/></bsdf>",
            "normalmap",
            "missing parameter \"normalmap\"",
        ),
        (
            "<bsdf type=\"normalmap\"><rgb name=\"normalmap\" value=\"0.5\"/></bsdf>",
            "normalmap",
            "exactly one nested BSDF, got 0",
        ),
        (
            "<bsdf type=\"normalmap\"><rgb name=\"normalmap\" value=\"0.5\"/>\n<bsdf type=\"diffuse\"/><bsdf type=\"diffuse\"/></bsdf>",
            "normalmap",
            "exactly one nested BSDF, got 2",
        ),
    ] {
        let body = format!("{SENSOR}\n{inner}\n<shape type=\"sphere\"/>");
        assert_body_error_at(&dir, "bad.xml", &body, marker, needle);
    }
}

#[test]
fn blendbsdf_mixes_two_bsdfs_in_file_order() {
    let dir = temp_dir("blendbsdf");
    let body = format!(
        r#"{SENSOR}
<bsdf type="blendbsdf" id="a">
  <float name="weight" value="0.25"/>
  <bsdf type="diffuse"/>
  <bsdf type="conductor"/>
</bsdf>
<bsdf type="blendbsdf" id="b">
  <texture type="checkerboard" name="weight"/>
  <bsdf type="roughplastic"/>
  <ref id="a"/>
</bsdf>
<shape type="sphere"><ref id="b"/></shape>"#
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    // Both top-level declarations are scene materials; "b" is the one the sphere uses.
    let [_, Bsdf::Blend(b)] = &scene.bsdfs[..] else {
        panic!("{:?}", scene.bsdfs)
    };
    assert!(matches!(b.weight, Texture::Checkerboard { .. }));
    assert!(matches!(b.nested[0], Bsdf::RoughPlastic(_)));
    let Bsdf::Blend(a) = &b.nested[1] else {
        panic!("{:?}", b.nested[1])
    };
    assert_eq!(a.weight_at(Vec2::ZERO.into()), 0.25);
    assert!(matches!(a.nested[0], Bsdf::Diffuse(_)));
    assert!(matches!(a.nested[1], Bsdf::Conductor(_)));
    for (inner, needle) in [
        (
            "<bsdf type=\"blendbsdf\">\n<bsdf type=\"diffuse\"/></bsdf>",
            "exactly two nested BSDFs, got 1",
        ),
        (
            "<bsdf type=\"blendbsdf\"><bsdf type=\"diffuse\"/>\n<bsdf type=\"diffuse\"/><bsdf type=\"diffuse\"/></bsdf>",
            "exactly two nested BSDFs, got 3",
        ),
    ] {
        let body = format!("{SENSOR}\n{inner}\n<shape type=\"sphere\"/>");
        assert_body_error_at(&dir, "bad.xml", &body, "blendbsdf", needle);
    }
}

#[test]
fn mask_wraps_one_bsdf_with_an_opacity() {
    let dir = temp_dir("mask");
    let body = format!(
        r#"{SENSOR}
<shape type="sphere">
  <bsdf type="mask">
    <texture type="checkerboard" name="opacity"/>
    <bsdf type="twosided"><bsdf type="diffuse"/></bsdf>
  </bsdf>
</shape>
<shape type="sphere"><bsdf type="mask"><bsdf type="conductor"/></bsdf></shape>"#
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let [Bsdf::Mask(a), Bsdf::Mask(b)] = &scene.bsdfs[..] else {
        panic!("{:?}", scene.bsdfs)
    };
    assert!(matches!(a.opacity, Texture::Checkerboard { .. }));
    assert!(matches!(*a.nested, Bsdf::TwoSided { .. }));
    // Mitsuba's default opacity.
    assert_eq!(b.opacity_at(Vec2::ZERO.into()), 0.5);
    for (inner, needle) in [
        (
            "<bsdf type=\"mask\">\n<float name=\"opacity\" value=\"0.3\"/></bsdf>",
            "exactly one nested BSDF, got 0",
        ),
        (
            "<bsdf type=\"mask\"><bsdf type=\"diffuse\"/>\n<bsdf type=\"diffuse\"/></bsdf>",
            "exactly one nested BSDF, got 2",
        ),
    ] {
        let body = format!("{SENSOR}\n{inner}\n<shape type=\"sphere\"/>");
        assert_body_error_at(&dir, "bad.xml", &body, "mask", needle);
    }
}

#[test]
fn area_emitters_take_a_texture_as_radiance() {
    let dir = temp_dir("textured-emitter");
    let body = format!(
        r#"{SENSOR}
<shape type="rectangle">
  <emitter type="area">
    <texture type="checkerboard" name="radiance">
      <rgb name="color0" value="0.9, 0.5, 0.1"/>
    </texture>
  </emitter>
</shape>
<shape type="sphere"><emitter type="area"><rgb name="radiance" value="2, 3, 4"/></emitter></shape>"#
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let Some(Texture::Checkerboard { color0, .. }) = &scene.shapes[0].emission else {
        panic!("{:?}", scene.shapes[0].emission)
    };
    assert_eq!(*color0, Vec3::new(0.9, 0.5, 0.1));
    assert!(
        matches!(scene.shapes[1].emission, Some(Texture::Constant(c)) if c == Vec3::new(2.0, 3.0, 4.0))
    );
    // Point lights still need a colour.
    let body = format!(
        "{SENSOR}\n<emitter type=\"point\">\n<texture type=\"checkerboard\" name=\"intensity\"/></emitter>"
    );
    assert_body_error_at(
        &dir,
        "bad.xml",
        &body,
        "checkerboard",
        "must be a constant colour",
    );
}

/// `directionalarea` (Mitsuba's collimated area light) nests in a shape like `area` and is
/// marked collimated; outside a shape it is an error naming it.
#[test]
fn directional_area_emitters_are_collimated_area_lights() {
    let dir = temp_dir("directionalarea");
    let body = format!(
        r#"{SENSOR}
<shape type="rectangle"><emitter type="directionalarea"><rgb name="radiance" value="2, 3, 4"/></emitter></shape>
<shape type="sphere"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>"#
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert!(scene.shapes[0].collimated && !scene.shapes[1].collimated);
    assert!(
        matches!(scene.shapes[0].emission, Some(Texture::Constant(c)) if c == Vec3::new(2.0, 3.0, 4.0))
    );
    let body = format!(
        "{SENSOR}\n<emitter type=\"directionalarea\"><rgb name=\"radiance\" value=\"1\"/></emitter>"
    );
    assert_body_error_at(
        &dir,
        "loose.xml",
        &body,
        "<emitter",
        "a directionalarea emitter must be nested inside a <shape>",
    );
}

#[test]
fn alpha_may_be_a_texture_except_for_roughplastic() {
    let dir = temp_dir("textured-alpha");
    let body = format!(
        r#"{SENSOR}
<shape type="sphere">
  <bsdf type="roughconductor">
    <texture type="checkerboard" name="alpha"><rgb name="color0" value="0.1"/><rgb name="color1" value="0.3"/></texture>
  </bsdf>
</shape>
<shape type="sphere"><bsdf type="roughdielectric"><float name="alpha" value="0.2"/></bsdf></shape>"#
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let [Bsdf::RoughConductor(a), Bsdf::RoughDielectric(b)] = &scene.bsdfs[..] else {
        panic!("{:?}", scene.bsdfs)
    };
    assert!(matches!(
        a.alpha_texture,
        Some(Texture::Checkerboard { .. })
    ));
    // The constant roughness holds the texture's mean (SPPM's glossy/diffuse class uses it).
    assert!((a.roughness.alpha_u - 0.2).abs() < 1e-6);
    assert!(b.alpha_texture.is_none() && b.roughness.alpha_u == 0.2);
    let body = format!(
        "{SENSOR}\n<bsdf type=\"roughplastic\">\n<texture type=\"checkerboard\" name=\"alpha\"/></bsdf>\n<shape type=\"sphere\"/>"
    );
    assert_body_error_at(
        &dir,
        "bad.xml",
        &body,
        "name=\"alpha\"",
        "needs a constant \"alpha\"",
    );
}

#[test]
fn bumpmap_takes_one_bitmap_and_one_bsdf_and_reports_misuse_by_line() {
    let dir = temp_dir("bumpmap");
    std::fs::create_dir_all(dir.join("tex")).unwrap();
    let pixels = [Vec3::splat(0.2), Vec3::splat(0.6)];
    crate::image_io::write_png_srgb(&dir.join("tex/h.png"), 2, 1, &pixels).unwrap();
    let body = format!(
        r#"{SENSOR}
<texture type="bitmap" id="h"><string name="filename" value="tex/h.png"/><boolean name="raw" value="true"/></texture>
<bsdf type="roughplastic" id="base"/>
<bsdf type="bumpmap" id="a">
  <ref id="base"/>
  <ref name="arbitrary" id="h"/>
</bsdf>
<bsdf type="bumpmap" id="b">
  <texture type="bitmap"><string name="filename" value="tex/h.png"/></texture>
  <float name="scale" value="-0.5"/>
  <boolean name="flip_invalid_normals" value="false"/>
  <boolean name="use_shadowing_function" value="false"/>
  <bsdf type="twosided"><bsdf type="diffuse"/></bsdf>
</bsdf>
<shape type="sphere"><ref id="a"/></shape>
<shape type="sphere"><ref id="b"/></shape>"#
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let [Bsdf::RoughPlastic(_), Bsdf::BumpMap(a), Bsdf::BumpMap(b)] = &scene.bsdfs[..] else {
        panic!("{:?}", scene.bsdfs)
    };
    assert!(matches!(a.height, Texture::Bitmap { .. }));
    assert!(matches!(*a.nested, Bsdf::RoughPlastic(_)));
    assert!(a.scale == 1.0 && a.flip_invalid_normals && a.use_shadowing_function);
    assert!(matches!(*b.nested, Bsdf::TwoSided { .. }));
    assert!(b.scale == -0.5 && !b.flip_invalid_normals && !b.use_shadowing_function);
    let bitmap = r#"<texture type="bitmap"><string name="filename" value="tex/h.png"/></texture>"#;
    for (inner, marker, needle) in [
        (
            "<bsdf type=\"bumpmap\">\n<bsdf type=\"diffuse\"/></bsdf>".to_owned(),
            "bumpmap",
            "exactly one nested texture (the height field), got 0",
        ),
        (
            format!("<bsdf type=\"bumpmap\">{bitmap}</bsdf>"),
            "bumpmap",
            "exactly one nested BSDF, got 0",
        ),
        (
            format!("<bsdf type=\"bumpmap\">{bitmap}{bitmap}<bsdf type=\"diffuse\"/></bsdf>"),
            "bumpmap",
            "exactly one nested texture (the height field), got 2",
        ),
        (
            "<bsdf type=\"bumpmap\"><bsdf type=\"diffuse\"/>\n<texture type=\"checkerboard\"/></bsdf>"
                .to_owned(),
            "checkerboard",
            "needs a bitmap height field",
        ),
        (
            format!("<bsdf type=\"bumpmap\">{bitmap}<bsdf type=\"diffuse\"/>\n<float name=\"scael\" value=\"2\"/></bsdf>"),
            "scael",
            "unknown parameter \"scael\"",
        ),
    ] {
        let body = format!("{SENSOR}\n{inner}\n<shape type=\"sphere\"/>");
        assert_body_error_at(&dir, "bad.xml", &body, marker, needle);
    }
}

#[test]
fn film_crop_window_and_principal_point() {
    use crate::description::FilmCrop;
    use glam::{UVec2, Vec2};
    let dir = temp_dir("crop");
    let scene = |kind: &str, sensor_extra: &str, film_extra: &str| {
        format!(
            "<sensor type=\"{kind}\"><float name=\"fov\" value=\"40\"/>{sensor_extra}\n\
             <film type=\"hdrfilm\"><integer name=\"width\" value=\"16\"/><integer name=\"height\" value=\"8\"/>\n\
             {film_extra}</film></sensor>"
        )
    };
    let camera = |body: &str| load(&write_scene(&dir, "scene.xml", body)).unwrap().camera;
    let c = camera(&scene("perspective", "", ""));
    assert_eq!((c.crop, c.principal_point), (None, Vec2::ZERO));
    let c = camera(&scene(
        "perspective",
        r#"<float name="principal_point_offset_x" value="0.1"/><float name="principal_point_offset_y" value="-0.25"/>"#,
        r#"<integer name="crop_offset_x" value="4"/><integer name="crop_offset_y" value="2"/>
           <integer name="crop_width" value="12"/><integer name="crop_height" value="3"/>"#,
    ));
    assert_eq!(
        c.crop,
        Some(FilmCrop {
            offset: UVec2::new(4, 2),
            size: UVec2::new(12, 3)
        })
    );
    assert_eq!(c.principal_point, Vec2::new(0.1, -0.25));
    // The window's size defaults to the film's, so an offset alone must come with a size.
    let c = camera(&scene(
        "perspective",
        "",
        r#"<integer name="crop_width" value="5"/>"#,
    ));
    assert_eq!(
        c.crop,
        Some(FilmCrop {
            offset: UVec2::ZERO,
            size: UVec2::new(5, 8)
        })
    );
    for (body, marker, needle) in [
        (
            scene(
                "perspective",
                "",
                r#"<integer name="crop_offset_x" value="4"/>"#,
            ),
            "<film",
            "does not fit inside the 16×8 film",
        ),
        (
            scene(
                "perspective",
                "",
                r#"<integer name="crop_width" value="0"/>"#,
            ),
            "crop_width",
            "\"crop_width\" must be in 1..=",
        ),
        (
            scene(
                "perspective",
                "",
                r#"<integer name="crop_offset_y" value="-1"/>"#,
            ),
            "crop_offset_y",
            "\"crop_offset_y\" must be in 0..=",
        ),
        (
            scene(
                "thinlens",
                r#"<float name="aperture_radius" value="0.1"/>
<float name="principal_point_offset_x" value="0.1"/>"#,
                "",
            ),
            "principal_point_offset_x",
            "unknown parameter \"principal_point_offset_x\"",
        ),
    ] {
        assert_body_error_at(&dir, "bad.xml", &body, marker, needle);
    }
}

#[test]
fn principled_parameters_follow_mitsuba() {
    use crate::bsdf::{Principled, PrincipledIor};
    let dir = temp_dir("principled");
    let body = format!(
        "{SENSOR}
<bsdf type=\"principled\"/>
<bsdf type=\"principled\">
  <rgb name=\"base_color\" value=\"0.9, 0.6, 0.3\"/>
  <float name=\"roughness\" value=\"0.2\"/>
  <float name=\"anisotropic\" value=\"0.5\"/>
  <float name=\"metallic\" value=\"0.7\"/>
  <float name=\"spec_trans\" value=\"0.4\"/>
  <float name=\"eta\" value=\"1.33\"/>
  <float name=\"spec_tint\" value=\"0.4\"/>
  <float name=\"sheen\" value=\"0.3\"/>
  <float name=\"sheen_tint\" value=\"0.2\"/>
  <float name=\"flatness\" value=\"0.1\"/>
  <float name=\"clearcoat\" value=\"0.6\"/>
  <float name=\"clearcoat_gloss\" value=\"0.3\"/>
  <float name=\"diffuse_reflectance_sampling_rate\" value=\"0.5\"/>
  <float name=\"main_specular_sampling_rate\" value=\"2\"/>
  <float name=\"clearcoat_sampling_rate\" value=\"0\"/>
</bsdf>
<bsdf type=\"principled\">
  <float name=\"spec_trans\" value=\"0\"/>
  <rgb name=\"clearcoat\" value=\"0\"/>
  <float name=\"specular\" value=\"0\"/>
  <texture type=\"checkerboard\" name=\"base_color\"/>
  <texture type=\"checkerboard\" name=\"metallic\"/>
</bsdf>"
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    let get = |i: usize| -> &Principled {
        let Bsdf::Principled(p) = &scene.bsdfs[i] else {
            panic!("{:?}", scene.bsdfs[i])
        };
        p
    };
    let grey = |t: &Texture| t.mean();
    // Defaults: base colour and roughness 0.5, specular 0.5 (η = 1.5), every lobe off,
    // clearcoat_gloss 0, sampling rates 1 (clearcoat's too: the code's default, not the doc's).
    let d = get(0).params();
    assert_eq!(grey(&d.base_color), Vec3::splat(0.5));
    assert_eq!(grey(&d.roughness), Vec3::splat(0.5));
    assert_eq!(d.ior, PrincipledIor::Specular(0.5));
    assert!((get(0).eta() - 1.5).abs() < 1e-6);
    for lobe in [
        &d.anisotropic,
        &d.metallic,
        &d.spec_trans,
        &d.spec_tint,
        &d.sheen,
        &d.sheen_tint,
        &d.flatness,
        &d.clearcoat,
    ] {
        assert!(lobe.is_none());
    }
    assert_eq!(grey(&d.clearcoat_gloss), Vec3::ZERO);
    assert_eq!(
        (
            d.diffuse_reflectance_sampling_rate,
            d.main_specular_sampling_rate,
            d.clearcoat_sampling_rate
        ),
        (1.0, 1.0, 1.0)
    );
    // Everything given.
    let f = get(1).params();
    assert_eq!(grey(&f.base_color), Vec3::new(0.9, 0.6, 0.3));
    assert_eq!(f.ior, PrincipledIor::Eta(1.33));
    let value = |t: &Option<Texture>| t.as_ref().map(|t| t.mean_1());
    assert_eq!(value(&f.anisotropic), Some(0.5));
    assert_eq!(value(&f.metallic), Some(0.7));
    assert_eq!(value(&f.spec_trans), Some(0.4));
    assert_eq!(value(&f.spec_tint), Some(0.4));
    assert_eq!(value(&f.sheen), Some(0.3));
    assert_eq!(value(&f.sheen_tint), Some(0.2));
    assert_eq!(value(&f.flatness), Some(0.1));
    assert_eq!(value(&f.clearcoat), Some(0.6));
    assert_eq!(f.clearcoat_gloss.mean_1(), 0.3);
    assert_eq!(grey(&f.roughness), Vec3::splat(0.2));
    assert_eq!(
        (
            f.diffuse_reflectance_sampling_rate,
            f.main_specular_sampling_rate,
            f.clearcoat_sampling_rate
        ),
        (0.5, 2.0, 0.0)
    );
    // A float 0 switches a lobe off (Mitsuba's get_flag), a colour 0 does not; specular 0 with
    // spec_trans off keeps η = 1; textures are accepted for colour and scalar parameters.
    let z = get(2).params();
    assert!(z.spec_trans.is_none());
    assert!(z.clearcoat.is_some());
    assert_eq!(z.ior, PrincipledIor::Specular(0.0));
    assert_eq!(get(2).eta(), 1.0);
    assert!(matches!(z.base_color, Texture::Checkerboard { .. }));
    assert!(matches!(z.metallic, Some(Texture::Checkerboard { .. })));
}

#[test]
fn principled_bad_values_are_errors_at_their_line() {
    let dir = temp_dir("principled-errors");
    let cases = [
        (
            "<bsdf type=\"principled\">\n<float name=\"eta\" value=\"1.4\"/>\n<float name=\"specular\" value=\"0.3\"/></bsdf>",
            "specular",
            "give either \"eta\" or \"specular\", not both",
        ),
        (
            "<bsdf type=\"principled\">\n<float name=\"roughness\" value=\"-0.1\"/></bsdf>",
            "roughness",
            "\"roughness\" must lie in [0, 1]",
        ),
        (
            "<bsdf type=\"principled\">\n<float name=\"metallic\" value=\"1.5\"/></bsdf>",
            "metallic",
            "\"metallic\" must lie in [0, 1]",
        ),
        (
            "<bsdf type=\"principled\">\n<texture type=\"checkerboard\" name=\"sheen\"><rgb name=\"color0\" value=\"2\"/></texture></bsdf>",
            "sheen",
            "\"sheen\" must lie in [0, 1], got values in [0.2, 2]",
        ),
        (
            "<bsdf type=\"principled\">\n<rgb name=\"base_color\" value=\"0.5, -0.1, 0.5\"/></bsdf>",
            "base_color",
            "\"base_color\" has negative or non-finite values",
        ),
        (
            "<bsdf type=\"principled\">\n<float name=\"eta\" value=\"0\"/></bsdf>",
            "eta",
            "\"eta\" must be positive",
        ),
        (
            "<bsdf type=\"principled\">\n<float name=\"specular\" value=\"1.2\"/></bsdf>",
            "specular",
            "\"specular\" = 1.2 is outside [0, 1]",
        ),
        (
            "<bsdf type=\"principled\">\n<texture type=\"checkerboard\" name=\"eta\"/></bsdf>",
            "eta",
            "parameter \"eta\" has the wrong type",
        ),
        (
            "<bsdf type=\"principled\">\n<float name=\"clearcoat_sampling_rate\" value=\"-1\"/></bsdf>",
            "clearcoat_sampling_rate",
            "\"clearcoat_sampling_rate\" must be non-negative",
        ),
        (
            "<bsdf type=\"principled\">\n<float name=\"subsurface\" value=\"0.5\"/></bsdf>",
            "subsurface",
            "unknown parameter \"subsurface\" of <bsdf type=\"principled\">",
        ),
    ];
    for (k, (bsdf, marker, needle)) in cases.iter().enumerate() {
        let body = format!("{SENSOR}\n{bsdf}");
        assert_body_error_at(&dir, &format!("e{k}.xml"), &body, marker, needle);
    }
}

/// `principledthin`: Mitsuba's defaults (η 1.5, no specular lobe without `spec_trans`),
/// every parameter read, `diff_trans` up to 2, `eta` as a texture, a lobe switched off by the
/// float 0; `twosided` refuses it without `allow_transmission` (Mitsuba lists its diffuse
/// transmission always); and its bad values with file and line.
#[test]
fn principledthin_parameters_follow_mitsuba() {
    use crate::bsdf::PrincipledThin;
    let dir = temp_dir("principledthin");
    let body = format!(
        "{SENSOR}
<bsdf type=\"principledthin\"/>
<bsdf type=\"principledthin\">
  <rgb name=\"base_color\" value=\"0.9, 0.6, 0.3\"/>
  <float name=\"roughness\" value=\"0.2\"/>
  <float name=\"anisotropic\" value=\"0.5\"/>
  <float name=\"spec_trans\" value=\"0.4\"/>
  <texture type=\"checkerboard\" name=\"eta\"><float name=\"color0\" value=\"1.2\"/><float name=\"color1\" value=\"1.6\"/></texture>
  <float name=\"spec_tint\" value=\"0.4\"/>
  <float name=\"sheen\" value=\"0.3\"/>
  <float name=\"sheen_tint\" value=\"0.2\"/>
  <float name=\"flatness\" value=\"0.1\"/>
  <float name=\"diff_trans\" value=\"1.5\"/>
  <float name=\"diffuse_reflectance_sampling_rate\" value=\"0.5\"/>
  <float name=\"specular_reflectance_sampling_rate\" value=\"2\"/>
  <float name=\"specular_transmittance_sampling_rate\" value=\"0.25\"/>
  <float name=\"diffuse_transmittance_sampling_rate\" value=\"0\"/>
</bsdf>
<bsdf type=\"principledthin\"><float name=\"diff_trans\" value=\"0\"/></bsdf>
<bsdf type=\"twosided\"><boolean name=\"allow_transmission\" value=\"true\"/><bsdf type=\"principledthin\"/></bsdf>"
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    let get = |i: usize| -> &PrincipledThin {
        let Bsdf::PrincipledThin(p) = &scene.bsdfs[i] else {
            panic!("{:?}", scene.bsdfs[i])
        };
        p
    };
    let d = get(0).params();
    assert_eq!(d.base_color.mean(), Vec3::splat(0.5));
    assert_eq!(d.roughness.mean_1(), 0.5);
    assert_eq!(d.eta.mean_1(), 1.5);
    for lobe in [
        &d.anisotropic,
        &d.spec_trans,
        &d.spec_tint,
        &d.sheen,
        &d.sheen_tint,
        &d.flatness,
        &d.diff_trans,
    ] {
        assert!(lobe.is_none());
    }
    assert!(!get(0).transmits());
    let f = get(1).params();
    let value = |t: &Option<Texture>| t.as_ref().map(|t| t.mean_1());
    assert_eq!(f.base_color.mean(), Vec3::new(0.9, 0.6, 0.3));
    assert_eq!(f.roughness.mean_1(), 0.2);
    assert_eq!(value(&f.anisotropic), Some(0.5));
    assert_eq!(value(&f.spec_trans), Some(0.4));
    assert!((f.eta.mean_1() - 1.4).abs() < 1e-6);
    assert_eq!(value(&f.spec_tint), Some(0.4));
    assert_eq!(value(&f.sheen), Some(0.3));
    assert_eq!(value(&f.sheen_tint), Some(0.2));
    assert_eq!(value(&f.flatness), Some(0.1));
    assert_eq!(value(&f.diff_trans), Some(1.5));
    assert_eq!(
        (
            f.diffuse_reflectance_sampling_rate,
            f.specular_reflectance_sampling_rate,
            f.specular_transmittance_sampling_rate,
            f.diffuse_transmittance_sampling_rate
        ),
        (0.5, 2.0, 0.25, 0.0)
    );
    assert!(get(1).transmits());
    assert!(get(2).params().diff_trans.is_none());

    let cases = [
        (
            "<bsdf type=\"principledthin\">\n<float name=\"diff_trans\" value=\"2.5\"/></bsdf>",
            "diff_trans",
            "\"diff_trans\" must lie in [0, 2]",
        ),
        (
            "<bsdf type=\"principledthin\">\n<float name=\"roughness\" value=\"1.1\"/></bsdf>",
            "roughness",
            "\"roughness\" must lie in [0, 1]",
        ),
        (
            "<bsdf type=\"principledthin\">\n<float name=\"eta\" value=\"-1\"/></bsdf>",
            "eta",
            "\"eta\" must be positive and finite",
        ),
        (
            "<bsdf type=\"principledthin\">\n<float name=\"specular_transmittance_sampling_rate\" value=\"-2\"/></bsdf>",
            "specular_transmittance_sampling_rate",
            "must be non-negative",
        ),
        (
            "<bsdf type=\"principledthin\">\n<float name=\"metallic\" value=\"0.5\"/></bsdf>",
            "metallic",
            "unknown parameter \"metallic\" of <bsdf type=\"principledthin\">",
        ),
        (
            "<bsdf type=\"twosided\">\n<bsdf type=\"principledthin\"/></bsdf>",
            "<bsdf type=\"principledthin\"/>",
            "allow_transmission",
        ),
    ];
    for (k, (bsdf, marker, needle)) in cases.iter().enumerate() {
        let body = format!("{SENSOR}\n{bsdf}");
        assert_body_error_at(&dir, &format!("e{k}.xml"), &body, marker, needle);
    }
}

/// A unit quad in z = 0 as one PLY polygon (fan-triangulated into (0, 1, 2) and (0, 2, 3)),
/// with float vertex colours, a 1-channel float vertex attribute, uchar vertex properties
/// (kept unnormalised, as Mitsuba 3.9.1 does), a ushort face colour (normalised and
/// sRGB-decoded) and a 1-channel float face attribute.
const ATTRIBUTE_PLY: &str = "ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
property float r
property float g
property float b
property float rough_x
property uchar q_x
element face 1
property list uchar int vertex_indices
property ushort tint_r
property ushort tint_g
property ushort tint_b
property float w_0
end_header
0 0 0 1 0 0 0.1 0
1 0 0 0 1 0 0.2 100
1 1 0 0 0 1 0.3 200
0 1 0 1 1 1 0.4 255
4 0 1 2 3 65535 32768 0 0.75
";

/// A `ply` shape reading quad.ply, with `inner` (its BSDF) on lines of its own.
fn quad_ply_shape(inner: &str) -> String {
    format!(
        "<shape type=\"ply\">\n<string name=\"filename\" value=\"quad.ply\"/>\n{inner}\n</shape>"
    )
}

/// A `mesh_attribute` texture for parameter `param` reading attribute `name`, its `name`
/// parameter on a line of its own, then `extra`.
fn mesh_attribute_xml(param: &str, name: &str, extra: &str) -> String {
    format!("<texture type=\"mesh_attribute\" name=\"{param}\">\n<string name=\"name\" value=\"{name}\"/>{extra}\n</texture>")
}

/// The texture of parameter `name` in the BSDF of shape `shape`.
fn mesh_attribute_of(
    scene: &SceneDescription,
    shape: usize,
) -> (Arc<crate::texture::AttributeValues>, f32) {
    let t = match &scene.bsdfs[scene.shapes[shape].bsdf] {
        Bsdf::Diffuse(d) => d.reflectance.clone(),
        Bsdf::Blend(b) => b.weight.clone(),
        Bsdf::RoughConductor(c) => c.alpha_texture.clone().expect("textured alpha"),
        other => panic!("unexpected BSDF {other:?}"),
    };
    match t {
        Texture::MeshAttribute { values, scale } => (values, scale),
        other => panic!("mesh_attribute expected, got {other:?}"),
    }
}

/// Vertex attributes interpolate barycentrically and face attributes stay constant per
/// triangle, through the whole chain: PLY properties → grouping and conversion → binding to
/// the shape → a ray hit's triangle and barycentrics → the texture value.
#[test]
fn mesh_attribute_textures_read_ply_properties_at_ray_hits() {
    use crate::texture::TexPoint;
    let dir = temp_dir("mesh-attribute");
    std::fs::write(dir.join("quad.ply"), ATTRIBUTE_PLY).unwrap();
    let scale = "<float name=\"scale\" value=\"2\"/>";
    let shape = |bsdf: &str, param: &str, name: &str, rest: &str| {
        let texture = mesh_attribute_xml(param, name, scale);
        quad_ply_shape(&format!("<bsdf type=\"{bsdf}\">{texture}{rest}</bsdf>"))
    };
    let nested = "<bsdf type=\"diffuse\"/><bsdf type=\"conductor\"/>";
    let body = [
        SENSOR.to_string(),
        shape("diffuse", "reflectance", "vertex_color", ""),
        shape("diffuse", "reflectance", "face_tint_color", ""),
        shape("blendbsdf", "weight", "face_w", nested),
        shape("roughconductor", "alpha", "vertex_rough", ""),
        shape("diffuse", "reflectance", "vertex_q", ""),
    ]
    .join("\n");
    let desc = load(&write_scene(&dir, "scene.xml", &body)).unwrap();

    // The ray hits triangle 1 = (v0, v2, v3) at p = (0.2, 0.7): b0 = 0.3, b1 = 0.2 (v2),
    // b2 = 0.5 (v3); unequal weights, so a swapped corner would show.
    let scene = crate::scene::Scene::build(&desc).unwrap();
    let ray = crate::math::Ray::new(Vec3::new(0.2, 0.7, 1.0), -Vec3::Z);
    let si = scene.intersect(&ray).expect("hit");
    assert_eq!(si.prim, 1);
    assert!(
        (si.bary - Vec2::new(0.2, 0.5)).length() < 1e-6,
        "{}",
        si.bary
    );
    let at: TexPoint = si.tex();
    let eval = |shape: usize| {
        let (values, scale) = mesh_attribute_of(&desc, shape);
        Texture::MeshAttribute { values, scale }.eval(at)
    };
    let close = |a: Rgb, b: Rgb| (a - b).abs().max_element() < 1e-5;
    // 0.3·(1, 0, 0) + 0.2·(0, 0, 1) + 0.5·(1, 1, 1), times scale 2.
    assert!(close(eval(0), Rgb::new(1.6, 1.0, 1.4)), "{}", eval(0));
    // ushort 65535 → 1, 32768 → 0.500008 sRGB-decoded = 0.2140481, 0 → 0; times 2, on both triangles.
    assert!(
        close(eval(1), 2.0 * Rgb::new(1.0, 0.214_048_1, 0.0)),
        "{}",
        eval(1)
    );
    let (tint, _) = mesh_attribute_of(&desc, 1);
    assert_eq!(tint.values[..3], tint.values[3..]);
    assert!(close(eval(2), Rgb::splat(1.5)));
    // 0.3·0.1 + 0.2·0.3 + 0.5·0.4 = 0.29, times 2; read as one number.
    let (rough, scale) = mesh_attribute_of(&desc, 3);
    let alpha = Texture::MeshAttribute {
        values: rough,
        scale,
    }
    .eval_1(at);
    assert!((alpha - 0.58).abs() < 1e-6, "{alpha}");
    // uchar stays 0–255: 0.3·0 + 0.2·200 + 0.5·255, times 2.
    let q = eval(4);
    assert!((q - Rgb::splat(335.0)).abs().max_element() < 1e-3, "{q}");
}

/// A BSDF with an id that reads a mesh attribute is bound separately to each shape using it.
#[test]
fn a_shared_bsdf_reads_each_shapes_own_attribute() {
    let dir = temp_dir("mesh-attribute-shared");
    std::fs::write(dir.join("a.ply"), ATTRIBUTE_PLY).unwrap();
    std::fs::write(dir.join("b.ply"), ATTRIBUTE_PLY.replace("0.75\n", "0.5\n")).unwrap();
    let body = format!(
        "{SENSOR}
<texture type=\"mesh_attribute\" id=\"w\"><string name=\"name\" value=\"face_w\"/></texture>
<bsdf type=\"blendbsdf\" id=\"mix\"><ref name=\"weight\" id=\"w\"/><bsdf type=\"diffuse\"/><bsdf type=\"conductor\"/></bsdf>
<shape type=\"ply\"><string name=\"filename\" value=\"a.ply\"/><ref id=\"mix\"/></shape>
<shape type=\"ply\"><string name=\"filename\" value=\"b.ply\"/><ref id=\"mix\"/></shape>"
    );
    let desc = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert_ne!(desc.shapes[0].bsdf, desc.shapes[1].bsdf);
    assert_eq!(mesh_attribute_of(&desc, 0).0.values, [0.75, 0.75]);
    assert_eq!(mesh_attribute_of(&desc, 1).0.values, [0.5, 0.5]);
}

/// Mesh attributes that cannot be read are errors naming the file, line and element (Mitsuba
/// 3.9.1 raises them in scalar variants; its JIT variants render zero instead).
#[test]
fn error_mesh_attribute_cases_name_file_and_line() {
    let dir = temp_dir("mesh-attribute-errors");
    std::fs::write(dir.join("quad.ply"), ATTRIBUTE_PLY).unwrap();
    let ply = |inner: &str| format!("{SENSOR}\n{}", quad_ply_shape(inner));
    let tex = |param: &str, name: &str| mesh_attribute_xml(param, name, "");
    let diffuse = |name: &str| {
        format!(
            "<bsdf type=\"diffuse\">\n{}\n</bsdf>",
            tex("reflectance", name)
        )
    };
    // Bad prefix: the `name` parameter's line.
    let body = ply(&diffuse("color"));
    assert_body_error_at(
        &dir,
        "prefix.xml",
        &body,
        "value=\"color\"",
        "must start with \"vertex_\" or \"face_\"",
    );
    // Missing attribute: the texture's line; the shape and the attributes it has are named.
    let body = ply(&diffuse("vertex_uv"));
    let err = assert_body_error_at(
        &dir,
        "missing.xml",
        &body,
        "mesh_attribute",
        "no attribute \"vertex_uv\"",
    );
    let msg = err.to_string();
    let shape_line = line_of(&body, "<shape");
    assert!(
        msg.contains(&format!(
            "<shape type=\"ply\"> at {}",
            dir.join("missing.xml").display()
        )),
        "{msg}"
    );
    assert!(msg.contains(&format!("missing.xml:{shape_line}:")), "{msg}");
    assert!(
        msg.contains("vertex_color, vertex_rough, vertex_q, face_tint_color, face_w"),
        "{msg}"
    );
    // Not a mesh.
    let body = format!(
        "{SENSOR}\n<shape type=\"sphere\">\n{}\n</shape>",
        diffuse("vertex_color")
    );
    assert_body_error_at(
        &dir,
        "sphere.xml",
        &body,
        "mesh_attribute",
        "not a triangle mesh",
    );
    // A 3-channel attribute read as one number.
    let body = ply(&format!(
        "<bsdf type=\"roughconductor\">\n{}\n</bsdf>",
        tex("alpha", "vertex_color")
    ));
    assert_body_error_at(&dir, "alpha.xml", &body, "mesh_attribute", "eval_1");
    // Plastics take the texture's mean on load, which Mitsuba does not implement.
    let body = ply(&format!(
        "<bsdf type=\"plastic\">\n{}\n</bsdf>",
        tex("diffuse_reflectance", "vertex_color")
    ));
    assert_body_error_at(&dir, "plastic.xml", &body, "mesh_attribute", "mean");
    // Outside any shape: the area emitter holding the texture is refused at its own line
    // before the texture is read.
    let body = format!(
        "{SENSOR}\n<emitter type=\"area\">\n{}\n</emitter>",
        tex("radiance", "vertex_color")
    );
    assert_body_error_at(
        &dir,
        "loose.xml",
        &body,
        "<emitter",
        "<emitter type=\"area\">: an area emitter must be nested inside a <shape>",
    );
}

/// An area light whose radiance is a vertex attribute: light samples (next-event estimation)
/// read it at the sampled point's triangle and barycentrics, and a ray hitting the light reads
/// the same value there (Mitsuba 3.9.1 reads triangle 0 for light samples, see
/// docs/validation.md, `mesh-attribute`).
#[test]
fn mesh_attribute_radiance_is_read_where_the_light_is_sampled() {
    let dir = temp_dir("mesh-attribute-light");
    std::fs::write(dir.join("quad.ply"), ATTRIBUTE_PLY).unwrap();
    let emitter = format!(
        "<emitter type=\"area\">{}</emitter>",
        mesh_attribute_xml("radiance", "vertex_rough", "")
    );
    let body = format!("{SENSOR}\n{}", quad_ply_shape(&emitter));
    let desc = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    let scene = crate::scene::Scene::build(&desc).unwrap();
    // vertex_rough is 0.1, 0.2, 0.3, 0.4 at (0, 0), (1, 0), (1, 1), (0, 1); triangles (0, 1, 2)
    // below the diagonal and (0, 2, 3) above it.
    let expected = |x: f32, y: f32| {
        if y <= x {
            0.1 * (1.0 - x) + 0.2 * (x - y) + 0.3 * y
        } else {
            0.1 * (1.0 - y) + 0.3 * x + 0.4 * (y - x)
        }
    };
    let from = Vec3::new(0.5, 0.5, 1.0);
    for (i, u) in [(0.1, 0.2), (0.7, 0.3), (0.35, 0.9), (0.9, 0.95)]
        .into_iter()
        .enumerate()
    {
        let ls = scene
            .sample_li(
                from,
                Vec3::ZERO,
                (i as f32 + 0.5) / 4.0,
                Vec2::new(u.0, u.1),
            )
            .expect("a light sample");
        let radiance = ls.weight * ls.pdf;
        let want = expected(ls.p.x, ls.p.y);
        assert!(
            (radiance - Rgb::splat(want)).abs().max_element() < 1e-5,
            "{radiance} vs {want} at {}",
            ls.p
        );
        // The ray towards the sample hits the light where it reads the same radiance.
        let si = scene
            .intersect(&crate::math::Ray::new(from, ls.wi))
            .expect("hit");
        let seen = scene.emitted(&si, -ls.wi);
        assert!(
            (seen - radiance).abs().max_element() < 1e-4,
            "{seen} vs {radiance}"
        );
    }
}

/// `direct`'s sample counts, read as Mitsuba reads them: `shading_samples` sets both,
/// `emitter_samples` / `bsdf_samples` each one; mixing them, negative counts and no samples at
/// all are errors naming file and line.
#[test]
fn direct_sample_counts_and_their_errors() {
    let dir = temp_dir("direct-samples");
    let with =
        |props: &str| format!("{SENSOR}\n<integrator type=\"direct\">\n{props}\n</integrator>");
    let counts = |file: &str, props: &str| {
        let scene = load(&write_scene(&dir, file, &with(props))).unwrap();
        let i = scene.integrator.unwrap();
        (i.emitter_samples, i.bsdf_samples)
    };
    assert_eq!(counts("none.xml", ""), (1, 1));
    assert_eq!(
        counts(
            "shading.xml",
            r#"<integer name="shading_samples" value="4"/>"#
        ),
        (4, 4)
    );
    assert_eq!(
        counts(
            "emitter.xml",
            r#"<integer name="emitter_samples" value="3"/>"#
        ),
        (3, 1)
    );
    assert_eq!(
        counts(
            "both.xml",
            r#"<integer name="emitter_samples" value="0"/><integer name="bsdf_samples" value="2"/>"#
        ),
        (0, 2)
    );
    let body = with(
        r#"<integer name="shading_samples" value="2"/><integer name="bsdf_samples" value="2"/>"#,
    );
    assert_body_error_at(
        &dir,
        "mixed.xml",
        &body,
        "<integrator",
        "give either it or them",
    );
    let body = with(r#"<integer name="shading_samples" value="0"/>"#);
    assert_body_error_at(
        &dir,
        "zero.xml",
        &body,
        "<integrator",
        "at least one emitter or BSDF sample",
    );
    let body = with(r#"<integer name="emitter_samples" value="-1"/>"#);
    assert_body_error_at(
        &dir,
        "negative.xml",
        &body,
        "value=\"-1\"",
        "\"emitter_samples\" must be >= 0, got -1",
    );
}

#[test]
fn spot_lights_project_a_texture_and_refuse_a_constant_one() {
    let dir = temp_dir("spot-texture");
    let spot = |inner: &str| {
        format!("{SENSOR}\n<emitter type=\"spot\"><rgb name=\"intensity\" value=\"2\"/>\n{inner}\n</emitter>")
    };
    let body = spot("<texture type=\"checkerboard\" name=\"texture\"/>");
    let desc = load(&write_scene(&dir, "ok.xml", &body)).unwrap();
    match &desc.emitters[..] {
        [EmitterDesc::Spot {
            texture: Some(crate::texture::Texture::Checkerboard { .. }),
            ..
        }] => {}
        other => panic!("{other:?}"),
    }
    let body = spot("<rgb name=\"texture\" value=\"0.5\"/>");
    assert_body_error_at(
        &dir,
        "constant.xml",
        &body,
        "name=\"texture\"",
        "must be spatially varying",
    );
    let body = spot("<texture type=\"mesh_attribute\" name=\"texture\"><string name=\"name\" value=\"vertex_color\"/></texture>");
    assert_body_error_at(
        &dir,
        "attr.xml",
        &body,
        "mesh_attribute",
        "can only be used by a shape's BSDF or area emitter",
    );
}

/// Mitsuba lets a film, sampler or reconstruction filter be declared at the top level with an
/// id and named by a `<ref>` where it is used; one that nothing names is ignored.
#[test]
fn films_samplers_and_filters_declared_outside_the_sensor() {
    let dir = temp_dir("detached");
    let body = r#"<sampler type="independent" id="spp"><integer name="sample_count" value="24"/></sampler>
<rfilter type="tent" id="filter"><float name="radius" value="1.5"/></rfilter>
<film type="hdrfilm" id="film"><integer name="width" value="20"/><integer name="height" value="10"/><ref id="filter"/></film>
<sensor type="perspective"><ref id="film"/><ref id="spp"/></sensor>"#;
    let scene = load(&write_scene(&dir, "refs.xml", body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!(scene.sample_count, Some(24));
    let c = &scene.camera;
    assert_eq!((c.width, c.height), (20, 10));
    assert_eq!(c.filter, FilterDesc::Tent { radius: 1.5 });

    // Unnamed by any `<ref>`: checked, ignored with a warning, the sensor's own settings stand.
    let body = r#"<sampler type="independent" id="unused"><integer name="sample_count" value="24"/></sampler>
<rfilter type="box"/>
<sensor type="perspective"><sampler type="independent"><integer name="sample_count" value="3"/></sampler></sensor>"#;
    let scene = load(&write_scene(&dir, "unused.xml", body)).unwrap();
    assert_eq!(scene.sample_count, Some(3));
    assert_eq!(scene.camera.filter, FilterDesc::Gaussian { stddev: 0.5 });
    assert_eq!(scene.warnings.len(), 2, "{:?}", scene.warnings);
    assert!(scene.warnings.iter().all(|w| w.contains("no <ref> names")));
    // ... but checked as Mitsuba instantiates it.
    let body = r#"<film type="hdrfilm"><integer name="width" value="-2"/></film>
<shape type="sphere"/>"#;
    assert_body_error_at(&dir, "bad.xml", body, "width", "\"width\" must be in");

    // A reference to something else is an error at the reference.
    let body = r#"<bsdf type="diffuse" id="m"/>
<sensor type="perspective"><ref id="m"/></sensor>"#;
    assert_body_error_at(
        &dir,
        "wrong.xml",
        body,
        "<sensor",
        "refers to a <film>, a <sampler> or a <medium>",
    );
    let body = r#"<bsdf type="diffuse" id="m"/>
<sensor type="perspective"><film type="hdrfilm"><ref id="m"/></film></sensor>"#;
    assert_body_error_at(
        &dir,
        "wrong2.xml",
        body,
        "<sensor",
        "refers to an <rfilter>",
    );
    let body = r#"<sensor type="perspective"><ref id="nowhere"/></sensor>"#;
    assert_body_error_at(
        &dir,
        "dangling.xml",
        body,
        "<sensor",
        "unknown id \"nowhere\"",
    );
}

/// Mitsuba's `<path value>` adds a folder where file names are looked up first (the latest
/// first), for plugins and includes alike; `<alias id as>` gives an element a second id.
#[test]
fn path_folders_and_aliases_as_mitsuba() {
    let dir = temp_dir("path-alias");
    write_part_triangle(&dir);
    let triangle = |file: &str, size: u32| {
        let path = dir.join(file);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(
            path,
            format!("v 0 0 0\nv {size} 0 0\nv 0 {size} 0\nf 1 2 3\n"),
        )
        .unwrap();
    };
    // Files of the same name in the scene's folder and in search folders.
    triangle("tri.obj", 5);
    triangle("other/tri.obj", 2);
    triangle("meshes/tri.obj", 3);
    std::fs::create_dir_all(dir.join("other/meshes")).unwrap();
    std::fs::write(
        dir.join("other/part.xml"),
        "<scene version=\"3.0.0\">\n<shape type=\"obj\" id=\"inc\"><string name=\"filename\" value=\"tri.obj\"/></shape>\n</scene>\n",
    )
    .unwrap();
    let body = r#"<sensor type="perspective"/>
<path value="parts/meshes"/>
<path value="other"/>
<include filename="part.xml"/>
<bsdf type="diffuse" id="red"><rgb name="reflectance" value="0.8, 0.1, 0.1"/></bsdf>
<alias id="red" as="crimson"/>
<shape type="obj" id="a"><string name="filename" value="tri.obj"/><ref id="crimson"/></shape>
<shape type="obj" id="b"><string name="filename" value="meshes/tri.obj"/><ref id="red"/></shape>"#;
    let path = write_scene(&dir, "scene.xml", body);
    let scene = load(&path).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let shape = |name: &str| {
        let shape = scene.shapes.iter().find(|s| s.name == name).unwrap();
        let Geometry::Mesh(m) = &shape.geometry else {
            panic!("{name}: not a mesh")
        };
        (m.positions[1].x, shape.bsdf)
    };
    // "other" was named last, so it is searched first (size 2), before parts/meshes (1) and
    // the scene's own folder (5); the include is looked up the same way (other/part.xml).
    assert_eq!(shape("a").0, 2.0);
    assert_eq!(shape("inc").0, 2.0);
    // A name no search folder has falls back to the scene's folder.
    assert_eq!(shape("b").0, 3.0);
    // The alias and the id name one BSDF, built once.
    assert_eq!(shape("a").1, shape("b").1);
    // The file list of the scene follows the same lookup.
    let files = scene_files(&path, &[]).unwrap();
    for f in ["other/part.xml", "other/tri.obj", "meshes/tri.obj"] {
        assert!(files.contains(&dir.join(f)), "{f}: {files:?}");
    }

    // Errors: a missing folder, a nested <path>, an alias before its source or of a taken id.
    assert_body_error_at(
        &dir,
        "e1.xml",
        r#"<path value="nowhere"/>"#,
        "<path",
        "folder",
    );
    assert_body_error_at(
        &dir,
        "e2.xml",
        "<shape type=\"sphere\">\n<path value=\"other\"/>\n</shape>",
        "<path",
        "only be a child of <scene>",
    );
    assert_body_error_at(
        &dir,
        "e3.xml",
        "<alias id=\"m\" as=\"n\"/>\n<bsdf type=\"diffuse\" id=\"m\"/>",
        "<alias",
        "alias source id \"m\" not found",
    );
    assert_body_error_at(
        &dir,
        "e4.xml",
        "<bsdf type=\"diffuse\" id=\"m\"/>\n<bsdf type=\"diffuse\" id=\"n\"/>\n<alias id=\"m\" as=\"n\"/>",
        "<alias",
        "already names",
    );
}

/// A scene of Mitsuba 0.6 (`version` < 2.0) loads as Mitsuba 3 loads it: camelCase parameter
/// names in snake_case, a diffuse BSDF's `diffuseReflectance` as its `reflectance`, and a
/// texture's `uoffset` … `vscale` as its `to_uv` — the same description as the file in today's
/// names. (Rendered by Mitsuba 3.9.1 and by us: means within 0.3 % at 1024 spp.)
#[test]
fn scenes_before_version_2_are_upgraded_as_mitsuba_does() {
    let dir = temp_dir("legacy");
    let legacy = r#"<integrator type="path"><integer name="maxDepth" value="4"/><integer name="rrDepth" value="3"/></integrator>
<sensor type="perspective"><float name="fov" value="40"/><string name="fovAxis" value="smaller"/>
<transform name="toWorld"><lookat origin="0,1,4" target="0,0,0" up="0,1,0"/></transform>
<sampler type="independent"><integer name="sampleCount" value="64"/></sampler></sensor>
<shape type="rectangle"><transform name="toWorld"><scale value="3"/></transform>
<bsdf type="diffuse"><texture type="checkerboard" name="diffuseReflectance"><float name="uscale" value="4"/><float name="vscale" value="2"/><float name="uoffset" value="0.1"/></texture></bsdf></shape>
<shape type="sphere"><bsdf type="roughdielectric"><float name="intIOR" value="1.6"/><rgb name="specularReflectance" value="0.9"/></bsdf></shape>
<shape type="sphere"><point name="center" x="0" y="3" z="0"/><emitter type="area"><rgb name="radiance" value="10"/></emitter></shape>"#;
    let modern = r#"<integrator type="path"><integer name="max_depth" value="4"/><integer name="rr_depth" value="3"/></integrator>
<sensor type="perspective"><float name="fov" value="40"/><string name="fov_axis" value="smaller"/>
<transform name="to_world"><lookat origin="0,1,4" target="0,0,0" up="0,1,0"/></transform>
<sampler type="independent"><integer name="sample_count" value="64"/></sampler></sensor>
<shape type="rectangle"><transform name="to_world"><scale value="3"/></transform>
<bsdf type="diffuse"><texture type="checkerboard" name="reflectance"><transform name="to_uv"><translate x="0.1"/><scale x="4" y="2"/></transform></texture></bsdf></shape>
<shape type="sphere"><bsdf type="roughdielectric"><float name="int_ior" value="1.6"/><rgb name="specular_reflectance" value="0.9"/></bsdf></shape>
<shape type="sphere"><point name="center" x="0" y="3" z="0"/><emitter type="area"><rgb name="radiance" value="10"/></emitter></shape>"#;
    let old_path = dir.join("old.xml");
    std::fs::write(
        &old_path,
        format!("<scene version=\"0.6.0\">\n{legacy}\n</scene>\n"),
    )
    .unwrap();
    let old = load(&old_path).unwrap();
    let new = load(&write_scene(&dir, "new.xml", modern)).unwrap();
    assert!(old.warnings.is_empty(), "{:?}", old.warnings);
    assert_eq!(format!("{:?}", old.bsdfs), format!("{:?}", new.bsdfs));
    assert_eq!(format!("{:?}", old.shapes), format!("{:?}", new.shapes));
    assert_eq!(format!("{:?}", old.camera), format!("{:?}", new.camera));
    assert_eq!(
        format!("{:?}", old.integrator),
        format!("{:?}", new.integrator)
    );
    assert_eq!(old.sample_count, Some(64));
    // The same names in a version 3 file are unknown parameters.
    let err = load(&write_scene(&dir, "v3.xml", legacy))
        .unwrap_err()
        .to_string();
    assert!(err.contains("unknown parameter \"maxDepth\""), "{err}");
    // The conversion itself, as Mitsuba's camel_to_underscore_case.
    for (from, to) in [
        ("intIOR", "int_ior"),
        ("specularReflectance", "specular_reflectance"),
        ("toWorld", "to_world"),
        ("IOR", "IOR"),
        ("already_snake", "already_snake"),
        ("aBcD", "a_bc_d"),
    ] {
        assert_eq!(crate::parity::upgrade::snake_case(from), to);
    }
    // A texture offset that is not a number is an error at its line.
    let bad = "<shape type=\"sphere\"><bsdf type=\"diffuse\"><texture type=\"checkerboard\" name=\"reflectance\">\n<string name=\"uscale\" value=\"x\"/></texture></bsdf></shape>";
    let path = dir.join("bad.xml");
    std::fs::write(
        &path,
        format!("<scene version=\"0.5.0\">\n{bad}\n</scene>\n"),
    )
    .unwrap();
    assert_error_at(&path, 3, "\"uscale\" must be a <float>");
}

/// `<spectrum type="…">` plugins as Mitsuba's RGB variants evaluate them (each value checked
/// against Mitsuba 3.9.1 `scalar_rgb` renders of an emitting sphere).
#[test]
fn typed_spectra_as_mitsubas_rgb_variants() {
    let dir = temp_dir("typed-spectra");
    let emitted = |spectrum: &str| {
        let body = format!(
            "{SENSOR}\n<shape type=\"sphere\"><emitter type=\"area\">\n{spectrum}\n</emitter></shape>"
        );
        let scene = load(&write_scene(&dir, "s.xml", &body))?;
        Ok::<_, SceneError>(format!("{:?}", scene.shapes[0].emission))
    };
    let constant = |c: Rgb| format!("{:?}", Some(Texture::Constant(c)));
    let cases = [
        (
            r#"<spectrum type="uniform" name="radiance"><float name="value" value="2"/></spectrum>"#,
            Rgb::splat(2.0),
        ),
        (
            r#"<spectrum type="srgb" name="radiance"><rgb name="color" value="0.5, 0.2, 0.1"/></spectrum>"#,
            Rgb::new(0.5, 0.2, 0.1),
        ),
        (
            r#"<spectrum type="srgb" name="radiance"><rgb name="color" value="5, 0.2, 0.1"/><boolean name="unbounded" value="true"/></spectrum>"#,
            Rgb::new(5.0, 0.2, 0.1),
        ),
        (r#"<spectrum type="d65" name="radiance"/>"#, Rgb::ONE),
        (
            r#"<spectrum type="d65" name="radiance"><rgb name="color" value="0.5, 0.2, 0.1"/><float name="scale" value="3"/></spectrum>"#,
            Rgb::new(1.5, 0.6, 0.3),
        ),
    ];
    for (spectrum, want) in cases {
        assert_eq!(emitted(spectrum).unwrap(), constant(want), "{spectrum}");
    }
    // Refused, as by Mitsuba: a bounded srgb colour above 1, the measured spectra.
    for (spectrum, needle) in [
        (
            r#"<spectrum type="srgb" name="radiance"><rgb name="color" value="5, 0.2, 0.1"/></spectrum>"#,
            "must be in [0, 1]",
        ),
        (
            r#"<spectrum type="blackbody" name="radiance"><float name="temperature" value="3000"/></spectrum>"#,
            "has no RGB form",
        ),
        (
            r#"<spectrum type="uniform" name="radiance"/>"#,
            "missing parameter \"value\"",
        ),
        (
            r#"<spectrum type="uniform" name="radiance"><float name="value" value="1"/><float name="scael" value="2"/></spectrum>"#,
            "unknown parameter \"scael\"",
        ),
    ] {
        let err = emitted(spectrum).unwrap_err().to_string();
        assert!(err.contains(needle) && err.contains("s.xml:"), "{err}");
    }
}

/// A typed spectrum declared at the top level and named by `<ref>`s (Mitsuba's spectra are
/// textures): as a BSDF's colour, inside a texture, and as an emitter's radiance; a top-level
/// `<ref>` to it is a declaration. Mitsuba 3.9.1 renders the test scene of the first kind the
/// same (means 0.8802 / 0.5742 / 0.5742 against our 0.8798 / 0.5741 / 0.5741 at 256 spp).
#[test]
fn top_level_typed_spectra_are_textures_for_refs() {
    let dir = temp_dir("top-level-spectra");
    let body = format!(
        r#"<spectrum type="srgb" id="red"><rgb name="color" value="0.8, 0.1, 0.1"/></spectrum>
<spectrum type="uniform" id="two"><float name="value" value="2"/></spectrum>
<ref id="red"/>
<texture type="checkerboard" id="chk"><rgb name="color0" value="0.2"/><ref name="color1" id="red"/></texture>
{SENSOR}
<shape type="rectangle"><bsdf type="diffuse"><ref name="reflectance" id="red"/></bsdf></shape>
<shape type="sphere"><bsdf type="diffuse"><ref name="reflectance" id="chk"/></bsdf></shape>
<shape type="sphere"><emitter type="area"><ref name="radiance" id="two"/></emitter></shape>"#
    );
    let scene = load(&write_scene(&dir, "s.xml", &body)).unwrap();
    let red = Rgb::new(0.8, 0.1, 0.1);
    let Bsdf::Diffuse(d) = &scene.bsdfs[scene.shapes[0].bsdf] else {
        panic!("{:?}", scene.bsdfs)
    };
    assert_eq!(
        format!("{:?}", d.reflectance),
        format!("{:?}", Texture::Constant(red))
    );
    let Bsdf::Diffuse(d) = &scene.bsdfs[scene.shapes[1].bsdf] else {
        panic!("{:?}", scene.bsdfs)
    };
    let Texture::Checkerboard { color1, .. } = &d.reflectance else {
        panic!("{:?}", d.reflectance)
    };
    assert_eq!(*color1, red);
    assert_eq!(
        format!("{:?}", scene.shapes[2].emission),
        format!("{:?}", Some(Texture::Constant(Rgb::splat(2.0))))
    );
    // Declared but wrong: the error names the declaration; an untyped one is no declaration.
    for (decl, needle) in [
        (
            r#"<spectrum type="blackbody" id="b"><float name="temperature" value="3000"/></spectrum>"#,
            "has no RGB form",
        ),
        (
            r#"<spectrum id="b" value="0.5"/>"#,
            "unexpected element <spectrum> in <scene>",
        ),
    ] {
        let body = format!("{SENSOR}\n{decl}");
        assert_body_error_at(&dir, "e.xml", &body, "id=\"b\"", needle);
    }
}

/// Mitsuba's `null` BSDF lets light through as a mask of opacity 0 does (Mitsuba 3.9.1 renders
/// both the same: mean 0.2708 / 0.2713 at 1024 spp on a test scene).
#[test]
fn null_bsdf_is_a_fully_transparent_mask() {
    let dir = temp_dir("null-bsdf");
    let body = format!("{SENSOR}\n<shape type=\"sphere\"><bsdf type=\"null\"/></shape>");
    let scene = load(&write_scene(&dir, "s.xml", &body)).unwrap();
    let Bsdf::Mask(m) = &scene.bsdfs[scene.shapes[0].bsdf] else {
        panic!("{:?}", scene.bsdfs)
    };
    assert_eq!(m.opacity.mean(), Vec3::ZERO);
    let body = format!("{SENSOR}\n<shape type=\"sphere\"><bsdf type=\"null\">\n<float name=\"opacity\" value=\"1\"/></bsdf></shape>");
    assert_body_error_at(
        &dir,
        "p.xml",
        &body,
        "opacity",
        "unknown parameter \"opacity\"",
    );
}

/// `projector`: the perspective camera's field of view over the image's aspect ratio, a
/// constant irradiance of 1 by default, and its values checked.
#[test]
fn projectors_take_the_cameras_field_of_view_over_their_image() {
    let dir = temp_dir("projector");
    std::fs::create_dir_all(dir.join("tex")).unwrap();
    image::RgbImage::new(40, 20)
        .save(dir.join("tex/wide.png"))
        .unwrap();
    let projector = |inner: &str| {
        let body = format!("{SENSOR}\n<emitter type=\"projector\">\n{inner}\n</emitter>");
        load(&write_scene(&dir, "p.xml", &body))
    };
    let fov_of = |scene: &SceneDescription| match &scene.emitters[0] {
        EmitterDesc::Projector {
            fov_x,
            scale,
            irradiance,
            ..
        } => (*fov_x, *scale, format!("{irradiance:?}")),
        e => panic!("{e:?}"),
    };
    // A constant: aspect 1, irradiance 1, scale 1; Mitsuba's default focal length 50 mm.
    let (fov, scale, irradiance) = fov_of(&projector("").unwrap());
    assert_eq!(scale, 1.0);
    assert_eq!(irradiance, format!("{:?}", Texture::Constant(Rgb::ONE)));
    let diagonal_50mm = 2.0 * (43.2666f64 / 2.0 / 50.0).atan().to_degrees() as f32;
    let want = crate::camera::horizontal_fov(diagonal_50mm, FovAxis::Diagonal, 1.0);
    assert!((fov - want).abs() < 1e-3, "{fov} vs {want}");
    // A 40x20 image with 30° on its smaller (vertical) axis: tan(x/2) = 2·tan(15°).
    let inner = r#"<texture type="bitmap" name="irradiance"><string name="filename" value="tex/wide.png"/></texture>
<float name="fov" value="30"/><string name="fov_axis" value="smaller"/><float name="scale" value="2"/>"#;
    let (fov, scale, _) = fov_of(&projector(inner).unwrap());
    let want = 2.0 * (2.0 * 15f32.to_radians().tan()).atan().to_degrees();
    assert!((fov - want).abs() < 1e-3 && scale == 2.0, "{fov} vs {want}");
    // Errors name the parameter's line.
    for (inner, needle) in [
        (
            r#"<float name="scale" value="-1"/>"#,
            "must not be negative",
        ),
        (r#"<rgb name="irradiance" value="-1"/>"#, "non-negative"),
        (r#"<float name="fov" value="180"/>"#, "field of view"),
        (
            r#"<float name="fov" value="30"/><string name="focal_length" value="35mm"/>"#,
            "not both",
        ),
    ] {
        let err = projector(inner).unwrap_err().to_string();
        assert!(err.contains(needle) && err.contains("p.xml:5:"), "{err}");
    }
}

/// A file named inside an `<include>`d file is looked up as Mitsuba 3.9.1 looks it up: in the
/// scene file's folder (the file resolver's), not the included file's — which is tried last,
/// where Mitsuba reports the file missing.
#[test]
fn names_in_included_files_resolve_against_the_scene_folder() {
    let dir = temp_dir("include-lookup");
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    let triangle = |file: &str, size: u32| {
        std::fs::write(
            dir.join(file),
            format!("v 0 0 0\nv {size} 0 0\nv 0 {size} 0\nf 1 2 3\n"),
        )
        .unwrap();
    };
    std::fs::write(
        dir.join("sub/part.xml"),
        "<scene version=\"3.0.0\">\n<shape type=\"obj\" id=\"inc\"><string name=\"filename\" value=\"tri.obj\"/></shape>\n</scene>\n",
    )
    .unwrap();
    let body = format!("{SENSOR}\n<include filename=\"sub/part.xml\"/>");
    let path = write_scene(&dir, "scene.xml", &body);
    let size = || {
        let scene = load(&path).unwrap();
        let Geometry::Mesh(m) = &scene.shapes[0].geometry else {
            panic!()
        };
        m.positions[1].x
    };
    // Only next to the scene (Mitsuba's layout): found there.
    triangle("tri.obj", 7);
    assert_eq!(size(), 7.0);
    // Next to both: the scene's folder wins, as in Mitsuba.
    triangle("sub/tri.obj", 2);
    assert_eq!(size(), 7.0);
    // Only next to the included file: found as a last resort (Mitsuba: file not found).
    std::fs::remove_file(dir.join("tri.obj")).unwrap();
    assert_eq!(size(), 2.0);
}

/// `twosided` refuses models that transmit light unless `allow_transmission`, as Mitsuba 3.9.1
/// does (with it, both render the same: docs/formats.md).
#[test]
fn twosided_transmission_needs_allow_transmission() {
    let dir = temp_dir("twosided-transmission");
    let scene = |inner: &str, allow: bool| {
        let flag = if allow {
            r#"<boolean name="allow_transmission" value="true"/>"#
        } else {
            ""
        };
        let body = format!(
            "{SENSOR}\n<shape type=\"sphere\"><bsdf type=\"twosided\">{flag}\n{inner}</bsdf></shape>"
        );
        load(&write_scene(&dir, "t.xml", &body))
    };
    for inner in [
        r#"<bsdf type="dielectric"/>"#,
        r#"<bsdf type="roughdielectric"/>"#,
        r#"<bsdf type="null"/>"#,
        r#"<bsdf type="mask"><bsdf type="diffuse"/></bsdf>"#,
        r#"<bsdf type="principled"><float name="spec_trans" value="0.5"/></bsdf>"#,
        r#"<bsdf type="diffuse"/><bsdf type="thindielectric"/>"#,
        r#"<bsdf type="blendbsdf"><bsdf type="diffuse"/><bsdf type="dielectric"/></bsdf>"#,
    ] {
        let err = scene(inner, false).unwrap_err().to_string();
        assert!(
            err.contains("t.xml:5:") && err.contains("allow_transmission"),
            "{inner}: {err}"
        );
        let loaded = scene(inner, true).unwrap();
        assert!(matches!(
            loaded.bsdfs[loaded.shapes[0].bsdf],
            Bsdf::TwoSided { .. }
        ));
    }
    // Reflection only: no flag needed.
    for inner in [
        r#"<bsdf type="diffuse"/>"#,
        r#"<bsdf type="roughplastic"/><bsdf type="conductor"/>"#,
        r#"<bsdf type="principled"/>"#,
    ] {
        assert!(scene(inner, false).is_ok(), "{inner}");
    }
}

/// A bitmap's storage `format` and `accel` (Mitsuba's) are accepted; a bad format is refused.
#[test]
fn bitmap_storage_options_are_accepted() {
    let dir = temp_dir("bitmap-format");
    std::fs::create_dir_all(dir.join("tex")).unwrap();
    image::RgbImage::new(4, 4)
        .save(dir.join("tex/a.png"))
        .unwrap();
    let scene = |extra: &str| {
        let body = format!(
            "{SENSOR}\n<shape type=\"sphere\"><bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\"><string name=\"filename\" value=\"tex/a.png\"/>\n{extra}</texture></bsdf></shape>"
        );
        load(&write_scene(&dir, "b.xml", &body))
    };
    let quiet =
        scene(r#"<string name="format" value="variant"/><boolean name="accel" value="false"/>"#)
            .unwrap();
    assert!(quiet.warnings.is_empty(), "{:?}", quiet.warnings);
    let half = scene(r#"<string name="format" value="float16"/>"#).unwrap();
    assert!(half.warnings.iter().any(|w| w.contains("single precision")));
    let err = scene(r#"<string name="format" value="float64"/>"#)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("b.xml:5:") && err.contains("invalid format"),
        "{err}"
    );
}

/// A `<ref>` at the top level adds the object once more, as Mitsuba 3.9.1 does (its scene then
/// holds two emitters and two shapes for the file below); a BSDF stays a declaration.
#[test]
fn top_level_references_add_the_object_again() {
    let dir = temp_dir("top-level-ref");
    let body = format!(
        "{SENSOR}\n<emitter type=\"point\" id=\"l\"><point name=\"position\" value=\"0, 2, 0\"/></emitter>\n<ref id=\"l\"/>\n<bsdf type=\"diffuse\" id=\"m\"/>\n<ref id=\"m\"/>\n<shape type=\"sphere\" id=\"s\"><ref id=\"m\"/></shape>\n<ref id=\"s\"/>"
    );
    let scene = load(&write_scene(&dir, "r.xml", &body)).unwrap();
    assert_eq!((scene.emitters.len(), scene.shapes.len()), (2, 2));
    assert_eq!(scene.bsdfs.len(), 1);
    // Anything else is refused at the reference; a dangling one too.
    let body = format!("{SENSOR}\n<integrator type=\"path\" id=\"i\"/>\n<ref id=\"i\"/>");
    assert_body_error_at(&dir, "i.xml", &body, "<ref", "not supported");
    let body = format!("{SENSOR}\n<ref id=\"nowhere\"/>");
    assert_body_error_at(&dir, "d.xml", &body, "<ref", "unknown id");
}

/// `$` substitution as Mitsuba 3.9.1's parser does it: `\$` is a literal dollar sign, and a
/// parameter name is matched as the longest defined name at the `$` (`$spp2` with only `spp`
/// defined reads as its value followed by "2").
#[test]
fn dollar_escapes_and_longest_parameter_names() {
    let mut used = std::collections::HashSet::new();
    let params: HashMap<String, String> = [("spp", "64"), ("spp_max", "128"), ("a", "x")]
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let sub =
        |v: &str, used: &mut std::collections::HashSet<String>| super::substitute(v, &params, used);
    assert_eq!(sub(r"price\$5", &mut used).unwrap(), "price$5");
    assert_eq!(sub(r"\$spp is $spp", &mut used).unwrap(), "$spp is 64");
    assert_eq!(sub("$spp2", &mut used).unwrap(), "642");
    assert_eq!(sub("$spp_max/$spp_min", &mut used).unwrap(), "128/64_min");
    assert_eq!(sub("$spp_max,$a", &mut used).unwrap(), "128,x");
    assert!(sub("cost: $", &mut used)
        .unwrap_err()
        .contains("followed by a parameter name"));
    assert!(sub("$nope", &mut used)
        .unwrap_err()
        .contains("undefined parameter \"$nope\""));
    let mut names: Vec<_> = used.into_iter().collect();
    names.sort();
    assert_eq!(names, ["a", "spp", "spp_max"]);
}

/// Media: a declared medium referred to as a shape's interior, a nested one as another
/// shape's exterior, the sensor's medium by `<ref>`, Mitsuba's defaults and `scale`.
#[test]
fn media_are_read_with_their_interfaces() {
    use crate::parity::media::{Density, MediumInterface, PhaseFunction};
    let dir = temp_dir("media");
    let body = r#"<medium type="homogeneous" id="fog">
    <rgb name="sigma_t" value="0.5, 0.25, 1"/>
    <float name="scale" value="4"/>
    <rgb name="albedo" value="0.9, 0.8, 0.7"/>
    <phase type="hg"><float name="g" value="-0.25"/></phase>
</medium>
<sensor type="perspective"><float name="fov" value="40"/><ref id="fog"/>
<film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="8"/></film></sensor>
<shape type="sphere"><bsdf type="null"/><ref name="interior" id="fog"/></shape>
<shape type="cube">
    <bsdf type="dielectric"/>
    <medium type="homogeneous" name="exterior"><boolean name="sample_emitters" value="false"/></medium>
</shape>
<shape type="rectangle"/>"#;
    let scene = load(&write_scene(&dir, "scene.xml", body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert_eq!(scene.media.len(), 2);
    let fog = &scene.media[0];
    assert_eq!(fog.name, "fog");
    assert_eq!(
        fog.density,
        Density::Homogeneous {
            sigma_t: Vec3::new(2.0, 1.0, 4.0),
            albedo: Vec3::new(0.9, 0.8, 0.7)
        }
    );
    assert_eq!(fog.phase, PhaseFunction::HenyeyGreenstein { g: -0.25 });
    assert!(fog.sample_emitters);
    // Mitsuba's defaults: sigma_t 1, albedo 0.75, isotropic.
    let nested = &scene.media[1];
    assert_eq!(
        (&nested.density, &nested.phase),
        (
            &Density::Homogeneous {
                sigma_t: Vec3::ONE,
                albedo: Vec3::splat(0.75)
            },
            &PhaseFunction::Isotropic
        )
    );
    assert!(!nested.sample_emitters);
    assert_eq!(scene.camera_medium, Some(0));
    let interfaces: Vec<MediumInterface> = scene.shapes.iter().map(|s| s.media).collect();
    assert_eq!(
        interfaces,
        [
            MediumInterface {
                interior: Some(0),
                exterior: None
            },
            MediumInterface {
                interior: None,
                exterior: Some(1)
            },
            MediumInterface::default(),
        ]
    );
    // Built once although referred to twice; the scene builds.
    crate::scene::Scene::build(&scene).unwrap();
}

/// Every media error names the file, line and element.
#[test]
fn error_media_cases_name_file_and_line() {
    let dir = temp_dir("media-errors");
    let cases: [(&str, &str, &str); 8] = [
        (
            r#"<medium type="smoke" id="m"/>"#,
            "smoke",
            "unsupported medium \"smoke\"",
        ),
        (
            r#"<medium type="homogeneous" id="m"><phase type="sggx"/></medium>"#,
            "sggx",
            "unsupported phase function \"sggx\"",
        ),
        (
            r#"<medium type="homogeneous" id="m"><phase type="hg"><float name="g" value="1"/></phase></medium>"#,
            "name=\"g\"",
            "\"g\" must lie in (-1, 1)",
        ),
        (
            r#"<medium type="homogeneous" id="m"><float name="albedo" value="1.5"/></medium>"#,
            "albedo",
            "\"albedo\" must lie in [0, 1]",
        ),
        (
            r#"<medium type="homogeneous" id="m"><float name="sigma_t" value="-1"/></medium>"#,
            "sigma_t",
            "\"sigma_t\" must be finite and >= 0",
        ),
        (
            r#"<shape type="sphere"><medium type="homogeneous"/></shape>"#,
            "<medium",
            "must be named \"interior\" or \"exterior\"",
        ),
        (
            r#"<shape type="sphere"><medium type="homogeneous" name="interior"/>
<medium type="homogeneous" name="interior"/></shape>"#,
            "<medium type=\"homogeneous\" name=\"interior\"/></shape>",
            "parameter \"interior\" given twice",
        ),
        (
            r#"<bsdf type="diffuse" id="d"/><emitter type="point"><ref id="d"/></emitter>"#,
            "<emitter",
            "inside an emitter",
        ),
    ];
    for (i, (body, marker, needle)) in cases.iter().enumerate() {
        let body = format!("{SENSOR}\n{body}");
        assert_body_error_at(&dir, &format!("case{i}.xml"), &body, marker, needle);
    }
}

/// `tabphase` (values separated by commas and spaces) and `blendphase` (a float or volume
/// weight, two nested phase functions — declared, referred to or nested in a blend — in file
/// order), and their errors with file and line.
#[test]
fn tabulated_and_blended_phases_are_read() {
    use crate::parity::media::PhaseFunction;
    let dir = temp_dir("phases");
    let body = format!(
        r#"{SENSOR}
<phase type="tabphase" id="table"><string name="values" value="1, 3 2,0"/></phase>
<medium type="homogeneous" id="a"><ref id="table"/></medium>
<medium type="homogeneous" id="b">
  <phase type="blendphase">
    <float name="weight" value="0.25"/>
    <phase type="hg" name="phase_0"><float name="g" value="0.5"/></phase>
    <ref id="table"/>
  </phase>
</medium>
<medium type="homogeneous" id="c">
  <phase type="blendphase">
    <volume type="constvolume" name="weight"><rgb name="value" value="0.2, 0.4, 0.9"/></volume>
    <phase type="blendphase"><phase type="isotropic"/><phase type="rayleigh"/></phase>
    <phase type="isotropic"/>
  </phase>
</medium>
<shape type="sphere"><bsdf type="null"/><ref name="interior" id="a"/></shape>
<shape type="sphere"><bsdf type="null"/><ref name="interior" id="b"/></shape>
<shape type="sphere"><bsdf type="null"/><ref name="interior" id="c"/></shape>"#
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let (p, d_in) = (Vec3::ZERO, Vec3::Z);
    let PhaseFunction::Tabulated(_) = &scene.media[0].phase else {
        panic!("{:?}", scene.media[0].phase)
    };
    // Values 1, 3, 2, 0 at cos θ = −1, −1/3, 1/3, 1: the trapezoids sum to 4/3 + 5/3 + 2/3 =
    // 11/3, so forward scattering (cos θ = 1) has density 0 and cos θ = 1/3 has 6/(11·2π).
    let table = &scene.media[0].phase;
    let at = |phase: &PhaseFunction, c: f32| {
        phase.eval(p, d_in, Vec3::new((1.0 - c * c).sqrt(), 0.0, c))
    };
    assert_eq!(at(table, 1.0), 0.0);
    let two_pi = 2.0 * std::f32::consts::PI;
    assert!((at(table, 1.0 / 3.0) - 6.0 / (11.0 * two_pi)).abs() < 1e-6);
    let hg = PhaseFunction::HenyeyGreenstein { g: 0.5 };
    for c in [-0.9, 0.0, 0.7] {
        let mixed = 0.75 * at(&hg, c) + 0.25 * at(table, c);
        assert!((at(&scene.media[1].phase, c) - mixed).abs() < 1e-6);
        // A constvolume weight is the mean of its channels (0.5): an even mix of the inner
        // blend (itself an even mix) and isotropic.
        let inner = 0.5 / (4.0 * std::f32::consts::PI) + 0.5 * at(&PhaseFunction::Rayleigh, c);
        let expected = 0.5 * inner + 0.5 / (4.0 * std::f32::consts::PI);
        assert!((at(&scene.media[2].phase, c) - expected).abs() < 1e-6);
    }
    crate::scene::Scene::build(&scene).unwrap();

    let cases: [(&str, &str, &str); 7] = [
        (
            r#"<medium type="homogeneous" id="m"><phase type="tabphase"/></medium>"#,
            "tabphase",
            "missing parameter \"values\"",
        ),
        (
            r#"<medium type="homogeneous" id="m"><phase type="tabphase"><string name="values" value="1, x"/></phase></medium>"#,
            "name=\"values\"",
            "\"x\" is not a number",
        ),
        (
            r#"<medium type="homogeneous" id="m"><phase type="tabphase"><string name="values" value="1, -2"/></phase></medium>"#,
            "name=\"values\"",
            "value 2 is -2",
        ),
        (
            r#"<medium type="homogeneous" id="m"><phase type="tabphase"><string name="values" value="0 0 0"/></phase></medium>"#,
            "name=\"values\"",
            "every value is zero",
        ),
        (
            r#"<medium type="homogeneous" id="m"><phase type="tabphase"><string name="values" value="1"/></phase></medium>"#,
            "name=\"values\"",
            "at least two values",
        ),
        (
            r#"<medium type="homogeneous" id="m"><phase type="blendphase"><phase type="isotropic"/></phase></medium>"#,
            "blendphase",
            "exactly two nested phase functions, got 1",
        ),
        (
            r#"<bsdf type="diffuse" id="d"/><medium type="homogeneous" id="m"><phase type="blendphase"><phase type="isotropic"/>
<ref id="d"/></phase></medium>"#,
            "<ref id=\"d\"/>",
            "a blendphase holds a <phase>",
        ),
    ];
    for (i, (body, marker, needle)) in cases.iter().enumerate() {
        let body = format!("{SENSOR}\n{body}");
        assert_body_error_at(&dir, &format!("case{i}.xml"), &body, marker, needle);
    }
}

/// A heterogeneous medium: a `gridvolume` `sigma_t` read from a `.vol` file next to the scene,
/// placed by `to_world` (its box is where the medium is), a `constvolume` albedo, `scale` in
/// the majorant; a declared volume named by `<ref>`; and the grid's errors with file and line.
#[test]
fn heterogeneous_media_read_their_grids() {
    use crate::parity::media::grid::{encode_vol, VolFile};
    use crate::parity::media::{Density, VolumeTexture};
    let dir = temp_dir("heterogeneous");
    let vol = VolFile {
        res: glam::UVec3::new(2, 1, 1),
        channels: 1,
        bbox: (Vec3::ZERO, Vec3::ONE),
        data: vec![0.5, 2.0],
    };
    std::fs::write(dir.join("d.vol"), encode_vol(&vol)).unwrap();
    let body = format!(
        r#"{SENSOR}
<volume type="gridvolume" id="density"><string name="filename" value="d.vol"/>
    <transform name="to_world"><scale x="2"/><translate x="1"/></transform></volume>
<medium type="heterogeneous" id="smoke">
    <ref name="sigma_t" id="density"/>
    <volume type="constvolume" name="albedo"><rgb name="value" value="0.5, 0.6, 0.7"/></volume>
    <float name="scale" value="3"/>
</medium>
<shape type="cube"><bsdf type="null"/><ref name="interior" id="smoke"/></shape>"#
    );
    let scene = load(&write_scene(&dir, "scene.xml", &body)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let Density::Heterogeneous(h) = &scene.media[0].density else {
        panic!("{:?}", scene.media[0].density)
    };
    assert_eq!(h.majorant, 6.0);
    assert_eq!(
        h.bounds,
        Some((Vec3::new(1.0, 0.0, 0.0), Vec3::new(3.0, 1.0, 1.0)))
    );
    assert_eq!(h.albedo, VolumeTexture::Constant(Vec3::new(0.5, 0.6, 0.7)));
    // Trilinear between the cell centres x = 1.5 (0.5) and 2.5 (2.0).
    assert_eq!(h.sigma_t.eval(Vec3::new(2.0, 0.5, 0.5)), Vec3::splat(1.25));
    crate::scene::Scene::build(&scene).unwrap();

    let bad = |name: &str, bytes: &[u8], needle: &str| {
        std::fs::write(dir.join(name), bytes).unwrap();
        let body = format!(
            "{SENSOR}\n<medium type=\"heterogeneous\" id=\"m\">\n<volume type=\"gridvolume\" name=\"sigma_t\"><string name=\"filename\" value=\"{name}\"/></volume>\n</medium>"
        );
        assert_body_error_at(&dir, &format!("{name}.xml"), &body, "filename", needle);
    };
    bad("truncated.vol", &encode_vol(&vol)[..50], "truncated");
    bad("text.vol", b"hello", "not a .vol grid");
    let body = format!(
        "{SENSOR}\n<medium type=\"heterogeneous\" id=\"m\">\n<volume type=\"gridvolume\" name=\"sigma_t\"><string name=\"filename\" value=\"missing.vol\"/></volume>\n</medium>"
    );
    assert_body_error_at(
        &dir,
        "missing.xml",
        &body,
        "missing.vol",
        "cannot load volume",
    );
    let body = format!(
        "{SENSOR}\n<medium type=\"homogeneous\" id=\"m\">\n<volume type=\"constvolume\" name=\"sigma_t\"/>\n</medium>"
    );
    assert_body_error_at(
        &dir,
        "homogeneous.xml",
        &body,
        "constvolume",
        "use a heterogeneous medium",
    );
    let body = format!(
        "{SENSOR}\n<medium type=\"heterogeneous\" id=\"m\">\n<volume type=\"gridvolume\" name=\"sigma_t\"><string name=\"filename\" value=\"d.vol\"/>\n<string name=\"filter_type\" value=\"cubic\"/></volume>\n</medium>"
    );
    assert_body_error_at(&dir, "filter.xml", &body, "cubic", "unknown filter_type");
}

#[test]
fn aov_integrator_reads_variables_and_nested_integrators_as_mitsuba_names_them() {
    use crate::description::{AovKind, AovSpec};
    let dir = temp_dir("aov");
    let body = format!(
        r#"{SENSOR}
<integrator type="aov">
  <string name="aovs" value="dd.y:depth, nn:sh_normal,alb:albedo"/>
  <integrator type="path" name="my_image"><integer name="max_depth" value="7"/></integrator>
  <integrator type="direct"><integer name="emitter_samples" value="3"/></integrator>
  <integrator type="depth"/>
</integrator>"#
    );
    let scene = load(&write_scene(&dir, "aov.xml", &body)).unwrap();
    let aov = scene.integrator.as_ref().unwrap();
    assert_eq!(aov.kind, "aov");
    let spec = |name: &str, kind| AovSpec {
        name: name.into(),
        kind,
    };
    assert_eq!(
        aov.aovs,
        [
            spec("dd.y", AovKind::Depth),
            spec("nn", AovKind::ShadingNormal),
            spec("alb", AovKind::Albedo)
        ]
    );
    let names: Vec<_> = aov
        .nested
        .iter()
        .map(|(n, i)| (n.as_str(), i.kind.as_str()))
        .collect();
    assert_eq!(
        names,
        [
            ("my_image", "path"),
            ("_arg_0", "direct"),
            ("_arg_1", "depth")
        ]
    );
    assert_eq!(aov.nested[1].1.emitter_samples, 3);
    // The depth settings the other tools read are the first nested integrator's.
    assert_eq!(aov.max_depth, 7);
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    // `depth` on its own is known too.
    let depth = format!("{SENSOR}\n<integrator type=\"depth\"/>");
    let scene = load(&write_scene(&dir, "depth.xml", &depth)).unwrap();
    assert_eq!(scene.integrator.unwrap().kind, "depth");
}

#[test]
fn aov_integrator_errors_name_the_line() {
    let dir = temp_dir("aov-errors");
    let case = |file: &str, inner: &str, marker: &str, needle: &str| {
        let body = format!("{SENSOR}\n<integrator type=\"aov\">\n{inner}\n</integrator>");
        assert_body_error_at(&dir, file, &body, marker, needle);
    };
    case(
        "kind.xml",
        r#"<string name="aovs" value="a:depth,b:curvature"/>"#,
        "curvature",
        "unknown AOV kind \"curvature\"",
    );
    case(
        "pair.xml",
        r#"<string name="aovs" value="depth"/>"#,
        "value=\"depth\"",
        "not a <name>:<kind> pair",
    );
    case(
        "boundary.xml",
        r#"<string name="aovs" value="b:boundary_test"/>"#,
        "boundary_test",
        "not supported",
    );
    case(
        "clash.xml",
        r#"<string name="aovs" value="x:depth,x:depth"/>"#,
        "x:depth",
        "channel \"x.T\"",
    );
    case(
        "sppm.xml",
        "<string name=\"aovs\" value=\"d:depth\"/>\n<integrator type=\"sppm\"/>",
        "type=\"sppm\"",
        "nests sampling integrators",
    );
    case(
        "nested-aov.xml",
        "<string name=\"aovs\" value=\"d:depth\"/>\n<integrator type=\"aov\"><string name=\"aovs\" value=\"e:depth\"/></integrator>",
        "type=\"aov\"><string",
        "nests sampling integrators",
    );
    let long = "n".repeat(300);
    let body = format!(
        "{SENSOR}\n<integrator type=\"aov\">\n<string name=\"aovs\" value=\"{long}:depth\"/>\n</integrator>"
    );
    assert_body_error_at(&dir, "long.xml", &body, "type=\"aov\"", "at most 255");
    // Without `aovs` the error is at the integrator.
    let body =
        format!("{SENSOR}\n<integrator type=\"aov\">\n<integrator type=\"path\"/>\n</integrator>");
    assert_body_error_at(
        &dir,
        "missing.xml",
        &body,
        "type=\"aov\"",
        "missing parameter \"aovs\"",
    );
}
