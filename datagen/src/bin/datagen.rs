//! `datagen`: generate randomized scenes, render datasets (sharded, kill-safe), assemble and
//! check manifests, and draw contact sheets. See `docs/datagen.md`.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use datagen::average::{average_references, summary_lines, AverageOptions, NOISE_FILE};
use datagen::check::check_dataset;
use datagen::config::Config;
use datagen::contact_sheet::{write_contact_sheet, SheetLayout};
use datagen::evaluation_reference::{evaluation_references, EvaluationOptions};
use datagen::families::{generate, scene_list};
use datagen::jobs::{check_external_scenes, render_dataset, RenderOptions};
use datagen::manifest::{assemble_manifest, Manifest};
use datagen::plan::{JobKinds, Plan, SceneSelection, Shard, Split};
use datagen::reference_noise::{markdown, noise_table, TABLE_FILE};
use datagen::scene::write_scene_files;
use datagen::sppm_backend::SppmBackend;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

/// Dataset generation for multi-level SPPM post-reconstruction.
#[derive(Debug, Parser)]
#[command(name = "datagen", version)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Write every scene of a config as Mitsuba 3 XML + PLY into OUT/<scene-id>/.
    #[command(allow_negative_numbers = true)]
    Scenes {
        /// Dataset config (TOML), e.g. configs/datagen/small.toml.
        #[arg(long)]
        config: PathBuf,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
    },
    /// Print what a config renders, per regime: scenes per split, image side, photons per
    /// pixel per pass, and the photons and eye passes of its inputs and references (the work
    /// that sizes a cluster job or a session).
    Plan {
        /// Dataset config (TOML).
        #[arg(long)]
        config: PathBuf,
        #[command(flatten)]
        selection: SelectionArgs,
    },
    /// Render references and input bundles into OUT (resumable; shards share OUT).
    #[command(allow_negative_numbers = true)]
    Render {
        /// Dataset config (TOML).
        #[arg(long)]
        config: PathBuf,
        /// Dataset directory (shared by all shards).
        #[arg(long)]
        out: PathBuf,
        /// Run shard I of N (0-based). Default: from SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT
        /// or JOB_COMPLETION_INDEX/DATAGEN_SHARD_COUNT when set, else the whole dataset.
        #[arg(long, value_parser = Shard::parse)]
        shard: Option<Shard>,
        #[command(flatten)]
        selection: SelectionArgs,
        /// Which jobs of the selected scenes: `references` (the long runs, small files: for a
        /// node with many cores that hands its files back), `inputs` (the bundles) or `all`.
        /// The kinds resume alike; a later call with the other kind completes the scenes.
        #[arg(long, value_enum, default_value_t = JobKinds::All)]
        jobs: JobKinds,
        /// Worker threads per render (0 = all cores; output does not depend on it).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Seconds of rendering between saves of a reference run's state: a killed reference
        /// job resumes from its last save instead of starting over.
        #[arg(long, value_name = "SECONDS", default_value_t = 60.0)]
        state_interval: f64,
        /// No progress bars.
        #[arg(long)]
        quiet: bool,
    },
    /// Assemble OUT/manifest.json from the job records (done automatically by the last shard).
    /// With --partial, while the render goes on: a manifest of the scenes finished so far,
    /// marked partial, for checking, evaluating or training on them early
    #[command(allow_negative_numbers = true)]
    Manifest {
        /// Dataset config (TOML).
        #[arg(long)]
        config: PathBuf,
        /// Dataset directory.
        #[arg(long)]
        out: PathBuf,
        /// List the scenes whose every job is done, marked partial, when some are not (the
        /// render's last shard replaces it with the complete manifest).
        #[arg(long)]
        partial: bool,
    },
    /// Verify a dataset against its manifest; exit status 1 on any problem.
    #[command(allow_negative_numbers = true)]
    Check {
        /// Dataset directory.
        dir: PathBuf,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Average more runs of a dataset's reference settings (other seeds) into less noisy
    /// references for evaluation: writes DIR/OUT/<scene id>.exr and DIR/OUT/noise.json.
    #[command(allow_negative_numbers = true)]
    AverageReferences {
        /// Dataset directory (with manifest.json).
        dir: PathBuf,
        /// Split whose scenes are averaged: train, val or test.
        #[arg(long, default_value = "test")]
        split: Split,
        /// Runs per scene, the dataset's own reference included (extra runs are kept in
        /// DIR/reference-runs and reused).
        #[arg(long, default_value_t = 8)]
        runs: usize,
        /// Output directory inside the dataset [default: references-avg<RUNS>, e.g.
        /// references-avg8].
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads per render (0 = all cores; output does not depend on it).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Seconds of rendering between saves of a run's state: a killed run resumes from its
        /// last save instead of starting over.
        #[arg(long, value_name = "SECONDS", default_value_t = 60.0)]
        state_interval: f64,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Render converged references for evaluation: per scene of the splits, two independent
    /// SPPM runs continued far past the inputs' pass count until the noise of their mean is at
    /// most TARGET × the best input level's error at the scene's largest pass count (or a
    /// limit flags the scene). Writes DIR/evaluation-references/<scene id>.exr and a record per
    /// scene, and lists them in the manifest (`evaluation_reference`), which evaluation and
    /// validation then use. Resumable: a later call continues the runs.
    #[command(allow_negative_numbers = true)]
    EvaluationReferences {
        /// Dataset directory (with manifest.json).
        dir: PathBuf,
        /// Splits whose scenes get one, comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "val,test")]
        splits: Vec<Split>,
        /// Only these scene ids (comma-separated); default: every scene of the splits.
        #[arg(long, value_delimiter = ',')]
        scenes: Vec<String>,
        /// Noise limit as a fraction of the best input level's error.
        #[arg(long, default_value_t = datagen::evaluation_reference::DEFAULT_TARGET)]
        target: f64,
        /// Most passes per run, as a multiple of the scene's reference passes.
        #[arg(long, default_value_t = 64)]
        max_factor: u32,
        /// Photons per pass of the runs at least this many (the scene's reference photons when
        /// more). SPPM's kernel bias falls with the photons per pass and the runs' spread cannot
        /// show it: the default is four times the 100 000 photons per pass the project's
        /// evaluations render. Runs of an earlier call with fewer are started again.
        #[arg(long, default_value_t = datagen::evaluation_reference::DEFAULT_MIN_PHOTONS)]
        min_photons: u64,
        /// Most seconds of rendering per scene (both runs); a scene that would need more is
        /// flagged (`converged: false`) and can be continued by a later call with a higher limit.
        #[arg(long, value_name = "SECONDS")]
        max_seconds: Option<f64>,
        /// Worker threads per render (0 = all cores; output does not depend on it).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Seconds of rendering between saves of a run's state.
        #[arg(long, value_name = "SECONDS", default_value_t = 60.0)]
        state_interval: f64,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Measure how noisy each reference is against the error of the inputs it judges (datasets
    /// with `render.reference_runs` ≥ 2): prints a per-family Markdown table, flags scenes whose
    /// reference noise exceeds 1/10 of the best input level's error at their largest pass
    /// count, and writes DIR/reference-noise.json.
    ReferenceNoise {
        /// Dataset directory (with manifest.json).
        dir: PathBuf,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Write a PNG grid of a dataset's reference images.
    #[command(allow_negative_numbers = true)]
    ContactSheet {
        /// Dataset directory.
        dir: PathBuf,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
        /// Tiles per row (at least 1).
        #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u16).range(1..))]
        columns: u16,
        /// Tile width in pixels (at least 8).
        #[arg(long, default_value_t = 160, value_parser = clap::value_parser!(u16).range(8..))]
        tile: u16,
        /// Show each scene's converged evaluation reference where the manifest lists one
        /// (`datagen evaluation-references`) instead of its training reference.
        #[arg(long)]
        evaluation: bool,
    },
}

/// Which scenes of a config a command takes (all criteria must hold; none given: all).
#[derive(Debug, clap::Args)]
struct SelectionArgs {
    /// Only the scenes of these splits (comma-separated: train, val, test).
    #[arg(long, value_delimiter = ',')]
    splits: Vec<Split>,
    /// Only the scenes of these families (comma-separated, e.g. lamp,tabletop).
    #[arg(long, value_delimiter = ',')]
    families: Vec<String>,
    /// Only these scene ids (comma-separated, e.g. 007-room).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Only the A-th to B-th scene of each family in each split (1-based, inclusive, e.g.
    /// 1-4): a slice of a dataset balanced across its families. Slices render the same files
    /// as the whole dataset, so later slices add to earlier ones.
    #[arg(long, value_name = "A-B", value_parser = SceneSelection::parse_range)]
    per_family: Option<(usize, usize)>,
}

impl SelectionArgs {
    fn into_selection(self) -> SceneSelection {
        SceneSelection {
            splits: self.splits,
            families: self.families,
            scenes: self.scenes,
            per_family: self.per_family,
        }
    }
}

fn main() {
    cli_output::install();
    match run(Cli::parse()) {
        Ok(code) => std::process::exit(code),
        Err(e) => {
            eprintln!("datagen: error: {e:#}");
            std::process::exit(2);
        }
    }
}

/// `--state-interval`, checked.
fn positive_interval(seconds: f64) -> Result<f64> {
    if seconds.is_nan() || seconds <= 0.0 {
        anyhow::bail!("--state-interval must be positive, got {seconds}");
    }
    Ok(seconds)
}

/// A duration as `HH:MM:SS`, as the progress bars show elapsed time.
fn hms(d: std::time::Duration) -> String {
    datagen::jobs::clock(d.as_secs() as f64)
}

/// A progress bar on stderr (hidden with `--quiet`) of `len` steps (`None`: set later) in the
/// given template.
fn command_bar(len: Option<u64>, quiet: bool, template: &str) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(
        len,
        if quiet {
            ProgressDrawTarget::hidden()
        } else {
            ProgressDrawTarget::stderr()
        },
    );
    bar.set_style(
        ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

/// Runs a command; returns the exit status.
fn run(cli: Cli) -> Result<i32> {
    match cli.command {
        Command::Scenes { config, out } => {
            let config = Config::load(&config)?;
            // The user's own scenes are not written, but they must be there: their XML and
            // every file it reads (as `render` checks before any job).
            check_external_scenes(&config)?;
            let list = scene_list(&config);
            let mut written = 0;
            for (index, (id, _)) in list.iter().enumerate() {
                // The user's own scenes (`[families.external]`) stay where they are.
                if let Some(scene) = generate(&config, index) {
                    write_scene_files(&scene, &out.join(id))
                        .with_context(|| format!("writing scene {id}"))?;
                    written += 1;
                }
            }
            eprintln!("wrote {written} scenes to {}", out.display());
            if written < list.len() {
                eprintln!(
                    "({} external scenes are rendered from their own files)",
                    list.len() - written
                );
            }
            Ok(0)
        }
        Command::Plan { config, selection } => {
            let config = Config::load(&config)?;
            let plan = Plan::new(&config);
            let keep = selection
                .into_selection()
                .scenes_of(&plan)
                .map_err(anyhow::Error::msg)?;
            print!("{}", datagen::plan::summary_of(&plan, &keep));
            Ok(0)
        }
        Command::Render {
            config,
            out,
            shard,
            selection,
            jobs,
            threads,
            state_interval,
            quiet,
        } => {
            let config = Config::load(&config)?;
            let env_shard =
                Shard::from_env(|k| std::env::var(k).ok()).map_err(anyhow::Error::msg)?;
            let shard = shard.or(env_shard).unwrap_or(Shard::ALL);
            let selection = selection.into_selection();
            // A part of the dataset: its manifest waits for the rest.
            let selected = selection != SceneSelection::default() || jobs != JobKinds::All;
            let options = RenderOptions {
                shard,
                selection,
                kinds: jobs,
                threads,
                progress: !quiet,
                state_interval: positive_interval(state_interval)?,
            };
            let report = render_dataset(&config, &out, options, &SppmBackend)?;
            eprintln!(
                "shard {}/{}: {} jobs rendered, {} already done, {} files in {}; manifest {}",
                shard.index,
                shard.count,
                report.rendered,
                report.skipped,
                report.samples,
                hms(report.elapsed),
                if report.manifest_complete {
                    "complete"
                } else if selected {
                    "waiting for the rest of the dataset (`datagen manifest --partial` lists the \
                     finished scenes)"
                } else {
                    "waiting for other shards"
                }
            );
            Ok(0)
        }
        Command::Manifest {
            config,
            out,
            partial,
        } => {
            let config = Config::load(&config)?;
            if !out.is_dir() {
                bail!("{}: no such dataset directory", out.display());
            }
            let plan = Plan::new(&config);
            match assemble_manifest(&out, &config, &plan, partial)? {
                Some(m) => {
                    eprintln!(
                        "{}: {} scenes{}, {} samples",
                        out.join("manifest.json").display(),
                        m.scenes.len(),
                        m.partial.map_or(String::new(), |p| format!(
                            " of {} (partial)",
                            p.planned_scenes
                        )),
                        m.samples.len()
                    );
                    Ok(0)
                }
                None => {
                    let all: Vec<usize> = (0..plan.jobs.len()).collect();
                    let other = datagen::manifest::jobs_of_other_config(
                        &out,
                        &plan,
                        &all,
                        &datagen::manifest::config_fingerprint(&config),
                    );
                    if other > 0 {
                        bail!(
                            "{}: {other} of {} jobs were rendered with another config than this \
                             one (is it the config the dataset was made with?)",
                            out.display(),
                            all.len()
                        )
                    }
                    if partial {
                        bail!(
                            "{}: no scene has finished yet (`datagen render` renders them)",
                            out.display()
                        )
                    }
                    bail!(
                        "{}: not every job has finished (rerun `datagen render` for the missing \
                         shards, or list the finished scenes with --partial)",
                        out.display()
                    )
                }
            }
        }
        Command::Check { dir, quiet } => {
            let bar = command_bar(None, quiet, "check {bar:40} {pos}/{len} files ETA {eta}");
            let report = check_dataset(&dir, |done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            });
            bar.finish_and_clear();
            for p in &report.problems {
                println!("BAD {p}");
            }
            if let Some((listed, planned)) = report.partial {
                println!(
                    "partial: the manifest lists {listed} of {planned} scenes (the render has not \
                     finished)"
                );
            }
            if report.ok() {
                println!("ok: {} files checked, no problems", report.files);
                Ok(0)
            } else {
                println!(
                    "{} problem(s) in {} files checked",
                    report.problems.len(),
                    report.files
                );
                Ok(1)
            }
        }
        Command::ReferenceNoise { dir, quiet } => {
            let manifest = Manifest::load(&dir)?;
            let bar = command_bar(
                Some(manifest.scenes.len() as u64),
                quiet,
                "reference noise {bar:40} {pos}/{len} scenes",
            );
            let table = noise_table(&dir, &manifest, |done, _| bar.set_position(done as u64))?;
            bar.finish_and_clear();
            let path = dir.join(TABLE_FILE);
            datagen::fsutil::write_atomic(&path, &datagen::manifest::to_json(&table))
                .with_context(|| format!("writing {}", path.display()))?;
            print!("{}", markdown(&table));
            eprintln!("wrote {}", path.display());
            Ok(0)
        }
        Command::EvaluationReferences {
            dir,
            splits,
            scenes,
            target,
            max_factor,
            min_photons,
            max_seconds,
            threads,
            state_interval,
            quiet,
        } => {
            let manifest = Manifest::load(&dir)?;
            let options = EvaluationOptions {
                splits,
                scenes,
                target,
                max_factor,
                min_photons,
                max_seconds,
                threads,
                state_interval: positive_interval(state_interval)?,
            };
            let bar = command_bar(
                Some(1),
                quiet,
                "{msg} {bar:40} {pos}/{len} passes ETA {eta}",
            );
            let started = std::time::Instant::now();
            let outcomes = evaluation_references(
                &dir,
                &manifest,
                &SppmBackend,
                &options,
                |o| {
                    let r = &o.reference;
                    let line = format!(
                        "{}: {} passes x {} photons x {} runs, noise {:.2e} = {:.3} x input                          error {:.2e}{}{}",
                        o.id,
                        r.passes,
                        r.photons,
                        r.seeds.len(),
                        r.noise,
                        r.noise / r.input_relmse,
                        r.input_relmse,
                        if r.converged { "" } else { " FLAGGED (limit reached)" },
                        if o.rendered { "" } else { " (kept)" },
                    );
                    // Printed with or without the bar (`--quiet` hides the bar only).
                    bar.suspend(|| println!("{line}"));
                },
                &mut |id, run, pass, target| {
                    if pass <= 1 || bar.length() != Some(u64::from(target)) {
                        bar.set_length(u64::from(target));
                        bar.set_message(format!("{id} run {run}"));
                    }
                    bar.set_position(u64::from(pass));
                },
            )?;
            bar.finish_and_clear();
            // The manifest lists the records (all of them, of earlier calls too).
            let plan = datagen::plan::Plan::new(&manifest.config);
            datagen::manifest::assemble_manifest(
                &dir,
                &manifest.config,
                &plan,
                manifest.partial.is_some(),
            )?;
            let flagged = outcomes.iter().filter(|o| !o.reference.converged).count();
            println!(
                "{} scene(s), {} converged, {flagged} flagged; {} of rendering in this call; \
                 manifest updated",
                outcomes.len(),
                outcomes.len() - flagged,
                hms(started.elapsed())
            );
            Ok(0)
        }
        Command::AverageReferences {
            dir,
            split,
            runs,
            out,
            threads,
            state_interval,
            quiet,
        } => {
            // Named after the run count, so an average of fewer runs never takes the place of
            // the one configs name (`references-avg8`).
            let out = out.unwrap_or_else(|| PathBuf::from(format!("references-avg{runs}")));
            // One bar over every extra run's passes (reused runs count as done); every scene of
            // a dataset has the same reference passes.
            let manifest = Manifest::load(&dir)?;
            let per_run = manifest
                .scenes
                .first()
                .map_or(0, |s| u64::from(s.reference_passes));
            let scenes = manifest.scenes.iter().filter(|s| s.split == split).count();
            let bar = command_bar(
                Some(per_run * (scenes * runs.saturating_sub(1)) as u64),
                quiet,
                "average {bar:40} {pos}/{len} passes ETA {eta}",
            );
            let runs_done = AtomicU64::new(0);
            let options = AverageOptions {
                split,
                runs,
                out: out.clone(),
                threads,
                state_interval: positive_interval(state_interval)?,
            };
            let report = average_references(
                &dir,
                &manifest,
                &SppmBackend,
                &options,
                |id, run, rendered| {
                    let done = runs_done.fetch_add(1, Ordering::Relaxed) + 1;
                    bar.set_position(per_run * done);
                    bar.println(format!(
                        "{id}: run {run} {}",
                        if rendered { "rendered" } else { "reused" }
                    ));
                },
                &mut |pass| {
                    bar.set_position(per_run * runs_done.load(Ordering::Relaxed) + u64::from(pass));
                },
            )?;
            bar.finish_and_clear();
            // What this call averaged (its split); noise.json also keeps the scenes of other
            // splits that earlier calls averaged into the same folder.
            let noise = dir.join(&out).join(NOISE_FILE);
            for line in summary_lines(&report, split, &noise) {
                println!("{line}");
            }
            println!("wrote {}", dir.join(&out).display());
            Ok(0)
        }
        Command::ContactSheet {
            dir,
            out,
            columns,
            tile,
            evaluation,
        } => {
            let is_png = out
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("png"));
            if !is_png {
                anyhow::bail!(
                    "--out {}: the contact sheet is a PNG (name it *.png)",
                    out.display()
                );
            }
            let manifest = Manifest::load(&dir)?;
            let files: Vec<(String, PathBuf)> = manifest
                .scenes
                .iter()
                .map(|s| {
                    let path = match (&s.evaluation_reference, evaluation) {
                        (Some(e), true) => &e.path,
                        _ => &s.reference,
                    };
                    (s.id.clone(), dir.join(path))
                })
                .collect();
            let layout = SheetLayout {
                columns: usize::from(columns),
                tile_width: usize::from(tile),
                gap: 2,
            };
            let n = write_contact_sheet(&files, layout, &out)?;
            eprintln!("{}: {n} references", out.display());
            Ok(0)
        }
    }
}
