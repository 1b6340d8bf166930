//! The two SPPM runs of a scene — multi-level (bundles for the network) and standard
//! single-level (the baseline) — with wall times that exclude the evaluator's own work.
//!
//! `render_sppm` reports `meta.seconds` measured from its start, so time spent in the
//! checkpoint callback (assembling the bundle, storing it) would count against every later
//! checkpoint. The standard run has many checkpoints (a dense convergence curve), so this
//! would handicap it. Each run therefore records, per checkpoint, the time from the end of the
//! pass to the end of the callback, and later checkpoints subtract the sum: the corrected time
//! is pure rendering. The multi-level pipeline's own bundle assembly is charged to it again by
//! the caller (as part of the reconstruction cost).

use std::sync::Mutex;
use std::time::Instant;

use anyhow::Result;
use bundle::Bundle;
use indicatif::{ProgressBar, ProgressStyle};
use renderer::integrators::sppm::{render_sppm, SppmMode, SppmSettings, StopCondition};
use renderer::scene::Scene;

/// A bundle with its corrected render time.
pub struct TimedBundle {
    /// The bundle as `render_sppm` made it.
    pub bundle: Bundle,
    /// Render seconds up to this checkpoint, without the evaluator's callback time.
    pub render_seconds: f64,
    /// Seconds `render_sppm` spent assembling this bundle after the pass ended.
    pub assembly_seconds: f64,
}

/// Returned by the checkpoint callback to end a run early; not a failure.
#[derive(Debug, thiserror::Error)]
#[error("enough checkpoints")]
struct Enough;

/// Renders `scene` in `mode` and hands every checkpoint bundle, with its corrected render
/// seconds, to `keep`, which returns what to store (e.g. the bundle itself, or only its
/// error). After each checkpoint `done(passes, corrected seconds)` may end the run (before
/// the last checkpoint of `stop`). Returns the kept values with their corrected render and
/// assembly seconds.
pub fn run_timed<T: Send>(
    scene: &Scene,
    settings: &SppmSettings,
    mode: SppmMode,
    stop: &StopCondition,
    label: &str,
    mut keep: impl FnMut(Bundle, f64) -> Result<T> + Send,
    done: impl Fn(u32, f64) -> bool + Send + Sync,
) -> Result<Vec<(T, f64, f64)>> {
    let sppm = SppmSettings {
        mode,
        ..settings.clone()
    };
    let bar = ProgressBar::new(stop.checkpoints.iter().copied().max().unwrap_or(0) as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{prefix} {elapsed_precise} [{wide_bar}] {pos}/{len} passes ({msg})",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar.set_prefix(label.to_string());
    // End of the last pass (set by `progress`, read by the checkpoint callback) and the
    // callback time accumulated so far.
    let pass_end: Mutex<Option<Instant>> = Mutex::new(None);
    let mut overhead = 0.0f64;
    let mut kept = Vec::new();
    let outcome = render_sppm(
        scene,
        &sppm,
        stop,
        |b| {
            let entered = Instant::now();
            let end = pass_end.lock().expect("progress lock").unwrap_or(entered);
            let assembly = (entered - end).as_secs_f64();
            let render_seconds = b.meta.seconds - overhead;
            let passes = b.meta.passes;
            let value = keep(b, render_seconds)?;
            kept.push((value, render_seconds, assembly));
            overhead += end.elapsed().as_secs_f64();
            if done(passes, render_seconds) {
                return Err(Enough.into());
            }
            Ok(())
        },
        |p| {
            *pass_end.lock().expect("progress lock") = Some(Instant::now());
            bar.set_position(p.pass as u64);
            bar.set_message(format!("{:.2} passes/s", p.pass as f64 / p.elapsed));
        },
    );
    bar.finish_and_clear();
    match outcome {
        Ok(_) => Ok(kept),
        Err(e) if e.downcast_ref::<Enough>().is_some() => Ok(kept),
        Err(e) => Err(e.context(format!("{label}: rendering"))),
    }
}

/// Loads and builds a Mitsuba XML scene for SPPM under the toolkit's scene policy
/// (`renderer::scene_file`, strict), printing its warnings.
pub fn load_scene(xml: &std::path::Path, defines: &[(String, String)]) -> Result<Scene> {
    let loaded = renderer::scene_file::load_for_sppm(xml, defines, false)?;
    for w in &loaded.warnings {
        eprintln!("warning: {}: {w}", xml.display());
    }
    Ok(loaded.scene)
}

/// Multi-level run: one bundle per configured pass count.
pub fn multi_level(
    scene: &Scene,
    settings: &SppmSettings,
    passes: &[u32],
) -> Result<Vec<TimedBundle>> {
    let stop = StopCondition {
        checkpoints: passes.to_vec(),
        seconds: None,
    };
    let kept = run_timed(
        scene,
        settings,
        SppmMode::MultiLevel,
        &stop,
        "multi-level",
        |b, _| Ok(b),
        |_, _| false,
    )?;
    Ok(kept
        .into_iter()
        .map(|(bundle, render_seconds, assembly_seconds)| TimedBundle {
            bundle,
            render_seconds,
            assembly_seconds,
        })
        .collect())
}
