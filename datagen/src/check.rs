//! `datagen check`: verifies a dataset against its manifest — every scene file, reference and
//! bundle present, readable, with the expected layers, finite, of the manifest's size and with
//! the recorded checksum — and reports each problem with the file it concerns.

use crate::fsutil::sha256_file;
use crate::manifest::{config_fingerprint, Manifest, MANIFEST_FILE, MANIFEST_FORMAT};
use bundle::{read_bundle, read_rgb_exr_image};
use renderer::state_file::scene_fingerprint;
use std::path::Path;

/// The outcome of a check: files looked at and problems found (each names its file).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CheckReport {
    /// Files checked.
    pub files: usize,
    /// Problems, one line each, starting with the file's path relative to the dataset root.
    pub problems: Vec<String>,
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
    let (w, h) = (manifest.width as usize, manifest.height as usize);
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
        if let Some(problem) = checksum_problem(root, &s.reference, &s.reference_sha256) {
            report.problems.push(problem);
        }
        match read_rgb_exr_image(&root.join(&s.reference)) {
            Err(e) => report
                .problems
                .push(format!("{}: unreadable: {e}", s.reference)),
            Ok(img) => {
                if (img.width, img.height) != (w, h) {
                    report.problems.push(format!(
                        "{}: size {}x{}, manifest says {w}x{h}",
                        s.reference, img.width, img.height
                    ));
                }
                if let Some(i) = img.data.iter().position(|v| !v.is_finite()) {
                    let p = i / 3;
                    report.problems.push(format!(
                        "{}: non-finite value {} (NaN/Inf) in channel {} at pixel ({}, {})",
                        s.reference,
                        img.data[i],
                        ["R", "G", "B"][i % 3],
                        p % img.width.max(1),
                        p / img.width.max(1)
                    ));
                }
            }
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
        if !seen_scenes.contains(&e.scene) {
            report.problems.push(format!(
                "{}: scene `{}` is not in the manifest",
                e.bundle, e.scene
            ));
        }
        if let Some(problem) = checksum_problem(root, &e.bundle, &e.sha256) {
            report.problems.push(problem);
        }
        match read_bundle(&root.join(&e.bundle)) {
            Err(err) => report
                .problems
                .push(format!("{}: unreadable: {err}", e.bundle)),
            Ok(b) => {
                let m = &b.meta;
                if (m.width as usize, m.height as usize) != (w, h) {
                    report.problems.push(format!(
                        "{}: size {}x{}, reference/manifest size is {w}x{h}",
                        e.bundle, m.width, m.height
                    ));
                }
                if m.passes != e.passes || m.seed != e.seed || m.photons_per_pass != e.photons {
                    report.problems.push(format!(
                        "{}: metadata (passes {}, seed {}, photons {}) disagrees with the manifest (passes {}, seed {}, photons {})",
                        e.bundle, m.passes, m.seed, m.photons_per_pass, e.passes, e.seed, e.photons
                    ));
                }
                if m.scene != e.scene {
                    report.problems.push(format!(
                        "{}: metadata scene `{}`, manifest says `{}`",
                        e.bundle, m.scene, e.scene
                    ));
                }
                if let Some((layer, channel, x, y)) = b.find_non_finite() {
                    report.problems.push(format!(
                        "{}: non-finite value (NaN/Inf) in layer `{layer}` channel `{channel}` at pixel ({x}, {y})",
                        e.bundle
                    ));
                }
            }
        }
        done += 1;
        on_file(done, total);
    }
    report
}

/// A problem line when the file is missing or its SHA-256 differs from the recorded one.
fn checksum_problem(root: &Path, rel: &str, expected: &str) -> Option<String> {
    match sha256_file(&root.join(rel)) {
        Err(e) => Some(format!("{rel}: missing or unreadable: {e}")),
        Ok(sha) if sha != expected => Some(format!(
            "{rel}: checksum mismatch (file {sha}, manifest {expected}): truncated or modified"
        )),
        Ok(_) => None,
    }
}
