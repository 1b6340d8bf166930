//! `evaluate --schedules SPPM_DIR CPPM_DIR`: the paper's SPPM-against-CPPM comparison (its Fig.
//! 8 and Table 2) from two finished evaluations of the same scenes, settings and seed, one with
//! `schedule = "sppm"` and one with `"cppm"`: per scene a log-log figure of the four curves and
//! a Markdown table of the ratios at each pass count.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::compare::{relmse_at_time, CurvePoint, Interpolated};
use crate::scene::SceneEval;
use crate::SceneResult;

/// The part of an evaluation's `results.json` this needs.
#[derive(Deserialize)]
struct Stored {
    config: StoredConfig,
    scenes: Vec<SceneResult>,
}

#[derive(Deserialize)]
struct StoredConfig {
    #[serde(default)]
    schedule: renderer::integrators::sppm::RadiusSchedule,
    photons_per_pass: u64,
    seed: u64,
}

/// One scene at one pass count.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ScheduleRow {
    /// Scene name.
    pub scene: String,
    /// Passes of the multi-level runs.
    pub passes: u32,
    /// Standard CPPM ÷ standard SPPM (single level), CPPM's curve read at the time standard SPPM
    /// took for `passes` passes.
    pub cppm_over_sppm: Option<f64>,
    /// Ours + CPPM ÷ standard CPPM at equal time (the CPPM evaluation's ratio).
    pub ours_cppm_over_cppm: f64,
    /// Ours + CPPM ÷ ours + SPPM, ours + CPPM interpolated log-log to ours + SPPM's total time.
    pub ours_cppm_over_ours_sppm: f64,
    /// That interpolation left ours + CPPM's checkpoints (its nearest one is used).
    pub extrapolated: bool,
    /// Multi-level overhead per pass of each schedule's run (CPPM, SPPM).
    pub overhead: (Option<f64>, Option<f64>),
}

/// Reads `<dir>/results.json`, checking its schedule.
fn load(dir: &Path, expected: renderer::integrators::sppm::RadiusSchedule) -> Result<Stored> {
    let path = dir.join("results.json");
    let text = std::fs::read_to_string(&path).with_context(|| path.display().to_string())?;
    let stored: Stored = serde_json::from_str(&text)
        .with_context(|| format!("{}: not an evaluation's results", path.display()))?;
    if stored.config.schedule != expected {
        bail!(
            "{}: an evaluation with schedule `{}`, expected `{}`",
            path.display(),
            stored.config.schedule.name(),
            expected.name()
        );
    }
    Ok(stored)
}

/// The ratios of one scene evaluated under both schedules.
pub fn scene_rows(name: &str, sppm: &SceneEval, cppm: &SceneEval) -> Vec<ScheduleRow> {
    let ours_cppm: Vec<CurvePoint> = cppm
        .checkpoints
        .iter()
        .map(|c| CurvePoint {
            passes: c.passes,
            seconds: c.total_seconds,
            relmse: c.ours_relmse,
        })
        .collect();
    let mut rows = Vec::new();
    for s in &sppm.checkpoints {
        let Some(c) = cppm.checkpoints.iter().find(|c| c.passes == s.passes) else {
            continue;
        };
        let cppm_over_sppm = sppm
            .standard
            .iter()
            .find(|p| p.passes == s.passes)
            .and_then(|p| relmse_at_time(&cppm.standard, p.seconds).map(|i| i.relmse / p.relmse));
        let Some(Interpolated {
            relmse,
            extrapolated,
        }) = relmse_at_time(&ours_cppm, s.total_seconds)
        else {
            continue;
        };
        rows.push(ScheduleRow {
            scene: name.to_owned(),
            passes: s.passes,
            cppm_over_sppm,
            ours_cppm_over_cppm: c.ratio_equal_time,
            ours_cppm_over_ours_sppm: relmse / s.ours_relmse,
            extrapolated,
            overhead: (c.overhead, s.overhead),
        });
    }
    rows
}

/// Reads both evaluations, writes `<out>/<scene>_schedules.png` for every scene evaluated
/// under both, and returns the rows (scenes in the SPPM evaluation's order).
pub fn compare_schedules(sppm_dir: &Path, cppm_dir: &Path, out: &Path) -> Result<Vec<ScheduleRow>> {
    use renderer::integrators::sppm::RadiusSchedule;
    let sppm = load(sppm_dir, RadiusSchedule::Sppm)?;
    let cppm = load(cppm_dir, RadiusSchedule::Cppm)?;
    if (sppm.config.photons_per_pass, sppm.config.seed)
        != (cppm.config.photons_per_pass, cppm.config.seed)
    {
        bail!(
            "{} and {} were run with other photons per pass or seeds ({} / {} against {} / {}): \
             not the same study",
            sppm_dir.display(),
            cppm_dir.display(),
            sppm.config.photons_per_pass,
            sppm.config.seed,
            cppm.config.photons_per_pass,
            cppm.config.seed
        );
    }
    std::fs::create_dir_all(out).with_context(|| out.display().to_string())?;
    let mut rows = Vec::new();
    for s in &sppm.scenes {
        let Some(c) = cppm.scenes.iter().find(|c| c.name == s.name) else {
            continue;
        };
        let (Some(se), Some(ce)) = (&s.eval, &c.eval) else {
            continue;
        };
        let stem: String = s
            .name
            .chars()
            .map(|ch| {
                if ch.is_ascii_alphanumeric() || ch == '-' {
                    ch
                } else {
                    '_'
                }
            })
            .collect();
        crate::plot::write_schedules_plot(
            &out.join(format!("{stem}_schedules.png")),
            &format!("{} — SPPM and CPPM, relMSE (log-log)", s.name),
            se,
            ce,
        )?;
        rows.extend(scene_rows(&s.name, se, ce));
    }
    if rows.is_empty() {
        bail!(
            "{} and {} share no evaluated scene",
            sppm_dir.display(),
            cppm_dir.display()
        );
    }
    Ok(rows)
}

/// The rows as the Markdown table of docs/results.md.
pub fn markdown(rows: &[ScheduleRow]) -> String {
    let pct = |o: Option<f64>| o.map_or_else(|| "–".into(), |v| format!("{:+.0} %", 100.0 * v));
    let mut out = String::from(
        "| scene, passes | CPPM ÷ SPPM | ours + CPPM ÷ CPPM | ours + CPPM ÷ ours + SPPM | overhead CPPM / SPPM |\n|---|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {}, {} | {} | {:.3} | {:.3}{} | {} / {} |\n",
            r.scene,
            r.passes,
            r.cppm_over_sppm
                .map_or_else(|| "–".into(), |v| format!("{v:.3}")),
            r.ours_cppm_over_cppm,
            r.ours_cppm_over_ours_sppm,
            if r.extrapolated { "*" } else { "" },
            pct(r.overhead.0),
            pct(r.overhead.1)
        ));
    }
    out
}

/// Writes the rows as JSON, atomically.
pub fn write_json(rows: &[ScheduleRow], path: &Path) -> Result<()> {
    crate::images::write_atomic(path, serde_json::to_string_pretty(rows)?.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::fixtures::{checkpoint, scene};

    /// A power-law curve relMSE = a / passes at one pass per `dt` seconds.
    fn curve(a: f64, dt: f64) -> Vec<CurvePoint> {
        [1u32, 4, 16, 64, 256]
            .iter()
            .map(|&p| CurvePoint {
                passes: p,
                seconds: dt * f64::from(p),
                relmse: a / f64::from(p),
            })
            .collect()
    }

    /// A scene whose ours reaches `ours` at 16 and 64 passes at the times given.
    fn evaluated(name: &str, standard: Vec<CurvePoint>, ours: [(f64, f64); 2]) -> SceneResult {
        let mut s = scene(
            name,
            vec![
                crate::scene::Checkpoint {
                    total_seconds: ours[0].0,
                    overhead: Some(0.1),
                    ..checkpoint(16, ours[0].1)
                },
                crate::scene::Checkpoint {
                    total_seconds: ours[1].0,
                    overhead: Some(0.3),
                    ..checkpoint(64, ours[1].1)
                },
            ],
        );
        s.eval.as_mut().unwrap().standard = standard;
        s
    }

    #[test]
    fn ratios_are_read_at_equal_time() {
        // CPPM's curve is SPPM's halved at equal time; ours + CPPM is a power law in time
        // through (2 s, 0.04) and (8 s, 0.01), read at ours + SPPM's 4 s: 0.02.
        let sppm = evaluated("a", curve(1.0, 0.1), [(4.0, 0.05), (16.0, 0.01)]);
        let cppm = evaluated("a", curve(0.5, 0.1), [(2.0, 0.04), (8.0, 0.01)]);
        let rows = scene_rows(
            "a",
            sppm.eval.as_ref().unwrap(),
            cppm.eval.as_ref().unwrap(),
        );
        assert_eq!(rows.len(), 2);
        let r = &rows[0];
        assert_eq!(r.passes, 16);
        assert!((r.cppm_over_sppm.unwrap() - 0.5).abs() < 1e-12, "{r:?}");
        assert!(
            (r.ours_cppm_over_ours_sppm - 0.02 / 0.05).abs() < 1e-12,
            "{r:?}"
        );
        assert!(!r.extrapolated);
        assert_eq!(r.ours_cppm_over_cppm, 0.04);
        assert_eq!(r.overhead, (Some(0.1), Some(0.1)));
        // At 64 passes ours + SPPM took 16 s, past ours + CPPM's last checkpoint (8 s).
        assert!(rows[1].extrapolated);
        let table = markdown(&rows);
        assert!(
            table.contains("| a, 16 | 0.500 | 0.040 | 0.400 | +10 % / +10 % |"),
            "{table}"
        );
        assert!(
            table.contains("| a, 64 | 0.500 | 0.010 | 1.000* |"),
            "{table}"
        );
    }

    fn write(dir: &Path, schedule: &str, seed: u64, scenes: &[SceneResult]) {
        std::fs::create_dir_all(dir).unwrap();
        let json = serde_json::json!({
            "config": {"photons_per_pass": 1000, "seed": seed, "schedule": schedule},
            "scenes": scenes,
        });
        std::fs::write(dir.join("results.json"), json.to_string()).unwrap();
    }

    #[test]
    fn writes_a_figure_per_shared_scene_and_refuses_other_studies() {
        let dir = std::env::temp_dir().join(format!("schedules-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let (s, c, out) = (dir.join("s"), dir.join("c"), dir.join("out"));
        let a = evaluated("a", curve(1.0, 0.1), [(4.0, 0.05), (16.0, 0.01)]);
        let b = evaluated("b/c", curve(1.0, 0.1), [(4.0, 0.05), (16.0, 0.01)]);
        write(&s, "sppm", 7, &[a.clone(), b.clone()]);
        write(&c, "cppm", 7, std::slice::from_ref(&b));
        let rows = compare_schedules(&s, &c, &out).unwrap();
        assert!(
            rows.iter().all(|r| r.scene == "b/c"),
            "only the shared scene"
        );
        assert!(out.join("b_c_schedules.png").is_file());
        assert!(!out.join("a_schedules.png").exists());
        // Swapped directories, another seed: errors naming the file and the reason.
        let err = compare_schedules(&c, &s, &out).unwrap_err().to_string();
        assert!(err.contains("schedule `cppm`, expected `sppm`"), "{err}");
        write(&c, "cppm", 8, &[b]);
        let err = compare_schedules(&s, &c, &out).unwrap_err().to_string();
        assert!(err.contains("not the same study"), "{err}");
    }
}
