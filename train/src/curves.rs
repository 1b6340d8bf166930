//! The training curves as a picture: `curves.png` in the output directory, redrawn after every
//! epoch — the training loss by epoch, and the validation relMSE of the reconstruction next to
//! that of every input level (the line the network has to stay under).

use std::path::Path;

use anyhow::{anyhow, Result};
use model::training::EpochReport;
use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// Picture size in pixels.
const SIZE: (u32, u32) = (1120, 440);

/// One line of a panel.
struct Line {
    /// Legend text.
    name: String,
    /// Stroke colour.
    colour: RGBColor,
    /// (epoch, value) with value > 0 and finite.
    points: Vec<(f64, f64)>,
    /// Inputs are dashed: they do not train, they are the bar.
    dashed: bool,
}

/// One panel: a y-axis title and its lines.
struct Panel {
    /// Title of the y axis.
    y_title: &'static str,
    /// The lines drawn.
    lines: Vec<Line>,
}

/// The two panels for `history`: training loss | validation relMSE (output and inputs).
fn panels(history: &[EpochReport], level_names: &[&str; 5]) -> [Panel; 2] {
    let positive = |e: usize, v: f64| (v.is_finite() && v > 0.0).then_some((e as f64, v));
    let loss = Line {
        name: "training loss".into(),
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
    let mut relmse = vec![Line {
        name: "reconstruction".into(),
        colour: plots::OURS,
        points: validated()
            .filter_map(|(e, v)| positive(e, v.output))
            .collect(),
        dashed: false,
    }];
    for (l, (name, colour)) in level_names.iter().zip(plots::LEVEL_COLOURS).enumerate() {
        relmse.push(Line {
            name: format!("input {name}"),
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
/// else a linear axis, whose labels stay readable over a narrow range.
fn y_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64, bool)> {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if hi <= 0.0 {
        return None;
    }
    if hi / lo > 20.0 {
        Some((lo / 1.25, hi * 4.0, true))
    } else {
        // Headroom above the highest line for the legend (upper right).
        let span = (hi - lo).max(0.01 * hi);
        Some(((lo - 0.08 * span).max(0.0), hi + 0.45 * span, false))
    }
}

/// Draws the title and the two panels into the PNG at `path`.
fn draw(path: &Path, title: &str, panels: &[Panel; 2]) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let (header, body) = root.split_vertically(32);
    header.titled(title, ("sans-serif", 18))?;
    let last_epoch = panels
        .iter()
        .flat_map(|p| p.lines.iter().flat_map(|l| l.points.iter().map(|q| q.0)))
        .fold(1.0f64, f64::max);
    let x = 0.5..last_epoch + 0.5;
    for (area, panel) in body.split_evenly((1, 2)).iter().zip(panels) {
        let values = panel
            .lines
            .iter()
            .flat_map(|l| l.points.iter().map(|q| q.1));
        // Nothing to show yet (e.g. no validation split): the panel stays blank.
        let Some((lo, hi, log)) = y_range(values) else {
            continue;
        };
        let mut builder = ChartBuilder::on(area);
        builder
            .margin(14)
            .x_label_area_size(36)
            .y_label_area_size(72);
        if log {
            let chart = builder.build_cartesian_2d(x.clone(), (lo..hi).log_scale())?;
            draw_panel(chart, panel, last_epoch)?;
        } else {
            let chart = builder.build_cartesian_2d(x.clone(), lo..hi)?;
            draw_panel(chart, panel, last_epoch)?;
        }
    }
    root.present()?;
    Ok(())
}

/// A y tick as a person writes it: four significant digits without trailing zeros between
/// 0.01 and 1000, scientific notation outside.
fn tick_label(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let magnitude = v.abs().log10().floor();
    if !(-2.0..3.0).contains(&magnitude) {
        return format!("{v:.2e}");
    }
    let text = format!("{v:.*}", (3.0 - magnitude) as usize);
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Axes, lines and legend of one panel, whatever its y axis.
fn draw_panel<'a, Y>(
    mut chart: ChartContext<'a, BitMapBackend<'a>, Cartesian2d<RangedCoordf64, Y>>,
    panel: &Panel,
    last_epoch: f64,
) -> Result<(), Box<dyn std::error::Error>>
where
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .light_line_style(TRANSPARENT)
        .x_desc("epoch")
        .y_desc(panel.y_title)
        .x_labels((last_epoch as usize).clamp(2, 12))
        .x_label_formatter(&|e| format!("{e:.0}"))
        .y_labels(8)
        .y_label_formatter(&|v| tick_label(*v))
        .draw()?;
    for line in &panel.lines {
        let colour = line.colour;
        let stroke = colour.stroke_width(if line.dashed { 1 } else { 2 });
        let series = if line.dashed {
            chart.draw_series(DashedLineSeries::new(line.points.clone(), 6, 4, stroke))?
        } else {
            chart.draw_series(LineSeries::new(line.points.clone(), stroke))?
        };
        series
            .label(line.name.as_str())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], stroke));
        // Markers make a single epoch (and each measured point) visible.
        chart.draw_series(
            line.points
                .iter()
                .map(|&p| Circle::new(p, 2, colour.filled())),
        )?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 12))
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::training::Validation;

    fn report(epoch: usize, loss: f64, output: Option<f64>) -> EpochReport {
        EpochReport {
            epoch,
            train_loss: loss,
            validation: output.map(|o| Validation {
                output: o,
                levels: [0.4, 0.2, 0.1, f64::NAN, 0.0],
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
        assert_eq!(val.lines[3].name, "input z2");
    }

    /// Tick labels read as numbers a person would write.
    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(tick_label(0.8), "0.8");
        assert_eq!(tick_label(0.1285), "0.1285");
        assert_eq!(tick_label(0.128), "0.128");
        assert_eq!(tick_label(2.5), "2.5");
        assert_eq!(tick_label(120.0), "120");
        assert_eq!(tick_label(0.0123), "0.0123");
        assert_eq!(tick_label(0.004), "4.00e-3");
        assert_eq!(tick_label(25000.0), "2.50e4");
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
