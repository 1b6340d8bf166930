//! Convergence plots (paper Fig. 8) with plotters: relMSE against wall time and against
//! passes on log-log axes, for standard SPPM, ours and every input level.

use std::path::Path;

use anyhow::{anyhow, Result};
use plots::{LogAxis, LogTicks, Series, LEVEL_COLOURS, OURS, STANDARD};
use plotters::prelude::*;

use crate::scene::SceneEval;
use infer::report::LEVEL_NAMES;

/// Positive finite points only (a log axis cannot show the rest).
fn loggable(points: impl IntoIterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    points
        .into_iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite() && *x > 0.0 && *y > 0.0)
        .collect()
}

/// The curves of one panel; `by_time` picks the x axis (seconds, else passes). The input
/// levels are dashed (they are the bar, not a result). `method`: the progressive method,
/// `SPPM` or `CPPM`.
fn curves(eval: &SceneEval, by_time: bool, method: &str) -> Vec<Series> {
    let x = |seconds: f64, passes: u32| if by_time { seconds } else { passes as f64 };
    let mut out = vec![Series {
        label: format!("standard {method}"),
        colour: STANDARD,
        points: loggable(
            eval.standard
                .iter()
                .map(|p| (x(p.seconds, p.passes), p.relmse)),
        ),
        dashed: false,
    }];
    out.push(Series {
        label: if by_time {
            "ours (render + inference)".into()
        } else {
            "ours".into()
        },
        colour: OURS,
        points: loggable(
            eval.checkpoints
                .iter()
                .map(|c| (x(c.total_seconds, c.passes), c.ours_relmse)),
        ),
        dashed: false,
    });
    for (l, name) in LEVEL_NAMES.iter().enumerate() {
        out.push(Series {
            label: format!("input {name}"),
            colour: LEVEL_COLOURS[l],
            points: loggable(
                eval.checkpoints
                    .iter()
                    .map(|c| (x(c.render_seconds, c.passes), c.level_relmse[l])),
            ),
            dashed: true,
        });
    }
    out
}

/// Writes the two-panel plot (relMSE vs seconds | relMSE vs passes) as a PNG, atomically;
/// `method` (`SPPM` or `CPPM`) names the standard curve.
pub fn write_convergence_plot(
    path: &Path,
    title: &str,
    eval: &SceneEval,
    method: &str,
) -> Result<()> {
    plots::write_atomically(path, |tmp| {
        draw(tmp, title, |by_time| curves(eval, by_time, method))
    })
    .map_err(|e| anyhow!(e))
}

/// The curves of the paper's SPPM-against-CPPM figure (its Fig. 8): standard SPPM and CPPM
/// (single level), ours on each (render + inference against seconds); CPPM's dashed.
fn schedule_curves(sppm: &SceneEval, cppm: &SceneEval, by_time: bool) -> Vec<Series> {
    let x = |seconds: f64, passes: u32| if by_time { seconds } else { passes as f64 };
    let standard = |eval: &SceneEval| {
        loggable(
            eval.standard
                .iter()
                .map(|p| (x(p.seconds, p.passes), p.relmse)),
        )
    };
    let ours = |eval: &SceneEval| {
        loggable(
            eval.checkpoints
                .iter()
                .map(|c| (x(c.total_seconds, c.passes), c.ours_relmse)),
        )
    };
    vec![
        Series {
            label: "SPPM".into(),
            colour: STANDARD,
            points: standard(sppm),
            dashed: false,
        },
        Series {
            label: "CPPM".into(),
            colour: STANDARD,
            points: standard(cppm),
            dashed: true,
        },
        Series {
            label: "ours + SPPM".into(),
            colour: OURS,
            points: ours(sppm),
            dashed: false,
        },
        Series {
            label: "ours + CPPM".into(),
            colour: OURS,
            points: ours(cppm),
            dashed: true,
        },
    ]
}

/// Writes the SPPM-against-CPPM plot of one scene (relMSE vs seconds | vs passes), atomically.
pub fn write_schedules_plot(
    path: &Path,
    title: &str,
    sppm: &SceneEval,
    cppm: &SceneEval,
) -> Result<()> {
    plots::write_atomically(path, |tmp| {
        draw(tmp, title, |by_time| schedule_curves(sppm, cppm, by_time))
    })
    .map_err(|e| anyhow!(e))
}

/// The log axes of one panel holding `points`: x (seconds, decimal ticks; or passes, powers
/// of two) and relMSE, padded so that no marker sits on the frame. `None` without points.
fn axes(points: &[(f64, f64)], by_time: bool) -> Option<(LogAxis, LogAxis)> {
    if points.is_empty() {
        return None;
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, 0.0f64, f64::MAX, 0.0f64);
    for (x, y) in points {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    let x_ticks = if by_time {
        LogTicks::Decimal
    } else {
        LogTicks::Binary
    };
    Some((
        LogAxis::new(x0 / 1.2..x1 * 1.2, x_ticks, 8),
        LogAxis::new(y0 / 1.5..y1 * 1.5, LogTicks::Decimal, 10),
    ))
}

/// Draws the two panels of the curves `panel(by_time)` gives.
fn draw(
    path: &Path,
    title: &str,
    panel: impl Fn(bool) -> Vec<Series>,
) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (1120, 460)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, body) = root.split_vertically(30);
    top.titled(title, ("sans-serif", 20))?;
    let areas = body.split_evenly((1, 2));
    for (area, by_time) in areas.iter().zip([true, false]) {
        let cs = panel(by_time);
        let all: Vec<(f64, f64)> = cs.iter().flat_map(|c| c.points.iter().copied()).collect();
        let Some((x_axis, y_axis)) = axes(&all, by_time) else {
            continue;
        };
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x_axis, y_axis)?;
        chart
            .configure_mesh()
            // Light lines at the 2..9 multiples of each decade show the log scale.
            .light_line_style(BLACK.mix(0.04))
            .x_desc(if by_time { "seconds" } else { "passes" })
            .y_desc("relMSE")
            .draw()?;
        plots::draw_series(&mut chart, &cs)?;
        // Curves fall from the upper left to the lower right: the lower left is usually free.
        plots::draw_legend(
            &mut chart,
            &cs,
            &[
                SeriesLabelPosition::LowerLeft,
                SeriesLabelPosition::UpperRight,
            ],
        )?;
    }
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The passes panel labels powers of two, the seconds and relMSE axes 1-2-5 steps inside
    /// their decades (the ranges of a short evaluation: 8..64 passes, 0.003..0.05 s, relMSE
    /// 0.3..5.6).
    #[test]
    fn axes_label_inside_the_decades() {
        let passes = [(8.0, 5.6), (16.0, 2.0), (32.0, 0.9), (64.0, 0.3)];
        let (x, y) = axes(&passes, false).unwrap();
        assert_eq!(x.labels(), [8.0, 16.0, 32.0, 64.0]);
        assert_eq!(y.labels(), [0.2, 0.5, 1.0, 2.0, 5.0]);
        let seconds = [(0.003, 5.6), (0.05, 0.3)];
        let (x, _) = axes(&seconds, true).unwrap();
        assert_eq!(x.labels(), [0.005, 0.01, 0.02, 0.05]);
        assert!(axes(&[], true).is_none());
    }
}
