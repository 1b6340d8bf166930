//! The worker-thread pool of a render (and of every other parallel job of the toolkit): one
//! rayon pool of the asked size, so a command's `--threads` means the same everywhere. Outputs
//! never depend on the count.

/// The most worker threads a render may ask for: far above any machine's cores, and low enough
/// that a mistyped count (`--threads 20000`) is refused at once instead of spending seconds
/// starting thousands of threads (outputs do not depend on the count).
pub const MAX_THREADS: usize = 1024;

/// Runs `f(pool)` inside a rayon pool with `threads` workers (0 = rayon's default: all cores).
pub fn with_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> anyhow::Result<R> {
    anyhow::ensure!(
        threads <= MAX_THREADS,
        "--threads {threads}: at most {MAX_THREADS} worker threads are supported"
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    Ok(pool.install(f))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_thread_counts_are_refused() {
        assert_eq!(with_threads(2, || 7).unwrap(), 7);
        let err = with_threads(MAX_THREADS + 1, || ())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("--threads 1025") && err.contains("1024"),
            "{err}"
        );
    }
}
