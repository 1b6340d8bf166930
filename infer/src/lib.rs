//! Post-reconstruction (docs/method.md, "Inference"): a trained model applied to a bundle in
//! tiles whose halo covers the receptive field ([`tiling`], on the native CPU engine or Burn),
//! error reports against a reference ([`report`]) and PNG previews ([`preview`]). The `infer`
//! binary also renders the bundle first when given a scene (`--scene`). [`memory`] keeps freed
//! buffers for the next reconstruction in one process.

pub mod memory;
pub mod oidn;
pub mod preview;
pub mod report;
pub mod tiling;

pub use report::ErrorReport;
pub use tiling::{reconstruct_tiled, Engine, Inference, Reconstruction};
