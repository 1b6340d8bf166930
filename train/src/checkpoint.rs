//! Checkpoints of a training run: the weights, the optimizer state and `state.json` (the
//! architecture, the settings, the epochs done and their reports), each written atomically,
//! `state.json` last — a checkpoint is complete once it names its epoch —; resuming restores
//! all of it, so a resumed run continues bit-identically. Also the final weights of a run.

use std::path::Path;

use burn::module::Module;
use burn::tensor::Device;
use model::network::ModelConfig;
use model::weights::{load_burnpack, save_burnpack, save_optimizer, save_safetensors};
use serde::{Deserialize, Serialize};

use crate::training::{adam, settings_differences, EpochReport, TrainSettings, Trainer};

/// Training state that is checkpointed besides the weights and the optimizer.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct CheckpointState {
    model: ModelConfig,
    settings: TrainSettings,
    epochs_done: usize,
    history: Vec<EpochReport>,
}

/// Writes `text` to `path` atomically, the error naming the file.
fn write_text(path: &Path, text: &str) -> Result<(), String> {
    fileio::atomic::write_bytes(path, text.as_bytes())
        .map_err(|e| format!("{}: {e}", path.display()))
}

impl Trainer {
    /// Writes `model.bpk`, `optimizer.bpk` and `state.json` into `dir` (each atomically;
    /// `state.json` last, so a checkpoint is complete once it names the epoch).
    pub fn save_checkpoint(&self, dir: &Path) -> Result<(), String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        save_burnpack(&self.model, &dir.join("model.bpk"))?;
        save_optimizer(&self.optim, &dir.join("optimizer.bpk"))?;
        let state = CheckpointState {
            model: self.config.clone(),
            settings: self.settings.clone(),
            epochs_done: self.epochs_done,
            history: self.history.clone(),
        };
        let json = serde_json::to_string_pretty(&state).expect("state serialises");
        write_text(&dir.join("state.json"), &json)
    }

    /// Restores a run from a checkpoint directory; `settings` may raise the epoch count (not
    /// with a decaying learning rate, whose schedule spans the epochs) but must otherwise match
    /// the checkpoint's.
    pub fn resume(dir: &Path, settings: TrainSettings, device: &Device) -> Result<Self, String> {
        let state_path = dir.join("state.json");
        let text = std::fs::read_to_string(&state_path)
            .map_err(|e| format!("{}: {e}", state_path.display()))?;
        let state: CheckpointState =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", state_path.display()))?;
        let differences = settings_differences(&state.settings, &settings);
        if !differences.is_empty() {
            return Err(format!(
                "{}: checkpoint settings differ from the config: {}",
                state_path.display(),
                differences.join("; ")
            ));
        }
        let device = device.clone().autodiff();
        let model = load_burnpack(&state.model, &dir.join("model.bpk"), &device)?;
        let optim_path = dir.join("optimizer.bpk");
        let optim = adam()
            .load(&optim_path)
            .map_err(|e| format!("{}: {e:?}", optim_path.display()))?;
        Ok(Self {
            model,
            optim,
            config: state.model,
            settings,
            epochs_done: state.epochs_done,
            history: state.history,
            device,
        })
    }

    /// Writes the final weights (`model.bpk`, `model.safetensors`) and `model.json` (the
    /// architecture) into `dir`.
    pub fn save_final(&self, dir: &Path) -> Result<(), String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let valid = self.model.valid();
        save_burnpack(&valid, &dir.join("model.bpk"))?;
        save_safetensors(&valid, &dir.join("model.safetensors"))?;
        let json = serde_json::to_string_pretty(&self.config).expect("config serialises");
        write_text(&dir.join("model.json"), &json)
    }
}
