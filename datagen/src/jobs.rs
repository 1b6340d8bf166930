//! Running the dataset's render jobs: skip a job whose record and outputs are intact, else
//! (re)write its scene files, render, write every output atomically, then its record; finally
//! assemble the manifest when every job of every shard is done. Rendering itself is behind
//! [`SampleRenderer`] so the bookkeeping is independent of the integrator.

use crate::average::{mean_and_noise, run_seed};
use crate::config::Config;
use crate::families::generate;
use crate::fsutil::{create_parent, remove_if_present, sha256_file, write_atomic};
use crate::manifest::{
    assemble_manifest, config_fingerprint, jobs_of_other_config, outputs_intact, read_record,
    to_json, JobRecord, SampleEntry, SceneEntry, MANIFEST_FORMAT,
};
use crate::plan::{Job, JobKinds, Plan, SceneSelection, Shard};
use crate::scene::write_scene_files;
use anyhow::{bail, Context, Result};
use bundle::{read_bundle, read_rgb_exr_image, write_bundle, write_rgb_exr_image, Bundle, Image};
use fileio::atomic::remove_stale_temps;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};
use renderer::integrators::sppm::{RadiusSchedule, SharpLevel, SppmMode, SppmSettings};
use renderer::state_file::scene_fingerprint;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What one render run needs to know.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSpec {
    /// The renderer's settings of the run (multi-level; its `scene_name` is the scene id written
    /// into bundle metadata, its `threads` do not change the results).
    pub sppm: SppmSettings,
    /// Pass counts to deliver (ascending); the reference uses only the last.
    pub passes: Vec<u32>,
    /// Where a long run keeps its resumable state, so a killed job continues mid-run (the
    /// reference jobs give one; a renderer may ignore it).
    pub state: Option<StateSpec>,
    /// `<default>` overrides of the scene file (scenes the user brings).
    pub defines: Vec<(String, String)>,
    /// The dataset's image size: a scene whose film differs is an error before rendering.
    pub size: (u32, u32),
}

/// The multi-level SPPM settings of a dataset run with radius schedule `schedule`: one light
/// sample per visible point and the sharp level gathered at subpath A (references always;
/// input runs unless the config's `render.emitter_samples` / `render.sharp_level` say
/// otherwise).
pub fn run_settings(
    scene_id: &str,
    seed: u64,
    photons_per_pass: u64,
    max_depth: u32,
    schedule: RadiusSchedule,
    threads: usize,
) -> SppmSettings {
    SppmSettings {
        photons_per_pass,
        seed,
        mode: SppmMode::MultiLevel,
        schedule,
        max_depth,
        threads,
        scene_name: scene_id.to_owned(),
        // Every dataset rendered before the options existed took one, at A.
        emitter_samples: Some(1),
        sharp_level: Some(SharpLevel::SubpathA),
        ..SppmSettings::default()
    }
}

/// Where and how often a run saves its resumable state.
#[derive(Debug, Clone, PartialEq)]
pub struct StateSpec {
    /// The state file (removed by the caller once the run's output is written).
    pub path: PathBuf,
    /// Seconds of rendering between saves.
    pub interval: f64,
}

/// Renders references and input bundles of one scene file.
pub trait SampleRenderer: Sync {
    /// Renders the long reference run and returns its RGB reference image.
    fn reference(
        &self,
        xml: &Path,
        spec: &RunSpec,
        on_pass: &mut (dyn FnMut(u32) + Send),
    ) -> Result<Image>;

    /// Renders one continuing input run, handing over a bundle at each of `spec.passes`.
    fn inputs(
        &self,
        xml: &Path,
        spec: &RunSpec,
        on_bundle: &mut (dyn FnMut(Bundle) -> Result<()> + Send),
        on_pass: &mut (dyn FnMut(u32) + Send),
    ) -> Result<()>;
}

/// Options of a `datagen render` invocation.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// Which jobs this process runs: its shard of the selected scenes' jobs.
    pub shard: Shard,
    /// Which scenes are rendered (default: all).
    pub selection: SceneSelection,
    /// Which of their jobs: references, inputs or both.
    pub kinds: JobKinds,
    /// Worker threads per render (0 = all cores).
    pub threads: usize,
    /// Draw progress bars on stderr.
    pub progress: bool,
    /// Seconds of rendering between saves of a reference run's state (a killed reference job
    /// resumes from its last save).
    pub state_interval: f64,
}

/// Counts of a finished invocation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RenderReport {
    /// Jobs rendered now.
    pub rendered: usize,
    /// Jobs skipped because their outputs were already valid.
    pub skipped: usize,
    /// Files (bundles + references) this shard is responsible for.
    pub samples: usize,
    /// Whether `manifest.json` is complete (all shards done).
    pub manifest_complete: bool,
    /// Jobs of this shard that had been rendered under another config (replaced now).
    pub replaced: usize,
    /// Wall-clock time of the invocation.
    pub elapsed: Duration,
}

/// Relative amount of work of a job, for the overall progress bar's ETA.
fn job_work(plan: &Plan, job: &Job) -> u64 {
    let r = &plan.scenes[job.scene()].render;
    let pixels = u64::from(r.width) * u64::from(r.height);
    match job {
        Job::Reference { .. } => {
            u64::from(r.reference_runs)
                * u64::from(r.reference_passes)
                * (r.reference_photons_per_pass + 2 * pixels)
        }
        Job::Inputs { .. } => u64::from(r.last_pass()) * (r.photons_per_pass + 2 * pixels),
    }
}

/// Output files of a job.
fn job_files(plan: &Plan, job: &Job) -> usize {
    match job {
        Job::Reference { .. } => 1,
        Job::Inputs { scene, .. } => plan.scenes[*scene].render.passes.len(),
    }
}

/// Passes a job's bar counts: every run of a reference one after the other.
fn job_passes(plan: &Plan, job: &Job) -> u32 {
    let r = &plan.scenes[job.scene()].render;
    match job {
        Job::Reference { .. } => r.reference_runs * r.reference_passes,
        Job::Inputs { .. } => r.last_pass(),
    }
}

/// Runs this shard's jobs of `config` into the dataset directory `root`, with progress bars on
/// stderr when `options.progress` is set.
pub fn render_dataset(
    config: &Config,
    root: &Path,
    options: RenderOptions,
    renderer: &dyn SampleRenderer,
) -> Result<RenderReport> {
    let target = if options.progress {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    render_dataset_to(config, root, options, renderer, target)
}

/// Seconds as `HH:MM:SS`, as the progress bars show time.
pub fn clock(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    format!("{:02}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
}

/// A position given to a bar that is not work of this session (skipped jobs, the passes a
/// resumed run had done before): recorded, then forgotten by the rate and ETA estimate.
fn jump(bar: &ProgressBar, pos: u64) {
    bar.set_position(pos);
    // `tick` records the position in the estimator whatever the draw rate; the reset then
    // drops everything before now, the jump included.
    bar.tick();
    bar.reset_eta();
}

/// A rate of passes per second as a progress bar shows it: three significant digits, or
/// seconds per pass when a pass takes longer than a second (`104 passes/s`, `2.35 passes/s`,
/// `12.3 s/pass`); `— passes/s` while nothing has been measured.
pub fn format_pass_rate(per_sec: f64) -> String {
    if !(per_sec.is_finite() && per_sec > 0.0) {
        return "\u{2014} passes/s".into();
    }
    let three = |v: f64| -> String {
        if v >= 99.95 {
            format!("{v:.0}")
        } else if v >= 9.995 {
            format!("{v:.1}")
        } else {
            format!("{v:.2}")
        }
    };
    if per_sec >= 1.0 {
        format!("{} passes/s", three(per_sec))
    } else {
        format!("{} s/pass", three(1.0 / per_sec))
    }
}

/// Passes per second since the first pass of this session: shared by a job's progress callback
/// (which starts it) and its bar's `{rate}` key.
#[derive(Debug, Clone, Default)]
struct SessionRate(std::sync::Arc<std::sync::Mutex<Option<(u64, Instant)>>>);

impl SessionRate {
    /// Starts the measurement at position `pos` (now).
    fn start(&self, pos: u64) {
        if let Ok(mut base) = self.0.lock() {
            *base = Some((pos, Instant::now()));
        }
    }

    /// The rate at position `pos`; 0 before two passes were seen.
    fn per_sec(&self, pos: u64) -> f64 {
        match self.0.lock().ok().and_then(|b| *b) {
            Some((base, at)) if pos > base => {
                (pos - base) as f64 / at.elapsed().as_secs_f64().max(1e-9)
            }
            _ => 0.0,
        }
    }
}

/// Finishes and clears a bar when dropped, so that no bar is left on the terminal (a finished
/// bar's line does not end, and what is printed next would be glued to it), on errors too.
struct ClearOnDrop(ProgressBar);

impl Drop for ClearOnDrop {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}

/// [`render_dataset`] drawing its progress to `target` (tests give a terminal stand-in).
pub fn render_dataset_to(
    config: &Config,
    root: &Path,
    options: RenderOptions,
    renderer: &dyn SampleRenderer,
    target: ProgressDrawTarget,
) -> Result<RenderReport> {
    let started = Instant::now();
    std::fs::create_dir_all(root).with_context(|| format!("creating {}", root.display()))?;
    remove_stale_temps(root);
    let plan = Plan::new(config);
    let fingerprint = config_fingerprint(config);
    let keep = options
        .selection
        .scenes_of(&plan)
        .map_err(anyhow::Error::msg)?;
    let mine = plan.shard_jobs(options.shard, &keep, options.kinds);
    let multi = MultiProgress::with_draw_target(target);
    // A line for the user: above the bars, or plainly on stderr where no bar is drawn (--quiet,
    // or stderr is not a terminal).
    let say = |line: String| {
        if multi.is_hidden() {
            eprintln!("{line}");
        } else {
            let _ = multi.println(line);
        }
    };
    let total_work: u64 = mine.iter().map(|&j| job_work(&plan, &plan.jobs[j])).sum();
    let overall = ClearOnDrop(multi.add(ProgressBar::new(total_work.max(1))));
    let overall = &overall.0;
    overall.set_style(
        ProgressStyle::with_template(
            "{prefix} [{elapsed_precise}] {wide_bar} {percent:>3}% {msg} ETA {eta_precise}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let shard = options.shard;
    overall.set_prefix(format!("shard {}/{}", shard.index, shard.count));
    let total_files: usize = mine.iter().map(|&j| job_files(&plan, &plan.jobs[j])).sum();
    let mut report = RenderReport {
        samples: total_files,
        ..Default::default()
    };
    report.replaced = jobs_of_other_config(root, &plan, &mine, &fingerprint);
    if report.replaced > 0 {
        // Said before the work starts: the user may have meant another directory.
        say(format!(
            "note: {} of this shard's {} jobs in {} were rendered with another config; they are \
             rendered again and their files replaced (keep one directory per config)",
            report.replaced,
            mine.len(),
            root.display()
        ));
    }
    let mut files_done = 0;
    let mut work_done = 0u64;
    // Where no bar can be drawn (stderr is a file: a batch job's log) and the user did not ask
    // for quiet, each finished job is a line, so the log says how far the run is and when it may
    // end. The ETA is this session's: the work rendered now over the seconds it took.
    let log_jobs = options.progress && multi.is_hidden();
    let (mut session_work, mut session_seconds) = (0u64, 0.0f64);
    // Files as in the summary line: references and bundles.
    overall.set_message(format!("{files_done}/{total_files} files"));
    // The user's scene files, hashed up front: a missing one (the XML or any file it reads)
    // stops the run before any render, and a job of a scene whose files changed since its
    // record is redone.
    let external = external_hashes(config, &plan, &mine)?;
    for &j in &mine {
        let job = plan.jobs[j];
        let work = job_work(&plan, &job);
        let existing = read_record(root, &plan, &job, &fingerprint);
        let scene_hash = external.get(&job.scene()).cloned();
        let scene_id = &plan.scenes[job.scene()].id;
        // How the job is named to the user (its record does not exist until it is done).
        let label = match job {
            Job::Reference { .. } => format!("{scene_id} reference"),
            Job::Inputs { seed_index, .. } => format!("{scene_id} seed {seed_index}"),
        };
        let skip =
            existing.is_some_and(|r| r.scene_sha256 == scene_hash && outputs_intact(root, &r));
        let mut seconds = None;
        if skip {
            report.skipped += 1;
        } else {
            let passes = job_passes(&plan, &job);
            let bar = ClearOnDrop(multi.add(ProgressBar::new(u64::from(passes))));
            // The rate of this session's passes: measured from the first pass this session
            // reports (a resumed run's earlier passes are not in it).
            let rate = SessionRate::default();
            let shown = rate.clone();
            bar.0.set_style(
                ProgressStyle::with_template("  {msg:24} {bar:30} {pos}/{len} passes  {rate}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar())
                    .with_key(
                        "rate",
                        move |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                            let _ = w.write_str(&format_pass_rate(shown.per_sec(s.pos())));
                        },
                    ),
            );
            bar.0.set_message(label.clone());
            // A state of this job and config left by a killed session: the run resumes from
            // it (its first pass reported is the one after the saved pass).
            let runs = match job {
                Job::Reference { scene } => plan.scenes[scene].render.reference_runs,
                Job::Inputs { .. } => 1,
            };
            let resuming = (0..runs).any(|run| {
                root.join(plan.reference_run_state(&job, &fingerprint, run))
                    .is_file()
                    || root
                        .join(plan.reference_run_image(&job, &fingerprint, run))
                        .is_file()
            });
            let mut first_pass = true;
            let start = Instant::now();
            let mut on_pass = |pass: u32| {
                let overall_pos = work_done + work * u64::from(pass) / u64::from(passes.max(1));
                if std::mem::take(&mut first_pass) {
                    rate.start(u64::from(pass));
                    if resuming && pass > 1 {
                        say(format!(
                            "{label}: resuming at pass {} of {passes}",
                            pass - 1
                        ));
                        // The passes done before are not this session's work: not in the
                        // overall ETA either.
                        bar.0.set_position(u64::from(pass));
                        jump(overall, overall_pos);
                        return;
                    }
                }
                bar.0.set_position(u64::from(pass));
                overall.set_position(overall_pos);
            };
            let record = run_job(
                config,
                root,
                &plan,
                &job,
                &fingerprint,
                scene_hash,
                &options,
                renderer,
                &mut on_pass,
            )
            .with_context(|| format!("job {label}"))?;
            drop(bar);
            write_atomic(&root.join(plan.record_path(&job)), &to_json(&record))
                .with_context(|| format!("writing {}", plan.record_path(&job)))?;
            // Only now, with the record written, are the finished runs of no further use.
            remove_run_files(root, &plan, &job, |_| true)?;
            // Wall-clock timing is useful but not reproducible: it lives outside the records.
            seconds = Some(start.elapsed().as_secs_f64());
            let timing = serde_json::json!({ "seconds": seconds });
            let _ = write_atomic(&root.join(plan.timing_path(&job)), &to_json(&timing));
            report.rendered += 1;
        }
        files_done += job_files(&plan, &job);
        overall.set_message(format!("{files_done}/{total_files} files"));
        work_done += work;
        if skip {
            // Done by an earlier session: not this session's work.
            jump(overall, work_done);
        } else {
            overall.set_position(work_done);
        }
        if let (true, Some(seconds)) = (log_jobs, seconds) {
            session_work += work;
            session_seconds += seconds;
            let left = total_work.saturating_sub(work_done) as f64;
            let eta = left * session_seconds / session_work.max(1) as f64;
            say(format!(
                "{label}: done in {} ({files_done}/{total_files} files, {:.0} % of the work, \
                 ETA {})",
                clock(seconds),
                100.0 * work_done as f64 / total_work.max(1) as f64,
                clock(eta)
            ));
        }
    }
    // Cleared, not left standing: the caller's summary line follows on a line of its own.
    overall.finish_and_clear();
    report.manifest_complete = assemble_manifest(root, config, &plan, false)?.is_some();
    report.elapsed = started.elapsed();
    Ok(report)
}

/// Removes state files a killed run of this job left under another config (their names carry
/// that config's fingerprint): they can never be resumed, and would only litter the dataset.
fn remove_stale_states(root: &Path, plan: &Plan, job: &Job, fingerprint: &str) -> Result<()> {
    remove_run_files(root, plan, job, |tag| {
        tag != &fingerprint[..fingerprint.len().min(16)]
    })
}

/// Removes the job's run files (resumable states, finished reference runs) whose config tag
/// `stale` accepts.
fn remove_run_files(
    root: &Path,
    plan: &Plan,
    job: &Job,
    stale: impl Fn(&str) -> bool,
) -> Result<()> {
    let record = root.join(plan.record_path(job));
    let (Some(dir), Some(stem)) = (record.parent(), record.file_stem()) else {
        return Ok(());
    };
    let prefix = format!("{}.", stem.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(rest) = name.strip_prefix(&prefix) else {
            continue;
        };
        let tag = rest.split('.').next().unwrap_or("");
        if (name.ends_with(".state") || name.ends_with(".exr")) && stale(tag) {
            remove_if_present(&e.path())?;
        }
    }
    Ok(())
}

/// Fingerprint ([`scene_fingerprint`]: the scene file, every file it reads, its `defines`) of
/// every external scene among `jobs` (by scene index); an error naming the file, the scene and
/// its XML when the scene file or a file it reads cannot be read.
fn external_hashes(
    config: &Config,
    plan: &Plan,
    jobs: &[usize],
) -> Result<std::collections::BTreeMap<usize, String>> {
    let mut out = std::collections::BTreeMap::new();
    for &j in jobs {
        let scene = plan.jobs[j].scene();
        if out.contains_key(&scene) {
            continue;
        }
        if let Some(hash) = external_fingerprint(config, plan, scene)? {
            out.insert(scene, hash);
        }
    }
    Ok(out)
}

/// Checks that every file of every external scene of `config` (`[families.external]`) can be
/// read: the scene files, their includes, meshes, textures, spectra. An error names the file,
/// the scene and its XML.
pub fn check_external_scenes(config: &Config) -> Result<()> {
    let plan = Plan::new(config);
    for scene in 0..plan.scenes.len() {
        external_fingerprint(config, &plan, scene)?;
    }
    Ok(())
}

/// The fingerprint of scene `scene` when it is external (`None` for a generated one), after
/// checking that its XML and every file it reads ([`renderer::xml::scene_files`]) can be read.
fn external_fingerprint(config: &Config, plan: &Plan, scene: usize) -> Result<Option<String>> {
    let Some(s) = config.external_scene(scene) else {
        return Ok(None);
    };
    let id = &plan.scenes[scene].id;
    let defines = s.define_pairs();
    let files = renderer::xml::scene_files(&s.xml, &defines).with_context(|| {
        format!(
            "scene {id} (families.external): reading {}",
            s.xml.display()
        )
    })?;
    for file in &files {
        let readable = std::fs::File::open(file)
            .and_then(|f| f.metadata())
            .and_then(|m| {
                if m.is_file() {
                    Ok(())
                } else {
                    Err(std::io::Error::other("not a file"))
                }
            });
        if let Err(e) = readable {
            bail!(
                "scene {id} (families.external, {}): cannot read {}, a file the scene reads: \
                 {e}",
                s.xml.display(),
                file.display()
            );
        }
    }
    let hash = scene_fingerprint(&s.xml, &defines).with_context(|| {
        format!(
            "scene {id} (families.external): reading {}",
            s.xml.display()
        )
    })?;
    Ok(Some(hash))
}

/// `path` as the manifest records it: relative to the dataset `root` (both made absolute), so
/// readers find it with `root.join(..)` wherever the two are moved together; absolute when no
/// relative path exists.
fn path_from_root(root: &Path, path: &Path) -> String {
    let (Ok(root), Ok(path)) = (root.canonicalize(), path.canonicalize()) else {
        return path.display().to_string();
    };
    let common = root
        .components()
        .zip(path.components())
        .take_while(|(a, b)| a == b)
        .count();
    if common == 0 {
        return path.display().to_string();
    }
    let mut rel = PathBuf::new();
    for _ in root.components().skip(common) {
        rel.push("..");
    }
    for c in path.components().skip(common) {
        rel.push(c);
    }
    rel.to_string_lossy().replace('\\', "/")
}

/// Renders one job and writes its outputs; returns its record (not yet written).
#[allow(clippy::too_many_arguments)]
fn run_job(
    config: &Config,
    root: &Path,
    plan: &Plan,
    job: &Job,
    fingerprint: &str,
    scene_hash: Option<String>,
    options: &RenderOptions,
    renderer: &dyn SampleRenderer,
    on_pass: &mut (dyn FnMut(u32) + Send),
) -> Result<JobRecord> {
    let sp = &plan.scenes[job.scene()];
    // A generated scene is written into the dataset; the user's file is rendered where it is.
    let (xml, manifest_xml, defines) =
        match (generate(config, sp.index), config.external_scene(sp.index)) {
            (Some(scene), _) => (
                write_scene_files(&scene, &root.join(sp.scene_dir()))?,
                sp.scene_xml(),
                Vec::new(),
            ),
            (None, Some(external)) => (
                external.xml.clone(),
                path_from_root(root, &external.xml),
                external.define_pairs(),
            ),
            (None, None) => bail!("scene {} is neither generated nor external", sp.id),
        };
    let r = &sp.render;
    let size = (r.width, r.height);
    let seed = plan.render_seed(job);
    remove_stale_states(root, plan, job, fingerprint)?;
    let mut record = JobRecord {
        format: MANIFEST_FORMAT.into(),
        config_sha256: fingerprint.to_owned(),
        scene: None,
        samples: Vec::new(),
        scene_sha256: scene_hash.clone(),
    };
    // Both kinds of job resume from this state; it is removed once their outputs are written.
    let state = StateSpec {
        path: root.join(plan.state_path(job, fingerprint)),
        interval: options.state_interval,
    };
    let wrong_size = |image: &Image, what: &str| -> Result<()> {
        if (image.width, image.height) != (size.0 as usize, size.1 as usize) {
            bail!(
                "{}: {what} is {}x{}, the scene's size is {}x{}",
                xml.display(),
                image.width,
                image.height,
                size.0,
                size.1
            );
        }
        Ok(())
    };
    match *job {
        Job::Reference { .. } => {
            let runs = r.reference_runs;
            let mut images = Vec::new();
            for run in 0..runs {
                // Run 0 is the dataset's own seed; more runs step from it as
                // `average-references` does.
                let run_seed = if run == 0 {
                    seed
                } else {
                    run_seed(seed, run as usize)
                };
                let done = root.join(plan.reference_run_image(job, fingerprint, run));
                if runs > 1 && done.is_file() {
                    // Finished by a session that was stopped before the job's record.
                    let image = read_rgb_exr_image(&done)?;
                    wrong_size(&image, "a finished reference run")?;
                    on_pass((run + 1) * r.reference_passes);
                    images.push(image);
                    continue;
                }
                let spec = RunSpec {
                    sppm: run_settings(
                        &sp.id,
                        run_seed,
                        r.reference_photons_per_pass,
                        config.render.max_depth,
                        // References are SPPM's whatever the inputs' schedule.
                        RadiusSchedule::Sppm,
                        options.threads,
                    ),
                    passes: vec![r.reference_passes],
                    state: Some(StateSpec {
                        path: root.join(plan.reference_run_state(job, fingerprint, run)),
                        interval: options.state_interval,
                    }),
                    defines: defines.clone(),
                    size,
                };
                let offset = run * r.reference_passes;
                let image = renderer.reference(&xml, &spec, &mut |p| on_pass(offset + p))?;
                wrong_size(&image, "the reference")?;
                if runs > 1 {
                    create_parent(&done)
                        .with_context(|| format!("creating the folder of {}", done.display()))?;
                    write_rgb_exr_image(&done, &image)?;
                    remove_if_present(&root.join(plan.reference_run_state(job, fingerprint, run)))?;
                }
                images.push(image);
            }
            let (image, noise) = if images.len() == 1 {
                (images.remove(0), None)
            } else {
                let (mean, one_run) = mean_and_noise(&images);
                (mean, Some(one_run / f64::from(runs)))
            };
            let rel = sp.reference();
            let path = root.join(&rel);
            create_parent(&path)
                .with_context(|| format!("creating the folder of {}", path.display()))?;
            write_rgb_exr_image(&path, &image)?;
            record.scene = Some(SceneEntry {
                id: sp.id.clone(),
                family: sp.family.name().to_owned(),
                split: sp.split,
                xml: manifest_xml,
                reference: rel,
                reference_sha256: sha256_file(&path)?,
                reference_seed: seed,
                reference_passes: r.reference_passes,
                reference_photons: r.reference_photons_per_pass,
                scene_sha256: scene_hash,
                defines: defines.iter().cloned().collect(),
                regime: r.regime.clone(),
                size: (size != (config.width, config.height)).then_some([size.0, size.1]),
                reference_runs: (runs > 1).then_some(runs),
                reference_noise: noise,
                evaluation_reference: None,
            });
        }
        Job::Inputs { seed_index, .. } => {
            let spec = RunSpec {
                sppm: SppmSettings {
                    emitter_samples: Some(config.render.emitter_samples.unwrap_or(1)),
                    sharp_level: Some(config.render.sharp_level.unwrap_or(SharpLevel::SubpathA)),
                    sampler: config.render.sampler.unwrap_or_default(),
                    ..run_settings(
                        &sp.id,
                        seed,
                        r.photons_per_pass,
                        config.render.max_depth,
                        config.render.schedule,
                        options.threads,
                    )
                },
                passes: r.passes.clone(),
                state: Some(state.clone()),
                defines,
                size,
            };
            // The manifest entry of the bundle of `passes` passes at `rel` (= `path`).
            let sample_entry = |rel: String, passes: u32, path: &Path| -> Result<SampleEntry> {
                Ok(SampleEntry {
                    bundle: rel,
                    scene: sp.id.clone(),
                    family: sp.family.name().to_owned(),
                    split: sp.split,
                    seed,
                    seed_index,
                    passes,
                    photons: r.photons_per_pass,
                    reference: sp.reference(),
                    sha256: sha256_file(path)?,
                })
            };
            let mut on_bundle = |mut b: Bundle| -> Result<()> {
                let passes = b.meta.passes;
                if !r.passes.contains(&passes) {
                    bail!("renderer delivered a bundle at {passes} passes, not a configured count");
                }
                // Wall-clock seconds would make reruns differ; timings go to `timings/`.
                b.meta.seconds = 0.0;
                let rel = plan.bundle_path(sp.index, seed_index, passes);
                let path = root.join(&rel);
                // Atomic, with byte-reproducible headers (`fileio::exr`).
                create_parent(&path)
                    .with_context(|| format!("creating the folder of {}", path.display()))?;
                write_bundle(&path, &b)?;
                record.samples.push(sample_entry(rel, passes, &path)?);
                Ok(())
            };
            renderer.inputs(&xml, &spec, &mut on_bundle, on_pass)?;
            // A run resumed from its state delivers the bundles from the saved pass on; the
            // earlier ones were written by the session that saved it (before the state).
            for &passes in &r.passes {
                if record.samples.iter().any(|s| s.passes == passes) {
                    continue;
                }
                let rel = plan.bundle_path(sp.index, seed_index, passes);
                let path = root.join(&rel);
                let earlier = read_bundle(&path).with_context(|| {
                    format!("the resumed run expects the earlier session's bundle {rel}")
                })?;
                if (earlier.meta.passes, earlier.meta.seed) != (passes, seed) {
                    bail!(
                        "{rel}: holds pass {} of seed {}, expected pass {passes} of seed {seed}",
                        earlier.meta.passes,
                        earlier.meta.seed
                    );
                }
                record.samples.push(sample_entry(rel, passes, &path)?);
            }
            record.samples.sort_by_key(|s| s.passes);
            let got: Vec<u32> = record.samples.iter().map(|s| s.passes).collect();
            if got != r.passes {
                bail!(
                    "renderer delivered bundles at {got:?} passes, expected {:?}",
                    r.passes
                );
            }
        }
    }
    // The outputs are written: the run's state is of no further use.
    remove_if_present(&state.path)?;
    Ok(record)
}
