//! Post-reconstruction (SPEC §6): trained model directories, tiled inference with a halo that
//! covers the receptive field, error reports against a reference, and PNG previews.

pub mod evaluate;
pub mod model_dir;
pub mod native;
pub mod preview;
pub mod report;
pub mod tiling;

pub use model_dir::TrainedModel;
pub use report::ErrorReport;
pub use tiling::{reconstruct_tiled, Engine, Inference, Reconstruction};
