//! Convergence study of multi-level SPPM (issue 3, must-show 1): relMSE of every level against
//! a path-traced reference at each doubling of passes, after 4×4 downsampling.
//!
//! ```text
//! cargo run --release -p renderer --example sppm_convergence -- \
//!     scenes/validation/cornell-diffuse/scene.xml --res 64 --photons 4096 \
//!     --passes 4096 --ref-spp 16384 --out out/convergence/cornell-diffuse
//! ```
//! Writes `<out>_ref.exr` (reused when present), `<out>.csv` (passes, seconds, relMSE per
//! level) and `<out>_p<N>.exr` bundles of the last checkpoint; prints the relMSE table as
//! markdown and, per level, whether it decreased at every doubling and ended ≤ `--target`.
//! Plot the CSVs with the `convergence_plot` example (docs/validation.md).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use bundle::{read_rgb_exr_image, write_bundle, write_rgb_exr_image, Image, LEVEL_NAMES};
use clap::Parser;
use renderer::integrators::path::PathTracer;
use renderer::integrators::sppm::{
    render_sppm, RadiusSchedule, SppmMode, SppmSettings, StopCondition,
};
use renderer::integrators::RayIntegrator;
use renderer::threads::with_threads;

/// relMSE of every SPPM level against a path-traced reference, per doubling of passes.
#[derive(Parser, Debug)]
struct Args {
    /// Mitsuba XML scene.
    scene: PathBuf,
    /// Film resolution override (square).
    #[arg(long, default_value_t = 64)]
    res: u32,
    /// Photons per pass.
    #[arg(long, default_value_t = 4096)]
    photons: u64,
    /// Last checkpoint (doublings from 64 up to it).
    #[arg(long, default_value_t = 4096)]
    passes: u32,
    /// Reference samples per pixel (path tracer, unbounded depth with RR).
    #[arg(long, default_value_t = 4096)]
    ref_spp: u32,
    /// Reference path tracer's `max_depth` (−1: unbounded, Russian roulette from depth 5).
    #[arg(long, default_value_t = -1, allow_hyphen_values = true)]
    ref_max_depth: i32,
    /// SPPM bound on eye delta/glossy bounces and photon bounces.
    #[arg(long, default_value_t = renderer::integrators::sppm::DEFAULT_MAX_DEPTH)]
    max_depth: u32,
    /// Target relMSE at the last checkpoint (reported, not enforced).
    #[arg(long, default_value_t = 3e-3)]
    target: f64,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Single-level mode instead of multi-level.
    #[arg(long)]
    single: bool,
    /// Radius schedule: `sppm` shrinks every pass, `cppm` by a chi-squared test per level.
    #[arg(long, value_enum, default_value_t = RadiusSchedule::Sppm)]
    schedule: RadiusSchedule,
    /// Output prefix.
    #[arg(long)]
    out: PathBuf,
    /// Worker threads (0 = all).
    #[arg(long, default_value_t = 0)]
    threads: usize,
}

/// Box-downsamples an RGB image by `f` in each axis.
fn downsample(img: &Image, f: usize) -> Image {
    let (w, h) = (img.width / f, img.height / f);
    let mut out = Image::new(w, h, 3);
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let mut s = 0.0;
                for dy in 0..f {
                    for dx in 0..f {
                        s += img.get(x * f + dx, y * f + dy, c);
                    }
                }
                out.set(x, y, c, s / (f * f) as f32);
            }
        }
    }
    out
}

/// Mean over pixels and channels of (x − r)² / (r² + 0.01).
fn rel_mse(img: &Image, reference: &Image) -> f64 {
    let n = img.data.len() as f64;
    img.data
        .iter()
        .zip(&reference.data)
        .map(|(&x, &r)| {
            let (x, r) = (x as f64, r as f64);
            (x - r).powi(2) / (r * r + 0.01)
        })
        .sum::<f64>()
        / n
}

/// Prints the relMSE table as markdown and, per level, whether it decreased at every
/// checkpoint and ended at or below `target`.
fn print_summary(table: &[(u32, Vec<f64>)], target: f64) {
    println!("| passes | {} |", LEVEL_NAMES.join(" | "));
    println!("|---|{}", "---|".repeat(LEVEL_NAMES.len()));
    for (passes, values) in table {
        let cells: Vec<String> = values.iter().map(|e| format!("{e:.2e}")).collect();
        println!("| {passes} | {} |", cells.join(" | "));
    }
    for (l, name) in LEVEL_NAMES.iter().enumerate() {
        let series: Vec<f64> = table.iter().map(|(_, v)| v[l]).collect();
        let monotone = series.windows(2).all(|w| w[1] < w[0]);
        let last = series.last().copied().unwrap_or(f64::NAN);
        println!(
            "{name}: decreases at every doubling: {}; final {last:.2e} {} {target:.0e}",
            if monotone { "yes" } else { "NO" },
            if last <= target { "<=" } else { ">" }
        );
    }
}

fn path_with_suffix(prefix: &std::path::Path, suffix: &str) -> PathBuf {
    let mut s = prefix.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

fn main() -> Result<()> {
    let args = Args::parse();
    let res = args.res.to_string();
    let defaults = vec![("res".to_string(), res)];
    let loaded = renderer::scene_file::load_for_sppm(&args.scene, &defaults, false)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    let scene = loaded.scene;
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let ref_path = path_with_suffix(&args.out, "_ref.exr");
    let reference = if ref_path.exists() {
        read_rgb_exr_image(&ref_path)?
    } else {
        let t = Instant::now();
        let pt = PathTracer {
            max_depth: args.ref_max_depth,
            ..PathTracer::default()
        };
        let film = with_threads(args.threads, || {
            pt.render(&scene, args.ref_spp, 1_000_003, None)
        })?;
        let img = Image {
            width: film.width as usize,
            height: film.height as usize,
            channels: 3,
            data: film.to_rgb_f32(),
        };
        write_rgb_exr_image(&ref_path, &img)?;
        eprintln!(
            "reference: {} spp in {:.1}s",
            args.ref_spp,
            t.elapsed().as_secs_f64()
        );
        img
    };
    let reference = downsample(&reference, 4);
    let mut checkpoints = Vec::new();
    let mut p = 64;
    while p <= args.passes {
        checkpoints.push(p);
        p *= 2;
    }
    let settings = SppmSettings {
        photons_per_pass: args.photons,
        seed: args.seed,
        mode: if args.single {
            SppmMode::Single
        } else {
            SppmMode::MultiLevel
        },
        threads: args.threads,
        max_depth: args.max_depth,
        schedule: args.schedule,
        scene_name: args.scene.display().to_string(),
        ..SppmSettings::default()
    };
    let mut rows = vec![format!("passes,seconds,{}", LEVEL_NAMES.join(","))];
    let mut table: Vec<(u32, Vec<f64>)> = Vec::new();
    let last = *checkpoints.last().context("--passes must be at least 64")?;
    let stop = StopCondition {
        checkpoints,
        seconds: None,
    };
    render_sppm(
        &scene,
        &settings,
        &stop,
        |b| {
            let values: Vec<f64> = b
                .levels
                .iter()
                .map(|l| rel_mse(&downsample(l, 4), &reference))
                .collect();
            let errs: Vec<String> = values.iter().map(|e| format!("{e:.4e}")).collect();
            table.push((b.meta.passes, values));
            eprintln!(
                "passes {:5} ({:7.1}s): relMSE {}",
                b.meta.passes,
                b.meta.seconds,
                errs.join(" ")
            );
            rows.push(format!(
                "{},{:.2},{}",
                b.meta.passes,
                b.meta.seconds,
                errs.join(",")
            ));
            if b.meta.passes == last {
                write_bundle(
                    &path_with_suffix(&args.out, &format!("_p{last:04}.exr")),
                    &b,
                )?;
            }
            Ok(())
        },
        |_| {},
    )?;
    let csv = path_with_suffix(&args.out, ".csv");
    std::fs::write(&csv, rows.join("\n") + "\n")?;
    eprintln!("wrote {}", csv.display());
    print_summary(&table, args.target);
    Ok(())
}
