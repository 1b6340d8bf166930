//! `train --config configs/train/<name>.toml [--resume]`: trains the combiner network on a
//! dataset written by `datagen` (SPEC §5).

mod config;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use burn::module::Module;
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use model::data::PatchDataset;
use model::training::{write_atomic, EpochReport, Trainer};

use config::TrainConfig;

/// Train the multi-level SPPM combiner network.
#[derive(Parser, Debug)]
#[command(version, about)]
struct Cli {
    /// Training configuration (TOML).
    #[arg(long)]
    config: PathBuf,
    /// Continue from the checkpoint in the output directory.
    #[arg(long)]
    resume: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(&cli) {
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
    let names = ["y", "z1", "z2", "z3", "z4"];
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
    write_atomic(&path, &text).map_err(anyhow::Error::msg)
}

fn run(cli: &Cli) -> Result<()> {
    let cfg = TrainConfig::read(&cli.config)?;
    let device = cfg.backend.device().map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&cfg.output).with_context(|| cfg.output.display().to_string())?;
    let config_text = std::fs::read_to_string(&cli.config)?;
    write_atomic(&cfg.output.join("train.toml"), &config_text).map_err(anyhow::Error::msg)?;

    let mut train = PatchDataset::open(
        &cfg.dataset,
        &cfg.train_split,
        cfg.patch,
        cfg.stride,
        cfg.cache_images,
    )
    .map_err(anyhow::Error::msg)?;
    report_bad(&cfg.train_split, &train, &cfg.output)?;
    if train.images.is_empty() {
        bail!(
            "{}: no usable samples in split `{}`",
            cfg.dataset.display(),
            cfg.train_split
        );
    }
    let mut val = PatchDataset::open(
        &cfg.dataset,
        &cfg.val_split,
        cfg.patch,
        cfg.patch,
        cfg.cache_images,
    )
    .map_err(anyhow::Error::msg)?;
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
    } else {
        Trainer::new(cfg.model_config(), settings, &device)
    };
    eprintln!(
        "model: {:?}, {} parameters",
        trainer.config.preset,
        trainer.model.num_params()
    );

    let csv_path = cfg.output.join("metrics.csv");
    let rewrite_metrics = |history: &[EpochReport]| -> Result<()> {
        let mut csv = String::from(CSV_HEADER);
        csv.push('\n');
        for r in history {
            csv.push_str(&csv_row(r));
            csv.push('\n');
        }
        write_atomic(&csv_path, &csv).map_err(anyhow::Error::msg)?;
        let json = serde_json::to_string_pretty(history)?;
        write_atomic(&cfg.output.join("metrics.json"), &json).map_err(anyhow::Error::msg)
    };

    let style =
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} patches, {per_sec}, ETA {eta}")?
            .progress_chars("=> ");
    while trainer.epochs_done < cfg.epochs {
        let epoch = trainer.epochs_done + 1;
        let bar = ProgressBar::new(train.patches_per_epoch() as u64).with_style(style.clone());
        bar.set_message(format!("epoch {epoch}/{}", cfg.epochs));
        let mut on_batch = |p: model::training::BatchProgress| {
            bar.set_position(p.done as u64);
            bar.set_message(format!("epoch {epoch}/{} loss {:.4}", cfg.epochs, p.loss));
        };
        let report = trainer
            .run_epoch(&mut train, Some(&mut val), &mut on_batch)
            .map_err(|b| anyhow::anyhow!("{}: {}", b.file.display(), b.reason))?;
        bar.finish_and_clear();
        let mut line = format!("epoch {epoch}: train loss {:.5}", report.train_loss);
        if let Some(v) = &report.validation {
            let (best, best_value) = v.best_level();
            let names = ["y", "z1", "z2", "z3", "z4"];
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
