//! The production [`SampleRenderer`]: loads the scene XML with the renderer's Mitsuba importer
//! and runs multi-level SPPM. The reference is level `y` (the sharpest, least biased level) of
//! one long multi-level run; inputs are bundles of one continuing run at each pass count.

use crate::jobs::{RunSpec, SampleRenderer};
use anyhow::{anyhow, bail, Context, Result};
use bundle::{Bundle, Image};
use renderer::integrators::sppm::{render_sppm_resumable, SppmMode, SppmSettings, StopCondition};
use renderer::scene::Scene;
use renderer::state_file::{scene_fingerprint, StateFile};
use std::path::Path;

/// Multi-level SPPM from the `renderer` crate.
#[derive(Debug, Clone, Copy, Default)]
pub struct SppmBackend;

/// Loads and builds a scene with the run's `-D` overrides (strict import: every file must be
/// fully supported) and checks that it renders at the dataset's size.
fn load(xml: &Path, spec: &RunSpec) -> Result<Scene> {
    let desc = renderer::xml::load_scene(xml, &spec.defines, false)
        .map_err(|e| anyhow!("{e}"))
        .with_context(|| format!("loading {}", xml.display()))?;
    // Strict as the import: a define the scene never reads (a misspelt name) is an error here,
    // where it would otherwise shape a whole dataset unnoticed.
    if let Some(unused) = desc.warnings.iter().find(|w| w.starts_with("-D ")) {
        bail!("{}: {unused}", xml.display());
    }
    let scene =
        Scene::from_description(desc).with_context(|| format!("building {}", xml.display()))?;
    // Bundles of one dataset share the box filter (the generated scenes name it): another
    // filter spreads each sample over neighbouring pixels and smooths the inputs unlike the
    // rest of the data.
    if let Some(why) = renderer::integrators::sppm::filter_warning(scene.camera.filter().desc()) {
        bail!("{}: {why}", xml.display());
    }
    let res = scene.camera.resolution();
    if (res.x, res.y) != spec.size {
        bail!(
            "{}: the scene renders {}x{}, the dataset is {}x{}; set the film's width and height \
             (or give `defines` that do)",
            xml.display(),
            res.x,
            res.y,
            spec.size.0,
            spec.size.1
        );
    }
    Ok(scene)
}

/// The run's state file, when the job gives one (its folder is created).
fn state_file(xml: &Path, spec: &RunSpec) -> Result<Option<StateFile>> {
    let Some(s) = &spec.state else {
        return Ok(None);
    };
    if let Some(dir) = s.path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    Ok(Some(StateFile {
        path: s.path.clone(),
        interval: s.interval,
        scene_fingerprint: scene_fingerprint(xml, &spec.defines)?,
    }))
}

/// SPPM settings of a run.
fn settings(spec: &RunSpec) -> SppmSettings {
    SppmSettings {
        photons_per_pass: spec.photons_per_pass,
        seed: spec.seed,
        mode: SppmMode::MultiLevel,
        max_depth: spec.max_depth,
        threads: spec.threads,
        scene_name: spec.scene_id.clone(),
        ..SppmSettings::default()
    }
}

impl SampleRenderer for SppmBackend {
    fn reference(
        &self,
        xml: &Path,
        spec: &RunSpec,
        on_pass: &mut (dyn FnMut(u32) + Send),
    ) -> Result<Image> {
        let scene = load(xml, spec)?;
        let stop = StopCondition {
            checkpoints: vec![*spec.passes.last().unwrap_or(&1)],
            seconds: None,
        };
        let state = state_file(xml, spec)?;
        let mut reference = None;
        render_sppm_resumable(
            &scene,
            &settings(spec),
            &stop,
            state.as_ref(),
            |b| {
                reference = Some(b.levels[0].clone());
                Ok(())
            },
            |p| on_pass(p.pass),
        )?;
        reference.ok_or_else(|| anyhow!("{}: the reference run produced no image", xml.display()))
    }

    fn inputs(
        &self,
        xml: &Path,
        spec: &RunSpec,
        on_bundle: &mut (dyn FnMut(Bundle) -> Result<()> + Send),
        on_pass: &mut (dyn FnMut(u32) + Send),
    ) -> Result<()> {
        let scene = load(xml, spec)?;
        let stop = StopCondition {
            checkpoints: spec.passes.clone(),
            seconds: None,
        };
        let state = state_file(xml, spec)?;
        render_sppm_resumable(
            &scene,
            &settings(spec),
            &stop,
            state.as_ref(),
            on_bundle,
            |p| on_pass(p.pass),
        )?;
        Ok(())
    }
}
