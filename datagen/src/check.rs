//! `datagen check`: verifies a dataset against its manifest — every scene file, reference and
//! bundle present, readable, with the expected layers, finite, of the manifest's size and with
//! the recorded checksum — and reports each problem with the file it concerns.

use crate::fsutil::sha256_file;
use crate::manifest::{config_fingerprint, Manifest, MANIFEST_FILE, MANIFEST_FORMAT};
use bundle::{read_bundle, read_rgb_exr_image};
use renderer::state_file::scene_fingerprint;
use std::path::Path;

/// The outcome of a check: files looked at and problems found (each names its file; a file
/// with several problems has one line naming all of them).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CheckReport {
    /// Files checked.
    pub files: usize,
    /// Problems, one line per broken file (or manifest problem), starting with the file's path
    /// relative to the dataset root.
    pub problems: Vec<String>,
    /// For a partial manifest (`datagen manifest --partial`): the scenes it lists and the
    /// scenes planned.
    pub partial: Option<(usize, usize)>,
}

impl CheckReport {
    /// True when no problem was found.
    pub fn ok(&self) -> bool {
        self.problems.is_empty()
    }
}

/// Checks the dataset in `root`; calls `on_file` after each file (for progress).
pub fn check_dataset(root: &Path, mut on_file: impl FnMut(usize, usize)) -> CheckReport {
    let mut report = CheckReport::default();
    let manifest = match Manifest::load(root) {
        Ok(m) => m,
        Err(e) => {
            report.problems.push(format!("{e:#}"));
            return report;
        }
    };
    if manifest.format != MANIFEST_FORMAT {
        report.problems.push(format!(
            "{MANIFEST_FILE}: format `{}`, expected `{MANIFEST_FORMAT}`",
            manifest.format
        ));
    }
    if config_fingerprint(&manifest.config) != manifest.config_sha256 {
        report.problems.push(format!(
            "{MANIFEST_FILE}: config_sha256 does not match the embedded config"
        ));
    }
    // Every planned scene is listed, unless the manifest says it is partial (a scene listed
    // twice is its own problem, below).
    let planned = crate::plan::Plan::new(&manifest.config).scenes.len();
    let listed = manifest
        .scenes
        .iter()
        .map(|s| s.id.as_str())
        .collect::<std::collections::HashSet<_>>()
        .len();
    match manifest.partial {
        None if listed != planned => report.problems.push(format!(
            "{MANIFEST_FILE}: lists {listed} scenes, its config plans {planned} (and it is not \
             marked partial)"
        )),
        Some(p) if p.planned_scenes != planned => report.problems.push(format!(
            "{MANIFEST_FILE}: partial, of {} planned scenes, its config plans {planned}",
            p.planned_scenes
        )),
        Some(_) => report.partial = Some((listed, planned)),
        None => {}
    }
    // Each scene's size (a regime may give it its own), for its reference and bundles.
    let sizes: std::collections::HashMap<&str, (usize, usize)> = manifest
        .scenes
        .iter()
        .map(|s| {
            let (w, h) = s.size_in(&manifest);
            (s.id.as_str(), (w as usize, h as usize))
        })
        .collect();
    let total = manifest.scenes.len() * 2 + manifest.samples.len();
    let mut done = 0;
    let mut seen_scenes = std::collections::HashSet::new();
    for s in &manifest.scenes {
        // A repeated entry would be trained on, or split, twice.
        if !seen_scenes.insert(s.id.clone()) {
            report.problems.push(format!(
                "{MANIFEST_FILE}: scene `{}` is listed more than once",
                s.id
            ));
        }
        report.files += 2;
        if !root.join(&s.xml).is_file() {
            report
                .problems
                .push(format!("{}: scene file missing", s.xml));
        } else if let Some(expected) = &s.scene_sha256 {
            // A scene the user brought: it and every file it reads must still be the ones
            // that were rendered.
            let defines: Vec<(String, String)> = s
                .defines
                .iter()
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect();
            match scene_fingerprint(&root.join(&s.xml), &defines) {
                Err(e) => report.problems.push(format!("{}: {e:#}", s.xml)),
                // Datasets of the twelfth session recorded the scene file's hash alone.
                Ok(_) if sha256_file(&root.join(&s.xml)).is_ok_and(|x| x == *expected) => {
                    report.problems.push(format!(
                        "{}: its manifest entry records the scene file's hash alone (written \
                         by an older datagen), which cannot vouch for the files the scene reads; \
                         `datagen render` redoes its jobs once",
                        s.xml
                    ))
                }
                Ok(found) if found != *expected => report.problems.push(format!(
                    "{}: the scene or a file it reads (include, mesh, texture) changed since \
                     the dataset was rendered (fingerprint {found}, manifest {expected}); \
                     `datagen render` redoes its jobs",
                    s.xml
                )),
                Ok(_) => {}
            }
        }
        done += 1;
        on_file(done, total);
        let size = sizes[s.id.as_str()];
        report.problems.extend(file_problem(
            &s.reference,
            reference_problems(root, &s.reference, &s.reference_sha256, size),
        ));
        if let Some(e) = &s.evaluation_reference {
            report.files += 1;
            report.problems.extend(file_problem(
                &e.path,
                reference_problems(root, &e.path, &e.sha256, size),
            ));
        }
        done += 1;
        on_file(done, total);
    }
    let mut seen_bundles = std::collections::HashSet::new();
    for e in &manifest.samples {
        report.files += 1;
        if !seen_bundles.insert(e.bundle.clone()) {
            report.problems.push(format!(
                "{MANIFEST_FILE}: sample {} is listed more than once",
                e.bundle
            ));
        }
        // Every problem of the bundle on one line, as for references.
        let mut reasons = Vec::new();
        if !seen_scenes.contains(&e.scene) {
            reasons.push(format!("scene `{}` is not in the manifest", e.scene));
        }
        match file_state(root, &e.bundle, &e.sha256) {
            FileState::Missing(why) => reasons.push(why),
            state => {
                match read_bundle(&root.join(&e.bundle)) {
                    Err(err) => reasons.push(format!("unreadable: {err}")),
                    Ok(b) => {
                        let m = &b.meta;
                        let (w, h) = sizes
                            .get(e.scene.as_str())
                            .copied()
                            .unwrap_or((manifest.width as usize, manifest.height as usize));
                        if (m.width as usize, m.height as usize) != (w, h) {
                            reasons.push(format!(
                                "size {}x{}, reference/manifest size is {w}x{h}",
                                m.width, m.height
                            ));
                        }
                        if m.passes != e.passes
                            || m.seed != e.seed
                            || m.photons_per_pass != e.photons
                        {
                            reasons.push(format!(
                                "metadata (passes {}, seed {}, photons {}) disagrees with the \
                                 manifest (passes {}, seed {}, photons {})",
                                m.passes, m.seed, m.photons_per_pass, e.passes, e.seed, e.photons
                            ));
                        }
                        if m.scene != e.scene {
                            reasons.push(format!(
                                "metadata scene `{}`, manifest says `{}`",
                                m.scene, e.scene
                            ));
                        }
                        if let Some((layer, channel, x, y)) = b.find_non_finite() {
                            reasons.push(format!(
                                "non-finite value (NaN/Inf) in layer `{layer}` channel \
                                 `{channel}` at pixel ({x}, {y})"
                            ));
                        }
                    }
                }
                if let FileState::Mismatch(why) = state {
                    reasons.push(why);
                }
            }
        }
        report.problems.extend(file_problem(&e.bundle, reasons));
        done += 1;
        on_file(done, total);
    }
    report
}

/// Every problem of a reference image on one line's worth of reasons (a truncated file is both
/// unreadable and of another checksum: one broken file, one line).
fn reference_problems(root: &Path, rel: &str, sha: &str, (w, h): (usize, usize)) -> Vec<String> {
    let mut reasons = Vec::new();
    match file_state(root, rel, sha) {
        FileState::Missing(why) => reasons.push(why),
        state => {
            match read_rgb_exr_image(&root.join(rel)) {
                Err(e) => reasons.push(format!("unreadable: {e}")),
                Ok(img) => {
                    if (img.width, img.height) != (w, h) {
                        reasons.push(format!(
                            "size {}x{}, manifest says {w}x{h}",
                            img.width, img.height
                        ));
                    }
                    if let Some(i) = img.data.iter().position(|v| !v.is_finite()) {
                        let p = i / 3;
                        reasons.push(format!(
                            "non-finite value {} (NaN/Inf) in channel {} at pixel ({}, {})",
                            img.data[i],
                            ["R", "G", "B"][i % 3],
                            p % img.width.max(1),
                            p / img.width.max(1)
                        ));
                    }
                }
            }
            if let FileState::Mismatch(why) = state {
                reasons.push(why);
            }
        }
    }
    reasons
}

/// What the checksum says about a file of the dataset.
enum FileState {
    /// Present with the recorded SHA-256.
    Intact,
    /// Missing or unreadable (the reason): nothing else about it can be checked.
    Missing(String),
    /// Present, another SHA-256 (the reason).
    Mismatch(String),
}

/// Compares the file `rel` (under `root`) with its recorded SHA-256.
fn file_state(root: &Path, rel: &str, expected: &str) -> FileState {
    let path = root.join(rel);
    match sha256_file(&path) {
        Err(_) if !path.exists() => FileState::Missing("missing".into()),
        Err(e) => FileState::Missing(format!("unreadable: {e}")),
        Ok(sha) if sha != expected => FileState::Mismatch(format!(
            "checksum mismatch (file {sha}, manifest {expected}): truncated or modified"
        )),
        Ok(_) => FileState::Intact,
    }
}

/// The one problem line of the file `rel`: its reasons joined, `None` when there are none.
fn file_problem(rel: &str, reasons: Vec<String>) -> Option<String> {
    (!reasons.is_empty()).then(|| format!("{rel}: {}", reasons.join("; ")))
}
