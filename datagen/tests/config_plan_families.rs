//! Configs, plans and scene families without rendering: every preset parses with the intended
//! sizes; config errors name the file and the field or value; shards partition the jobs
//! exactly; the render order puts held-out scenes first and lets the families take turns; splits
//! are by scene and cover every family; scheduler variables map to shards;
//! every generated scene of the `small` preset is deterministic, distinct, loads in the
//! renderer's strict importer at the configured size, respects its family's configured ranges
//! and has its family's defining feature (glass, water, metal, thin lens, hidden lights); the
//! `families` preset holds two scenes of every family, and its lamp and tabletop scenes are
//! deterministic, load and build, with small emitting bulbs and glass respectively, its
//! exterior scenes have a sun, a sky and a dielectric, its material scenes span several BSDF
//! kinds, its textured scenes carry their own images (bitmap albedos, bump and normal maps,
//! byte-identical on every generation); configs without those tables keep their scene ids and
//! fingerprints.

mod common;

use common::fresh_dir;
use datagen::config::Config;
use datagen::families::{generate, scene_list};
use datagen::plan::{Plan, Shard, Split};
use datagen::scene::{write_scene_files, Family};
use renderer::bsdf::Bsdf;
use renderer::description::{EmitterDesc, FovAxis, Geometry, SceneDescription};
use std::collections::{BTreeMap, BTreeSet, HashSet};
use std::path::PathBuf;

fn preset_path(name: &str) -> PathBuf {
    PathBuf::from(
        std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_else(|| env!("CARGO_MANIFEST_DIR").into()),
    )
    .join(format!("../configs/datagen/{name}.toml"))
}

fn preset(name: &str) -> Config {
    Config::load(&preset_path(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn per_family(config: &Config) -> BTreeMap<Family, usize> {
    let mut m = BTreeMap::new();
    for (_, f) in scene_list(config) {
        *m.entry(f).or_default() += 1;
    }
    m
}

#[test]
fn every_shipped_config_loads() {
    let dir = preset_path("tiny").parent().unwrap().to_path_buf();
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            Config::load(&path).unwrap_or_else(|e| panic!("{e}"));
            count += 1;
        }
    }
    assert!(
        count >= 3,
        "found only {count} configs in {}",
        dir.display()
    );
}

#[test]
fn presets_parse_with_intended_sizes() {
    let tiny = preset("tiny");
    assert_eq!((tiny.width, tiny.height), (32, 32));
    assert_eq!(
        per_family(&tiny).values().copied().collect::<Vec<_>>(),
        [1; 5]
    );

    let small = preset("small");
    assert_eq!((small.width, small.height), (128, 128));
    let counts = per_family(&small);
    assert_eq!(counts.len(), 5);
    assert!(counts.values().all(|&n| n >= 5), "{counts:?}");
    assert_eq!(small.render.passes.as_ref().map(Vec::len), Some(3));

    let paper = preset("paper");
    assert_eq!((paper.width, paper.height), (1280, 720));
    assert_eq!(paper.scene_count(), 60);
    assert_eq!(paper.render.passes.as_deref(), Some(&[100, 200, 400][..]));
    assert_eq!(paper.render.seeds, 10);
    assert_eq!(paper.render.photons_per_pass, Some(100_000));
}

/// Config errors name the file, the field or table (and the line, for TOML errors that have
/// one) and what is wrong.
#[test]
fn config_errors_name_file_and_field() {
    let text = std::fs::read_to_string(preset_path("tiny")).unwrap();

    // The 1-based line of the first line of `text` containing `needle`.
    let line_of = |text: &str, needle: &str| {
        text.lines()
            .position(|l| l.contains(needle))
            .unwrap_or_else(|| panic!("tiny.toml no longer has `{needle}`"))
            + 1
    };

    let typo = text.replacen("photons_per_pass =", "photon_per_pass =", 1);
    let e = Config::parse(&typo, "typo.toml").unwrap_err().to_string();
    let line = line_of(&typo, "photon_per_pass =");
    assert!(
        e.contains("typo.toml")
            && e.contains(&format!("line {line}"))
            && e.contains("photon_per_pass"),
        "want typo.toml, line {line} and the field: {e}"
    );

    let descending = text.replacen("passes = [2, 4]", "passes = [4, 2]", 1);
    assert_ne!(
        descending, text,
        "tiny.toml no longer has `passes = [2, 4]`"
    );
    let e = Config::parse(&descending, "desc.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("desc.toml") && e.contains("strictly ascending"),
        "{e}"
    );

    let split = text.replacen("train = 0.6", "train = 0.7", 1);
    assert_ne!(split, text, "tiny.toml no longer has `train = 0.6`");
    let e = Config::parse(&split, "split.toml").unwrap_err().to_string();
    assert!(
        e.contains("split.toml") && e.contains("split fractions") && e.contains("sum to 1"),
        "want split.toml and the split fractions: {e}"
    );

    let glas = text.replacen("[families.glass]", "[families.glas]", 1);
    let e = Config::parse(&glas, "f.toml").unwrap_err().to_string();
    let line = line_of(&glas, "[families.glas]");
    assert!(
        e.contains("f.toml") && e.contains(&format!("line {line}")) && e.contains("`glas`"),
        "want f.toml, line {line} and the table `glas`: {e}"
    );

    // Values the config's types accept but no dataset can be made of, each refused naming its
    // field (found by scripts/fuzz_inputs.py: a huge count aborted on a failed allocation, an
    // f32-infinite range failed inside a generated scene).
    for (from, to, needle) in [
        ("count = 1", "count = 2147483648", "at most 100000"),
        (
            "fov = [55.0, 75.0]",
            "fov = [55.0, 1e300]",
            "families.room.fov",
        ),
        ("fov = [55.0, 75.0]", "fov = [75.0, 55.0]", "lo > hi"),
        (
            "objects = [2, 5]",
            "objects = [2, 4000000000]",
            "families.room.objects",
        ),
        ("width = 32", "width = 65536", "at most 8192"),
    ] {
        let bad = text.replacen(from, to, 1);
        assert_ne!(bad, text, "tiny.toml no longer has `{from}`");
        let e = Config::parse(&bad, "bad.toml").unwrap_err().to_string();
        assert!(e.contains("bad.toml") && e.contains(needle), "{to}: {e}");
    }
}

/// `[render] schedule`: absent is SPPM's and leaves the config's fingerprint as it was (a
/// dataset made before the option still belongs to its config); `"cppm"` parses and changes
/// the fingerprint; any other value is refused naming it.
#[test]
fn render_schedule_defaults_to_sppm_and_takes_cppm() {
    use renderer::integrators::sppm::RadiusSchedule;
    let text = std::fs::read_to_string(preset_path("tiny")).unwrap();
    let tiny = Config::parse(&text, "tiny.toml").unwrap();
    assert_eq!(tiny.render.schedule, RadiusSchedule::Sppm);
    let json = serde_json::to_string(&tiny).unwrap();
    assert!(!json.contains("schedule"), "{json}");
    let with = |value: &str| {
        let edited = text.replacen(
            "max_depth = 8",
            &format!("max_depth = 8\nschedule = {value}"),
            1,
        );
        assert_ne!(edited, text, "tiny.toml no longer has `max_depth = 8`");
        Config::parse(&edited, "s.toml")
    };
    let explicit_sppm = with("\"sppm\"").unwrap();
    assert_eq!(
        datagen::manifest::config_fingerprint(&explicit_sppm),
        datagen::manifest::config_fingerprint(&tiny)
    );
    let cppm = with("\"cppm\"").unwrap();
    assert_eq!(cppm.render.schedule, RadiusSchedule::Cppm);
    assert_ne!(
        datagen::manifest::config_fingerprint(&cppm),
        datagen::manifest::config_fingerprint(&tiny)
    );
    let e = with("\"ppm\"").unwrap_err().to_string();
    assert!(e.contains("s.toml") && e.contains("ppm"), "{e}");
}

#[test]
fn shards_partition_the_jobs() {
    let plan = Plan::new(&preset("small"));
    // Per scene: one reference and one input job per seed.
    assert_eq!(plan.jobs.len(), 40 * 4);
    for n in 1..=7u32 {
        let mut seen = vec![0u32; plan.jobs.len()];
        for i in 0..n {
            let mine = plan.shard_jobs(
                Shard::new(i, n).unwrap(),
                &vec![true; plan.scenes.len()],
                Default::default(),
            );
            // Balanced within one job.
            let ideal = plan.jobs.len() as f64 / f64::from(n);
            assert!(
                (mine.len() as f64 - ideal).abs() < 1.0,
                "{n}: {}",
                mine.len()
            );
            for j in mine {
                seen[j] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1), "N = {n}: not a partition");
    }
    // Render seeds are distinct per job and fit in 32 bits.
    let seeds: HashSet<u64> = plan.jobs.iter().map(|j| plan.render_seed(j)).collect();
    assert_eq!(seeds.len(), plan.jobs.len());
    assert!(seeds.iter().all(|&s| s <= u64::from(u32::MAX)));
}

#[test]
fn render_order_puts_held_out_scenes_first_and_lets_families_take_turns() {
    let plan = Plan::new(&preset("large"));
    // Every scene once, its reference job first and then its input seeds.
    let mut order: Vec<usize> = Vec::new();
    for (j, job) in plan.jobs.iter().enumerate() {
        if let datagen::plan::Job::Reference { scene } = *job {
            order.push(scene);
        } else {
            assert_eq!(
                Some(&job.scene()),
                order.last(),
                "job {j} before its reference"
            );
        }
    }
    let mut sorted = order.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..plan.scenes.len()).collect::<Vec<_>>());
    // Test, then validation, then training scenes.
    let rank = |s: Split| {
        [Split::Test, Split::Val, Split::Train]
            .iter()
            .position(|&x| x == s)
    };
    let ranks: Vec<_> = order.iter().map(|&s| rank(plan.scenes[s].split)).collect();
    assert!(ranks.windows(2).all(|w| w[0] <= w[1]), "splits interleaved");
    // Within a split, the first ten training scenes are one of each family, and no family is
    // ever two scenes ahead of another that still has scenes of that split left.
    let train: Vec<usize> = order
        .iter()
        .copied()
        .filter(|&s| plan.scenes[s].split == Split::Train)
        .collect();
    let first: BTreeSet<Family> = train[..10].iter().map(|&s| plan.scenes[s].family).collect();
    assert_eq!(first.len(), 10, "{first:?}");
    let total = per_family(&preset("large"));
    assert_eq!(total.len(), 10);
    let mut done: BTreeMap<Family, usize> = BTreeMap::new();
    let left = |f: Family, done: &BTreeMap<Family, usize>| {
        train
            .iter()
            .filter(|&&s| plan.scenes[s].family == f)
            .count()
            - done.get(&f).unwrap_or(&0)
    };
    for &s in &train {
        let family = plan.scenes[s].family;
        let mine = *done.get(&family).unwrap_or(&0);
        for &other in total.keys() {
            if other != family && left(other, &done) > 0 {
                assert!(
                    mine <= *done.get(&other).unwrap_or(&0),
                    "{family:?} ahead of {other:?}"
                );
            }
        }
        *done.entry(family).or_default() += 1;
    }
    // Scene seeds follow the scene, not the order.
    let seeds: HashSet<u64> = plan.jobs.iter().map(|j| plan.render_seed(j)).collect();
    assert_eq!(seeds.len(), plan.jobs.len());
}

#[test]
fn splits_are_by_scene_and_cover_every_family() {
    let config = preset("small");
    let plan = Plan::new(&config);
    let mut by_split: BTreeMap<&str, Vec<Family>> = BTreeMap::new();
    for s in &plan.scenes {
        let name = match s.split {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        };
        by_split.entry(name).or_default().push(s.family);
    }
    // 40 scenes × (0.7, 0.15, 0.15) → 28, 6, 6.
    assert_eq!(by_split["train"].len(), 28);
    assert_eq!(by_split["val"].len(), 6);
    assert_eq!(by_split["test"].len(), 6);
    for (split, families) in &by_split {
        let distinct: BTreeSet<_> = families.iter().collect();
        assert_eq!(distinct.len(), 5, "{split} misses a family: {families:?}");
    }
    // Same config → same plan; another master seed → another assignment.
    let again = Plan::new(&config);
    assert!(plan.scenes.iter().zip(&again.scenes).all(|(a, b)| a == b));
    let mut other = config.clone();
    other.seed += 1;
    let other = Plan::new(&other);
    assert!(plan
        .scenes
        .iter()
        .zip(&other.scenes)
        .any(|(a, b)| a.split != b.split));
}

#[test]
fn shard_arguments_and_scheduler_variables() {
    assert_eq!(Shard::parse("2/3"), Ok(Shard { index: 2, count: 3 }));
    for bad in ["3/3", "0/0", "a/3", "1", "-1/3"] {
        let e = Shard::parse(bad).unwrap_err();
        assert!(e.contains(bad), "{bad}: {e}");
    }
    let env = |vars: &'static [(&'static str, &'static str)]| {
        move |k: &str| {
            vars.iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    };
    assert_eq!(Shard::from_env(env(&[])), Ok(None));
    // Slurm: 1-based array 1-4 → task 3 is shard 2 of 4.
    assert_eq!(
        Shard::from_env(env(&[
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ])),
        Ok(Some(Shard { index: 2, count: 4 }))
    );
    assert_eq!(
        Shard::from_env(env(&[
            ("JOB_COMPLETION_INDEX", "5"),
            ("DATAGEN_SHARD_COUNT", "8"),
        ])),
        Ok(Some(Shard { index: 5, count: 8 }))
    );
    let e = Shard::from_env(env(&[("JOB_COMPLETION_INDEX", "5")])).unwrap_err();
    assert!(e.contains("DATAGEN_SHARD_COUNT"), "{e}");
    let e = Shard::from_env(env(&[
        ("JOB_COMPLETION_INDEX", "8"),
        ("DATAGEN_SHARD_COUNT", "8"),
    ]))
    .unwrap_err();
    assert!(e.contains('8'), "{e}");
    let e = Shard::from_env(env(&[
        ("SLURM_ARRAY_TASK_ID", "x"),
        ("SLURM_ARRAY_TASK_COUNT", "4"),
    ]))
    .unwrap_err();
    assert!(e.contains("SLURM_ARRAY_TASK_ID"), "{e}");
}

/// Scene `index` of `config` (id `id`), checked to be deterministic in the config and to
/// change with its master seed, written under `dir` and loaded by the renderer's strict
/// importer without warnings as a 64×64 pinhole view.
fn deterministic_pinhole_scene(
    config: &Config,
    index: usize,
    id: &str,
    dir: &std::path::Path,
) -> SceneDescription {
    let scene = generate(config, index).unwrap();
    assert_eq!(scene.id, id);
    assert_eq!(
        scene.files(),
        generate(config, index).unwrap().files(),
        "{id}"
    );
    let mut other = config.clone();
    other.seed += 1;
    assert_ne!(generate(&other, index).unwrap().xml, scene.xml, "{id}");
    let xml = write_scene_files(&scene, &dir.join(id)).unwrap();
    let d = renderer::xml::load_scene(&xml, &[], false).unwrap_or_else(|e| panic!("{id}: {e}"));
    assert!(d.warnings.is_empty(), "{id}: {:?}", d.warnings);
    assert_eq!((d.camera.width, d.camera.height), (64, 64), "{id}");
    assert_eq!(d.camera.aperture_radius, 0.0, "{id}: pinhole expected");
    d
}

fn has_bsdf(d: &SceneDescription, pred: impl Fn(&Bsdf) -> bool + Copy) -> bool {
    fn any(b: &Bsdf, pred: &dyn Fn(&Bsdf) -> bool) -> bool {
        match b {
            Bsdf::TwoSided { front, back } => any(front, pred) || any(back, pred),
            other => pred(other),
        }
    }
    d.shapes.iter().any(|s| any(&d.bsdfs[s.bsdf], &pred))
}

fn within(v: f32, range: Option<[f32; 2]>) -> bool {
    range.is_none_or(|[lo, hi]| v >= lo - 1e-3 && v <= hi + 1e-3)
}

#[test]
fn small_scenes_are_deterministic_distinct_loadable_and_true_to_family() {
    let config = preset("small");
    let dir = fresh_dir("families");
    let f = &config.families;
    let mut xmls = HashSet::new();
    for (index, (id, family)) in scene_list(&config).into_iter().enumerate() {
        let scene = generate(&config, index).expect("the small preset generates every scene");
        assert_eq!(scene.id, id);
        assert_eq!(
            scene.files(),
            generate(&config, index).unwrap().files(),
            "{id}"
        );
        assert!(xmls.insert(scene.xml.clone()), "{id} repeats a scene");

        let xml = write_scene_files(&scene, &dir.join(&id)).unwrap();
        let d = renderer::xml::load_scene(&xml, &[], false).unwrap_or_else(|e| panic!("{id}: {e}"));
        assert!(d.warnings.is_empty(), "{id}: {:?}", d.warnings);
        assert_eq!((d.camera.width, d.camera.height), (128, 128), "{id}");
        assert!(matches!(d.camera.fov_axis, FovAxis::X), "{id}");
        let area_lights = d.shapes.iter().filter(|s| s.emission.is_some()).count();
        let lights = area_lights
            + d.emitters
                .iter()
                .filter(|e| !matches!(e, EmitterDesc::Constant { .. }))
                .count();
        assert!(lights >= 1, "{id}: no light");
        let dielectric = has_bsdf(&d, |b| {
            matches!(b, Bsdf::Dielectric(_) | Bsdf::RoughDielectric(_))
        });
        let metal = has_bsdf(&d, |b| {
            matches!(b, Bsdf::Conductor(_) | Bsdf::RoughConductor(_))
        });
        let fov = match family {
            Family::Room => {
                assert!(area_lights >= 1, "{id}: rooms are lit by area lights");
                f.room.as_ref().map(|c| c.fov)
            }
            Family::Glass => {
                assert!(dielectric, "{id}: no glass");
                assert_eq!(lights, 1, "{id}: one small light");
                f.glass.as_ref().map(|c| c.fov)
            }
            Family::Water => {
                assert!(dielectric, "{id}: no water surface");
                assert!(
                    d.emitters.iter().any(|e| matches!(
                        e,
                        EmitterDesc::Directional { .. } | EmitterDesc::Spot { .. }
                    )),
                    "{id}: neither sun nor spot"
                );
                f.water.as_ref().map(|c| c.fov)
            }
            Family::Metal => {
                assert!(metal, "{id}: no metal");
                assert_eq!(lights, 1, "{id}: one small light");
                f.metal.as_ref().map(|c| c.fov)
            }
            Family::Shelf => {
                let c = f.shelf.as_ref().unwrap();
                assert!(
                    within(d.camera.aperture_radius, Some(c.aperture_radius))
                        && d.camera.aperture_radius > 0.0,
                    "{id}: aperture {}",
                    d.camera.aperture_radius
                );
                assert!(d.camera.focus_distance > 0.0, "{id}");
                Some(c.fov)
            }
            Family::Lamp
            | Family::Tabletop
            | Family::Exterior
            | Family::Material
            | Family::Textured
            | Family::External => {
                unreachable!("{id}: the small preset has no {family:?} scenes")
            }
        };
        assert!(within(d.camera.fov, fov), "{id}: fov {}", d.camera.fov);
        if family != Family::Shelf {
            assert_eq!(d.camera.aperture_radius, 0.0, "{id}: pinhole expected");
        }
        renderer::scene::Scene::build(&d).unwrap_or_else(|e| panic!("{id}: {e}"));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The `families` preset: two 64×64 scenes of every generated family, in `Family::ALL` order.
#[test]
fn families_preset_has_two_scenes_of_every_family() {
    let config = preset("families");
    assert_eq!((config.width, config.height), (64, 64));
    let counts = per_family(&config);
    let generated: Vec<Family> = Family::ALL
        .into_iter()
        .filter(|f| *f != Family::External)
        .collect();
    assert_eq!(counts.keys().copied().collect::<Vec<_>>(), generated);
    assert!(counts.values().all(|&n| n == 2), "{counts:?}");
    let ids: Vec<String> = scene_list(&config).into_iter().map(|(id, _)| id).collect();
    assert_eq!(
        ids[10..],
        [
            "010-lamp",
            "011-lamp",
            "012-tabletop",
            "013-tabletop",
            "014-exterior",
            "015-exterior",
            "016-material",
            "017-material",
            "018-textured",
            "019-textured"
        ]
    );
}

/// The new tables are checked like the others: ranges, choice lists and their own domains,
/// each error naming the field.
#[test]
fn lamp_and_tabletop_config_errors_name_the_field() {
    let text = std::fs::read_to_string(preset_path("families")).unwrap();
    for (from, to, needle) in [
        ("lamps = [1, 3]", "lamps = [0, 3]", "families.lamp.lamps"),
        (
            "bulb_radius = [0.02, 0.05]",
            "bulb_radius = [0.05, 0.02]",
            "families.lamp.bulb_radius",
        ),
        (
            "kinds = [\"floor\", \"table\", \"pendant\"]",
            "kinds = []",
            "families.lamp.kinds",
        ),
        (
            "liquid_fill = [0.3, 0.8]",
            "liquid_fill = [0.3, 1.5]",
            "families.tabletop.liquid_fill",
        ),
        (
            "light_count = [1, 2]",
            "light_count = [0, 2]",
            "families.tabletop",
        ),
        (
            "mirror_materials = [\"Ag\", \"Al\"]",
            "mirror_materials = []",
            "mirror_materials",
        ),
        (
            "shade_taper = [0.5, 0.9]",
            "shade_tapper = [0.5, 0.9]",
            "shade_tapper",
        ),
    ] {
        let bad = text.replacen(from, to, 1);
        assert_ne!(bad, text, "families.toml no longer has `{from}`");
        let e = Config::parse(&bad, "bad.toml").unwrap_err().to_string();
        assert!(e.contains("bad.toml") && e.contains(needle), "{to}: {e}");
    }
}

/// The lamp and tabletop tables are new: configs without them must list the same scenes and
/// serialise (fingerprint) exactly as before they existed.
#[test]
fn configs_without_the_new_families_keep_ids_and_fingerprints() {
    let small = preset("small");
    let ids: Vec<String> = scene_list(&small).into_iter().map(|(id, _)| id).collect();
    let names = ["room", "glass", "water", "metal", "shelf"];
    let expected: Vec<String> = (0..40)
        .map(|i| format!("{i:03}-{}", names[i / 8]))
        .collect();
    assert_eq!(ids, expected);
    let json = serde_json::to_string(&small).unwrap();
    assert!(
        !json.contains("lamp") && !json.contains("tabletop"),
        "{json}"
    );
    // The fingerprint of `tiny` as the datagen before these families wrote it in a manifest.
    assert_eq!(
        datagen::manifest::config_fingerprint(&preset("tiny")),
        TINY_FINGERPRINT
    );
}

/// Fingerprint (`config_sha256`) of configs/datagen/tiny.toml, unchanged since before the lamp
/// and tabletop families.
const TINY_FINGERPRINT: &str = "eaff9951eb809cbaacd1b1b723e44bd09d096940daddecfb93386071206c8b49";

/// Bounding-box diagonal of a shape's geometry.
fn extent(g: &Geometry) -> f32 {
    match g {
        Geometry::Mesh(m) => {
            let lo = m
                .positions
                .iter()
                .fold(glam::Vec3::INFINITY, |a, p| a.min(*p));
            let hi = m
                .positions
                .iter()
                .fold(glam::Vec3::NEG_INFINITY, |a, p| a.max(*p));
            (hi - lo).length()
        }
        Geometry::Sphere { radius, .. } => 2.0 * 3f32.sqrt() * radius,
        other => panic!("unexpected geometry {other:?}"),
    }
}

#[test]
fn lamp_and_tabletop_scenes_are_deterministic_loadable_and_true_to_family() {
    // The `families` preset's ranges with eight scenes of each, to meet every kind of lamp and
    // object.
    let mut config = preset("families");
    config.families.lamp.as_mut().unwrap().count = 8;
    config.families.tabletop.as_mut().unwrap().count = 8;
    let dir = fresh_dir("new-families");
    let (lamp, tabletop) = (
        config.families.lamp.as_ref().unwrap(),
        config.families.tabletop.as_ref().unwrap(),
    );
    let mut seen = 0;
    for (index, (id, family)) in scene_list(&config).into_iter().enumerate() {
        if !matches!(family, Family::Lamp | Family::Tabletop) {
            continue;
        }
        seen += 1;
        let d = deterministic_pinhole_scene(&config, index, &id, &dir);
        let emitting: Vec<_> = d.shapes.iter().filter(|s| s.emission.is_some()).collect();
        match family {
            Family::Lamp => {
                assert!(
                    within(d.camera.fov, Some(lamp.fov)),
                    "{id}: fov {}",
                    d.camera.fov
                );
                // Lit by its bulbs alone: small spheres, tiny next to the room.
                assert!(d.emitters.is_empty(), "{id}: {:?}", d.emitters);
                let n = emitting.len() as u32;
                assert!(n >= lamp.lamps[0] && n <= lamp.lamps[1], "{id}: {n} bulbs");
                let room = d
                    .shapes
                    .iter()
                    .map(|s| extent(&s.geometry))
                    .fold(0.0, f32::max);
                for s in &emitting {
                    assert!(matches!(s.geometry, Geometry::Sphere { .. }), "{id}");
                    let size = extent(&s.geometry);
                    assert!(size < 0.05 * room, "{id}: bulb {size} in a room of {room}");
                }
            }
            _ => {
                assert!(
                    within(d.camera.fov, Some(tabletop.fov)),
                    "{id}: fov {}",
                    d.camera.fov
                );
                assert!(
                    has_bsdf(&d, |b| matches!(b, Bsdf::Dielectric(_))),
                    "{id}: no glass"
                );
                let lights = emitting.len()
                    + d.emitters
                        .iter()
                        .filter(|e| !matches!(e, EmitterDesc::Constant { .. }))
                        .count();
                let [lo, hi] = tabletop.light_count;
                assert!(
                    lights >= lo as usize && lights <= hi as usize,
                    "{id}: {lights}"
                );
            }
        }
        renderer::scene::Scene::build(&d).unwrap_or_else(|e| panic!("{id}: {e}"));
    }
    assert_eq!(seen, 16);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The exterior and material tables are checked like the others, each error naming the field.
#[test]
fn exterior_and_material_config_errors_name_the_field() {
    let text = std::fs::read_to_string(preset_path("families")).unwrap();
    for (from, to, needle) in [
        (
            "glass_objects = [1, 3]",
            "glass_objects = [0, 3]",
            "families.exterior.glass_objects",
        ),
        (
            "sun_irradiance = [6.0, 12.0]",
            "sun_irradiance = [0.0, 12.0]",
            "families.exterior.sun_irradiance",
        ),
        (
            "sun_elevation = [30.0, 65.0]",
            "sun_elevation = [30.0, 95.0]",
            "families.exterior.sun_elevation",
        ),
        (
            "glass_shapes = [\"sphere\", \"block\", \"slab\", \"pool\"]",
            "glass_shapes = []",
            "families.exterior.glass_shapes",
        ),
        (
            "pool_size = [0.4, 0.7]",
            "pool_size = [0.7, 0.4]",
            "families.exterior.pool_size",
        ),
        (
            "kinds = [\"diffuse\", \"plastic\"",
            "kinds = [\"diffuse\", \"plastik\"",
            "plastik",
        ),
        (
            "alpha = [0.05, 0.4]",
            "alpha = [0.05, 1.4]",
            "families.material.alpha",
        ),
        (
            "objects = [2, 5]\nshapes = [\"vase\"",
            "objects = [0, 5]\nshapes = [\"vase\"",
            "families.material.objects",
        ),
        (
            "metals = [\"Au\", \"Cu\", \"Al\", \"Ag\", \"Cr\"]",
            "metals = []",
            "families.material.metals",
        ),
        (
            "texture_probability = 0.4",
            "texture_probabilty = 0.4",
            "texture_probabilty",
        ),
    ] {
        let bad = text.replacen(from, to, 1);
        assert_ne!(bad, text, "families.toml no longer has `{from}`");
        let e = Config::parse(&bad, "bad.toml").unwrap_err().to_string();
        assert!(e.contains("bad.toml") && e.contains(needle), "{to}: {e}");
    }
    let small = serde_json::to_string(&preset("small")).unwrap();
    assert!(
        !small.contains("exterior") && !small.contains("\"material\""),
        "{small}"
    );
}

#[test]
fn exterior_and_material_scenes_are_deterministic_loadable_and_true_to_family() {
    // The `families` preset's ranges with eight scenes of each, to meet most shapes and kinds.
    let mut config = preset("families");
    config.families.exterior.as_mut().unwrap().count = 8;
    config.families.material.as_mut().unwrap().count = 8;
    let dir = fresh_dir("exterior-material");
    let (exterior, material) = (
        config.families.exterior.as_ref().unwrap(),
        config.families.material.as_ref().unwrap(),
    );
    let mut seen = 0;
    let mut material_kinds = BTreeSet::new();
    for (index, (id, family)) in scene_list(&config).into_iter().enumerate() {
        if !matches!(family, Family::Exterior | Family::Material) {
            continue;
        }
        seen += 1;
        let d = deterministic_pinhole_scene(&config, index, &id, &dir);
        let constant = d
            .emitters
            .iter()
            .any(|e| matches!(e, EmitterDesc::Constant { .. }));
        match family {
            Family::Exterior => {
                assert!(within(d.camera.fov, Some(exterior.fov)), "{id}");
                assert!(
                    d.emitters
                        .iter()
                        .any(|e| matches!(e, EmitterDesc::Directional { .. })),
                    "{id}: no sun"
                );
                assert!(constant, "{id}: no sky");
                assert!(
                    has_bsdf(&d, |b| matches!(b, Bsdf::Dielectric(_))),
                    "{id}: no glass or water"
                );
            }
            _ => {
                assert!(within(d.camera.fov, Some(material.fov)), "{id}");
                assert!(constant, "{id}: no environment");
                assert_eq!(
                    d.shapes.iter().filter(|s| s.emission.is_some()).count(),
                    1,
                    "{id}: one area light"
                );
                for s in d.shapes.iter().filter(|s| s.emission.is_none()) {
                    let name = format!("{:?}", d.bsdfs[s.bsdf]);
                    let kind = name.split(['(', ' ', '{']).next().unwrap().to_owned();
                    material_kinds.insert(kind);
                }
            }
        }
        renderer::scene::Scene::build(&d).unwrap_or_else(|e| panic!("{id}: {e}"));
    }
    assert_eq!(seen, 16);
    // Floors and walls are diffuse; the objects bring the other kinds.
    material_kinds.remove("Diffuse");
    assert!(material_kinds.len() >= 3, "{material_kinds:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The textured table is checked like the others, each error naming the field; configs without
/// it serialise (fingerprint) without it.
#[test]
fn textured_config_errors_name_the_field() {
    let text = std::fs::read_to_string(preset_path("families")).unwrap();
    let (head, table) = text.split_at(
        text.find("[families.textured]")
            .expect("families.toml has a textured table"),
    );
    for (from, to, needle) in [
        (
            "layouts = [\"corner\", \"table\"]",
            "layouts = []",
            "families.textured.layouts",
        ),
        (
            "wall_patterns = [\"plaster\"",
            "wall_patterns = [\"marble\"",
            "marble",
        ),
        (
            "bump_depth = [0.002, 0.006]",
            "bump_depth = [0.0, 0.006]",
            "families.textured.bump_depth",
        ),
        (
            "pattern_size = [0.4, 1.0]",
            "pattern_size = [1.0, 0.4]",
            "families.textured.pattern_size",
        ),
        (
            "texture_size = [128, 256]",
            "texture_size = [4, 256]",
            "families.textured.texture_size",
        ),
        (
            "normalmap_probability = 0.5",
            "normalmap_probability = 1.5",
            "families.textured.normalmap_probability",
        ),
        (
            "alpha = [0.05, 0.3]",
            "alpha = [0.05, 1.3]",
            "families.textured.alpha",
        ),
        (
            "small_lights = [\"spot\", \"point\"]",
            "small_lights = []",
            "families.textured.small_lights",
        ),
        (
            "bump_depth = [0.002, 0.006]",
            "bump_dept = [0.002, 0.006]",
            "bump_dept",
        ),
    ] {
        let bad = format!("{head}{}", table.replacen(from, to, 1));
        assert_ne!(bad, text, "the textured table no longer has `{from}`");
        let e = Config::parse(&bad, "bad.toml").unwrap_err().to_string();
        assert!(e.contains("bad.toml") && e.contains(needle), "{to}: {e}");
    }
    for name in ["small", "tiny", "mixed", "paper"] {
        let json = serde_json::to_string(&preset(name)).unwrap();
        assert!(!json.contains("textured"), "{name}: {json}");
    }
}

/// The surface's albedo under any bump or normal map, if it is a bitmap.
fn bitmap_albedo(b: &Bsdf) -> bool {
    use renderer::texture::Texture;
    match b {
        Bsdf::BumpMap(m) => bitmap_albedo(&m.nested),
        Bsdf::NormalMap(m) => bitmap_albedo(&m.nested),
        Bsdf::TwoSided { front, .. } => bitmap_albedo(front),
        Bsdf::Diffuse(d) => matches!(d.reflectance, Texture::Bitmap { .. }),
        Bsdf::Plastic(p) => matches!(p.diffuse_reflectance, Texture::Bitmap { .. }),
        Bsdf::RoughPlastic(p) => matches!(p.diffuse_reflectance, Texture::Bitmap { .. }),
        _ => false,
    }
}

/// Every `value="textures/…"` file name in a scene's XML.
fn texture_files(xml: &str) -> BTreeSet<String> {
    xml.split("value=\"")
        .skip(1)
        .filter_map(|rest| rest.split('"').next())
        .filter(|v| v.starts_with("textures/"))
        .map(str::to_owned)
        .collect()
}

#[test]
fn textured_scenes_carry_their_images_load_and_are_true_to_family() {
    use renderer::texture::Texture;
    // The `families` preset's ranges with eight scenes, on smaller images (a debug build
    // generates them).
    let mut config = preset("families");
    let c = config.families.textured.as_mut().unwrap();
    c.count = 8;
    c.texture_size = [48, 96];
    let textured = c.clone();
    let dir = fresh_dir("textured");
    let (mut seen, mut bumps, mut normals, mut metals, mut glossy, mut small) = (0, 0, 0, 0, 0, 0);
    for (index, (id, family)) in scene_list(&config).into_iter().enumerate() {
        if family != Family::Textured {
            continue;
        }
        seen += 1;
        // Deterministic to the byte, images included.
        let d = deterministic_pinhole_scene(&config, index, &id, &dir);
        let scene = generate(&config, index).unwrap();
        assert!(within(d.camera.fov, Some(textured.fov)), "{id}");

        // The images: PNGs, named exactly by the XML, written next to it, each a square of a
        // configured size; a height map is 16-bit grey, albedo and normal maps 8-bit RGB.
        let names: BTreeSet<String> = scene.images.iter().map(|(n, _)| n.clone()).collect();
        assert_eq!(names, texture_files(&scene.xml), "{id}");
        assert_eq!(names.len(), scene.images.len(), "{id}: a name twice");
        for (name, bytes) in &scene.images {
            assert_eq!(
                &std::fs::read(dir.join(&id).join(name)).unwrap(),
                bytes,
                "{id}/{name}"
            );
            let img = image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
                .unwrap_or_else(|e| panic!("{id}/{name}: {e}"));
            let [lo, hi] = textured.texture_size;
            assert!(
                img.width() == img.height() && (lo..=hi).contains(&img.width()),
                "{id}/{name}: {}x{}",
                img.width(),
                img.height()
            );
            let want = if name.ends_with("_height.png") {
                image::ColorType::L16
            } else {
                image::ColorType::Rgb8
            };
            assert_eq!(img.color(), want, "{id}/{name}");
        }

        // The family's point: bitmap albedos under bump or normal maps of bitmaps.
        let shape_bsdfs: Vec<&Bsdf> = d.shapes.iter().map(|s| &d.bsdfs[s.bsdf]).collect();
        assert!(
            shape_bsdfs.iter().any(|b| bitmap_albedo(b)),
            "{id}: no bitmap albedo"
        );
        let mut relief = false;
        for b in &shape_bsdfs {
            match b {
                Bsdf::BumpMap(m) => {
                    assert!(matches!(m.height, Texture::Bitmap { .. }), "{id}");
                    assert!(
                        m.scale > 0.0 && m.scale <= textured.bump_depth[1] + 1e-6,
                        "{id}: scale {}",
                        m.scale
                    );
                    bumps += 1;
                    relief = true;
                }
                Bsdf::NormalMap(m) => {
                    assert!(matches!(m.normalmap, Texture::Bitmap { .. }), "{id}");
                    normals += 1;
                    relief = true;
                }
                _ => {}
            }
        }
        assert!(relief, "{id}: neither a bump map nor a normal map");
        let under = |pred: fn(&Bsdf) -> bool| {
            shape_bsdfs.iter().any(|b| match b {
                Bsdf::BumpMap(m) => pred(&m.nested),
                Bsdf::NormalMap(m) => pred(&m.nested),
                other => pred(other),
            })
        };
        metals += usize::from(under(|b| {
            matches!(b, Bsdf::Conductor(_) | Bsdf::RoughConductor(_))
        }));
        glossy += usize::from(under(|b| {
            matches!(b, Bsdf::Plastic(_) | Bsdf::RoughPlastic(_))
        }));

        // One area light above, and at most one small spot or point light.
        assert_eq!(
            d.shapes.iter().filter(|s| s.emission.is_some()).count(),
            1,
            "{id}: one area light"
        );
        let compact = d
            .emitters
            .iter()
            .filter(|e| matches!(e, EmitterDesc::Spot { .. } | EmitterDesc::Point { .. }))
            .count();
        assert!(compact <= 1, "{id}: {compact} small lights");
        small += compact;
        renderer::scene::Scene::build(&d).unwrap_or_else(|e| panic!("{id}: {e}"));
    }
    assert_eq!(seen, 8);
    // Across the scenes every kind of relief, glossy and metal objects and a small light.
    assert!(
        bumps > 0 && normals > 0 && metals > 0 && glossy > 0 && small > 0,
        "bump maps {bumps}, normal maps {normals}, metal {metals}, glossy {glossy}, small lights {small}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
