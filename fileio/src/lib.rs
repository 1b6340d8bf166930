//! The file jobs every crate of the toolkit shares, each written once: atomic writes
//! ([`atomic`]: a temporary file next to the target, flushed to disk, renamed over it — a reader
//! or a killed job never sees half a file) and the image encodings ([`srgb`]: the transfer curve
//! and its 8-bit quantisation; [`png`]: 8-bit RGB PNG; [`exr`]: float32 OpenEXR of named
//! channels, which bundles, references and the renderer's images are).

pub mod atomic;
pub mod exr;
pub mod png;
pub mod srgb;
