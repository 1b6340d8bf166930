//! Convergence plots (paper Fig. 8) with plotters: relMSE against wall time and against
//! passes on log-log axes, for standard SPPM, ours and every input level.

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;

use super::scene::SceneEval;
use crate::report::LEVEL_NAMES;
use plots::{LEVEL_COLOURS, OURS, STANDARD};

/// One curve: label, colour, points (x, relMSE), dashed or solid.
struct Curve {
    label: String,
    colour: RGBColor,
    points: Vec<(f64, f64)>,
    dashed: bool,
}

/// Positive finite points only (a log axis cannot show the rest).
fn loggable(points: impl IntoIterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    points
        .into_iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite() && *x > 0.0 && *y > 0.0)
        .collect()
}

/// The curves of one panel; `by_time` picks the x axis (seconds, else passes).
fn curves(eval: &SceneEval, by_time: bool) -> Vec<Curve> {
    let x = |seconds: f64, passes: u32| if by_time { seconds } else { passes as f64 };
    let mut out = vec![Curve {
        label: "standard SPPM".into(),
        colour: STANDARD,
        points: loggable(
            eval.standard
                .iter()
                .map(|p| (x(p.seconds, p.passes), p.relmse)),
        ),
        dashed: false,
    }];
    out.push(Curve {
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
        out.push(Curve {
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

/// Writes the two-panel plot (relMSE vs seconds | relMSE vs passes) as a PNG, atomically.
pub fn write_convergence_plot(path: &Path, title: &str, eval: &SceneEval) -> Result<()> {
    plots::write_atomically(path, |tmp| draw(tmp, title, eval)).map_err(|e| anyhow!(e))
}

fn draw(path: &Path, title: &str, eval: &SceneEval) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (1120, 460)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, body) = root.split_vertically(30);
    top.titled(title, ("sans-serif", 20))?;
    let areas = body.split_evenly((1, 2));
    for (area, by_time) in areas.iter().zip([true, false]) {
        let cs = curves(eval, by_time);
        let all: Vec<(f64, f64)> = cs.iter().flat_map(|c| c.points.iter().copied()).collect();
        if all.is_empty() {
            continue;
        }
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, 0.0f64, f64::MAX, 0.0f64);
        for (x, y) in &all {
            x0 = x0.min(*x);
            x1 = x1.max(*x);
            y0 = y0.min(*y);
            y1 = y1.max(*y);
        }
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (x0 / 1.2..x1 * 1.2).log_scale(),
                (y0 / 1.5..y1 * 1.5).log_scale(),
            )?;
        chart
            .configure_mesh()
            // Log axes: plotters' minor grid lines crowd the decades; keep the major ones.
            .light_line_style(TRANSPARENT)
            .x_labels(8)
            .y_labels(8)
            .x_desc(if by_time { "seconds" } else { "passes" })
            .y_desc("relMSE")
            .x_label_formatter(&|v| {
                if *v >= 10.0 {
                    format!("{v:.0}")
                } else {
                    format!("{v:.2}")
                }
            })
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()?;
        for c in cs {
            let colour = c.colour;
            let width = if c.dashed { 1 } else { 2 };
            let style = colour.stroke_width(width);
            let anno = if c.dashed {
                chart.draw_series(DashedLineSeries::new(c.points.clone(), 5, 4, style))?
            } else {
                chart.draw_series(LineSeries::new(c.points.clone(), style))?
            };
            anno.label(c.label).legend(move |(x, y)| {
                PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(width))
            });
            let marker = if c.dashed { 2 } else { 3 };
            chart.draw_series(
                c.points
                    .into_iter()
                    .map(|p| Circle::new(p, marker, colour.filled())),
            )?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .draw()?;
    }
    root.present()?;
    Ok(())
}
