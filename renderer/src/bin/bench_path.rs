//! `bench_path`: path-tracing throughput (samples/s) on a scene, with 1 and 2 threads (or the
//! counts given), for docs/performance.md. Default: Mitsuba's Cornell box at 256×256,
//! max_depth 8, as in the Mitsuba 3 peer measurement of BASELINES.md.

use anyhow::Result;
use clap::Parser;
use renderer::integrators::path::PathTracer;
use renderer::integrators::RayIntegrator;
use renderer::threads::with_threads;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// The scene measured when none is given: Mitsuba's Cornell box from the shared test scenes
/// next to the repository.
const DEFAULT_SCENE: &str = "../shared/scenes/external/cbox/scene.xml";

/// Measure path-tracing samples per second.
#[derive(Debug, Parser)]
#[command(version, allow_negative_numbers = true)]
struct Cli {
    /// Scene file (Mitsuba 3 XML).
    #[arg(default_value = DEFAULT_SCENE)]
    scene: PathBuf,
    /// Image side length (sets the `res` default of the file).
    #[arg(long, default_value_t = 256)]
    res: u32,
    /// Samples per pixel per measurement.
    #[arg(long, default_value_t = 16)]
    spp: u32,
    /// Mitsuba's `max_depth`.
    #[arg(long, default_value_t = 8, allow_hyphen_values = true)]
    max_depth: i32,
    /// Thread counts to measure (each 1 to 1024).
    #[arg(long, value_delimiter = ',', default_value = "1,2",
          value_parser = clap::value_parser!(u16).range(1..=1024))]
    threads: Vec<u16>,
    /// Repetitions per thread count (the best is reported).
    #[arg(long, default_value_t = 3)]
    repeat: u32,
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
    let defines = vec![("res".to_string(), cli.res.to_string())];
    cli_output::paths::check_default_input(&cli.scene, DEFAULT_SCENE, "the default scene (Mitsuba's Cornell box from the shared test scenes next to the repository)")
        .map_err(anyhow::Error::msg)?;
    let loaded = renderer::scene_file::load(&cli.scene, &defines, false)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    let scene = loaded.scene;
    let res = scene.camera.resolution();
    let pt = PathTracer {
        max_depth: cli.max_depth,
        rr_depth: 5,
    };
    let samples = res.x as f64 * res.y as f64 * cli.spp as f64;
    let mut results = Vec::new();
    for &threads in &cli.threads {
        let mut best = f64::INFINITY;
        let mut best_cpu = f64::INFINITY;
        for rep in 0..cli.repeat {
            let cpu0 = process_cpu_seconds();
            let t = Instant::now();
            let film = with_threads(usize::from(threads), || {
                pt.render(&scene, cli.spp, rep as u64, None)
            })?;
            let secs = t.elapsed().as_secs_f64();
            let cpu = process_cpu_seconds() - cpu0;
            std::hint::black_box(&film);
            best = best.min(secs);
            best_cpu = best_cpu.min(cpu);
        }
        let rate = samples / best / 1e6;
        println!(
            "threads {threads}: {}x{} x {} spp, max_depth {}: best {best:.3} s wall = {rate:.3} M samples/s \
             (CPU {best_cpu:.2} s = {:.3} M samples/s per busy core)",
            res.x,
            res.y,
            cli.spp,
            cli.max_depth,
            samples / best_cpu / 1e6
        );
        results.push((threads, rate));
    }
    if let (Some(&(t1, r1)), Some(&(t2, r2))) = (results.first(), results.get(1)) {
        println!("scaling {t1} -> {t2} threads: {:.2}x", r2 / r1);
    }
    Ok(())
}

/// CPU time (user + system) used by this process so far, from /proc (Linux; 0 elsewhere). On a
/// shared, loaded machine wall time overstates the cost; CPU time shows what the work needs.
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
    // rest starts at field 3 (state): utime = field 14 → index 11, stime → index 12.
    (ticks(11) + ticks(12)) / 100.0
}
