//! File-system helpers for kill-safe dataset jobs: atomic writes (unique temp file, fsync,
//! rename) and SHA-256 checksums.

use sha2::{Digest, Sha256};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Distinguishes temp files of concurrent writers inside one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// A short tag of this machine (hash of its host name), so a shared directory can tell whose
/// leftover temp files it may clean: process ids are only meaningful on their own host.
pub fn host_tag() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .unwrap_or_default();
    format!("{:016x}", crate::rng::hash_str(host.trim()))
}

/// A temp-file path next to `path`, unique per host, process and call:
/// `.<name>.tmp-<pid>-<counter>-<host tag>`. Leftovers of killed runs are recognisable.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let k = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(
        ".{name}.tmp-{}-{k}-{}",
        std::process::id(),
        host_tag()
    ))
}

/// Writes `bytes` to `path` atomically: readers see the old file or the whole new one, never
/// a part. Parent directories are created.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent)?;
    }
    let tmp = temp_path(path);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` atomically unless `path` already holds exactly these bytes (idempotent
/// reruns leave file times alone). Returns whether it wrote.
pub fn write_if_changed(path: &Path, bytes: &[u8]) -> std::io::Result<bool> {
    if let Ok(existing) = std::fs::read(path) {
        if existing == bytes {
            return Ok(false);
        }
    }
    write_atomic(path, bytes)?;
    Ok(true)
}

/// Lower-case hex SHA-256 of a byte slice.
pub fn sha256_bytes(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// Lower-case hex SHA-256 of a file's contents.
pub fn sha256_file(path: &Path) -> std::io::Result<String> {
    let mut f = std::fs::File::open(path)?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hex(&hasher.finalize()))
}

/// Hex encoding.
fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Removes leftover temp files of [`temp_path`] made on this host by processes that are no
/// longer running, recursively under `dir` (temp files of other hosts are left alone: their
/// writers may still be alive). Returns how many were removed.
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

/// Removes `path`; a file that is already gone is fine, any other failure is an error naming it.
pub fn remove_if_present(path: &Path) -> anyhow::Result<()> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            Err(anyhow::Error::new(e).context(format!("removing {}", path.display())))
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_of_known_string() {
        assert_eq!(
            sha256_bytes(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp() {
        let dir = std::env::temp_dir().join(format!("datagen-fsutil-{}", std::process::id()));
        let path = dir.join("sub/file.bin");
        write_atomic(&path, b"one").unwrap();
        assert!(write_if_changed(&path, b"two").unwrap());
        assert!(!write_if_changed(&path, b"two").unwrap());
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        assert_eq!(sha256_file(&path).unwrap(), sha256_bytes(b"two"));
        let names: Vec<_> = std::fs::read_dir(dir.join("sub"))
            .unwrap()
            .flatten()
            .collect();
        assert_eq!(names.len(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
