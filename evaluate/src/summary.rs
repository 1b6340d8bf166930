//! `evaluate --combine DIR...`: one summary over the scenes of several finished evaluations
//! (e.g. a dataset's test split and the external scenes, which need different configs), read
//! back from their `results.json` — the figures docs/results.md quotes over both sets.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::html::opt_sci;
use crate::peers::Peer;
use crate::{summarise, SceneResult, Summary};

/// The part of an evaluation's `results.json` the combined summary needs.
#[derive(Deserialize)]
struct StoredResults {
    config: StoredConfig,
    scenes: Vec<SceneResult>,
}

/// The settings of a stored evaluation shown next to its scenes.
#[derive(Deserialize)]
struct StoredConfig {
    photons_per_pass: u64,
    passes: Vec<u32>,
}

/// One scene of a combined summary, at the summary's pass count.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct CombinedRow {
    /// The evaluation directory the scene comes from.
    pub evaluation: PathBuf,
    /// Scene name.
    pub scene: String,
    /// Photons per pass of that evaluation.
    pub photons_per_pass: u64,
    /// Ours' relMSE (multi-level SPPM + reconstruction), or `None` when the scene failed.
    pub ours_relmse: Option<f64>,
    /// Standard SPPM's relMSE at ours' total time.
    pub standard_relmse_equal_time: Option<f64>,
    /// Ours / standard at equal time.
    pub ratio_equal_time: Option<f64>,
    /// Multi-level overhead per pass at this pass count.
    pub overhead: Option<f64>,
    /// Ours / (SPPM + OIDN) at equal time, when that peer was run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ratio_sppm_oidn: Option<f64>,
    /// Ours / (PT + OIDN) at equal time, when that peer was run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ratio_pt_oidn: Option<f64>,
    /// Why the scene failed.
    pub error: Option<String>,
}

/// What `--combine` prints and writes.
#[derive(Clone, Debug, Serialize)]
pub struct EvaluationsSummary {
    /// The evaluation directories, in the order given.
    pub evaluations: Vec<PathBuf>,
    /// Per scene, evaluation by evaluation.
    pub rows: Vec<CombinedRow>,
    /// Aggregates over every scene, at the largest pass count all evaluations share.
    pub summary: Summary,
}

/// Reads `results.json` of each directory and summarises all their scenes together, at the
/// largest pass count every evaluation has. Errors name the file.
pub fn summarize_evaluations(dirs: &[PathBuf]) -> Result<EvaluationsSummary> {
    if dirs.is_empty() {
        bail!("--combine needs at least one evaluation directory");
    }
    let mut stored = Vec::with_capacity(dirs.len());
    for dir in dirs {
        let path = dir.join("results.json");
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!("reading {} (run `evaluate --config` first)", path.display())
        })?;
        let results: StoredResults =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        stored.push(results);
    }
    let mut common: BTreeSet<u32> = stored[0].config.passes.iter().copied().collect();
    for s in &stored[1..] {
        let these: BTreeSet<u32> = s.config.passes.iter().copied().collect();
        common = common.intersection(&these).copied().collect();
    }
    let Some(&passes) = common.iter().next_back() else {
        bail!(
            "the evaluations share no pass count ({}): combine evaluations with a common checkpoint",
            describe_passes(dirs, &stored)
        );
    };
    let mut rows = Vec::new();
    let mut scenes = Vec::new();
    for (dir, s) in dirs.iter().zip(stored) {
        for r in s.scenes {
            let checkpoint = r
                .eval
                .as_ref()
                .and_then(|e| e.checkpoints.iter().find(|c| c.passes == passes));
            rows.push(CombinedRow {
                evaluation: dir.clone(),
                scene: r.name.clone(),
                photons_per_pass: s.config.photons_per_pass,
                ours_relmse: checkpoint.map(|c| c.ours_relmse),
                standard_relmse_equal_time: checkpoint.map(|c| c.standard_equal_time.relmse),
                ratio_equal_time: checkpoint.map(|c| c.ratio_equal_time),
                overhead: checkpoint.and_then(|c| c.overhead),
                ratio_sppm_oidn: checkpoint
                    .and_then(|c| c.peer(Peer::SppmOidn))
                    .map(|p| p.ratio),
                ratio_pt_oidn: checkpoint
                    .and_then(|c| c.peer(Peer::PtOidn))
                    .map(|p| p.ratio),
                error: r.error.clone(),
            });
            scenes.push(r);
        }
    }
    Ok(EvaluationsSummary {
        evaluations: dirs.to_vec(),
        rows,
        summary: summarise(&scenes, passes),
    })
}

fn describe_passes(dirs: &[PathBuf], stored: &[StoredResults]) -> String {
    dirs.iter()
        .zip(stored)
        .map(|(d, s)| format!("{}: {:?}", d.display(), s.config.passes))
        .collect::<Vec<_>>()
        .join("; ")
}

/// The combined table as Markdown (scene rows, then the aggregates), as printed.
pub fn markdown(c: &EvaluationsSummary) -> String {
    let ratio = |v: Option<f64>| v.map_or_else(|| "–".into(), |x| format!("{x:.3}"));
    let overhead =
        |v: Option<f64>| v.map_or_else(|| "–".into(), |x| format!("{:+.0} %", 100.0 * x));
    // Peer columns only when some scene has that peer.
    let sppm_oidn = c.rows.iter().any(|r| r.ratio_sppm_oidn.is_some());
    let pt_oidn = c.rows.iter().any(|r| r.ratio_pt_oidn.is_some());
    let mut out = String::from(
        "| evaluation | scene | photons/pass | ours relMSE | standard relMSE, equal time | ours / standard | overhead |",
    );
    let mut rule = String::from("|---|---|---|---|---|---|---|");
    for (shown, name) in [(sppm_oidn, "SPPM + OIDN"), (pt_oidn, "PT + OIDN")] {
        if shown {
            out += &format!(" ours / {name} |");
            rule += "---|";
        }
    }
    out += &format!("\n{rule}\n");
    for r in &c.rows {
        let outcome = match (&r.error, r.ratio_equal_time) {
            (Some(e), _) => format!("failed: {e}"),
            (None, Some(_)) => format!("**{}**", ratio(r.ratio_equal_time)),
            (None, None) => "–".into(),
        };
        out += &format!(
            "| {} | {} | {} | {} | {} | {} | {} |",
            r.evaluation.display(),
            r.scene,
            r.photons_per_pass,
            opt_sci(r.ours_relmse),
            opt_sci(r.standard_relmse_equal_time),
            outcome,
            overhead(r.overhead),
        );
        for (shown, value) in [(sppm_oidn, r.ratio_sppm_oidn), (pt_oidn, r.ratio_pt_oidn)] {
            if shown {
                out += &format!(" {} |", ratio(value));
            }
        }
        out.push('\n');
    }
    let s = &c.summary;
    out += &format!(
        "\nAt {} passes: ours better at equal time on {} of {} scenes ({} failed), median ratio {}, \
         geometric mean {}; median overhead per pass {}.\n",
        s.passes,
        s.ours_better_equal_time,
        s.scenes - s.failed,
        s.failed,
        ratio(s.median_ratio_equal_time),
        ratio(s.geomean_ratio_equal_time),
        overhead(s.median_overhead),
    );
    for p in &s.peers {
        out += &format!(
            "Against {}: ours better on {} of {} scenes, median ratio {}.\n",
            p.peer.name(),
            p.ours_better,
            p.scenes,
            ratio(p.median_ratio)
        );
    }
    out
}

/// Writes the combined summary as JSON, atomically (temp file + rename).
pub fn write_json(c: &EvaluationsSummary, path: &Path) -> Result<()> {
    let text = serde_json::to_string_pretty(c).context("serialising the combined summary")?;
    crate::images::write_atomic(path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compare::Interpolated;
    use crate::scene::fixtures::{self, scene};
    use crate::scene::Checkpoint;

    fn checkpoint(passes: u32, ours: f64, standard: f64, overhead: f64) -> Checkpoint {
        Checkpoint {
            level_relmse: vec![2.0 * ours; 5],
            best_level: "z4".into(),
            standard_equal_time: Interpolated {
                relmse: standard,
                extrapolated: false,
            },
            ratio_equal_time: ours / standard,
            standard_equal_passes: Some(standard),
            standard_seconds_equal_passes: Some(1.0),
            overhead: Some(overhead),
            ..fixtures::checkpoint(passes, ours)
        }
    }

    /// Writes `dir/results.json` with the fields an evaluation writes that `combine` reads.
    fn write_results(dir: &Path, photons: u64, passes: &[u32], scenes: &[SceneResult]) {
        std::fs::create_dir_all(dir).unwrap();
        let json = serde_json::json!({
            "config": {"photons_per_pass": photons, "passes": passes, "model": "m"},
            "scenes": scenes,
            "summary": {},
        });
        std::fs::write(dir.join("results.json"), json.to_string()).unwrap();
    }

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("combine-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn summarises_all_scenes_at_the_largest_shared_pass_count() {
        let dir = temp_dir("ok");
        let (a, b) = (dir.join("a"), dir.join("b"));
        // `a` has checkpoints 8, 16, 32; `b` 16 and 32 and 64: the shared largest is 32.
        write_results(
            &a,
            100_000,
            &[8, 16, 32],
            &[
                scene(
                    "room",
                    vec![checkpoint(16, 1.0, 1.0, 0.5), checkpoint(32, 1.0, 4.0, 0.1)],
                ),
                scene("glass", vec![checkpoint(32, 3.0, 2.0, 0.3)]),
            ],
        );
        let mut failed = SceneResult::new("broken".into(), "x.xml".into(), "x.exr".into());
        failed.error = Some("reference has 3 channels".into());
        write_results(
            &b,
            400_000,
            &[16, 32, 64],
            &[
                scene(
                    "cbox",
                    vec![checkpoint(32, 1.0, 2.0, 0.2), checkpoint(64, 1.0, 9.0, 0.0)],
                ),
                failed,
            ],
        );
        let c = summarize_evaluations(&[a.clone(), b.clone()]).unwrap();
        assert_eq!(c.summary.passes, 32);
        assert_eq!(c.summary.scenes, 4);
        assert_eq!(c.summary.failed, 1);
        // Ratios at 32 passes: 0.25, 1.5, 0.5 → two better, median 0.5, geometric mean
        // (0.25·1.5·0.5)^(1/3).
        assert_eq!(c.summary.ours_better_equal_time, 2);
        assert_eq!(c.summary.median_ratio_equal_time, Some(0.5));
        let g = c.summary.geomean_ratio_equal_time.unwrap();
        assert!((g - (0.25f64 * 1.5 * 0.5).cbrt()).abs() < 1e-12, "{g}");
        let names: Vec<&str> = c.rows.iter().map(|r| r.scene.as_str()).collect();
        assert_eq!(names, ["room", "glass", "cbox", "broken"]);
        assert_eq!(c.rows[0].ratio_equal_time, Some(0.25));
        assert_eq!(c.rows[2].photons_per_pass, 400_000);
        assert_eq!(c.rows[3].ratio_equal_time, None);
        let table = markdown(&c);
        assert!(
            table.contains("failed: reference has 3 channels"),
            "{table}"
        );
        assert!(
            table.contains("on 2 of 3 scenes (1 failed), median ratio 0.500"),
            "{table}"
        );
        // The JSON written back holds the same rows.
        let out = dir.join("combined.json");
        write_json(&c, &out).unwrap();
        let back: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        assert_eq!(back["rows"].as_array().unwrap().len(), 4);
        assert_eq!(back["summary"]["passes"], 32);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn missing_or_disjoint_evaluations_are_errors_naming_them() {
        let dir = temp_dir("bad");
        let (a, b) = (dir.join("a"), dir.join("b"));
        let err = format!(
            "{:#}",
            summarize_evaluations(std::slice::from_ref(&a)).unwrap_err()
        );
        assert!(err.contains("results.json"), "{err}");
        write_results(&a, 1000, &[8], &[]);
        write_results(&b, 1000, &[16], &[]);
        let err = format!(
            "{:#}",
            summarize_evaluations(&[a.clone(), b.clone()]).unwrap_err()
        );
        assert!(err.contains("share no pass count"), "{err}");
        std::fs::write(b.join("results.json"), "{ not json").unwrap();
        let err = format!("{:#}", summarize_evaluations(&[a, b.clone()]).unwrap_err());
        assert!(
            err.contains(&b.join("results.json").display().to_string()),
            "{err}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
