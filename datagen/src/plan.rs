//! The dataset plan: every scene with its split, every render job (one reference run per
//! scene, one input run per (scene, seed) writing a bundle at each configured pass count),
//! the relative paths of all outputs, render seeds, and the assignment of jobs to shards.

use crate::config::Config;
use crate::families::scene_list;
use crate::rng::{hash_seq, hash_str, Rng};
use crate::scene::Family;

pub use bundle::manifest::Split;

/// One planned scene.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenePlan {
    /// Index in generation order.
    pub index: usize,
    /// Scene id, e.g. `007-glass`.
    pub id: String,
    /// Family.
    pub family: Family,
    /// Split.
    pub split: Split,
    /// Its place among the scenes of its family and split (1-based, in index order): the
    /// render order takes the families in turns by it, and `--per-family` selects by it.
    pub turn: usize,
    /// How the scene is rendered (its regime's settings, or the config's).
    pub render: SceneRender,
}

/// How one scene is rendered: image size, input runs and reference, from the config's render
/// section and the scene's regime (`[[render.regimes]]`).
#[derive(Debug, Clone, PartialEq)]
pub struct SceneRender {
    /// Name of the scene's regime (`None` without regimes).
    pub regime: Option<String>,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Photons per pass of the input runs.
    pub photons_per_pass: u64,
    /// Pass counts of the input bundles (ascending).
    pub passes: Vec<u32>,
    /// Input runs (seeds).
    pub seeds: u32,
    /// Passes of each reference run.
    pub reference_passes: u32,
    /// Photons per pass of each reference run.
    pub reference_photons_per_pass: u64,
    /// Independent reference runs averaged into the reference.
    pub reference_runs: u32,
}

impl SceneRender {
    /// The last (largest) input pass count.
    pub fn last_pass(&self) -> u32 {
        *self.passes.last().unwrap_or(&0)
    }
}

impl ScenePlan {
    /// Directory of the scene's XML and PLY files, relative to the dataset root.
    pub fn scene_dir(&self) -> String {
        format!("scenes/{}", self.id)
    }

    /// The scene's XML, relative to the dataset root.
    pub fn scene_xml(&self) -> String {
        format!("scenes/{}/scene.xml", self.id)
    }

    /// The reference EXR, relative to the dataset root.
    pub fn reference(&self) -> String {
        format!("references/{}.exr", self.id)
    }
}

/// One unit of rendering work; a shard runs whole jobs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Job {
    /// The long reference run of a scene.
    Reference {
        /// Scene index.
        scene: usize,
    },
    /// One input run of a scene, writing one bundle per configured pass count.
    Inputs {
        /// Scene index.
        scene: usize,
        /// Seed number 0..seeds.
        seed_index: u32,
    },
}

impl Job {
    /// The job's scene index.
    pub fn scene(&self) -> usize {
        match *self {
            Job::Reference { scene } | Job::Inputs { scene, .. } => scene,
        }
    }
}

/// The whole plan of a configuration.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Scenes in index order.
    pub scenes: Vec<ScenePlan>,
    /// Jobs in render order ([`render_order`]): per scene, its reference then its input seeds.
    pub jobs: Vec<Job>,
    /// Master seed.
    seed: u64,
}

impl Plan {
    /// Plans a configuration (deterministic).
    pub fn new(config: &Config) -> Self {
        let list = scene_list(config);
        let splits = assign_splits(config, &list);
        let regimes = assign_regimes(config, &list);
        let turns = family_turns(&list, &splits);
        let scenes: Vec<ScenePlan> = list
            .into_iter()
            .enumerate()
            .map(|(index, (id, family))| ScenePlan {
                index,
                id,
                family,
                split: splits[index],
                turn: turns[index],
                render: scene_render(config, index, splits[index], regimes[index]),
            })
            .collect();
        let mut jobs = Vec::new();
        for s in render_order(&scenes) {
            let scene = &scenes[s];
            jobs.push(Job::Reference { scene: s });
            for seed_index in 0..scene.render.seeds {
                jobs.push(Job::Inputs {
                    scene: s,
                    seed_index,
                });
            }
        }
        Self {
            scenes,
            jobs,
            seed: config.seed,
        }
    }

    /// Render seed of a job (32 bits so JSON readers in any language keep it exact).
    pub fn render_seed(&self, job: &Job) -> u64 {
        let key = match *job {
            Job::Reference { scene } => hash_seq(&[self.seed, hash_str("reference"), scene as u64]),
            Job::Inputs { scene, seed_index } => hash_seq(&[
                self.seed,
                hash_str("inputs"),
                scene as u64,
                u64::from(seed_index),
            ]),
        };
        key & 0xffff_ffff
    }

    /// Bundle path (relative) of an input run at a pass count.
    pub fn bundle_path(&self, scene: usize, seed_index: u32, passes: u32) -> String {
        format!(
            "bundles/{}/s{seed_index:02}_p{passes:05}.exr",
            self.scenes[scene].id
        )
    }

    /// Path (relative) of a job's completion record.
    pub fn record_path(&self, job: &Job) -> String {
        let id = &self.scenes[job.scene()].id;
        match *job {
            Job::Reference { .. } => format!("records/{id}/reference.json"),
            Job::Inputs { seed_index, .. } => format!("records/{id}/s{seed_index:02}.json"),
        }
    }

    /// Path (relative) of the resumable state of a job's run under the config with fingerprint
    /// `fingerprint` while it renders (removed when the job is done; next to its record, so a
    /// shard only ever touches its own). The fingerprint is in the name so that a state left by
    /// a killed run of an earlier config is never resumed under a changed one.
    pub fn state_path(&self, job: &Job, fingerprint: &str) -> String {
        let tag = &fingerprint[..fingerprint.len().min(16)];
        self.record_path(job)
            .replace(".json", &format!(".{tag}.state"))
    }

    /// Path (relative) of the resumable state of run `run` of a reference averaged from
    /// several runs (run 0's is [`Plan::state_path`]).
    pub fn reference_run_state(&self, job: &Job, fingerprint: &str, run: u32) -> String {
        let state = self.state_path(job, fingerprint);
        if run == 0 {
            state
        } else {
            state.replace(".state", &format!(".run{run}.state"))
        }
    }

    /// Path (relative) of the finished image of run `run` of a reference averaged from several
    /// runs, kept until the job's record is written so that a killed job loses no finished run.
    pub fn reference_run_image(&self, job: &Job, fingerprint: &str, run: u32) -> String {
        self.state_path(job, fingerprint)
            .replace(".state", &format!(".run{run}.exr"))
    }

    /// Path (relative) of a job's timing note (wall-clock; not part of the canonical data).
    pub fn timing_path(&self, job: &Job) -> String {
        self.record_path(job).replacen("records/", "timings/", 1)
    }

    /// Indices of the jobs shard `index` of `count` runs: every `count`-th job of the scenes
    /// `keep` marks ([`SceneSelection::scenes_of`]; all `true` for the whole dataset).
    pub fn shard_jobs(&self, shard: Shard, keep: &[bool], kinds: JobKinds) -> Vec<usize> {
        (0..self.jobs.len())
            .filter(|&j| keep[self.jobs[j].scene()] && kinds.runs(&self.jobs[j]))
            .enumerate()
            .filter(|(k, _)| k % shard.count as usize == shard.index as usize)
            .map(|(_, j)| j)
            .collect()
    }
}

/// The order scenes are rendered in: the evaluation splits first (test, then validation), then
/// training; within each, the families take turns (the first scene of each family, then the
/// second, ...). A render stopped part-way — a long one spans sessions — then holds held-out
/// scenes of every family and a training subset balanced across families, instead of the first
/// families only. Seeds and paths depend on the scene index, not on this order.
fn render_order(scenes: &[ScenePlan]) -> Vec<usize> {
    let split_rank = |s: Split| match s {
        Split::Test => 0,
        Split::Val => 1,
        Split::Train => 2,
    };
    let mut order: Vec<usize> = (0..scenes.len()).collect();
    order.sort_by_key(|&i| {
        (
            split_rank(scenes[i].split),
            scenes[i].turn,
            scenes[i].family,
            i,
        )
    });
    order
}

/// Each scene's place among the scenes of its family and split (1-based, in index order).
fn family_turns(list: &[(String, Family)], splits: &[Split]) -> Vec<usize> {
    let mut counts: std::collections::HashMap<(Family, Split), usize> = Default::default();
    list.iter()
        .zip(splits)
        .map(|((_, family), &split)| {
            let count = counts.entry((*family, split)).or_default();
            *count += 1;
            *count
        })
        .collect()
}

/// A Markdown table of what `plan` renders, one row per regime (one row without regimes):
/// scenes (train/val/test), side, photons per pixel per pass (min–max), and the photons and eye
/// passes (passes × pixels, in 128² units) of all input runs and of all reference runs.
pub fn summary(plan: &Plan) -> String {
    summary_of(plan, &vec![true; plan.scenes.len()])
}

/// [`summary`] of the scenes `keep` marks ([`SceneSelection::scenes_of`]).
pub fn summary_of(plan: &Plan, keep: &[bool]) -> String {
    let kept: Vec<&ScenePlan> = plan.scenes.iter().filter(|s| keep[s.index]).collect();
    let mut names: Vec<Option<String>> = Vec::new();
    for s in &kept {
        if !names.contains(&s.render.regime) {
            names.push(s.render.regime.clone());
        }
    }
    let mut out = String::from(
        "| regime | scenes (train/val/test) | side | photons/pixel/pass | input photons | \
         reference photons | input eye passes | reference eye passes |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    let mut totals = [0.0f64; 4];
    for name in &names {
        let scenes: Vec<&ScenePlan> = kept
            .iter()
            .copied()
            .filter(|s| &s.render.regime == name)
            .collect();
        let count = |split: Split| scenes.iter().filter(|s| s.split == split).count();
        let mut sides: Vec<u32> = scenes.iter().map(|s| s.render.width).collect();
        sides.dedup();
        let density = |s: &&ScenePlan| {
            s.render.photons_per_pass as f64 / f64::from(s.render.width * s.render.height)
        };
        let lo = scenes.iter().map(density).fold(f64::INFINITY, f64::min);
        let hi = scenes.iter().map(density).fold(0.0, f64::max);
        let mut row = [0.0f64; 4];
        for s in &scenes {
            let r = &s.render;
            let pixels = f64::from(r.width * r.height) / 16384.0;
            let seeds = f64::from(r.seeds);
            let runs = f64::from(r.reference_runs * r.reference_passes);
            row[0] += seeds * r.photons_per_pass as f64 * f64::from(r.last_pass());
            row[1] += runs * r.reference_photons_per_pass as f64;
            row[2] += seeds * f64::from(r.last_pass()) * pixels;
            row[3] += runs * pixels;
        }
        for (t, v) in totals.iter_mut().zip(row) {
            *t += v;
        }
        out.push_str(&format!(
            "| {} | {} ({}/{}/{}) | {} | {lo:.2}–{hi:.2} | {:.3e} | {:.3e} | {:.3e} | {:.3e} |\n",
            name.as_deref().unwrap_or("—"),
            scenes.len(),
            count(Split::Train),
            count(Split::Val),
            count(Split::Test),
            sides
                .iter()
                .map(u32::to_string)
                .collect::<Vec<_>>()
                .join(", "),
            row[0],
            row[1],
            row[2],
            row[3]
        ));
    }
    out.push_str(&format!(
        "| all | {} | | | {:.3e} | {:.3e} | {:.3e} | {:.3e} |\n",
        kept.len(),
        totals[0],
        totals[1],
        totals[2],
        totals[3]
    ));
    out
}

/// Which scenes a `datagen render` runs (all criteria must hold; an empty list allows all). A
/// session that cannot render a whole dataset renders what it needs: the evaluation splits of
/// some families, or a slice of the training split that takes every family in turn.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SceneSelection {
    /// Only scenes of these splits.
    pub splits: Vec<Split>,
    /// Only scenes of these families (names as in the config, e.g. `lamp`).
    pub families: Vec<String>,
    /// Only these scene ids.
    pub scenes: Vec<String>,
    /// Only the scenes whose place in their family and split ([`ScenePlan::turn`]) lies in
    /// this inclusive 1-based range.
    pub per_family: Option<(usize, usize)>,
}

impl SceneSelection {
    /// Parses `--per-family`'s `A-B` (or `A`, one place), 1-based and inclusive.
    pub fn parse_range(s: &str) -> Result<(usize, usize), String> {
        let (a, b) = s.split_once('-').unwrap_or((s, s));
        let num = |t: &str| -> Result<usize, String> {
            t.trim()
                .parse::<usize>()
                .ok()
                .filter(|&n| n >= 1)
                .ok_or_else(|| format!("`{s}`: expected A-B with 1 ≤ A ≤ B, e.g. 1-4"))
        };
        let (a, b) = (num(a)?, num(b)?);
        if a > b {
            return Err(format!(
                "`{s}`: the first place ({a}) is after the last ({b})"
            ));
        }
        Ok((a, b))
    }

    /// The scene indices of `plan` this selection keeps. Names that match no family or scene of
    /// the config, and a selection that keeps no scene, are errors (a typo would otherwise
    /// render nothing, or everything).
    pub fn scenes_of(&self, plan: &Plan) -> Result<Vec<bool>, String> {
        for name in &self.families {
            if !plan.scenes.iter().any(|s| s.family.name() == name) {
                let mut known: Vec<&str> = plan.scenes.iter().map(|s| s.family.name()).collect();
                known.dedup();
                return Err(format!(
                    "family `{name}` is not in this config (its families: {})",
                    known.join(", ")
                ));
            }
        }
        for id in &self.scenes {
            if !plan.scenes.iter().any(|s| &s.id == id) {
                return Err(format!("scene `{id}` is not in this config"));
            }
        }
        let keep: Vec<bool> = plan
            .scenes
            .iter()
            .map(|s| {
                (self.splits.is_empty() || self.splits.contains(&s.split))
                    && (self.families.is_empty()
                        || self.families.iter().any(|f| f == s.family.name()))
                    && (self.scenes.is_empty() || self.scenes.contains(&s.id))
                    && self
                        .per_family
                        .is_none_or(|(a, b)| (a..=b).contains(&s.turn))
            })
            .collect();
        if !keep.contains(&true) {
            return Err(
                "the selection (--splits, --families, --scenes, --per-family) keeps no \
                        scene of this config"
                    .into(),
            );
        }
        Ok(keep)
    }
}

/// Which kinds of the selected scenes' jobs a `datagen render` runs. They suit different
/// machines: a scene's reference is one long run that writes one small image (on `large`, more
/// than half of a scene's time and ≈ 0.3 MB), its inputs short runs that write most of its
/// bytes (≈ 13 MB). A short-lived node with many cores can render references and hand them
/// back; the bundles are rendered where training reads them. Either kind resumes the same way,
/// and a later call with the other kind completes the scenes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum JobKinds {
    /// References and inputs.
    #[default]
    All,
    /// Only the references.
    References,
    /// Only the input bundles.
    Inputs,
}

impl JobKinds {
    /// Whether `job` is of these kinds.
    pub fn runs(self, job: &Job) -> bool {
        matches!(
            (self, job),
            (JobKinds::All, _)
                | (JobKinds::References, Job::Reference { .. })
                | (JobKinds::Inputs, Job::Inputs { .. })
        )
    }
}

/// A shard: this process runs jobs `index`, `index + count`, ...
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// 0-based shard index.
    pub index: u32,
    /// Number of shards (≥ 1).
    pub count: u32,
}

impl Shard {
    /// The whole dataset in one process.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Parses `I/N` (0 ≤ I < N).
    pub fn parse(s: &str) -> Result<Self, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("shard `{s}`: expected I/N, e.g. 0/4"))?;
        let index: u32 = i
            .trim()
            .parse()
            .map_err(|_| format!("shard `{s}`: bad index"))?;
        let count: u32 = n
            .trim()
            .parse()
            .map_err(|_| format!("shard `{s}`: bad count"))?;
        Self::new(index, count).map_err(|e| format!("shard `{s}`: {e}"))
    }

    /// Validates index < count.
    pub fn new(index: u32, count: u32) -> Result<Self, String> {
        if count == 0 || index >= count {
            return Err(format!(
                "index {index} must be below count {count} (count ≥ 1)"
            ));
        }
        Ok(Self { index, count })
    }

    /// The shard from scheduler environment variables, if set: Slurm array jobs
    /// (`SLURM_ARRAY_TASK_ID` − `SLURM_ARRAY_TASK_MIN` of `SLURM_ARRAY_TASK_COUNT`) or
    /// Kubernetes Indexed Jobs (`JOB_COMPLETION_INDEX` of `DATAGEN_SHARD_COUNT`).
    pub fn from_env(get: impl Fn(&str) -> Option<String>) -> Result<Option<Self>, String> {
        let num =
            |name: &str| -> Result<Option<u32>, String> {
                match get(name) {
                    None => Ok(None),
                    Some(v) => v.trim().parse().map(Some).map_err(|_| {
                        format!("environment variable {name}=`{v}` is not an integer")
                    }),
                }
            };
        if let Some(id) = num("SLURM_ARRAY_TASK_ID")? {
            let count = num("SLURM_ARRAY_TASK_COUNT")?
                .ok_or("SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not")?;
            let min = num("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let index = id
                .checked_sub(min)
                .ok_or("SLURM_ARRAY_TASK_ID is below SLURM_ARRAY_TASK_MIN")?;
            return Self::new(index, count).map(Some);
        }
        if let Some(index) = num("JOB_COMPLETION_INDEX")? {
            let count = num("DATAGEN_SHARD_COUNT")?.ok_or(
                "JOB_COMPLETION_INDEX is set but DATAGEN_SHARD_COUNT (the Job's completions) is not",
            )?;
            return Self::new(index, count).map(Some);
        }
        Ok(None)
    }
}

/// The image size of scene `index`: its regime's side, or the config's size.
pub fn scene_size(config: &Config, index: usize) -> (u32, u32) {
    let regimes = assign_regimes(config, &scene_list(config));
    scene_side(config, regimes[index])
}

fn scene_side(config: &Config, regime: Option<usize>) -> (u32, u32) {
    match regime.and_then(|g| config.render.regimes[g].side) {
        Some(side) => (side, side),
        None => (config.width, config.height),
    }
}

/// The render settings of scene `index` (split `split`, regime `regime`). The photon density
/// of a regime is drawn log-uniformly per scene (its own stream: scenes and splits are not
/// touched); the reference's photons per pass follow from the photon factor of the split.
fn scene_render(config: &Config, index: usize, split: Split, regime: Option<usize>) -> SceneRender {
    let r = &config.render;
    let (width, height) = scene_side(config, regime);
    // Validation guarantees the render section's counts where there are no regimes.
    let (name, photons_per_pass, passes, seeds, reference_passes) =
        match regime.map(|g| &r.regimes[g]) {
            None => (
                None,
                r.photons_per_pass.unwrap_or(1),
                r.passes.clone().unwrap_or_default(),
                r.seeds,
                r.reference_passes,
            ),
            Some(g) => {
                let mut rng = Rng::new(hash_seq(&[config.seed, hash_str("photons"), index as u64]));
                let [lo, hi] = g.photons_per_pixel;
                let per_pixel = (lo.ln() + rng.uniform() * (hi / lo).ln()).exp();
                let photons = (per_pixel * f64::from(width) * f64::from(height)).round() as u64;
                (
                    Some(g.name.clone()),
                    photons.max(1),
                    g.passes.clone(),
                    g.seeds.unwrap_or(r.seeds),
                    g.reference_passes.unwrap_or(r.reference_passes),
                )
            }
        };
    let runs = r.reference_runs.unwrap_or(1);
    let factor = match split {
        Split::Train => r
            .train_reference_photon_factor
            .or(r.reference_photon_factor),
        Split::Val | Split::Test => r.reference_photon_factor,
    };
    let reference_photons_per_pass = match factor {
        None => r.reference_photons_per_pass,
        Some(f) => {
            let input = photons_per_pass as f64 * f64::from(*passes.last().unwrap_or(&1));
            let per_pass = (f * input / f64::from(reference_passes * runs)).ceil() as u64;
            per_pass.max(r.reference_photons_per_pass)
        }
    };
    SceneRender {
        regime: name,
        width,
        height,
        photons_per_pass,
        passes,
        seeds,
        reference_passes,
        reference_photons_per_pass,
        reference_runs: runs,
    }
}

/// The regime of every scene (`None` everywhere without regimes): within each family the
/// scenes are split over the regimes by their shares (largest remainders), in a seeded order,
/// so that every family is rendered in every regime as far as its count allows.
fn assign_regimes(config: &Config, list: &[(String, Family)]) -> Vec<Option<usize>> {
    let regimes = &config.render.regimes;
    let mut out = vec![None; list.len()];
    if regimes.is_empty() {
        return out;
    }
    let total: f64 = regimes.iter().map(|g| g.share).sum();
    for family in Family::ALL {
        let mut members: Vec<usize> = (0..list.len()).filter(|&i| list[i].1 == family).collect();
        let n = members.len();
        if n == 0 {
            continue;
        }
        let exact: Vec<f64> = regimes.iter().map(|g| g.share / total * n as f64).collect();
        let mut counts: Vec<usize> = exact.iter().map(|e| e.floor() as usize).collect();
        let mut by_remainder: Vec<usize> = (0..regimes.len()).collect();
        by_remainder.sort_by(|&a, &b| {
            let (ra, rb) = (exact[a] - exact[a].floor(), exact[b] - exact[b].floor());
            rb.total_cmp(&ra).then(a.cmp(&b))
        });
        let missing = n - counts.iter().sum::<usize>();
        for &g in by_remainder.iter().take(missing) {
            counts[g] += 1;
        }
        let mut rng = Rng::new(hash_seq(&[
            config.seed,
            hash_str("regime"),
            hash_str(family.name()),
        ]));
        rng.shuffle(&mut members);
        let mut next = members.into_iter();
        for (g, &count) in counts.iter().enumerate() {
            for i in next.by_ref().take(count) {
                out[i] = Some(g);
            }
        }
    }
    out
}

/// Assigns splits by scene: within each family the scenes are shuffled (seeded), then test and
/// validation scenes are taken round-robin over the families so every split sees every family
/// as far as counts allow. Counts are the rounded fractions (at least one scene for a positive
/// fraction when there are at least three scenes).
fn assign_splits(config: &Config, list: &[(String, Family)]) -> Vec<Split> {
    // External scenes with a fixed split keep it; the fractions apply to the other scenes.
    let fixed: Vec<Option<Split>> = (0..list.len())
        .map(|i| config.external_scene(i).and_then(|s| s.split))
        .collect();
    let free: Vec<usize> = (0..list.len()).filter(|&i| fixed[i].is_none()).collect();
    let n = free.len();
    let count_for = |f: f32| {
        let k = (f * n as f32).round() as usize;
        if f > 0.0 && k == 0 && n >= 3 {
            1
        } else {
            k
        }
    };
    let n_test = count_for(config.split.test);
    let n_val = count_for(config.split.val).min(n - n_test.min(n));
    let mut rng = Rng::new(hash_seq(&[config.seed, hash_str("split")]));
    let mut per_family: Vec<Vec<usize>> = Family::ALL
        .iter()
        .map(|f| free.iter().copied().filter(|&i| list[i].1 == *f).collect())
        .collect();
    for v in &mut per_family {
        rng.shuffle(v);
    }
    // Round-robin order: first of each family, second of each family, ...
    let mut order = Vec::new();
    let longest = per_family.iter().map(Vec::len).max().unwrap_or(0);
    for k in 0..longest {
        for v in &per_family {
            if let Some(&i) = v.get(k) {
                order.push(i);
            }
        }
    }
    let mut splits: Vec<Split> = fixed.iter().map(|f| f.unwrap_or(Split::Train)).collect();
    for (rank, &i) in order.iter().enumerate() {
        if rank < n_test {
            splits[i] = Split::Test;
        } else if rank < n_test + n_val {
            splits[i] = Split::Val;
        }
    }
    splits
}

#[cfg(test)]
mod tests {
    use super::Split;

    #[test]
    fn split_names_match_the_manifest_spelling_and_parse_back() {
        for split in [Split::Train, Split::Val, Split::Test] {
            let json = serde_json::to_value(split).unwrap();
            assert_eq!(json.as_str(), Some(split.name()));
            assert_eq!(split.name().parse::<Split>(), Ok(split));
        }
        assert!("validation"
            .parse::<Split>()
            .unwrap_err()
            .contains("validation"));
    }
}
