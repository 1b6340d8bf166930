//! `bundle_info`: prints a sample bundle's metadata and per-layer statistics, and optionally
//! writes each estimate level (and the G-buffer) as an sRGB PNG for a quick look, or one level
//! as a plain RGB EXR (e.g. a long single-level render as a reference image).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use bundle::{read_bundle, Bundle, Image, LEVEL_NAMES};
use clap::Parser;
use fileio::srgb::encode8;

/// Inspect a multi-level SPPM sample bundle (docs/formats.md).
#[derive(Parser, Debug)]
#[command(version)]
struct Args {
    /// Bundle EXR written by `render --integrator sppm-ml|sppm`.
    bundle: PathBuf,
    /// Write `<prefix>_<layer>.png` for y, z1..z4, albedo, normal and depth.
    #[arg(long)]
    png: Option<PathBuf>,
    /// Exposure in stops applied to the estimate PNGs (needs --png).
    #[arg(
        long,
        default_value_t = 0.0,
        requires = "png",
        allow_hyphen_values = true
    )]
    exposure: f32,
    /// Write level LEVEL (y, z1..z4) as a plain RGB float EXR to FILE, e.g. `--exr y ref.exr`
    /// to use a long `render --integrator sppm` run as a reference.
    #[arg(long, num_args = 2, value_names = ["LEVEL", "FILE"])]
    exr: Option<Vec<String>>,
}

/// Min, max, mean and non-finite count of one channel.
struct ChannelStats {
    min: f64,
    max: f64,
    mean: f64,
    non_finite: usize,
}

/// Statistics of channel `c` of `img`, over finite samples.
fn channel_stats(img: &Image, c: usize) -> ChannelStats {
    let (mut min, mut max, mut sum, mut n, mut non_finite) =
        (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize, 0usize);
    for v in img.data.iter().skip(c).step_by(img.channels) {
        if v.is_finite() {
            let v = *v as f64;
            min = min.min(v);
            max = max.max(v);
            sum += v;
            n += 1;
        } else {
            non_finite += 1;
        }
    }
    ChannelStats {
        min,
        max,
        mean: if n > 0 { sum / n as f64 } else { f64::NAN },
        non_finite,
    }
}

/// Prints one table row per channel of a layer.
fn print_layer(name: &str, channels: &[&str], img: &Image) {
    for (c, ch) in channels.iter().enumerate() {
        let s = channel_stats(img, c);
        println!(
            "{:<14} {:>13.6e} {:>13.6e} {:>13.6e} {:>9}",
            format!("{name}.{ch}"),
            s.min,
            s.max,
            s.mean,
            s.non_finite
        );
    }
}

/// Writes the first three channels of `img` (or its single channel as grey), mapped by `map`,
/// as an 8-bit sRGB PNG (non-finite values black).
fn write_png(path: &Path, img: &Image, map: impl Fn(f32) -> f32) -> Result<()> {
    let mut bytes = Vec::with_capacity(img.width * img.height * 3);
    for y in 0..img.height {
        for x in 0..img.width {
            let p = img.pixel(x, y);
            let rgb = if img.channels >= 3 {
                [p[0], p[1], p[2]]
            } else {
                [p[0]; 3]
            };
            bytes.extend(rgb.map(|v| {
                let v = map(v);
                encode8(if v.is_finite() { v } else { 0.0 })
            }));
        }
    }
    fileio::png::write_rgb8(path, img.width, img.height, &bytes)
        .with_context(|| format!("writing {}", path.display()))
}

/// Writes the PNG previews next to `prefix`.
fn write_pngs(b: &Bundle, prefix: &Path, exposure: f32) -> Result<()> {
    let scale = exposure.exp2();
    let name = |layer: &str| {
        let mut s = prefix.as_os_str().to_owned();
        s.push(format!("_{layer}.png"));
        PathBuf::from(s)
    };
    for (level, img) in LEVEL_NAMES.iter().zip(&b.levels) {
        write_png(&name(level), img, |v| v * scale)?;
    }
    write_png(&name("albedo"), &b.albedo, |v| v)?;
    write_png(&name("normal"), &b.normal, |v| 0.5 * v + 0.5)?;
    let max_depth = channel_stats(&b.depth, 0).max.max(1e-6) as f32;
    write_png(&name("depth"), &b.depth, |v| v / max_depth)?;
    eprintln!(
        "wrote {}_{{y,z1..z4,albedo,normal,depth}}.png",
        prefix.display()
    );
    Ok(())
}

fn main() -> std::process::ExitCode {
    cli_output::install();
    match run(&Args::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// Prints the bundle's metadata and statistics, and writes the PNGs if asked.
fn run(args: &Args) -> Result<()> {
    let b = read_bundle(&args.bundle)?;
    let exr = match args.exr.as_deref() {
        Some([level, file]) => {
            let Some(l) = LEVEL_NAMES.iter().position(|n| n == level) else {
                anyhow::bail!(
                    "--exr: no level `{level}` (one of {})",
                    LEVEL_NAMES.join(", ")
                );
            };
            let file = PathBuf::from(file);
            cli_output::paths::create_parent_dir("--exr", &file).map_err(anyhow::Error::msg)?;
            Some((l, file))
        }
        _ => None,
    };
    if let Some(prefix) = &args.png {
        // Before any output: a folder that cannot be made fails at once (missing ones are
        // made, as every other command does for its outputs).
        cli_output::paths::create_parent_dir("--png", prefix).map_err(anyhow::Error::msg)?;
    }
    println!("file:        {}", args.bundle.display());
    println!("{}", serde_json::to_string_pretty(&b.meta)?);
    println!(
        "{:<14} {:>13} {:>13} {:>13} {:>9}",
        "channel", "min", "max", "mean", "nonfinite"
    );
    for (level, img) in LEVEL_NAMES.iter().zip(&b.levels) {
        print_layer(level, &["R", "G", "B"], img);
    }
    print_layer("variance", &LEVEL_NAMES, &b.variance);
    print_layer("albedo", &["R", "G", "B"], &b.albedo);
    print_layer("normal", &["X", "Y", "Z"], &b.normal);
    print_layer("depth", &["Z"], &b.depth);
    if let Some(radius) = &b.radius {
        print_layer("radius", &LEVEL_NAMES, radius);
    }
    if let Some(direct) = &b.direct {
        print_layer("ydirect", &["R", "G", "B"], &direct.y);
        print_layer("zdirect", &["R", "G", "B"], &direct.z);
        print_layer("directvariance", &bundle::DIRECT_NAMES, &direct.variance);
    }
    if let Some((layer, channel, x, y)) = b.find_non_finite() {
        println!("first non-finite sample: {layer}.{channel} at ({x}, {y})");
    }
    if let Some(prefix) = &args.png {
        write_pngs(&b, prefix, args.exposure)?;
    }
    if let Some((level, file)) = exr {
        bundle::write_rgb_exr_image(&file, &b.levels[level])?;
        eprintln!("wrote {} ({})", file.display(), LEVEL_NAMES[level]);
    }
    Ok(())
}
