//! The reference-noise table of a dataset whose references average several runs
//! (`render.reference_runs` ≥ 2): per scene the relMSE its reference carries from its own noise
//! (the manifest's `reference_noise`) against the error of the best input level at the scene's
//! largest pass count, per family the median and worst ratio, and the scenes whose reference is
//! too noisy to judge that input (ratio above [`LIMIT`]) flagged.

use crate::evaluation_reference::best_input_relmse;
use crate::manifest::Manifest;
use anyhow::{Context, Result};
use bundle::read_rgb_exr_image;
use serde::Serialize;
use std::path::Path;

/// The most noise a converged reference may carry, as a fraction of the error it is to measure.
pub const LIMIT: f64 = 0.1;

/// File the table is written to, in the dataset folder.
pub const TABLE_FILE: &str = "reference-noise.json";

/// One scene's row.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneRow {
    /// Scene id.
    pub id: String,
    /// Family name.
    pub family: String,
    /// Split name.
    pub split: String,
    /// Regime, where the dataset has them.
    pub regime: Option<String>,
    /// The largest input pass count of the scene.
    pub passes: u32,
    /// relMSE the reference carries (manifest `reference_noise`).
    pub reference_noise: f64,
    /// The best input level's relMSE against the reference at `passes` (mean over seeds), less
    /// the reference's noise — the input's own error.
    pub input_relmse: f64,
    /// `reference_noise / input_relmse`; `None` where the measured error is all reference noise.
    pub ratio: Option<f64>,
    /// The ratio is above [`LIMIT`] (or undefined).
    pub flagged: bool,
}

/// One family's summary.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FamilyRow {
    /// Family name.
    pub family: String,
    /// Scenes with a measured reference noise.
    pub scenes: usize,
    /// Median ratio (flagged scenes without a ratio count as infinite).
    pub median: f64,
    /// Worst ratio.
    pub worst: f64,
    /// Scenes above [`LIMIT`].
    pub flagged: usize,
}

/// The whole table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NoiseTable {
    /// [`LIMIT`].
    pub limit: f64,
    /// Per scene, in id order.
    pub scenes: Vec<SceneRow>,
    /// Per family, in order of first appearance.
    pub families: Vec<FamilyRow>,
    /// Scenes whose reference is a single run (no noise measured).
    pub unmeasured: Vec<String>,
    /// The scenes with a converged evaluation reference (`datagen evaluation-references`).
    pub evaluation: Vec<EvaluationRow>,
    /// Per family, of `evaluation`.
    pub evaluation_families: Vec<FamilyRow>,
}

/// One scene's evaluation reference.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvaluationRow {
    /// Scene id.
    pub id: String,
    /// Family name.
    pub family: String,
    /// Split name.
    pub split: String,
    /// Passes of each of its runs.
    pub passes: u32,
    /// The scene's (training) reference passes, the inputs' largest count.
    pub reference_passes: u32,
    /// relMSE the evaluation reference carries from its own noise.
    pub noise: f64,
    /// The best input level's error at the largest pass count, its noise subtracted.
    pub input_relmse: f64,
    /// `noise / input_relmse`.
    pub ratio: Option<f64>,
    /// Not converged (a limit reached) or above [`LIMIT`].
    pub flagged: bool,
}

/// Per family (in order of first appearance): scene count, median and worst ratio, scenes above
/// [`LIMIT`]; a missing ratio counts as infinite.
fn family_rows<'a>(rows: impl Iterator<Item = (&'a str, Option<f64>)>) -> Vec<FamilyRow> {
    let rows: Vec<(&str, Option<f64>)> = rows.collect();
    let mut families: Vec<FamilyRow> = Vec::new();
    for &(family, _) in &rows {
        if families.iter().any(|f| f.family == family) {
            continue;
        }
        let mut ratios: Vec<f64> = rows
            .iter()
            .filter(|(f, _)| *f == family)
            .map(|(_, r)| r.unwrap_or(f64::INFINITY))
            .collect();
        ratios.sort_by(f64::total_cmp);
        let n = ratios.len();
        let median = if n % 2 == 1 {
            ratios[n / 2]
        } else {
            0.5 * (ratios[n / 2 - 1] + ratios[n / 2])
        };
        families.push(FamilyRow {
            family: family.to_owned(),
            scenes: n,
            median,
            worst: ratios[n - 1],
            flagged: ratios.iter().filter(|&&r| r > LIMIT).count(),
        });
    }
    families
}

/// Measures the table of the dataset at `root`; `on_scene(done, total)` reports progress.
pub fn noise_table(
    root: &Path,
    manifest: &Manifest,
    mut on_scene: impl FnMut(usize, usize),
) -> Result<NoiseTable> {
    let mut scenes = Vec::new();
    let mut unmeasured = Vec::new();
    for (done, s) in manifest.scenes.iter().enumerate() {
        on_scene(done, manifest.scenes.len());
        let Some(noise) = s.reference_noise else {
            unmeasured.push(s.id.clone());
            continue;
        };
        let reference = read_rgb_exr_image(&root.join(&s.reference))
            .with_context(|| format!("reference of scene {}", s.id))?;
        let Some((passes, measured)) = best_input_relmse(root, manifest, s, &reference)? else {
            unmeasured.push(s.id.clone());
            continue;
        };
        let input = measured - noise;
        let ratio = (input > 0.0).then(|| noise / input);
        scenes.push(SceneRow {
            id: s.id.clone(),
            family: s.family.clone(),
            split: s.split.name().to_owned(),
            regime: s.regime.clone(),
            passes,
            reference_noise: noise,
            input_relmse: input,
            ratio,
            flagged: ratio.is_none_or(|r| r > LIMIT),
        });
    }
    on_scene(manifest.scenes.len(), manifest.scenes.len());
    let families = family_rows(scenes.iter().map(|r| (r.family.as_str(), r.ratio)));
    // The converged evaluation references, from their manifest entries.
    let evaluation: Vec<EvaluationRow> = manifest
        .scenes
        .iter()
        .filter_map(|s| {
            let e = s.evaluation_reference.as_ref()?;
            let ratio = (e.input_relmse > 0.0).then(|| e.noise / e.input_relmse);
            Some(EvaluationRow {
                id: s.id.clone(),
                family: s.family.clone(),
                split: s.split.name().to_owned(),
                passes: e.passes,
                reference_passes: s.reference_passes,
                noise: e.noise,
                input_relmse: e.input_relmse,
                ratio,
                flagged: !e.converged || ratio.is_none_or(|r| r > LIMIT),
            })
        })
        .collect();
    let evaluation_families = family_rows(evaluation.iter().map(|r| (r.family.as_str(), r.ratio)));
    Ok(NoiseTable {
        limit: LIMIT,
        scenes,
        families,
        unmeasured,
        evaluation,
        evaluation_families,
    })
}

/// The table as Markdown: one row per family, then the flagged scenes.
pub fn markdown(table: &NoiseTable) -> String {
    let mut out = String::from(
        "| family | scenes | median noise ÷ input error | worst | above 1/10 |\n|---|---|---|---|---|\n",
    );
    for f in &table.families {
        out.push_str(&format!(
            "| {} | {} | {:.3} | {:.3} | {} |\n",
            f.family, f.scenes, f.median, f.worst, f.flagged
        ));
    }
    for s in table.scenes.iter().filter(|s| s.flagged) {
        out.push_str(&format!(
            "\nflagged: {} ({}, {} passes): reference noise {:.3e}, input error {:.3e}",
            s.id, s.split, s.passes, s.reference_noise, s.input_relmse
        ));
    }
    if !table.evaluation.is_empty() {
        out.push_str(
            "\n\nEvaluation references (`datagen evaluation-references`):\n\n| family | scenes | \
             median noise ÷ input error | worst | above 1/10 |\n|---|---|---|---|---|\n",
        );
        for f in &table.evaluation_families {
            out.push_str(&format!(
                "| {} | {} | {:.3} | {:.3} | {} |\n",
                f.family, f.scenes, f.median, f.worst, f.flagged
            ));
        }
        for s in table.evaluation.iter().filter(|s| s.flagged) {
            out.push_str(&format!(
                "\nflagged: {} ({}): evaluation reference at {} passes ({}x the inputs') noise \
                 {:.3e}, input error {:.3e}",
                s.id,
                s.split,
                s.passes,
                s.passes / s.reference_passes.max(1),
                s.noise,
                s.input_relmse
            ));
        }
    }
    if !table.unmeasured.is_empty() {
        out.push_str(&format!(
            "\n{} scene(s) without a measured reference noise (one-run references)",
            table.unmeasured.len()
        ));
    }
    out.push('\n');
    out
}
