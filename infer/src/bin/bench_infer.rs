//! `bench_infer`: speed and memory of tiled inference (issue 6 "Speed"): a randomly
//! initialised network of a preset reconstructs a synthetic bundle of the given size through
//! `infer`'s tiled path, on the native engine and on Burn in the same run (or on the one named
//! by `--engine`); the PyTorch peer (`bench/peer.py`) does the same forward + combination on the
//! whole image. Prints a table and optionally JSON.

use std::path::PathBuf;
use std::process::{Command, ExitCode};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Parser;
use infer::{reconstruct_tiled, Engine};
use model::backend::Backend;
use model::features::pack;
use model::model_dir::TrainedModel;
use model::synthetic::synthetic_bundle;
use model::{ModelConfig, Preset};
use serde_json::{json, Value};

/// Benchmark tiled inference of a network preset against the PyTorch peer.
#[derive(Debug, Parser)]
#[command(version, allow_negative_numbers = true)]
struct Cli {
    /// Network preset: paper, medium, small or tiny.
    #[arg(long, default_value = "paper")]
    preset: String,
    /// Image width in pixels (and height, unless `--height` is given).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(1..=16384))]
    size: u32,
    /// Image height in pixels, e.g. `--size 1280 --height 720`; absent: square.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=16384))]
    height: Option<u32>,
    /// Tile side (0 = whole image); `infer`'s default.
    #[arg(long, default_value_t = 512)]
    tile: usize,
    /// Timed repetitions after one warm-up; the median is reported.
    #[arg(long, default_value_t = 2)]
    repeats: usize,
    /// Tensor backend.
    #[arg(long, default_value = "flex", value_parser = Backend::parse)]
    backend: Backend,
    /// Inference engine to time; absent: both, native first (the default for flex), in the
    /// same run, with their ratio.
    #[arg(long, value_enum)]
    engine: Option<Engine>,
    /// PyTorch peer script, or `none`.
    #[arg(long, default_value = "bench/peer.py")]
    peer: String,
    /// Python interpreter for the peer.
    #[arg(long, default_value = "python3")]
    python: String,
    /// Write all numbers as JSON here.
    #[arg(long)]
    output: Option<PathBuf>,
}

/// Peak resident set size of this process so far, in MiB (Linux), if known.
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn main() -> ExitCode {
    cli_output::install();
    match run(&Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: &Cli) -> Result<()> {
    let preset: Preset =
        serde_json::from_value(Value::String(cli.preset.clone())).with_context(|| {
            format!(
                "unknown preset `{}` (paper, medium, small, tiny)",
                cli.preset
            )
        })?;
    let device = cli.backend.device().map_err(anyhow::Error::msg)?;
    if let Some(note) = cli.backend.adapter_note(&device) {
        eprintln!("{note}");
    }
    let config = ModelConfig::preset(preset);
    let network = config.init(0, &device);
    let model = TrainedModel {
        dir: PathBuf::new(),
        config,
        network,
    };
    let (n, h) = (cli.size as usize, cli.height.unwrap_or(cli.size) as usize);
    let (bundle, _) = synthetic_bundle(n, h, 0.3, 1);
    let packed = pack(&bundle)?;
    drop(bundle);
    let rss_before = peak_rss_mib();
    let engines = match cli.engine {
        Some(e) => vec![e],
        None => vec![Engine::Native, Engine::Burn],
    };
    // (engine, median seconds, all timed runs, peak RSS after it)
    let mut timed = Vec::new();
    for &engine in &engines {
        let mut times = Vec::new();
        for k in 0..=cli.repeats.max(1) {
            let t = Instant::now();
            let r = reconstruct_tiled(&model, &packed, cli.tile, engine, &device, |_, _| {});
            let s = t.elapsed().as_secs_f64();
            assert!(r.image.iter().all(|v| v.is_finite()));
            eprintln!(
                "{engine:?} run {k}: {s:.3} s{}",
                if k == 0 { " (warm-up)" } else { "" }
            );
            if k > 0 {
                times.push(s);
            }
        }
        times.sort_by(|a, b| a.total_cmp(b));
        timed.push((engine, times[times.len() / 2], times, peak_rss_mib()));
    }
    let ours = timed[0].1;

    // The peer reconstructs square images only.
    let peer = if cli.peer == "none" || preset != Preset::Paper || n != h {
        Value::Null
    } else {
        eprintln!("running the PyTorch peer {} on {n}x{n} ...", cli.peer);
        // A trivial training step (batch 1 of 8x8) so the peer's time goes to inference.
        let out = Command::new(&cli.python)
            .arg(&cli.peer)
            .args([
                "--batch",
                "1",
                "--patch",
                "8",
                "--infer-size",
                &n.to_string(),
            ])
            .args(["--steps", &cli.repeats.max(1).to_string()])
            .output()
            .with_context(|| format!("running {} {}", cli.python, cli.peer))?;
        if out.status.success() {
            let text = String::from_utf8_lossy(&out.stdout);
            serde_json::from_str(text.trim()).with_context(|| format!("peer output: {text}"))?
        } else {
            let err = String::from_utf8_lossy(&out.stderr);
            json!({ "error": err.lines().last().unwrap_or("").to_string() })
        }
    };

    println!(
        "{:?} preset, {n}x{h}, tile {} (+{} px halo), backend {:?}",
        preset,
        cli.tile,
        model.config.receptive_radius(),
        cli.backend
    );
    for (engine, median, _, rss) in &timed {
        println!(
            "  {engine:?} engine (infer, tiled): {median:.3} s   peak RSS so far {:.0} MiB (before: {:.0} MiB)",
            rss.unwrap_or(f64::NAN),
            rss_before.unwrap_or(f64::NAN)
        );
    }
    if let [(_, native, ..), (_, burn, ..)] = timed.as_slice() {
        println!("  native / burn: {:.2}", native / burn);
    }
    if let Some(p) = peer["infer_s"].as_f64() {
        println!(
            "  {} (whole image): {p:.3} s",
            peer["framework"].as_str().unwrap_or("pytorch")
        );
        println!("  ours ({:?}) / pytorch: {:.2}", timed[0].0, ours / p);
    } else if !peer.is_null() {
        println!("  peer failed: {}", peer["error"]);
    } else if cli.peer != "none" && n != h {
        println!("  (no PyTorch peer: it reconstructs square images only)");
    } else if cli.peer != "none" {
        // Said, not silently left out: the peer implements the paper preset only.
        println!("  (no PyTorch peer: it implements the paper preset only; this is {preset:?})");
    }
    if let Some(path) = &cli.output {
        let all = json!({
            "preset": cli.preset, "width": n, "height": h, "tile": cli.tile, "backend": format!("{:?}", cli.backend),
            "infer_s": ours,
            "engines": timed.iter().map(|(e, median, all, rss)| json!({
                "engine": format!("{e:?}"), "infer_s": median, "all_s": all, "peak_rss_mib": rss,
            })).collect::<Vec<_>>(),
            "pytorch": peer,
        });
        std::fs::write(path, serde_json::to_string_pretty(&all)?)
            .with_context(|| path.display().to_string())?;
    }
    Ok(())
}
