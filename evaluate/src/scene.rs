//! Evaluation of one scene: the multi-level run reconstructed at every checkpoint, the
//! standard SPPM run to (at least) the same wall time, and their comparison at equal time,
//! at equal passes, and per pass (overhead).

use std::time::Instant;

use anyhow::{Context, Result};
use bundle::read_rgb_exr_image;
use model::features::{pack, pack_with, planar_reference};
use model::metrics::relmse_planar;
use renderer::integrators::sppm::{SppmMode, StopCondition};
use serde::{Deserialize, Serialize};

use crate::compare::{dense_checkpoints, relmse_at_time, CurvePoint, Interpolated};
use crate::config::EvalScene;
use crate::peers::{path_trace_progressive, Denoiser, Guides, Peer, PeerResult};
use crate::runs::{load_scene, multi_level, run_timed};
use infer::report::LEVEL_NAMES;
use infer::{ErrorReport, Inference};
use model::model_dir::TrainedModel;
use renderer::integrators::path::PathTracer;
use renderer::integrators::sppm::SppmSettings;

/// The standard run's dense checkpoints go up to this multiple of the largest pass count.
const STANDARD_PASS_CAP_FACTOR: u32 = 64;

/// Results at one multi-level checkpoint.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Checkpoint {
    /// Passes of the multi-level run.
    pub passes: u32,
    /// Multi-level render seconds.
    pub render_seconds: f64,
    /// Reconstruction seconds: bundle assembly + feature packing + network + combination.
    pub inference_seconds: f64,
    /// render + inference: the time ours is charged at equal-time comparisons.
    pub total_seconds: f64,
    /// relMSE of the reconstruction.
    pub ours_relmse: f64,
    /// relMSE of the input levels ỹ, z̃1..z̃4.
    pub level_relmse: Vec<f64>,
    /// Name of the best input level.
    pub best_level: String,
    /// relMSE of each ablation variant (`[ablation] dual_models`, in that order) on the same
    /// bundle; their inference time is not charged to ours.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub variant_relmse: Vec<f64>,
    /// Standard SPPM's relMSE at `total_seconds` (log-log interpolation of its curve).
    pub standard_equal_time: Interpolated,
    /// ours / standard at equal time (< 1: ours is better).
    pub ratio_equal_time: f64,
    /// Standard SPPM's relMSE after the same number of passes, if it got there.
    pub standard_equal_passes: Option<f64>,
    /// Standard SPPM's render seconds for the same number of passes.
    pub standard_seconds_equal_passes: Option<f64>,
    /// Multi-level render time per pass over single-level's, minus one (paper Table 2).
    pub overhead: Option<f64>,
    /// Standard SPPM denoised by OIDN, at (at least) `total_seconds` (`peers`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sppm_oidn: Option<PeerResult>,
    /// Path tracing denoised by OIDN, at (at least) `total_seconds` (`peers`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pt_oidn: Option<PeerResult>,
}

impl Checkpoint {
    /// This checkpoint's result of `peer`, if it was run.
    pub fn peer(&self, peer: Peer) -> Option<&PeerResult> {
        match peer {
            Peer::SppmOidn => self.sppm_oidn.as_ref(),
            Peer::PtOidn => self.pt_oidn.as_ref(),
        }
    }
}

/// What the peers need: which to run, the denoiser, and the path tracer's depth when the scene
/// file names none.
pub struct PeerSetup<'a> {
    /// The peers to run (none: the evaluation is ours against standard SPPM only).
    pub peers: &'a [Peer],
    /// The OIDN runner.
    pub denoiser: &'a Denoiser,
    /// Path depth of the path tracer when the scene has no `<integrator>`: the evaluation's
    /// `max_depth` (the references' depth), else unbounded.
    pub max_depth: Option<u32>,
    /// Light samples per visible point of the standard SPPM run, whose image SPPM + OIDN
    /// denoises (the paper's standard SPPM: one).
    pub standard_emitter_samples: u32,
}

/// Everything measured on one scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SceneEval {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// One entry per configured pass count.
    pub checkpoints: Vec<Checkpoint>,
    /// Standard SPPM's convergence curve (dense checkpoints).
    pub standard: Vec<CurvePoint>,
}

/// Images of the last checkpoint, planar linear RGB, for the previews.
pub struct SceneImages {
    /// Standard SPPM at (about) ours' total time.
    pub standard: Vec<f32>,
    /// Passes and seconds of that standard image.
    pub standard_at: CurvePoint,
    /// Ours.
    pub ours: Vec<f32>,
    /// The reference.
    pub reference: Vec<f32>,
    /// Input levels ỹ, z̃1..z̃4.
    pub levels: Vec<Vec<f32>>,
    /// The peers' denoised images at the last checkpoint, in `peers` order.
    pub peers: Vec<(Peer, Vec<f32>)>,
}

/// A peer's image captured at the first of its checkpoints at or past a target time.
struct Capture {
    samples: u32,
    seconds: f64,
    image: Vec<f32>,
    albedo: Vec<f32>,
    normal: Vec<f32>,
}

/// Evaluates one scene; `variants` (the ablation's models) reconstruct the same bundles as
/// `model`.
pub fn evaluate_scene(
    scene: &EvalScene,
    settings: &SppmSettings,
    passes: &[u32],
    model: &TrainedModel,
    variants: &[TrainedModel],
    inference: &Inference,
    peers: &PeerSetup,
) -> Result<(SceneEval, SceneImages)> {
    let built = load_scene(&scene.xml, &scene.defines)?;
    let res = built.camera.resolution();
    let (width, height) = (res.x as usize, res.y as usize);
    let reference = read_rgb_exr_image(&scene.reference)?;
    let reference = planar_reference(&reference, width, height)
        .with_context(|| format!("reference {}", scene.reference.display()))?;

    // (a) multi-level + inference.
    let bundles = multi_level(&built, settings, passes)?;
    let mut checkpoints = Vec::new();
    let mut last_ours = Vec::new();
    let mut last_levels = Vec::new();
    for tb in &bundles {
        let what = || format!("{}: bundle at {} passes", scene.name, tb.bundle.meta.passes);
        let t = Instant::now();
        // The model's input, its screen levels (if any) filtered: part of its time.
        let input = pack_with(&tb.bundle, &model.config.packing()).with_context(what)?;
        let rec = inference.reconstruct(model, &input);
        let inference_seconds = t.elapsed().as_secs_f64() + tb.assembly_seconds;
        // The levels as rendered, for the report's per-level errors.
        let packed = if model.config.screen_levels.is_empty() {
            input
        } else {
            pack(&tb.bundle).with_context(what)?
        };
        let report = ErrorReport::new(&packed, &rec.image, &reference);
        let mut variant_relmse = Vec::with_capacity(variants.len());
        for v in variants {
            let input = pack_with(&tb.bundle, &v.config.packing()).with_context(what)?;
            let image = inference.reconstruct(v, &input).image;
            variant_relmse.push(relmse_planar(&image, &reference));
        }
        checkpoints.push(Checkpoint {
            passes: tb.bundle.meta.passes,
            render_seconds: tb.render_seconds,
            inference_seconds,
            total_seconds: tb.render_seconds + inference_seconds,
            ours_relmse: report.output,
            level_relmse: report.levels.clone(),
            best_level: report.best_level.clone(),
            variant_relmse,
            standard_equal_time: Interpolated {
                relmse: f64::NAN,
                extrapolated: true,
            },
            ratio_equal_time: f64::NAN,
            standard_equal_passes: None,
            standard_seconds_equal_passes: None,
            overhead: None,
            sppm_oidn: None,
            pt_oidn: None,
        });
        last_levels = (0..LEVEL_NAMES.len())
            .map(|l| packed.level(l).to_vec())
            .collect();
        last_ours = rec.image;
    }

    // (b) standard SPPM, past the slowest multi-level total.
    let max_total = checkpoints
        .iter()
        .map(|c| c.total_seconds)
        .fold(0.0, f64::max);
    let max_passes = passes.iter().copied().max().unwrap_or(1);
    // It stops at the first checkpoint that has both the largest configured pass count (for
    // the equal-passes and overhead columns) and a render time past ours' slowest total (so
    // every equal-time point is bracketed by two checkpoints), or at the pass cap.
    let stop = StopCondition {
        checkpoints: dense_checkpoints(passes, max_passes.saturating_mul(STANDARD_PASS_CAP_FACTOR)),
        seconds: None,
    };
    // Only one standard image is kept for the comparison: the first checkpoint at or past
    // ours' last total time (or the last one, if the run never got there).
    let last_total = checkpoints.last().map_or(0.0, |c| c.total_seconds);
    // The peers' render budgets: ours' totals less the denoiser's time, measured once on an
    // image of this size (its time does not depend on the content).
    let denoise_seconds = match (peers.peers.is_empty(), bundles.last()) {
        (false, Some(tb)) => {
            let (albedo, normal) = guides_of(&tb.bundle, width, height)?;
            let color = planar_reference(&tb.bundle.levels[1], width, height)?;
            let (_, s) = peers
                .denoiser
                .denoise(
                    width,
                    height,
                    &color,
                    &Guides {
                        albedo: &albedo,
                        normal: &normal,
                    },
                )
                .with_context(|| format!("{}: OIDN", scene.name))?;
            s
        }
        _ => 0.0,
    };
    let targets: Vec<f64> = checkpoints
        .iter()
        .map(|c| (c.total_seconds - denoise_seconds).max(0.0))
        .collect();
    let want_sppm_oidn = peers.peers.contains(&Peer::SppmOidn);
    let mut sppm_captures: Vec<Option<Capture>> = (0..targets.len()).map(|_| None).collect();
    let mut shown: Option<(u32, f64, Vec<f32>)> = None;
    let mut shown_final = false;
    let standard = SppmSettings {
        emitter_samples: Some(peers.standard_emitter_samples),
        // One eye subpath: its only level is gathered there.
        sharp_level: None,
        ..settings.clone()
    };
    let kept = run_timed(
        &built,
        &standard,
        SppmMode::Single,
        &stop,
        "standard",
        |b, seconds| {
            // The single level fills every level layer; z1 is the documented one to read.
            let image = planar_reference(&b.levels[1], width, height)
                .with_context(|| format!("{}: standard SPPM bundle", scene.name))?;
            let relmse = relmse_planar(&image, &reference);
            if want_sppm_oidn {
                for (slot, &target) in sppm_captures.iter_mut().zip(&targets) {
                    if slot.is_none() && seconds >= target {
                        let (albedo, normal) = guides_of(&b, width, height)?;
                        *slot = Some(Capture {
                            samples: b.meta.passes,
                            seconds,
                            image: image.clone(),
                            albedo,
                            normal,
                        });
                    }
                }
            }
            if !shown_final {
                shown_final = seconds >= last_total;
                shown = Some((b.meta.passes, seconds, image));
            }
            Ok((b.meta.passes, relmse))
        },
        |p, seconds| p >= max_passes && seconds > max_total,
    )?;
    let standard: Vec<CurvePoint> = kept
        .iter()
        .map(|((passes, relmse), seconds, _)| CurvePoint {
            passes: *passes,
            seconds: *seconds,
            relmse: *relmse,
        })
        .collect();

    // (c) equal time, (d) overhead.
    for c in &mut checkpoints {
        if let Some(i) = relmse_at_time(&standard, c.total_seconds) {
            c.standard_equal_time = i;
            c.ratio_equal_time = c.ours_relmse / i.relmse;
        }
        if let Some(p) = standard.iter().find(|p| p.passes == c.passes) {
            c.standard_equal_passes = Some(p.relmse);
            c.standard_seconds_equal_passes = Some(p.seconds);
            if p.seconds > 0.0 {
                c.overhead = Some(c.render_seconds / p.seconds - 1.0);
            }
        }
    }

    // (e) the peers: path tracing to the same budgets, then every capture denoised.
    let mut pt_captures: Vec<Option<Capture>> = (0..targets.len()).map(|_| None).collect();
    if peers.peers.contains(&Peer::PtOidn) {
        let file = built.integrator.as_ref();
        let tracer = PathTracer {
            max_depth: file
                .map(|i| i.max_depth)
                .or(peers.max_depth.map(|d| d as i32))
                .unwrap_or(-1),
            rr_depth: file.map_or(5, |i| i.rr_depth),
        };
        let until = targets.iter().copied().fold(0.0, f64::max);
        // The G-buffer of ours' bundle at each checkpoint: the same first-hit albedo and
        // normal a path tracer would output.
        let guides = bundles
            .iter()
            .map(|tb| guides_of(&tb.bundle, width, height))
            .collect::<Result<Vec<_>>>()?;
        path_trace_progressive(
            &built,
            &tracer,
            settings.seed,
            until,
            PT_MAX_SPP,
            |spp, seconds, image| {
                for ((slot, &target), (albedo, normal)) in
                    pt_captures.iter_mut().zip(&targets).zip(&guides)
                {
                    if slot.is_none() && seconds >= target {
                        *slot = Some(Capture {
                            samples: spp,
                            seconds,
                            image: image.to_vec(),
                            albedo: albedo.clone(),
                            normal: normal.clone(),
                        });
                    }
                }
            },
        );
    }
    let mut peer_images = Vec::new();
    let last = checkpoints.len().saturating_sub(1);
    for (peer, captures) in [(Peer::SppmOidn, sppm_captures), (Peer::PtOidn, pt_captures)] {
        for (c, capture) in captures.into_iter().enumerate() {
            let Some(cap) = capture else { continue };
            let guides = Guides {
                albedo: &cap.albedo,
                normal: &cap.normal,
            };
            let (image, denoise) = peers
                .denoiser
                .denoise(width, height, &cap.image, &guides)
                .with_context(|| format!("{}: {}", scene.name, peer.name()))?;
            let relmse = relmse_planar(&image, &reference);
            let checkpoint = &mut checkpoints[c];
            let result = PeerResult {
                samples: cap.samples,
                render_seconds: cap.seconds,
                render_budget_seconds: targets[c],
                denoise_seconds: denoise,
                total_seconds: cap.seconds + denoise,
                relmse,
                ratio: checkpoint.ours_relmse / relmse,
            };
            match peer {
                Peer::SppmOidn => checkpoint.sppm_oidn = Some(result),
                Peer::PtOidn => checkpoint.pt_oidn = Some(result),
            }
            if c == last {
                peer_images.push((peer, image));
            }
        }
    }

    let Some((shown_passes, shown_seconds, standard_image)) = shown else {
        anyhow::bail!("{}: the standard run produced no bundle", scene.name);
    };
    let standard_at = standard
        .iter()
        .copied()
        .find(|p| p.passes == shown_passes)
        .unwrap_or(CurvePoint {
            passes: shown_passes,
            seconds: shown_seconds,
            relmse: relmse_planar(&standard_image, &reference),
        });
    Ok((
        SceneEval {
            width,
            height,
            checkpoints,
            standard,
        },
        SceneImages {
            standard: standard_image,
            standard_at,
            ours: last_ours,
            reference,
            levels: last_levels,
            peers: peer_images,
        },
    ))
}

/// Path-tracing samples per pixel beyond which the PT peer stops even short of its budget.
const PT_MAX_SPP: u32 = 1 << 20;

/// A bundle's albedo and normal, planar RGB, for OIDN.
fn guides_of(b: &bundle::Bundle, width: usize, height: usize) -> Result<(Vec<f32>, Vec<f32>)> {
    Ok((
        planar_reference(&b.albedo, width, height).context("bundle albedo")?,
        planar_reference(&b.normal, width, height).context("bundle normal")?,
    ))
}

/// Hand-made results for the unit tests of the modules that aggregate them.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::{Checkpoint, SceneEval};
    use crate::compare::Interpolated;
    use crate::SceneResult;

    /// A checkpoint where ours has relMSE `ours` and standard SPPM 1 at equal time; no
    /// equal-pass figures, no overhead, no variants (tests override what they look at).
    pub(crate) fn checkpoint(passes: u32, ours: f64) -> Checkpoint {
        Checkpoint {
            passes,
            render_seconds: 1.0,
            inference_seconds: 0.1,
            total_seconds: 1.1,
            ours_relmse: ours,
            level_relmse: vec![1.0, 0.5, 2.0, 3.0, 4.0],
            best_level: "z1".into(),
            variant_relmse: Vec::new(),
            standard_equal_time: Interpolated {
                relmse: 1.0,
                extrapolated: false,
            },
            ratio_equal_time: ours,
            standard_equal_passes: None,
            standard_seconds_equal_passes: None,
            overhead: None,
            sppm_oidn: None,
            pt_oidn: None,
        }
    }

    /// An evaluated 1×1 scene with these checkpoints.
    pub(crate) fn scene(name: &str, checkpoints: Vec<Checkpoint>) -> SceneResult {
        SceneResult {
            eval: Some(SceneEval {
                width: 1,
                height: 1,
                checkpoints,
                standard: Vec::new(),
            }),
            ..SceneResult::new(name.into(), "s.xml".into(), "r.exr".into())
        }
    }
}
