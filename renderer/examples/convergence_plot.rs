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
            .build_cartesian_2d(
                plots::LogAxis::new(pmin..pmax, plots::LogTicks::Binary, 8),
                plots::LogAxis::new(lo..hi, plots::LogTicks::Decimal, 10),
            )?;
        chart
            .configure_mesh()
            // Light lines at the 2..9 multiples of each decade show the log scale.
            .light_line_style(BLACK.mix(0.04))
            .x_desc("passes")
            .y_desc("relMSE (4x4 downsampled)")
            .draw()?;
        let mut series: Vec<plots::Series> = curves
            .levels
            .iter()
            .enumerate()
            .map(|(l, name)| plots::Series {
                label: name.clone(),
                colour: colours[l % colours.len()],
                points: curves.rows.iter().map(|(p, v)| (*p, v[l])).collect(),
                dashed: false,
            })
            .collect();
        plots::draw_series(&mut chart, &series).map_err(|e| anyhow::anyhow!("{e}"))?;
        // The target: a dashed black line without markers, named in the legend.
        let target = plots::Series {
            label: "target".into(),
            colour: BLACK,
            points: vec![(pmin, args.target), (pmax, args.target)],
            dashed: true,
        };
        chart
            .draw_series(DashedLineSeries::new(
                target.points.clone(),
                plots::DASH.0,
                plots::DASH.1,
                target.stroke(),
            ))?
            .label("target")
            .legend(plots::swatch(target.stroke(), true));
        series.push(target);
        plots::draw_legend(&mut chart, &series, &[SeriesLabelPosition::UpperRight])
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    root.present()
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}
