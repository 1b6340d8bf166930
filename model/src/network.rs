//! The kernel-predicting network (paper §4.3): configuration presets and the convolution stack.

use burn::module::{Module, Param};
use burn::nn::conv::Conv2d;
use burn::nn::PaddingConfig2d;
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use crate::features::{ExtraFeature, Packing};
use crate::screen_filter::{DirectFilter, ScreenFilters, ScreenLevel};

use crate::unet::{forward_region, UNet};

/// Number of network input channels with every level: 5×3 colours + 5 variances + 7 G-buffer
/// (paper §4.3).
pub const INPUT_CHANNELS: usize = 27;

/// Number of estimates in a bundle: ỹ and z̃1..z̃4 (m = 5 in the paper).
pub const LEVELS: usize = 5;

/// G-buffer input channels: albedo (3), shading normal (3), depth (1).
pub const GBUFFER_CHANNELS: usize = 7;

/// Network input channels when `levels` estimates are combined: RGB + variance per level, plus
/// the G-buffer.
pub fn input_channels(levels: usize) -> usize {
    4 * levels + GBUFFER_CHANNELS
}

/// Every level of a bundle, ỹ, z̃1..z̃4: the paper's multi-level network (and the default of
/// `model.json` files written before level subsets existed).
pub fn all_levels() -> Vec<usize> {
    (0..LEVELS).collect()
}

/// Named network sizes; `paper` is exactly the published network.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// 10 layers of 5×5, 50 filters, 19×19 window, ≈ 2.34 M parameters.
    Paper,
    /// 6 layers of 5×5, 32 filters, 11×11 window: trains on a 2-core CPU.
    Small,
    /// 8 layers of 5×5, 48 filters, 11×11 window: the `small` network with more capacity, meant
    /// to be grown from trained `small` weights ([`ModelConfig::grow`]) and fine-tuned on a CPU.
    Medium,
    /// 3 layers of 3×3, 12 filters, 5×5 window: for tests.
    Tiny,
    /// A U-Net ([`crate::unet`]): 3×3 convolutions at full, 1/2, 1/4 and 1/8 resolution (16,
    /// 32, 48, 64 filters), a 1×1 output layer, 11×11 window: a 43-px receptive radius for
    /// ≈ 34 k multiply-adds per pixel, a fifteenth of `small`'s.
    #[serde(rename = "unet")]
    UNet,
}

/// How raw network outputs become positive combination weights.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Weighting {
    /// w = ReLU(out) + 1e-4 (the paper's choice).
    Relu,
    /// w = exp(out − max) (softmax once normalised).
    Softmax,
}

/// Architecture of the network and of the combination window; saved next to the weights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    /// Preset this configuration was made from (informational).
    pub preset: Preset,
    /// Input channels of the first convolution (27).
    pub in_channels: usize,
    /// Number of hidden convolutions (each `filters` wide, followed by ReLU).
    pub hidden_layers: usize,
    /// Filters of each hidden convolution.
    pub filters: usize,
    /// Convolution kernel size (odd; "same" padding).
    pub kernel: usize,
    /// Combination window side |Ω| = window² (odd).
    pub window: usize,
    /// Positive-weight transform.
    pub weighting: Weighting,
    /// Estimates combined, as indices into ỹ, z̃1..z̃4: ỹ (0) first, then increasing correlated
    /// levels. All five by default; `[0, j]` is the paper's Dual(ỹ, z̃j) of Table 1.
    #[serde(default = "all_levels")]
    pub levels: Vec<usize>,
    /// Strength κ of the safeguard that pulls the output towards the smoothest combined level
    /// where it differs from it by less than its estimated noise (docs/method.md §5.4): 0 is
    /// the paper's Eq. 6 alone. Absent from a model.json: [`DEFAULT_GUARD`].
    #[serde(default = "default_guard")]
    pub guard: f32,
    /// The safeguard's trust λ in the smoothest level: λ times that level's own variance counts
    /// as evidence for keeping Eq. 6, so a smoothest level made noisy by a caustic photon in its
    /// wide kernel is not pulled towards. Absent from a model.json:
    /// [`DEFAULT_GUARD_TARGET_NOISE`].
    #[serde(default = "default_guard_target_noise")]
    pub guard_target_noise: f32,
    /// The convolutions' layout when it is a U-Net (`hidden_layers` then counts all its hidden
    /// convolutions, `filters` is its full-resolution width, `kernel` its kernel, and the output
    /// layer is 1×1). Absent (every model.json written before it existed): the paper's stack of
    /// `hidden_layers` convolutions at full resolution and an output layer of `kernel`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unet: Option<UNet>,
    /// Screen-space filtered levels put in the place of some of the bundle's levels before
    /// packing ([`crate::screen_filter`]; docs/method.md §9). Absent or empty: the bundle's
    /// levels as rendered (every model.json written before it existed).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub screen_levels: Vec<ScreenLevel>,
    /// The photon-free part (emission, next-event estimation) filtered across pixels before it
    /// is added to the combination's output ([`crate::screen_filter::DirectFilter`];
    /// docs/method.md §9). Absent: added as the two eye subpaths' fused estimate (every
    /// model.json written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direct_filter: Option<DirectFilter>,
    /// Input planes after the paper's 27, in this order ([`ExtraFeature`]; `in_channels`
    /// counts them). Absent or empty: the paper's inputs (every model.json written before they
    /// existed).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extra_features: Vec<ExtraFeature>,
}

/// The safeguard strength κ of every preset and of model files that name none. With
/// [`DEFAULT_GUARD_TARGET_NOISE`] the pair with the fewest bundles above 1.05× the best input
/// on 78 validation bundles (data/small's `val` split and six renderer validation scenes at
/// 64², 2 000 and 20 000 photons per pass), grid κ 12–48 × λ 4–64 (docs/results.md, "Never
/// worse than its inputs").
pub const DEFAULT_GUARD: f32 = 16.0;

/// The safeguard's trust λ in the smoothest level, for every preset and model files that name
/// none (chosen with [`DEFAULT_GUARD`]).
pub const DEFAULT_GUARD_TARGET_NOISE: f32 = 8.0;

/// Serde default of [`ModelConfig::guard`].
fn default_guard() -> f32 {
    DEFAULT_GUARD
}

/// Serde default of [`ModelConfig::guard_target_noise`].
fn default_guard_target_noise() -> f32 {
    DEFAULT_GUARD_TARGET_NOISE
}

impl ModelConfig {
    /// The configuration of a preset.
    pub fn preset(preset: Preset) -> Self {
        let unet = (preset == Preset::UNet).then(UNet::preset);
        let (hidden_layers, filters, kernel, window) = match (preset, &unet) {
            (Preset::Paper, _) => (9, 50, 5, 19),
            (Preset::Small, _) => (5, 32, 5, 11),
            (Preset::Medium, _) => (7, 48, 5, 11),
            (Preset::Tiny, _) => (2, 12, 3, 5),
            (Preset::UNet, Some(u)) => (u.hidden_layers(), u.widths[0], 3, 11),
            (Preset::UNet, None) => unreachable!("the unet preset has a layout"),
        };
        Self {
            preset,
            in_channels: INPUT_CHANNELS,
            hidden_layers,
            filters,
            kernel,
            window,
            weighting: Weighting::Relu,
            levels: all_levels(),
            guard: DEFAULT_GUARD,
            guard_target_noise: DEFAULT_GUARD_TARGET_NOISE,
            unet,
            screen_levels: Vec::new(),
            direct_filter: None,
            extra_features: Vec::new(),
        }
    }

    /// The same architecture combining only `levels` (indices into ỹ, z̃1..z̃4); the input
    /// channels follow. Call [`ModelConfig::validate`] to check the choice.
    pub fn with_levels(mut self, levels: Vec<usize>) -> Self {
        self.levels = levels;
        self.in_channels = self.expected_in_channels();
        self
    }

    /// The same architecture reading the `extra` feature planes after the 27; the input
    /// channels follow. Call [`ModelConfig::validate`] to check the choice.
    pub fn with_extra_features(mut self, extra: Vec<ExtraFeature>) -> Self {
        self.extra_features = extra;
        self.in_channels = self.expected_in_channels();
        self
    }

    /// The input channels of this config's levels and extra features.
    fn expected_in_channels(&self) -> usize {
        let m = self.levels.len();
        input_channels(m)
            + self
                .extra_features
                .iter()
                .map(|f| f.planes(m))
                .sum::<usize>()
    }

    /// The screen-space filters this model applies to a bundle before packing it.
    pub fn screen_filters(&self) -> ScreenFilters {
        ScreenFilters {
            levels: self.screen_levels.clone(),
            direct: self.direct_filter.clone(),
        }
    }

    /// How this model packs a bundle: its screen filters and extra feature planes.
    pub fn packing(&self) -> Packing {
        Packing {
            screen: self.screen_filters(),
            extra: self.extra_features.clone(),
        }
    }

    /// Number of correlated estimates combined with ỹ (m − 1; 4 for the full network).
    pub fn pairs(&self) -> usize {
        self.levels.len().saturating_sub(1)
    }

    /// Number of window entries |Ω|.
    pub fn window_area(&self) -> usize {
        self.window * self.window
    }

    /// Output channels of the last layer: (m − 1)·|Ω| weights per pixel.
    pub fn out_channels(&self) -> usize {
        self.pairs() * self.window_area()
    }

    /// Kernel side of the output layer: `kernel` for the paper's stack, 1 for a U-Net.
    pub fn output_kernel(&self) -> usize {
        if self.unet.is_some() {
            1
        } else {
            self.kernel
        }
    }

    /// Pixels of context (features) one pixel's raw network output depends on: the halo of
    /// features an image tile needs for its network output to be exact.
    pub fn conv_reach(&self) -> usize {
        match &self.unet {
            Some(unet) => unet.reach(self.kernel, self.output_kernel()),
            None => (self.hidden_layers + 1) * (self.kernel / 2),
        }
    }

    /// Pixels of context one output pixel depends on (convolutions or window, whichever is
    /// wider).
    pub fn receptive_radius(&self) -> usize {
        self.conv_reach().max(self.window / 2)
    }

    /// `infer`'s tile side when none is given. 512 px for the convolution stacks (their halo
    /// is ≤ 20 px, 1.08× the pixels recomputed at most). 1024 px for a U-Net: its 43-px halo
    /// would recompute 1.36× the pixels of an inner 512-px tile, and its full-resolution
    /// activations are narrow (16 channels), so a 1024-px tile stays well inside infer's
    /// memory bound (1280×720: 545 MiB peak against 383 MiB at 512 px, ≈ 10–20 % less time).
    pub fn default_tile(&self) -> usize {
        if self.unet.is_some() {
            1024
        } else {
            512
        }
    }

    /// Checks the configuration for values the network cannot be built with.
    pub fn validate(&self) -> Result<(), String> {
        if self.kernel.is_multiple_of(2) || self.kernel == 0 {
            return Err(format!("kernel must be odd, got {}", self.kernel));
        }
        if self.window.is_multiple_of(2) || self.window == 0 {
            return Err(format!("window must be odd, got {}", self.window));
        }
        validate_levels(&self.levels)?;
        crate::screen_filter::validate(&self.screen_levels)?;
        if let Some(d) = &self.direct_filter {
            crate::screen_filter::validate_direct(d)?;
        }
        for (i, f) in self.extra_features.iter().enumerate() {
            if self.extra_features[..i].contains(f) {
                return Err(format!("extra_features lists {f:?} twice"));
            }
        }
        let expected = self.expected_in_channels();
        if self.in_channels != expected {
            return Err(format!(
                "in_channels must be {expected} for {} levels and extra features {:?}, got {}",
                self.levels.len(),
                self.extra_features,
                self.in_channels
            ));
        }
        if self.hidden_layers == 0 || self.filters == 0 {
            return Err("hidden_layers and filters must be positive".into());
        }
        if let Some(unet) = &self.unet {
            unet.validate()?;
            if self.hidden_layers != unet.hidden_layers() || self.filters != unet.widths[0] {
                return Err(format!(
                    "a U-Net of widths {:?} and convs {:?} has {} hidden layers and {} filters at \
                     full resolution, the config says {} and {}",
                    unet.widths,
                    unet.convs,
                    unet.hidden_layers(),
                    unet.widths[0],
                    self.hidden_layers,
                    self.filters
                ));
            }
        }
        if !(self.guard.is_finite() && self.guard >= 0.0) {
            return Err(format!(
                "guard must be a finite number ≥ 0, got {}",
                self.guard
            ));
        }
        if !(self.guard_target_noise.is_finite() && self.guard_target_noise >= 0.0) {
            return Err(format!(
                "guard_target_noise must be a finite number ≥ 0, got {}",
                self.guard_target_noise
            ));
        }
        Ok(())
    }

    /// Builds the network with Glorot-uniform weights and zero biases from `seed`.
    ///
    /// The initial weights are drawn on the host from a PCG stream, so every backend starts
    /// from bit-identical parameters.
    pub fn init(&self, seed: u64, device: &Device) -> Network {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        if let Some(unet) = &self.unet {
            let hidden = unet
                .conv_shapes(self.in_channels)
                .into_iter()
                .map(|(cin, cout)| glorot_conv(cin, cout, self.kernel, &mut rng, device))
                .collect();
            let output = glorot_conv(
                unet.widths[0],
                self.out_channels(),
                self.output_kernel(),
                &mut rng,
                device,
            );
            return Network {
                hidden,
                output,
                weighting: self.weighting,
                unet: Some(unet.clone()),
            }
            .with_stable_ids();
        }
        let mut hidden = Vec::with_capacity(self.hidden_layers);
        let mut cin = self.in_channels;
        for _ in 0..self.hidden_layers {
            hidden.push(glorot_conv(
                cin,
                self.filters,
                self.kernel,
                &mut rng,
                device,
            ));
            cin = self.filters;
        }
        let output = glorot_conv(cin, self.out_channels(), self.kernel, &mut rng, device);
        Network {
            hidden,
            output,
            weighting: self.weighting,
            unet: None,
        }
        .with_stable_ids()
    }
}

impl ModelConfig {
    /// This config with `other`'s settings around the network — what it reads (screen levels,
    /// direct filter) and what happens to its output (the guard) — which change no weight's
    /// shape: weights trained with some start a fine-tuning with others.
    pub fn with_settings_around_the_network_of(self, other: &ModelConfig) -> ModelConfig {
        ModelConfig {
            screen_levels: other.screen_levels.clone(),
            direct_filter: other.direct_filter.clone(),
            guard: other.guard,
            guard_target_noise: other.guard_target_noise,
            ..self
        }
    }

    /// Why a network of architecture `from` cannot be grown into this one (`None`: it can).
    /// Growing needs the same inputs, kernel and weighting, no fewer hidden layers or filters,
    /// and the same window or (ReLU weighting) a wider one.
    pub fn growth_obstacle(&self, from: &ModelConfig) -> Option<String> {
        if self.unet.is_some() || from.unet.is_some() {
            // Growing adds filters and identity layers to a single-resolution stack; a U-Net's
            // skips and scales have no such function-preserving embedding here.
            return Some(format!(
                "growing is defined for the single-resolution convolution stack only, and {} a \
                 U-Net (preset unet): fine-tune a U-Net from weights of the same architecture",
                match (from.unet.is_some(), self.unet.is_some()) {
                    (true, true) => "both are",
                    (true, false) => "the trained network is",
                    _ => "this network is",
                }
            ));
        }
        let same = |what: &str, a: String, b: String| {
            (a != b).then(|| format!("{what} differs (the trained network's {b}, this {a})"))
        };
        same(
            "levels",
            format!("{:?}", self.levels),
            format!("{:?}", from.levels),
        )
        .or_else(|| {
            same(
                "in_channels",
                self.in_channels.to_string(),
                from.in_channels.to_string(),
            )
        })
        .or_else(|| same("kernel", self.kernel.to_string(), from.kernel.to_string()))
        .or_else(|| {
            same(
                "weighting",
                format!("{:?}", self.weighting),
                format!("{:?}", from.weighting),
            )
        })
        .or_else(|| {
            // A wider window only with ReLU weights: the new entries start at a weight of
            // `NEW_WINDOW_ENTRY`, next to nothing (below). Softmax weights have no such floor.
            let grows = self.window > from.window && self.weighting == Weighting::Relu;
            if grows {
                None
            } else {
                same("window", self.window.to_string(), from.window.to_string())
            }
        })
        .or_else(|| {
            (from.hidden_layers > self.hidden_layers || from.filters > self.filters).then(|| {
                format!(
                    "{} hidden layers of {} filters do not fit into {} of {}",
                    from.hidden_layers, from.filters, self.hidden_layers, self.filters
                )
            })
        })
    }

    /// Embeds the trained network `net` (architecture `from`) into a network of this wider
    /// and/or deeper architecture that computes the same function (exactly, or nearly when the
    /// window grows; Net2Net-style growth, Chen et al. 2016), so fine-tuning starts from the
    /// trained network's quality with spare capacity:
    /// * each old hidden layer keeps its filters; its new filters read every input channel
    ///   with Glorot-uniform weights from `seed`, and the old filters ignore the new channels
    ///   (zero weights);
    /// * the extra hidden layers come after the old ones and copy their input (a 1 at the
    ///   kernel centre from channel c to channel c): their input is a ReLU output, ≥ 0, so the
    ///   ReLU after them changes nothing;
    /// * the last layer reads only the old channels (zero weights from the new ones);
    /// * a wider combination window (ReLU weighting only) keeps every old entry's output and
    ///   gives each new outer entry zero weights and the bias [`NEW_WINDOW_ENTRY`]: its
    ///   combination weight is that plus the 1e-4 floor, ≈ 10⁻³, against per-pixel weight sums
    ///   of ≈ 20–2 000 in a trained network (all new entries together: ≈ 0.1–3 % of the weight
    ///   at the pixels with the smallest sums, far less elsewhere), and the entries are alive
    ///   (ReLU passes their gradient).
    ///
    /// Zero weights still receive gradients, so the new capacity is used once training moves.
    pub fn grow(
        &self,
        from: &ModelConfig,
        net: &Network,
        seed: u64,
        device: &Device,
    ) -> Result<Network, String> {
        if let Some(why) = self.growth_obstacle(from) {
            return Err(format!("cannot grow the network: {why}"));
        }
        if net.hidden.len() != from.hidden_layers {
            return Err(format!(
                "cannot grow the network: it has {} hidden layers, its config says {}",
                net.hidden.len(),
                from.hidden_layers
            ));
        }
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let k = self.kernel;
        let area = k * k;
        let (big, small) = (self.filters, from.filters);
        let mut hidden = Vec::with_capacity(self.hidden_layers);
        for layer in 0..self.hidden_layers {
            let cin = if layer == 0 { self.in_channels } else { big };
            let mut weight = vec![0.0f32; big * cin * area];
            let mut bias = vec![0.0f32; big];
            if let Some(old) = net.hidden.get(layer) {
                let old_cin = if layer == 0 { from.in_channels } else { small };
                let (old_weight, old_bias) = conv_values(old)?;
                for o in 0..small {
                    for i in 0..old_cin {
                        let src = (o * old_cin + i) * area;
                        let dst = (o * cin + i) * area;
                        weight[dst..dst + area].copy_from_slice(&old_weight[src..src + area]);
                    }
                }
                bias[..small].copy_from_slice(&old_bias);
                let new_filters = &mut weight[small * cin * area..];
                new_filters.copy_from_slice(&glorot_values(
                    new_filters.len(),
                    cin,
                    big,
                    k,
                    &mut rng,
                ));
            } else {
                for c in 0..big {
                    weight[(c * cin + c) * area + area / 2] = 1.0;
                }
            }
            hidden.push(conv_from_values(weight, bias, big, cin, k, device));
        }
        let (old_weight, old_bias) = conv_values(&net.output)?;
        let cout = self.out_channels();
        let mut weight = vec![0.0f32; cout * big * area];
        let mut bias = vec![NEW_WINDOW_ENTRY; cout];
        let (window, old_window) = (self.window, from.window);
        let shift = (window - old_window) / 2;
        for (o, b) in bias.iter_mut().enumerate() {
            // Output channels are pair-major, then window entries row-major.
            let (pair, entry) = (o / (window * window), o % (window * window));
            let (row, col) = (entry / window, entry % window);
            let inside = (shift..shift + old_window).contains(&row)
                && (shift..shift + old_window).contains(&col);
            if !inside {
                continue;
            }
            let old_o = pair * old_window * old_window + (row - shift) * old_window + (col - shift);
            *b = old_bias[old_o];
            for i in 0..small {
                let src = (old_o * small + i) * area;
                let dst = (o * big + i) * area;
                weight[dst..dst + area].copy_from_slice(&old_weight[src..src + area]);
            }
        }
        let output = conv_from_values(weight, bias, cout, big, k, device);
        Ok(Network {
            hidden,
            output,
            weighting: self.weighting,
            unet: None,
        }
        .with_stable_ids())
    }
}

impl ModelConfig {
    /// Why the weights of a network of architecture `from` cannot start this one by reading
    /// the extra feature planes this one adds (`None`: they can): everything but the extra
    /// features must be the same, and this list must begin with `from`'s.
    pub fn input_growth_obstacle(&self, from: &ModelConfig) -> Option<String> {
        let adds = self.extra_features.len() > from.extra_features.len()
            && self.extra_features.starts_with(&from.extra_features);
        if !adds {
            return Some(format!(
                "extra_features {:?} do not extend the trained network's {:?}",
                self.extra_features, from.extra_features
            ));
        }
        (!self.differs_only_in_extra_features(from)).then(|| {
            "only extra_features may differ from the trained network's architecture when \
             features are added"
                .to_owned()
        })
    }

    /// Whether `other` is this architecture reading other extra feature planes (or the same
    /// ones): everything but `extra_features` and the input channels they add is equal.
    pub fn differs_only_in_extra_features(&self, other: &ModelConfig) -> bool {
        ModelConfig {
            extra_features: other.extra_features.clone(),
            in_channels: other.in_channels,
            ..self.clone()
        } == *other
    }

    /// The trained network `net` (architecture `from`) reading this config's further extra
    /// feature planes: its first convolution gets zero weights from the new input channels
    /// (packed after the old ones, [`crate::features::feature_channels`]), so it computes the
    /// same function, and fine-tuning moves them (zero weights still receive gradients).
    pub fn with_new_inputs(
        &self,
        from: &ModelConfig,
        net: &Network,
        device: &Device,
    ) -> Result<Network, String> {
        if let Some(why) = self.input_growth_obstacle(from) {
            return Err(format!("cannot add input features: {why}"));
        }
        let Some(first) = net.hidden.first() else {
            return Err("cannot add input features: the network has no hidden layer".into());
        };
        let [cout, old_cin, k, _] = first.weight.shape().dims::<4>();
        if old_cin != from.in_channels {
            return Err(format!(
                "cannot add input features: the first convolution reads {old_cin} channels, its \
                 config says {}",
                from.in_channels
            ));
        }
        let (old_weight, bias) = conv_values(first)?;
        let (cin, area) = (self.in_channels, k * k);
        let mut weight = vec![0.0f32; cout * cin * area];
        for o in 0..cout {
            let (src, dst) = (o * old_cin * area, o * cin * area);
            weight[dst..dst + old_cin * area]
                .copy_from_slice(&old_weight[src..src + old_cin * area]);
        }
        let mut hidden = net.hidden.clone();
        hidden[0] = conv_from_values(weight, bias, cout, cin, k, device);
        Ok(Network {
            hidden,
            output: net.output.clone(),
            weighting: net.weighting,
            unet: net.unet.clone(),
        }
        .with_stable_ids())
    }
}

/// Numbers a network's parameters 0, 1, 2, … in module order. Burn draws every new
/// parameter's id at random, and the ids are stored in the weight, checkpoint and optimizer
/// files: with drawn ids two identical trainings would write different files.
struct StableIds {
    next: u64,
}

impl burn::module::ModuleMapper for StableIds {
    fn map_float<const D: usize>(&mut self, mut param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        param.id = burn::module::ParamId::from(self.next);
        self.next += 1;
        param
    }
}

impl Network {
    /// This network with its parameters numbered in module order ([`StableIds`]).
    fn with_stable_ids(self) -> Self {
        self.map(&mut StableIds { next: 0 })
    }
}

/// Raw output (bias) given to the new outer entries when [`ModelConfig::grow`] widens the
/// combination window: small, so the grown network computes nearly what the old one did, and
/// positive, so ReLU lets gradients reach them.
pub const NEW_WINDOW_ENTRY: f32 = 1e-3;

/// A convolution's weights `[cout, cin, k, k]` and bias as host vectors.
fn conv_values(conv: &Conv2d) -> Result<(Vec<f32>, Vec<f32>), String> {
    let values = |t: Tensor<1>| {
        t.into_data()
            .try_to_vec::<f32>()
            .map_err(|e| format!("weights are not f32: {e:?}"))
    };
    let weight = values(conv.weight.val().flatten(0, 3))?;
    let bias = match &conv.bias {
        Some(b) => values(b.val())?,
        None => vec![0.0; conv.weight.shape().dims::<4>()[0]],
    };
    Ok((weight, bias))
}

/// Checks a level choice: ỹ (0) first, at least one correlated level, indices increasing and
/// below [`LEVELS`] (Eq. 6 pairs ỹ with each correlated estimate).
pub fn validate_levels(levels: &[usize]) -> Result<(), String> {
    if levels.first() != Some(&0) {
        return Err(format!(
            "levels must start with 0 (the independent estimate y), got {levels:?}"
        ));
    }
    if levels.len() < 2 {
        return Err(format!(
            "levels need y and at least one correlated level z1..z4, got {levels:?}"
        ));
    }
    if levels.windows(2).any(|w| w[0] >= w[1]) || levels.iter().any(|&l| l >= LEVELS) {
        return Err(format!(
            "levels must be increasing indices below {LEVELS} (0 = y, 1..4 = z1..z4), got {levels:?}"
        ));
    }
    Ok(())
}

/// Uniform f32 in [0, 1) from the top 24 bits of a PCG draw.
fn unit_f32(rng: &mut Pcg64Mcg) -> f32 {
    (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// `n` Glorot-uniform draws for a `kernel`×`kernel` convolution from `cin` to `cout` channels:
/// uniform in ±sqrt(6 / ((cin + cout)·kernel²)).
fn glorot_values(n: usize, cin: usize, cout: usize, kernel: usize, rng: &mut Pcg64Mcg) -> Vec<f32> {
    let limit = (6.0 / ((cin + cout) * kernel * kernel) as f64).sqrt() as f32;
    (0..n)
        .map(|_| (2.0 * unit_f32(rng) - 1.0) * limit)
        .collect()
}

/// A "same"-padded convolution with Glorot-uniform weights and a zero bias.
fn glorot_conv(
    cin: usize,
    cout: usize,
    kernel: usize,
    rng: &mut Pcg64Mcg,
    device: &Device,
) -> Conv2d {
    let weights = glorot_values(cout * cin * kernel * kernel, cin, cout, kernel, rng);
    conv_from_values(weights, vec![0.0f32; cout], cout, cin, kernel, device)
}

/// A "same"-padded convolution with the given weights `[cout, cin, kernel, kernel]` and bias.
fn conv_from_values(
    weights: Vec<f32>,
    bias: Vec<f32>,
    cout: usize,
    cin: usize,
    kernel: usize,
    device: &Device,
) -> Conv2d {
    let weight = Param::from_data(
        TensorData::new(weights, [cout, cin, kernel, kernel]),
        device,
    );
    let bias = Param::from_data(TensorData::new(bias, [cout]), device);
    let pad = kernel / 2;
    Conv2d {
        weight,
        bias: Some(bias),
        stride: [1, 1],
        kernel_size: [kernel, kernel],
        dilation: [1, 1],
        groups: 1,
        padding: PaddingConfig2d::Explicit(pad, pad, pad, pad),
    }
}

/// The convolution stack: features `[B, 27, H, W]` → raw weights `[B, (m−1)·|Ω|, H, W]`.
#[derive(Module, Debug)]
pub struct Network {
    /// Hidden convolutions, each followed by ReLU (a U-Net's in the order of its plan).
    pub hidden: Vec<Conv2d>,
    /// Last convolution producing one raw weight per level pair and window entry.
    pub output: Conv2d,
    /// Positive-weight transform applied by [`Network::weights`].
    #[module(skip)]
    pub weighting: Weighting,
    /// How the hidden convolutions connect when they form a U-Net ([`crate::unet`]); `None`:
    /// one after the other at full resolution. Not a parameter: it comes from the config.
    #[module(skip)]
    pub unet: Option<UNet>,
}

impl Network {
    /// Raw (unconstrained) network output.
    pub fn forward(&self, features: Tensor<4>) -> Tensor<4> {
        if let Some(unet) = &self.unet {
            let [_, _, height, width] = features.dims();
            let whole = [0, 0, width, height];
            let x = forward_region(unet, &self.hidden, features, whole, whole, width, height);
            return self.output.forward(x);
        }
        let mut x = features;
        for conv in &self.hidden {
            x = relu(conv.forward(x));
        }
        self.output.forward(x)
    }

    /// Positive, unnormalised combination weights `[B, (m−1)·|Ω|, H, W]` (normalisation happens
    /// in the combination, after the out-of-image entries are masked).
    pub fn weights(&self, features: Tensor<4>) -> Tensor<4> {
        positive_weights(self.forward(features), self.weighting)
    }
}

/// Applies the configured positive transform to raw network outputs.
pub fn positive_weights(raw: Tensor<4>, weighting: Weighting) -> Tensor<4> {
    match weighting {
        Weighting::Relu => relu(raw).add_scalar(1e-4),
        Weighting::Softmax => {
            // Subtracting the per-pixel maximum keeps exp() finite; it cancels in the
            // normalisation, so the result is the softmax over all entries.
            let max = raw.clone().detach().max_dim(1);
            (raw - max).exp()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::combine::reconstruct;
    use crate::features::PackedImage;
    use crate::synthetic::synthetic_sample;
    use burn::tensor::{Device, Tensor, TensorData};

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

    /// The shipped `small` weights' model.json (no `unet` key) loads as the `small` preset with
    /// its screen levels, a plain stack, and is written back as it is; the default weights'
    /// model.json loads as the `unet` preset with the same screen levels; a model.json written before screen
    /// levels existed loads without them and is written back without the key; a U-Net's config
    /// round-trips, and a misspelt key inside `unet` is refused like one outside it.
    #[test]
    fn model_json_files_without_unet_load_as_before() {
        let shipped = include_str!("../../models/small/model.json");
        let config: ModelConfig = serde_json::from_str(shipped).unwrap();
        assert_eq!(
            ModelConfig {
                screen_levels: Vec::new(),
                direct_filter: None,
                ..config.clone()
            },
            ModelConfig::preset(Preset::Small)
        );
        assert!(config.unet.is_none());
        assert_eq!(config.screen_levels.len(), 1);
        config.validate().unwrap();
        let written = serde_json::to_value(&config).unwrap();
        assert_eq!(
            written,
            serde_json::from_str::<serde_json::Value>(shipped).unwrap()
        );
        // The weights shipped until 2026-11-28 had this model.json.
        let older = r#"{"preset": "small", "in_channels": 27, "hidden_layers": 5, "filters": 32,
            "kernel": 5, "window": 11, "weighting": "relu", "levels": [0, 1, 2, 3, 4],
            "guard": 16.0, "guard_target_noise": 8.0}"#;
        let config: ModelConfig = serde_json::from_str(older).unwrap();
        assert_eq!(config, ModelConfig::preset(Preset::Small));
        assert_eq!(
            serde_json::to_value(&config).unwrap(),
            serde_json::from_str::<serde_json::Value>(older).unwrap()
        );

        let unet = ModelConfig::preset(Preset::UNet);
        unet.validate().unwrap();
        // The shipped weights: the `unet` preset reading the two extra planes (since
        // 2026-12-06); their predecessor `models/unet-es2` reads the paper's 27.
        let default = include_str!("../../models/default/model.json");
        let config: ModelConfig = serde_json::from_str(default).unwrap();
        config.validate().unwrap();
        use crate::features::ExtraFeature;
        let planes = vec![ExtraFeature::Disagreement, ExtraFeature::Passes];
        assert_eq!(config.in_channels, 32);
        assert_eq!(
            ModelConfig {
                screen_levels: Vec::new(),
                direct_filter: None,
                guard_target_noise: unet.guard_target_noise,
                ..config.clone()
            },
            unet.clone().with_extra_features(planes)
        );
        let before = include_str!("../../models/unet-es2/model.json");
        let before: ModelConfig = serde_json::from_str(before).unwrap();
        assert_eq!(
            before,
            ModelConfig {
                in_channels: unet.in_channels,
                extra_features: Vec::new(),
                ..config.clone()
            }
        );
        assert_eq!(config.screen_levels.len(), 1);
        // The shipped weights trust the screen-filtered smoothest level less than the presets
        // do (journal/2026-12-04-guard-lambda.md).
        assert_eq!(config.guard_target_noise, 32.0);
        let text = serde_json::to_string(&unet).unwrap();
        assert!(text.contains(r#""preset":"unet""#), "{text}");
        assert!(
            text.contains(r#""unet":{"widths":[16,32,48,64],"convs":[1,2,2,2]}"#),
            "{text}"
        );
        assert_eq!(serde_json::from_str::<ModelConfig>(&text).unwrap(), unet);
        let misspelt = text.replace(r#""convs""#, r#""conv""#);
        assert!(serde_json::from_str::<ModelConfig>(&misspelt).is_err());
        // The counts that describe the U-Net must agree with its layout.
        let wrong = ModelConfig {
            hidden_layers: 9,
            ..unet.clone()
        };
        assert!(wrong.validate().unwrap_err().contains("hidden layers"));
    }

    #[test]
    fn unet_preset_costs_a_fifteenth_of_small_and_sees_further() {
        // Multiply-adds per full-resolution pixel of the hidden convolutions and output layer.
        let macs = |c: &ModelConfig| -> usize {
            let k2 = c.kernel * c.kernel;
            let out = c.out_channels() * c.output_kernel().pow(2);
            match &c.unet {
                None => {
                    let first = c.in_channels * c.filters * k2;
                    first + (c.hidden_layers - 1) * c.filters * c.filters * k2 + c.filters * out
                }
                Some(u) => {
                    let steps = u.plan(c.in_channels);
                    let hidden: usize = steps
                        .iter()
                        .filter_map(|s| match &s.op {
                            crate::unet::Op::Conv { inputs, .. } => {
                                let cin: usize = inputs.iter().map(|&i| steps[i].channels).sum();
                                Some(cin * s.channels * k2 / 4usize.pow(s.scale as u32))
                            }
                            _ => None,
                        })
                        .sum();
                    hidden + c.filters * out
                }
            }
        };
        let small = ModelConfig::preset(Preset::Small);
        let unet = ModelConfig::preset(Preset::UNet);
        assert_eq!(macs(&small), 511_200);
        assert_eq!(macs(&unet), 33_952);
        assert_eq!(unet.out_channels(), small.out_channels());
        assert_eq!(
            (small.receptive_radius(), unet.receptive_radius()),
            (12, 43)
        );
    }

    #[test]
    fn unet_is_not_grown() {
        let device = Device::flex();
        let small = ModelConfig::preset(Preset::Small);
        let unet = ModelConfig::preset(Preset::UNet);
        let tiny_unet = ModelConfig::preset(Preset::Tiny);
        let why = unet.growth_obstacle(&small).unwrap();
        assert!(
            why.contains("U-Net") && why.contains("this network is"),
            "{why}"
        );
        let why = small.growth_obstacle(&unet).unwrap();
        assert!(why.contains("the trained network is"), "{why}");
        let err = unet
            .grow(&unet, &unet.init(1, &device), 2, &device)
            .unwrap_err();
        assert!(
            err.starts_with("cannot grow the network") && err.contains("both"),
            "{err}"
        );
        // Plain stacks still grow.
        assert!(small.growth_obstacle(&tiny_unet).is_some()); // (other kernel)
        assert!(ModelConfig::preset(Preset::Medium)
            .growth_obstacle(&small)
            .is_none());
    }

    /// A U-Net reading extra feature planes: its config counts them, round-trips through JSON,
    /// and trained weights without them start it computing the same raw output (zero weights
    /// from the new planes, whatever their values); configs that do not just add planes are
    /// refused.
    #[test]
    fn extra_features_start_from_the_same_function() {
        use crate::features::{pack_with, ExtraFeature};
        use crate::synthetic::{synthetic_bundle, with_distinct_biases};
        let device = Device::flex();
        let plain = ModelConfig::preset(Preset::UNet);
        let extra = vec![ExtraFeature::Disagreement, ExtraFeature::Passes];
        let wide = plain.clone().with_extra_features(extra.clone());
        assert_eq!(wide.in_channels, INPUT_CHANNELS + 5);
        wide.validate().unwrap();
        let json = serde_json::to_string(&wide).unwrap();
        assert!(
            json.contains(r#""extra_features":["disagreement","passes"]"#),
            "{json}"
        );
        assert_eq!(serde_json::from_str::<ModelConfig>(&json).unwrap(), wide);
        assert!(!serde_json::to_string(&plain)
            .unwrap()
            .contains("extra_features"));
        let dual = wide.clone().with_levels(vec![0, 2]);
        assert_eq!(dual.in_channels, input_channels(2) + 2);

        let net = with_distinct_biases(plain.init(5, &device));
        let widened = wide.with_new_inputs(&plain, &net, &device).unwrap();
        let (mut bundle, _) = synthetic_bundle(24, 16, 0.3, 8);
        bundle.meta.passes = 64;
        let forward = |network: &Network, config: &ModelConfig| -> Vec<f32> {
            let packed = pack_with(&bundle, &config.packing()).unwrap();
            let f = Tensor::<4>::from_data(
                TensorData::new(packed.features, [1, config.in_channels, 16, 24]),
                &device,
            );
            network.forward(f).into_data().try_to_vec::<f32>().unwrap()
        };
        let (before, after) = (forward(&net, &plain), forward(&widened, &wide));
        let scale = before.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let worst = before
            .iter()
            .zip(&after)
            .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
        assert!(worst <= 1e-5 * scale, "{worst} against a scale of {scale}");
        // A network reading the extra planes with its own weights computes something else.
        let fresh = forward(&with_distinct_biases(wide.init(5, &device)), &wide);
        assert!(fresh
            .iter()
            .zip(&before)
            .any(|(a, b)| (a - b).abs() > 1e-3 * scale));

        let reordered = plain
            .clone()
            .with_extra_features(vec![ExtraFeature::Passes, ExtraFeature::Disagreement]);
        let from = plain
            .clone()
            .with_extra_features(vec![ExtraFeature::Disagreement]);
        let why = reordered.input_growth_obstacle(&from).unwrap();
        assert!(why.contains("extra_features"), "{why}");
        assert!(wide.input_growth_obstacle(&from).is_none());
        assert!(wide.input_growth_obstacle(&wide).is_some());
        let other = ModelConfig {
            window: 9,
            ..wide.clone()
        };
        let err = other.with_new_inputs(&plain, &net, &device).unwrap_err();
        assert!(err.contains("only extra_features may differ"), "{err}");
        let twice = ModelConfig {
            extra_features: vec![ExtraFeature::Passes, ExtraFeature::Passes],
            in_channels: INPUT_CHANNELS + 2,
            ..plain.clone()
        };
        assert!(twice.validate().unwrap_err().contains("twice"));
        let miscounted = ModelConfig {
            in_channels: INPUT_CHANNELS,
            ..wide.clone()
        };
        assert!(miscounted.validate().unwrap_err().contains("in_channels"));
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
