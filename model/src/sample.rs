//! One network input with its target: a bundle packed into features and colour planes
//! ([`crate::features::pack`]) next to its reference, loaded from files and screened, so a
//! broken bundle or reference becomes a [`BadSample`] naming the file instead of a panic.

use std::path::{Path, PathBuf};

use crate::features::{pack_with, planar_reference, PackedImage, Packing};

/// A sample that was screened out, with the file and the reason.
#[derive(Clone, Debug, PartialEq)]
pub struct BadSample {
    /// The offending file (bundle or reference).
    pub file: PathBuf,
    /// What is wrong with it.
    pub reason: String,
}

/// A loaded image: network input, raw colours and the planar reference.
#[derive(Clone, Debug)]
pub struct Sample {
    /// Features and raw levels.
    pub packed: PackedImage,
    /// Planar RGB reference.
    pub reference: Vec<f32>,
}

/// Loads and checks one bundle and its reference, packed as a network's `packing` says.
pub fn load_sample(
    bundle_path: &Path,
    reference_path: &Path,
    packing: &Packing,
) -> Result<Sample, BadSample> {
    let bad = |file: &Path, reason: String| BadSample {
        file: file.to_owned(),
        reason,
    };
    if !reference_path.exists() {
        return Err(bad(reference_path, "missing reference".into()));
    }
    let bundle = bundle::read_bundle(bundle_path).map_err(|e| bad(bundle_path, e.to_string()))?;
    let packed = pack_with(&bundle, packing).map_err(|e| bad(bundle_path, e.to_string()))?;
    let reference = bundle::read_rgb_exr_image(reference_path)
        .map_err(|e| bad(reference_path, e.to_string()))?;
    let reference = planar_reference(&reference, packed.width, packed.height)
        .map_err(|e| bad(reference_path, e.to_string()))?;
    Ok(Sample { packed, reference })
}
