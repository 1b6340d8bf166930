//! Locating the workspace's binaries from an end-to-end test (they live next to the test's
//! `deps/` directory in the Cargo target directory).

use std::path::PathBuf;

/// Path of workspace binary `name` in the target directory of the running test.
///
/// Panics with instructions when it is missing: the binaries are built by
/// `cargo test --workspace`, not by `cargo test -p e2e` alone.
pub fn workspace_bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("test executable lives in <target>/<profile>/deps");
    let path = profile_dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    assert!(
        path.exists(),
        "{} not found: run the end-to-end tests with `cargo test --workspace` (it builds the \
         datagen, train and infer binaries)",
        path.display()
    );
    path
}

/// The workspace root (the parent of this crate's directory).
///
/// Read at run time first: a target dir shared between checkouts (the CI cache) can hold a
/// binary compiled in another checkout, whose compile-time path would point there.
pub fn workspace_root() -> PathBuf {
    PathBuf::from(
        std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_else(|| env!("CARGO_MANIFEST_DIR").into()),
    )
    .parent()
    .expect("crate inside the workspace")
    .to_owned()
}
