//! Checks of the files a command line names, shared by the binaries that write outputs
//! (`render`, `infer`): made before any work, so that a bad name fails at once rather than
//! after a render, and so that no output silently replaces another output or an input.

use std::path::{Component, Path, PathBuf};

/// Whether `path` is written with a trailing separator (`out/`): a folder, not a file name.
pub fn ends_with_separator(path: &Path) -> bool {
    path.as_os_str()
        .to_string_lossy()
        .ends_with(std::path::is_separator)
}

/// Refuses a missing input `path` that is a binary's `default` (a path relative to the
/// repository root, such as a bench's default scene) with a message that says so: the usual
/// cause is running from another directory. `what` names the default ("the bundled default
/// scene"). Other paths are left to the loader's own error.
pub fn check_default_input(path: &Path, default: &str, what: &str) -> Result<(), String> {
    if path == Path::new(default) && !path.exists() {
        return Err(format!(
            "{default} not found: {what} is relative to the repository root; run from there \
             or give a scene file"
        ));
    }
    Ok(())
}

/// Refuses an output `path` (given by `option`) that is an existing directory or is written as
/// one (`out/`).
pub fn check_not_directory(option: &str, path: &Path) -> Result<(), String> {
    if path.is_dir() || ends_with_separator(path) {
        return Err(format!("{option} {} is a directory", path.display()));
    }
    Ok(())
}

/// `path`'s extension, lower-cased.
pub fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}

/// Refuses `path` (given by `option`) when it has an extension other than `.{wanted}` (no
/// extension is accepted); `what` says what the file is, for the message.
pub fn check_extension(option: &str, path: &Path, wanted: &str, what: &str) -> Result<(), String> {
    match extension(path) {
        Some(ext) if ext != wanted => Err(format!(
            "{option} {}: {what}, not .{ext}; give a name ending in .{wanted}",
            path.display()
        )),
        _ => Ok(()),
    }
}

/// Refuses two of `files` (what names it, path) that are the same file, however spelt.
pub fn check_distinct(files: &[(String, PathBuf)]) -> Result<(), String> {
    let keys: Vec<PathBuf> = files.iter().map(|(_, p)| resolved(p)).collect();
    for (i, (a, path_a)) in files.iter().enumerate() {
        for (j, (b, path_b)) in files.iter().enumerate().skip(i + 1) {
            if keys[i] == keys[j] {
                return Err(format!(
                    "{a} {} and {b} {} are the same file: one would overwrite the other",
                    path_a.display(),
                    path_b.display()
                ));
            }
        }
    }
    Ok(())
}

/// Creates the missing folders of an output file (`option` names it in the error).
pub fn create_parent_dir(option: &str, file: &Path) -> Result<(), String> {
    match file.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(dir) => std::fs::create_dir_all(dir)
            .map_err(|e| format!("{option}: creating the folder {}: {e}", dir.display())),
        None => Ok(()),
    }
}

/// `path` made absolute, its existing part with symbolic links, `.` and `..` resolved and the
/// rest (not yet created) normalised by name: two spellings of one file give the same path.
pub fn resolved(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_owned());
    let mut existing = absolute.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(mut out) = existing.canonicalize() {
            for part in rest.iter().rev() {
                match part {
                    Component::ParentDir => {
                        out.pop();
                    }
                    Component::CurDir => {}
                    part => out.push(part),
                }
            }
            return out;
        }
        match (existing.parent(), existing.components().next_back()) {
            (Some(parent), Some(last)) => {
                rest.push(last);
                existing = parent;
            }
            _ => return absolute,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spellings_of_one_file_are_the_same_file() {
        let dir = std::env::temp_dir().join(format!("cli-output-paths-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("a")).unwrap();
        let files =
            |a: PathBuf, b: PathBuf| vec![("--out".to_string(), a), ("--png".to_string(), b)];
        // An existing folder, a file not yet written, `.` and `..`.
        let plain = dir.join("a/x.exr");
        let dotted = dir.join("a/./../a/x.exr");
        let err = check_distinct(&files(plain.clone(), dotted)).unwrap_err();
        assert!(
            err.contains("--out") && err.contains("--png") && err.contains("same file"),
            "{err}"
        );
        // Not-yet-existing folders too.
        let deep = dir.join("new/sub/../y.exr");
        assert!(check_distinct(&files(dir.join("new/y.exr"), deep)).is_err());
        assert!(check_distinct(&files(plain, dir.join("a/y.exr"))).is_ok());
        assert!(check_extension("--out", Path::new("q.PNG"), "exr", "an EXR").is_err());
        assert!(check_extension("--out", Path::new("q.EXR"), "exr", "an EXR").is_ok());
        assert!(check_extension("--out", Path::new("q"), "exr", "an EXR").is_ok());
        assert!(ends_with_separator(Path::new("out/")) && !ends_with_separator(Path::new("out")));
        let err = check_not_directory("--out", &dir).unwrap_err();
        assert!(
            err.starts_with("--out ") && err.ends_with("is a directory"),
            "{err}"
        );
        assert!(check_not_directory("--out", &dir.join("a/x.exr")).is_ok());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A missing default is explained as relative to the repository root; a missing path the
    /// user gave, or a default that exists, is left to the loader.
    #[test]
    fn a_missing_default_input_names_the_repository_root() {
        let default = "no-such-dir/scene.xml";
        let err =
            check_default_input(Path::new(default), default, "the default scene").unwrap_err();
        assert!(
            err.starts_with("no-such-dir/scene.xml not found: the default scene is relative to the repository root"),
            "{err}"
        );
        assert!(check_default_input(Path::new("other/scene.xml"), default, "x").is_ok());
        let here = concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml");
        assert!(check_default_input(Path::new(here), here, "x").is_ok());
    }
}
