//! The allocator setting of the binaries that reconstruct (`infer`, `bench_infer`, `evaluate`):
//! freed memory stays with the process for the next allocation instead of going back to the
//! kernel.
//!
//! Why: a reconstruction's buffers are tens to hundreds of MB (a 1280×720 bundle's features
//! alone are 100 MB), above glibc's threshold for serving an allocation from its own `mmap`
//! and returning it with `munmap` when freed. The next buffer is then mapped afresh and the
//! kernel zeroes it page by page on first touch: ≈ 90 000 page faults, ≈ 10 % of the CPU time
//! of each 1280×720 reconstruction after the first in one process (docs/performance.md,
//! "Next to Open Image Denoise"). Served from the heap and kept there when freed, the pages
//! stay mapped and are reused. One heap for all threads: the work runs on rayon's threads, and
//! glibc gives other threads heaps of at most 64 MiB, mapping anything larger on its own
//! whatever the threshold. The process's resident memory then stays at its peak until it
//! exits, which suits these short-lived commands and `evaluate`'s run of similar bundles.

/// Allocations up to this size come from glibc's heap (kept when freed); larger ones are
/// still mapped on their own.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const HEAP_UP_TO: libc::c_int = 1 << 30;

/// Makes glibc's allocator serve allocations up to 1 GiB from one heap for all threads and
/// keep up to 2 GiB of free space at the heap's top instead of handing it back to the kernel.
/// Call once, first thing in `main`.
/// Elsewhere than Linux with glibc it does nothing (the platform allocator keeps its policy).
pub fn retain_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: `mallopt` only changes allocator parameters, all three documented for these
        // values (mallopt(3)); it takes no pointers. A refusal (return 0) leaves the default
        // policy, which is correct, only slower.
        unsafe {
            libc::mallopt(libc::M_ARENA_MAX, 1);
            libc::mallopt(libc::M_MMAP_THRESHOLD, HEAP_UP_TO);
            libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX);
        }
    }
}
