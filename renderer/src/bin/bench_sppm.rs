//! `bench_sppm`: cost of multi-level SPPM over single-level SPPM per pass (same photons per
//! pass), photons/s, visible points/s and 1 → N thread scaling of the photon and gather phases,
//! for docs/performance.md (issue 3, must-show 3).
//!
//! The two modes are measured in the same process and interleaved (S, M, M, S, S, M, …), so a
//! load change on a shared machine hits both about equally. Each measurement is a fresh run of
//! `--passes` passes; the first pass (which also initialises the radii by k-NN queries) is
//! reported separately by excluding it from the steady-state time per pass.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Parser;
use renderer::integrators::sppm::{render_sppm, SppmMode, SppmSettings, StopCondition};
use renderer::scene::Scene;

/// The scene measured when none is given (the bundled default scene).
const DEFAULT_SCENE: &str = "scenes/default/scene.xml";

/// Measure the time per pass of `sppm-ml` over `sppm` and the thread scaling of SPPM.
#[derive(Debug, Parser)]
#[command(version, allow_negative_numbers = true)]
struct Cli {
    /// Scene file (Mitsuba 3 XML).
    #[arg(default_value = DEFAULT_SCENE)]
    scene: PathBuf,
    /// Image side length: sets the file's `res` default (the default scene's is 256). Leave it
    /// out for a scene without one (e.g. a dataset's generated scenes, which fix their size).
    #[arg(long)]
    res: Option<u32>,
    /// Photons traced per pass (the same for both modes).
    #[arg(long, default_value_t = 100_000)]
    photons: u64,
    /// Passes per measurement (the first is excluded from the steady-state time per pass).
    #[arg(long, default_value_t = 6)]
    passes: u32,
    /// Measurements per mode and thread count (interleaved; the median is reported).
    #[arg(long, default_value_t = 3)]
    rounds: u32,
    /// Thread counts to measure (each 1 to 1024).
    #[arg(long, value_delimiter = ',', default_value = "1,2",
          value_parser = clap::value_parser!(u16).range(1..=1024))]
    threads: Vec<u16>,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Measure only this mode (`sppm` or `sppm-ml`; for profiling one mode). Default: both.
    #[arg(long)]
    only: Option<String>,
}

/// One measured run of `passes` passes.
#[derive(Debug, Clone, Copy)]
struct Sample {
    /// Wall seconds per pass, passes 2..=N (radius initialisation excluded).
    steady_per_pass: f64,
    /// Process CPU seconds per pass over the whole run.
    cpu_per_pass: f64,
    /// Photon tracing + grid build seconds per pass (all passes).
    photon_per_pass: f64,
    /// Of which the grid build.
    grid_per_pass: f64,
    /// Eye subpaths + gather + accumulation seconds per pass (all passes).
    gather_per_pass: f64,
    /// Photons emitted per second of the photon phase.
    photons_per_s: f64,
    /// Visible points per second of the gather phase.
    visible_points_per_s: f64,
}

fn main() -> ExitCode {
    cli_output::install();
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let cli = Cli::parse();
    anyhow::ensure!(
        cli.passes >= 2,
        "--passes must be at least 2 (pass 1 is excluded)"
    );
    anyhow::ensure!(cli.rounds >= 1, "--rounds must be at least 1");
    anyhow::ensure!(
        !cli.threads.is_empty(),
        "--threads needs at least one count"
    );
    let defines: Vec<(String, String)> = cli
        .res
        .map(|res| vec![("res".to_string(), res.to_string())])
        .unwrap_or_default();
    cli_output::paths::check_default_input(&cli.scene, DEFAULT_SCENE, "the bundled default scene")
        .map_err(anyhow::Error::msg)?;
    let loaded = renderer::scene_file::load_for_sppm(&cli.scene, &defines, false)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    let scene = loaded.scene;
    let res = scene.camera.resolution();
    println!(
        "{}: {}x{}, {} photons/pass, {} passes per run, {} runs per mode (median), seed {}",
        cli.scene.display(),
        res.x,
        res.y,
        cli.photons,
        cli.passes,
        cli.rounds,
        cli.seed
    );
    let modes = [SppmMode::Single, SppmMode::MultiLevel];
    // results[thread index][mode index] = median sample
    let mut results = Vec::new();
    for &threads in &cli.threads {
        let mut samples: [Vec<Sample>; 2] = [Vec::new(), Vec::new()];
        for round in 0..cli.rounds {
            // ABBA order: alternate which mode goes first.
            let order = if round % 2 == 0 { [0, 1] } else { [1, 0] };
            for m in order {
                if cli.only.as_deref().is_some_and(|o| o != modes[m].name()) {
                    continue;
                }
                samples[m].push(measure(&scene, &cli, modes[m], usize::from(threads))?);
            }
        }
        if cli.only.is_some() {
            for (m, v) in samples.iter().enumerate().filter(|(_, v)| !v.is_empty()) {
                let s = median(v);
                println!(
                    "threads {threads} {:8}: {:.4} s/pass steady, {:.4} CPU s/pass, photon {:.4} \
                     (grid {:.4}), gather {:.4}",
                    modes[m].name(),
                    s.steady_per_pass,
                    s.cpu_per_pass,
                    s.photon_per_pass,
                    s.grid_per_pass,
                    s.gather_per_pass
                );
            }
            continue;
        }
        let med = [median(&samples[0]), median(&samples[1])];
        for (m, s) in med.iter().enumerate() {
            println!(
                "threads {threads} {:8}: {:.4} s/pass steady (wall), {:.4} CPU s/pass; \
                 photon phase {:.4} s/pass (grid build {:.4}) = {:.3} M photons/s; gather phase \
                 {:.4} s/pass = {:.3} M visible points/s",
                modes[m].name(),
                s.steady_per_pass,
                s.cpu_per_pass,
                s.photon_per_pass,
                s.grid_per_pass,
                s.photons_per_s / 1e6,
                s.gather_per_pass,
                s.visible_points_per_s / 1e6
            );
        }
        println!(
            "threads {threads}: sppm-ml / sppm time per pass = {:.3} (wall, steady), {:.3} (CPU); \
             photon phase {:.3}, gather phase {:.3}",
            med[1].steady_per_pass / med[0].steady_per_pass,
            med[1].cpu_per_pass / med[0].cpu_per_pass,
            med[1].photon_per_pass / med[0].photon_per_pass,
            med[1].gather_per_pass / med[0].gather_per_pass,
        );
        results.push((threads, med));
    }
    if let (Some((t1, a)), Some((t2, b))) = (results.first(), results.get(1)) {
        for (m, mode) in modes.iter().enumerate() {
            println!(
                "scaling {t1} -> {t2} threads, {}: whole pass {:.2}x, photon phase {:.2}x \
                 (tracing {:.2}x, grid build {:.2}x), gather phase {:.2}x",
                mode.name(),
                a[m].steady_per_pass / b[m].steady_per_pass,
                a[m].photon_per_pass / b[m].photon_per_pass,
                (a[m].photon_per_pass - a[m].grid_per_pass)
                    / (b[m].photon_per_pass - b[m].grid_per_pass),
                a[m].grid_per_pass / b[m].grid_per_pass,
                a[m].gather_per_pass / b[m].gather_per_pass,
            );
        }
    }
    Ok(())
}

/// Runs `cli.passes` passes of `mode` on `threads` workers and times them.
fn measure(scene: &Scene, cli: &Cli, mode: SppmMode, threads: usize) -> Result<Sample> {
    let settings = SppmSettings {
        photons_per_pass: cli.photons,
        seed: cli.seed,
        mode,
        threads,
        scene_name: cli.scene.display().to_string(),
        ..SppmSettings::default()
    };
    let stop = StopCondition {
        checkpoints: vec![cli.passes],
        seconds: None,
    };
    let mut after_first = 0.0;
    let mut after_last = 0.0;
    let cpu0 = process_cpu_seconds();
    let summary = render_sppm(
        scene,
        &settings,
        &stop,
        |b| {
            std::hint::black_box(&b);
            Ok(())
        },
        |p| {
            if p.pass == 1 {
                after_first = p.elapsed;
            }
            after_last = p.elapsed;
        },
    )?;
    let cpu = process_cpu_seconds() - cpu0;
    let n = summary.passes as f64;
    Ok(Sample {
        steady_per_pass: (after_last - after_first) / (n - 1.0),
        cpu_per_pass: cpu / n,
        photon_per_pass: summary.photon_seconds / n,
        grid_per_pass: summary.grid_seconds / n,
        gather_per_pass: summary.gather_seconds / n,
        photons_per_s: summary.photons_emitted as f64 / summary.photon_seconds.max(1e-12),
        visible_points_per_s: summary.visible_points as f64 / summary.gather_seconds.max(1e-12),
    })
}

/// The sample with the median steady-state time per pass.
fn median(samples: &[Sample]) -> Sample {
    let mut v = samples.to_vec();
    v.sort_by(|a, b| a.steady_per_pass.total_cmp(&b.steady_per_pass));
    v[v.len() / 2]
}

/// CPU time (user + system) used by this process so far, from /proc (Linux; 0 elsewhere).
fn process_cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let Some(rest) = stat.rsplit_once(')').map(|(_, r)| r) else {
        return 0.0;
    };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}
