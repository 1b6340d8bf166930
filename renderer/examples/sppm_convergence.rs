//! Convergence study of multi-level SPPM (issue 3, must-show 1): relMSE of every level against
//! a path-traced reference at each doubling of passes, after 4×4 downsampling.
//!
//! ```text
//! cargo run --release -p renderer --example sppm_convergence -- \
//!     scenes/validation/cornell-diffuse/scene.xml --res 64 --photons 4096 \
//!     --passes 4096 --ref-spp 4096 --out target/conv/cornell
//! ```
//! Writes `<out>_ref.exr` (reused when present), `<out>.csv` (passes, seconds, relMSE per
//! level) and `<out>_p<N>.exr` bundles of the last checkpoint.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use bundle::{read_rgb_exr_image, write_bundle, write_rgb_exr_image, Image, LEVEL_NAMES};
use clap::Parser;
use renderer::film::with_threads;
use renderer::integrators::path::PathTracer;
use renderer::integrators::sppm::{render_sppm, SppmMode, SppmSettings, StopCondition};
use renderer::scene::Scene;

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
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Single-level mode instead of multi-level.
    #[arg(long)]
    single: bool,
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

fn path_with_suffix(prefix: &std::path::Path, suffix: &str) -> PathBuf {
    let mut s = prefix.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

fn main() -> Result<()> {
    let args = Args::parse();
    let res = args.res.to_string();
    let defaults = vec![("res".to_string(), res)];
    let desc = renderer::xml::load_scene(&args.scene, &defaults, false)
        .with_context(|| format!("loading {}", args.scene.display()))?;
    let scene = Scene::build(&desc)?;
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let ref_path = path_with_suffix(&args.out, "_ref.exr");
    let reference = if ref_path.exists() {
        read_rgb_exr_image(&ref_path)?
    } else {
        let t = Instant::now();
        let pt = PathTracer::default();
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
        scene_name: args.scene.display().to_string(),
        ..SppmSettings::default()
    };
    let mut rows = vec![format!("passes,seconds,{}", LEVEL_NAMES.join(","))];
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
            let errs: Vec<String> = b
                .levels
                .iter()
                .map(|l| format!("{:.4e}", rel_mse(&downsample(l, 4), &reference)))
                .collect();
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
    Ok(())
}
