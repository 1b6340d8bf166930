//! The dual-vs-multi ablation (paper Table 1): networks combining ỹ with fewer correlated
//! levels, reconstructing the same multi-level bundles as the main model, compared per scene.

use std::path::PathBuf;

use model::network::all_levels;
use model::{ModelConfig, Preset};
use serde::Serialize;

use crate::compare::geometric_mean;
use crate::SceneResult;
use infer::report::LEVEL_NAMES;

/// The note shown when the config has no `[ablation]`.
pub const NOT_RUN: &str = "Not run: the config has no [ablation] section. Train a network \
combining y with one z level (train config `levels = [0, j]`, same preset and schedule as the \
main model) and name its directory in `[ablation] dual_models = [...]`.";

/// What the comparison is.
pub const METHOD: &str = "Every model reconstructs the same multi-level bundles (same scene, \
seed and passes); the table gives relMSE at the largest pass count. Dual (y, zj) combines the \
independent estimate with one correlated level (paper Table 1); the main model combines the \
levels its model.json names. The variants' inference time is not charged anywhere.";

/// One model of the ablation.
#[derive(Clone, Debug, Serialize)]
pub struct AblationModel {
    /// Model directory.
    pub dir: PathBuf,
    /// Paper-style name, e.g. `Dual (y, z2)` or `Multi (y, z1, ..., z4)`.
    pub label: String,
    /// Levels combined, by name.
    pub levels: Vec<String>,
    /// Preset it was built from.
    pub preset: Preset,
}

impl AblationModel {
    /// Describes the model in `dir` with architecture `config`.
    pub fn new(dir: PathBuf, config: &ModelConfig) -> Self {
        Self {
            dir,
            label: label(&config.levels),
            levels: config
                .levels
                .iter()
                .map(|&l| LEVEL_NAMES[l].to_string())
                .collect(),
            preset: config.preset,
        }
    }
}

/// One scene's row: relMSE of the main model and of each variant on the same bundle.
#[derive(Clone, Debug, Serialize)]
pub struct AblationRow {
    /// Scene name.
    pub scene: String,
    /// relMSE of the main model.
    pub multi: f64,
    /// relMSE of each variant, in [`Ablation::variants`] order.
    pub variants: Vec<f64>,
    /// Label of the model with the lowest relMSE on this scene.
    pub best: String,
    /// relMSE of the best single input level on the same bundle (for context).
    pub best_input: f64,
    /// Name of that level.
    pub best_input_level: String,
}

/// The ablation as written to results.json and shown on the page.
#[derive(Clone, Debug, Serialize)]
pub struct Ablation {
    /// How it is made, or why it was not run.
    pub note: String,
    /// The pass count of the table (the largest configured).
    pub passes: u32,
    /// The main model.
    pub multi: Option<AblationModel>,
    /// The variants.
    pub variants: Vec<AblationModel>,
    /// Scenes that succeeded, in config order.
    pub rows: Vec<AblationRow>,
    /// Per variant: geometric mean over scenes of variant / main relMSE (> 1: main is better).
    pub geomean_ratio_to_multi: Vec<Option<f64>>,
    /// Per variant: scenes where the main model is strictly better.
    pub multi_better: Vec<usize>,
}

/// Paper-style name of a level choice.
pub fn label(levels: &[usize]) -> String {
    let names: Vec<&str> = levels.iter().map(|&l| LEVEL_NAMES[l]).collect();
    if levels == all_levels().as_slice() {
        "Multi (y, z1, ..., z4)".into()
    } else if levels.len() == 2 {
        format!("Dual ({})", names.join(", "))
    } else {
        format!("Levels ({})", names.join(", "))
    }
}

/// The ablation that was not configured.
pub fn not_run(passes: u32) -> Ablation {
    Ablation {
        note: NOT_RUN.into(),
        passes,
        multi: None,
        variants: Vec::new(),
        rows: Vec::new(),
        geomean_ratio_to_multi: Vec::new(),
        multi_better: Vec::new(),
    }
}

/// Builds the table at `passes` from the scene results (failed scenes are left out; the page
/// lists them in the main table).
pub fn build(
    results: &[SceneResult],
    passes: u32,
    multi: AblationModel,
    variants: Vec<AblationModel>,
) -> Ablation {
    let mut rows = Vec::new();
    for r in results {
        let Some(c) = r
            .eval
            .as_ref()
            .and_then(|e| e.checkpoints.iter().find(|c| c.passes == passes))
        else {
            continue;
        };
        if c.variant_relmse.len() != variants.len() {
            continue;
        }
        let mut best = (multi.label.clone(), c.ours_relmse);
        for (m, &v) in variants.iter().zip(&c.variant_relmse) {
            if v < best.1 {
                best = (m.label.clone(), v);
            }
        }
        rows.push(AblationRow {
            scene: r.name.clone(),
            multi: c.ours_relmse,
            variants: c.variant_relmse.clone(),
            best: best.0,
            best_input: c.level_relmse.iter().copied().fold(f64::INFINITY, f64::min),
            best_input_level: c.best_level.clone(),
        });
    }
    let geomean_ratio_to_multi = (0..variants.len())
        .map(|k| {
            let ratios: Vec<f64> = rows.iter().map(|r| r.variants[k] / r.multi).collect();
            geometric_mean(&ratios)
        })
        .collect();
    let multi_better = (0..variants.len())
        .map(|k| rows.iter().filter(|r| r.multi < r.variants[k]).count())
        .collect();
    let mut note = METHOD.to_string();
    if let Some(v) = variants.iter().find(|v| v.preset != multi.preset) {
        note.push_str(&format!(
            " Warning: {} uses the {:?} preset, the main model {:?}: not the same network size.",
            v.label, v.preset, multi.preset
        ));
    }
    Ablation {
        note,
        passes,
        multi: Some(multi),
        variants,
        rows,
        geomean_ratio_to_multi,
        multi_better,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::fixtures::{self, scene};
    use crate::scene::Checkpoint;

    fn checkpoint(passes: u32, ours: f64, variants: Vec<f64>) -> Checkpoint {
        Checkpoint {
            variant_relmse: variants,
            ..fixtures::checkpoint(passes, ours)
        }
    }

    fn model(levels: Vec<usize>) -> AblationModel {
        let config = ModelConfig::preset(Preset::Small).with_levels(levels);
        AblationModel::new(PathBuf::from("m"), &config)
    }

    #[test]
    fn labels_follow_the_paper() {
        assert_eq!(label(&[0, 1, 2, 3, 4]), "Multi (y, z1, ..., z4)");
        assert_eq!(label(&[0, 3]), "Dual (y, z3)");
        assert_eq!(label(&[0, 1, 4]), "Levels (y, z1, z4)");
    }

    #[test]
    fn table_takes_the_largest_pass_count_and_counts_wins() {
        let results = vec![
            // At 16 passes: multi 0.2 vs dual 0.4 → multi wins, ratio 2.
            scene(
                "a",
                vec![
                    checkpoint(8, 9.0, vec![9.0]),
                    checkpoint(16, 0.2, vec![0.4]),
                ],
            ),
            // Dual wins here, ratio 0.5.
            scene("b", vec![checkpoint(16, 0.2, vec![0.1])]),
            // No checkpoint at 16: left out.
            scene("c", vec![checkpoint(8, 0.2, vec![0.1])]),
        ];
        let a = build(&results, 16, model(all_levels()), vec![model(vec![0, 2])]);
        assert_eq!(a.rows.len(), 2);
        assert_eq!(a.rows[0].multi, 0.2);
        assert_eq!(a.rows[0].variants, vec![0.4]);
        assert_eq!(a.rows[0].best, "Multi (y, z1, ..., z4)");
        assert_eq!(a.rows[1].best, "Dual (y, z2)");
        assert_eq!(
            (a.rows[1].best_input, a.rows[1].best_input_level.as_str()),
            (0.5, "z1")
        );
        assert_eq!(a.multi_better, vec![1]);
        let g = a.geomean_ratio_to_multi[0].unwrap();
        assert!((g - 1.0).abs() < 1e-12, "{g}");
    }
}
