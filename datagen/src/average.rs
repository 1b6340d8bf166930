//! Averaged references (`datagen average-references`): more runs of a dataset's reference
//! settings with other seeds, their per-pixel mean, and the noise a single run carries.
//!
//! A dataset's reference is one long SPPM run, so it is noisy itself; relMSE against it adds
//! that noise to every method alike and pulls every ratio towards 1 (docs/evaluation.md). The
//! mean of N runs keeps 1/N of it, and the spread between the runs measures it.

use crate::fsutil::{remove_if_present, write_atomic};
use crate::jobs::{run_settings, RunSpec, SampleRenderer, StateSpec};
use crate::manifest::{to_json, Manifest, SceneEntry};
use crate::plan::Split;
use anyhow::{bail, Context, Result};
use bundle::{read_rgb_exr_image, scene_reference_path, write_rgb_exr_image, Image};
use renderer::integrators::sppm::RadiusSchedule;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

/// Directory inside the dataset holding the extra runs. It is shared by every average, so a
/// later call with more runs reuses the runs already rendered.
pub const RUNS_DIR: &str = "reference-runs";

/// Name of the noise report written next to the averaged references.
pub const NOISE_FILE: &str = "noise.json";

/// Seed of extra run `run` (1, 2, …) of a scene: steps of a prime from the reference's own seed
/// (run 0), wrapped to 32 bits like every render seed of the dataset.
pub fn run_seed(reference_seed: u64, run: usize) -> u64 {
    (reference_seed + 7919 * run as u64) % (1 << 32)
}

/// What to average.
#[derive(Debug, Clone, PartialEq)]
pub struct AverageOptions {
    /// Scenes of this split.
    pub split: Split,
    /// Runs per scene, the dataset's own reference included (≥ 2).
    pub runs: usize,
    /// Output directory inside the dataset, e.g. `references-avg8`.
    pub out: PathBuf,
    /// Worker threads per render (0 = all cores; results do not depend on it).
    pub threads: usize,
    /// Seconds of rendering between saves of a run's state (a killed run resumes from it).
    pub state_interval: f64,
}

/// The noise of one scene's references, relative to the noise-free limit of the same
/// estimator: the relMSE summand (docs/method.md §5.6) Σ s²/(ref² + 0.01) / (3·pixels), with s² the unbiased
/// per-sample variance across the runs. Variance only: the estimator's bias is not in it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneNoise {
    /// Split the scene belongs to.
    pub split: Split,
    /// Runs averaged.
    pub runs: usize,
    /// relMSE one run carries.
    pub relmse_one_run: f64,
    /// relMSE the mean carries (one run's ÷ runs).
    pub relmse_mean: f64,
    /// Seeds of the runs, the dataset's reference first.
    pub seeds: Vec<u64>,
}

/// Contents of `<out>/noise.json`: every scene averaged into `<out>` so far, of any split
/// (one call averages one split; later calls for other splits add their scenes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseReport {
    /// Passes of every run.
    pub reference_passes: u32,
    /// Photons per pass of every run.
    pub reference_photons: u64,
    /// Per scene id.
    pub scenes: BTreeMap<String, SceneNoise>,
}

/// `noise.json` as the first version wrote it: one split for the whole file.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NoiseReportV1 {
    split: Split,
    reference_passes: u32,
    reference_photons: u64,
    scenes: BTreeMap<String, SceneNoiseV1>,
}

/// A scene of [`NoiseReportV1`].
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneNoiseV1 {
    runs: usize,
    relmse_one_run: f64,
    relmse_mean: f64,
    seeds: Vec<u64>,
}

impl NoiseReport {
    /// Reads a report (either version); `None` when `path` does not exist.
    pub fn read(path: &Path) -> Result<Option<Self>> {
        let bytes = match std::fs::read(path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
        };
        if let Ok(v1) = serde_json::from_slice::<NoiseReportV1>(&bytes) {
            let scenes = v1
                .scenes
                .into_iter()
                .map(|(id, s)| {
                    let noise = SceneNoise {
                        split: v1.split,
                        runs: s.runs,
                        relmse_one_run: s.relmse_one_run,
                        relmse_mean: s.relmse_mean,
                        seeds: s.seeds,
                    };
                    (id, noise)
                })
                .collect();
            return Ok(Some(NoiseReport {
                reference_passes: v1.reference_passes,
                reference_photons: v1.reference_photons,
                scenes,
            }));
        }
        serde_json::from_slice(&bytes)
            .map(Some)
            .with_context(|| format!("{}: not a noise report", path.display()))
    }
}

/// The lines `datagen average-references` prints after averaging `split` into a folder whose
/// report (its `noise.json`, at `noise_path`) is `report`: the noise of each scene this call
/// averaged, and a note on the scenes of other splits the report keeps from earlier calls.
pub fn summary_lines(report: &NoiseReport, split: Split, noise_path: &Path) -> Vec<String> {
    let mut lines: Vec<String> = report
        .scenes
        .iter()
        .filter(|(_, n)| n.split == split)
        .map(|(id, n)| {
            format!(
                "{id}: noise of one run {:.3e} relMSE, of the mean of {} {:.3e}",
                n.relmse_one_run, n.runs, n.relmse_mean
            )
        })
        .collect();
    let earlier = report.scenes.values().filter(|n| n.split != split).count();
    if earlier > 0 {
        lines.push(format!(
            "({earlier} scene(s) of other splits, averaged by earlier calls, are kept in {})",
            noise_path.display()
        ));
    }
    lines
}

/// The run settings of an extra run of `scene`'s reference (depth, the SPPM radius schedule,
/// the scene's size and `-D` overrides) with its own `seed`, `photons` per pass and `passes`,
/// keeping its state in `state`.
pub fn extra_reference_run(
    manifest: &Manifest,
    scene: &SceneEntry,
    seed: u64,
    photons: u64,
    passes: u32,
    state: StateSpec,
    threads: usize,
) -> RunSpec {
    // The `-D` overrides of a scene the user brought (the plan numbers the scenes by id).
    let plan = crate::plan::Plan::new(&manifest.config);
    let defines = plan
        .scenes
        .iter()
        .find(|s| s.id == scene.id)
        .and_then(|s| manifest.config.external_scene(s.index))
        .map(|e| e.define_pairs())
        .unwrap_or_default();
    RunSpec {
        sppm: run_settings(
            &scene.id,
            seed,
            photons,
            manifest.config.render.max_depth,
            // References are SPPM's whatever the inputs' schedule.
            RadiusSchedule::Sppm,
            threads,
        ),
        passes: vec![passes],
        state: Some(state),
        defines,
        size: scene.size_in(manifest),
    }
}

/// Where extra run `seed` of `scene` lives (relative to the dataset root): the settings are in
/// the name, so runs of another reference configuration are never mixed in.
fn run_path(scene: &SceneEntry, seed: u64) -> PathBuf {
    Path::new(RUNS_DIR).join(format!(
        "{}_p{}_n{}_s{seed}.exr",
        scene.id, scene.reference_passes, scene.reference_photons
    ))
}

/// Checks that `out` names a new directory inside the dataset, not the dataset's own
/// references or runs (which the averages must never overwrite).
fn check_out(out: &Path) -> Result<()> {
    let plain =
        !out.as_os_str().is_empty() && out.components().all(|c| matches!(c, Component::Normal(_)));
    if !plain {
        bail!(
            "--out {}: give a directory name inside the dataset (no `..`, not absolute)",
            out.display()
        );
    }
    if out == Path::new("references") || out == Path::new(RUNS_DIR) {
        bail!(
            "--out {}: that directory belongs to the dataset; choose another name",
            out.display()
        );
    }
    Ok(())
}

/// `img` (read from or written to `path`) if it has the dataset's size.
fn check_size(img: Image, path: &Path, width: u32, height: u32) -> Result<Image> {
    if (img.width, img.height) != (width as usize, height as usize) {
        bail!(
            "{}: {}x{}, the dataset is {width}x{height}",
            path.display(),
            img.width,
            img.height
        );
    }
    Ok(img)
}

/// Reads an RGB image and checks its size.
fn read_checked(path: &Path, width: u32, height: u32) -> Result<Image> {
    // The bundle crate's errors name the file already.
    check_size(read_rgb_exr_image(path)?, path, width, height)
}

/// Per-sample mean of `images` (all the same shape) and the noise one of them carries.
pub fn mean_and_noise(images: &[Image]) -> (Image, f64) {
    let first = &images[0];
    let n = images.len() as f64;
    let mut mean = Image::new(first.width, first.height, first.channels);
    let mut var = vec![0.0f64; first.data.len()];
    for (i, (m, v)) in mean.data.iter_mut().zip(&mut var).enumerate() {
        let mu = images.iter().map(|img| f64::from(img.data[i])).sum::<f64>() / n;
        *v = images
            .iter()
            .map(|img| (f64::from(img.data[i]) - mu).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        *m = mu as f32;
    }
    // relMSE weight (docs/method.md §5.6) of a pixel: 1 / ((mean over RGB of the reference)² + 0.01).
    let c = first.channels;
    let mut sum = 0.0;
    for (px, v) in mean.data.chunks(c).zip(var.chunks(c)) {
        let grey = px.iter().map(|&x| f64::from(x)).sum::<f64>() / c as f64;
        sum += v.iter().sum::<f64>() / (grey * grey + 0.01);
    }
    (mean, sum / var.len() as f64)
}

/// Averages the references of every scene of `options.split` of the dataset at `root` (whose
/// manifest is `manifest`): renders the missing extra runs (kept in [`RUNS_DIR`]), writes `<out>/<scene id>.exr` (the mean) and `<out>/noise.json`,
/// all atomically. `on_run(scene id, run, rendered)` reports each extra run (rendered now or
/// reused); `on_pass` the passes of a run being rendered.
pub fn average_references(
    root: &Path,
    manifest: &Manifest,
    renderer: &dyn SampleRenderer,
    options: &AverageOptions,
    mut on_run: impl FnMut(&str, usize, bool),
    on_pass: &mut (dyn FnMut(u32) + Send),
) -> Result<NoiseReport> {
    if options.runs < 2 {
        bail!("--runs must be at least 2 (the spread between runs is the noise estimate)");
    }
    check_out(&options.out)?;
    let scenes: Vec<&SceneEntry> = manifest
        .scenes
        .iter()
        .filter(|s| s.split == options.split)
        .collect();
    let Some(first) = scenes.first() else {
        bail!(
            "{}: no scene in split {:?}",
            root.join("manifest.json").display(),
            options.split
        );
    };
    if let Some(s) = scenes.iter().find(|s| s.reference_runs.is_some()) {
        bail!(
            "{}: scene {} has a reference averaged from {} runs already, its noise in the \
             manifest (`reference_noise`); average-references is for datasets of one-run \
             references",
            root.join("manifest.json").display(),
            s.id,
            s.reference_runs.unwrap_or(1)
        );
    }
    let out_dir = root.join(&options.out);
    std::fs::create_dir_all(root.join(RUNS_DIR))
        .with_context(|| format!("creating {}", root.join(RUNS_DIR).display()))?;
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    // Scenes averaged into `out` by earlier calls (other splits) stay in the report; mixing
    // runs of other reference settings into one directory is refused.
    let noise_path = out_dir.join(NOISE_FILE);
    let mut report = match NoiseReport::read(&noise_path)? {
        Some(r)
            if (r.reference_passes, r.reference_photons)
                != (first.reference_passes, first.reference_photons) =>
        {
            bail!(
                "{}: holds references of {} passes x {} photons, this dataset's are {} x {}; \
                 choose another --out",
                noise_path.display(),
                r.reference_passes,
                r.reference_photons,
                first.reference_passes,
                first.reference_photons
            )
        }
        Some(r) => {
            // Means of another run count in one folder would be read as one set of references
            // of uneven noise: refused, not silently replaced scene by scene.
            let other: std::collections::BTreeSet<usize> = r
                .scenes
                .values()
                .map(|n| n.runs)
                .filter(|&n| n != options.runs)
                .collect();
            if !other.is_empty() {
                let found: Vec<String> = other.iter().map(usize::to_string).collect();
                let named = PathBuf::from(format!("references-avg{}", options.runs));
                let example = if options.out == named {
                    String::new()
                } else {
                    format!(" (e.g. {})", named.display())
                };
                bail!(
                    "{}: holds averages of {} runs (see its {NOISE_FILE}), this call asks for \
                     {}; choose another --out{example}",
                    out_dir.display(),
                    found.join(" and "),
                    options.runs,
                )
            }
            r
        }
        None => NoiseReport {
            reference_passes: first.reference_passes,
            reference_photons: first.reference_photons,
            scenes: BTreeMap::new(),
        },
    };
    for scene in scenes {
        let (width, height) = scene.size_in(manifest);
        let mut seeds = vec![scene.reference_seed];
        let mut images = vec![read_checked(&root.join(&scene.reference), width, height)?];
        for run in 1..options.runs {
            let seed = run_seed(scene.reference_seed, run);
            let path = root.join(run_path(scene, seed));
            let rendered = !path.exists();
            let image = if rendered {
                // A killed run continues from its state; removed once the image is written.
                let state = StateSpec {
                    path: path.with_extension("state"),
                    interval: options.state_interval,
                };
                let spec = extra_reference_run(
                    manifest,
                    scene,
                    seed,
                    scene.reference_photons,
                    scene.reference_passes,
                    state,
                    options.threads,
                );
                let image = renderer.reference(&root.join(&scene.xml), &spec, on_pass)?;
                // The run is averaged as rendered (EXR float32 keeps it exactly), not read back.
                let image = check_size(image, &path, width, height)?;
                write_rgb_exr_image(&path, &image)
                    .with_context(|| format!("writing {}", path.display()))?;
                if let Some(state) = &spec.state {
                    remove_if_present(&state.path)?;
                }
                image
            } else {
                read_checked(&path, width, height)?
            };
            images.push(image);
            seeds.push(seed);
            on_run(&scene.id, run, rendered);
        }
        let (mean, one_run) = mean_and_noise(&images);
        let path = scene_reference_path(&out_dir, &scene.id);
        write_rgb_exr_image(&path, &mean).with_context(|| format!("writing {}", path.display()))?;
        report.scenes.insert(
            scene.id.clone(),
            SceneNoise {
                split: scene.split,
                runs: options.runs,
                relmse_one_run: one_run,
                relmse_mean: one_run / options.runs as f64,
                seeds,
            },
        );
    }
    write_atomic(&noise_path, &to_json(&report))
        .with_context(|| format!("writing {}", noise_path.display()))?;
    Ok(report)
}
