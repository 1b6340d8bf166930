//! `bench_infer`: speed and memory of tiled inference (issue 6 "Speed", issue 40 item 5): a
//! randomly initialised network of each preset named reconstructs a synthetic bundle of the
//! given size through `infer`'s tiled path, on the native engine and on Burn in the same run (or
//! on the one named by `--engine`). Peers on the same image, in the same run: the PyTorch peer
//! (`bench/peer.py`, the paper preset's forward + combination on the whole image) and Intel Open
//! Image Denoise 2.5 (`--oidn scripts/oidn_denoise.py`: HDR colour ỹ + albedo + normal, quality
//! `high`, through Python `pyoidn`; a development-side peer, never linked). With `--rounds R`
//! every measurement is repeated R times, interleaved (ours, then OIDN, R times), so that a
//! machine shared with other work loads both alike; the ratios are taken within each round.
//! `--model DIR` times trained weights as `infer` runs them: the bundle packed with the model's
//! screen-filtered levels and its direct filter (their time counted), then the tiled
//! reconstruction. The synthetic bundle carries photon-free layers as rendered bundles do.
//! Prints a table and optionally JSON.

use std::path::PathBuf;
use std::process::{Command, ExitCode};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Parser;
use infer::oidn::{Denoiser, Guides};
use infer::{reconstruct_tiled, Engine};
use model::backend::Backend;
use model::features::{pack, pack_with, planar_reference, ExtraFeature};
use model::model_dir::TrainedModel;
use model::synthetic::synthetic_bundle;
use model::{ModelConfig, Preset};
use serde_json::{json, Value};

/// Benchmark tiled inference of network presets against PyTorch and Open Image Denoise.
#[derive(Debug, Parser)]
#[command(version, allow_negative_numbers = true)]
struct Cli {
    /// Network presets, comma-separated: paper, medium, small, tiny, unet (e.g. `unet,small`);
    /// absent: `paper`, unless `--model` is given. Randomly initialised, no screen levels:
    /// the network, Eq. 6 and the guard are timed.
    #[arg(long)]
    preset: Option<String>,
    /// Trained model directories (`model.json` + `model.bpk`, e.g. `models/default`) to time
    /// as `infer` runs them: packing the bundle with the model's screen-filtered levels is
    /// counted. Repeat the flag for several.
    #[arg(long)]
    model: Vec<PathBuf>,
    /// Extra feature planes, comma-separated (`disagreement`, `passes`): each preset and model
    /// is also timed reading these planes after its own, in the same rounds — a preset
    /// randomly initialised, a model with zero weights for the new planes (as `train` starts
    /// it with `init`; speed does not depend on the values). A widened network's time counts
    /// packing the bundle, as `--model` timings do (a plain preset's does not).
    #[arg(long, value_delimiter = ',')]
    extra_features: Vec<String>,
    /// The synthetic bundle's pass count: the screen filter's bandwidth shrinks with it
    /// (σ₀ at 64 passes), so it sets what `--model` timings pay for the filter.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..))]
    passes: u32,
    /// Image width in pixels (and height, unless `--height` is given).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(1..=16384))]
    size: u32,
    /// Image height in pixels, e.g. `--size 1280 --height 720`; absent: square.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=16384))]
    height: Option<u32>,
    /// Tile side (0 = whole image); absent: `infer`'s default for each preset (512, a U-Net
    /// 1024).
    #[arg(long)]
    tile: Option<usize>,
    /// Timed repetitions per round (after one warm-up in the first round); the median is
    /// reported.
    #[arg(long, default_value_t = 2)]
    repeats: usize,
    /// Rounds of the whole measurement (every preset, then OIDN), interleaved.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    rounds: u32,
    /// Worker threads of our reconstruction (0 = every core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
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
    /// Open Image Denoise peer script (`scripts/oidn_denoise.py`), or `none`.
    #[arg(long, default_value = "none")]
    oidn: String,
    /// Python interpreter for the peers.
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

/// The median of `values` (the upper one of an even count).
fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() -> ExitCode {
    cli_output::install();
    infer::memory::retain_freed_memory();
    let cli = Cli::parse();
    let result = renderer::threads::with_threads(cli.threads, || run(&cli)).and_then(|r| r);
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Photon-free layers for the synthetic bundle: every bundle `infer --scene` renders carries
/// them, and the emission split and a model's direct filter run on them, so the timed bundle
/// must too. Path A's part is a share of the noisy ỹ, path B's the same share of z̃1, with the
/// variances that share implies.
fn add_direct_light(bundle: &mut bundle::Bundle) {
    const SHARE: f32 = 0.4;
    let scaled = |image: &bundle::Image| {
        let mut out = image.clone();
        out.data.iter_mut().for_each(|v| *v *= SHARE);
        out
    };
    let (w, h) = (bundle.levels[0].width, bundle.levels[0].height);
    let mut variance = bundle::Image::new(w, h, 2);
    for (p, v) in variance.data.chunks_exact_mut(2).enumerate() {
        v[0] = SHARE * SHARE * bundle.variance.data[p * 5];
        v[1] = SHARE * SHARE * bundle.variance.data[p * 5 + 1];
    }
    bundle.direct = Some(bundle::DirectLight {
        y: scaled(&bundle.levels[0]),
        z: scaled(&bundle.levels[1]),
        variance,
    });
}

/// A network to time: a randomly initialised preset, or trained weights from a directory.
struct Entry {
    /// The preset's name, or the directory.
    name: String,
    model: TrainedModel,
    /// Trained weights: the packing with the model's screen levels is part of the time.
    pack_in_time: bool,
}

/// One network and engine's timings.
struct Timed {
    /// Index into the entries.
    entry: usize,
    engine: Engine,
    /// Median seconds of each round.
    rounds: Vec<f64>,
    /// Every timed run.
    all: Vec<f64>,
    /// Of every timed run, the seconds spent packing the bundle (trained weights only).
    packing: Vec<f64>,
    /// Peak RSS after its last run.
    rss: Option<f64>,
}

/// `entry` also reading the `extra` planes after its own: a preset initialised afresh, trained
/// weights with zero weights for the new planes.
fn widened(entry: &Entry, extra: &[ExtraFeature], device: &burn::tensor::Device) -> Result<Entry> {
    let from = &entry.model.config;
    if let Some(f) = extra.iter().find(|f| from.extra_features.contains(f)) {
        bail!(
            "{} already reads the {f:?} planes: --extra-features adds planes a network does not read",
            entry.name
        );
    }
    let all: Vec<ExtraFeature> = from.extra_features.iter().chain(extra).copied().collect();
    let config = from.clone().with_extra_features(all);
    let context = || format!("{}: adding {extra:?}", entry.name);
    config
        .validate()
        .map_err(anyhow::Error::msg)
        .with_context(context)?;
    let network = if entry.pack_in_time {
        config
            .with_new_inputs(from, &entry.model.network, device)
            .map_err(anyhow::Error::msg)
            .with_context(context)?
    } else {
        config.init(0, device)
    };
    Ok(Entry {
        name: format!("{} + {extra:?}", entry.name),
        model: TrainedModel {
            dir: entry.model.dir.clone(),
            network,
            config,
        },
        pack_in_time: true,
    })
}

fn run(cli: &Cli) -> Result<()> {
    let preset_list = match (&cli.preset, cli.model.is_empty()) {
        (Some(list), _) => list.as_str(),
        (None, true) => "paper",
        (None, false) => "",
    };
    let presets = preset_list
        .split(',')
        .filter(|name| !name.trim().is_empty())
        .map(|name| {
            serde_json::from_value::<Preset>(Value::String(name.trim().to_string())).with_context(
                || format!("unknown preset `{name}` (paper, medium, small, tiny, unet)"),
            )
        })
        .collect::<Result<Vec<_>>>()?;
    let device = cli.backend.device().map_err(anyhow::Error::msg)?;
    if let Some(note) = cli.backend.adapter_note(&device) {
        eprintln!("{note}");
    }
    let mut entries: Vec<Entry> = presets
        .iter()
        .map(|&preset| {
            let config = ModelConfig::preset(preset);
            Entry {
                name: format!("{preset:?}"),
                model: TrainedModel {
                    dir: PathBuf::new(),
                    network: config.init(0, &device),
                    config,
                },
                pack_in_time: false,
            }
        })
        .collect();
    for dir in &cli.model {
        let model = TrainedModel::open(dir, &device)
            .with_context(|| format!("loading the model in {}", dir.display()))?;
        entries.push(Entry {
            name: dir.display().to_string(),
            model,
            pack_in_time: true,
        });
    }
    if entries.is_empty() {
        bail!("nothing to time: give --preset or --model");
    }
    if !cli.extra_features.is_empty() {
        let extra = cli
            .extra_features
            .iter()
            .map(|name| {
                serde_json::from_value::<ExtraFeature>(Value::String(name.trim().to_string()))
                    .with_context(|| {
                        format!("unknown extra feature `{name}` (disagreement, passes)")
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        let widened = entries
            .iter()
            .map(|e| widened(e, &extra, &device))
            .collect::<Result<Vec<_>>>()?;
        entries.extend(widened);
    }
    let (n, h) = (cli.size as usize, cli.height.unwrap_or(cli.size) as usize);
    let (mut bundle, _) = synthetic_bundle(n, h, 0.3, 1);
    bundle.meta.passes = cli.passes;
    add_direct_light(&mut bundle);
    let packed = pack(&bundle)?;
    // OIDN's inputs: the same bundle's sharpest level ỹ as the noisy HDR colour, its albedo and
    // normal (planar RGB).
    let denoiser = (cli.oidn != "none").then(|| Denoiser {
        python: cli.python.clone(),
        script: PathBuf::from(&cli.oidn),
        repeats: cli.repeats.max(1) as u32,
    });
    let planar = |image: &bundle::Image| planar_reference(image, n, h);
    let oidn_inputs = (
        planar(&bundle.levels[0])?,
        planar(&bundle.albedo)?,
        planar(&bundle.normal)?,
    );
    let rss_before = peak_rss_mib();
    let engines = match cli.engine {
        Some(e) => vec![e],
        None => vec![Engine::Native, Engine::Burn],
    };
    let mut timed: Vec<Timed> = (0..entries.len())
        .flat_map(|entry| {
            engines.iter().map(move |&engine| Timed {
                entry,
                engine,
                rounds: Vec::new(),
                all: Vec::new(),
                packing: Vec::new(),
                rss: None,
            })
        })
        .collect();
    let mut oidn_rounds: Vec<f64> = Vec::new();
    let mut oidn_reports: Vec<Value> = Vec::new();
    let threads = match cli.threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    };
    for round in 0..cli.rounds as usize {
        for t in timed.iter_mut() {
            let entry = &entries[t.entry];
            let model = &entry.model;
            let mut times = Vec::new();
            let first = if round == 0 { 0 } else { 1 };
            for k in first..=cli.repeats.max(1) {
                let start = Instant::now();
                let own;
                let input = if entry.pack_in_time {
                    own = pack_with(&bundle, &model.config.packing())?;
                    if k > 0 {
                        t.packing.push(start.elapsed().as_secs_f64());
                    }
                    &own
                } else {
                    &packed
                };
                let tile = cli.tile.unwrap_or(model.config.default_tile());
                let r = reconstruct_tiled(model, input, tile, t.engine, &device, |_, _| {});
                let s = start.elapsed().as_secs_f64();
                assert!(r.image.iter().all(|v| v.is_finite()));
                eprintln!(
                    "round {round}: {} {:?} run {k}: {s:.3} s{}",
                    entry.name,
                    t.engine,
                    if k == 0 { " (warm-up)" } else { "" }
                );
                if k > 0 {
                    times.push(s);
                }
            }
            t.rounds.push(median(&times));
            t.all.extend(times);
            t.rss = peak_rss_mib();
        }
        if let Some(denoiser) = &denoiser {
            let (color, albedo, normal) = &oidn_inputs;
            let guides = Guides { albedo, normal };
            let (_, report) = denoiser.denoise_with_report(n, h, color, &guides)?;
            let s = report["seconds"]
                .as_f64()
                .with_context(|| format!("{}: no `seconds` in {report}", cli.oidn))?;
            eprintln!("round {round}: OIDN {s:.3} s");
            oidn_rounds.push(s);
            oidn_reports.push(report);
        }
    }

    // The PyTorch peer implements the paper preset, on square images only.
    let peer = if cli.peer == "none" || !presets.contains(&Preset::Paper) || n != h {
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

    let tile_name = cli
        .tile
        .map_or("infer's default".to_string(), |t| t.to_string());
    println!(
        "{n}x{h}, tile {tile_name}, backend {:?}, {threads} threads, {} round(s) of {} timed run(s)",
        cli.backend,
        cli.rounds,
        cli.repeats.max(1)
    );
    for e in &entries {
        let m = &e.model;
        let screen = if e.pack_in_time {
            format!(
                ", {} screen level(s) and {} extra plane(s) packed in the time ({} passes)",
                m.config.screen_levels.len(),
                m.config.in_channels - model::network::input_channels(m.config.levels.len()),
                cli.passes
            )
        } else {
            String::new()
        };
        println!(
            "  {} ({:?} preset): +{} px halo per tile of {}{screen}",
            e.name,
            m.config.preset,
            m.config.conv_reach(),
            cli.tile.unwrap_or(m.config.default_tile())
        );
    }
    let list = |v: &[f64]| {
        v.iter()
            .map(|s| format!("{s:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    for t in &timed {
        println!(
            "  {} {:?} engine (infer, tiled): {:.3} s (rounds: {})   peak RSS so far {:.0} MiB (before: {:.0} MiB)",
            entries[t.entry].name,
            t.engine,
            median(&t.rounds),
            list(&t.rounds),
            t.rss.unwrap_or(f64::NAN),
            rss_before.unwrap_or(f64::NAN)
        );
        if !t.packing.is_empty() {
            println!(
                "    of which packing the bundle (screen filters, extra planes): {:.3} s (median of {} runs)",
                median(&t.packing),
                t.packing.len()
            );
        }
    }
    for pair in timed.chunks(engines.len()) {
        if let [native, burn] = pair {
            println!(
                "  {} native / burn: {:.2}",
                entries[native.entry].name,
                median(&native.rounds) / median(&burn.rounds)
            );
        }
    }
    // Ours ÷ OIDN per round, then the median over rounds.
    let oidn_ratios: Vec<(String, Vec<f64>)> = timed
        .iter()
        .filter(|_| !oidn_rounds.is_empty())
        .map(|t| {
            let ratios = t
                .rounds
                .iter()
                .zip(&oidn_rounds)
                .map(|(ours, oidn)| ours / oidn)
                .collect();
            (format!("{} {:?}", entries[t.entry].name, t.engine), ratios)
        })
        .collect();
    if !oidn_rounds.is_empty() {
        let version = oidn_reports[0]["oidn"].as_str().unwrap_or("?");
        println!(
            "  OIDN {version} (quality high, colour + albedo + normal): {:.3} s (rounds: {})",
            median(&oidn_rounds),
            list(&oidn_rounds)
        );
        for (name, ratios) in &oidn_ratios {
            println!(
                "  ours ({name}) / OIDN: {:.2} (rounds: {})",
                median(ratios),
                list(ratios)
            );
        }
    }
    let ours = median(&timed[0].rounds);
    if let Some(p) = peer["infer_s"].as_f64() {
        let paper = timed
            .iter()
            .find(|t| {
                !entries[t.entry].pack_in_time
                    && entries[t.entry].model.config.preset == Preset::Paper
            })
            .expect("the peer runs only with the paper preset");
        println!(
            "  {} (whole image): {p:.3} s",
            peer["framework"].as_str().unwrap_or("pytorch")
        );
        println!(
            "  ours (paper, {:?}) / pytorch: {:.2}",
            paper.engine,
            median(&paper.rounds) / p
        );
    } else if !peer.is_null() {
        println!("  peer failed: {}", peer["error"]);
    } else if cli.peer != "none" && n != h {
        println!("  (no PyTorch peer: it reconstructs square images only)");
    } else if cli.peer != "none" {
        // Said, not silently left out: the peer implements the paper preset only.
        println!("  (no PyTorch peer: it implements the paper preset only)");
    }
    if let Some(path) = &cli.output {
        let all = json!({
            "preset": preset_list, "models": cli.model, "passes": cli.passes, "width": n, "height": h, "tile": cli.tile.map_or("default".into(), |t| json!(t)),
            "backend": format!("{:?}", cli.backend), "threads": threads, "rounds": cli.rounds,
            "infer_s": ours,
            "engines": timed.iter().map(|t| json!({
                "name": entries[t.entry].name,
                "preset": format!("{:?}", entries[t.entry].model.config.preset),
                "engine": format!("{:?}", t.engine),
                "infer_s": median(&t.rounds), "rounds_s": t.rounds, "all_s": t.all,
                "packing_s": (!t.packing.is_empty()).then(|| median(&t.packing)),
                "peak_rss_mib": t.rss,
            })).collect::<Vec<_>>(),
            "oidn": if oidn_rounds.is_empty() { Value::Null } else { json!({
                "seconds": median(&oidn_rounds), "rounds_s": oidn_rounds, "reports": oidn_reports,
                "ratios": oidn_ratios.iter().map(|(name, r)| json!({
                    "ours": name, "median": median(r), "rounds": r,
                })).collect::<Vec<_>>(),
            })},
            "pytorch": peer,
        });
        std::fs::write(path, serde_json::to_string_pretty(&all)?)
            .with_context(|| path.display().to_string())?;
    }
    Ok(())
}
