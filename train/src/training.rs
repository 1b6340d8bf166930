//! The training loop: Adam steps on patch batches, per-epoch validation against the best single
//! input level, checkpoints that resume exactly, and the saved weights.

use std::path::Path;
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::Device;
use model::combine::reconstruct;
use model::loss::Loss;
use model::metrics::relmse_sum_planar;
use model::model_dir::TrainedModel;
use model::network::{ModelConfig, Network, LEVELS};
use model::sample::BadSample;
use serde::{Deserialize, Serialize};

use crate::data::{Batch, PatchDataset};

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
    /// The same per image of the dataset, in its order (for `--evaluate`; not kept in the
    /// training history).
    #[serde(skip)]
    pub images: Vec<ImageValidation>,
}

/// relMSE of the output and of every input level over one image.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageValidation {
    /// relMSE of the reconstruction.
    pub output: f64,
    /// relMSE of ỹ, z̃1..z̃4.
    pub levels: [f64; LEVELS],
}

impl ImageValidation {
    /// The best (lowest) single input level of this image as (index, relMSE).
    pub fn best_level(&self) -> (usize, f64) {
        best_of(&self.levels)
    }
}

impl Validation {
    /// The best (lowest) single input level as (index, relMSE).
    pub fn best_level(&self) -> (usize, f64) {
        best_of(&self.levels)
    }
}

/// The lowest of `levels` as (index, value).
fn best_of(levels: &[f64; LEVELS]) -> (usize, f64) {
    levels
        .iter()
        .copied()
        .enumerate()
        .fold(
            (0, f64::INFINITY),
            |best, (i, v)| if v < best.1 { (i, v) } else { best },
        )
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

/// Adam with the paper's learning rate handled by the caller and ε = 1e-8 (Burn's default
/// is 1e-5).
pub fn adam() -> ModuleOptimizer {
    AdamConfig::new().with_epsilon(1e-8).init()
}

/// Why an epoch stopped before its end.
#[derive(Debug)]
pub enum EpochError {
    /// A sample failed to load mid-epoch (it changed after screening).
    Sample(BadSample),
    /// The device could not run a step: on a GPU, typically a buffer larger than it allows.
    Device(String),
}

impl std::fmt::Display for EpochError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Sample(b) => write!(f, "{}: {}", b.file.display(), b.reason),
            Self::Device(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for EpochError {}

impl From<BadSample> for EpochError {
    fn from(b: BadSample) -> Self {
        Self::Sample(b)
    }
}

/// A device error on one line: Burn chains its causes over many lines ("Caused by:", backtrace
/// notes), the innermost saying what failed ("can't allocate buffer of size: …").
fn device_cause(e: impl std::fmt::Display) -> String {
    e.to_string()
        .lines()
        .map(str::trim)
        .filter(|l| {
            !l.is_empty()
                && !l.starts_with("Caused by")
                && !l.starts_with("Asked at")
                && !l.contains("backtrace")
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// One optimisation step minimising `loss`; returns the updated model and the batch loss, or
/// why the device could not run it. Burn runs the step lazily, so a device failure (a GPU
/// buffer above its limit) surfaces where the loss is read; the message names the batch.
pub fn train_step(
    model: Network,
    optim: &mut ModuleOptimizer,
    config: &ModelConfig,
    batch: Batch,
    lr: f64,
    loss: Loss,
) -> Result<(Network, f64), String> {
    let [patches, _, height, width] = batch.features.dims();
    let prediction = reconstruct(&model, config, batch.features, batch.levels) + batch.direct;
    let loss = loss.evaluate(prediction, batch.reference);
    let grads = loss.backward();
    let value: f32 = loss.try_into_scalar::<f32>().map_err(|e| {
        format!(
            "the device failed a training step of {patches} patches of {width}×{height}: {} \
             (on a GPU: lower `batch` or `patch`, docs/performance.md \"On a GPU\")",
            device_cause(e)
        )
    })?;
    let grads = GradientsParams::from_grads(grads, &model);
    Ok((optim.step(lr, model, grads), value as f64))
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
) -> Result<Validation, EpochError> {
    // Per image: squared-error sums of the output and the levels, and the values summed.
    let mut sums = vec![(0.0f64, [0.0f64; LEVELS], 0usize); dataset.images.len()];
    dataset.levels = config.levels.clone();
    dataset.set_packing(&config.packing());
    let refs: Vec<_> = (0..dataset.images.len())
        .flat_map(|i| dataset.image_patches(i, dataset.patch))
        .collect();
    for chunk in refs.chunks(batch.max(1)) {
        let host = dataset.batch(chunk)?;
        let b = host.to_device(device);
        let [patches, _, height, width] = b.features.dims();
        let prediction = reconstruct(model, config, b.features, b.levels) + b.direct;
        let prediction = prediction
            .try_into_data()
            .map_err(|e| {
                EpochError::Device(format!(
                    "the device failed to reconstruct {patches} patches of {width}×{height} \
                     for validation: {}",
                    device_cause(e)
                ))
            })?
            .try_to_vec::<f32>()
            .expect("f32 output");
        let p2 = host.size * host.size;
        for (k, patch) in chunk.iter().enumerate().take(host.len) {
            let (output, levels, count) = &mut sums[patch.image];
            let reference = &host.reference[k * 3 * p2..(k + 1) * 3 * p2];
            *output += relmse_sum_planar(&prediction[k * 3 * p2..(k + 1) * 3 * p2], reference);
            let patch_levels = &host.levels[k * 3 * LEVELS * p2..(k + 1) * 3 * LEVELS * p2];
            for (l, sum) in levels.iter_mut().enumerate() {
                *sum += relmse_sum_planar(&patch_levels[l * 3 * p2..(l + 1) * 3 * p2], reference);
            }
            *count += 3 * p2;
        }
    }
    // Pooled over all pixels, as the loss sees them.
    let count: usize = sums.iter().map(|s| s.2).sum();
    let n = count.max(1) as f64;
    let output = sums.iter().map(|s| s.0).sum::<f64>() / n;
    let levels = std::array::from_fn(|l| sums.iter().map(|s| s.1[l]).sum::<f64>() / n);
    let images = sums
        .iter()
        .map(|(output, levels, count)| {
            let n = (*count).max(1) as f64;
            ImageValidation {
                output: output / n,
                levels: levels.map(|s| s / n),
            }
        })
        .collect();
    Ok(Validation {
        output,
        levels,
        images,
    })
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
    pub(crate) device: Device,
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
    /// into `config` without changing what it computes ([`ModelConfig::grow`]), or the same
    /// one reading fewer extra feature planes ([`ModelConfig::with_new_inputs`]).
    pub fn from_weights(
        config: ModelConfig,
        settings: TrainSettings,
        dir: &Path,
        device: &Device,
    ) -> Result<Self, String> {
        let device = device.clone().autodiff();
        let mut trained = TrainedModel::open(dir, &device).map_err(|e| e.to_string())?;
        // The filters and the guard are the config's: they change no weight's shape.
        trained.config = trained.config.with_settings_around_the_network_of(&config);
        if trained.config == config {
            return Ok(Self::fresh(trained.network, config, settings, device));
        }
        // The same network reading more input planes starts with zero weights from them.
        if config.input_growth_obstacle(&trained.config).is_none() {
            let widened = config
                .with_new_inputs(&trained.config, &trained.network, &device)
                .map_err(|e| format!("{}: {e}", dir.display()))?;
            return Ok(Self::fresh(widened, config, settings, device));
        }
        // The model reads planes the config does not list: a network cannot drop inputs, and
        // the config most likely forgot them (say which, in the config's spelling).
        if config.differs_only_in_extra_features(&trained.config)
            && !trained.config.extra_features.is_empty()
        {
            let spelt = |c: &ModelConfig| serde_json::to_string(&c.extra_features).unwrap();
            return Err(format!(
                "{}: the model reads extra_features = {}, the config lists {}: a fine-tune keeps \
                 the planes its model reads (and may add more after them); give the config \
                 extra_features = {}",
                dir.display(),
                spelt(&trained.config),
                spelt(&config),
                spelt(&trained.config)
            ));
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
    ) -> Result<EpochReport, EpochError> {
        let start = Instant::now();
        let epoch = self.epochs_done;
        train.levels = self.config.levels.clone();
        train.set_packing(&self.config.packing());
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
            )
            .map_err(EpochError::Device)?;
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
}

#[cfg(test)]
mod tests {
    use super::device_cause;

    #[test]
    fn a_device_error_reads_on_one_line_with_its_innermost_cause() {
        // The chain Burn's wgpu backend reported on an H200 for a batch above the buffer limit.
        let chain = "An error happened during execution\nCaused by:\n  Several failures at once\n\
                     Caused by:\n  An IO error happened\nCaused by:\n  can't allocate buffer of \
                     size: 4542431232\nNo backtrace available\nAsked at:\nNo backtrace available";
        assert_eq!(
            device_cause(chain),
            "An error happened during execution; Several failures at once; An IO error \
             happened; can't allocate buffer of size: 4542431232"
        );
    }
}
