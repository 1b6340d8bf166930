//! End-to-end tests of the `datagen` binary with the real multi-level SPPM renderer on a tiny
//! dataset: three concurrent shard processes write exactly the files of one process; a
//! process killed with SIGKILL mid-run and then resumed ends with exactly the same dataset and
//! `check` passes; `check` names a truncated bundle and a bundle holding a NaN;
//! `average-references` averages real runs (thread-count independent), rejects bad requests.

mod common;

use bundle::{read_bundle, write_bundle};
use common::{assert_same, fresh_dir, snapshot, test_config};
use datagen::manifest::Manifest;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

const BIN: &str = env!("CARGO_BIN_EXE_datagen");

/// Writes the test config (16×16, passes 2 and 4, two seeds, 24 reference passes).
fn write_config(dir: &Path) -> PathBuf {
    let mut config = test_config(16, &[2, 4], 2, 24);
    config.render.photons_per_pass = Some(500);
    config.render.reference_photons_per_pass = 1000;
    let path = dir.join("config.toml");
    std::fs::write(&path, toml::to_string(&config).unwrap()).unwrap();
    path
}

fn datagen(args: &[&str]) -> Command {
    let mut cmd = Command::new(BIN);
    cmd.args(args);
    for var in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_COUNT",
        "JOB_COMPLETION_INDEX",
    ] {
        cmd.env_remove(var);
    }
    cmd
}

/// Bundles (EXR files, not the hidden temporaries of atomic writes) finished under `dir`.
fn finished_bundles(dir: &Path) -> usize {
    fn walk(dir: &Path) -> usize {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return 0;
        };
        entries
            .flatten()
            .map(|e| {
                let p = e.path();
                let name = e.file_name().to_string_lossy().into_owned();
                if p.is_dir() {
                    walk(&p)
                } else {
                    usize::from(name.ends_with(".exr") && !name.starts_with('.'))
                }
            })
            .sum()
    }
    walk(dir)
}

fn ok(out: Output) -> Output {
    assert!(
        out.status.success(),
        "datagen failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn render(config: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut args = vec![
        "render",
        "--config",
        config.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    datagen(&args)
}

#[test]
fn shards_kill_resume_and_check() {
    let work = fresh_dir("cli");
    let config = write_config(&work);

    // Reference: one uninterrupted process.
    let single = work.join("single");
    ok(render(&config, &single, &["--threads", "2"])
        .output()
        .unwrap());
    let reference = snapshot(&single);
    let manifest = Manifest::load(&single).unwrap();
    assert_eq!(manifest.scenes.len(), 5);
    assert_eq!(manifest.samples.len(), 5 * 2 * 2);

    // Three shard processes at once into one directory (one through the Slurm variables).
    let sharded = work.join("sharded");
    let mut children = vec![
        render(&config, &sharded, &["--shard", "0/3", "--threads", "1"])
            .spawn()
            .unwrap(),
        render(&config, &sharded, &["--shard", "1/3", "--threads", "1"])
            .spawn()
            .unwrap(),
    ];
    let mut slurm = render(&config, &sharded, &["--threads", "1"]);
    slurm
        .env("SLURM_ARRAY_TASK_ID", "2")
        .env("SLURM_ARRAY_TASK_COUNT", "3");
    children.push(slurm.spawn().unwrap());
    for mut c in children {
        assert!(c.wait().unwrap().success());
    }
    assert_same(&reference, &snapshot(&sharded));

    // Kill -9 at several moments of a run — before its first finished bundle, right after it,
    // and halfway through the bundles — then resume and compare. The moments are read from the
    // run's own progress (finished EXR files), not from a clock, so the kill lands mid-run on
    // any machine, however loaded; within a moment it may hit a render, the gap between jobs or
    // a write.
    let total = reference.keys().filter(|k| k.ends_with(".exr")).count();
    assert!(total >= 4, "{total} bundles");
    for (k, after) in [0usize, 1, total / 2].into_iter().enumerate() {
        let dir = work.join(format!("killed{k}"));
        let mut child = render(&config, &dir, &["--threads", "1"]).spawn().unwrap();
        let finished = loop {
            let done = child.try_wait().unwrap().is_some();
            if done || finished_bundles(&dir) >= after {
                break done;
            }
            std::thread::sleep(Duration::from_millis(1));
        };
        if after == 0 {
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill(); // SIGKILL
        let _ = child.wait();
        assert!(
            !finished && !dir.join("manifest.json").exists(),
            "kill {k} (after {after} of {total} bundles) came after the run had finished"
        );
        ok(render(&config, &dir, &["--threads", "2"]).output().unwrap());
        assert_same(&reference, &snapshot(&dir));
        let out = ok(datagen(&["check", dir.to_str().unwrap(), "--quiet"])
            .output()
            .unwrap());
        assert!(String::from_utf8_lossy(&out.stdout).starts_with("ok:"));
    }

    // `check` names a truncated bundle and a bundle with a NaN, and exits non-zero.
    let truncated = manifest.samples[1].bundle.clone();
    let bytes = std::fs::read(single.join(&truncated)).unwrap();
    std::fs::write(single.join(&truncated), &bytes[..bytes.len() * 2 / 3]).unwrap();
    let nan = manifest.samples[6].bundle.clone();
    let mut b = read_bundle(&single.join(&nan)).unwrap();
    b.variance.set(7, 9, 4, f32::NAN);
    write_bundle(&single.join(&nan), &b).unwrap();
    let out = datagen(&["check", single.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout
            .lines()
            .any(|l| l.contains(&truncated) && l.contains("truncated")),
        "{stdout}"
    );
    assert!(
        stdout
            .lines()
            .any(|l| l.contains(&nan) && l.contains("NaN") && l.contains("variance")),
        "{stdout}"
    );
    // One line and one count per broken file, however many of its checks fail.
    assert_eq!(
        stdout.lines().filter(|l| l.starts_with("BAD ")).count(),
        2,
        "{stdout}"
    );
    assert!(stdout.contains("2 problem(s)"), "{stdout}");
    std::fs::remove_dir_all(&work).unwrap();
}

#[test]
fn average_references_with_the_real_renderer() {
    let dir = fresh_dir("cli-average");
    let config = write_config(&dir);
    let data = dir.join("data");
    ok(render(&config, &data, &[]).output().unwrap());
    let manifest = Manifest::load(&data).unwrap();
    let split = manifest.scenes[0].split.name();
    let average = |extra: &[&str]| {
        let mut args = vec!["average-references", data.to_str().unwrap(), "--quiet"];
        if !extra.contains(&"--split") {
            args.extend(["--split", split]);
        }
        args.extend_from_slice(extra);
        datagen(&args).output().unwrap()
    };
    let out = ok(average(&["--runs", "3", "--out", "avg", "--threads", "1"]));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let noise: serde_json::Value =
        serde_json::from_slice(&std::fs::read(data.join("avg/noise.json")).unwrap()).unwrap();
    for scene in manifest.scenes.iter().filter(|s| s.split.name() == split) {
        assert!(stdout.contains(&scene.id), "{stdout}");
        let mean = bundle::read_rgb_exr_image(&data.join(format!("avg/{}.exr", scene.id))).unwrap();
        assert_eq!((mean.width, mean.height), (16, 16));
        assert!(mean.data.iter().all(|x| x.is_finite() && *x >= 0.0));
        // Independent SPPM runs differ, so the measured noise is positive; the mean of 3 carries
        // a third of it.
        let one = noise["scenes"][&scene.id]["relmse_one_run"]
            .as_f64()
            .unwrap();
        let of_mean = noise["scenes"][&scene.id]["relmse_mean"].as_f64().unwrap();
        assert!(one > 0.0 && one.is_finite(), "{one}");
        assert!((of_mean * 3.0 - one).abs() <= 1e-12 * one);
    }
    // Thread count does not change the result: a second directory averaged with 2 threads
    // from fresh runs is byte-identical.
    let runs_before = snapshot(&data.join("reference-runs"));
    std::fs::remove_dir_all(data.join("reference-runs")).unwrap();
    ok(average(&["--runs", "3", "--out", "avg2", "--threads", "2"]));
    assert_same(&runs_before, &snapshot(&data.join("reference-runs")));
    assert_same(&snapshot(&data.join("avg")), &snapshot(&data.join("avg2")));
    // Without --out the directory is named after the run count (never the `references-avg8`
    // that configs name, unless 8 runs were averaged).
    ok(average(&["--runs", "3", "--threads", "2"]));
    assert_same(
        &snapshot(&data.join("avg")),
        &snapshot(&data.join("references-avg3")),
    );
    assert!(!data.join("references-avg8").exists());
    // Bad requests: a clear message and a non-zero exit, the dataset's references untouched.
    let references = snapshot(&data.join("references"));
    for (extra, needle) in [
        (&["--out", "references"][..], "references"),
        (&["--runs", "1"][..], "at least 2"),
        (&["--split", "nope"][..], "nope"),
        // `avg` holds 3-run means: 2-run means would silently replace them.
        (
            &["--runs", "2", "--out", "avg"][..],
            "holds averages of 3 runs",
        ),
    ] {
        let out = average(extra);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(needle),
            "{extra:?}: {stderr}"
        );
    }
    assert_same(&references, &snapshot(&data.join("references")));
    // The contact sheet of the same dataset: a PNG, and refused settings name the option.
    let sheet = dir.join("sheet.png");
    ok(datagen(&[
        "contact-sheet",
        data.to_str().unwrap(),
        "--out",
        sheet.to_str().unwrap(),
    ])
    .output()
    .unwrap());
    assert!(image::open(&sheet).unwrap().width() > 16);
    // `--evaluation` shows converged evaluation references where there are; this dataset has
    // none, so the training references, the same sheet.
    let evaluation_sheet = dir.join("sheet-evaluation.png");
    ok(datagen(&[
        "contact-sheet",
        data.to_str().unwrap(),
        "--out",
        evaluation_sheet.to_str().unwrap(),
        "--evaluation",
    ])
    .output()
    .unwrap());
    assert_eq!(
        std::fs::read(&sheet).unwrap(),
        std::fs::read(&evaluation_sheet).unwrap()
    );
    // The same directory under a changed config: every job is redone, with a note saying so
    // before the work starts; afterwards the old config no longer matches the records, and
    // `manifest` says that rather than that jobs are unfinished.
    let old_config = dir.join("old.toml");
    std::fs::copy(&config, &old_config).unwrap();
    let mut changed: datagen::config::Config =
        toml::from_str(&std::fs::read_to_string(&config).unwrap()).unwrap();
    changed.render.photons_per_pass = changed.render.photons_per_pass.map(|p| p + 100);
    std::fs::write(&config, toml::to_string(&changed).unwrap()).unwrap();
    let out = ok(render(&config, &data, &[]).output().unwrap());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("were rendered with another config"),
        "{stderr}"
    );
    let out = datagen(&[
        "manifest",
        "--config",
        old_config.to_str().unwrap(),
        "--out",
        data.to_str().unwrap(),
    ])
    .output()
    .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("rendered with another config"),
        "{stderr}"
    );
    for (extra, needle) in [
        (&["--out", "sheet.exr"][..], "*.png"),
        (&["--out", "x.png", "--tile", "0"][..], "--tile"),
        (&["--out", "x.png", "--columns", "0"][..], "--columns"),
    ] {
        let mut args = vec!["contact-sheet", data.to_str().unwrap()];
        args.extend_from_slice(extra);
        let out = datagen(&args).current_dir(&dir).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(needle),
            "{extra:?}: {stderr}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Writes `config` to `work/config.toml`, renders it uninterrupted into `work/whole` and returns
/// the config's path and the dataset's snapshot (what an interrupted run must end with).
fn render_uninterrupted(
    work: &Path,
    config: &datagen::config::Config,
) -> (PathBuf, std::collections::BTreeMap<String, Vec<u8>>) {
    let config_path = work.join("config.toml");
    std::fs::write(&config_path, toml::to_string(config).unwrap()).unwrap();
    let whole = work.join("whole");
    ok(render(&config_path, &whole, &["--threads", "2"])
        .output()
        .unwrap());
    (config_path, snapshot(&whole))
}

/// Starts `cmd` and kills it (SIGKILL) as soon as `ready()` holds, reading the moment from the
/// run's own files so that it lands mid-run however loaded the machine is; asserts that the
/// run had not finished by then.
fn kill_when(mut cmd: Command, ready: impl Fn() -> bool) {
    let mut child = cmd.spawn().unwrap();
    let finished = loop {
        let done = child.try_wait().unwrap().is_some();
        if done || ready() {
            break done;
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    let _ = child.kill();
    let _ = child.wait();
    assert!(!finished, "the run had finished before the kill");
}

/// The state files (`records/<scene>/reference.<config>.state`) under `dir` and their saved
/// pass counts.
fn reference_states(dir: &Path) -> Vec<(PathBuf, u64)> {
    run_states(dir, "reference.")
}

/// The state files `records/<scene>/<prefix>…state` under `dir` and their saved pass counts.
fn run_states(dir: &Path, prefix: &str) -> Vec<(PathBuf, u64)> {
    let Ok(scenes) = std::fs::read_dir(dir.join("records")) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for scene in scenes.flatten() {
        let Some(path) = std::fs::read_dir(scene.path()).ok().and_then(|files| {
            files.flatten().map(|f| f.path()).find(|p| {
                let name = p.file_name().unwrap_or_default().to_string_lossy();
                name.starts_with(prefix) && name.ends_with(".state")
            })
        }) else {
            continue;
        };
        let Ok(bytes) = std::fs::read(&path) else {
            continue;
        };
        let header = bytes
            .split(|&b| b == b'\n')
            .nth(1)
            .and_then(|l| serde_json::from_slice::<serde_json::Value>(l).ok());
        if let Some(passes) = header.and_then(|h| h["state"]["passes"].as_u64()) {
            out.push((path, passes));
        }
    }
    out
}

#[test]
fn a_reference_job_killed_mid_run_resumes_from_its_state() {
    let work = fresh_dir("cli-reference-state");
    let mut config = test_config(16, &[2], 1, 300);
    config.render.photons_per_pass = Some(500);
    config.render.reference_photons_per_pass = 2000;
    let (config_path, reference) = render_uninterrupted(&work, &config);
    assert!(reference.keys().all(|k| !k.ends_with(".state")));

    // Killed (SIGKILL) while a reference run has saved its state past pass 5.
    let dir = work.join("killed");
    let saving = ["--threads", "1", "--state-interval", "0.0001"];
    kill_when(render(&config_path, &dir, &saving), || {
        reference_states(&dir).iter().any(|(_, p)| *p >= 5)
    });
    let states = reference_states(&dir);
    let (state, passes) = states.iter().find(|(_, p)| *p >= 5).unwrap().clone();
    assert!(passes < 300, "saved at pass {passes}");

    // The next run reads that state: a damaged one is named, not silently re-rendered.
    let good = std::fs::read(&state).unwrap();
    std::fs::write(&state, &good[..good.len() / 2]).unwrap();
    let out = render(&config_path, &dir, &saving).output().unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("reference.") && stderr.contains(".state") && stderr.contains("truncated"),
        "{stderr}"
    );
    // Intact, it resumes, saying so; the dataset equals the uninterrupted one and no state is
    // left.
    std::fs::write(&state, &good).unwrap();
    let out = ok(render(&config_path, &dir, &saving).output().unwrap());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&format!(" reference: resuming at pass {passes} of 300")),
        "{stderr}"
    );
    assert_same(&reference, &snapshot(&dir));

    // Killed again mid-reference, then run under a changed config: the old state is not
    // resumed (it is another run) but removed, and the new config's dataset is complete.
    std::fs::remove_dir_all(dir.join("records")).unwrap();
    kill_when(render(&config_path, &dir, &saving), || {
        reference_states(&dir).iter().any(|(_, p)| *p >= 5)
    });
    assert!(!reference_states(&dir).is_empty());
    config.render.reference_photons_per_pass = 1500;
    std::fs::write(&config_path, toml::to_string(&config).unwrap()).unwrap();
    ok(render(&config_path, &dir, &saving).output().unwrap());
    assert!(
        reference_states(&dir).is_empty(),
        "a state file was left behind"
    );
    let out = ok(datagen(&["check", dir.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap());
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("ok:"));
    std::fs::remove_dir_all(&work).unwrap();
}

/// Writes the floor mesh of a [`user_scene`]: a square of half-size `half` at y = 0, facing up.
fn write_floor(dir: &Path, half: f32) {
    let h = half;
    std::fs::write(
        dir.join("floor.obj"),
        format!("v -{h} 0 -{h}\nv -{h} 0 {h}\nv {h} 0 {h}\nv {h} 0 -{h}\nf 1 2 3\nf 1 3 4\n"),
    )
    .unwrap();
}

/// A small lit floor as a user might bring it: a Mitsuba 3 scene whose film is `$res` square
/// (default 32), whose floor is an OBJ mesh and whose light has radiance `radiance`.
fn user_scene(dir: &Path, radiance: f32) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    write_floor(dir, 2.0);
    let path = dir.join("scene.xml");
    std::fs::write(
        &path,
        format!(
            r#"<scene version="3.0.0">
    <default name="res" value="32"/>
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 3, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="$res"/><integer name="height" value="$res"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="obj">
        <string name="filename" value="floor.obj"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
    </shape>
    <shape type="sphere">
        <float name="radius" value="0.4"/>
        <point name="center" x="0" y="0.4" z="0"/>
        <bsdf type="dielectric"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="90"/><scale value="0.3"/><translate y="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="{radiance}, {radiance}, {radiance}"/></emitter>
    </shape>
</scene>
"#
        ),
    )
    .unwrap();
    path
}

#[test]
fn external_scenes_are_rendered_checked_and_redone_when_edited() {
    use datagen::config::{ExternalConfig, ExternalScene};
    use datagen::plan::Split;
    let work = fresh_dir("cli-external");
    let floor = user_scene(&work.join("mine/floor"), 20.0);
    let lamp = user_scene(&work.join("mine/lamp"), 40.0);
    let mut config = test_config(16, &[2], 1, 16);
    config.render.photons_per_pass = Some(500);
    config.render.reference_photons_per_pass = 1000;
    let at_16 = |xml: &Path, split: Option<Split>, name: Option<&str>| ExternalScene {
        xml: xml.to_owned(),
        name: name.map(String::from),
        split,
        defines: [("res".to_string(), "16".to_string())].into(),
    };
    config.families.external = Some(ExternalConfig {
        scenes: vec![
            at_16(&floor, Some(Split::Test), None),
            at_16(&lamp, None, Some("bright-lamp")),
        ],
    });
    let config_path = work.join("config.toml");
    std::fs::write(&config_path, toml::to_string(&config).unwrap()).unwrap();
    let data = work.join("data");
    let out = ok(render(&config_path, &data, &["--threads", "2"])
        .output()
        .unwrap());
    assert!(String::from_utf8_lossy(&out.stderr).contains("manifest complete"));

    let manifest = Manifest::load(&data).unwrap();
    let ids: Vec<&str> = manifest.scenes.iter().map(|s| s.id.as_str()).collect();
    assert_eq!(ids.len(), 7, "{ids:?}");
    assert_eq!(&ids[5..], ["005-floor", "006-bright-lamp"]);
    let floor_entry = &manifest.scenes[5];
    assert_eq!(floor_entry.split, Split::Test, "the fixed split is kept");
    assert_eq!(floor_entry.family, "external");
    // The manifest finds the user's file from the dataset root, and records its checksum.
    assert_eq!(floor_entry.xml, "../mine/floor/scene.xml");
    assert!(data.join(&floor_entry.xml).is_file());
    assert!(floor_entry.scene_sha256.is_some());
    // … and the overrides it was rendered with, for `evaluate` to render it the same way.
    assert_eq!(
        floor_entry.defines.get("res").map(String::as_str),
        Some("16")
    );
    assert_eq!(
        manifest
            .samples
            .iter()
            .filter(|s| s.scene == "006-bright-lamp")
            .count(),
        1
    );
    // Generated scenes are written into the dataset; the user's are not copied.
    assert!(!data.join("scenes/005-floor").exists());
    let check = |expect_ok: bool| {
        let out = datagen(&["check", data.to_str().unwrap(), "--quiet"])
            .output()
            .unwrap();
        assert_eq!(out.status.success(), expect_ok, "{out:?}");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    check(true);

    // A rerun does nothing; after an edit of one scene, `check` names it and a rerun redoes
    // that scene's jobs only.
    let out = ok(render(&config_path, &data, &[]).output().unwrap());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("0 jobs rendered"),
        "{out:?}"
    );
    // `edit` changes the scene `dir` (under `mine/`), whose jobs are those of `id`.
    let redone_after = |edit: &dyn Fn(), dir: &str, id: &str| {
        let before = snapshot(&data);
        edit();
        let report = check(false);
        assert!(
            report.contains(&format!("mine/{dir}/scene.xml"))
                && report.contains("the scene or a file it reads"),
            "{report}"
        );
        let out = ok(render(&config_path, &data, &[]).output().unwrap());
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("2 jobs rendered"),
            "{out:?}"
        );
        let after = snapshot(&data);
        let changed: Vec<&String> = before
            .keys()
            .filter(|k| before.get(*k) != after.get(*k))
            .collect();
        assert!(
            changed
                .iter()
                .all(|k| k.contains(id) || *k == "manifest.json"),
            "{changed:?}"
        );
        assert!(changed
            .iter()
            .any(|k| k.starts_with(&format!("references/{id}"))));
        check(true);
    };
    redone_after(
        &|| drop(user_scene(&work.join("mine/lamp"), 25.0)),
        "lamp",
        "006-bright-lamp",
    );
    // The same for a file the scene reads: an edited mesh, with the XML untouched.
    redone_after(
        &|| write_floor(&work.join("mine/floor"), 1.5),
        "floor",
        "005-floor",
    );

    // Renders with `variant` written as the config into `work/<out>`: (exit success, stderr).
    let render_variant = |variant: &datagen::config::Config, out: &str| {
        std::fs::write(&config_path, toml::to_string(variant).unwrap()).unwrap();
        let out = render(&config_path, &work.join(out), &[]).output().unwrap();
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    // A scene whose film is not the dataset's size, and a missing scene file: errors naming
    // the file, the second before anything is rendered.
    let mut wrong = config.clone();
    wrong.families.external.as_mut().unwrap().scenes[1]
        .defines
        .clear();
    let (ok, stderr) = render_variant(&wrong, "wrong");
    assert!(!ok);
    assert!(
        stderr.contains("lamp/scene.xml") && stderr.contains("renders 32x32, the dataset is 16x16"),
        "{stderr}"
    );
    // The failing job is named by scene and kind, not by a record that does not exist yet.
    assert!(
        stderr.contains("job 006-bright-lamp reference") && !stderr.contains("records/"),
        "{stderr}"
    );
    // A scene without `<rfilter type="box"/>` (Mitsuba's default is a Gaussian) is refused.
    let soft = work.join("mine/soft/scene.xml");
    std::fs::create_dir_all(soft.parent().unwrap()).unwrap();
    write_floor(soft.parent().unwrap(), 2.0);
    let text = std::fs::read_to_string(&floor).unwrap();
    std::fs::write(&soft, text.replace("<rfilter type=\"box\"/>", "")).unwrap();
    let mut gaussian = config.clone();
    gaussian.families.external.as_mut().unwrap().scenes[0].xml = soft;
    let (ok, stderr) = render_variant(&gaussian, "soft");
    assert!(!ok);
    assert!(
        stderr.contains("soft/scene.xml") && stderr.contains("<rfilter type=\"box\"/>"),
        "{stderr}"
    );
    let mut missing = config.clone();
    missing.families.external.as_mut().unwrap().scenes[0].xml = work.join("nowhere.xml");
    let (ok, stderr) = render_variant(&missing, "missing");
    assert!(!ok);
    assert!(stderr.contains("nowhere.xml"), "{stderr}");
    assert!(
        !work.join("missing/references").exists(),
        "nothing rendered"
    );
    // `datagen scenes` checks the user's scenes too.
    let scenes = |out: &str| {
        datagen(&[
            "scenes",
            "--config",
            config_path.to_str().unwrap(),
            "--out",
            work.join(out).to_str().unwrap(),
        ])
        .output()
        .unwrap()
    };
    let out = scenes("scenes-missing");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("nowhere.xml"),
        "{stderr}"
    );
    // A file the scene reads (its mesh) missing: named with the scene and its XML, before any
    // job (and by `scenes`).
    let bare = work.join("mine/bare");
    let bare_xml = user_scene(&bare, 20.0);
    std::fs::remove_file(bare.join("floor.obj")).unwrap();
    let mut meshless = config.clone();
    meshless.families.external.as_mut().unwrap().scenes[1].xml = bare_xml;
    let (ok, stderr) = render_variant(&meshless, "meshless");
    assert!(
        !ok && stderr.contains("bare/floor.obj")
            && stderr.contains("bare/scene.xml")
            && stderr.contains("006-bright-lamp"),
        "{stderr}"
    );
    assert!(
        !work.join("meshless/references").exists(),
        "nothing rendered"
    );
    let out = scenes("scenes-meshless");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("bare/floor.obj"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&work).unwrap();
}

#[test]
fn an_input_job_killed_between_its_bundles_resumes_from_its_state() {
    let work = fresh_dir("cli-input-state");
    let mut config = test_config(16, &[2, 60], 1, 4);
    config.render.photons_per_pass = Some(2000);
    config.render.reference_photons_per_pass = 500;
    let (config_path, reference) = render_uninterrupted(&work, &config);

    // Killed once an input run has saved its state past pass 5: its bundle at pass 2 is on
    // disk, the one at pass 60 is not. The resumed run takes the first from the disk.
    let dir = work.join("killed");
    let saving = ["--threads", "1", "--state-interval", "0.0001"];
    kill_when(render(&config_path, &dir, &saving), || {
        run_states(&dir, "s00.").iter().any(|(_, p)| *p >= 5)
    });
    let states = run_states(&dir, "s00.");
    let (_, passes) = states.iter().find(|(_, p)| *p >= 5).unwrap();
    assert!(*passes < 60, "saved at pass {passes}");
    let out = ok(render(&config_path, &dir, &saving).output().unwrap());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains(" seed 0: resuming at pass "), "{stderr}");
    assert_same(&reference, &snapshot(&dir));
    std::fs::remove_dir_all(&work).unwrap();
}

/// A batch job's log (stderr not a terminal, so no bar is drawn) gets one line per finished job
/// with the run's progress and ETA; jobs an earlier run finished get none, and `--quiet` none.
#[test]
fn a_log_without_a_terminal_gets_a_line_per_finished_job() {
    let work = fresh_dir("log-lines");
    let config = write_config(&work);
    let dir = work.join("data");
    let args = |quiet: bool| {
        let mut a = vec![
            "render".to_string(),
            "--config".into(),
            config.display().to_string(),
            "--out".into(),
            dir.display().to_string(),
            "--threads".into(),
            "2".into(),
        ];
        if quiet {
            a.push("--quiet".into());
        }
        a
    };
    let run = |quiet: bool| {
        let a = args(quiet);
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let out = ok(datagen(&a).output().unwrap());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let job_lines = |stderr: &str| -> Vec<String> {
        stderr
            .lines()
            .filter(|l| l.contains(": done in "))
            .map(str::to_owned)
            .collect()
    };
    let stderr = run(false);
    let lines = job_lines(&stderr);
    // Five scenes: a reference and two seeds' inputs each.
    assert_eq!(lines.len(), 15, "{stderr}");
    assert_eq!(
        lines
            .iter()
            .filter(|l| l.contains(" reference: done in "))
            .count(),
        5,
        "{stderr}"
    );
    assert_eq!(
        lines
            .iter()
            .filter(|l| l.contains(" seed 1: done in "))
            .count(),
        5,
        "{stderr}"
    );
    // Files and work counted up to the whole run, which then has nothing left.
    assert!(lines[0].contains("(1/25 files, "), "{stderr}");
    let last = lines.last().unwrap();
    assert!(
        last.contains("25/25 files, 100 % of the work, ETA 00:00:00)"),
        "{stderr}"
    );
    // Everything done already: no job line.
    assert!(job_lines(&run(false)).is_empty());
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(job_lines(&run(true)).is_empty());
    std::fs::remove_dir_all(&work).unwrap();
}
