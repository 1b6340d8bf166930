//! Memory checks for renders whose size the user picks (resolution, photons per pass): the
//! memory a run needs is compared with what the machine has before it is allocated, so an
//! impossible request ends with an error saying how much was asked for, instead of an abort
//! on a failed allocation or the kernel's out-of-memory kill.

use anyhow::{bail, Result};

/// Memory the system can still give (Linux: `MemAvailable` + `SwapFree` of /proc/meminfo),
/// in bytes; `None` where that is not known.
pub fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let field = |name: &str| -> Option<u64> {
        let line = text.lines().find(|l| l.starts_with(name))?;
        let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kib * 1024)
    };
    Some(field("MemAvailable:")? + field("SwapFree:").unwrap_or(0))
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
        assert_eq!(format_bytes(3 << 30), "3.00 GB");
        assert_eq!(format_bytes(5 << 20), "5.0 MB");
    }
}
