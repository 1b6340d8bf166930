//! Plots the relMSE-vs-passes curves written by the `sppm_convergence` example (one panel per
//! CSV, one line per level, log–log axes, the target as a dashed line) into a PNG for
//! docs/validation.md (issue 3, must-show 1).
//!
//! ```text
//! cargo run --release -p renderer --example convergence_plot -- \
//!     --out docs/img/sppm_convergence.png \
//!     "cornell-diffuse=out/conv/cornell.csv" "glass-mirror-spheres=out/conv/glass.csv"
//! ```

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Parser;
use plotters::prelude::*;

/// Plot SPPM convergence curves (relMSE per level against passes).
#[derive(Parser, Debug)]
#[command()]
struct Args {
    /// Panels as `title=path.csv` (CSV: passes,seconds,y,z1,z2,z3,z4 with a header line).
    #[arg(required = true)]
    panels: Vec<String>,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Target relMSE drawn as a dashed line.
    #[arg(long, default_value_t = 3e-3)]
    target: f64,
}

/// One CSV: level names and rows of (passes, relMSE per level).
struct Curves {
    levels: Vec<String>,
    rows: Vec<(f64, Vec<f64>)>,
}

fn read_csv(path: &std::path::Path) -> Result<Curves> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .with_context(|| format!("{}: empty file", path.display()))?
        .split(',')
        .collect();
    if header.len() < 3 || header[0] != "passes" || header[1] != "seconds" {
        bail!(
            "{}: line 1: expected a header `passes,seconds,<levels…>`",
            path.display()
        );
    }
    let levels: Vec<String> = header[2..].iter().map(|s| s.to_string()).collect();
    let mut rows = Vec::new();
    for (i, line) in lines.enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let values: Vec<f64> = line
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("{}: line {}: malformed number", path.display(), i + 2))?;
        if values.len() != header.len() {
            bail!(
                "{}: line {}: {} values, expected {}",
                path.display(),
                i + 2,
                values.len(),
                header.len()
            );
        }
        rows.push((values[0], values[2..].to_vec()));
    }
    if rows.is_empty() {
        bail!("{}: no data rows", path.display());
    }
    Ok(Curves { levels, rows })
}

fn main() -> Result<()> {
    let args = Args::parse();
    let mut panels = Vec::new();
    for p in &args.panels {
        let (title, path) = p
            .split_once('=')
            .with_context(|| format!("panel `{p}`: expected title=path.csv"))?;
        panels.push((title.to_string(), read_csv(path.as_ref())?));
    }
    let (mut lo, mut hi) = (args.target, args.target);
    let (mut pmin, mut pmax) = (f64::INFINITY, 0.0f64);
    for (_, c) in &panels {
        for (p, v) in &c.rows {
            pmin = pmin.min(*p);
            pmax = pmax.max(*p);
            for &e in v {
                lo = lo.min(e);
                hi = hi.max(e);
            }
        }
    }
    let (lo, hi) = (lo / 1.5, hi * 1.5);
    let (pmin, pmax) = (pmin / 1.2, pmax * 1.2);
    let width = 560 * panels.len() as u32;
    // The text's font is embedded (no system fonts needed).
    plots::register_font().map_err(anyhow::Error::msg)?;
    let root = BitMapBackend::new(&args.out, (width, 460)).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((1, panels.len()));
    let colours = [
        RGBColor(0xd6, 0x27, 0x28),
        RGBColor(0xff, 0x7f, 0x0e),
        RGBColor(0x2c, 0xa0, 0x2c),
        RGBColor(0x1f, 0x77, 0xb4),
        RGBColor(0x94, 0x67, 0xbd),
    ];
    for ((title, curves), area) in panels.iter().zip(&areas) {
        let mut chart = ChartBuilder::on(area)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d((pmin..pmax).log_scale(), (lo..hi).log_scale())?;
        chart
            .configure_mesh()
            // Log axes: the minor grid lines of plotters crowd the decades; keep the major ones.
            .light_line_style(TRANSPARENT)
            .x_labels(6)
            .x_desc("passes")
            .y_desc("relMSE (4x4 downsampled)")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()?;
        chart.draw_series(DashedLineSeries::new(
            [(pmin, args.target), (pmax, args.target)],
            6,
            4,
            BLACK.stroke_width(1),
        ))?;
        for (l, name) in curves.levels.iter().enumerate() {
            let colour = colours[l % colours.len()];
            let pts: Vec<(f64, f64)> = curves.rows.iter().map(|(p, v)| (*p, v[l])).collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))?
                .label(name.as_str())
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(2))
                });
            chart.draw_series(pts.into_iter().map(|p| Circle::new(p, 3, colour.filled())))?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}
