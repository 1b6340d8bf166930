//! State files of resumable renders (`render --state FILE`): the framing shared by the path
//! tracer's and SPPM's — a magic line naming the kind of state, one line of JSON (the run's
//! identity and progress, the body's length and CRC-32), then a binary body — written
//! atomically (temporary file, flushed to disk, renamed over the target), and read back with an
//! error naming the file for anything foreign, truncated or damaged, or saved by a run with
//! other settings.

use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// Where a run keeps its state, and how often it saves it.
#[derive(Debug, Clone, PartialEq)]
pub struct StateFile {
    /// The state file: resumed from when it exists, (re)written while the run goes on.
    pub path: PathBuf,
    /// Seconds of rendering between saves (a run also saves at its bundles and at its end).
    pub interval: f64,
    /// Identifies the scene (e.g. [`scene_fingerprint`]): a state saved for another scene
    /// is refused.
    pub scene_fingerprint: String,
}

impl StateFile {
    /// The state file `path` of a render of the scene file `xml` with its `-D` overrides
    /// `defines` and leniency, saved every `interval` seconds; checked: a positive interval and
    /// a location where the state can be written.
    pub fn for_scene(
        path: &Path,
        interval: f64,
        xml: &Path,
        defines: &[(String, String)],
        lenient: bool,
    ) -> Result<Self> {
        let mut identity = defines.to_vec();
        identity.push(("--lenient".into(), lenient.to_string()));
        let state = StateFile {
            path: path.to_owned(),
            interval,
            scene_fingerprint: scene_fingerprint(xml, &identity)?,
        };
        state.check_interval()?;
        state.check_writable()?;
        Ok(state)
    }

    /// Checks that the saving interval is a positive number of seconds.
    pub fn check_interval(&self) -> Result<()> {
        if self.interval.is_nan() || self.interval <= 0.0 {
            bail!(
                "the state-saving interval must be positive, got {}",
                self.interval
            );
        }
        Ok(())
    }

    /// Checks up front that the state can be written where it is asked for (a temporary file
    /// is created there and removed), so a bad path fails before any rendering, not at the
    /// first save.
    pub fn check_writable(&self) -> Result<()> {
        let tmp = temp_path(&self.path);
        std::fs::File::create(&tmp)
            .with_context(|| format!("cannot write the run state {}", self.path.display()))?;
        let _ = std::fs::remove_file(&tmp);
        Ok(())
    }
}

/// The JSON line: the caller's header and the body's length and checksum.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Envelope<H> {
    /// The caller's header (identity and progress of the run).
    state: H,
    /// Length of the binary body in bytes.
    body_bytes: u64,
    /// CRC-32 of the binary body.
    body_crc32: u32,
}

/// The temporary file next to `path` (same directory: the rename over `path` is atomic). One
/// name per state file, so a save interrupted by a kill leaves no litter beyond the next save.
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "state".into());
    path.with_file_name(format!(".{name}.tmp"))
}

/// Writes `magic`, `header` and `body` to `path` atomically.
pub fn save<H: Serialize>(path: &Path, magic: &str, header: &H, body: &[u8]) -> Result<()> {
    let envelope = Envelope {
        state: header,
        body_bytes: body.len() as u64,
        body_crc32: crc32fast::hash(body),
    };
    let tmp = temp_path(path);
    let result = fileio::atomic::write_via(path, &tmp, |tmp| -> std::io::Result<()> {
        let mut w = BufWriter::new(std::fs::File::create(tmp)?);
        writeln!(w, "{magic}")?;
        serde_json::to_writer(&mut w, &envelope)?;
        writeln!(w)?;
        w.write_all(body)?;
        w.into_inner().map_err(|e| e.into_error())?;
        Ok(())
    });
    if let Err(e) = result {
        return Err(e.into_io())
            .with_context(|| format!("writing the run state {}", path.display()));
    }
    Ok(())
}

/// Reads the state at `path`: `None` when there is no such file, the header and body when it
/// is a `magic` state file whose body is intact, an error naming the file otherwise.
pub fn load<H: DeserializeOwned>(path: &Path, magic: &str) -> Result<Option<(H, Vec<u8>)>> {
    let file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => {
            return Err(e).with_context(|| format!("reading the run state {}", path.display()))
        }
    };
    let context = || format!("reading the run state {}", path.display());
    let mut r = BufReader::new(file);
    let mut line = Vec::new();
    // Short reads: a large foreign file is not read whole as one "line".
    (&mut r)
        .take(magic.len() as u64 + 1)
        .read_until(b'\n', &mut line)
        .with_context(context)?;
    if line.strip_suffix(b"\n") != Some(magic.as_bytes()) {
        bail!(
            "{}: not a run state of this kind (its first line should be `{magic}`); give --state \
             a new file name, or delete this file",
            path.display()
        );
    }
    line.clear();
    (&mut r)
        .take(1 << 20)
        .read_until(b'\n', &mut line)
        .with_context(context)?;
    let envelope: Envelope<H> = serde_json::from_slice(&line)
        .with_context(|| format!("{}: line 2: damaged run-state header", path.display()))?;
    let mut body = Vec::new();
    (&mut r)
        .take(envelope.body_bytes.saturating_add(1))
        .read_to_end(&mut body)
        .with_context(context)?;
    if body.len() as u64 != envelope.body_bytes {
        bail!(
            "{}: damaged run state: {} bytes of data after the header, which says {} (a \
             truncated or extended file)",
            path.display(),
            body.len(),
            envelope.body_bytes
        );
    }
    if crc32fast::hash(&body) != envelope.body_crc32 {
        bail!(
            "{}: damaged run state: the data's checksum does not match its header",
            path.display()
        );
    }
    Ok(Some((envelope.state, body)))
}

/// Compares the identity saved in a state file (`saved`) with this run's (`here`), field by
/// field: an error naming the file and the first field that differs — the integrator first,
/// when it differs (the other fields then differ because of it).
pub fn check_identity<I: Serialize>(path: &Path, saved: &I, here: &I) -> Result<()> {
    let (saved, here) = (serde_json::to_value(saved)?, serde_json::to_value(here)?);
    let (Some(a), Some(b)) = (saved.as_object(), here.as_object()) else {
        bail!("run identities must be JSON objects");
    };
    // Every key of either side: a setting at its default is left out of an identity, so a key
    // only one side has is a setting that differs from the default on that side.
    let mut keys: Vec<&String> = b
        .keys()
        .chain(a.keys().filter(|k| !b.contains_key(*k)))
        .collect();
    keys.sort_by_key(|key| key.as_str() != "integrator");
    let null = serde_json::Value::Null;
    let shown = |v: &serde_json::Value| {
        if v.is_null() {
            "absent (the default)".to_string()
        } else {
            v.to_string()
        }
    };
    for key in keys {
        let (old, value) = (a.get(key).unwrap_or(&null), b.get(key).unwrap_or(&null));
        if old != value {
            let (old, value) = (shown(old), shown(value));
            let hint = if key == "scene_fingerprint" {
                " (the scene file, a file it reads — include, mesh, texture — or its -D overrides \
                 changed)"
            } else {
                ""
            };
            bail!(
                "{}: the saved run differs from this one: {key}: {old} in the file, {value} in \
                 this run{hint}; resume with the same scene and settings, or give --state a new \
                 file name",
                path.display()
            );
        }
    }
    Ok(())
}

/// SHA-256 (lower-case hex) over what a render of the scene file `xml` with the `-D`
/// overrides `defines` depends on: the overrides, and the contents of every file the scene
/// reads ([`crate::xml::scene_files`]: the XML, its includes, meshes, textures, spectra), in
/// document order. A file that cannot be read counts as missing (the scene's load names it).
pub fn scene_fingerprint(xml: &Path, defines: &[(String, String)]) -> Result<String> {
    use sha2::{Digest, Sha256};
    let files = crate::xml::scene_files(xml, defines)?;
    let mut h = Sha256::new();
    for (name, value) in defines {
        for part in [name, value] {
            h.update((part.len() as u64).to_le_bytes());
            h.update(part.as_bytes());
        }
    }
    for file in &files {
        // The file's order in the list identifies it (a renamed file with the same contents
        // renders the same); its length frames its bytes.
        match std::fs::read(file) {
            Ok(bytes) => {
                h.update((bytes.len() as u64).to_le_bytes());
                h.update(&bytes);
            }
            Err(_) => h.update(u64::MAX.to_le_bytes()),
        }
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

/// Little-endian reader over a binary body.
pub struct Cursor<'a> {
    /// The bytes.
    bytes: &'a [u8],
    /// Read position.
    at: usize,
}

impl<'a> Cursor<'a> {
    /// A reader at the start of `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        Cursor { bytes, at: 0 }
    }

    /// The next `N` bytes; the caller has checked the body's length.
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let b: [u8; N] = self.bytes[self.at..self.at + N]
            .try_into()
            .expect("body length checked by the caller");
        self.at += N;
        b
    }

    /// The next f32.
    pub fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }

    /// The next u32.
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }

    /// The next f64.
    pub fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }

    /// The next three f64.
    pub fn dvec3(&mut self) -> glam::DVec3 {
        glam::DVec3::new(self.f64(), self.f64(), self.f64())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Identities are compared on every key of either side: a setting left out at its default
    /// on one side and set on the other is a difference, named with both values.
    #[test]
    fn identities_differ_on_a_key_only_one_side_has() {
        #[derive(serde::Serialize)]
        struct Id {
            integrator: &'static str,
            #[serde(skip_serializing_if = "Option::is_none")]
            sampler: Option<&'static str>,
        }
        let path = Path::new("run.state");
        let plain = Id {
            integrator: "sppm-ml",
            sampler: None,
        };
        let set = Id {
            integrator: "sppm-ml",
            sampler: Some("ldsampler"),
        };
        check_identity(path, &plain, &plain).unwrap();
        check_identity(path, &set, &set).unwrap();
        for (saved, here, old, new) in [
            (&set, &plain, "\"ldsampler\"", "absent (the default)"),
            (&plain, &set, "absent (the default)", "\"ldsampler\""),
        ] {
            let e = check_identity(path, saved, here).unwrap_err().to_string();
            assert!(
                e.contains("run.state")
                    && e.contains(&format!("sampler: {old} in the file, {new} in this run")),
                "{e}"
            );
        }
    }

    #[test]
    fn the_scene_fingerprint_changes_with_any_file_the_scene_reads() {
        let dir = std::env::temp_dir().join(format!("state-fingerprint-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("meshes")).unwrap();
        let xml = dir.join("scene.xml");
        std::fs::write(
            &xml,
            "<scene version=\"3.0.0\">\n<default name=\"m\" value=\"tri\"/>\n\
             <shape type=\"obj\"><string name=\"filename\" value=\"meshes/$m.obj\"/></shape>\n</scene>\n",
        )
        .unwrap();
        let mesh = dir.join("meshes/tri.obj");
        let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        std::fs::write(&mesh, tri).unwrap();
        let fingerprint = |defines: &[(String, String)]| scene_fingerprint(&xml, defines).unwrap();
        let original = fingerprint(&[]);
        assert_eq!(fingerprint(&[]), original, "deterministic");
        // An edited mesh is another scene, even with the XML untouched …
        std::fs::write(&mesh, tri.replace("v 0 1 0", "v 0 2 0")).unwrap();
        assert_ne!(fingerprint(&[]), original);
        // … and the same one again once restored.
        std::fs::write(&mesh, tri).unwrap();
        assert_eq!(fingerprint(&[]), original);
        // A define that names another file, and a missing mesh, are other scenes too (the
        // missing file is left for the scene's load to report).
        let other = fingerprint(&[("m".into(), "quad".into())]);
        assert_ne!(other, original);
        std::fs::remove_file(&mesh).unwrap();
        assert_ne!(fingerprint(&[]), original);
        // The XML itself is read: a missing scene file is an error naming it.
        let err = scene_fingerprint(&dir.join("none.xml"), &[]).unwrap_err();
        assert!(format!("{err:#}").contains("none.xml"), "{err:#}");
    }
}
