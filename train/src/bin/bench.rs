//! `bench`: times the network (paper preset by default) — a training step (forward, backward,
//! Adam) on a batch of patches and a forward-only whole-image reconstruction — and runs the
//! PyTorch peer `bench/peer.py` in the same invocation for a same-machine comparison.

use std::path::PathBuf;
use std::process::{Command, ExitCode};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use clap::{Parser, ValueEnum};
use model::combine::reconstruct;
use model::loss::Loss;
use model::{ModelConfig, Preset};
use serde_json::{json, Value};
use train::data::Batch;
use train::training::{adam, train_step};

/// Time Burn against the PyTorch peer on the combiner network.
#[derive(Parser, Debug)]
#[command(version)]
struct Cli {
    /// Network preset.
    #[arg(long, value_enum, default_value = "paper")]
    preset: PresetArg,
    /// Backend: flex, ndarray or wgpu (wgpu needs `--features wgpu`).
    #[arg(long, default_value = "flex")]
    backend: String,
    /// Patches per training batch.
    #[arg(long, default_value_t = 8)]
    batch: usize,
    /// Patch side.
    #[arg(long, default_value_t = 64)]
    patch: usize,
    /// Side of the square image reconstructed forward-only.
    #[arg(long, default_value_t = 256)]
    infer_size: usize,
    /// Timed repetitions (after one warm-up) of each measurement.
    #[arg(long, default_value_t = 3)]
    steps: usize,
    /// The PyTorch peer script; `none` skips it.
    #[arg(long, default_value = "bench/peer.py")]
    peer: String,
    /// Python interpreter for the peer.
    #[arg(long, default_value = "python3")]
    python: String,
    /// Also write the results as JSON here.
    #[arg(long)]
    output: Option<PathBuf>,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum PresetArg {
    Paper,
    Medium,
    Small,
    Tiny,
    /// The shipped weights' network (`models/default`).
    Unet,
}

fn device(name: &str) -> Result<Device> {
    match name {
        "flex" => Ok(Device::flex()),
        #[allow(deprecated)]
        "ndarray" => Ok(Device::ndarray()),
        #[cfg(feature = "wgpu")]
        "wgpu" => Ok(Device::wgpu(Default::default())),
        other => bail!("unknown or not compiled-in backend `{other}` (flex, ndarray, wgpu with --features wgpu)"),
    }
}

/// Deterministic values in [0, 1).
fn filler(n: usize, seed: u32) -> Vec<f32> {
    let mut s = seed.wrapping_mul(2654435761).wrapping_add(1);
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            (s >> 8) as f32 / (1u32 << 24) as f32
        })
        .collect()
}

fn tensor(shape: [usize; 4], seed: u32, device: &Device) -> Tensor<4> {
    Tensor::from_data(
        TensorData::new(filler(shape.iter().product(), seed), shape),
        device,
    )
}

/// Median of the timed repetitions after one warm-up.
fn time_it(steps: usize, mut f: impl FnMut()) -> (f64, Vec<f64>) {
    f();
    let mut times: Vec<f64> = (0..steps.max(1))
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .collect();
    let all = times.clone();
    times.sort_by(|a, b| a.partial_cmp(b).unwrap());
    (times[times.len() / 2], all)
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
    let preset = match cli.preset {
        PresetArg::Paper => Preset::Paper,
        PresetArg::Medium => Preset::Medium,
        PresetArg::Small => Preset::Small,
        PresetArg::Tiny => Preset::Tiny,
        PresetArg::Unet => Preset::UNet,
    };
    let config = ModelConfig::preset(preset);
    let base = device(&cli.backend)?;
    let ad = base.clone().autodiff();
    let (b, p) = (cli.batch, cli.patch);

    let mut net = config.init(0, &ad);
    let params = net.num_params();
    eprintln!(
        "burn {}: {:?} preset, {params} parameters; train step batch {b} of {p}x{p}",
        cli.backend, preset
    );
    let mut optim = adam();
    let (train_s, train_all) = time_it(cli.steps, || {
        let batch = Batch {
            features: tensor([b, 27, p, p], 1, &ad),
            levels: tensor([b, 15, p, p], 2, &ad),
            direct: tensor([b, 3, p, p], 4, &ad),
            reference: tensor([b, 3, p, p], 3, &ad),
        };
        let (next, _) = train_step(
            net.clone(),
            &mut optim,
            &config,
            batch,
            1e-4,
            Loss::default(),
        )
        .unwrap_or_else(|e| {
            eprintln!("error: {e}");
            std::process::exit(1)
        });
        net = next;
    });
    let rss_train = peak_rss_mib();
    eprintln!(
        "burn train step: {train_s:.3} s (all {train_all:.3?}), peak RSS {rss_train:.0?} MiB"
    );

    let n = cli.infer_size;
    let valid = net.valid();
    let (infer_s, infer_all) = time_it(cli.steps, || {
        let out = reconstruct(
            &valid,
            &config,
            tensor([1, 27, n, n], 4, &base),
            tensor([1, 15, n, n], 5, &base),
        );
        let _ = out.into_data();
    });
    let rss_infer = peak_rss_mib();
    eprintln!("burn inference {n}x{n}: {infer_s:.3} s (all {infer_all:.3?}), peak RSS {rss_infer:.0?} MiB");

    let burn = json!({
        "framework": format!("burn 0.22.1 {}", cli.backend),
        "params": params,
        "train_step_s": train_s,
        "train_step_all_s": train_all,
        "infer_s": infer_s,
        "infer_all_s": infer_all,
        "peak_rss_mib": rss_infer,
    });

    let peer = if cli.peer == "none" || !matches!(preset, Preset::Paper) {
        Value::Null
    } else {
        eprintln!("running the PyTorch peer {} ...", cli.peer);
        let out = Command::new(&cli.python)
            .arg(&cli.peer)
            .args(["--batch", &b.to_string(), "--patch", &p.to_string()])
            .args([
                "--infer-size",
                &n.to_string(),
                "--steps",
                &cli.steps.to_string(),
            ])
            .output()
            .with_context(|| format!("running {} {}", cli.python, cli.peer))?;
        if out.status.success() {
            let text = String::from_utf8_lossy(&out.stdout);
            serde_json::from_str(text.trim()).with_context(|| format!("peer output: {text}"))?
        } else {
            let err = String::from_utf8_lossy(&out.stderr);
            eprintln!(
                "peer failed ({}): {}",
                out.status,
                err.lines().last().unwrap_or("")
            );
            json!({ "error": err.lines().last().unwrap_or("").to_string() })
        }
    };

    println!(
        "{:<28} {:>14} {:>16}",
        "",
        "train step (s)",
        format!("infer {n}² (s)")
    );
    println!(
        "{:<28} {:>14.3} {:>16.3}",
        format!("burn {}", cli.backend),
        train_s,
        infer_s
    );
    if let (Some(t), Some(i)) = (peer["train_step_s"].as_f64(), peer["infer_s"].as_f64()) {
        println!(
            "{:<28} {:>14.3} {:>16.3}",
            peer["framework"].as_str().unwrap_or("pytorch"),
            t,
            i
        );
        println!(
            "{:<28} {:>14.2} {:>16.2}",
            "burn / pytorch",
            train_s / t,
            infer_s / i
        );
    }
    if let Some(path) = &cli.output {
        let all = json!({ "batch": b, "patch": p, "infer_size": n, "burn": burn, "pytorch": peer });
        std::fs::write(path, serde_json::to_string_pretty(&all)?)
            .with_context(|| path.display().to_string())?;
    }
    Ok(())
}
