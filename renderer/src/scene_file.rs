//! Loading a scene file under the toolkit's one policy, the same for every command that renders
//! (`render`, `infer --scene`, `datagen render`, `evaluate`), so that a scene one of them accepts
//! no other refuses for reasons of its own:
//!
//! 1. The Mitsuba 3 XML is read with the command's `-D` overrides; unknown plugins, parameters
//!    and attributes are errors unless the user asked for `--lenient` (only the commands a person
//!    points at a foreign scene offer it: `render`, `infer`).
//! 2. A `-D` that no file of the scene reads is an error: it is most likely a misspelt name, and
//!    would otherwise shape a render — or a whole dataset — unnoticed.
//! 3. The loader's other warnings are returned for the command to print.
//! 4. For SPPM ([`load_for_sppm`], [`LoadedScene::check_for_sppm`]): a reconstruction filter
//!    other than the box is a warning — each pixel's samples spread over its neighbours, so the
//!    bundle is smoother than those the networks were trained on. (A dataset refuses it, by the
//!    dataset's own rule that its bundles are alike: `datagen`.)
//!
//! Every error names the file.

use std::path::Path;

use anyhow::{Context, Result};

use crate::scene::Scene;

/// A built scene and the warnings its loading produced (to be printed by the command).
pub struct LoadedScene {
    /// The scene, ready to render.
    pub scene: Scene,
    /// What the loader noticed but accepted (rule 3), and for SPPM the filter note (rule 4).
    pub warnings: Vec<String>,
}

impl LoadedScene {
    /// Adds the SPPM notes (rule 4) to the warnings.
    pub fn check_for_sppm(&mut self) {
        if let Some(w) = crate::integrators::sppm::filter_warning(self.scene.camera.filter().desc())
        {
            self.warnings.push(w);
        }
    }
}

/// Loads and builds the scene `xml` under rules 1–3.
pub fn load(xml: &Path, defines: &[(String, String)], lenient: bool) -> Result<LoadedScene> {
    let mut desc = crate::xml::load_scene(xml, defines, lenient)
        .map_err(|e| crate::xml::load_error(e, xml))?;
    if let Some(unused) = desc.warnings.iter().find(|w| w.starts_with("-D ")) {
        anyhow::bail!("{}: {unused}", xml.display());
    }
    let warnings = std::mem::take(&mut desc.warnings);
    let scene =
        Scene::from_description(desc).with_context(|| format!("building {}", xml.display()))?;
    Ok(LoadedScene { scene, warnings })
}

/// Loads and builds the scene `xml` for SPPM: rules 1–4.
pub fn load_for_sppm(
    xml: &Path,
    defines: &[(String, String)],
    lenient: bool,
) -> Result<LoadedScene> {
    let mut loaded = load(xml, defines, lenient)?;
    loaded.check_for_sppm();
    Ok(loaded)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene in its own folder: the lit floor of the CLI tests with `filter` as its film's
    /// reconstruction filter and its floor's BSDF of type `bsdf`.
    fn scene(name: &str, filter: &str, bsdf: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("scene-file-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let text = include_str!("../tests/fixtures/lit-floor.xml")
            .replace(r#"<rfilter type="box"/>"#, filter)
            .replace(r#"type="diffuse""#, &format!("type=\"{bsdf}\""));
        let path = dir.join("scene.xml");
        std::fs::write(&path, text).unwrap();
        path
    }

    fn define(name: &str, value: &str) -> Vec<(String, String)> {
        vec![(name.into(), value.into())]
    }

    #[test]
    fn an_unused_define_is_an_error_naming_the_file_and_the_define() {
        let path = scene("unused", r#"<rfilter type="box"/>"#, "diffuse");
        let ok = load(&path, &define("res", "8"), false).unwrap();
        assert_eq!(ok.scene.camera.resolution().x, 8);
        assert!(ok.warnings.is_empty(), "{:?}", ok.warnings);
        for lenient in [false, true] {
            let err = format!(
                "{:#}",
                load(&path, &define("rez", "8"), lenient).err().unwrap()
            );
            assert!(
                err.contains("scene.xml") && err.contains("-D rez=8"),
                "lenient {lenient}: {err}"
            );
            assert!(load_for_sppm(&path, &define("rez", "8"), lenient).is_err());
        }
    }

    #[test]
    fn sppm_warns_about_a_non_box_filter_and_the_path_tracer_does_not() {
        let path = scene("gaussian", r#"<rfilter type="gaussian"/>"#, "diffuse");
        let plain = load(&path, &[], false).unwrap();
        assert!(plain.warnings.is_empty(), "{:?}", plain.warnings);
        let sppm = load_for_sppm(&path, &[], false).unwrap();
        assert_eq!(sppm.warnings.len(), 1, "{:?}", sppm.warnings);
        assert!(
            sppm.warnings[0].contains("gaussian") && sppm.warnings[0].contains("box"),
            "{}",
            sppm.warnings[0]
        );
        let boxed = scene("box", r#"<rfilter type="box"/>"#, "diffuse");
        assert!(load_for_sppm(&boxed, &[], false)
            .unwrap()
            .warnings
            .is_empty());
    }

    #[test]
    fn unknown_plugins_are_errors_unless_lenient() {
        let path = scene("unknown", r#"<rfilter type="box"/>"#, "velvet");
        let err = format!("{:#}", load(&path, &[], false).err().unwrap());
        assert!(err.contains("scene.xml") && err.contains("velvet"), "{err}");
        let lenient = load(&path, &[], true).unwrap();
        assert!(
            lenient.warnings.iter().any(|w| w.contains("velvet")),
            "{:?}",
            lenient.warnings
        );
    }
}
