//! Evaluation (docs/method.md §8): standard SPPM against multi-level SPPM + inference on held-out
//! scenes, at equal wall time (inference counted), at equal passes, and per pass (overhead);
//! writes results.json, convergence plots, comparison images and one self-contained HTML page.

pub mod ablation;
pub mod compare;
pub mod config;
pub mod html;
pub mod images;
pub mod peers;
pub mod plot;
pub mod resume;
pub mod runs;
pub mod scene;
pub mod schedules;
pub mod summary;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use model::ModelConfig;
use serde::{Deserialize, Serialize};

use self::ablation::{Ablation, AblationModel};
use self::compare::{geometric_mean, median};
use self::config::{EvalConfig, EvalScene};
use self::images::{error_panel, error_scale, relative_error_map, row_png, srgb_panel};
use self::scene::{evaluate_scene, SceneEval};
use model::model_dir::TrainedModel;
use renderer::integrators::sppm::{SppmSettings, DEFAULT_MAX_DEPTH, DEFAULT_PHOTON_FOCUS};

/// How the comparison is made, stored in results.json and shown on the page.
pub const METHOD_NOTE: &str = "Equal time: ours is charged render seconds (multi-level SPPM up \
to the checkpoint) plus inference seconds (bundle assembly, feature packing, network and \
combination). Standard SPPM (single level) runs once with dense checkpoints (every configured \
pass count plus sixteen per doubling) until it has both the largest configured pass count and a \
render time past the slowest ours total; its relMSE at ours' total time is interpolated linearly in log(time)–log(relMSE) between the two \
checkpoints around it. Render times exclude the evaluator's own callback work (bundle assembly \
and error computation at checkpoints), so the dense checkpoints do not slow the baseline. \
Overhead = multi-level render seconds / single-level render seconds at the same pass count − 1. \
Light samples per visible point: ours' runs take emitter_samples (absent: two, stratified), the \
standard run standard_emitter_samples (absent: one, the paper's standard SPPM). Both SPPM runs \
take the same eye sampler (sampler; absent: independent).";

/// The outcome of one scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SceneResult {
    /// Scene name.
    pub name: String,
    /// Scene XML.
    pub xml: PathBuf,
    /// Reference EXR.
    pub reference: PathBuf,
    /// The measurements, or `None` if the scene failed.
    pub eval: Option<SceneEval>,
    /// Why the scene failed.
    pub error: Option<String>,
    /// Convergence plot PNG, relative to the output directory.
    pub plot: Option<String>,
    /// Comparison image PNG (standard | ours | reference | error maps), relative.
    pub comparison: Option<String>,
    /// Input levels PNG (ỹ, z̃1..z̃4 at the last checkpoint), relative.
    pub inputs: Option<String>,
    /// Passes and seconds of the standard image in the comparison.
    pub comparison_standard: Option<compare::CurvePoint>,
    /// Colour-scale maximum of the error maps.
    pub error_scale: Option<f32>,
    /// Taken from an earlier run with the same settings (`--resume`): the timings are that
    /// run's.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub reused: bool,
    /// The reference's own noise against the errors measured with it, where the dataset
    /// measured that noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_noise: Option<ReferenceNoise>,
}

/// A reference's own noise next to the smallest error measured against it. A noisy reference
/// adds its noise to every relMSE measured with it, which pulls every ratio toward 1: where the
/// noise is more than [`ReferenceNoise::LIMIT`] of the smallest error, differences of that size
/// are not measured (the dataset standard is a tenth, docs/datagen.md).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceNoise {
    /// The reference's relMSE noise as the dataset recorded it.
    pub noise: f64,
    /// The smallest relMSE measured against it: any input level, ours, standard SPPM at equal
    /// time or a peer, at any checkpoint.
    pub smallest_error: f64,
}

impl ReferenceNoise {
    /// The largest noise, as a fraction of the smallest error, that measures differences.
    pub const LIMIT: f64 = 0.1;

    /// From the recorded noise and the measurements; `None` without either.
    pub fn measure(noise: Option<f64>, eval: &SceneEval) -> Option<Self> {
        let noise = noise?;
        let smallest = eval
            .checkpoints
            .iter()
            .flat_map(|c| {
                let peers = [c.sppm_oidn.as_ref(), c.pt_oidn.as_ref()]
                    .into_iter()
                    .flatten()
                    .map(|p| p.relmse);
                c.level_relmse
                    .iter()
                    .copied()
                    .chain([c.ours_relmse, c.standard_equal_time.relmse])
                    .chain(c.variant_relmse.iter().copied())
                    .chain(peers)
            })
            .filter(|e| e.is_finite())
            .fold(f64::INFINITY, f64::min);
        smallest.is_finite().then_some(Self {
            noise,
            smallest_error: smallest,
        })
    }

    /// Noise ÷ the smallest error.
    pub fn fraction(&self) -> f64 {
        self.noise / self.smallest_error
    }

    /// The largest noise, as a fraction of either error, for which [`Self::corrected_ratio`]
    /// is reported: beyond it the difference of two noisy estimates is mostly noise.
    pub const CORRECTABLE: f64 = 0.5;

    /// `ours / other` with the reference's noise taken out of both errors: (ours − n) / (other −
    /// n). Against a reference with independent noise of relMSE n, each measured relMSE is the
    /// error against the true image plus n in expectation, which pulls every ratio toward 1;
    /// this undoes it. Which of the two is smaller does not change. `None` where the noise is
    /// unknown (NaN) or more than [`Self::CORRECTABLE`] of either error.
    pub fn corrected_ratio(&self, ours: f64, other: f64) -> Option<f64> {
        let n = self.noise;
        let ok = n.is_finite()
            && n >= 0.0
            && ours.is_finite()
            && other.is_finite()
            && n <= Self::CORRECTABLE * ours.min(other);
        ok.then(|| (ours - n) / (other - n))
    }

    /// Whether the reference is too noisy for the smallest differences measured with it.
    pub fn too_noisy(&self) -> bool {
        // NaN (an unrecorded or broken noise) counts as too noisy.
        self.fraction().is_nan() || self.fraction() > Self::LIMIT
    }

    /// The warning a report shows for a too noisy reference.
    pub fn warning(&self) -> String {
        format!(
            "the reference's own noise ({:.2e}) is {:.2} x the smallest error measured against \
             it ({:.2e}), more than {}: it adds to every error here and pulls the ratios toward \
             1 (`datagen evaluation-references` with a smaller --target converges it further)",
            self.noise,
            self.fraction(),
            self.smallest_error,
            Self::LIMIT
        )
    }
}

impl SceneResult {
    /// A scene not evaluated yet: its paths, no measurements, no error, no pictures.
    pub fn new(name: String, xml: PathBuf, reference: PathBuf) -> Self {
        Self {
            name,
            xml,
            reference,
            eval: None,
            error: None,
            plot: None,
            comparison: None,
            inputs: None,
            comparison_standard: None,
            error_scale: None,
            reused: false,
            reference_noise: None,
        }
    }
}

/// Aggregates over the scenes at the largest pass count.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// Scenes in the config.
    pub scenes: usize,
    /// Scenes that failed.
    pub failed: usize,
    /// The pass count the summary is taken at (the largest).
    pub passes: u32,
    /// Scenes where ours beats standard SPPM at equal time.
    pub ours_better_equal_time: usize,
    /// Median over scenes of ours / standard at equal time.
    pub median_ratio_equal_time: Option<f64>,
    /// Geometric mean over scenes of ours / standard at equal time.
    pub geomean_ratio_equal_time: Option<f64>,
    /// Median over scenes and pass counts of the multi-level overhead per pass.
    pub median_overhead: Option<f64>,
    /// Scenes where ours beats the best input level.
    pub ours_better_than_best_input: usize,
    /// Ours against each peer that was run (`peers`), at equal time.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub peers: Vec<PeerSummary>,
    /// With noisy references (training targets): the ratios with the references' noise taken
    /// out ([`ReferenceNoise::corrected_ratio`]), over the scenes where that is measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise_corrected: Option<NoiseCorrected>,
}

/// Medians of ratios with the reference's noise taken out of both errors, over the scenes whose
/// recorded noise is at most [`ReferenceNoise::CORRECTABLE`] of both.
#[derive(Clone, Debug, Serialize)]
pub struct NoiseCorrected {
    /// Scenes with a corrected ratio against standard SPPM.
    pub scenes: usize,
    /// Median over them of ours / standard at equal time, corrected.
    pub median_ratio_equal_time: Option<f64>,
    /// Per peer: scenes with a corrected ratio and their median.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub peers: Vec<PeerSummary>,
}

/// Ours against one peer over the scenes, at the summary's pass count.
#[derive(Clone, Debug, Serialize)]
pub struct PeerSummary {
    /// The peer.
    pub peer: peers::Peer,
    /// Scenes with a result of this peer.
    pub scenes: usize,
    /// Scenes where ours beats it.
    pub ours_better: usize,
    /// Median over scenes of ours / peer.
    pub median_ratio: Option<f64>,
}

impl PeerSummary {
    /// The summary of ours ÷ `peer` over the scenes' `ratios`; `None` without any.
    fn from_ratios(peer: peers::Peer, ratios: &[f64]) -> Option<Self> {
        (!ratios.is_empty()).then(|| PeerSummary {
            peer,
            scenes: ratios.len(),
            ours_better: ratios.iter().filter(|r| **r < 1.0).count(),
            median_ratio: median(ratios),
        })
    }
}

/// Everything written to results.json.
#[derive(Clone, Debug, Serialize)]
pub struct EvalResults {
    /// The config as run.
    pub config: EvalConfig,
    /// The model's architecture.
    pub model: ModelConfig,
    /// How the comparison is made.
    pub method: String,
    /// Per-scene results, in config order, failures included.
    pub scenes: Vec<SceneResult>,
    /// Aggregates.
    pub summary: Summary,
    /// The dual-vs-multi ablation (paper Table 1), or why it was not run.
    pub ablation_dual_vs_multi: Ablation,
}

/// Runs the evaluation described by `config`, writing everything into `config.output`.
/// Scene failures are recorded (and the run goes on); configuration errors stop it early.
/// Every finished scene is also saved on its own (`<output>/scenes/<name>.json`); with
/// `resume`, a scene saved by a run with the same settings, model, scene and reference is
/// taken from there instead of being evaluated again (a killed evaluation continues).
pub fn run(config: &EvalConfig, resume: bool) -> Result<EvalResults> {
    let scenes = config.resolve_scenes()?;
    let backend = model::backend::Backend::parse(&config.backend).map_err(anyhow::Error::msg)?;
    let device = backend.device().map_err(anyhow::Error::msg)?;
    if let Some(note) = backend.adapter_note(&device) {
        eprintln!("{note}");
    }
    let model = TrainedModel::open(&config.model, &device)
        .with_context(|| format!("loading model {}", config.model.display()))?;
    let variants = config
        .ablation
        .iter()
        .flat_map(|a| &a.dual_models)
        .map(|dir| {
            TrainedModel::open(dir, &device)
                .with_context(|| format!("loading ablation model {}", dir.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    std::fs::create_dir_all(&config.output)
        .with_context(|| format!("output = {}: creating it", config.output.display()))?;
    let passes = config.pass_counts();
    let denoiser = peers::Denoiser {
        python: config.oidn_python.clone(),
        script: config.oidn_script.clone(),
        // The script's own default: the median of three calls after the warm-up.
        repeats: 3,
    };
    if !config.peers.is_empty() {
        let version = denoiser.check()?;
        eprintln!(
            "peers: {} (pyoidn {version})",
            config
                .peers
                .iter()
                .map(|p| p.name())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let peer_setup = scene::PeerSetup {
        peers: &config.peers,
        denoiser: &denoiser,
        max_depth: config.max_depth,
        standard_emitter_samples: config.standard_emitter_samples.unwrap_or(1),
    };
    // The settings and model files, hashed once for every scene's saved result.
    let run_fingerprint = resume::run_fingerprint(config)?;
    let mut results = Vec::new();
    for (i, s) in scenes.iter().enumerate() {
        eprintln!("[{}/{}] {}", i + 1, scenes.len(), s.name);
        let settings = SppmSettings {
            photons_per_pass: config.photons_per_pass,
            seed: config.seed,
            threads: config.threads,
            max_depth: config.max_depth.unwrap_or(DEFAULT_MAX_DEPTH),
            emitter_samples: config.emitter_samples,
            photon_focus: config.photon_focus.unwrap_or(DEFAULT_PHOTON_FOCUS),
            sharp_level: config.sharp_level,
            sampler: config.sampler.unwrap_or_default(),
            schedule: config.schedule,
            scene_name: s.name.clone(),
            ..SppmSettings::default()
        };
        let inference = infer::Inference {
            tile: config.tile,
            engine: config.engine.unwrap_or(infer::Engine::default_for(backend)),
            device: &device,
        };
        // A scene whose files cannot be read has no fingerprint: it is evaluated (and its
        // failure recorded in the report) but neither reused nor saved.
        let fingerprint = resume::scene_fingerprint(&run_fingerprint, s).ok();
        let saved = resume::result_path(&config.output, &file_stem(&s.name));
        let reused = match (&fingerprint, resume) {
            (Some(f), true) => match resume::load(&saved, f, &config.output)? {
                Ok(r) => Some(r),
                Err(why) => {
                    eprintln!("  evaluating ({why})");
                    None
                }
            },
            _ => None,
        };
        let r = match reused {
            Some(mut r) => {
                eprintln!("  taken from {}", saved.display());
                r.reused = true;
                r
            }
            None => {
                let r = evaluate_one(
                    config,
                    s,
                    &settings,
                    &passes,
                    &model,
                    &variants,
                    &inference,
                    &peer_setup,
                );
                if let Some(f) = &fingerprint {
                    resume::save(&saved, f, &r)?;
                }
                r
            }
        };
        match &r.error {
            Some(e) => eprintln!("  FAILED: {e}"),
            None => {
                if let Some(c) = r.eval.as_ref().and_then(|e| e.checkpoints.last()) {
                    eprintln!(
                        "  {} passes: ours {:.3e} ({:.2} s) vs standard {:.3e} at equal time: ratio {:.3}",
                        c.passes,
                        c.ours_relmse,
                        c.total_seconds,
                        c.standard_equal_time.relmse,
                        c.ratio_equal_time
                    );
                    for peer in &config.peers {
                        if let Some(p) = c.peer(*peer) {
                            eprintln!(
                                "  {}: {:.3e} ({} samples, {:.2} s + {:.2} s): ratio {:.3}",
                                peer.name(),
                                p.relmse,
                                p.samples,
                                p.render_seconds,
                                p.denoise_seconds,
                                p.ratio
                            );
                        }
                    }
                    if let Some(n) = r.reference_noise.as_ref().filter(|n| n.too_noisy()) {
                        eprintln!("  warning: {}", n.warning());
                        let mut line = String::new();
                        let standard = c.standard_equal_time.relmse;
                        if let Some(x) = n.corrected_ratio(c.ours_relmse, standard) {
                            line += &format!(" standard {x:.3}");
                        }
                        for peer in &config.peers {
                            let corrected = c
                                .peer(*peer)
                                .and_then(|p| n.corrected_ratio(c.ours_relmse, p.relmse));
                            if let Some(x) = corrected {
                                line += &format!(", {} {x:.3}", peer.name());
                            }
                        }
                        if !line.is_empty() {
                            eprintln!(
                                "  ratios with the reference's noise taken out:{}",
                                line.trim_start_matches(',')
                            );
                        }
                    }
                    for (v, e) in variants.iter().zip(&c.variant_relmse) {
                        eprintln!(
                            "  ablation {}: {e:.3e} (ours / it = {:.3})",
                            ablation::label(&v.config.levels),
                            c.ours_relmse / e
                        );
                    }
                }
            }
        }
        results.push(r);
    }
    let last_passes = *passes.last().expect("validated non-empty");
    let summary = summarise(&results, last_passes);
    let ablation = if variants.is_empty() {
        ablation::not_run(last_passes)
    } else {
        ablation::build(
            &results,
            last_passes,
            AblationModel::new(config.model.clone(), &model.config),
            variants
                .iter()
                .map(|v| AblationModel::new(v.dir.clone(), &v.config))
                .collect(),
        )
    };
    let out = EvalResults {
        config: config.clone(),
        model: model.config.clone(),
        method: METHOD_NOTE.into(),
        scenes: results,
        summary,
        ablation_dual_vs_multi: ablation,
    };
    let json = serde_json::to_string_pretty(&out)?;
    images::write_atomic(&config.output.join("results.json"), json.as_bytes())?;
    let page = html::page(&out, &config.output)?;
    images::write_atomic(&config.output.join("index.html"), page.as_bytes())?;
    Ok(out)
}

/// File-name-safe version of a scene name.
fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[allow(clippy::too_many_arguments)]
fn evaluate_one(
    config: &EvalConfig,
    s: &EvalScene,
    settings: &SppmSettings,
    passes: &[u32],
    model: &TrainedModel,
    variants: &[TrainedModel],
    inference: &infer::Inference,
    peers: &scene::PeerSetup,
) -> SceneResult {
    let mut r = SceneResult::new(s.name.clone(), s.xml.clone(), s.reference.clone());
    let outcome = (|| -> Result<()> {
        let (eval, imgs) = evaluate_scene(s, settings, passes, model, variants, inference, peers)?;
        let stem = file_stem(&s.name);
        let plot = format!("{stem}_convergence.png");
        plot::write_convergence_plot(
            &config.output.join(&plot),
            &format!("{} — relMSE (log-log)", s.name),
            &eval,
            &settings.schedule.name().to_uppercase(),
        )?;
        let pixels = eval.width * eval.height;
        let err_std = relative_error_map(&imgs.standard, &imgs.reference, pixels);
        let err_ours = relative_error_map(&imgs.ours, &imgs.reference, pixels);
        let err_peers: Vec<Vec<f32>> = imgs
            .peers
            .iter()
            .map(|(_, image)| relative_error_map(image, &imgs.reference, pixels))
            .collect();
        let mut all_errors: Vec<&[f32]> = vec![&err_std, &err_ours];
        all_errors.extend(err_peers.iter().map(Vec::as_slice));
        let scale = error_scale(&all_errors);
        // standard | ours | reference | error maps, then each peer's image and error map.
        let mut panels = vec![
            srgb_panel(&imgs.standard, pixels),
            srgb_panel(&imgs.ours, pixels),
            srgb_panel(&imgs.reference, pixels),
            error_panel(&err_std, scale),
            error_panel(&err_ours, scale),
        ];
        for ((_, image), err) in imgs.peers.iter().zip(&err_peers) {
            panels.push(srgb_panel(image, pixels));
            panels.push(error_panel(err, scale));
        }
        let row = row_png(&panels, eval.width, eval.height)?;
        let comparison = format!("{stem}_compare.png");
        images::write_atomic(&config.output.join(&comparison), &row)?;
        let levels: Vec<images::Panel> =
            imgs.levels.iter().map(|l| srgb_panel(l, pixels)).collect();
        let inputs = format!("{stem}_inputs.png");
        images::write_atomic(
            &config.output.join(&inputs),
            &row_png(&levels, eval.width, eval.height)?,
        )?;
        r.plot = Some(plot);
        r.comparison = Some(comparison);
        r.inputs = Some(inputs);
        r.comparison_standard = Some(imgs.standard_at);
        r.error_scale = Some(scale);
        r.reference_noise = ReferenceNoise::measure(s.reference_noise, &eval);
        r.eval = Some(eval);
        Ok(())
    })();
    if let Err(e) = outcome {
        r.error = Some(format!("{e:#}"));
    }
    r
}

/// Aggregates at the largest pass count.
pub fn summarise(results: &[SceneResult], passes: u32) -> Summary {
    fn at_passes(r: &SceneResult, passes: u32) -> Option<&scene::Checkpoint> {
        r.eval
            .as_ref()?
            .checkpoints
            .iter()
            .find(|c| c.passes == passes)
    }
    let last: Vec<&scene::Checkpoint> = results
        .iter()
        .filter_map(|r| at_passes(r, passes))
        .collect();
    // Each scene's checkpoint with its reference's noise, where the dataset recorded one.
    let noisy: Vec<(&scene::Checkpoint, &ReferenceNoise)> = results
        .iter()
        .filter_map(|r| Some((at_passes(r, passes)?, r.reference_noise.as_ref()?)))
        .collect();
    let ratios: Vec<f64> = last.iter().map(|c| c.ratio_equal_time).collect();
    let overheads: Vec<f64> = results
        .iter()
        .filter_map(|r| r.eval.as_ref())
        .flat_map(|e| e.checkpoints.iter().filter_map(|c| c.overhead))
        .collect();
    Summary {
        scenes: results.len(),
        failed: results.iter().filter(|r| r.error.is_some()).count(),
        passes,
        ours_better_equal_time: ratios.iter().filter(|r| **r < 1.0).count(),
        median_ratio_equal_time: median(&ratios),
        geomean_ratio_equal_time: geometric_mean(&ratios),
        median_overhead: median(&overheads),
        ours_better_than_best_input: last
            .iter()
            .filter(|c| {
                c.ours_relmse < c.level_relmse.iter().copied().fold(f64::INFINITY, f64::min)
            })
            .count(),
        peers: [peers::Peer::SppmOidn, peers::Peer::PtOidn]
            .into_iter()
            .filter_map(|peer| {
                let ratios: Vec<f64> = last
                    .iter()
                    .filter_map(|c| c.peer(peer).map(|p| p.ratio))
                    .collect();
                PeerSummary::from_ratios(peer, &ratios)
            })
            .collect(),
        noise_corrected: noise_corrected(&noisy),
    }
}

/// The summary's ratios with the references' noise taken out; `None` when no scene has one.
fn noise_corrected(noisy: &[(&scene::Checkpoint, &ReferenceNoise)]) -> Option<NoiseCorrected> {
    let standard: Vec<f64> = noisy
        .iter()
        .filter_map(|(c, n)| n.corrected_ratio(c.ours_relmse, c.standard_equal_time.relmse))
        .collect();
    let peers: Vec<PeerSummary> = [peers::Peer::SppmOidn, peers::Peer::PtOidn]
        .into_iter()
        .filter_map(|peer| {
            let ratios: Vec<f64> = noisy
                .iter()
                .filter_map(|(c, n)| n.corrected_ratio(c.ours_relmse, c.peer(peer)?.relmse))
                .collect();
            PeerSummary::from_ratios(peer, &ratios)
        })
        .collect();
    (!standard.is_empty() || !peers.is_empty()).then(|| NoiseCorrected {
        scenes: standard.len(),
        median_ratio_equal_time: median(&standard),
        peers,
    })
}

/// Reads a file written next to the page, for embedding.
pub(crate) fn read_output_file(dir: &Path, name: &str) -> Result<Vec<u8>> {
    let p = dir.join(name);
    std::fs::read(&p).with_context(|| format!("reading {}", p.display()))
}

#[cfg(test)]
mod reference_noise_tests {
    use super::*;
    use crate::peers::PeerResult;
    use crate::scene::fixtures::{checkpoint, scene};

    fn peer(relmse: f64) -> PeerResult {
        PeerResult {
            samples: 1,
            render_seconds: 1.0,
            render_budget_seconds: 1.0,
            denoise_seconds: 0.1,
            total_seconds: 1.1,
            relmse,
            ratio: 1.0,
        }
    }

    #[test]
    fn the_smallest_error_of_any_method_at_any_checkpoint_is_the_yardstick() {
        // Levels 1.0 .. 4.0 (smallest 0.5), standard 1.0, ours 0.3 then 0.2.
        let mut late = checkpoint(256, 0.2);
        late.sppm_oidn = Some(peer(0.04));
        let eval = scene("s", vec![checkpoint(64, 0.3), late]).eval.unwrap();
        let n = ReferenceNoise::measure(Some(0.005), &eval).unwrap();
        assert_eq!(n.smallest_error, 0.04);
        assert!((n.fraction() - 0.125).abs() < 1e-12);
        assert!(n.too_noisy());
        assert!(n.warning().contains("0.12 x"), "{}", n.warning());
        // A tenth exactly is converged enough; without the peer ours' 0.2 is the yardstick.
        let eval = scene("s", vec![checkpoint(64, 0.3), checkpoint(256, 0.2)])
            .eval
            .unwrap();
        let n = ReferenceNoise::measure(Some(0.02), &eval).unwrap();
        assert_eq!(n.smallest_error, 0.2);
        assert!(!n.too_noisy());
        assert!(ReferenceNoise::measure(Some(0.021), &eval)
            .unwrap()
            .too_noisy());
        // No recorded noise: nothing to say.
        assert_eq!(ReferenceNoise::measure(None, &eval), None);
        // A NaN noise is never taken for converged.
        assert!(ReferenceNoise::measure(Some(f64::NAN), &eval)
            .unwrap()
            .too_noisy());
    }

    #[test]
    fn the_corrected_ratio_takes_the_noise_out_of_both_errors() {
        let n = ReferenceNoise {
            noise: 0.01,
            smallest_error: 0.02,
        };
        // True errors 0.01 and 0.04 measured as 0.02 and 0.05: 0.4 pulled to 0.25.
        assert!((n.corrected_ratio(0.02, 0.05).unwrap() - 0.25).abs() < 1e-12);
        // The order of the two never changes.
        assert!(n.corrected_ratio(0.05, 0.02).unwrap() > 1.0);
        // Noise above half of either error: not measured.
        assert_eq!(n.corrected_ratio(0.019, 0.05), None);
        assert_eq!(n.corrected_ratio(0.05, 0.019), None);
        let nan = ReferenceNoise {
            noise: f64::NAN,
            smallest_error: 0.02,
        };
        assert_eq!(nan.corrected_ratio(0.02, 0.05), None);
    }

    #[test]
    fn the_summary_reports_corrected_medians_only_where_the_noise_allows() {
        use crate::peers::Peer;
        // Ours 0.02, standard 1.0 (the fixture), SPPM + OIDN 0.05; noise 0.01 on the first
        // scene, 0.2 (too much) on the second, none on the third.
        let mut results = Vec::new();
        for (name, noise) in [("a", Some(0.01)), ("b", Some(0.2)), ("c", None)] {
            let mut c = checkpoint(64, 0.02);
            c.sppm_oidn = Some(peer(0.05));
            let mut r = scene(name, vec![c]);
            r.reference_noise = ReferenceNoise::measure(noise, r.eval.as_ref().unwrap());
            results.push(r);
        }
        let s = summarise(&results, 64);
        let n = s.noise_corrected.expect("one scene has a usable noise");
        assert_eq!(n.scenes, 1);
        let standard = results[0].eval.as_ref().unwrap().checkpoints[0]
            .standard_equal_time
            .relmse;
        let expected = (0.02 - 0.01) / (standard - 0.01);
        assert!((n.median_ratio_equal_time.unwrap() - expected).abs() < 1e-12);
        assert_eq!(n.peers.len(), 1);
        assert_eq!(n.peers[0].peer, Peer::SppmOidn);
        assert_eq!(n.peers[0].scenes, 1);
        assert!((n.peers[0].median_ratio.unwrap() - 0.25).abs() < 1e-12);
        // Without any recorded noise there is nothing to report.
        for r in &mut results {
            r.reference_noise = None;
        }
        assert!(summarise(&results, 64).noise_corrected.is_none());
    }
}
