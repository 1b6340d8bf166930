//! A trained model directory as written by `train`: `model.json` (architecture) and
//! `model.bpk` (weights), optionally `metrics.csv` and the training config. Read by `infer`
//! and `evaluate`, and by `train` when it fine-tunes (`init`).

use std::path::{Path, PathBuf};

use crate::weights::load_burnpack;
use crate::{ModelConfig, Network};
use burn::tensor::Device;

/// Architecture file inside a model directory.
pub const CONFIG_FILE: &str = "model.json";
/// Weights file inside a model directory (Burn's burnpack format).
pub const WEIGHTS_FILE: &str = "model.bpk";

/// Why a model directory cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ModelDirError {
    /// A file is missing or unreadable.
    #[error("{path}: {reason}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        reason: String,
    },
    /// `model.json` is not a valid architecture.
    #[error("{path}: {reason}")]
    Config {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The weights do not load into the architecture.
    #[error("{0}")]
    Weights(String),
}

/// A network with its architecture, ready to run.
pub struct TrainedModel {
    /// The directory it was loaded from.
    pub dir: PathBuf,
    /// Architecture (window size, preset, …).
    pub config: ModelConfig,
    /// The network on the inference device.
    pub network: Network,
}

impl TrainedModel {
    /// Loads `dir/model.json` and `dir/model.bpk` onto `device`.
    pub fn open(dir: &Path, device: &Device) -> Result<Self, ModelDirError> {
        let config_path = dir.join(CONFIG_FILE);
        let text = std::fs::read_to_string(&config_path).map_err(|e| ModelDirError::Io {
            path: config_path.clone(),
            reason: e.to_string(),
        })?;
        let config: ModelConfig =
            serde_json::from_str(&text).map_err(|e| ModelDirError::Config {
                path: config_path.clone(),
                reason: e.to_string(),
            })?;
        config.validate().map_err(|reason| ModelDirError::Config {
            path: config_path.clone(),
            reason,
        })?;
        let network = load_burnpack(&config, &dir.join(WEIGHTS_FILE), device)
            .map_err(ModelDirError::Weights)?;
        Ok(Self {
            dir: dir.to_owned(),
            config,
            network,
        })
    }
}
