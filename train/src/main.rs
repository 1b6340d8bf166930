//! `train --config configs/train/<name>.toml [--resume]`: trains the combiner network on a
//! dataset written by `datagen` (docs/method.md §6).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use burn::module::Module;
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use model::weights::load_burnpack;
use train::data::{FamilyFilter, PatchDataset, SampleSource};
use train::training::{validate, EpochReport, Trainer};
use train::{config, curves};

use config::TrainConfig;

/// Train the multi-level SPPM combiner network.
#[derive(Parser, Debug)]
#[command(version, allow_negative_numbers = true)]
struct Cli {
    /// Training configuration (TOML).
    #[arg(long)]
    config: PathBuf,
    /// Continue from the checkpoint in the output directory.
    #[arg(long)]
    resume: bool,
    /// Instead of training, evaluate the final weights in the output directory (`model.bpk` +
    /// `model.json`) on whole images of this split (e.g. `test`) and write `eval_<split>.json`.
    #[arg(long, value_name = "SPLIT", conflicts_with = "resume")]
    evaluate: Option<String>,
    /// With `--evaluate`: read these families only (comma-separated, e.g. `lamp`), instead of
    /// the config's `families` / `exclude_families` — a network trained without a family,
    /// measured on it.
    #[arg(
        long,
        value_name = "FAMILIES",
        value_delimiter = ',',
        requires = "evaluate"
    )]
    evaluate_families: Option<Vec<String>>,
    /// With `--evaluate`: the model in this directory (`model.bpk` + `model.json`, e.g.
    /// `models/default`) instead of the output directory's — the weights a run starts from,
    /// measured on the config's dataset. Written to the output directory as
    /// `eval_<split>[_<families>]_<DIR's name>.json`.
    #[arg(long, value_name = "DIR", requires = "evaluate")]
    weights: Option<PathBuf>,
    /// Instead of training, redraw `curves.png` in the output directory from its
    /// `metrics.json` (e.g. for a run made before the picture existed).
    #[arg(long, conflicts_with_all = ["resume", "evaluate"])]
    plot: bool,
    /// Worker threads on the CPU backends (0 = all cores, at most 1024). The trained weights and
    /// files do not depend on it.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u16).range(0..=1024))]
    threads: u16,
    /// Wall-time budget of this invocation's training, in seconds: no epoch starts that the
    /// previous epoch's duration says would end past it (the first always runs). The checkpoint
    /// and the weights are then written as after a finished run; `--resume` continues.
    #[arg(long, value_name = "SECONDS", conflicts_with_all = ["evaluate", "plot"],
          value_parser = positive_seconds)]
    time: Option<f64>,
}

/// A `--time` budget: a finite number of seconds above zero.
fn positive_seconds(text: &str) -> Result<f64, String> {
    let value: f64 = text
        .parse()
        .map_err(|_| format!("`{text}` is not a number of seconds"))?;
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(format!(
            "`{text}`: the budget must be a finite number of seconds above 0"
        ))
    }
}

fn main() -> ExitCode {
    cli_output::install();
    let cli = Cli::parse();
    // Burn's CPU backends run on rayon: one pool of `--threads` bounds the whole run.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(usize::from(cli.threads))
        .build();
    let result = match pool {
        Ok(pool) => pool.install(|| run(&cli)),
        Err(e) => Err(anyhow::anyhow!(
            "starting {} worker threads: {e}",
            cli.threads
        )),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The `metrics.csv` header; one row per epoch follows.
const CSV_HEADER: &str = "epoch,train_loss,val_relmse,best_level,best_level_relmse,relmse_y,relmse_z1,relmse_z2,relmse_z3,relmse_z4,patches,seconds";

/// Formats one epoch as a `metrics.csv` row.
fn csv_row(r: &EpochReport) -> String {
    let names = LEVEL_NAMES;
    match &r.validation {
        Some(v) => {
            let (best, best_value) = v.best_level();
            format!(
                "{},{:.6e},{:.6e},{},{:.6e},{},{},{:.2}",
                r.epoch,
                r.train_loss,
                v.output,
                names[best],
                best_value,
                v.levels
                    .iter()
                    .map(|x| format!("{x:.6e}"))
                    .collect::<Vec<_>>()
                    .join(","),
                r.patches,
                r.seconds
            )
        }
        None => format!(
            "{},{:.6e},,,,,,,,,{},{:.2}",
            r.epoch, r.train_loss, r.patches, r.seconds
        ),
    }
}

/// Names of the input levels, in `Validation::levels` order.
const LEVEL_NAMES: [&str; 5] = ["y", "z1", "z2", "z3", "z4"];

/// The names of the levels a model combines, e.g. `y+z2`.
fn level_list(levels: &[usize]) -> String {
    levels
        .iter()
        .map(|&l| LEVEL_NAMES[l])
        .collect::<Vec<_>>()
        .join("+")
}

/// `--evaluate SPLIT`: relMSE of the trained output and of every input level over whole images
/// of `split`, pooled over all pixels; printed and written to `<output>/eval_<split>.json`.
fn evaluate(
    cfg: &TrainConfig,
    split: &str,
    families: &FamilyFilter,
    weights: Option<&Path>,
    device: &burn::tensor::Device,
) -> Result<()> {
    let model_dir = weights.unwrap_or(&cfg.output);
    let model_json = model_dir.join("model.json");
    let hint = if weights.is_some() {
        "--weights names a model directory: model.json + model.bpk"
    } else {
        "train first"
    };
    let text = std::fs::read_to_string(&model_json)
        .with_context(|| format!("{} ({hint})", model_json.display()))?;
    let model_config: model::ModelConfig =
        serde_json::from_str(&text).with_context(|| model_json.display().to_string())?;
    model_config
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", model_json.display()))?;
    let net = load_burnpack(&model_config, &model_dir.join("model.bpk"), device)
        .map_err(anyhow::Error::msg)?;
    // Screen with a 1-pixel patch, then evaluate each image as one patch of the smallest image
    // side (whole images when a split has one size, as datagen writes them).
    let mut ds = PatchDataset::open(
        &cfg.dataset,
        split,
        1,
        1,
        cfg.cache_images,
        cfg.references.as_deref(),
        families,
        true,
    )
    .map_err(anyhow::Error::msg)?;
    report_bad(split, &ds, &cfg.output)?;
    let side = ds
        .images
        .iter()
        .map(|e| e.width.min(e.height))
        .min()
        .with_context(|| no_usable_samples(cfg, split, &ds))?;
    ds.patch = side;
    ds.stride = side;
    let v = validate(&net, &model_config, &mut ds, 1, device).map_err(anyhow::Error::new)?;
    let (best, best_value) = v.best_level();
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "split `{split}`: {} images of {side}x{side} ({} bad); model levels {}",
        ds.images.len(),
        ds.bad.len(),
        level_list(&model_config.levels)
    )?;
    writeln!(out, "relMSE output       {:.5e}", v.output)?;
    for (name, value) in LEVEL_NAMES.iter().zip(v.levels) {
        writeln!(out, "relMSE input {name:<6} {value:.5e}")?;
    }
    writeln!(
        out,
        "output / best input level ({}) = {:.3}",
        LEVEL_NAMES[best],
        v.output / best_value
    )?;
    let per_image = per_image_scores(&ds.images, &v.images);
    let ratios: Vec<f64> = per_image
        .iter()
        .filter_map(|e| e["ratio_to_best_level"].as_f64())
        .filter(|r| r.is_finite() && *r > 0.0)
        .collect();
    let geomean = (ratios.iter().map(|r| r.ln()).sum::<f64>() / ratios.len().max(1) as f64).exp();
    let below = ratios.iter().filter(|&&r| r < 1.0).count();
    writeln!(
        out,
        "per image: output below its best level in {below} of {}; geometric mean of output / \
         best level {geomean:.3}",
        ratios.len()
    )?;
    let reference_noise = pooled_reference_noise(&ds.images);
    let smallest = v.output.min(best_value);
    if let Some(noise) = reference_noise {
        writeln!(
            out,
            "reference noise     {noise:.5e} = {:.3} x the smallest error above",
            noise / smallest
        )?;
        if noise.is_nan() || noise > 0.1 * smallest {
            eprintln!(
                "warning: the references' own noise is more than a tenth of the smallest error \
                 measured: the ratio is pulled toward 1 (`datagen evaluation-references` with a \
                 larger --max-seconds or a smaller --target converges them further)"
            );
        }
    }
    let json = serde_json::json!({
        "weights": model_dir,
        "split": split,
        "families": families.only,
        "exclude_families": families.exclude,
        "images": ds.images.len(),
        "bad": ds.bad.len(),
        "image_side": side,
        "model_levels": model_config
            .levels
            .iter()
            .map(|&l| LEVEL_NAMES[l])
            .collect::<Vec<_>>(),
        "relmse_output": v.output,
        "relmse_levels": LEVEL_NAMES
            .iter()
            .zip(v.levels)
            .map(|(n, x)| (n.to_string(), serde_json::json!(x)))
            .collect::<serde_json::Map<_, _>>(),
        "best_level": LEVEL_NAMES[best],
        "best_level_relmse": best_value,
        "ratio_to_best_level": v.output / best_value,
        "reference_noise": reference_noise,
        "images_below_best_level": below,
        "geomean_ratio_to_best_level": geomean,
        "per_image": per_image,
    });
    // A family-restricted evaluation has a file of its own: `eval_test_lamp.json`.
    // Other weights than the run's (`--weights`) are named too: `eval_test_lamp_default.json`.
    let mut name = match &families.only {
        Some(only) => format!("eval_{split}_{}", only.join("+")),
        None => format!("eval_{split}"),
    };
    if let Some(dir) = weights {
        let stem = dir
            .file_name()
            .map_or_else(|| "weights".into(), |n| n.to_string_lossy().into_owned());
        name = format!("{name}_{stem}");
    }
    let name = format!("{name}.json");
    // With `--weights` the run may never have trained: its output folder may not exist yet.
    std::fs::create_dir_all(&cfg.output)
        .with_context(|| format!("creating {}", cfg.output.display()))?;
    write_text(
        &cfg.output.join(name),
        &serde_json::to_string_pretty(&json)?,
    )
}

/// Each image's scores against its own best level, as the eval JSON lists them. Pooled errors
/// are dominated by the noisiest images (few photons, few passes); per image, all weigh alike.
fn per_image_scores(
    images: &[train::data::ImageEntry],
    scores: &[train::training::ImageValidation],
) -> Vec<serde_json::Value> {
    images
        .iter()
        .zip(scores)
        .map(|(entry, iv)| {
            let (best, best_value) = iv.best_level();
            let bundle = match &entry.source {
                SampleSource::Files { bundle, .. } => bundle.display().to_string(),
                SampleSource::Memory(_) => String::new(),
            };
            serde_json::json!({
                "scene": entry.scene,
                "bundle": bundle,
                "relmse_output": iv.output,
                "best_level": LEVEL_NAMES[best],
                "best_level_relmse": best_value,
                "ratio_to_best_level": iv.output / best_value,
            })
        })
        .collect()
}

/// The references' own noise pooled like the errors (pixel-weighted), where the dataset recorded
/// it for every image: it adds to every relMSE measured and pulls ratios toward 1.
fn pooled_reference_noise(images: &[train::data::ImageEntry]) -> Option<f64> {
    let pixels: usize = images.iter().map(|e| e.width * e.height).sum();
    images
        .iter()
        .map(|e| e.reference_noise.map(|n| n * (e.width * e.height) as f64))
        .sum::<Option<f64>>()
        .filter(|_| pixels > 0)
        .map(|sum| sum / pixels as f64)
}

/// Writes `text` to `path` atomically.
fn write_text(path: &Path, text: &str) -> Result<()> {
    fileio::atomic::write_bytes(path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// The title of `curves.png`: the run's output directory and its network.
fn curves_title(cfg: &TrainConfig, net: &model::ModelConfig) -> String {
    let preset = format!("{:?}", net.preset).to_lowercase();
    format!(
        "{}: {preset} preset, levels {}, {}x{} patches, batch {}",
        cfg.output.display(),
        level_list(&net.levels),
        cfg.patch,
        cfg.patch,
        cfg.batch
    )
}

/// `--plot`: redraws `curves.png` from the output directory's `metrics.json` (written after
/// every epoch, so this also works for a run still in progress).
fn redraw_curves(cfg: &TrainConfig) -> Result<()> {
    let metrics = cfg.output.join("metrics.json");
    let text = std::fs::read_to_string(&metrics)
        .with_context(|| format!("{} (train first)", metrics.display()))?;
    let history: Vec<EpochReport> =
        serde_json::from_str(&text).with_context(|| metrics.display().to_string())?;
    let path = cfg.output.join("curves.png");
    curves::write(
        &path,
        &curves_title(cfg, &cfg.model_config()),
        &history,
        &LEVEL_NAMES,
    )?;
    println!("{} ({} epochs)", path.display(), history.len());
    Ok(())
}

/// The error for a split of which no sample can be used, with the first reason when samples
/// were screened out (e.g. a `patch` larger than the images), so that it stands on its own.
fn no_usable_samples(cfg: &TrainConfig, split: &str, ds: &PatchDataset) -> String {
    let mut message = format!(
        "{}: no usable samples in split `{split}`",
        cfg.dataset.display()
    );
    if let Some(first) = ds.bad.first() {
        message.push_str(&format!(
            " (all {} screened out; the first: {}: {})",
            ds.bad.len(),
            first.file.display(),
            first.reason
        ));
    }
    message
}

/// Prints every screened-out sample and writes them to `bad_samples.txt`.
fn report_bad(split: &str, ds: &PatchDataset, output: &Path) -> Result<()> {
    if ds.bad.is_empty() {
        return Ok(());
    }
    eprintln!(
        "{} bad sample(s) in split `{split}` (skipped, never trained on):",
        ds.bad.len()
    );
    let mut text = String::new();
    for b in &ds.bad {
        eprintln!("  {}: {}", b.file.display(), b.reason);
        text.push_str(&format!("{split}\t{}\t{}\n", b.file.display(), b.reason));
    }
    let path = output.join(format!("bad_samples_{split}.txt"));
    write_text(&path, &text)
}

/// Files of a training run in its output directory, finished or partial: the checkpoint is
/// complete once `state.json` is written (a `checkpoint/` without it holds nothing resumable).
const RUN_FILES: [&str; 6] = [
    "checkpoint/state.json",
    "model.bpk",
    "model.safetensors",
    "model.json",
    "metrics.csv",
    "metrics.json",
];

/// What `checkpoint/state.json` records that a resumed run must agree with (its history is
/// read by `Trainer::resume`).
#[derive(serde::Deserialize)]
struct CheckpointHead {
    model: model::ModelConfig,
    settings: train::training::TrainSettings,
    epochs_done: usize,
}

/// Refuses, before anything is written: a new run into an `output` that holds a run (it would
/// be overwritten); `--resume` without a checkpoint; `--resume` with a config whose network or
/// optimisation settings the checkpoint cannot continue, or with fewer epochs than it has done.
fn check_output(cfg: &TrainConfig, resume: bool) -> Result<()> {
    let checkpoint = cfg.output.join("checkpoint");
    let state_path = checkpoint.join("state.json");
    if !resume {
        let found: Vec<&str> = RUN_FILES
            .into_iter()
            .filter(|f| cfg.output.join(f).exists())
            .collect();
        if found.is_empty() {
            return Ok(());
        }
        let hint = if state_path.is_file() {
            "pass --resume to continue it, or choose another `output` (or delete the directory) \
             to start a new one"
        } else {
            "it has no checkpoint to resume: choose another `output` (or delete the directory) to \
             start a new one"
        };
        bail!(
            "{} already holds a training run ({}); {hint}",
            cfg.output.display(),
            found.join(", ")
        );
    }
    if !state_path.is_file() {
        bail!(
            "no checkpoint to resume in {} (start without --resume)",
            checkpoint.display()
        );
    }
    let text =
        std::fs::read_to_string(&state_path).with_context(|| state_path.display().to_string())?;
    let head: CheckpointHead =
        serde_json::from_str(&text).with_context(|| state_path.display().to_string())?;
    let differences = cfg.checkpoint_differences(&head.model, &head.settings);
    if !differences.is_empty() {
        bail!(
            "{}: checkpoint settings differ from the config: {}",
            state_path.display(),
            differences.join("; ")
        );
    }
    if cfg.epochs < head.epochs_done {
        bail!(
            "{}: epochs {} (config) is fewer than the {} the checkpoint has done",
            state_path.display(),
            cfg.epochs,
            head.epochs_done
        );
    }
    Ok(())
}

fn run(cli: &Cli) -> Result<()> {
    let cfg = TrainConfig::read(&cli.config)?;
    // A `dataset` that is no directory would otherwise surface as `<it>/manifest.json: Not a
    // directory`, without the key that set it (redrawing the curves needs no dataset).
    if !cli.plot && !cfg.dataset.is_dir() {
        bail!(
            "{}: dataset = {}: {}",
            cli.config.display(),
            cfg.dataset.display(),
            if cfg.dataset.exists() {
                "not a directory"
            } else {
                "no such directory (a relative path is read from the directory train runs in)"
            }
        );
    }
    // A misspelt `references` directory would otherwise only show as every sample screened out.
    if let Some(dir) = &cfg.references {
        let path = cfg.dataset.join(dir);
        if !path.is_dir() {
            bail!(
                "{}: references directory {} does not exist",
                cli.config.display(),
                path.display()
            );
        }
    }
    if cli.plot {
        return redraw_curves(&cfg);
    }
    let device = cfg.backend.device().map_err(anyhow::Error::msg)?;
    if let Some(note) = cfg.backend.adapter_note(&device) {
        eprintln!("{note}");
    }
    if let Some(split) = &cli.evaluate {
        let families = match &cli.evaluate_families {
            Some(only) => FamilyFilter {
                only: Some(only.clone()),
                exclude: Vec::new(),
            },
            None => cfg.family_filter(),
        };
        return evaluate(&cfg, split, &families, cli.weights.as_deref(), &device);
    }
    // Everything that can refuse the run is checked before anything is written into `output`.
    check_output(&cfg, cli.resume)?;
    let config_text =
        std::fs::read_to_string(&cli.config).with_context(|| cli.config.display().to_string())?;
    std::fs::create_dir_all(&cfg.output).with_context(|| cfg.output.display().to_string())?;

    let mut train = PatchDataset::open(
        &cfg.dataset,
        &cfg.train_split,
        cfg.patch,
        cfg.stride,
        cfg.cache_images,
        cfg.references.as_deref(),
        &cfg.family_filter(),
        false,
    )
    .map_err(anyhow::Error::msg)?;
    report_bad(&cfg.train_split, &train, &cfg.output)?;
    if train.images.is_empty() {
        bail!(no_usable_samples(&cfg, &cfg.train_split, &train));
    }
    // `val_split = ""` trains without validation.
    let mut val = if cfg.val_split.is_empty() {
        PatchDataset::from_samples(Vec::new(), cfg.patch, cfg.patch)
    } else {
        PatchDataset::open(
            &cfg.dataset,
            &cfg.val_split,
            cfg.patch,
            cfg.patch,
            cfg.cache_images,
            cfg.references.as_deref(),
            &cfg.family_filter(),
            true,
        )
        .map_err(anyhow::Error::msg)?
    };
    report_bad(&cfg.val_split, &val, &cfg.output)?;
    let total_bad = train.bad.len() + val.bad.len();
    eprintln!(
        "dataset {}: {} train images ({} patches/epoch), {} val images, {} bad; backend {:?}",
        cfg.dataset.display(),
        train.images.len(),
        train.patches_per_epoch(),
        val.images.len(),
        total_bad,
        cfg.backend
    );

    let checkpoint = cfg.output.join("checkpoint");
    let settings = cfg.settings();
    let mut trainer = if cli.resume {
        let t = Trainer::resume(&checkpoint, settings, &device).map_err(anyhow::Error::msg)?;
        eprintln!("resuming after epoch {}", t.epochs_done);
        t
    } else if let Some(init) = &cfg.init {
        let t = Trainer::from_weights(cfg.model_config(), settings, init, &device)
            .map_err(|e| anyhow::anyhow!("{}: init: {e}", cli.config.display()))?;
        eprintln!("starting from the weights of {}", init.display());
        t
    } else {
        Trainer::new(cfg.model_config(), settings, &device)
    };
    // The run is accepted (data screened, checkpoint or `init` weights loaded): record its
    // config.
    write_text(&cfg.output.join("train.toml"), &config_text)?;
    eprintln!(
        "model: {:?}, levels {}, {} parameters",
        trainer.config.preset,
        level_list(&trainer.config.levels),
        trainer.model.num_params()
    );

    let csv_path = cfg.output.join("metrics.csv");
    let curves_path = cfg.output.join("curves.png");
    let curves_title = curves_title(&cfg, &trainer.config);
    let rewrite_metrics = |history: &[EpochReport]| -> Result<()> {
        let mut csv = String::from(CSV_HEADER);
        csv.push('\n');
        for r in history {
            csv.push_str(&csv_row(r));
            csv.push('\n');
        }
        write_text(&csv_path, &csv)?;
        let json = serde_json::to_string_pretty(history)?;
        write_text(&cfg.output.join("metrics.json"), &json)?;
        // The picture is a convenience: failing to draw it (a full disk) must not stop training.
        if let Err(e) = curves::write(&curves_path, &curves_title, history, &LEVEL_NAMES) {
            eprintln!("warning: {e:#}");
        }
        Ok(())
    };

    let style =
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} patches, {per_sec}, ETA {eta}")?
            .progress_chars("=> ");
    let started = std::time::Instant::now();
    let mut last_epoch_seconds = 0.0_f64;
    let mut epochs_this_run = 0usize;
    while trainer.epochs_done < cfg.epochs {
        let epoch = trainer.epochs_done + 1;
        if let Some(budget) = cli.time {
            let elapsed = started.elapsed().as_secs_f64();
            if epochs_this_run > 0 && elapsed + last_epoch_seconds > budget {
                eprintln!(
                    "--time {budget} s: stopping after epoch {} of {} ({elapsed:.1} s spent, an \
                     epoch takes {last_epoch_seconds:.1} s); continue with --resume",
                    trainer.epochs_done, cfg.epochs
                );
                break;
            }
        }
        let epoch_start = std::time::Instant::now();
        let bar = ProgressBar::new(train.patches_per_epoch() as u64).with_style(style.clone());
        bar.set_message(format!("epoch {epoch}/{}", cfg.epochs));
        let mut on_batch = |p: train::training::BatchProgress| {
            bar.set_position(p.done as u64);
            bar.set_message(format!("epoch {epoch}/{} loss {:.4}", cfg.epochs, p.loss));
        };
        let report = trainer
            .run_epoch(&mut train, Some(&mut val), &mut on_batch)
            .map_err(|e| anyhow::anyhow!("epoch {epoch}: {e}"))?;
        bar.finish_and_clear();
        let mut line = format!("epoch {epoch}: train loss {:.5}", report.train_loss);
        if let Some(v) = &report.validation {
            let (best, best_value) = v.best_level();
            let names = LEVEL_NAMES;
            line.push_str(&format!(
                ", val relMSE {:.5e} (best input level {} {:.5e}, ratio {:.3})",
                v.output,
                names[best],
                best_value,
                v.output / best_value
            ));
        }
        line.push_str(&format!(", {:.1} s", report.seconds));
        eprintln!("{line}");
        trainer
            .save_checkpoint(&checkpoint)
            .map_err(anyhow::Error::msg)?;
        rewrite_metrics(&trainer.history)?;
        last_epoch_seconds = epoch_start.elapsed().as_secs_f64();
        epochs_this_run += 1;
    }
    trainer
        .save_final(&cfg.output)
        .map_err(anyhow::Error::msg)?;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "weights: {} (+ model.safetensors, model.json, metrics.csv)",
        cfg.output.join("model.bpk").display()
    )?;
    if total_bad > 0 {
        writeln!(
            out,
            "{total_bad} bad sample(s) skipped; see bad_samples_*.txt"
        )?;
    }
    Ok(())
}
