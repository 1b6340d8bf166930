//! Synthetic multi-level bundles with a known truth, and networks with chosen biases, for
//! tests and smoke runs.
//!
//! The truth is a smooth pattern plus edges. ỹ is the truth plus independent noise (unbiased,
//! noisy, like the sharpest SPPM level gathered by path A); z̃1..z̃4 are box blurs of radius
//! 1..4 of the truth plus a second, shared noise field (correlated with each other, less noisy
//! and increasingly biased, like path B's nested bandwidths).

use bundle::{Bundle, BundleMeta, Image};
use burn::module::{Module, ModuleMapper, Param};
use burn::tensor::{Device, Tensor, TensorData};
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg64Mcg;

use crate::combine::reconstruct;
use crate::features::{interleaved, pack, planar_reference};
use crate::network::{ModelConfig, Network};
use crate::sample::Sample;

/// Approximately standard-normal noise (sum of four uniforms, rescaled).
fn gaussian(rng: &mut Pcg64Mcg) -> f32 {
    let s: f32 = (0..4)
        .map(|_| (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32)
        .sum();
    (s - 2.0) * (3.0f32).sqrt()
}

/// The truth at pixel (x, y), channel c.
fn truth(x: usize, y: usize, c: usize, phase: f32) -> f32 {
    let (fx, fy) = (x as f32, y as f32);
    let smooth = 0.6 + 0.35 * (fx / 6.0 + phase).sin() * (fy / 9.0 - phase).cos();
    let edge = if (fx + 0.7 * fy + 9.0 * phase) % 23.0 < 7.0 {
        0.8
    } else {
        0.0
    };
    (smooth + edge) * [1.0, 0.8, 0.6][c]
}

/// Box blur of radius `r` with clamped borders, planar RGB `[3][h*w]`.
fn box_blur(src: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let mut out = vec![0.0; src.len()];
    for c in 0..3 {
        for y in 0..h {
            for x in 0..w {
                let (mut sum, mut n) = (0.0, 0.0);
                for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                    for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                        sum += src[c * w * h + yy * w + xx];
                        n += 1.0;
                    }
                }
                out[c * w * h + y * w + x] = sum / n;
            }
        }
    }
    out
}

/// A synthetic bundle and its planar RGB truth; `noise` is ỹ's noise standard deviation.
pub fn synthetic_bundle(w: usize, h: usize, noise: f32, seed: u64) -> (Bundle, Image) {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let phase = (rng.next_u32() % 1000) as f32 / 100.0;
    let pixels = w * h;
    let mut t = vec![0.0f32; 3 * pixels];
    for c in 0..3 {
        for y in 0..h {
            for x in 0..w {
                t[c * pixels + y * w + x] = truth(x, y, c, phase);
            }
        }
    }
    let y_level: Vec<f32> = t
        .iter()
        .map(|&v| (v + noise * gaussian(&mut rng)).max(0.0))
        .collect();
    let noisy_b: Vec<f32> = t
        .iter()
        .map(|&v| (v + noise * gaussian(&mut rng)).max(0.0))
        .collect();
    let mut levels = vec![interleaved(&y_level, w, h, 3)];
    let mut variance = vec![0.0f32; 5 * pixels];
    variance[..pixels].fill(noise * noise);
    for r in 1..=4 {
        levels.push(interleaved(&box_blur(&noisy_b, w, h, r), w, h, 3));
        let n = ((2 * r + 1) * (2 * r + 1)) as f32;
        variance[r * pixels..(r + 1) * pixels].fill(noise * noise / n);
    }
    let mut albedo = Image::new(w, h, 3);
    albedo.data.fill(0.5);
    let mut normal = Image::new(w, h, 3);
    for p in 0..pixels {
        normal.data[p * 3 + 2] = 1.0;
    }
    let mut depth = Image::new(w, h, 1);
    for (p, d) in depth.data.iter_mut().enumerate() {
        *d = 2.0 + (p % w) as f32 * 0.01;
    }
    let bundle = Bundle {
        meta: BundleMeta {
            scene: format!("synthetic-{seed}"),
            seed,
            passes: 1,
            photons_per_pass: 0,
            seconds: 0.0,
            integrator: "synthetic".into(),
            schedule: bundle::DEFAULT_SCHEDULE.into(),
            emitter_samples: 1,
            sharp_level: "a".into(),
            sampler: "independent".into(),
            width: w as u32,
            height: h as u32,
        },
        levels,
        variance: interleaved(&variance, w, h, 5),
        albedo,
        normal,
        depth,
        radius: None,
        direct: None,
    };
    (bundle, interleaved(&t, w, h, 3))
}

/// A packed synthetic sample (see [`synthetic_bundle`]).
pub fn synthetic_sample(w: usize, h: usize, noise: f32, seed: u64) -> Sample {
    let (bundle, reference) = synthetic_bundle(w, h, noise, seed);
    let packed = pack(&bundle).expect("synthetic bundle is well formed");
    let reference = planar_reference(&reference, w, h).expect("synthetic reference is well formed");
    Sample { packed, reference }
}

/// Sets every bias (the networks' only 1-D parameters) from its index over all biases in
/// module order.
struct SetBiases<F: FnMut(usize) -> f32> {
    /// The value of bias entry n.
    value: F,
    /// Bias entries set so far.
    next: usize,
}

impl<F: FnMut(usize) -> f32> ModuleMapper for SetBiases<F> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        if D != 1 {
            return param;
        }
        param.map(|t| {
            let dims = t.dims();
            let values: Vec<f32> = (self.next..self.next + dims[0])
                .map(&mut self.value)
                .collect();
            self.next += dims[0];
            Tensor::from_data(TensorData::new(values, dims), &t.device())
        })
    }
}

/// `network` with bias entry n (over all layers, in module order) set to `value(n)`.
pub fn with_biases(network: Network, value: impl FnMut(usize) -> f32) -> Network {
    network.map(&mut SetBiases { value, next: 0 })
}

/// `network` with distinct non-zero biases (`init` gives zero ones, which leave a bias path
/// untested): entry n gets ±0.3·(2·frac(0.3 + n·0.618…) − 1), different from channel to channel
/// and layer to layer, so a bias skipped or read from another layer or channel shows.
pub fn with_distinct_biases(network: Network) -> Network {
    with_biases(network, |n| {
        (0.3 * (2.0 * (0.3 + n as f64 * 0.618_033_988_749_895).fract() - 1.0)) as f32
    })
}

/// A convolution's bias values.
pub fn conv_bias(conv: &burn::nn::conv::Conv2d) -> Vec<f32> {
    let b = conv.bias.as_ref().expect("convolutions have a bias");
    b.val().into_data().try_to_vec::<f32>().unwrap_or_default()
}

/// Parameter values of a network, flattened in visiting order (weights, then bias, layer by
/// layer).
pub fn parameters(network: &Network) -> Vec<f32> {
    let mut out = Vec::new();
    for conv in network
        .hidden
        .iter()
        .chain(std::iter::once(&network.output))
    {
        out.extend(
            conv.weight
                .val()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap_or_default(),
        );
        out.extend(conv_bias(conv));
    }
    out
}

/// The reconstruction (network + combination, clamped at zero) of the 12×10 synthetic sample
/// of `seed`, planar RGB.
pub fn synthetic_reconstruction(
    network: &Network,
    config: &ModelConfig,
    seed: u64,
    device: &Device,
) -> Vec<f32> {
    let s = synthetic_sample(12, 10, 0.3, seed);
    let f = Tensor::<4>::from_data(
        TensorData::new(s.packed.features.clone(), [1, 27, 10, 12]),
        device,
    );
    let l = Tensor::<4>::from_data(
        TensorData::new(s.packed.levels.clone(), [1, 15, 10, 12]),
        device,
    );
    reconstruct(network, config, f, l)
        .into_data()
        .try_to_vec::<f32>()
        .unwrap_or_default()
}

/// The raw network output on the features of the 12×10 synthetic sample of seed 4.
pub fn synthetic_raw_output(network: &Network, device: &Device) -> Vec<f32> {
    let s = synthetic_sample(12, 10, 0.3, 4);
    let f = Tensor::<4>::from_data(
        TensorData::new(s.packed.features.clone(), [1, 27, 10, 12]),
        device,
    );
    network
        .forward(f)
        .into_data()
        .try_to_vec::<f32>()
        .unwrap_or_default()
}

/// The largest difference between `a` and `b` relative to the magnitude (at least 1).
pub fn max_relative_difference(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len(), "compared slices differ in length");
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / x.abs().max(1.0))
        .fold(0.0f32, f32::max)
}
