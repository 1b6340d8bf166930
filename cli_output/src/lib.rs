//! What every binary of the toolkit does when its standard output or standard error cannot be
//! written (a reader that closed the pipe, `> /dev/full`): Rust's `println!` and `eprintln!`
//! panic then (exit code 101 and a backtrace hint). [`install`] turns exactly those panics into
//! an ordinary end: a closed pipe (`datagen check | head -1`) ends the process silently with
//! status 141, as the default SIGPIPE action does for other Unix tools; any other write error
//! (a full disk) prints one line and exits with 1, like every other error of the tools. Every
//! other panic keeps Rust's default report. [`paths`] holds the checks of the output files a
//! command line names.

pub mod paths;

use std::io::Write;

/// The start of the panic message of a failed `print!`/`println!`/`eprint!`/`eprintln!`.
const PRINT_FAILURE: &str = "failed printing to std";

/// Whether a panic message is that of a failed print to standard output or error.
pub fn is_print_failure(message: &str) -> bool {
    message.starts_with(PRINT_FAILURE)
}

/// Exit status after a closed pipe: 128 + SIGPIPE, what a shell reports for a tool the signal
/// ended.
pub const BROKEN_PIPE_STATUS: i32 = 141;

/// Whether a failed print's message is that of a closed pipe (EPIPE).
pub fn is_broken_pipe(message: &str) -> bool {
    message.contains("Broken pipe") || message.contains("os error 32")
}

/// Installs the panic hook described in the crate docs. Call first thing in `main`.
pub fn install() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if is_print_failure(message) {
            if is_broken_pipe(message) {
                // The reader has what it wanted (`| head`): nothing to report.
                std::process::exit(BROKEN_PIPE_STATUS);
            }
            // Standard error may be the stream that failed: the message is best effort.
            let _ = writeln!(std::io::stderr(), "error: {message}");
            std::process::exit(1);
        }
        default(info);
    }));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The messages std gives a failed print are recognised; other panics are not.
    #[test]
    fn recognises_print_failures_only() {
        assert!(is_print_failure(
            "failed printing to stdout: Broken pipe (os error 32)"
        ));
        assert!(is_print_failure(
            "failed printing to stderr: No space left on device (os error 28)"
        ));
        assert!(!is_print_failure("index out of bounds"));
        assert!(!is_print_failure(""));
        assert!(is_broken_pipe(
            "failed printing to stdout: Broken pipe (os error 32)"
        ));
        assert!(!is_broken_pipe(
            "failed printing to stdout: No space left on device (os error 28)"
        ));
    }
}
