//! The network library (docs/method.md, "The network"): the kernel-predicting combiner
//! ([`network`]; its multi-scale layout in [`unet`]), the multi-level combination of paper
//! Eq. 6 ([`combine`]), its loss and metrics, the input features of a bundle ([`features`],
//! [`sample`]), weight files ([`weights`]), a trained-model folder ([`model_dir`]) and the
//! native CPU engine ([`native`]), a second implementation of the network's forward pass. Data loading and the training loop belong to
//! the `train` crate, reconstruction of images to `infer`.

pub mod backend;
pub mod combine;
pub mod features;
pub mod loss;
pub mod metrics;
pub mod model_dir;
pub mod native;
pub mod network;
pub mod sample;
pub mod screen_filter;
pub mod synthetic;
pub mod unet;
pub mod weights;

pub use combine::{combine, level_weight_shares};
pub use loss::relative_log_l1;
pub use metrics::{relmse, relmse_planar};
pub use network::{ModelConfig, Network, Preset, Weighting, NEW_WINDOW_ENTRY};
