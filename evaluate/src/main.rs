//! `evaluate --config configs/eval/<name>.toml` (docs/method.md §8): standard SPPM against multi-level
//! SPPM + inference at equal wall time on held-out scenes; writes results.json, convergence
//! plots, comparison images and a self-contained index.html into the config's output folder.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
use evaluate::config::EvalConfig;

/// Equal-time evaluation of multi-level SPPM + neural reconstruction against standard SPPM.
#[derive(Debug, Parser)]
#[command(version, allow_negative_numbers = true)]
struct Cli {
    /// Evaluation config (TOML), e.g. `configs/eval/small.toml`.
    #[arg(long, required_unless_present_any = ["combine", "schedules"])]
    config: Option<PathBuf>,
    /// Instead of evaluating, summarise finished evaluations together: the output directories
    /// of earlier runs (each holding results.json), e.g. a dataset's test split and the
    /// external scenes. Prints a Markdown table and the aggregates over all their scenes at the
    /// largest pass count they share.
    #[arg(long, num_args = 1.., value_name = "DIR", conflicts_with_all = ["config", "model", "limit", "resume"])]
    combine: Vec<PathBuf>,
    /// Instead of evaluating, compare two finished evaluations of the same scenes, one with
    /// `schedule = "sppm"` and one with `"cppm"` (the paper's Fig. 8 and Table 2): writes
    /// `<scene>_schedules.png` (SPPM, CPPM, ours + SPPM, ours + CPPM, log-log) and
    /// `schedules.json` into `--output` (default: the CPPM directory) and prints the table.
    #[arg(long, num_args = 2, value_names = ["SPPM_DIR", "CPPM_DIR"],
          conflicts_with_all = ["config", "model", "limit", "resume", "combine"])]
    schedules: Vec<PathBuf>,
    /// Override the config's model directory.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Override the config's output directory; with `--combine`, the JSON file the combined
    /// summary is written to.
    #[arg(long)]
    output: Option<PathBuf>,
    /// Evaluate only the first N scenes.
    #[arg(long)]
    limit: Option<usize>,
    /// Continue an evaluation that was stopped: scenes finished by an earlier run with the same
    /// settings, model, scene file and reference (saved in `<output>/scenes/`) are taken from
    /// there; the rest are evaluated. Their timings come from the earlier run.
    #[arg(long)]
    resume: bool,
}

fn main() -> ExitCode {
    cli_output::install();
    infer::memory::retain_freed_memory();
    let cli = Cli::parse();
    match run(&cli) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Returns whether every scene was evaluated.
fn run(cli: &Cli) -> Result<bool> {
    if let [sppm, cppm] = &cli.schedules[..] {
        let out = cli.output.clone().unwrap_or_else(|| cppm.clone());
        let rows = evaluate::schedules::compare_schedules(sppm, cppm, &out)?;
        print!("{}", evaluate::schedules::markdown(&rows));
        let json = out.join("schedules.json");
        evaluate::schedules::write_json(&rows, &json)?;
        println!("wrote {} and the figures beside it", json.display());
        return Ok(true);
    }
    let Some(config_path) = &cli.config else {
        return combine(cli);
    };
    let mut config = EvalConfig::load(config_path)?;
    if let Some(m) = &cli.model {
        config.model = m.clone();
    }
    if let Some(o) = &cli.output {
        config.output = o.clone();
    }
    if cli.limit.is_some() {
        config.limit = cli.limit;
    }
    config.validate()?;
    let results = evaluate::run(&config, cli.resume)?;
    let s = &results.summary;
    println!(
        "{} scene(s), {} failed; at {} passes ours beats standard SPPM at equal time on {} (median ratio {})",
        s.scenes,
        s.failed,
        s.passes,
        s.ours_better_equal_time,
        s.median_ratio_equal_time
            .map_or_else(|| "–".into(), |v| format!("{v:.3}"))
    );
    if let Some(n) = &s.noise_corrected {
        println!("{}", evaluate::html::noise_corrected_sentence(n));
    }
    println!("wrote {}", config.output.join("index.html").display());
    println!("wrote {}", config.output.join("results.json").display());
    if s.failed > 0 {
        // The first failure's reason, so that the last line stands on its own.
        let first = results
            .scenes
            .iter()
            .find_map(|r| r.error.as_ref().map(|e| format!("{}: {e}", r.name)))
            .unwrap_or_default();
        eprintln!(
            "error: {} scene(s) failed (listed in the report; the first: {first})",
            s.failed
        );
    }
    Ok(s.failed == 0)
}

/// `--combine`: the summary over several finished evaluations. Returns whether none of their
/// scenes failed.
fn combine(cli: &Cli) -> Result<bool> {
    let combined = evaluate::summary::summarize_evaluations(&cli.combine)?;
    print!("{}", evaluate::summary::markdown(&combined));
    if let Some(path) = &cli.output {
        evaluate::summary::write_json(&combined, path)?;
        println!("wrote {}", path.display());
    }
    Ok(combined.summary.failed == 0)
}
