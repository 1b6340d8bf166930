//! `render`: renders a Mitsuba 3 XML scene with the path tracer, direct illumination, Mitsuba's
//! `depth` and `aov` integrators or (multi-level) SPPM and writes a float32 EXR (RGB; an `aov`
//! integrator's named channels; SPPM: sample bundles) and optionally a tone-mapped sRGB PNG.

use anyhow::{bail, Context, Result};
use clap::error::ErrorKind;
use clap::parser::ValueSource;
use clap::{ArgMatches, CommandFactory, FromArgMatches, Parser, ValueEnum};
use cli_output::paths::{check_distinct, check_extension, check_not_directory, extension};
use indicatif::{ProgressBar, ProgressStyle};
use renderer::description::{AovSpec, IntegratorDesc};
use renderer::film::Film;
use renderer::image_io::{write_channels_exr, write_png_srgb, write_rgb_exr};
use renderer::integrators::path::PathTracer;
use renderer::integrators::sppm::{EyeSampler, RadiusSchedule, SharpLevel};
use renderer::integrators::RayIntegrator;
use renderer::parity::aov::{environment_seen, render_aovs, DepthIntegrator};
use renderer::parity::direct::DirectIntegrator;
use renderer::parity::volpath::VolPathTracer;
use renderer::scene::Scene;
use renderer::state_file::StateFile;
use renderer::threads::with_threads;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

/// Which light-transport algorithm renders the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum IntegratorKind {
    /// Unidirectional path tracer with NEE + MIS (Mitsuba's `path`).
    Path,
    /// The path tracer through participating media (Mitsuba's `volpath`).
    Volpath,
    /// Direct illumination only: light and BSDF samples at the first surface, combined by MIS
    /// (Mitsuba's `direct`).
    Direct,
    /// Single-level stochastic progressive photon mapping (the baseline).
    Sppm,
    /// Multi-level SPPM: writes sample bundles with five bandwidths.
    SppmMl,
    /// The distance to the first surface along each camera ray (Mitsuba's `depth`).
    Depth,
    /// The scene file's `aov` integrator: its variables (depth, normals, albedo, …) and the
    /// images of the integrators it nests, as the channels of one EXR (Mitsuba's `aov`).
    Aov,
}

/// Render a Mitsuba 3 XML scene.
#[derive(Debug, Parser)]
#[command(name = "render", version, allow_negative_numbers = true)]
struct Cli {
    /// The scene file (Mitsuba 3 XML).
    scene: PathBuf,
    /// Light-transport algorithm. Default: the scene file's integrator when it is `direct`,
    /// `volpath` (also for `volpathmis`), `depth` or `aov`, else `path`. Only `volpath` renders
    /// participating media.
    #[arg(long, value_enum)]
    integrator: Option<IntegratorKind>,
    /// Output: an RGB EXR for `path`, `volpath`, `direct` and `depth`, a multi-channel EXR for
    /// `aov` (its name ends in `.exr` or has no extension); for the SPPM integrators the prefix of the bundles `<prefix>_p<passes>.exr`
    /// (a trailing `.exr` is dropped: `b.exr` gives `b_p0064.exr`). Missing folders are created.
    #[arg(long, visible_alias = "output", value_name = "PATH")]
    out: PathBuf,
    /// Also write a tone-mapped (clamped, sRGB) PNG preview here (a name ending in `.png` or
    /// without extension).
    #[arg(long, value_name = "FILE")]
    png: Option<PathBuf>,
    /// Random seed; the same seed and settings give a bit-identical image for any thread count.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Override a `<default name=… value=…>` of the scene file: `-D spp=64` (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = renderer::xml::parse_define)]
    define: Vec<(String, String)>,
    /// Turn unsupported plugins/attributes into warnings instead of errors.
    #[arg(long)]
    lenient: bool,
    /// Longest path (Mitsuba's `max_depth`; −1 = unbounded). Path tracer default: the file's,
    /// else −1. SPPM bounds its eye and photon paths by it when positive (default 16; the
    /// file's depth is the path tracer's and is not used).
    #[arg(long, allow_hyphen_values = true, value_parser = clap::value_parser!(i32).range(-1..))]
    max_depth: Option<i32>,
    /// Path tracer: depth at which Russian roulette starts. Default: the file's, else 5.
    #[arg(long, help_heading = "Path tracer")]
    rr_depth: Option<u32>,
    /// Keep the run's state in this file and resume from it when it exists: a killed render
    /// started again with the same arguments continues from its last save (the path tracer's
    /// finished rows, SPPM's last pass; an `aov` integrator's nested images keep theirs in
    /// FILE.<name>) and writes the same outputs as an uninterrupted run. A finished SPPM run
    /// continues when given more passes.
    #[arg(long, value_name = "FILE")]
    state: Option<PathBuf>,
    /// Seconds of rendering between saves of --state (also saved with every SPPM bundle and at
    /// the end).
    #[arg(
        long,
        value_name = "SECONDS",
        default_value_t = 60.0,
        requires = "state"
    )]
    state_interval: f64,

    /// Path tracer and direct: samples per pixel. Default: the file's sampler `sample_count`,
    /// else 16.
    #[arg(long, help_heading = "Path tracer")]
    spp: Option<u32>,

    /// Direct: light samples per pixel sample (Mitsuba's `emitter_samples`). Default: the
    /// file's `direct` integrator's, else 1. SPPM: light samples at each visible point, their
    /// light choices stratified. Default: 2 for `sppm-ml` (the method's setting, docs/sppm.md),
    /// 1 for `sppm` (the paper's standard SPPM). Recorded in the bundles.
    #[arg(long, help_heading = "Direct")]
    emitter_samples: Option<u32>,
    /// Direct: BSDF samples per pixel sample (Mitsuba's `bsdf_samples`). Default: the file's
    /// `direct` integrator's, else 1.
    #[arg(long, help_heading = "Direct")]
    bsdf_samples: Option<u32>,

    /// SPPM: photons traced per pass.
    #[arg(long, default_value_t = 100_000, help_heading = "SPPM")]
    photons: u64,
    /// SPPM: pass counts at which to write a bundle, e.g. `100,200,400` (the run stops at the last).
    #[arg(long, value_delimiter = ',', help_heading = "SPPM")]
    passes: Vec<u32>,
    /// SPPM: stop after this many seconds instead (a bundle is written at the end).
    #[arg(long, help_heading = "SPPM")]
    time: Option<f64>,
    /// SPPM: k of the k-nearest-photon initial radius.
    #[arg(long, default_value_t = renderer::integrators::sppm::DEFAULT_KNN, help_heading = "SPPM")]
    knn: usize,
    /// SPPM: cap on the initial radius in world units (default: 1/50 of the scene's diagonal).
    #[arg(long, help_heading = "SPPM")]
    max_radius: Option<f32>,
    /// SPPM: how the kernel radii evolve over passes: `sppm` shrinks them after every pass,
    /// `cppm` keeps each level's radius while a chi-squared test finds the photons in it
    /// uniform and shrinks it otherwise (docs/sppm.md, "CPPM radius schedule"). Recorded in
    /// the bundles.
    #[arg(long, value_enum, default_value_t = RadiusSchedule::Sppm, help_heading = "SPPM")]
    schedule: RadiusSchedule,
    /// SPPM: share of the infinite lights' (sun, sky, environment) photons aimed at the region
    /// the camera sees, in [0, 1); 0 starts every photon on the scene's bounding disk. Unbiased
    /// either way; off by default (docs/sppm.md, "Photons from infinite lights").
    #[arg(long, default_value_t = renderer::integrators::sppm::DEFAULT_PHOTON_FOCUS, help_heading = "SPPM")]
    photon_focus: f32,
    /// SPPM: where `sppm-ml` gathers the sharp level ỹ's photons: `both` averages the gathers
    /// around eye subpaths A's and B's visible points (the default: less noise for no time),
    /// `a` gathers at A's alone, as the paper and every bundle before 2026-12-06 (docs/sppm.md,
    /// "The sharp level at both subpaths"). Recorded in the bundles; `sppm` takes only `a`.
    #[arg(long, value_enum, help_heading = "SPPM")]
    sharp_level: Option<SharpLevel>,
    /// SPPM: where the eye subpaths' random numbers come from across passes: `independent`
    /// draws (the default; every bundle before 2026-12-06), or `ldsampler`, a scrambled
    /// (0, 2)-sequence per pixel that stratifies the film position, lens and light samples over
    /// the passes (docs/sppm.md, "Eye samples across passes"). Recorded in the bundles.
    #[arg(long, value_enum, default_value_t = EyeSampler::Independent, help_heading = "SPPM")]
    sampler: EyeSampler,
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

/// Options that only the SPPM integrators read, by their clap ids.
const SPPM_ONLY: [&str; 9] = [
    "photons",
    "passes",
    "time",
    "knn",
    "max_radius",
    "schedule",
    "photon_focus",
    "sharp_level",
    "sampler",
];
/// Options that only the direct integrator reads.
const DIRECT_ONLY: [&str; 1] = ["bsdf_samples"];
/// Options that the direct and the SPPM integrators read.
const DIRECT_AND_SPPM: [&str; 1] = ["emitter_samples"];

impl IntegratorKind {
    /// The command-line options (clap ids) this integrator ignores, and who reads them.
    fn ignored_options(self) -> Vec<(&'static str, &'static str)> {
        let sppm = SPPM_ONLY.map(|id| (id, "the SPPM integrators (sppm, sppm-ml)"));
        let direct = DIRECT_ONLY.map(|id| (id, "the direct integrator"));
        let lights = DIRECT_AND_SPPM.map(|id| (id, "the direct and SPPM integrators"));
        match self {
            IntegratorKind::Path | IntegratorKind::Volpath => {
                [&sppm[..], &direct[..], &lights[..]].concat()
            }
            IntegratorKind::Direct => {
                let path = [
                    ("max_depth", "path and SPPM"),
                    ("rr_depth", "the path tracer"),
                ];
                [&sppm[..], &path[..]].concat()
            }
            IntegratorKind::Sppm | IntegratorKind::SppmMl => {
                let path = [("spp", "path and direct"), ("rr_depth", "the path tracer")];
                [&path[..], &direct[..]].concat()
            }
            IntegratorKind::Depth => {
                let path = [
                    ("max_depth", "path and SPPM"),
                    ("rr_depth", "the path tracer"),
                ];
                [&sppm[..], &direct[..], &lights[..], &path[..]].concat()
            }
            // Depths and sample counts go to the integrators it nests.
            IntegratorKind::Aov => sppm.to_vec(),
        }
    }

    /// Whether it writes one image (`path`, `direct`, …) rather than SPPM bundles.
    fn writes_image(self) -> bool {
        !matches!(self, IntegratorKind::Sppm | IntegratorKind::SppmMl)
    }

    /// Its `--integrator` value.
    fn name(self) -> String {
        let value = self.to_possible_value().expect("no skipped variants");
        value.get_name().to_owned()
    }
}

/// The command line, refused (usage error, exit code 2) when it sets an option that the chosen
/// integrator would ignore: `--time` with the path tracer would otherwise render the default
/// 16 spp without a word.
fn parse_cli() -> (Cli, ArgMatches) {
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    if let Some(kind) = cli.integrator {
        if let Some(conflict) = ignored_option_given(&matches, kind) {
            Cli::command()
                .error(ErrorKind::ArgumentConflict, conflict)
                .exit();
        }
    }
    (cli, matches)
}

/// The message for the first option on the command line that integrator `kind` would ignore.
fn ignored_option_given(matches: &ArgMatches, kind: IntegratorKind) -> Option<String> {
    kind.ignored_options()
        .into_iter()
        .find(|(id, _)| matches.value_source(id) == Some(ValueSource::CommandLine))
        .map(|(id, reader)| {
            format!(
                "--{} is read by {reader} only, not by --integrator {}",
                id.replace('_', "-"),
                kind.name()
            )
        })
}

/// The integrator to run: `--integrator`, else the scene file's `direct`, `volpath`
/// (`volpathmis`: the same image), `depth` or `aov`, else `path`. When it
/// comes from the file, an option given for another integrator is refused here, as
/// [`parse_cli`] refuses it for an `--integrator` given on the command line.
fn chosen_integrator(cli: &Cli, matches: &ArgMatches, scene: &Scene) -> Result<IntegratorKind> {
    if let Some(kind) = cli.integrator {
        return Ok(kind);
    }
    let kind = match scene.integrator.as_ref().map(|i| i.kind.as_str()) {
        Some("direct") => IntegratorKind::Direct,
        Some("volpath" | "volpathmis") => IntegratorKind::Volpath,
        Some("depth") => IntegratorKind::Depth,
        Some("aov") => IntegratorKind::Aov,
        _ => IntegratorKind::Path,
    };
    if let Some(conflict) = ignored_option_given(matches, kind) {
        bail!(
            "{conflict} (the integrator of {}; choose one with --integrator)",
            cli.scene.display()
        );
    }
    Ok(kind)
}

fn run() -> Result<()> {
    let (cli, matches) = parse_cli();
    // Everything about the outputs that can be known without the scene is checked first, so a
    // bad name fails at once instead of after the render.
    let outputs = check_outputs(&cli)?;
    let t0 = Instant::now();
    let mut loaded = renderer::scene_file::load(&cli.scene, &cli.define, cli.lenient)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    create_parent_dirs(&outputs)?;
    eprintln!(
        "loaded {} ({} shapes, {} lights) in {:.2} s",
        cli.scene.display(),
        loaded.scene.shapes.len(),
        loaded.scene.lights.len(),
        t0.elapsed().as_secs_f64()
    );
    let integrator = chosen_integrator(&cli, &matches, &loaded.scene)?;
    if matches!(integrator, IntegratorKind::Sppm | IntegratorKind::SppmMl) {
        let before = loaded.warnings.len();
        loaded.check_for_sppm();
        for w in &loaded.warnings[before..] {
            eprintln!("warning: {w}");
        }
    }
    let scene = loaded.scene;
    with_threads(cli.threads, || match integrator {
        IntegratorKind::Path
        | IntegratorKind::Volpath
        | IntegratorKind::Direct
        | IntegratorKind::Depth => run_image(&cli, &scene, integrator),
        IntegratorKind::Aov => run_aov(&cli, &scene),
        IntegratorKind::Sppm => run_sppm(&cli, &scene, false),
        IntegratorKind::SppmMl => run_sppm(&cli, &scene, true),
    })?
}

/// The image extensions other than `.exr` that an SPPM bundle prefix is refused with: `--out
/// b.png` asks for an image the SPPM integrators do not write.
const IMAGE_EXTENSIONS: [&str; 9] = [
    "png", "jpg", "jpeg", "hdr", "tif", "tiff", "bmp", "pfm", "ppm",
];

/// Checks the output paths before anything is loaded or rendered and returns the folders the
/// outputs go to, each with the option that names it:
/// - an output and the PNG preview (or the run-state file, or the scene) that are one file are
///   refused, one would overwrite the other (SPPM: each bundle of a `--passes` checkpoint);
/// - the path tracer's EXR must be named `.exr` (or have no extension), the PNG `.png`: `--out
///   q.png` would otherwise write an EXR named .png; an SPPM prefix must not name an image;
/// - an output that is an existing directory is refused.
///
/// Also the SPPM options that need no scene (`--passes`/`--time`).
fn check_outputs(cli: &Cli) -> Result<Vec<(&'static str, PathBuf)>> {
    // (what names it, path) of every file this run writes or reads
    let mut files: Vec<(String, PathBuf)> = Vec::new();
    let mut folders = Vec::new();
    // Without --integrator it is `path` or the file's `direct`: both write one image.
    let writes_image = cli.integrator.is_none_or(IntegratorKind::writes_image);
    if writes_image {
        check_not_directory("--out", &cli.out).map_err(anyhow::Error::msg)?;
        files.push(("--out".into(), cli.out.clone()));
        folders.push(("--out", cli.out.clone()));
    } else {
        if cli.passes.is_empty() && cli.time.is_none() {
            bail!("SPPM needs --passes N[,N…] and/or --time SECONDS");
        }
        if cli.passes.contains(&0) {
            bail!("--passes values must be at least 1");
        }
        if let Some(ext) = extension(&cli.out).filter(|e| IMAGE_EXTENSIONS.contains(&&**e)) {
            bail!(
                "--out {}: the SPPM integrators write EXR bundles <prefix>_p<passes>.exr, \
                 not a .{ext} image; give a prefix (or a name ending in .exr), and --png \
                 for a preview",
                cli.out.display()
            );
        }
        // Also the folder of a run stopped by --time only.
        folders.push(("--out", bundle_path(&cli.out, 1)));
        let mut passes = cli.passes.clone();
        passes.sort_unstable();
        passes.dedup();
        for n in passes {
            let path = bundle_path(&cli.out, n);
            if path.is_dir() {
                bail!(
                    "{} (the bundle of pass {n} of --out {}) is a directory",
                    path.display(),
                    cli.out.display()
                );
            }
            files.push((format!("the pass-{n} bundle of --out"), path));
        }
    }
    if let Some(png) = &cli.png {
        check_not_directory("--png", png).map_err(anyhow::Error::msg)?;
        files.push(("--png".into(), png.clone()));
        folders.push(("--png", png.clone()));
    }
    if let Some(state) = &cli.state {
        files.push(("--state".into(), state.clone()));
    }
    files.push(("the scene".into(), cli.scene.clone()));
    check_distinct(&files).map_err(anyhow::Error::msg)?;
    if writes_image {
        check_extension(
            "--out",
            &cli.out,
            "exr",
            "the path, volpath, direct, depth and aov integrators write an OpenEXR image",
        )
        .map_err(anyhow::Error::msg)?;
    }
    if let Some(png) = &cli.png {
        check_extension("--png", png, "png", "the preview is a PNG image")
            .map_err(anyhow::Error::msg)?;
    }
    Ok(folders)
}

/// Creates the missing folders of the outputs `files` (option, a file in the folder) before
/// rendering, so that a render is never lost to a missing folder.
fn create_parent_dirs(files: &[(&str, PathBuf)]) -> Result<()> {
    for (option, file) in files {
        cli_output::paths::create_parent_dir(option, file).map_err(anyhow::Error::msg)?;
    }
    Ok(())
}

/// Depth settings: command line, else `file` (the scene file's integrator, or one nested in its
/// `aov`), else Mitsuba's defaults.
fn depths(cli: &Cli, file: Option<&IntegratorDesc>) -> (i32, u32) {
    let max_depth = cli.max_depth.or(file.map(|i| i.max_depth)).unwrap_or(-1);
    let rr_depth = cli.rr_depth.or(file.map(|i| i.rr_depth)).unwrap_or(5);
    (max_depth, rr_depth)
}

/// A progress bar over `total` units of work, labelled with `unit`.
fn progress_bar(total: u64, unit: &str) -> ProgressBar {
    let bar = ProgressBar::new(total);
    let template = format!("{{elapsed_precise}} [{{wide_bar}}] {{human_pos}}/{{human_len}} {unit} ({{per_sec}}, ETA {{eta}})");
    bar.set_style(
        ProgressStyle::with_template(&template)
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar
}

/// Writes the EXR and, if asked, the PNG preview of a film.
fn write_outputs(film: &Film, exr: &Path, png: Option<&Path>) -> Result<()> {
    write_rgb_exr(exr, film.width, film.height, &film.pixels)?;
    if let Some(png) = png {
        write_png_srgb(png, film.width, film.height, &film.pixels)?;
    }
    Ok(())
}

/// The run's state file, when `--state` names one.
fn state_file(cli: &Cli) -> Result<Option<StateFile>> {
    cli.state
        .as_deref()
        .map(|p| state_file_at(cli, p))
        .transpose()
}

/// A state file of this run at `path`.
fn state_file_at(cli: &Cli, path: &Path) -> Result<StateFile> {
    if path.exists() {
        eprintln!("resuming from the run state {}", path.display());
    }
    let (interval, lenient) = (cli.state_interval, cli.lenient);
    StateFile::for_scene(path, interval, &cli.scene, &cli.define, lenient)
}

/// Sample counts of the direct integrator: command line, else `file`'s when it is a `direct`
/// integrator, else Mitsuba's defaults (1 and 1).
fn direct_settings(cli: &Cli, file: Option<&IntegratorDesc>) -> Result<DirectIntegrator> {
    let file = file.filter(|i| i.kind == "direct");
    let emitter = cli.emitter_samples.or(file.map(|i| i.emitter_samples));
    let bsdf = cli.bsdf_samples.or(file.map(|i| i.bsdf_samples));
    DirectIntegrator::new(emitter.unwrap_or(1), bsdf.unwrap_or(1))
        .context("--emitter-samples and --bsdf-samples")
}

/// The samples per pixel: `--spp`, else the file's sampler's `sample_count`, else 16.
fn samples_per_pixel(cli: &Cli, scene: &Scene) -> Result<u32> {
    let spp = cli.spp.or(scene.sample_count).unwrap_or(16);
    if spp == 0 {
        bail!("--spp must be at least 1");
    }
    Ok(spp)
}

/// Refuses a scene with participating media for an integrator that cannot render them (all
/// but `volpath`; `depth` only measures distances to surfaces).
fn refuse_media(cli: &Cli, scene: &Scene, kind: IntegratorKind) -> Result<()> {
    if matches!(kind, IntegratorKind::Volpath | IntegratorKind::Depth) {
        return Ok(());
    }
    scene
        .refuse_media(&kind.name())
        .with_context(|| cli.scene.display().to_string())
}

/// Renders the image of the image integrator `kind` with its settings from the command line,
/// else `file`, resuming from (and saving to) `state`. Returns the film and its settings in
/// words.
fn render_film(
    cli: &Cli,
    scene: &Scene,
    kind: IntegratorKind,
    file: Option<&IntegratorDesc>,
    spp: u32,
    bar: &ProgressBar,
    state: Option<StateFile>,
) -> Result<(Film, String)> {
    let (max_depth, rr_depth) = depths(cli, file);
    Ok(match kind {
        IntegratorKind::Direct => {
            let d = direct_settings(cli, file)?;
            let settings = format!(
                "{} emitter and {} BSDF samples",
                d.emitter_samples, d.bsdf_samples
            );
            (
                render_image(scene, &d, spp, cli.seed, bar, state)?,
                settings,
            )
        }
        IntegratorKind::Volpath => {
            let tracer = VolPathTracer {
                max_depth,
                rr_depth,
            };
            let film = render_image(scene, &tracer, spp, cli.seed, bar, state)?;
            (film, format!("max_depth {max_depth}"))
        }
        IntegratorKind::Depth => {
            let film = render_image(scene, &DepthIntegrator, spp, cli.seed, bar, state)?;
            (film, "distance to the first surface".into())
        }
        _ => {
            let tracer = PathTracer {
                max_depth,
                rr_depth,
            };
            let film = render_image(scene, &tracer, spp, cli.seed, bar, state)?;
            (film, format!("max_depth {max_depth}"))
        }
    })
}

/// The `path`, `volpath`, `direct` and `depth` integrators: one image of `spp` samples per
/// pixel.
fn run_image(cli: &Cli, scene: &Scene, kind: IntegratorKind) -> Result<()> {
    refuse_media(cli, scene, kind)?;
    let spp = samples_per_pixel(cli, scene)?;
    let res = scene.camera.resolution();
    // The film, its copy for the EXR writer and the PNG (12 + 12 + 4 bytes per pixel); a state
    // file adds its encoded copy.
    let per_pixel = if cli.state.is_some() { 40 } else { 28 };
    renderer::memory::check_fits(
        &format!("a {}x{} image", res.x, res.y),
        res.x as u64 * res.y as u64 * per_pixel,
    )?;
    // Rows restored from a state file were not rendered now: no throughput for this session.
    let resumed = cli.state.as_ref().is_some_and(|p| p.exists());
    let total = res.x as u64 * res.y as u64 * spp as u64;
    let bar = progress_bar(total, "samples");
    let t = Instant::now();
    let file = scene.integrator.as_ref();
    let (film, settings) = render_film(cli, scene, kind, file, spp, &bar, state_file(cli)?)?;
    bar.finish_and_clear();
    let secs = t.elapsed().as_secs_f64();
    let rate = if resumed {
        "resumed".to_string()
    } else {
        format!("{:.2} M samples/s", total as f64 / secs / 1e6)
    };
    eprintln!(
        "{}: {}x{} at {spp} spp, {settings}, in {secs:.2} s ({rate}); mean RGB {:?}",
        kind.name(),
        res.x,
        res.y,
        film.mean().to_array()
    );
    write_outputs(&film, &cli.out, cli.png.as_deref())
}

/// The image integrator an `aov` integrator nests as `desc` (the XML accepts only these).
fn nested_kind(desc: &IntegratorDesc) -> IntegratorKind {
    match desc.kind.as_str() {
        "volpath" | "volpathmis" => IntegratorKind::Volpath,
        "direct" => IntegratorKind::Direct,
        "depth" => IntegratorKind::Depth,
        _ => IntegratorKind::Path,
    }
}

/// The state file of the image nested as `name`, next to `--state`: `<state>.<name>`.
fn nested_state_path(state: &Path, name: &str) -> PathBuf {
    let mut path = state.as_os_str().to_owned();
    path.push(format!(".{name}"));
    PathBuf::from(path)
}

/// The scene file's `aov` integrator: each nested integrator's image (resumable from
/// `<state>.<name>`), then the variables, written as one multi-channel EXR with Mitsuba's
/// channel names — `R`, `G`, `B` (the first nested image), `<name>.R`…`<name>.A` per nested
/// image, `<variable>.<suffix>` per variable — and the first nested image as the PNG.
fn run_aov(cli: &Cli, scene: &Scene) -> Result<()> {
    let Some(aov) = scene.integrator.as_ref().filter(|i| i.kind == "aov") else {
        bail!(
            "--integrator aov: {} has no aov integrator (its variables and nested integrators \
             are read from the file)",
            cli.scene.display()
        );
    };
    if cli.png.is_some() && aov.nested.is_empty() {
        bail!(
            "--png: the aov integrator of {} nests no integrator, so it renders no image to \
             preview",
            cli.scene.display()
        );
    }
    for (_, desc) in &aov.nested {
        refuse_media(cli, scene, nested_kind(desc))?;
    }
    let spp = samples_per_pixel(cli, scene)?;
    let res = scene.camera.resolution();
    let pixels = res.x as u64 * res.y as u64;
    let channels = 3 + 4 * aov.nested.len() + aovs_channel_count(&aov.aovs);
    // Per nested image its film and planes (24 bytes + a state file's 12), and every channel
    // twice (planes and the interleaved render).
    let per_pixel = 36 * aov.nested.len() as u64 + 8 * channels as u64;
    renderer::memory::check_fits(
        &format!("a {}x{} image of {channels} channels", res.x, res.y),
        pixels * per_pixel,
    )?;
    let bar = progress_bar(
        pixels * spp as u64 * (aov.nested.len() as u64 + 1),
        "samples",
    );
    let t = Instant::now();
    let mut films = Vec::new();
    for (name, desc) in &aov.nested {
        let kind = nested_kind(desc);
        let state = match &cli.state {
            Some(p) => Some(state_file_at(cli, &nested_state_path(p, name))?),
            None => None,
        };
        let (film, settings) = render_film(cli, scene, kind, Some(desc), spp, &bar, state)?;
        bar.println(format!("{name}: {} ({settings})", desc.kind));
        films.push(film);
    }
    let variables = render_aovs(scene, &aov.aovs, spp, cli.seed, Some(&bar));
    bar.finish_and_clear();
    let rgb_planes = |film: &Film| -> [Vec<f32>; 3] {
        std::array::from_fn(|c| film.pixels.iter().map(|p| p[c]).collect())
    };
    let mut planes: Vec<(String, Vec<f32>)> = Vec::new();
    let base = films.first().map_or_else(
        || std::array::from_fn(|_| vec![0.0; pixels as usize]),
        rgb_planes,
    );
    planes.extend(["R", "G", "B"].into_iter().map(String::from).zip(base));
    // Mitsuba's alpha: the samples that met a surface, or all of them for the path tracers
    // under a visible environment light.
    let env = environment_seen(scene);
    for ((name, desc), film) in aov.nested.iter().zip(&films) {
        let [r, g, b] = rgb_planes(film);
        let alpha = match nested_kind(desc) {
            IntegratorKind::Path | IntegratorKind::Volpath if env => variables.weights.clone(),
            _ => variables.hits.clone(),
        };
        for (c, plane) in ["R", "G", "B", "A"].into_iter().zip([r, g, b, alpha]) {
            planes.push((format!("{name}.{c}"), plane));
        }
    }
    planes.extend(variables.channels.into_iter().zip(variables.planes));
    eprintln!(
        "aov: {}x{} at {spp} spp, {} nested images and {} variables ({} channels) in {:.2} s",
        res.x,
        res.y,
        films.len(),
        aov.aovs.len(),
        planes.len(),
        t.elapsed().as_secs_f64()
    );
    write_channels_exr(&cli.out, res.x, res.y, planes)?;
    if let (Some(png), Some(film)) = (&cli.png, films.first()) {
        write_png_srgb(png, film.width, film.height, &film.pixels)?;
    }
    Ok(())
}

/// The channels the variables `aovs` fill.
fn aovs_channel_count(aovs: &[AovSpec]) -> usize {
    aovs.iter().map(|a| a.kind.suffixes().len()).sum()
}

/// Renders the image with `integrator`, resuming from `state` when given.
fn render_image(
    scene: &Scene,
    integrator: &impl RayIntegrator,
    spp: u32,
    seed: u64,
    bar: &ProgressBar,
    state: Option<StateFile>,
) -> Result<Film> {
    Ok(match state {
        Some(state) => integrator.render_resumable(scene, spp, seed, Some(bar), &state)?,
        None => integrator.render(scene, spp, seed, Some(bar)),
    })
}

// ---------------------------------------------------------------------------------------------
// SPPM dispatch arm: owned by the SPPM integrator (renderer::integrators::sppm). It receives the
// parsed command line (--photons, --passes, --time, --seed, --out, --png, depths) and the scene.
// ---------------------------------------------------------------------------------------------

/// The bundle file of `passes` passes for the output prefix `out`: `<out>_p<passes>.exr`, a
/// trailing `.exr` of the prefix dropped first (`b.exr` → `b_p0064.exr`, not `b.exr_p0064.exr`).
fn bundle_path(out: &Path, passes: u32) -> PathBuf {
    let prefix = match out.extension() {
        Some(ext) if ext.eq_ignore_ascii_case("exr") => out.with_extension(""),
        _ => out.to_owned(),
    };
    let mut name = prefix.into_os_string();
    name.push(format!("_p{passes:04}.exr"));
    PathBuf::from(name)
}

/// The `sppm` (single-level) and `sppm-ml` (multi-level) integrators: one continuing run that
/// writes a bundle `<out>_p<passes>.exr` at each `--passes` checkpoint (or once at `--time`).
fn run_sppm(cli: &Cli, scene: &Scene, multi_level: bool) -> Result<()> {
    use renderer::integrators::sppm::{
        render_sppm_resumable, SppmMode, SppmSettings, StopCondition, DEFAULT_MAX_DEPTH,
    };
    if let Some(w) = renderer::integrators::sppm::filter_warning(scene.camera.filter().desc()) {
        eprintln!("warning: {w}");
    }
    let mode = if multi_level {
        SppmMode::MultiLevel
    } else {
        SppmMode::Single
    };
    let settings = SppmSettings {
        photons_per_pass: cli.photons,
        seed: cli.seed,
        max_radius: cli.max_radius,
        knn: cli.knn,
        mode,
        schedule: cli.schedule,
        // SPPM bounds eye (delta/glossy) and photon bounces; the file's depth is the path
        // tracer's and is not used.
        max_depth: cli
            .max_depth
            .filter(|&d| d > 0)
            .map_or(DEFAULT_MAX_DEPTH, |d| d as u32),
        emitter_samples: cli.emitter_samples,
        photon_focus: cli.photon_focus,
        sharp_level: cli.sharp_level,
        sampler: cli.sampler,
        threads: cli.threads,
        scene_name: cli.scene.display().to_string(),
        ..SppmSettings::default()
    };
    let stop = StopCondition {
        checkpoints: cli.passes.clone(),
        seconds: cli.time,
    };
    let state = state_file(cli)?;
    let target = cli.passes.iter().copied().max();
    let bar = match target {
        Some(n) => progress_bar(n as u64, "passes"),
        None => ProgressBar::new_spinner(),
    };
    if target.is_none() {
        bar.set_style(
            ProgressStyle::with_template("{elapsed_precise} {spinner} pass {pos} {msg}")
                .expect("valid template"),
        );
    }
    let res = scene.camera.resolution();
    let mut last_bundle = None;
    let summary = render_sppm_resumable(
        scene,
        &settings,
        &stop,
        state.as_ref(),
        |b| {
            let path = bundle_path(&cli.out, b.meta.passes);
            bundle::write_bundle(&path, &b)?;
            bar.println(format!(
                "pass {:5}: wrote {} ({:.1} s)",
                b.meta.passes,
                path.display(),
                b.meta.seconds
            ));
            last_bundle = Some(b);
            Ok(())
        },
        |p| {
            bar.set_position(p.pass as u64);
            bar.set_message(format!(
                "{:.2} passes/s, {:.2} M photons/s",
                p.pass as f64 / p.elapsed,
                p.photons_emitted as f64 / p.elapsed / 1e6
            ));
        },
    )
    .with_context(|| format!("rendering {}", cli.scene.display()))?;
    bar.finish_and_clear();
    if summary.resumed_from > 0 {
        eprintln!("resumed at pass {}", summary.resumed_from);
        // Bundles of checkpoints before the saved pass come from the earlier sessions only.
        for &c in cli.passes.iter().filter(|&&c| c < summary.resumed_from) {
            let path = bundle_path(&cli.out, c);
            if !path.exists() {
                eprintln!(
                    "warning: no bundle {}: pass {c} lies before the saved pass {}, and the \
                     earlier sessions of this run did not write it",
                    path.display(),
                    summary.resumed_from
                );
            }
        }
    }
    let secs = summary.seconds.max(1e-9);
    eprintln!(
        "{}{}: {}x{}, {} passes x {} photons in {secs:.2} s: {:.3} passes/s, {:.3} M photons/s \
         (photon pass {:.2} s), {:.3} M visible points/s (eye paths + gathering {:.2} s)",
        mode.name(),
        match settings.schedule {
            RadiusSchedule::Sppm => "",
            RadiusSchedule::Cppm => " (cppm radii)",
        },
        res.x,
        res.y,
        summary.passes,
        settings.photons_per_pass,
        summary.passes as f64 / secs,
        summary.photons_emitted as f64 / summary.photon_seconds.max(1e-9) / 1e6,
        summary.photon_seconds,
        summary.visible_points as f64 / summary.gather_seconds.max(1e-9) / 1e6,
        summary.gather_seconds,
    );
    if let (Some(png), Some(b)) = (&cli.png, &last_bundle) {
        // Preview: the sharpest level (y).
        let y = &b.levels[0];
        let pixels: Vec<_> = y
            .data
            .chunks_exact(3)
            .map(|c| glam::Vec3::new(c[0], c[1], c[2]))
            .collect();
        write_png_srgb(png, res.x, res.y, &pixels)?;
    }
    Ok(())
}
