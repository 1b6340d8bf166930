//! The training TOML: backend, dataset, preset, patching, optimisation and output settings.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use model::training::TrainSettings;
use model::{ModelConfig, Preset, Weighting};
use serde::Deserialize;

pub use model::backend::Backend;

fn default_split_train() -> String {
    "train".into()
}
fn default_split_val() -> String {
    "val".into()
}
fn default_lr() -> f64 {
    1e-4
}
fn default_cache() -> usize {
    8
}

/// `configs/train/<name>.toml`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// `flex` (default), `ndarray` or `wgpu`.
    #[serde(default)]
    pub backend: Backend,
    /// Dataset directory holding `manifest.json`.
    pub dataset: PathBuf,
    /// Split trained on.
    #[serde(default = "default_split_train")]
    pub train_split: String,
    /// Split validated on after every epoch.
    #[serde(default = "default_split_val")]
    pub val_split: String,
    /// Network preset: `paper`, `small` or `tiny`.
    pub preset: Preset,
    /// Weight transform: `relu` (paper) or `softmax`.
    #[serde(default)]
    pub weighting: Option<Weighting>,
    /// Patch side in pixels.
    pub patch: usize,
    /// Patch stride in pixels.
    pub stride: usize,
    /// Patches per batch.
    pub batch: usize,
    /// Total epochs.
    pub epochs: usize,
    /// Adam learning rate.
    #[serde(default = "default_lr")]
    pub lr: f64,
    /// Seed of the weights and the patch order.
    pub seed: u64,
    /// Images held in memory at once.
    #[serde(default = "default_cache")]
    pub cache_images: usize,
    /// Output directory (weights, checkpoint, metrics).
    pub output: PathBuf,
}

impl TrainConfig {
    /// Reads and checks a config file.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
        let cfg: TrainConfig =
            toml::from_str(&text).with_context(|| format!("{}", path.display()))?;
        if cfg.patch == 0 || cfg.stride == 0 || cfg.batch == 0 || cfg.epochs == 0 {
            bail!(
                "{}: patch, stride, batch and epochs must be positive",
                path.display()
            );
        }
        if !(cfg.lr > 0.0 && cfg.lr.is_finite()) {
            bail!("{}: lr must be a positive number", path.display());
        }
        cfg.model_config()
            .validate()
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Ok(cfg)
    }

    /// The network architecture.
    pub fn model_config(&self) -> ModelConfig {
        let mut c = ModelConfig::preset(self.preset);
        if let Some(w) = self.weighting {
            c.weighting = w;
        }
        c
    }

    /// The optimisation settings.
    pub fn settings(&self) -> TrainSettings {
        TrainSettings {
            batch: self.batch,
            epochs: self.epochs,
            lr: self.lr,
            seed: self.seed,
        }
    }
}
