//! Atomic file writes: the content goes to a temporary file in the target's folder (same file
//! system, so the rename is atomic), which is flushed to disk (`fsync`) and renamed over the
//! target. Readers see the old file or the whole new one; a job killed mid-write leaves at most
//! a temporary file whose name says which process on which host wrote it
//! ([`remove_stale_temps`] clears those of dead processes).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Distinguishes the temporary files of concurrent writers inside one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Why an atomic write failed: the caller's writing of the temporary file, or committing it
/// (flushing it to disk, renaming it over the target). The target is unchanged either way and
/// the temporary file is removed.
#[derive(Debug)]
pub enum AtomicError<E> {
    /// Writing the temporary file failed.
    Write(E),
    /// Flushing or renaming the written temporary file failed.
    Commit(std::io::Error),
}

impl<E> AtomicError<E> {
    /// The caller's error, with a commit failure turned into one by `commit`.
    pub fn into_error(self, commit: impl FnOnce(std::io::Error) -> E) -> E {
        match self {
            Self::Write(e) => e,
            Self::Commit(e) => commit(e),
        }
    }
}

impl AtomicError<std::io::Error> {
    /// The I/O error, whichever step failed.
    pub fn into_io(self) -> std::io::Error {
        self.into_error(|e| e)
    }
}

/// A short tag of this machine (a hash of its host name): a folder shared by several machines
/// can tell whose leftover temporary files it may clear, since process ids mean something only
/// on their own host.
pub fn host_tag() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .unwrap_or_default();
    // FNV-1a, then a SplitMix64 finaliser: stable across builds and platforms, unlike std's
    // hasher.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in host.trim().bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h = (h ^ (h >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    format!("{:016x}", h ^ (h >> 31))
}

/// A temporary path next to `path`, unique per host, process and call:
/// `.<name>.tmp-<pid>-<counter>-<host tag>.<extension>`. The real extension comes last, for
/// encoders that pick the format from the file name.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let k = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(
        ".{name}.tmp-{}-{k}-{}{ext}",
        std::process::id(),
        host_tag()
    ))
}

/// Writes `path` atomically: `write` fills the temporary file [`temp_path`] (it is given its
/// path), which is then flushed to disk and renamed over `path`. On failure the temporary file
/// is removed and `path` is left as it was.
pub fn write_with<E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), AtomicError<E>> {
    write_via(path, &temp_path(path), write)
}

/// [`write_with`] through a temporary file of the caller's choosing (in `path`'s folder): a
/// fixed name for a file saved over and over, so that a save cut short by a kill leaves nothing
/// behind beyond the next save.
pub fn write_via<E>(
    path: &Path,
    tmp: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), AtomicError<E>> {
    let result = match write(tmp) {
        Err(e) => Err(AtomicError::Write(e)),
        Ok(()) => std::fs::OpenOptions::new()
            .write(true)
            .open(tmp)
            .and_then(|f| f.sync_all())
            .and_then(|()| std::fs::rename(tmp, path))
            .map_err(AtomicError::Commit),
    };
    if result.is_err() {
        let _ = std::fs::remove_file(tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically ([`write_with`]).
pub fn write_bytes(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_with(path, |tmp| {
        let mut f = std::fs::File::create(tmp)?;
        f.write_all(bytes)
    })
    .map_err(AtomicError::into_io)
}

/// Writes `bytes` atomically unless `path` already holds exactly these bytes (reruns leave the
/// file and its times alone). Returns whether it wrote.
pub fn write_if_changed(path: &Path, bytes: &[u8]) -> std::io::Result<bool> {
    if std::fs::read(path).is_ok_and(|existing| existing == bytes) {
        return Ok(false);
    }
    write_bytes(path, bytes)?;
    Ok(true)
}

/// Removes the leftover temporary files of [`temp_path`] made on this host by processes that
/// are no longer running, recursively under `dir`. Temporary files of other hosts are left
/// alone: their writers may still be alive. Returns how many were removed.
pub fn remove_stale_temps(dir: &Path) -> usize {
    let host = host_tag();
    let mut removed = 0;
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if path.is_dir() {
            removed += remove_stale_temps(&path);
            continue;
        }
        let Some((_, tail)) = name.split_once(".tmp-") else {
            continue;
        };
        let mut fields = tail.splitn(3, '-');
        let pid = fields.next().and_then(|p| p.parse::<u32>().ok());
        let _counter = fields.next();
        let tag_ok = fields.next().is_some_and(|t| t.starts_with(&host));
        let alive = pid.is_some_and(|p| Path::new(&format!("/proc/{p}")).exists());
        if name.starts_with('.') && tag_ok && !alive && std::fs::remove_file(&path).is_ok() {
            removed += 1;
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("fileio-atomic-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn replaces_the_file_and_leaves_no_temp() {
        let dir = temp_dir("replace");
        let path = dir.join("file.bin");
        write_bytes(&path, b"one").unwrap();
        assert!(write_if_changed(&path, b"two").unwrap());
        assert!(!write_if_changed(&path, b"two").unwrap());
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        assert_eq!(names(&dir), ["file.bin"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_removes_the_temp() {
        let dir = temp_dir("fail");
        let path = dir.join("file.txt");
        write_bytes(&path, b"old").unwrap();
        let result = write_with(&path, |tmp| {
            std::fs::write(tmp, b"half")?;
            Err::<(), _>(std::io::Error::other("encoder failed"))
        });
        assert!(matches!(result, Err(AtomicError::Write(_))));
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(names(&dir), ["file.txt"]);
        // A writer that never created the temporary file cannot be committed.
        let result = write_with(&path, |_| Ok::<(), std::io::Error>(()));
        assert!(matches!(result, Err(AtomicError::Commit(_))));
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn temp_names_keep_the_extension_and_stale_ones_are_cleared() {
        let dir = temp_dir("stale");
        let path = dir.join("img.png");
        let a = temp_path(&path);
        let b = temp_path(&path);
        assert_ne!(a, b);
        let name = a.file_name().unwrap().to_string_lossy().into_owned();
        assert!(
            name.starts_with(".img.png.tmp-") && name.ends_with(".png"),
            "{name}"
        );
        // A leftover of a live process (this one) stays; one of a dead process goes; one of
        // another host stays.
        std::fs::write(&a, b"x").unwrap();
        let dead = dir.join(format!(".img.png.tmp-{}-0-{}.png", u32::MAX, host_tag()));
        std::fs::write(&dead, b"x").unwrap();
        let other = dir.join(format!(
            ".img.png.tmp-{}-0-{}.png",
            u32::MAX,
            "0".repeat(16)
        ));
        std::fs::write(&other, b"x").unwrap();
        assert_eq!(remove_stale_temps(&dir), 1);
        assert!(a.exists() && !dead.exists() && other.exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
