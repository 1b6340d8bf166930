//! `bench_infer`'s command line through the real binary: `--extra-features` times every
//! network a second time reading the extra planes (a trained model widened with zero weights for
//! them, as `train` starts it with `init`), and an unknown or repeated feature is refused by name.

use std::process::Output;

fn bench(args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_bench_infer"))
        .args(args)
        .output()
        .expect("running bench_infer")
}

/// Shipped weights that read the paper's 27 planes only (the U-Net before `models/default`).
const WITHOUT_PLANES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/unet-es2");
/// The shipped default, which already reads both extra planes.
const DEFAULT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/default");

#[test]
fn extra_features_time_each_network_also_with_the_planes() {
    let out = bench(&[
        "--model",
        WITHOUT_PLANES,
        "--preset",
        "tiny",
        "--extra-features",
        "disagreement,passes",
        "--size",
        "24",
        "--height",
        "16",
        "--repeats",
        "1",
        "--engine",
        "native",
        "--peer",
        "none",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // That model reads no extra plane; widened it reads four disagreement planes (one per
    // correlated level) and the pass count.
    assert!(
        stdout.contains("0 extra plane(s) packed in the time"),
        "{stdout}"
    );
    assert!(
        stdout.contains("+ [Disagreement, Passes] (UNet preset)")
            && stdout.contains("5 extra plane(s) packed in the time"),
        "{stdout}"
    );
    assert!(
        stdout.contains("Tiny + [Disagreement, Passes] (Tiny preset)"),
        "{stdout}"
    );
    // Four networks timed: two as given, two widened.
    assert_eq!(stdout.matches("Native engine (infer, tiled)").count(), 4);
}

/// Runs bench_infer on an 8-pixel image with `network` (e.g. `--preset tiny`) widened by
/// `extra` and asserts it fails with `message` on stderr, without a panic.
fn refused(network: [&str; 2], extra: &str, message: &str) {
    let mut args = network.to_vec();
    args.extend(["--extra-features", extra, "--size", "8", "--peer", "none"]);
    let out = bench(&args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains(message), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn an_unknown_extra_feature_is_named() {
    refused(
        ["--preset", "tiny"],
        "disagreement,pass",
        "unknown extra feature `pass`",
    );
}

#[test]
fn a_feature_listed_twice_is_refused() {
    refused(
        ["--model", WITHOUT_PLANES],
        "passes,passes",
        "extra_features lists Passes twice",
    );
    // A model that already reads a plane cannot be widened by it again.
    refused(
        ["--model", DEFAULT],
        "passes",
        "models/default already reads the Passes planes",
    );
}
