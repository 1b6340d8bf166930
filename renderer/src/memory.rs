//! Memory checks for renders whose size the user picks (resolution, photons per pass): the
//! memory a run needs is compared with what the machine has before it is allocated, so an
//! impossible request ends with an error saying how much was asked for, instead of an abort
//! on a failed allocation or the kernel's out-of-memory kill.

use anyhow::{bail, Result};

/// Memory this process can still get, in bytes: what the system can still give (Linux:
/// `MemAvailable` + `SwapFree` of /proc/meminfo), less where the process's own limits are
/// lower — its address-space limit (`ulimit -v`, less the address space it already uses) and
/// its cgroup's memory limit (a container's, less what the group already uses); `None` where
/// none of these is known.
pub fn available_bytes() -> Option<u64> {
    let system = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| {
            let free = kib_field(&text, "MemAvailable:")?;
            Some(free + kib_field(&text, "SwapFree:").unwrap_or(0))
        });
    [system, address_space_left(), cgroup_left()]
        .into_iter()
        .flatten()
        .min()
}

/// The value of a `Name:   123 kB` line of a /proc file, in bytes.
fn kib_field(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Address space left under the process's `RLIMIT_AS` (`ulimit -v`); `None` when unlimited
/// or unknown.
fn address_space_left() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    address_space_left_in(&limits, &status)
}

/// The soft "Max address space" of a /proc/<pid>/limits text less the `VmSize` of a
/// /proc/<pid>/status text.
fn address_space_left_in(limits: &str, status: &str) -> Option<u64> {
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max address space"))?;
    let soft: u64 = line
        .trim_start_matches("Max address space")
        .split_whitespace()
        .next()?
        .parse()
        .ok()?;
    Some(soft.saturating_sub(kib_field(status, "VmSize:")?))
}

/// Memory left under the cgroup (v2) limit of the process: `memory.max` less `memory.current`
/// of its group; `None` when the group has no limit or is not known.
fn cgroup_left() -> Option<u64> {
    let cgroup = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    // v2: one line "0::/path".
    let path = cgroup.lines().find_map(|l| l.strip_prefix("0::"))?;
    let dir = std::path::Path::new("/sys/fs/cgroup").join(path.trim_start_matches('/'));
    let read = |name: &str| -> Option<u64> {
        std::fs::read_to_string(dir.join(name))
            .ok()?
            .trim()
            .parse()
            .ok()
    };
    // "max" (no limit) does not parse.
    let max = read("memory.max")?;
    Some(max.saturating_sub(read("memory.current").unwrap_or(0)))
}

/// `bytes` in human units (GB with two decimals, MB below 1 GB).
pub fn format_bytes(bytes: u64) -> String {
    if bytes >= 1 << 30 {
        format!("{:.2} GB", bytes as f64 / (1u64 << 30) as f64)
    } else {
        format!("{:.1} MB", bytes as f64 / (1u64 << 20) as f64)
    }
}

/// An error when `bytes` (what `what` needs) exceed the memory the system can give.
pub fn check_fits(what: &str, bytes: u64) -> Result<()> {
    if let Some(available) = available_bytes() {
        if bytes > available {
            bail!(
                "{what} needs {} of memory, but only {} is available",
                format_bytes(bytes),
                format_bytes(available)
            );
        }
    }
    Ok(())
}

/// A vector of `n` copies of `value`, or an error naming `what` and the size when it cannot be
/// allocated.
pub fn try_filled_vec<T: Clone>(n: usize, value: T, what: &str) -> Result<Vec<T>> {
    let bytes = (n as u64).saturating_mul(std::mem::size_of::<T>() as u64);
    check_fits(what, bytes)?;
    let mut v = Vec::new();
    if v.try_reserve_exact(n).is_err() {
        bail!(
            "{what} needs {} of memory, which could not be allocated",
            format_bytes(bytes)
        );
    }
    v.resize(n, value);
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn impossible_requests_are_errors_naming_the_size() {
        let e = try_filled_vec(usize::MAX / 64, 0u64, "a test buffer")
            .unwrap_err()
            .to_string();
        assert!(e.contains("a test buffer needs") && e.contains("GB"), "{e}");
        assert_eq!(try_filled_vec(3, 7u8, "small").unwrap(), vec![7, 7, 7]);
        if let Some(a) = available_bytes() {
            assert!(a > 0);
            assert!(check_fits("twice what there is", a.saturating_mul(2)).is_err());
            assert!(check_fits("one byte", 1).is_ok());
        }
        // `ulimit -v`: the limit less the address space in use; none without a limit.
        let status = "Name:\tx\nVmPeak:\t  9000 kB\nVmSize:\t  4096 kB\n";
        let limited = "Limit Soft Limit Hard Limit Units\n\
            Max address space         6291456000           6291456000           bytes     \n";
        assert_eq!(
            address_space_left_in(limited, status),
            Some(6_291_456_000 - 4096 * 1024)
        );
        let unlimited =
            "Max address space         unlimited            unlimited            bytes\n";
        assert_eq!(address_space_left_in(unlimited, status), None);
        assert_eq!(format_bytes(3 << 30), "3.00 GB");
        assert_eq!(format_bytes(5 << 20), "5.0 MB");
    }
}
