//! Error report against a reference: relMSE (docs/method.md §5.6) of every input level and of the output.

use model::features::PackedImage;
use model::metrics::relmse_planar;
use serde::{Deserialize, Serialize};

/// Names of the five input levels, in bundle order.
pub const LEVEL_NAMES: [&str; 5] = ["y", "z1", "z2", "z3", "z4"];

/// relMSE of each input level and of the reconstruction against one reference.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorReport {
    /// relMSE of ỹ, z̃1..z̃4 in [`LEVEL_NAMES`] order.
    pub levels: Vec<f64>,
    /// relMSE of the reconstruction.
    pub output: f64,
    /// Name of the best input level.
    pub best_level: String,
    /// relMSE of the best input level.
    pub best_level_relmse: f64,
    /// output / best level (< 1: the reconstruction beats every input).
    pub ratio_to_best: f64,
}

impl ErrorReport {
    /// Compares the levels of `packed` and the planar RGB `output` with the planar `reference`.
    pub fn new(packed: &PackedImage, output: &[f32], reference: &[f32]) -> Self {
        let levels: Vec<f64> = (0..LEVEL_NAMES.len())
            .map(|l| relmse_planar(packed.level(l), reference))
            .collect();
        let (best, &best_value) = levels
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .expect("five levels");
        let output = relmse_planar(output, reference);
        Self {
            output,
            best_level: LEVEL_NAMES[best].to_string(),
            best_level_relmse: best_value,
            ratio_to_best: output / best_value,
            levels,
        }
    }

    /// A human-readable table.
    pub fn to_text(&self) -> String {
        let mut s = String::from("relMSE vs reference\n");
        for (name, v) in LEVEL_NAMES.iter().zip(&self.levels) {
            let mark = if *name == self.best_level {
                "  (best input)"
            } else {
                ""
            };
            s.push_str(&format!("  input {name:<3} {v:.4e}{mark}\n"));
        }
        s.push_str(&format!(
            "  output    {:.4e}  ({:.3}x the best input)\n",
            self.output, self.ratio_to_best
        ));
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_names_the_best_level_and_the_ratio() {
        // One pixel; reference (1, 1, 1) → denominator 1.01. Level l is off by 0.1·(l + 1) in
        // every channel except level 2, which is exact; the output is off by 0.05.
        let reference = vec![1.0, 1.0, 1.0];
        let mut levels = Vec::new();
        for l in 0..5 {
            let e = if l == 2 { 0.0 } else { 0.1 * (l + 1) as f32 };
            levels.extend([1.0 + e; 3]);
        }
        let packed = PackedImage {
            width: 1,
            height: 1,
            features: vec![0.0; 27],
            extra: Vec::new(),
            levels,
            direct: None,
            direct_added: None,
        };
        let output = vec![1.05, 1.05, 1.05];
        let r = ErrorReport::new(&packed, &output, &reference);
        assert!((r.levels[0] - 0.01 / 1.01).abs() < 1e-6);
        assert_eq!(r.levels[2], 0.0);
        assert_eq!(r.best_level, "z2");
        assert!((r.output - 0.0025 / 1.01).abs() < 1e-6);
        assert!(r.ratio_to_best.is_infinite());
        assert!(r.to_text().contains("z2"));
    }
}
