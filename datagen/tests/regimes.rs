//! Input regimes (`[[render.regimes]]`: per-scene photon density, passes, seeds and side) and
//! references averaged from several runs (`render.reference_runs`, photon factors): the plan,
//! the generated films, validation errors, and a whole dataset with a stand-in renderer —
//! sizes and reference noise in the manifest, `check`, the noise table, and a reference job
//! killed between its runs that resumes without redoing the finished run.

mod common;

use anyhow::{bail, Result};
use bundle::{Bundle, Image};
use common::{assert_same, fresh_dir, snapshot, stand_in_bundle, test_config};
use datagen::average::{mean_and_noise, run_seed};
use datagen::check::check_dataset;
use datagen::config::{Config, Regime};
use datagen::families::generate;
use datagen::jobs::{render_dataset, RenderOptions, RunSpec, SampleRenderer};
use datagen::manifest::Manifest;
use datagen::plan::{Plan, Shard, Split};
use datagen::reference_noise::noise_table;
use datagen::rng::hash_seq;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

fn regime(name: &str, share: f64, side: Option<u32>, ppx: [f64; 2], passes: &[u32]) -> Regime {
    Regime {
        name: name.into(),
        share,
        side,
        photons_per_pixel: ppx,
        passes: passes.to_vec(),
        seeds: None,
        reference_passes: None,
    }
}

/// The tiny preset at 16×16 with `per_family` scenes of each of its families and two regimes:
/// `sparse` (share 3, the config's size, 0.1–1 photons per pixel, passes 2 and 4) and `wide`
/// (share 2, 24×24, 10–60 photons per pixel, passes 2, one seed, 8 reference passes).
fn regime_config(per_family: u32) -> Config {
    let mut c = test_config(16, &[2, 4], 2, 4);
    c.render.passes = None;
    c.render.photons_per_pass = None;
    let mut wide = regime("wide", 2.0, Some(24), [10.0, 60.0], &[2]);
    wide.seeds = Some(1);
    wide.reference_passes = Some(8);
    c.render.regimes = vec![regime("sparse", 3.0, None, [0.1, 1.0], &[2, 4]), wide];
    let f = &mut c.families;
    for count in [
        f.room.as_mut().map(|x| &mut x.count),
        f.glass.as_mut().map(|x| &mut x.count),
        f.water.as_mut().map(|x| &mut x.count),
        f.metal.as_mut().map(|x| &mut x.count),
        f.shelf.as_mut().map(|x| &mut x.count),
    ]
    .into_iter()
    .flatten()
    {
        *count = per_family;
    }
    c
}

#[test]
fn every_family_is_split_over_the_regimes_by_share_with_densities_in_range() {
    let config = regime_config(5);
    let plan = Plan::new(&config);
    assert_eq!(plan.scenes.len(), 25);
    for family in ["room", "glass", "water", "metal", "shelf"] {
        let of = |name: &str| {
            plan.scenes
                .iter()
                .filter(|s| s.family.name() == family && s.render.regime.as_deref() == Some(name))
                .count()
        };
        assert_eq!((of("sparse"), of("wide")), (3, 2), "{family}");
    }
    for s in &plan.scenes {
        let r = &s.render;
        let (side, lo, hi, passes, seeds, reference_passes) = match r.regime.as_deref() {
            Some("sparse") => (16, 0.1, 1.0, vec![2, 4], 2, 4),
            Some("wide") => (24, 10.0, 60.0, vec![2], 1, 8),
            other => panic!("{}: regime {other:?}", s.id),
        };
        assert_eq!((r.width, r.height), (side, side), "{}", s.id);
        let per_pixel = r.photons_per_pass as f64 / f64::from(side * side);
        assert!(
            per_pixel >= lo - 0.5 / 256.0 && per_pixel <= hi + 0.5 / 256.0,
            "{}: {per_pixel} photons per pixel outside [{lo}, {hi}]",
            s.id
        );
        assert_eq!(
            (r.passes.clone(), r.seeds, r.reference_passes),
            (passes, seeds, reference_passes)
        );
        let jobs = plan.jobs.iter().filter(|j| j.scene() == s.index).count();
        assert_eq!(
            jobs as u32,
            1 + seeds,
            "{}: a reference and one job per seed",
            s.id
        );
    }
    // Densities are drawn per scene, not one per regime.
    let sparse: std::collections::BTreeSet<u64> = plan
        .scenes
        .iter()
        .filter(|s| s.render.regime.as_deref() == Some("sparse"))
        .map(|s| s.render.photons_per_pass)
        .collect();
    assert!(sparse.len() > 10, "{sparse:?}");
    // Deterministic, and the regimes touch neither the scenes nor the splits.
    let again = Plan::new(&config);
    assert_eq!(
        plan.scenes.iter().map(|s| &s.render).collect::<Vec<_>>(),
        again.scenes.iter().map(|s| &s.render).collect::<Vec<_>>()
    );
    let mut plain = regime_config(5);
    plain.render.regimes.clear();
    plain.render.passes = Some(vec![2, 4]);
    plain.render.photons_per_pass = Some(1000);
    let plain_plan = Plan::new(&plain);
    for (a, b) in plan.scenes.iter().zip(&plain_plan.scenes) {
        assert_eq!((&a.id, a.split), (&b.id, b.split));
    }
}

#[test]
fn reference_photons_follow_the_photon_factor_of_the_split() {
    let mut config = regime_config(5);
    config.render.reference_runs = Some(2);
    config.render.reference_photon_factor = Some(32.0);
    config.render.train_reference_photon_factor = Some(2.0);
    config.render.reference_photons_per_pass = 100;
    let plan = Plan::new(&config);
    let mut splits = std::collections::BTreeSet::new();
    for s in &plan.scenes {
        let r = &s.render;
        let factor = if s.split == Split::Train { 2.0 } else { 32.0 };
        let input = r.photons_per_pass as f64 * f64::from(r.last_pass());
        let per_pass = (factor * input / f64::from(r.reference_passes * 2)).ceil() as u64;
        assert_eq!(r.reference_photons_per_pass, per_pass.max(100), "{}", s.id);
        assert_eq!(r.reference_runs, 2);
        splits.insert(s.split.name());
    }
    assert_eq!(splits.len(), 3, "every split is planned");
    // Without a factor the fixed count stays.
    config.render.reference_photon_factor = None;
    config.render.train_reference_photon_factor = None;
    assert!(Plan::new(&config)
        .scenes
        .iter()
        .all(|s| s.render.reference_photons_per_pass == 100));
}

#[test]
fn generated_films_have_their_regime_side() {
    let config = regime_config(5);
    let plan = Plan::new(&config);
    for s in &plan.scenes {
        let xml = generate(&config, s.index).unwrap().xml;
        let side = s.render.width;
        assert!(
            xml.contains(&format!("name=\"width\" value=\"{side}\""))
                && xml.contains(&format!("name=\"height\" value=\"{side}\"")),
            "{}: film is not {side}x{side}",
            s.id
        );
    }
}

#[test]
fn bad_regimes_are_errors_naming_the_key() {
    let base = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/datagen/tiny.toml"),
    )
    .unwrap();
    let regimes = "\n[[render.regimes]]\nname = \"a\"\nshare = 1.0\nphotons_per_pixel = [0.5, 2.0]\npasses = [2, 4]\n";
    // Regimes replace the render section's passes and photons.
    let with_both = base.replacen("[split]", &format!("{regimes}\n[split]"), 1);
    let err = Config::parse(&with_both, "x.toml").unwrap_err().to_string();
    assert!(err.contains("not used with [[render.regimes]]"), "{err}");
    let without =
        base.replacen("photons_per_pass = 1000\n", "", 1)
            .replacen("passes = [2, 4]\n", "", 1);
    let err = Config::parse(&without, "x.toml").unwrap_err().to_string();
    assert!(err.contains("are required"), "{err}");
    let good = without.replacen("[split]", &format!("{regimes}\n[split]"), 1);
    Config::parse(&good, "x.toml").expect("regimes alone are a valid render section");
    for (from, to, needle) in [
        (
            "photons_per_pixel = [0.5, 2.0]",
            "photons_per_pixel = [2.0, 0.5]",
            "render.regimes[0] (`a`).photons_per_pixel",
        ),
        (
            "passes = [2, 4]\n\n[split]",
            "passes = [4, 2]\n\n[split]",
            "strictly ascending",
        ),
        (
            "share = 1.0",
            "share = 0.0",
            "render.regimes[0] (`a`).share",
        ),
        (
            "share = 1.0",
            "share = 1.0\nside = 0",
            "render.regimes[0] (`a`).side",
        ),
        (
            "share = 1.0",
            "share = 1.0\nsides = 64",
            "unknown field `sides`",
        ),
        (
            "[[render.regimes]]",
            "reference_photon_factor = -1\n[[render.regimes]]",
            "render.reference_photon_factor",
        ),
        (
            "[[render.regimes]]",
            "reference_runs = 0\n[[render.regimes]]",
            "render.reference_runs",
        ),
    ] {
        assert!(good.contains(from), "{from}");
        let text = good.replacen(from, to, 1);
        let err = Config::parse(&text, "x.toml").unwrap_err().to_string();
        assert!(err.contains(needle), "{to}: {err}");
    }
    let twice = good.replacen("[split]", &format!("{regimes}\n[split]"), 1);
    let err = Config::parse(&twice, "x.toml").unwrap_err().to_string();
    assert!(err.contains("a name of its own"), "{err}");
}

/// References are hashes of (seed, pixel); a reference run can be made to fail after `fail_at`
/// successful runs, as a killed process would stop.
struct StandIn {
    reference_runs: AtomicUsize,
    fail_at: Option<usize>,
}

impl StandIn {
    fn new(fail_at: Option<usize>) -> Self {
        Self {
            reference_runs: AtomicUsize::new(0),
            fail_at,
        }
    }
}

fn film(xml: &Path) -> (usize, usize) {
    let text = std::fs::read_to_string(xml).unwrap();
    let key = "name=\"width\" value=\"";
    let at = text.find(key).unwrap() + key.len();
    let w = text[at..].split('"').next().unwrap().parse().unwrap();
    (w, w)
}

fn picture(seed: u64, (w, h): (usize, usize), channels: usize, salt: usize) -> Image {
    let mut img = Image::new(w, h, channels);
    for (i, v) in img.data.iter_mut().enumerate() {
        *v = (hash_seq(&[seed, i as u64, salt as u64]) % 1000) as f32 / 500.0;
    }
    img
}

impl SampleRenderer for StandIn {
    fn reference(
        &self,
        xml: &Path,
        spec: &RunSpec,
        on_pass: &mut (dyn FnMut(u32) + Send),
    ) -> Result<Image> {
        let n = self.reference_runs.fetch_add(1, Ordering::SeqCst);
        if self.fail_at == Some(n) {
            bail!("killed");
        }
        on_pass(spec.passes[0]);
        Ok(picture(spec.sppm.seed, film(xml), 3, 0))
    }

    fn inputs(
        &self,
        xml: &Path,
        spec: &RunSpec,
        on_bundle: &mut (dyn FnMut(Bundle) -> Result<()> + Send),
        on_pass: &mut (dyn FnMut(u32) + Send),
    ) -> Result<()> {
        let size = film(xml);
        for &p in &spec.passes {
            on_pass(p);
            on_bundle(stand_in_bundle(spec, p, size, true, |channels, salt| {
                picture(spec.sppm.seed + u64::from(p), size, channels, salt)
            }))?;
        }
        Ok(())
    }
}

fn options() -> RenderOptions {
    RenderOptions {
        shard: Shard::ALL,
        selection: Default::default(),
        kinds: Default::default(),
        threads: 1,
        progress: false,
        state_interval: 60.0,
    }
}

#[test]
fn a_dataset_of_regimes_records_sizes_and_reference_noise_and_resumes_between_runs() {
    let mut config = regime_config(1);
    config.render.reference_runs = Some(2);
    let whole = fresh_dir("regimes-whole");
    let r = StandIn::new(None);
    let report = render_dataset(&config, &whole, options(), &r).unwrap();
    assert!(report.manifest_complete);
    let manifest: Manifest = Manifest::load(&whole).unwrap();
    let plan = Plan::new(&config);
    for (s, p) in manifest.scenes.iter().zip(&plan.scenes) {
        let side = p.render.width;
        assert_eq!(s.size, (side != 16).then_some([side, side]), "{}", s.id);
        assert_eq!(s.regime, p.render.regime);
        assert_eq!(s.reference_runs, Some(2));
        // The noise of the mean of the two runs, as `average-references` measures it.
        let runs: Vec<Image> = [s.reference_seed, run_seed(s.reference_seed, 1)]
            .iter()
            .map(|&seed| picture(seed, (side as usize, side as usize), 3, 0))
            .collect();
        let (mean, one_run) = mean_and_noise(&runs);
        assert_eq!(s.reference_noise, Some(one_run / 2.0), "{}", s.id);
        let written = bundle::read_rgb_exr_image(&whole.join(&s.reference)).unwrap();
        assert_eq!(
            written, mean,
            "{}: the reference is the mean of its runs",
            s.id
        );
    }
    for e in &manifest.samples {
        let side = plan
            .scenes
            .iter()
            .find(|s| s.id == e.scene)
            .unwrap()
            .render
            .width;
        let b = bundle::read_bundle(&whole.join(&e.bundle)).unwrap();
        assert_eq!((b.meta.width, b.meta.height), (side, side), "{}", e.bundle);
    }
    let check = check_dataset(&whole, |_, _| {});
    assert!(check.ok(), "{:?}", check.problems);
    let table = noise_table(&whole, &manifest, |_, _| {}).unwrap();
    assert_eq!(table.scenes.len(), 5);
    assert!(table.unmeasured.is_empty());
    assert_eq!(table.families.len(), 5);
    for row in &table.scenes {
        assert_eq!(row.flagged, row.ratio.is_none_or(|r| r > 0.1), "{}", row.id);
    }

    // Killed after the first reference's first run: that run is kept and not rendered again.
    let resumed = fresh_dir("regimes-resumed");
    let killed = StandIn::new(Some(1));
    assert!(render_dataset(&config, &resumed, options(), &killed).is_err());
    let kept = std::fs::read_dir(resumed.join("records").join(&plan.scenes[0].id))
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".run0.exr"))
        .count();
    assert_eq!(kept, 1, "the finished run is kept for the next session");
    let again = StandIn::new(None);
    render_dataset(&config, &resumed, options(), &again).unwrap();
    assert_eq!(
        again.reference_runs.load(Ordering::SeqCst),
        2 * 5 - 1,
        "every reference run but the kept one"
    );
    assert_same(&snapshot(&whole), &snapshot(&resumed));
}

#[test]
fn the_plan_summary_counts_scenes_and_work_per_regime() {
    let config = regime_config(5);
    let plan = Plan::new(&config);
    let table = datagen::plan::summary(&plan);
    let row = |name: &str| -> Vec<String> {
        let line = table
            .lines()
            .find(|l| l.starts_with(&format!("| {name} |")))
            .unwrap_or_else(|| panic!("no row {name}: {table}"));
        line.split('|').map(|c| c.trim().to_owned()).collect()
    };
    let sparse = row("sparse");
    assert!(sparse[2].starts_with("15 ("), "{sparse:?}");
    assert_eq!(sparse[3], "16");
    let wide = row("wide");
    assert!(wide[2].starts_with("10 ("), "{wide:?}");
    assert_eq!(wide[3], "24");
    // Input eye passes in 128² units: 10 scenes × 1 seed × 2 passes × 24²/128².
    let eye: f64 = wide[7].parse().unwrap();
    assert!((eye - 10.0 * 2.0 * 576.0 / 16384.0).abs() < 1e-3, "{eye}");
    assert!(row("all")[2] == "25");

    // `plan --per-family 1`: one scene of each family in each split, the rows of those only.
    let selection = datagen::plan::SceneSelection {
        per_family: Some((1, 1)),
        ..Default::default()
    };
    let keep = selection.scenes_of(&plan).unwrap();
    let firsts = keep.iter().filter(|&&k| k).count();
    assert!((1..25).contains(&firsts), "{firsts}");
    let table = datagen::plan::summary_of(&plan, &keep);
    let all: Vec<&str> = table
        .lines()
        .find(|l| l.starts_with("| all |"))
        .unwrap()
        .split('|')
        .map(str::trim)
        .collect();
    assert_eq!(all[2], firsts.to_string(), "{table}");
}
