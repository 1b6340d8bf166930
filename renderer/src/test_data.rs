//! Test-only: reads the data files of `renderer/tests/data/` (values computed by Mitsuba
//! itself, written by the generator scripts there) for the unit tests that compare against
//! them.

use serde::de::DeserializeOwned;
use std::path::PathBuf;

/// The JSON file `name` of `renderer/tests/data/`, parsed. Its numbers are f32 values written
/// exactly (as the shortest decimal of their f64 value), so they read back bit for bit.
pub(crate) fn read_json<T: DeserializeOwned>(name: &str) -> T {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("cannot parse {}: {e}", path.display()))
}
