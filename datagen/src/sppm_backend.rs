//! The production [`SampleRenderer`]: loads the scene XML with the renderer's Mitsuba importer
//! and runs multi-level SPPM. The reference is level `y` (the sharpest, least biased level) of
//! one long multi-level run; inputs are bundles of one continuing run at each pass count.

use crate::jobs::{RunSpec, SampleRenderer};
use anyhow::{anyhow, bail, Context, Result};
use bundle::{Bundle, Image};
use renderer::integrators::sppm::{render_sppm_resumable, StopCondition};
use renderer::scene::Scene;
use renderer::state_file::{scene_fingerprint, StateFile};
use std::path::Path;

/// Multi-level SPPM from the `renderer` crate.
#[derive(Debug, Clone, Copy, Default)]
pub struct SppmBackend;

/// Loads and builds a scene with the run's `-D` overrides under the toolkit's scene policy
/// (`renderer::scene_file`, strict) and the dataset's own rules: the box filter and the
/// dataset's image size, so that its bundles are alike.
fn load(xml: &Path, spec: &RunSpec) -> Result<Scene> {
    // The toolkit's scene policy (renderer::scene_file), strict: no --lenient for datasets.
    let loaded = renderer::scene_file::load(xml, &spec.defines, false)?;
    for w in &loaded.warnings {
        eprintln!("warning: {}: {w}", xml.display());
    }
    let scene = loaded.scene;
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
            &spec.sppm,
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
        render_sppm_resumable(&scene, &spec.sppm, &stop, state.as_ref(), on_bundle, |p| {
            on_pass(p.pass)
        })?;
        Ok(())
    }
}
