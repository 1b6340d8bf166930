//! The training curves as a picture: `curves.png` in the output directory, redrawn after every
//! epoch — the training loss by epoch, and the validation relMSE of the reconstruction next to
//! that of every input level (the line the network has to stay under).

use std::path::Path;

use crate::training::EpochReport;
use anyhow::{anyhow, Result};
use plots::{LogAxis, LogTicks, Series};
use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// Picture size in pixels.
const SIZE: (u32, u32) = (1120, 440);
/// Height of the title strip.
const HEADER: u32 = 32;
/// Margin around each panel's chart.
const MARGIN: u32 = 14;
/// Height of the x axis' labels.
const X_LABELS: u32 = 36;

/// One panel: a y-axis title and its lines (inputs dashed: they do not train, they are the
/// bar).
struct Panel {
    /// Title of the y axis.
    y_title: &'static str,
    /// The lines drawn, each a (epoch, value) series with value > 0 and finite.
    lines: Vec<Series>,
}

/// The two panels for `history`: training loss | validation relMSE (output and inputs).
fn panels(history: &[EpochReport], level_names: &[&str; 5]) -> [Panel; 2] {
    let positive = |e: usize, v: f64| (v.is_finite() && v > 0.0).then_some((e as f64, v));
    let loss = Series {
        label: "training loss".into(),
        colour: plots::OURS,
        points: history
            .iter()
            .filter_map(|r| positive(r.epoch, r.train_loss))
            .collect(),
        dashed: false,
    };
    let validated = || {
        history
            .iter()
            .filter_map(|r| Some((r.epoch, r.validation.as_ref()?)))
    };
    let mut relmse = vec![Series {
        label: "reconstruction".into(),
        colour: plots::OURS,
        points: validated()
            .filter_map(|(e, v)| positive(e, v.output))
            .collect(),
        dashed: false,
    }];
    for (l, (name, colour)) in level_names.iter().zip(plots::LEVEL_COLOURS).enumerate() {
        relmse.push(Series {
            label: format!("input {name}"),
            colour,
            points: validated()
                .filter_map(|(e, v)| positive(e, v.levels[l]))
                .collect(),
            dashed: true,
        });
    }
    [
        Panel {
            y_title: "training loss",
            lines: vec![loss],
        },
        Panel {
            y_title: "validation relMSE",
            lines: relmse,
        },
    ]
}

/// Draws `history` into `path` (a PNG), atomically.
pub fn write(path: &Path, title: &str, history: &[EpochReport], levels: &[&str; 5]) -> Result<()> {
    let panels = panels(history, levels);
    plots::write_atomically(path, |tmp| draw(tmp, title, &panels)).map_err(|e| anyhow!(e))
}

/// The y range of a panel holding `values`: `(low, high, log)` — a log axis when the values
/// span more than a factor of 20 (an untrained network's first epochs against the final one),
/// else a linear axis, whose labels stay readable over a narrow range. The top `headroom`
/// fraction of the axis (0..0.9) stays above every value: room for the legend, which then
/// covers no data in an upper corner.
fn y_range(values: impl Iterator<Item = f64>, headroom: f64) -> Option<(f64, f64, bool)> {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if hi <= 0.0 {
        return None;
    }
    let f = headroom.clamp(0.0, 0.9);
    // The top of an axis from `bottom` whose top fraction f lies above `top`.
    let above = |bottom: f64, top: f64| (top - f * bottom) / (1.0 - f);
    if hi / lo > 20.0 {
        let bottom = lo / 1.25;
        // A little room above the highest point even without a legend.
        let top = (hi * 1.25).ln();
        Some((bottom, above(bottom.ln(), top).exp(), true))
    } else {
        let span = (hi - lo).max(0.01 * hi);
        let bottom = (lo - 0.08 * span).max(0.0);
        Some((bottom, above(bottom, hi + 0.08 * span), false))
    }
}

/// Draws the title and the two panels into the PNG at `path`.
fn draw(path: &Path, title: &str, panels: &[Panel; 2]) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let (header, body) = root.split_vertically(HEADER);
    header.titled(title, ("sans-serif", 18))?;
    let last_epoch = panels
        .iter()
        .flat_map(|p| p.lines.iter().flat_map(|l| l.points.iter().map(|q| q.0)))
        .fold(1.0f64, f64::max);
    let x = 0.5..last_epoch + 0.5;
    let plot_height = SIZE.1.saturating_sub(HEADER + 2 * MARGIN + X_LABELS).max(1);
    for (area, panel) in body.split_evenly((1, 2)).iter().zip(panels) {
        let values = panel
            .lines
            .iter()
            .flat_map(|l| l.points.iter().map(|q| q.1));
        // Room for the legend above the data, plus a few pixels of air.
        let (_, legend_height) = plots::legend_size(panel.lines.iter().map(|l| l.label.as_str()))?;
        let headroom = f64::from(legend_height + plots::LEGEND_INSET + 6) / f64::from(plot_height);
        // Nothing to show yet (e.g. no validation split): the panel stays blank.
        let Some((lo, hi, log)) = y_range(values, headroom) else {
            continue;
        };
        let mut builder = ChartBuilder::on(area);
        builder
            .margin(MARGIN)
            .x_label_area_size(X_LABELS)
            .y_label_area_size(72);
        if log {
            let y = LogAxis::new(lo..hi, LogTicks::Decimal, 10);
            let chart = builder.build_cartesian_2d(x.clone(), y)?;
            draw_panel(chart, panel, last_epoch, true)?;
        } else {
            let chart = builder.build_cartesian_2d(x.clone(), lo..hi)?;
            draw_panel(chart, panel, last_epoch, false)?;
        }
    }
    root.present()?;
    Ok(())
}

/// Axes, lines and legend of one panel, whatever its y axis (`log`: a [`LogAxis`], whose
/// light grid lines mark the multiples of each decade).
fn draw_panel<'a, Y>(
    mut chart: ChartContext<'a, BitMapBackend<'a>, Cartesian2d<RangedCoordf64, Y>>,
    panel: &Panel,
    last_epoch: f64,
    log: bool,
) -> Result<(), Box<dyn std::error::Error>>
where
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        // Light lines only where a log axis puts them (2..9 of each decade).
        .light_line_style(BLACK.mix(0.04))
        .x_max_light_lines(0)
        .y_max_light_lines(if log { 10 } else { 0 })
        .x_desc("epoch")
        .y_desc(panel.y_title)
        .x_labels((last_epoch as usize).clamp(2, 12))
        .x_label_formatter(&|e| format!("{e:.0}"))
        .y_labels(8)
        .y_label_formatter(&|v| plots::tick_label(*v))
        .draw()?;
    plots::draw_series(&mut chart, &panel.lines)?;
    plots::draw_legend(&mut chart, &panel.lines, &[SeriesLabelPosition::UpperRight])?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::training::Validation;

    fn report(epoch: usize, loss: f64, output: Option<f64>) -> EpochReport {
        EpochReport {
            epoch,
            train_loss: loss,
            validation: output.map(|o| Validation {
                output: o,
                levels: [0.4, 0.2, 0.1, f64::NAN, 0.0],
                images: Vec::new(),
            }),
            patches: 10,
            seconds: 1.0,
        }
    }

    /// The panels hold one point per epoch and skip what a log axis cannot show (a NaN
    /// level, a zero relMSE, an epoch without validation).
    #[test]
    fn panels_keep_only_loggable_points() {
        let history = [
            report(1, 0.9, Some(0.3)),
            report(2, 0.8, None),
            report(3, 0.7, Some(0.25)),
        ];
        let [loss, val] = panels(&history, &["y", "z1", "z2", "z3", "z4"]);
        assert_eq!(loss.lines.len(), 1);
        assert_eq!(
            loss.lines[0].points,
            vec![(1.0, 0.9), (2.0, 0.8), (3.0, 0.7)]
        );
        assert_eq!(val.lines.len(), 6);
        assert_eq!(val.lines[0].points, vec![(1.0, 0.3), (3.0, 0.25)]);
        assert_eq!(val.lines[1].points, vec![(1.0, 0.4), (3.0, 0.4)]);
        assert!(val.lines[4].points.is_empty(), "NaN level");
        assert!(val.lines[5].points.is_empty(), "zero level");
        assert_eq!(val.lines[3].label, "input z2");
        assert!(val.lines[3].dashed && !val.lines[0].dashed);
    }

    /// The y range leaves the asked-for top fraction above every value (room for the
    /// legend), on a linear axis for a narrow range and a log axis for a wide one.
    #[test]
    fn y_range_leaves_headroom_for_the_legend() {
        let (lo, hi, log) = y_range([0.05, 0.1, 0.76].into_iter(), 0.4).unwrap();
        assert!(!log);
        assert!((0.0..0.05).contains(&lo), "{lo}");
        assert!((hi - 0.76) / (hi - lo) >= 0.4 - 1e-9, "{lo}..{hi}");
        let (lo, hi, log) = y_range([0.01, 0.5, 2.0].into_iter(), 0.3).unwrap();
        assert!(log);
        assert!(lo < 0.01);
        let top = (hi.ln() - 2f64.ln()) / (hi.ln() - lo.ln());
        assert!(top >= 0.3 - 1e-9, "{lo}..{hi}");
        assert!(y_range(std::iter::empty(), 0.3).is_none());
    }

    /// A PNG of the right size is written in place, with no temp file left behind.
    #[test]
    fn writes_a_png_atomically() {
        let dir = std::env::temp_dir().join(format!("curves-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("curves.png");
        let history = [report(1, 0.9, Some(0.3)), report(2, 0.8, Some(0.2))];
        write(&path, "test run", &history, &["y", "z1", "z2", "z3", "z4"]).unwrap();
        let png = image::open(&path).unwrap();
        assert_eq!((png.width(), png.height()), SIZE);
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, vec!["curves.png".to_string()]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
