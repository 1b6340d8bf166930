//! The training TOML: backend, dataset, preset, patching, optimisation and output settings.

use std::path::{Path, PathBuf};

use crate::data::FamilyFilter;
use crate::training::{toml_name, TrainSettings};
use anyhow::{bail, Context, Result};
use model::loss::Loss;
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
    /// Directory inside the dataset whose `<scene id>.exr` replaces every sample's reference
    /// (training, validation and `--evaluate`), e.g. the averaged runs written by
    /// `datagen average-references` (`references-avg8`). Absent: the manifest's references —
    /// for validation and `--evaluate` each scene's converged evaluation reference where the
    /// manifest lists one (`datagen evaluation-references`), for training its training one.
    #[serde(default)]
    pub references: Option<PathBuf>,
    /// Split trained on.
    #[serde(default = "default_split_train")]
    pub train_split: String,
    /// Split validated on after every epoch.
    #[serde(default = "default_split_val")]
    pub val_split: String,
    /// Network preset: `paper`, `medium`, `small` or `tiny`.
    pub preset: Preset,
    /// Weight transform: `relu` (paper) or `softmax`.
    #[serde(default)]
    pub weighting: Option<Weighting>,
    /// Combination window side (odd), replacing the preset's: e.g. a `small` network with the
    /// window grown from 11 to 15 through `init`. Absent: the preset's.
    #[serde(default)]
    pub window: Option<usize>,
    /// Estimates the network combines, as indices into ỹ, z̃1..z̃4 (0 = ỹ first, increasing):
    /// all five by default (the paper's network); `[0, j]` trains Dual(ỹ, z̃j) of paper Table 1.
    #[serde(default)]
    pub levels: Option<Vec<usize>>,
    /// Strength of the safeguard towards the smoothest level (docs/method.md §5.4; 0 = Eq. 6
    /// alone), which the loss sees and `model.json` keeps for inference. Absent: the preset's
    /// (`model::network::DEFAULT_GUARD`).
    #[serde(default)]
    pub guard: Option<f32>,
    /// The safeguard's trust λ in the smoothest level (docs/method.md §5.4). Absent: the
    /// preset's (`model::network::DEFAULT_GUARD_TARGET_NOISE`).
    #[serde(default)]
    pub guard_target_noise: Option<f32>,
    /// Screen-space filtered levels in the place of some bundle levels (docs/method.md §9):
    /// `[{ slot = 4, source = 4, sigma = 2.0 }]` reads z̃4 filtered across pixels (guided by the
    /// G-buffer and, with `range`, default 2, by the level's own noise) in z̃4's place. Absent:
    /// the bundle's levels.
    #[serde(default)]
    pub screen_levels: Vec<model::screen_filter::ScreenLevel>,
    /// The photon-free part filtered across pixels before it is added to the output
    /// (docs/method.md §9): `{ sigma = 1.0, range = 4.0 }` (`models/default`'s). The loss sees
    /// the filtered output and `model.json` keeps it for inference. Absent: not filtered.
    #[serde(default)]
    pub direct_filter: Option<model::screen_filter::DirectFilter>,
    /// Input planes after the paper's 27 (docs/method.md §9, "Other weight predictors"):
    /// `["disagreement", "passes"]` — per correlated level how far ỹ and z̃ʲ differ against
    /// their noise, and the pass count. With `init` naming a model without them (and otherwise
    /// the same architecture), the first convolution reads them with zero weights at the start.
    /// Absent: the paper's inputs.
    #[serde(default)]
    pub extra_features: Vec<model::features::ExtraFeature>,
    /// Patch side in pixels.
    pub patch: usize,
    /// Patch stride in pixels.
    pub stride: usize,
    /// Patches per batch.
    pub batch: usize,
    /// Total epochs.
    pub epochs: usize,
    /// Adam learning rate (of the first step when `lr_end` is set).
    #[serde(default = "default_lr")]
    pub lr: f64,
    /// Learning rate of the last step: the rate decays from `lr` to `lr_end` along a cosine over
    /// all steps of `epochs`. Absent: constant `lr`.
    #[serde(default)]
    pub lr_end: Option<f64>,
    /// Loss minimised: `relative-log-l1` (paper Eq. 8, default) or `relmse` (the evaluation
    /// metric; for fine-tuning).
    #[serde(default)]
    pub loss: Loss,
    /// Start from the weights of this trained model directory (`model.json` + `model.bpk`, e.g.
    /// an earlier run's output or `models/default`) instead of random ones, with a fresh
    /// optimizer: fine-tuning. The architecture must match this config's, or be a smaller one
    /// (fewer hidden layers or filters, a narrower window with ReLU weighting; same kernel,
    /// levels, weighting) that is grown into it computing the same function (nearly, for a
    /// wider window), e.g. `small` weights into the `medium` preset, or the same one without
    /// some of `extra_features` (read with zero weights at the start).
    /// Ignored by `--resume`.
    #[serde(default)]
    pub init: Option<PathBuf>,
    /// Scene families read (training, validation and `--evaluate`), e.g. `["room", "glass"]`.
    /// Absent: every family of the dataset.
    #[serde(default)]
    pub families: Option<Vec<String>>,
    /// Scene families left out (training, validation and `--evaluate`): `["lamp"]` trains a
    /// network that never saw a lamp (leave-one-family-out; `--evaluate-families lamp` then
    /// measures it on them).
    #[serde(default)]
    pub exclude_families: Vec<String>,
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
        if cfg.dataset.as_os_str().is_empty() {
            bail!("{}: dataset must name a dataset directory", path.display());
        }
        if cfg.patch == 0 || cfg.stride == 0 || cfg.batch == 0 || cfg.epochs == 0 {
            bail!(
                "{}: patch, stride, batch and epochs must be positive",
                path.display()
            );
        }
        if !(cfg.lr > 0.0 && cfg.lr.is_finite()) {
            bail!("{}: lr must be a positive number", path.display());
        }
        if cfg.lr_end.is_some_and(|e| !(e > 0.0 && e.is_finite())) {
            bail!("{}: lr_end must be a positive number", path.display());
        }
        cfg.model_config()
            .validate()
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Ok(cfg)
    }

    /// The families this config reads.
    pub fn family_filter(&self) -> FamilyFilter {
        FamilyFilter {
            only: self.families.clone(),
            exclude: self.exclude_families.clone(),
        }
    }

    /// The network architecture.
    pub fn model_config(&self) -> ModelConfig {
        let mut c = ModelConfig::preset(self.preset);
        if let Some(w) = self.weighting {
            c.weighting = w;
        }
        if let Some(window) = self.window {
            c.window = window;
        }
        if let Some(guard) = self.guard {
            c.guard = guard;
        }
        if let Some(lambda) = self.guard_target_noise {
            c.guard_target_noise = lambda;
        }
        c.screen_levels = self.screen_levels.clone();
        c.direct_filter = self.direct_filter.clone();
        let c = c.with_extra_features(self.extra_features.clone());
        match &self.levels {
            Some(levels) => c.with_levels(levels.clone()),
            None => c,
        }
    }

    /// The optimisation settings.
    pub fn settings(&self) -> TrainSettings {
        TrainSettings {
            batch: self.batch,
            epochs: self.epochs,
            lr: self.lr,
            lr_end: self.lr_end,
            seed: self.seed,
            loss: self.loss,
        }
    }

    /// What a checkpoint of network `model` trained with `settings` cannot continue as this
    /// config says, one `<key> <checkpoint's> (checkpoint) vs <config's> (config)` per differing
    /// TOML key: the network (`preset`, `weighting`, `window`, `guard`, `guard_target_noise`,
    /// `levels`, `screen_levels`, `direct_filter`, `extra_features`) and the optimisation
    /// (`batch`, `lr`, `lr_end`, `seed`, `loss`; `epochs` too under a decaying rate, whose
    /// schedule spans them). Empty: the checkpoint resumes with this config.
    pub fn checkpoint_differences(
        &self,
        model: &ModelConfig,
        settings: &TrainSettings,
    ) -> Vec<String> {
        let net = self.model_config();
        let ours = self.settings();
        let mut out = Vec::new();
        let mut differ = |key: &str, checkpoint: String, config: String| {
            if checkpoint != config {
                out.push(format!(
                    "{key} {checkpoint} (checkpoint) vs {config} (config)"
                ));
            }
        };
        differ("preset", toml_name(&model.preset), toml_name(&net.preset));
        differ(
            "weighting",
            toml_name(&model.weighting),
            toml_name(&net.weighting),
        );
        differ("window", model.window.to_string(), net.window.to_string());
        differ("guard", model.guard.to_string(), net.guard.to_string());
        differ(
            "guard_target_noise",
            model.guard_target_noise.to_string(),
            net.guard_target_noise.to_string(),
        );
        differ(
            "levels",
            format!("{:?}", model.levels),
            format!("{:?}", net.levels),
        );
        differ(
            "screen_levels",
            format!("{:?}", model.screen_levels),
            format!("{:?}", net.screen_levels),
        );
        differ(
            "direct_filter",
            format!("{:?}", model.direct_filter),
            format!("{:?}", net.direct_filter),
        );
        differ(
            "extra_features",
            format!("{:?}", model.extra_features),
            format!("{:?}", net.extra_features),
        );
        out.extend(crate::training::settings_differences(settings, &ours));
        // Same keys, different network: a preset whose sizes changed since the checkpoint.
        if out.is_empty() && *model != net {
            let layers = |c: &ModelConfig| {
                format!(
                    "{} {} hidden layers of {} filters, kernel {}, {} input channels",
                    toml_name(&c.preset),
                    c.hidden_layers,
                    c.filters,
                    c.kernel,
                    c.in_channels
                )
            };
            out.push(format!(
                "network {} (checkpoint) vs {} (config)",
                layers(model),
                layers(&net)
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The repository root, where `configs/` lives (the crate's manifest directory's parent).
    fn repo_root() -> PathBuf {
        PathBuf::from(
            std::env::var_os("CARGO_MANIFEST_DIR")
                .unwrap_or_else(|| env!("CARGO_MANIFEST_DIR").into()),
        )
        .join("..")
    }

    const BASE: &str = "dataset = \"d\"\npreset = \"tiny\"\npatch = 8\nstride = 8\nbatch = 2\n\
                        epochs = 1\nseed = 1\noutput = \"o\"\n";

    #[test]
    fn levels_key_chooses_the_combined_levels() {
        let all: TrainConfig = toml::from_str(BASE).unwrap();
        assert_eq!(all.model_config().levels, vec![0, 1, 2, 3, 4]);
        assert_eq!(all.model_config().in_channels, 27);
        let dual: TrainConfig = toml::from_str(&format!("{BASE}levels = [0, 2]\n")).unwrap();
        let c = dual.model_config();
        assert_eq!(c.levels, vec![0, 2]);
        assert_eq!(c.in_channels, 15);
        c.validate().unwrap();
        let bad: TrainConfig = toml::from_str(&format!("{BASE}levels = [2]\n")).unwrap();
        assert!(bad.model_config().validate().is_err());
        assert!(toml::from_str::<TrainConfig>(&format!("{BASE}level = [0, 2]\n")).is_err());
    }

    #[test]
    fn loss_key_chooses_the_training_loss() {
        let default: TrainConfig = toml::from_str(BASE).unwrap();
        assert_eq!(default.settings().loss, Loss::RelativeLogL1);
        let relmse: TrainConfig = toml::from_str(&format!("{BASE}loss = \"relmse\"\n")).unwrap();
        assert_eq!(relmse.settings().loss, Loss::Relmse);
        let noisy: TrainConfig =
            toml::from_str(&format!("{BASE}loss = \"noisy-relmse\"\n")).unwrap();
        assert_eq!(noisy.settings().loss, Loss::NoisyRelmse);
        let eq8: TrainConfig =
            toml::from_str(&format!("{BASE}loss = \"relative-log-l1\"\n")).unwrap();
        assert_eq!(eq8.settings().loss, Loss::RelativeLogL1);
        let err = toml::from_str::<TrainConfig>(&format!("{BASE}loss = \"l2\"\n"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("l2") && err.contains("relmse"), "{err}");
    }

    #[test]
    fn checkpoint_differences_name_the_toml_keys() {
        let base: TrainConfig = toml::from_str(BASE).unwrap();
        let (model, settings) = (base.model_config(), base.settings());
        assert!(base.checkpoint_differences(&model, &settings).is_empty());
        // A longer run with a constant rate resumes: `epochs` may be raised.
        let longer: TrainConfig =
            toml::from_str(&BASE.replace("epochs = 1", "epochs = 3")).unwrap();
        assert!(longer.checkpoint_differences(&model, &settings).is_empty());
        let diff = |extra: &str| {
            let cfg: TrainConfig = toml::from_str(&format!("{BASE}{extra}")).unwrap();
            cfg.checkpoint_differences(&model, &settings)
        };
        assert_eq!(
            diff("lr = 0.01\n"),
            ["lr 0.0001 (checkpoint) vs 0.01 (config)"]
        );
        let changed = TrainConfig {
            preset: Preset::Small,
            batch: 8,
            seed: 2,
            loss: Loss::Relmse,
            lr_end: Some(1e-5),
            ..base.clone()
        };
        assert_eq!(
            changed.checkpoint_differences(&model, &settings),
            [
                "preset tiny (checkpoint) vs small (config)",
                "window 5 (checkpoint) vs 11 (config)",
                "batch 2 (checkpoint) vs 8 (config)",
                "lr_end absent (checkpoint) vs 0.00001 (config)",
                "seed 1 (checkpoint) vs 2 (config)",
                "loss relative-log-l1 (checkpoint) vs relmse (config)",
            ]
        );
        assert_eq!(
            diff("weighting = \"softmax\"\nwindow = 7\nlevels = [0, 2]\n"),
            [
                "weighting relu (checkpoint) vs softmax (config)",
                "window 5 (checkpoint) vs 7 (config)",
                "levels [0, 1, 2, 3, 4] (checkpoint) vs [0, 2] (config)",
            ]
        );
        assert_eq!(
            diff("extra_features = [\"disagreement\", \"passes\"]\n"),
            ["extra_features [] (checkpoint) vs [Disagreement, Passes] (config)"]
        );
        let with_extra: TrainConfig =
            toml::from_str(&format!("{BASE}extra_features = [\"passes\"]\n")).unwrap();
        assert_eq!(
            with_extra.model_config().in_channels,
            model::network::INPUT_CHANNELS + 1
        );
        assert!(
            toml::from_str::<TrainConfig>(&format!("{BASE}extra_features = [\"pass\"]\n"))
                .unwrap_err()
                .to_string()
                .contains("disagreement")
        );
        // Under a decaying rate the schedule spans `epochs`: they are fixed.
        let decaying: TrainConfig = toml::from_str(&format!("{BASE}lr_end = 1e-6\n")).unwrap();
        let decaying_longer = TrainConfig {
            epochs: 3,
            ..decaying.clone()
        };
        let err = decaying_longer.checkpoint_differences(&model, &decaying.settings());
        assert_eq!(err.len(), 1, "{err:?}");
        assert!(
            err[0].starts_with("epochs 1 (checkpoint) vs 3 (config"),
            "{err:?}"
        );
        // The same keys but another network (a preset whose sizes changed): named as a whole.
        let older = ModelConfig {
            filters: 16,
            ..model.clone()
        };
        let err = base.checkpoint_differences(&older, &settings);
        assert_eq!(
            err,
            ["network tiny 2 hidden layers of 16 filters, kernel 3, 27 input channels (checkpoint) \
              vs tiny 2 hidden layers of 12 filters, kernel 3, 27 input channels (config)"]
        );
    }

    #[test]
    fn window_key_replaces_the_presets_window() {
        let default: TrainConfig = toml::from_str(BASE).unwrap();
        assert_eq!(default.model_config().window, 5);
        let wide: TrainConfig = toml::from_str(&format!("{BASE}window = 9\n")).unwrap();
        assert_eq!(wide.model_config().window, 9);
        assert_eq!(wide.model_config().out_channels(), 4 * 81);
        let even: TrainConfig = toml::from_str(&format!("{BASE}window = 8\n")).unwrap();
        let err = even.model_config().validate().unwrap_err();
        assert!(err.contains("window must be odd"), "{err}");
    }

    #[test]
    fn every_shipped_config_loads() {
        let dir = repo_root().join("configs/train");
        let mut count = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                TrainConfig::read(&path).unwrap_or_else(|e| panic!("{e:#}"));
                count += 1;
            }
        }
        assert!(
            count >= 5,
            "found only {count} configs in {}",
            dir.display()
        );
    }

    #[test]
    fn shipped_dual_configs_match_small_except_levels_and_output() {
        let root = repo_root();
        let small = TrainConfig::read(&root.join("configs/train/small.toml")).unwrap();
        assert_eq!(small.levels, None);
        for (file, j) in [
            ("small-dual-z1", 1),
            ("small-dual", 2),
            ("small-dual-z3", 3),
            ("small-dual-z4", 4),
        ] {
            let path = root.join(format!("configs/train/{file}.toml"));
            let dual = TrainConfig::read(&path).unwrap();
            assert_eq!(dual.levels, Some(vec![0, j]), "{file}");
            assert_eq!(
                (dual.preset, dual.patch, dual.stride, dual.cache_images),
                (small.preset, small.patch, small.stride, small.cache_images)
            );
            assert_eq!(dual.settings(), small.settings());
            assert_eq!(
                (dual.backend, &dual.dataset),
                (small.backend, &small.dataset)
            );
            assert_eq!(dual.weighting, small.weighting);
            assert_eq!(dual.output, Path::new("runs").join(file));
        }
    }

    /// A control run differs from its twin in the one thing it tests: the extra feature planes
    /// learnt from scratch (`unet-extra-scratch`) against the same run without them.
    #[test]
    fn scratch_control_differs_from_its_twin_in_the_extra_planes_only() {
        let dir = repo_root().join("configs/train");
        let table = |file: &str| -> toml::Table {
            let text = std::fs::read_to_string(dir.join(file)).unwrap();
            text.parse().unwrap()
        };
        let mut twin = table("unet-extra-scratch.toml");
        let mut control = table("unet-es2-scratch.toml");
        assert!(twin.remove("extra_features").is_some());
        assert_eq!(control.remove("extra_features"), None);
        assert_eq!(
            twin.remove("output").unwrap().as_str(),
            Some("runs/unet-extra-scratch")
        );
        assert_eq!(
            control.remove("output").unwrap().as_str(),
            Some("runs/unet-es2-scratch")
        );
        assert_eq!(twin, control);
    }
}
