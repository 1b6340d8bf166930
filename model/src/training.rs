//! The training loop: Adam steps on patch batches, per-epoch validation against the best single
//! input level, checkpoints that resume exactly, and the saved weights.

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::store::{BurnpackStore, ModuleSnapshot, SafetensorsStore};
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::combine::combine;
use crate::data::{BadSample, Batch, PatchDataset};
use crate::loss::Loss;
use crate::metrics::relmse_sum_planar;
use crate::model::{ModelConfig, Network, LEVELS};
use crate::model_dir::TrainedModel;

/// Optimisation settings (the parts of the train TOML the loop needs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainSettings {
    /// Patches per batch.
    pub batch: usize,
    /// Epochs to run in total.
    pub epochs: usize,
    /// Adam learning rate (the first step's, with a decay).
    pub lr: f64,
    /// Learning rate of the last step of a cosine decay from `lr` over all steps of `epochs`;
    /// `None`: constant `lr`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lr_end: Option<f64>,
    /// Seed of the initial weights and of the patch order.
    pub seed: u64,
    /// The loss minimised (paper Eq. 8 unless set).
    #[serde(default, skip_serializing_if = "Loss::is_default")]
    pub loss: Loss,
}

/// What a checkpoint trained with `checkpoint` cannot continue as `config` says, one
/// `<key> <checkpoint's> (checkpoint) vs <config's> (config)` per differing key of the train
/// TOML (`batch`, `lr`, `lr_end`, `seed`, `loss`; `epochs` too under a decaying rate, whose
/// schedule spans them). Empty: the run resumes with `config` (which may add epochs).
pub fn settings_differences(checkpoint: &TrainSettings, config: &TrainSettings) -> Vec<String> {
    let mut out = Vec::new();
    let mut differ = |key: &str, was: String, now: String| {
        if was != now {
            out.push(format!("{key} {was} (checkpoint) vs {now} (config)"));
        }
    };
    differ(
        "batch",
        checkpoint.batch.to_string(),
        config.batch.to_string(),
    );
    differ("lr", checkpoint.lr.to_string(), config.lr.to_string());
    let lr_end = |e: Option<f64>| e.map_or_else(|| "absent".to_string(), |e| e.to_string());
    differ("lr_end", lr_end(checkpoint.lr_end), lr_end(config.lr_end));
    differ("seed", checkpoint.seed.to_string(), config.seed.to_string());
    differ("loss", toml_name(&checkpoint.loss), toml_name(&config.loss));
    if checkpoint.lr_end.is_some() && checkpoint.epochs != config.epochs {
        out.push(format!(
            "epochs {} (checkpoint) vs {} (config; fixed by lr_end, whose decay spans them)",
            checkpoint.epochs, config.epochs
        ));
    }
    out
}

/// How `value` is spelt in a TOML config (its serde name: `relative-log-l1`, not Debug's
/// `RelativeLogL1`).
pub fn toml_name<T: Serialize>(value: &T) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::String(s)) => s,
        Ok(other) => other.to_string(),
        Err(e) => format!("<{e}>"),
    }
}

impl TrainSettings {
    /// The learning rate of step `step` (0-based) of a run of `total_steps`: `lr`, or the cosine
    /// decay from `lr` (first step) to `lr_end` (last step).
    pub fn lr_at(&self, step: usize, total_steps: usize) -> f64 {
        match self.lr_end {
            None => self.lr,
            Some(end) => {
                let progress = if total_steps > 1 {
                    step.min(total_steps - 1) as f64 / (total_steps - 1) as f64
                } else {
                    0.0
                };
                end + 0.5 * (self.lr - end) * (1.0 + (std::f64::consts::PI * progress).cos())
            }
        }
    }
}

/// Validation result: relMSE of the output and of every input level on the same pixels.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Validation {
    /// relMSE of the reconstruction.
    pub output: f64,
    /// relMSE of ỹ, z̃1..z̃4.
    pub levels: [f64; LEVELS],
}

impl Validation {
    /// The best (lowest) single input level as (index, relMSE).
    pub fn best_level(&self) -> (usize, f64) {
        self.levels
            .iter()
            .copied()
            .enumerate()
            .fold(
                (0, f64::INFINITY),
                |best, (i, v)| if v < best.1 { (i, v) } else { best },
            )
    }
}

/// One row of `metrics.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpochReport {
    /// 1-based epoch number.
    pub epoch: usize,
    /// Mean training loss over the epoch's batches.
    pub train_loss: f64,
    /// Validation result, if a validation split exists.
    pub validation: Option<Validation>,
    /// Patches trained on.
    pub patches: usize,
    /// Wall-clock seconds of the epoch (training and validation).
    pub seconds: f64,
}

/// Progress of one batch, for progress bars.
#[derive(Clone, Copy, Debug)]
pub struct BatchProgress {
    /// Patches done in this epoch.
    pub done: usize,
    /// Patches in this epoch.
    pub total: usize,
    /// Loss of this batch.
    pub loss: f64,
}

/// Training state that is checkpointed besides the weights and the optimizer.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct CheckpointState {
    model: ModelConfig,
    settings: TrainSettings,
    epochs_done: usize,
    history: Vec<EpochReport>,
}

/// Adam with the paper's learning rate handled by the caller and ε = 1e-8 (Burn's default
/// is 1e-5).
pub fn adam() -> ModuleOptimizer {
    AdamConfig::new().with_epsilon(1e-8).init()
}

/// Forward pass of network + combination: `[B, 3, P, P]` reconstruction of a batch, clamped
/// at zero.
///
/// Eq. 6 is a control-variate form (ỹ_i + z̃_c − z̃_i) and goes negative next to bright spots
/// that the smooth levels spread out; the loss (SPEC §4, Eq. 8) sees ŷ clamped ≥ 0, so the
/// clamped image is what the network was trained to produce — and radiance is never negative.
pub fn reconstruct(
    model: &Network,
    config: &ModelConfig,
    features: Tensor<4>,
    levels: Tensor<4>,
) -> Tensor<4> {
    combine(levels, model.weights(features), config.window).clamp_min(0.0)
}

/// One optimisation step minimising `loss`; returns the updated model and the batch loss.
pub fn train_step(
    model: Network,
    optim: &mut ModuleOptimizer,
    config: &ModelConfig,
    batch: Batch,
    lr: f64,
    loss: Loss,
) -> (Network, f64) {
    let prediction = reconstruct(&model, config, batch.features, batch.levels);
    let loss = loss.evaluate(prediction, batch.reference);
    let grads = loss.backward();
    let value: f32 = loss.into_scalar::<f32>();
    let grads = GradientsParams::from_grads(grads, &model);
    (optim.step(lr, model, grads), value as f64)
}

/// Validates `model` (a validation copy on a plain device) on non-overlapping patches of
/// `dataset`, pooling squared relative errors over all pixels. The dataset is set to feed the
/// levels of `config`; the input-level errors cover all five levels whatever the model combines.
pub fn validate(
    model: &Network,
    config: &ModelConfig,
    dataset: &mut PatchDataset,
    batch: usize,
    device: &Device,
) -> Result<Validation, BadSample> {
    let mut output = 0.0f64;
    let mut levels = [0.0f64; LEVELS];
    let mut count = 0usize;
    dataset.levels = config.levels.clone();
    let refs: Vec<_> = (0..dataset.images.len())
        .flat_map(|i| dataset.image_patches(i, dataset.patch))
        .collect();
    for chunk in refs.chunks(batch.max(1)) {
        let host = dataset.batch(chunk)?;
        let b = host.to_device(device);
        let prediction = reconstruct(model, config, b.features, b.levels);
        let prediction = prediction
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 output");
        let p2 = host.size * host.size;
        for k in 0..host.len {
            let reference = &host.reference[k * 3 * p2..(k + 1) * 3 * p2];
            output += relmse_sum_planar(&prediction[k * 3 * p2..(k + 1) * 3 * p2], reference);
            let patch_levels = &host.levels[k * 3 * LEVELS * p2..(k + 1) * 3 * LEVELS * p2];
            for (l, sum) in levels.iter_mut().enumerate() {
                *sum += relmse_sum_planar(&patch_levels[l * 3 * p2..(l + 1) * 3 * p2], reference);
            }
            count += 3 * p2;
        }
    }
    let n = count.max(1) as f64;
    Ok(Validation {
        output: output / n,
        levels: levels.map(|s| s / n),
    })
}

/// Saves a module as burnpack, atomically (temp file + rename).
pub fn save_burnpack(model: &Network, path: &Path) -> Result<(), String> {
    let tmp = temp_path(path);
    let mut store = BurnpackStore::from_file(&tmp)
        .auto_extension(false)
        .overwrite(true);
    model
        .save_into(&mut store)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display()))
}

/// Saves a module as safetensors, atomically, with its header in a canonical order.
pub fn save_safetensors(model: &Network, path: &Path) -> Result<(), String> {
    let tmp = temp_path(path);
    let mut store = SafetensorsStore::from_file(&tmp);
    model
        .save_into(&mut store)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    canonical_safetensors_header(&tmp).map_err(|e| format!("{}: {e}", path.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display()))
}

/// Rewrites a safetensors file's JSON header with its keys sorted. Burn writes the
/// `__metadata__` entries from a hash map, in an order that changes from run to run, so the
/// same weights would give different files. The tensor entries name their byte ranges, so their
/// order is free; the header keeps its length (padded with spaces, as the format allows), so the
/// tensor data is not moved.
pub fn canonical_safetensors_header(path: &Path) -> Result<(), String> {
    let mut bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    let len_bytes: [u8; 8] = bytes
        .get(..8)
        .and_then(|b| b.try_into().ok())
        .ok_or("not a safetensors file (shorter than its header length)")?;
    let len = usize::try_from(u64::from_le_bytes(len_bytes)).map_err(|e| e.to_string())?;
    let header = bytes
        .get(8..8 + len)
        .ok_or("not a safetensors file (header longer than the file)")?;
    let value: serde_json::Value =
        serde_json::from_slice(header).map_err(|e| format!("safetensors header: {e}"))?;
    let mut sorted = serde_json::to_vec(&sort_keys(value)).map_err(|e| e.to_string())?;
    if sorted.len() > len {
        return Err("safetensors header grew when sorted".into());
    }
    sorted.resize(len, b' ');
    bytes[8..8 + len].copy_from_slice(&sorted);
    std::fs::write(path, bytes).map_err(|e| e.to_string())
}

/// Writes the burnpack file `from` to `to` with its tensors in name order. Burn's optimizer
/// lists its per-parameter state in hash-map order, which changes from run to run, so the same
/// training would otherwise write different checkpoint files. (Scalars and metadata are kept in
/// maps ordered by key already.)
fn sorted_burnpack(from: &Path, to: &Path) -> Result<(), String> {
    let reader = burn_pack::Reader::from_file_exact(from).map_err(|e| e.to_string())?;
    let scalars = reader.scalars().clone();
    let metadata = reader.metadata().clone();
    let mut tensors = reader.into_tensors().map_err(|e| e.to_string())?;
    tensors.sort_by(|a, b| a.name.cmp(&b.name));
    let mut writer = burn_pack::Writer::new(tensors)
        .auto_extension(false)
        .overwrite(true);
    for (key, value) in &scalars {
        writer = writer.with_scalar(key, *value);
    }
    for (key, value) in &metadata {
        writer = writer.with_metadata(key, value);
    }
    writer.write_to_file(to).map_err(|e| e.to_string())
}

/// `value` with the keys of every object in sorted order (whatever order serde_json's map
/// keeps, which depends on its `preserve_order` feature).
fn sort_keys(value: serde_json::Value) -> serde_json::Value {
    match value {
        serde_json::Value::Object(map) => {
            let sorted: std::collections::BTreeMap<String, serde_json::Value> =
                map.into_iter().map(|(k, v)| (k, sort_keys(v))).collect();
            serde_json::Value::Object(sorted.into_iter().collect())
        }
        serde_json::Value::Array(items) => {
            serde_json::Value::Array(items.into_iter().map(sort_keys).collect())
        }
        other => other,
    }
}

/// Loads burnpack weights into a freshly built network of `config`.
pub fn load_burnpack(
    config: &ModelConfig,
    path: &Path,
    device: &Device,
) -> Result<Network, String> {
    if !path.exists() {
        return Err(format!("{}: no such file", path.display()));
    }
    let mut model = config.init(0, device);
    let mut store = BurnpackStore::from_file(path).auto_extension(false);
    let result = model
        .load_from(&mut store)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    if !result.is_success() || !result.missing.is_empty() {
        return Err(format!(
            "{}: weights do not match the model config: {result:?}",
            path.display()
        ));
    }
    // Tensors the network has no place for (a deeper network's extra layers) are not ignored.
    if !result.unused.is_empty() {
        return Err(format!(
            "{}: weights do not match the model config: the file holds {} that a network of \
             {} hidden layers does not have",
            path.display(),
            result.unused.join(", "),
            config.hidden_layers
        ));
    }
    Ok(model)
}

/// Writes `text` to `path` atomically.
pub fn write_atomic(path: &Path, text: &str) -> Result<(), String> {
    let tmp = temp_path(path);
    std::fs::write(&tmp, text).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("{}: {e}", path.display()))
}

fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp{}", std::process::id()))
}

/// A training run: model, optimizer, settings and history.
pub struct Trainer {
    /// The model being trained (on the autodiff device).
    pub model: Network,
    /// Adam and its moments.
    pub optim: ModuleOptimizer,
    /// Architecture.
    pub config: ModelConfig,
    /// Optimisation settings.
    pub settings: TrainSettings,
    /// Completed epochs.
    pub epochs_done: usize,
    /// Reports of the completed epochs.
    pub history: Vec<EpochReport>,
    device: Device,
}

impl Trainer {
    /// A fresh run on `device` (autodiff is enabled on it here).
    pub fn new(config: ModelConfig, settings: TrainSettings, device: &Device) -> Self {
        let device = device.clone().autodiff();
        let model = config.init(settings.seed, &device);
        Self::fresh(model, config, settings, device)
    }

    /// A fresh run (new optimizer, epoch 0) that starts from the weights of the trained model
    /// directory `dir` instead of random ones: fine-tuning. The directory's architecture must
    /// equal `config`, or be a narrower/shallower one of the same kind, which is then grown
    /// into `config` without changing what it computes ([`ModelConfig::grow`]).
    pub fn from_weights(
        config: ModelConfig,
        settings: TrainSettings,
        dir: &Path,
        device: &Device,
    ) -> Result<Self, String> {
        let device = device.clone().autodiff();
        let trained = TrainedModel::open(dir, &device).map_err(|e| e.to_string())?;
        if trained.config == config {
            return Ok(Self::fresh(trained.network, config, settings, device));
        }
        // A smaller network of the same kind is grown into this architecture, computing the
        // same function (ModelConfig::grow); anything else is a mistake in the config.
        let grown = config
            .grow(&trained.config, &trained.network, settings.seed, &device)
            .map_err(|e| {
                format!(
                    "{}: architecture {:?} differs from the config's {:?}: {e}",
                    dir.display(),
                    trained.config,
                    config
                )
            })?;
        Ok(Self::fresh(grown, config, settings, device))
    }

    /// Epoch 0 of a run on the autodiff `device` from `model`, with a new optimizer.
    fn fresh(model: Network, config: ModelConfig, settings: TrainSettings, device: Device) -> Self {
        Self {
            model,
            optim: adam(),
            config,
            settings,
            epochs_done: 0,
            history: Vec::new(),
            device,
        }
    }

    /// The plain (non-autodiff) device used for validation.
    pub fn plain_device(&self) -> Device {
        self.device.clone().inner()
    }

    /// Trains one epoch and validates; `on_batch` is called after every batch. Both datasets are
    /// set to feed the levels the model combines.
    pub fn run_epoch(
        &mut self,
        train: &mut PatchDataset,
        val: Option<&mut PatchDataset>,
        on_batch: &mut dyn FnMut(BatchProgress),
    ) -> Result<EpochReport, BadSample> {
        let start = Instant::now();
        let epoch = self.epochs_done;
        train.levels = self.config.levels.clone();
        let plan = train.epoch_plan(self.settings.seed, epoch);
        let total = plan.len();
        let batch_size = self.settings.batch.max(1);
        // Every epoch has the same number of steps (the plan's length does not change).
        let steps_per_epoch = total.div_ceil(batch_size);
        let total_steps = steps_per_epoch * self.settings.epochs;
        let (mut loss_sum, mut batches, mut done) = (0.0, 0usize, 0usize);
        for chunk in plan.chunks(batch_size) {
            let batch = train.batch(chunk)?.to_device(&self.device);
            let model = self.model.clone();
            let lr = self
                .settings
                .lr_at(epoch * steps_per_epoch + batches, total_steps);
            let (model, loss) = train_step(
                model,
                &mut self.optim,
                &self.config,
                batch,
                lr,
                self.settings.loss,
            );
            self.model = model;
            loss_sum += loss;
            batches += 1;
            done += chunk.len();
            on_batch(BatchProgress { done, total, loss });
        }
        let validation = match val {
            Some(val) if !val.images.is_empty() => {
                let plain = self.plain_device();
                let valid = self.model.valid();
                Some(validate(
                    &valid,
                    &self.config,
                    val,
                    self.settings.batch,
                    &plain,
                )?)
            }
            _ => None,
        };
        self.epochs_done += 1;
        let report = EpochReport {
            epoch: self.epochs_done,
            train_loss: loss_sum / batches.max(1) as f64,
            validation,
            patches: done,
            seconds: start.elapsed().as_secs_f64(),
        };
        self.history.push(report.clone());
        Ok(report)
    }

    /// Writes `model.bpk`, `optimizer.bpk` and `state.json` into `dir` (each atomically;
    /// `state.json` last, so a checkpoint is complete once it names the epoch).
    pub fn save_checkpoint(&self, dir: &Path) -> Result<(), String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        save_burnpack(&self.model, &dir.join("model.bpk"))?;
        let optim_path = dir.join("optimizer.bpk");
        let raw = temp_path(&dir.join("optimizer.raw.bpk"));
        self.optim
            .save(&raw)
            .map_err(|e| format!("{}: {e:?}", optim_path.display()))?;
        let tmp = temp_path(&optim_path);
        let sorted = sorted_burnpack(&raw, &tmp);
        let _ = std::fs::remove_file(&raw);
        sorted.map_err(|e| format!("{}: {e}", optim_path.display()))?;
        std::fs::rename(&tmp, &optim_path).map_err(|e| format!("{}: {e}", optim_path.display()))?;
        let state = CheckpointState {
            model: self.config.clone(),
            settings: self.settings.clone(),
            epochs_done: self.epochs_done,
            history: self.history.clone(),
        };
        let json = serde_json::to_string_pretty(&state).expect("state serialises");
        write_atomic(&dir.join("state.json"), &json)
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
        write_atomic(&dir.join("model.json"), &json)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::PackedImage;
    use crate::model::Preset;
    use crate::synthetic::synthetic_sample;
    use burn::tensor::TensorData;

    /// Reconstructs a whole packed image with a model of `config` (initial weights).
    fn run(config: &ModelConfig, packed: &PackedImage) -> Vec<f32> {
        let device = Device::flex();
        let net = config.init(3, &device);
        let s = packed.select_levels(&config.levels);
        let (w, h) = (s.width, s.height);
        let f = Tensor::<4>::from_data(
            TensorData::new(s.features.clone(), [1, config.in_channels, h, w]),
            &device,
        );
        let l = Tensor::<4>::from_data(
            TensorData::new(s.levels.clone(), [1, s.levels.len() / (w * h), h, w]),
            &device,
        );
        reconstruct(&net, config, f, l)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()
    }

    #[test]
    fn dual_model_reproduces_identical_levels() {
        // Consistency of Eq. 6 for m = 2: when ỹ and the chosen z̃ are the same image, every
        // term ỹ_i + z̃_c − z̃_i equals ỹ_c, so the output is ỹ whatever the (random) weights.
        let mut packed = synthetic_sample(9, 7, 0.2, 5).packed;
        let pixels = packed.pixels();
        let y = packed.level(0).to_vec();
        packed.levels[3 * 2 * pixels..3 * 3 * pixels].copy_from_slice(&y);
        let config = ModelConfig::preset(Preset::Tiny).with_levels(vec![0, 2]);
        config.validate().unwrap();
        assert_eq!(config.in_channels, 15);
        assert_eq!(config.out_channels(), 25);
        let out = run(&config, &packed);
        for (i, (o, e)) in out.iter().zip(&y).enumerate() {
            assert!((o - e).abs() <= 1e-4 * e.abs().max(1.0), "{i}: {o} vs {e}");
        }
        // With a different z̃2 the output moves away from ỹ: the test can fail.
        let fresh = synthetic_sample(9, 7, 0.2, 5).packed;
        let moved = run(&config, &fresh);
        assert!(moved
            .iter()
            .zip(fresh.level(0))
            .any(|(o, e)| (o - e).abs() > 1e-3));
    }

    #[test]
    fn model_json_without_levels_loads_as_all_five() {
        let old = r#"{"preset": "small", "in_channels": 27, "hidden_layers": 5, "filters": 32,
            "kernel": 5, "window": 11, "weighting": "relu"}"#;
        let config: ModelConfig = serde_json::from_str(old).unwrap();
        assert_eq!(config, ModelConfig::preset(Preset::Small));
        assert_eq!(config.levels, vec![0, 1, 2, 3, 4]);
        config.validate().unwrap();
        let dual = ModelConfig::preset(Preset::Small).with_levels(vec![0, 3]);
        let text = serde_json::to_string(&dual).unwrap();
        assert_eq!(serde_json::from_str::<ModelConfig>(&text).unwrap(), dual);
    }

    #[test]
    fn bad_level_choices_are_rejected() {
        for levels in [
            vec![],
            vec![0],
            vec![1, 2],
            vec![0, 2, 2],
            vec![0, 3, 1],
            vec![0, 5],
        ] {
            let c = ModelConfig::preset(Preset::Tiny).with_levels(levels.clone());
            assert!(c.validate().is_err(), "{levels:?}");
        }
        let mut c = ModelConfig::preset(Preset::Tiny).with_levels(vec![0, 1, 4]);
        c.validate().unwrap();
        c.in_channels = 27;
        assert!(c.validate().is_err());
    }
}
