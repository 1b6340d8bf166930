//! `infer`: post-reconstruction in one command (docs/method.md §7). Reads a multi-level SPPM bundle, or
//! renders one from a Mitsuba XML scene first, and combines its five levels with trained
//! weights; writes the result as EXR (+ PNG previews) and, given a reference, the relMSE of
//! every input level and of the output.

use cli_output::paths::{check_distinct, check_extension, check_not_directory, create_parent_dir};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use bundle::{read_bundle, read_rgb_exr_image, write_bundle, write_rgb_exr_image, Bundle};
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::error::ErrorKind;
use clap::parser::ValueSource;
use clap::{CommandFactory, FromArgMatches, Parser};
use indicatif::{ProgressBar, ProgressStyle};
use infer::preview::{write_side_by_side, write_weight_map, Panel};
use infer::{reconstruct_tiled, Engine, ErrorReport};
use model::backend::Backend;
use model::features::{interleaved, pack, pack_with, planar_reference};
use model::model_dir::TrainedModel;
use renderer::integrators::sppm::RadiusSchedule;

/// Reconstruct a multi-level SPPM render with a trained combiner network.
///
/// Either `--input bundle.exr` (written by `render --integrator sppm-ml` or `datagen`) or
/// `--scene scene.xml` (renders the bundle first).
#[derive(Debug, Parser)]
#[command(
    name = "infer",
    version,
    allow_negative_numbers = true,
    override_usage = "infer [OPTIONS] --input <bundle.exr> --output <out.exr>\n       \
                      infer [OPTIONS] --scene <scene.xml> [--output <out.exr>]"
)]
struct Cli {
    /// Trained model directory (`model.json` + `model.bpk`, as written by `train`).
    #[arg(long, default_value = DEFAULT_MODEL)]
    model: PathBuf,
    /// Sample bundle to reconstruct (this or `--scene` is required).
    #[arg(long, value_name = "bundle.exr", conflicts_with = "scene")]
    input: Option<PathBuf>,
    /// Render this Mitsuba 3 XML scene with multi-level SPPM first, then reconstruct.
    #[arg(long, value_name = "scene.xml")]
    scene: Option<PathBuf>,
    /// Output EXR (RGB; a name ending in `.exr` or without extension; missing folders are
    /// created). Required with `--input`; default with `--scene`: `out/<name>/ours.exr`, the
    /// name being the scene file's stem, or its folder's name for a file called `scene.xml`.
    #[arg(long, visible_alias = "out", value_name = "out.exr")]
    output: Option<PathBuf>,
    /// Reference RGB EXR: report relMSE of every input level and of the output.
    #[arg(long)]
    reference: Option<PathBuf>,
    /// Also write PNG previews: the output, standard SPPM | ours | reference, the weight map.
    #[arg(long)]
    png: bool,
    /// Tensor backend.
    #[arg(long, default_value = "flex", value_parser = backend_parser())]
    backend: Backend,
    /// Inference engine: `native` (CPU im2col + gemm, fused combination) or `burn` (Burn's
    /// tensor operations on `--backend`). Default: native with flex, Burn otherwise.
    #[arg(long, value_enum)]
    engine: Option<Engine>,
    /// Tile side in pixels (a halo covering the receptive field is added; the last layer and
    /// the combination run in bands of rows, so memory stays near 1 GB); 0 = whole image.
    /// Default: 512, or 1024 for a U-Net (its halo is wider, its activations narrower).
    #[arg(long)]
    tile: Option<usize>,
    /// Strength κ of the guard towards the smoothest level, replacing the model's (`guard` in
    /// model.json; docs/method.md §5.4); 0 = Eq. 6 alone.
    #[arg(long)]
    guard: Option<f32>,
    /// The guard's trust λ in the smoothest level, replacing the model's (`guard_target_noise`
    /// in model.json; docs/method.md §5.4); 0 = the smoothest level taken as exact.
    #[arg(long, value_name = "LAMBDA")]
    guard_target_noise: Option<f32>,
    /// Combine the whole levels with Eq. 6, as the paper does, instead of leaving the bundle's
    /// photon-free part (emission, direct light) out of the window filter. With `--guard 0`:
    /// the paper's reconstruction exactly.
    #[arg(long)]
    whole_levels: bool,

    /// `--scene`: SPPM passes to render [default: 64, or no pass limit with --time].
    #[arg(long, help_heading = "Rendering (--scene)")]
    passes: Option<u32>,
    /// `--scene`: render for this many seconds instead: the render stops after the first pass
    /// that ends past it (the reconstruction's time comes on top). With --passes too, whichever
    /// comes first.
    #[arg(long, value_name = "SECONDS", help_heading = "Rendering (--scene)")]
    time: Option<f64>,
    /// `--scene`: photons traced per pass.
    #[arg(long, default_value_t = 100_000, help_heading = "Rendering (--scene)")]
    photons: u64,
    /// `--scene`: how the kernel radii evolve over passes (as `render --schedule`): `sppm`
    /// shrinks them after every pass, `cppm` per level by a chi-squared test of the photons
    /// in the kernel (docs/sppm.md, "CPPM radius schedule"). The bundled models were trained
    /// on `sppm` bundles.
    #[arg(
        long,
        value_enum,
        default_value_t = RadiusSchedule::Sppm,
        help_heading = "Rendering (--scene)"
    )]
    schedule: RadiusSchedule,
    /// `--scene`: random seed of the render.
    #[arg(long, default_value_t = 1, help_heading = "Rendering (--scene)")]
    seed: u64,
    /// Worker threads of the render and of the reconstruction (0 = all cores; the output does
    /// not depend on it).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// `--scene`: longest eye and photon path of the render (as `render --max-depth` for SPPM;
    /// the scene file's depth is the path tracer's and is not used) [default: 16].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..), help_heading = "Rendering (--scene)")]
    max_depth: Option<u32>,
    /// `--scene`: light samples at each visible point, their light choices stratified (as
    /// `render --emitter-samples` for `sppm-ml`) [default: 2].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..), help_heading = "Rendering (--scene)")]
    emitter_samples: Option<u32>,
    /// `--scene`: where the sharp level's photons are gathered (as `render --sharp-level`):
    /// `both` eye subpaths' visible points, or `a` alone [default: both].
    #[arg(long, value_enum, help_heading = "Rendering (--scene)")]
    sharp_level: Option<renderer::integrators::sppm::SharpLevel>,
    /// `--scene`: where the eye subpaths' random numbers come from across passes (as `render
    /// --sampler`): `independent` or `ldsampler` [default: independent].
    #[arg(long, value_enum, help_heading = "Rendering (--scene)")]
    sampler: Option<renderer::integrators::sppm::EyeSampler>,
    /// `--scene`: turn unsupported plugins/attributes of the scene into warnings instead of
    /// errors (as `render --lenient`).
    #[arg(long, help_heading = "Rendering (--scene)")]
    lenient: bool,
    /// `--scene`: override a `<default name=… value=…>` of the scene, e.g. `-D res=128`.
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = renderer::xml::parse_define, help_heading = "Rendering (--scene)")]
    define: Vec<(String, String)>,
    /// `--scene`: keep the render's state in this file and resume from it when it exists (a
    /// killed run started again continues from its last save, bit-identically; see `render
    /// --state`).
    #[arg(long, value_name = "FILE", help_heading = "Rendering (--scene)")]
    state: Option<PathBuf>,
    /// `--scene`: seconds of rendering between saves of --state.
    #[arg(
        long,
        value_name = "SECONDS",
        default_value_t = 60.0,
        requires = "state",
        help_heading = "Rendering (--scene)"
    )]
    state_interval: f64,
}

/// `--backend`'s values, listed in `--help` and in the error for an unknown one.
fn backend_parser() -> impl TypedValueParser<Value = Backend> {
    PossibleValuesParser::new([
        PossibleValue::new("flex").help("Burn's pure-Rust CPU backend"),
        PossibleValue::new("ndarray").help("burn-ndarray (CPU; slow)"),
        PossibleValue::new("wgpu").help("burn-wgpu: needs the `wgpu` cargo feature and a GPU"),
    ])
    .try_map(|name| Backend::parse(&name))
}

/// `--model`'s default: the bundled weights, relative to the repository root.
const DEFAULT_MODEL: &str = "models/default";

/// The options that only `--scene` reads (it renders; `--input` does not), by their clap ids.
const RENDERING_ONLY: [&str; 13] = [
    "passes",
    "time",
    "photons",
    "schedule",
    "seed",
    "max_depth",
    "emitter_samples",
    "sharp_level",
    "sampler",
    "lenient",
    "define",
    "state",
    "state_interval",
];

/// The command line, refused (usage error, exit code 2) when it sets a rendering option without
/// `--scene`: `--input b.exr --passes 256` would otherwise reconstruct the bundle as it is and
/// ignore the option. (Checked here, not with clap's `requires`: clap does not enforce that on
/// an option whose required one conflicts with a given one, as `--scene` does with `--input`.)
fn parse_cli() -> Cli {
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    // Checked here, not by clap: its message would name `--input` and `--output` only.
    let missing = match (&cli.input, &cli.scene, &cli.output) {
        (None, None, _) => Some("one of --input <bundle.exr> or --scene <scene.xml> is required"),
        (Some(_), None, None) => {
            Some("--output <out.exr> is required with --input (only --scene has a default output)")
        }
        _ => None,
    };
    if let Some(message) = missing {
        Cli::command()
            .error(ErrorKind::MissingRequiredArgument, message)
            .exit();
    }
    if cli.scene.is_none() {
        let given = RENDERING_ONLY
            .iter()
            .find(|id| matches.value_source(id) == Some(ValueSource::CommandLine));
        if let Some(id) = given {
            let flag = match *id {
                "define" => "-D".to_string(),
                id => format!("--{}", id.replace('_', "-")),
            };
            Cli::command()
                .error(
                    ErrorKind::MissingRequiredArgument,
                    format!("{flag} sets how --scene renders; it needs --scene, not --input"),
                )
                .exit();
        }
    }
    cli
}

fn main() -> ExitCode {
    cli_output::install();
    infer::memory::retain_freed_memory();
    let cli = parse_cli();
    // Every parallel part (the render, the native engine, Burn's CPU backends) runs on rayon:
    // one pool of `--threads` bounds them all.
    let result = renderer::threads::with_threads(cli.threads, || run(&cli)).and_then(|r| r);
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// `<stem><suffix>` next to `path` (e.g. `out.exr` → `out_compare.png`).
fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    path.with_file_name(format!("{stem}{suffix}"))
}

/// `--scene`'s default output `out/<name>/ours.exr`: `<name>` is the scene file's stem
/// (`sc/volpath.xml` → `out/volpath/ours.exr`, so two scenes of one folder do not share an
/// output), or the name of its folder for a file called `scene.xml` (`scenes/default/scene.xml`
/// → `out/default/ours.exr`).
fn default_output(scene: &Path) -> PathBuf {
    let stem = scene
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty());
    let name = match stem {
        Some(stem) if stem != "scene" => stem,
        _ => scene
            .parent()
            .and_then(|p| p.file_name())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into()),
    };
    PathBuf::from("out").join(name).join("ours.exr")
}

/// The PNG of the output (`--png`).
fn png_path(output: &Path) -> PathBuf {
    output.with_extension("png")
}

/// The comparison PNG (`--png`).
fn compare_path(output: &Path) -> PathBuf {
    sibling(output, "_compare.png")
}

/// The weight-map PNG (`--png`).
fn weights_path(output: &Path) -> PathBuf {
    sibling(output, "_weights.png")
}

/// The relMSE report (`--reference`).
fn report_path(output: &Path) -> PathBuf {
    sibling(output, "_report.json")
}

/// The bundle `--scene` renders.
fn bundle_path(output: &Path) -> PathBuf {
    sibling(output, "_bundle.exr")
}

/// Checks, before any work, the files this run writes: the output is an EXR named `.exr` (or
/// without extension: `--output z.png` would write an EXR named .png, then its PNG preview over
/// it), no output is an existing directory, and no two of the outputs and inputs (`--input`,
/// `--reference`, `--scene`, `--state`) are one file.
fn check_outputs(cli: &Cli, output: &Path) -> Result<()> {
    let option = if cli.output.is_some() {
        "--output"
    } else {
        "the default output"
    };
    check_not_directory(option, output).map_err(anyhow::Error::msg)?;
    check_extension(
        option,
        output,
        "exr",
        "the output is an OpenEXR image (--png writes the PNG previews next to it)",
    )
    .map_err(anyhow::Error::msg)?;
    // (what names it, path)
    let mut files: Vec<(String, PathBuf)> = vec![(option.to_string(), output.to_owned())];
    if cli.scene.is_some() {
        files.push(("the bundle (--scene)".into(), bundle_path(output)));
    }
    if cli.png {
        files.push(("the PNG (--png)".into(), png_path(output)));
        files.push(("the comparison PNG (--png)".into(), compare_path(output)));
        files.push(("the weight map (--png)".into(), weights_path(output)));
    }
    if cli.reference.is_some() {
        files.push(("the report (--reference)".into(), report_path(output)));
    }
    for (what, path) in &files[1..] {
        if path.is_dir() {
            bail!("{} ({what}) is a directory", path.display());
        }
    }
    let inputs = [
        ("--input", &cli.input),
        ("--reference", &cli.reference),
        ("--scene", &cli.scene),
        ("--state", &cli.state),
    ];
    files.extend(
        inputs
            .into_iter()
            .filter_map(|(what, path)| Some((what.to_string(), path.clone()?))),
    );
    check_distinct(&files).map_err(anyhow::Error::msg)?;
    Ok(())
}

fn run(cli: &Cli) -> Result<()> {
    // The output paths are checked before anything is loaded, rendered or reconstructed.
    let output = match (&cli.output, &cli.scene) {
        (Some(output), _) => output.clone(),
        (None, Some(scene)) => default_output(scene),
        (None, None) => bail!("give --output out.exr"),
    };
    check_outputs(cli, &output)?;
    let device = cli.backend.device().map_err(anyhow::Error::msg)?;
    if let Some(note) = cli.backend.adapter_note(&device) {
        eprintln!("{note}");
    }
    let mut model = TrainedModel::open(&cli.model, &device).with_context(|| {
        // The default is relative to the repository root: say so where it is the default.
        let hint = if cli.model == Path::new(DEFAULT_MODEL) && !cli.model.exists() {
            " (the default, relative to the repository root: run from there or give --model DIR)"
        } else {
            ""
        };
        format!("loading model {}{hint}", cli.model.display())
    })?;
    if let Some(guard) = cli.guard {
        model.config.guard = guard;
        model
            .config
            .validate()
            .map_err(|e| anyhow::anyhow!("--guard: {e}"))?;
    }
    if let Some(lambda) = cli.guard_target_noise {
        model.config.guard_target_noise = lambda;
        model
            .config
            .validate()
            .map_err(|e| anyhow::anyhow!("--guard-target-noise: {e}"))?;
    }
    eprintln!(
        "model {}: preset {:?}, window {}×{}, receptive radius {} px, backend {:?}, engine {:?}",
        cli.model.display(),
        model.config.preset,
        model.config.window,
        model.config.window,
        model.config.receptive_radius(),
        cli.backend,
        cli.engine.unwrap_or(Engine::default_for(cli.backend))
    );

    // Read the reference before any rendering so a bad file fails fast.
    let reference_image = match &cli.reference {
        Some(path) => Some((path, read_rgb_exr_image(path)?)),
        None => None,
    };
    let (bundle, source) = match (&cli.input, &cli.scene) {
        (Some(input), _) => {
            let bundle = read_bundle(input)?;
            create_parent_dir("--output", &output).map_err(anyhow::Error::msg)?;
            (bundle, input)
        }
        (None, Some(scene)) => {
            let bundle = render_bundle(cli, scene, &output)?;
            let bundle_path = bundle_path(&output);
            write_bundle(&bundle_path, &bundle)?;
            eprintln!("wrote {} (the multi-level bundle)", bundle_path.display());
            (bundle, scene)
        }
        (None, None) => bail!("give --input bundle.exr or --scene scene.xml"),
    };
    // The levels as rendered (the report's and the pictures'), and the network's input: the
    // same, or with the model's screen-space levels in place.
    let mut packed = pack(&bundle).with_context(|| format!("bundle {}", source.display()))?;
    let mut input = if model.config.screen_levels.is_empty() {
        None
    } else {
        Some(pack_with(&bundle, &model.config.packing())?)
    };
    if cli.whole_levels {
        packed.direct = None;
        if let Some(i) = &mut input {
            i.direct = None;
        }
    }
    let reference = match reference_image {
        Some((path, image)) => Some(
            planar_reference(&image, packed.width, packed.height)
                .with_context(|| format!("reference {}", path.display()))?,
        ),
        None => None,
    };

    let t = Instant::now();
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{wide_bar}] tile {pos}/{len} (ETA {eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let engine = cli.engine.unwrap_or(Engine::default_for(cli.backend));
    let tile = cli.tile.unwrap_or(model.config.default_tile());
    let result = reconstruct_tiled(
        &model,
        input.as_ref().unwrap_or(&packed),
        tile,
        engine,
        &device,
        |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
    );
    bar.finish_and_clear();
    let seconds = t.elapsed().as_secs_f64();
    eprintln!(
        "reconstructed {}×{} in {seconds:.2} s ({} px tiles)",
        packed.width, packed.height, tile
    );

    // Finite inputs can still overflow float32 in Eq. 6 (values near f32::MAX): say so
    // instead of writing an image of infinities.
    if let Some(i) = result.image.iter().position(|v| !v.is_finite()) {
        let pixel = i % (packed.width * packed.height);
        bail!(
            "{}: the reconstruction is not finite at pixel ({}, {}), channel {}: the bundle's \
             values are too large for float32 arithmetic; nothing written",
            source.display(),
            pixel % packed.width,
            pixel / packed.width,
            ["R", "G", "B"][i / (packed.width * packed.height)]
        );
    }
    write_rgb_exr_image(
        &output,
        &interleaved(&result.image, packed.width, packed.height, 3),
    )?;
    let mut written = vec![output.clone()];
    if cli.scene.is_some() {
        written.push(bundle_path(&output));
    }
    if cli.png {
        let png = png_path(&output);
        let (w, h) = (packed.width, packed.height);
        write_side_by_side(
            &png,
            w,
            h,
            &[Panel {
                planes: &result.image,
            }],
        )?;
        let mut panels = vec![
            Panel {
                planes: packed.level(1),
            },
            Panel {
                planes: &result.image,
            },
        ];
        if let Some(r) = &reference {
            panels.push(Panel { planes: r });
        }
        let compare = compare_path(&output);
        write_side_by_side(&compare, w, h, &panels)?;
        let weights = weights_path(&output);
        write_weight_map(&weights, w, h, &result.shares)?;
        written.extend([png, compare, weights]);
    }
    if let Some(r) = &reference {
        let report = ErrorReport::new(&packed, &result.image, r);
        print!("{}", report.to_text());
        let json = report_path(&output);
        fileio::atomic::write_bytes(&json, serde_json::to_string_pretty(&report)?.as_bytes())
            .with_context(|| format!("writing {}", json.display()))?;
        written.push(json);
    }
    println!("wrote:");
    for p in written {
        println!("  {}", p.display());
    }
    Ok(())
}

/// Passes `infer --scene` renders when given neither `--passes` nor `--time`.
const DEFAULT_PASSES: u32 = 64;

/// Renders `scene` with multi-level SPPM for `--passes` passes (and/or `--time` seconds) and
/// returns the bundle; creates the folder of `output` once the scene has loaded.
fn render_bundle(cli: &Cli, scene_path: &Path, output: &Path) -> Result<Bundle> {
    use renderer::integrators::sppm::{
        render_sppm_resumable, SppmMode, SppmSettings, StopCondition,
    };
    use renderer::state_file::StateFile;
    let passes = match (cli.passes, cli.time) {
        (Some(0), _) => bail!("--passes must be at least 1"),
        (Some(n), _) => Some(n),
        (None, Some(_)) => None,
        (None, None) => Some(DEFAULT_PASSES),
    };
    // Checked before the scene loads, so a bad limit fails at once.
    if let Some(t) = cli.time {
        renderer::integrators::sppm::check_time_limit(t)
            .map_err(|why| anyhow::anyhow!("--time {why}"))?;
    }
    let loaded = renderer::scene_file::load_for_sppm(scene_path, &cli.define, cli.lenient)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    let scene = loaded.scene;
    create_parent_dir("--output", output).map_err(anyhow::Error::msg)?;
    let settings = SppmSettings {
        photons_per_pass: cli.photons,
        seed: cli.seed,
        mode: SppmMode::MultiLevel,
        schedule: cli.schedule,
        threads: cli.threads,
        scene_name: scene_path.display().to_string(),
        max_depth: cli
            .max_depth
            .unwrap_or(renderer::integrators::sppm::DEFAULT_MAX_DEPTH),
        emitter_samples: cli.emitter_samples,
        sharp_level: cli.sharp_level,
        sampler: cli.sampler.unwrap_or_default(),
        ..SppmSettings::default()
    };
    let stop = StopCondition {
        checkpoints: passes.into_iter().collect(),
        seconds: cli.time,
    };
    let bar = match passes {
        Some(n) => {
            let bar = ProgressBar::new(n as u64);
            bar.set_style(
                ProgressStyle::with_template(
                    "{elapsed_precise} [{wide_bar}] {pos}/{len} passes ({msg}, ETA {eta})",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            bar
        }
        // Time-bounded: the pass count is not known in advance.
        None => {
            let bar = ProgressBar::new_spinner();
            bar.set_style(
                ProgressStyle::with_template("{elapsed_precise} {spinner} pass {pos} ({msg})")
                    .expect("valid template"),
            );
            bar
        }
    };
    let state = match &cli.state {
        Some(path) => {
            if path.exists() {
                eprintln!("resuming from the run state {}", path.display());
            }
            let interval = cli.state_interval;
            Some(StateFile::for_scene(
                path,
                interval,
                scene_path,
                &cli.define,
                false,
            )?)
        }
        None => None,
    };
    let mut result = None;
    render_sppm_resumable(
        &scene,
        &settings,
        &stop,
        state.as_ref(),
        // One bundle: at the pass count or at the time limit, whichever came first.
        |b| {
            result = Some(b);
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
    .with_context(|| format!("rendering {}", scene_path.display()))?;
    bar.finish_and_clear();
    let bundle = result.context("the renderer wrote no bundle")?;
    eprintln!(
        "rendered {} passes × {} photons in {:.1} s",
        bundle.meta.passes, bundle.meta.photons_per_pass, bundle.meta.seconds
    );
    Ok(bundle)
}
