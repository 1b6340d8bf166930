//! `average_references` with a stand-in renderer whose runs are images that depend on the seed,
//! the pixel and the channel: the per-pixel mean and the noise estimate equal values computed
//! by hand from the documented formula, extra runs are reused (and only the missing ones
//! rendered when more runs are asked for), and bad requests are errors.

mod common;

use anyhow::Result;
use bundle::{read_rgb_exr_image, Bundle, Image};
use common::{fresh_dir, stand_in_bundle, test_config};
use datagen::average::{
    average_references, run_seed, summary_lines, AverageOptions, NoiseReport, NOISE_FILE,
};
use datagen::jobs::{render_dataset, RenderOptions, RunSpec, SampleRenderer};
use datagen::manifest::Manifest;
use datagen::plan::Shard;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

const SIDE: usize = 8;

/// The overall level of a run with this seed.
fn level(seed: u64) -> f32 {
    0.25 + (seed % 7) as f32 * 0.5
}

/// The sample of a run with this seed at pixel (x, y), channel c: the seed's level scaled by a
/// ramp over x, plus offsets in y and c and a term mixing seed, pixel and channel, so the
/// per-pixel spread between runs differs from pixel to pixel and from channel to channel.
fn sample(seed: u64, x: usize, y: usize, c: usize) -> f32 {
    let mix = (seed as usize % 5 + 3 * x + 5 * y + 7 * c) % 4;
    level(seed) * (1.0 + 0.25 * x as f32) + 0.125 * y as f32 + 0.5 * c as f32 + 0.0625 * mix as f32
}

/// The stand-in renderer: every run is [`run_image`] of its seed; counts reference runs.
#[derive(Default)]
struct StandIn {
    references: AtomicUsize,
}

/// The image of a run with this seed, `channels` channels of [`sample`].
fn run_image(seed: u64, channels: usize) -> Image {
    let mut img = Image::new(SIDE, SIDE, channels);
    for y in 0..SIDE {
        for x in 0..SIDE {
            for c in 0..channels {
                img.set(x, y, c, sample(seed, x, y, c));
            }
        }
    }
    img
}

impl SampleRenderer for StandIn {
    fn reference(
        &self,
        _: &Path,
        spec: &RunSpec,
        _: &mut (dyn FnMut(u32) + Send),
    ) -> Result<Image> {
        self.references.fetch_add(1, Ordering::SeqCst);
        Ok(run_image(spec.sppm.seed, 3))
    }

    fn inputs(
        &self,
        _: &Path,
        spec: &RunSpec,
        on_bundle: &mut (dyn FnMut(Bundle) -> Result<()> + Send),
        _: &mut (dyn FnMut(u32) + Send),
    ) -> Result<()> {
        for &p in &spec.passes {
            on_bundle(stand_in_bundle(
                spec,
                p,
                (SIDE, SIDE),
                false,
                |channels, _| run_image(spec.sppm.seed, channels),
            ))?;
        }
        Ok(())
    }
}

fn dataset(name: &str) -> (PathBuf, Manifest) {
    let dir = fresh_dir(name);
    let config = test_config(SIDE as u32, &[2], 1, 4);
    let options = RenderOptions {
        shard: Shard::ALL,
        selection: Default::default(),
        kinds: Default::default(),
        threads: 1,
        progress: false,
        state_interval: 60.0,
    };
    render_dataset(&config, &dir, options, &StandIn::default()).unwrap();
    let manifest = Manifest::load(&dir).unwrap();
    (dir, manifest)
}

fn options(manifest: &Manifest, runs: usize) -> AverageOptions {
    AverageOptions {
        split: manifest.scenes[0].split,
        runs,
        out: PathBuf::from("avg"),
        threads: 1,
        state_interval: 60.0,
    }
}

fn average(dir: &Path, manifest: &Manifest, runs: usize, renderer: &StandIn) -> NoiseReport {
    average_references(
        dir,
        manifest,
        renderer,
        &options(manifest, runs),
        |_, _, _| {},
        &mut |_| {},
    )
    .unwrap()
}

/// The averaged image is the per-pixel, per-channel mean of the runs and the noise report the
/// documented relMSE of one run (and of the mean), both computed by hand; runs are reused.
#[test]
fn mean_and_noise_match_hand_computed_values_and_runs_are_reused() {
    let (dir, manifest) = dataset("avg-values");
    let scene = &manifest.scenes[0];
    let in_split = manifest
        .scenes
        .iter()
        .filter(|s| s.split == scene.split)
        .count();
    let renderer = StandIn::default();
    let report = average(&dir, &manifest, 3, &renderer);
    assert_eq!(renderer.references.load(Ordering::SeqCst), 2 * in_split);
    assert_eq!(report.scenes.len(), in_split);

    // By hand: the runs are images of seeds s0 (the dataset's reference), s1, s2.
    let seeds: Vec<u64> = (0..3)
        .map(|r| {
            if r == 0 {
                scene.reference_seed
            } else {
                run_seed(scene.reference_seed, r)
            }
        })
        .collect();
    let got = &report.scenes[&scene.id];
    assert_eq!(got.seeds, seeds);
    // Per sample: mean m and unbiased variance s² over the runs; per pixel: the weight
    // 1/(g² + 0.01) with g the mean over RGB of m; the noise of one run is the mean over all
    // samples of s²·weight (Σ s²/(ref² + 0.01) / (3·pixels), datagen::average::SceneNoise).
    let mut mean = vec![[0.0f64; 3]; SIDE * SIDE];
    let mut sum = 0.0f64;
    for y in 0..SIDE {
        for x in 0..SIDE {
            let m = &mut mean[y * SIDE + x];
            let mut s2 = [0.0f64; 3];
            for c in 0..3 {
                let v: Vec<f64> = seeds
                    .iter()
                    .map(|&s| f64::from(sample(s, x, y, c)))
                    .collect();
                m[c] = v.iter().sum::<f64>() / 3.0;
                s2[c] = v.iter().map(|x| (x - m[c]).powi(2)).sum::<f64>() / 2.0;
            }
            let grey = (m[0] + m[1] + m[2]) / 3.0;
            sum += (s2[0] + s2[1] + s2[2]) / (grey * grey + 0.01);
        }
    }
    let noise = sum / (3 * SIDE * SIDE) as f64;
    assert!(noise > 0.0, "the runs must differ: noise {noise}");
    assert!(
        (got.relmse_one_run - noise).abs() <= 1e-6 * noise,
        "relmse_one_run {} vs {noise} by hand",
        got.relmse_one_run
    );
    assert!(
        (got.relmse_mean - noise / 3.0).abs() <= 1e-6 * noise,
        "relmse_mean {} vs {} by hand",
        got.relmse_mean,
        noise / 3.0
    );
    let avg_path = dir.join("avg").join(format!("{}.exr", scene.id));
    let img = read_rgb_exr_image(&avg_path).unwrap();
    assert_eq!((img.width, img.height, img.channels), (SIDE, SIDE, 3));
    for y in 0..SIDE {
        for x in 0..SIDE {
            for (c, &want) in mean[y * SIDE + x].iter().enumerate() {
                let got = f64::from(img.get(x, y, c));
                assert!(
                    (got - want).abs() <= 1e-6 * want,
                    "{}: pixel ({x}, {y}) channel {c} = {got}, want the mean {want}",
                    avg_path.display()
                );
            }
        }
    }
    let written: NoiseReport =
        serde_json::from_slice(&std::fs::read(dir.join("avg").join(NOISE_FILE)).unwrap()).unwrap();
    assert_eq!(written, report);

    // The same request renders nothing.
    let again = average(&dir, &manifest, 3, &renderer);
    assert_eq!(renderer.references.load(Ordering::SeqCst), 2 * in_split);
    assert_eq!(again, report);
    // Another run count into the same folder is refused (its means would silently replace
    // the 3-run ones), naming the folder, both counts and --out; nothing is rendered or written.
    let before = std::fs::read(dir.join("avg").join(NOISE_FILE)).unwrap();
    for runs in [2, 4] {
        let err = average_references(
            &dir,
            &manifest,
            &renderer,
            &options(&manifest, runs),
            |_, _, _| {},
            &mut |_| {},
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("avg")
                && err.contains("averages of 3 runs")
                && err.contains(&format!("asks for {runs}"))
                && err.contains("--out"),
            "{err}"
        );
    }
    assert_eq!(renderer.references.load(Ordering::SeqCst), 2 * in_split);
    assert_eq!(
        std::fs::read(dir.join("avg").join(NOISE_FILE)).unwrap(),
        before
    );
    // One more run into another folder renders only that run per scene.
    let four = AverageOptions {
        out: PathBuf::from("avg4"),
        ..options(&manifest, 4)
    };
    average_references(&dir, &manifest, &renderer, &four, |_, _, _| {}, &mut |_| {}).unwrap();
    assert_eq!(renderer.references.load(Ordering::SeqCst), 3 * in_split);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Too few runs and output folders that would overwrite the dataset are errors naming them;
/// the dataset's own references stay as rendered.
#[test]
fn bad_requests_are_errors() {
    let (dir, manifest) = dataset("avg-errors");
    let renderer = StandIn::default();
    let run = |o: AverageOptions| {
        average_references(&dir, &manifest, &renderer, &o, |_, _, _| {}, &mut |_| {})
            .unwrap_err()
            .to_string()
    };
    assert!(run(options(&manifest, 1)).contains("at least 2"));
    for out in ["references", "reference-runs", "../elsewhere", "/tmp/x"] {
        let err = run(AverageOptions {
            out: PathBuf::from(out),
            ..options(&manifest, 2)
        });
        assert!(err.contains(out), "{out}: {err}");
    }
    // The dataset's own references are untouched by any of this.
    let reference = std::fs::read(dir.join(&manifest.scenes[0].reference)).unwrap();
    assert_eq!(
        read_rgb_exr_image(&dir.join(&manifest.scenes[0].reference)).unwrap(),
        run_image(manifest.scenes[0].reference_seed, 3)
    );
    assert!(!reference.is_empty());
    assert_eq!(renderer.references.load(Ordering::SeqCst), 0);
    // A dataset directory without a manifest is named (the manifest is read before averaging).
    let empty = fresh_dir("avg-empty");
    let err = Manifest::load(&empty).unwrap_err().to_string();
    assert!(err.contains("manifest.json"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&empty);
}

#[test]
fn splits_share_one_directory_and_its_noise_report() {
    let (dir, manifest) = dataset("avg-splits");
    let renderer = StandIn::default();
    let mut splits: Vec<_> = manifest.scenes.iter().map(|s| s.split).collect();
    splits.sort_by_key(|s| s.name());
    splits.dedup();
    assert!(splits.len() >= 2, "the test dataset should have two splits");
    let run = |split| {
        let o = AverageOptions {
            split,
            ..options(&manifest, 2)
        };
        average_references(&dir, &manifest, &renderer, &o, |_, _, _| {}, &mut |_| {}).unwrap()
    };
    run(splits[0]);
    let both = run(splits[1]);
    // The second call keeps the first split's scenes: every scene of both splits is listed once,
    // with its own split.
    let want: Vec<_> = manifest
        .scenes
        .iter()
        .filter(|s| s.split == splits[0] || s.split == splits[1])
        .map(|s| (s.id.clone(), s.split))
        .collect();
    let got: Vec<_> = both
        .scenes
        .iter()
        .map(|(id, n)| (id.clone(), n.split))
        .collect();
    let mut want = want;
    want.sort_by(|a, b| a.0.cmp(&b.0));
    assert_eq!(got, want);
    let path = dir.join("avg").join(NOISE_FILE);
    assert_eq!(NoiseReport::read(&path).unwrap(), Some(both.clone()));
    // What the second call prints: its own split's scenes, the first split's only counted.
    let lines = summary_lines(&both, splits[1], &path);
    let of = |split| manifest.scenes.iter().filter(move |s| s.split == split);
    assert_eq!(lines.len(), of(splits[1]).count() + 1, "{lines:?}");
    for s in of(splits[1]) {
        assert!(lines.iter().any(|l| l.starts_with(&s.id)), "{lines:?}");
    }
    for s in of(splits[0]) {
        assert!(!lines.iter().any(|l| l.contains(&s.id)), "{lines:?}");
    }
    assert!(
        lines.last().unwrap().contains(&format!(
            "{} scene(s) of other splits, averaged by earlier calls",
            of(splits[0]).count()
        )),
        "{lines:?}"
    );

    // A report of the first version (one split for the file) is read and kept.
    let (id, scene) = both.scenes.iter().next().unwrap();
    let v1 = serde_json::json!({
        "split": scene.split,
        "reference_passes": both.reference_passes,
        "reference_photons": both.reference_photons,
        "scenes": { id: {
            "runs": scene.runs,
            "relmse_one_run": scene.relmse_one_run,
            "relmse_mean": scene.relmse_mean,
            "seeds": scene.seeds,
        }},
    });
    std::fs::write(&path, serde_json::to_vec(&v1).unwrap()).unwrap();
    let read = NoiseReport::read(&path).unwrap().unwrap();
    assert_eq!(read.scenes.len(), 1);
    assert_eq!(read.scenes[id], *scene);

    // References of other settings in the same directory are refused, naming the file.
    let mut other = both.clone();
    other.reference_passes += 1;
    std::fs::write(&path, serde_json::to_vec(&other).unwrap()).unwrap();
    let o = options(&manifest, 2);
    let err = average_references(&dir, &manifest, &renderer, &o, |_, _, _| {}, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("noise.json") && err.contains("passes"),
        "{err}"
    );
    // A file that is not a report at all is an error too, not silently replaced.
    std::fs::write(&path, b"{\"nope\": 1}").unwrap();
    let err = average_references(&dir, &manifest, &renderer, &o, |_, _, _| {}, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("not a noise report"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
