//! Burn side of the toolkit (SPEC §4): the kernel-predicting network, the multi-level
//! combination (paper Eq. 6), the loss (Eq. 8), relMSE, feature packing, patch data and the
//! training loop used by the `train` binary.

pub mod backend;
pub mod combine;
pub mod data;
pub mod features;
pub mod loss;
pub mod metrics;
pub mod model;
pub mod model_dir;
pub mod synthetic;
pub mod training;

pub use combine::{combine, level_weight_shares};
pub use loss::relative_log_l1;
pub use metrics::{relmse, relmse_planar};
pub use model::{ModelConfig, Network, Preset, Weighting, NEW_WINDOW_ENTRY};
