//! The multi-level combination of paper Eq. 6 with image-border handling.
//!
//! ŷ_c = Σ_j Σ_{i∈Ω_c} w^j_i (ỹ_i + z̃^j_c − z̃^j_i) / Σ_j Σ_{i∈Ω_c} w^j_i
//!
//! rewritten as Σ_j [Σ_i w^j_i (ỹ_i − z̃^j_i) + (Σ_i w^j_i) z̃^j_c] / W_c, so the window gather
//! is needed only for the differences d^j = ỹ − z̃^j. The gather is `unfold4d` on an explicitly
//! zero-padded input (with padding in the unfold options Burn would run a one-hot convolution),
//! one window row at a time so that no buffer holds the whole window of every pixel.
//! Window entries outside the image get zero weight and W_c is the sum of the remaining ones,
//! so the weights are renormalised over the pixels that exist.
//!
//! The safeguard ([`combine_guarded_block`], `guard` in the model's config) then pulls each
//! pixel towards the smoothest combined level where Eq. 6 departs from it by less than its
//! estimated noise (docs/method.md §5.4); `reconstruct` is what training and inference output.

use burn::tensor::module::unfold4d;
use burn::tensor::ops::{PadMode, UnfoldOptions};
use burn::tensor::{Device, Tensor, TensorData};

use crate::network::{ModelConfig, Network};

/// 1 where window entry k of pixel p lies inside the `height`×`width` image, else 0; shape
/// `[1, 1, 1, window², height·width]`, entries ordered like `unfold4d` (row-major offsets).
pub fn inside_mask(height: usize, width: usize, window: usize, device: &Device) -> Tensor<5> {
    let r = window / 2;
    block_mask(height, width, window, [r; 4], device)
}

/// The window mask of a `height`×`width` block of pixels cut out of a larger image: 1 where
/// window entry k of pixel p lies on an image pixel, else 0; shape `[1, 1, 1, window²,
/// height·width]`. `margins` `[top, bottom, left, right]` is how many of the window's reach
/// `r = window / 2` on each side lies outside the image (r at an image border, 0 where the image
/// continues for at least r pixels).
pub fn block_mask(
    height: usize,
    width: usize,
    window: usize,
    margins: [usize; 4],
    device: &Device,
) -> Tensor<5> {
    let r = window / 2;
    let [top, bottom, left, right] = margins;
    // Entry (ki, kj) of pixel (py, px) reads padded position (py + ki, px + kj); the image
    // covers padded rows [top, height + 2r − bottom) and columns [left, width + 2r − right).
    let (rows, cols) = (top..height + 2 * r - bottom, left..width + 2 * r - right);
    let area = window * window;
    let pixels = height * width;
    let mut mask = vec![0.0f32; area * pixels];
    for ki in 0..window {
        for kj in 0..window {
            let row = &mut mask[(ki * window + kj) * pixels..][..pixels];
            for py in (0..height).filter(|py| rows.contains(&(py + ki))) {
                for px in (0..width).filter(|px| cols.contains(&(px + kj))) {
                    row[py * width + px] = 1.0;
                }
            }
        }
    }
    Tensor::from_data(TensorData::new(mask, [1, 1, 1, area, pixels]), device)
}

/// Positive weights of `pairs` correlated levels masked to the image: `weights`
/// `[B, pairs·|Ω|, H, W]` → `[B, pairs, 1, |Ω|, H·W]` (`margins` as in [`block_mask`]).
fn masked_weights(
    weights: Tensor<4>,
    window: usize,
    pairs: usize,
    margins: [usize; 4],
) -> Tensor<5> {
    let [batch, channels, height, width] = weights.dims();
    let area = window * window;
    assert_eq!(
        channels,
        pairs * area,
        "weights need (m-1)*window^2 = {} channels, got {channels}",
        pairs * area
    );
    let mask = block_mask(height, width, window, margins, &weights.device());
    weights.reshape([batch, pairs, 1, area, height * width]) * mask
}

/// Combines m levels with per-pixel window weights (paper Eq. 6).
///
/// `levels`: raw linear colours `[B, 3·m, H, W]` ordered ỹ then the correlated levels (RGB
/// each; m = 5 for ỹ, z̃1..z̃4, m = 2 for a dual network);
/// `weights`: positive weights `[B, (m−1)·window², H, W]`, pair-major then window row-major;
/// returns ŷ `[B, 3, H, W]`.
pub fn combine(levels: Tensor<4>, weights: Tensor<4>, window: usize) -> Tensor<4> {
    combine_block(levels, weights, window, [window / 2; 4])
}

/// [`combine`] for a block of pixels cut out of a larger image (tiled inference): `weights`
/// `[B, (m−1)·window², h, w]` are those of the block's pixels, `levels` cover the block grown
/// by the window reach r = window / 2 except `margins` `[top, bottom, left, right]` — the
/// part of the reach outside the image on each side (r at an image border, 0 inside). Returns
/// ŷ `[B, 3, h, w]`, equal to the whole-image [`combine`] at those pixels.
pub fn combine_block(
    levels: Tensor<4>,
    weights: Tensor<4>,
    window: usize,
    margins: [usize; 4],
) -> Tensor<4> {
    combine_guarded_block(levels, weights, None, window, margins)
}

/// The safeguard's inputs: the raw variances of the combined levels at the output pixels
/// `[B, m, h, w]` (ỹ first, as the levels) and its two constants.
pub struct Guard {
    /// Variance of the mean of each combined level, ỹ first.
    pub variances: Tensor<4>,
    /// Strength κ (> 0): how many times Eq. 6's own noise a departure must exceed to be kept.
    pub strength: f32,
    /// Trust λ (≥ 0) in the smoothest level: how much of that level's own variance counts as a
    /// reason to keep Eq. 6 (0: the smoothest level is taken as exact).
    pub target_noise: f32,
}

/// [`combine_block`] followed, with a [`Guard`], by the safeguard of docs/method.md §5.4: with
/// z̃ₛ the smoothest combined level at the pixel and Δ = ŷ − z̃ₛ, the output is z̃ₛ + k·Δ with
///
///   k = 1 / (1 + (κ·V / (Δ² + λ·v_s))²),
///
/// V an estimate of the variance of Eq. 6 itself,
///
///   V = Σ_j (Σ_i (w^j_i)² / W²) (v_ỹ + v_j) + Σ_j (W_j / W)² v_j,
///
/// W_j = Σ_i w^j_i, W = Σ_j W_j, v the variances of the levels' means at the pixel itself
/// (the window's pixels are taken to be as noisy as its centre, and the levels independent),
/// v_s the smoothest level's. Where Eq. 6 departs from a calm smoothest level by less than its
/// own noise, the output stays near that level; where the departure is well beyond it (a bias
/// the network removes), or where the smoothest level is itself noisy (a caustic photon caught
/// by its wide kernel: v_s large), Eq. 6 is kept. The squared ratio makes the switch sharp: a
/// departure of 8 standard deviations at κ = 16 keeps 94 % of Δ, not the 80 % of a plain
/// Δ²/(Δ² + κV), so a real bias of the smoothest level is not half put back. Any blend
/// between two estimates that converge converges, so consistency holds.
pub fn combine_guarded_block(
    levels: Tensor<4>,
    weights: Tensor<4>,
    guard: Option<Guard>,
    window: usize,
    margins: [usize; 4],
) -> Tensor<4> {
    let [batch, channels, _, _] = levels.dims();
    let [_, _, height, width] = weights.dims();
    assert!(
        channels >= 6 && channels % 3 == 0,
        "levels need 3·m channels with m ≥ 2, got {channels}"
    );
    let pairs = channels / 3 - 1;
    assert_eq!(window % 2, 1, "window must be odd");
    let r = window / 2;
    let [top, bottom, left, right] = margins;
    assert!(
        margins.iter().all(|&m| m <= r),
        "margins exceed the window reach"
    );
    assert_eq!(
        levels.dims()[2..],
        [height + 2 * r - top - bottom, width + 2 * r - left - right],
        "levels must cover the weights' pixels grown by the window reach less the margins"
    );
    let pixels = height * width;

    let y = levels.clone().narrow(1, 0, 3);
    let z = levels.narrow(1, 3, 3 * pairs);
    let differences = y.repeat_dim(1, pairs) - z.clone();
    let padded = differences.pad([(top, bottom), (left, right)], PadMode::Constant(0.0));
    // z̃ at the block's own pixels (the window centres).
    let z = if margins == [r; 4] {
        z
    } else {
        z.narrow(2, r - top, height).narrow(3, r - left, width)
    };
    let z = z.reshape([batch, pairs, 3, 1, pixels]);

    let w = masked_weights(weights, window, pairs, margins);
    let weight_sums = w.clone().sum_dim(3); // [B, 4, 1, 1, HW]
    let squares = guard.as_ref().map(|_| (w.clone() * w.clone()).sum_dim(3));
    // Σ_i w^j_i d^j_i, gathered one window row at a time: the whole window at once is
    // 3·(m−1)·|Ω| floats per pixel (4 332 for the 19×19 window) in one buffer, which exceeds
    // a GPU's largest buffer (≈ 2 GB) at a training batch of 64 patches of 64²; a row is
    // 1/window of that.
    let mut window_term: Option<Tensor<5>> = None;
    for row in 0..window {
        let gathered = unfold4d(
            padded.clone().narrow(2, row, height),
            [1, window],
            UnfoldOptions::new([1, 1], [0, 0], [1, 1]),
        )
        .reshape([batch, pairs, 3, window, pixels]);
        let term = (gathered * w.clone().narrow(3, row * window, window)).sum_dim(3);
        window_term = Some(match window_term {
            None => term,
            Some(sum) => sum + term,
        });
    }
    let window_term = window_term.expect("the window has at least one row"); // [B, 4, 3, 1, HW]
    let centre_term = weight_sums.clone() * z.clone();
    let numerator = (window_term + centre_term).sum_dim(1); // [B, 1, 3, 1, HW]
    let normaliser = weight_sums.clone().sum_dim(1); // [B, 1, 1, 1, HW]
    let combined = numerator / normaliser.clone();
    let (Some(guard), Some(squares)) = (guard, squares) else {
        return combined.reshape([batch, 3, height, width]);
    };
    let v = guard.variances.reshape([batch, pairs + 1, 1, 1, pixels]);
    let v_y = v.clone().narrow(1, 0, 1);
    let v_z = v.narrow(1, 1, pairs);
    let total_squared = normaliser.clone() * normaliser.clone();
    let window_noise = (squares * (v_z.clone() + v_y)).sum_dim(1) / total_squared.clone();
    let shares = weight_sums.clone() * weight_sums / total_squared;
    let centre_noise = (shares * v_z.clone()).sum_dim(1);
    let noise = window_noise + centre_noise; // [B, 1, 1, 1, HW]
    let smoothest_noise = v_z.narrow(1, pairs - 1, 1);
    let smoothest = z.narrow(1, pairs - 1, 1); // [B, 1, 3, 1, HW]
    let delta = combined - smoothest.clone();
    let evidence = delta.clone() * delta.clone()
        + smoothest_noise
            .mul_scalar(guard.target_noise)
            .add_scalar(GUARD_EVIDENCE_FLOOR);
    // Capped before squaring: where the evidence is all but zero (a calm, noise-free smoothest
    // level that Eq. 6 matches) the ratio reaches 1e28 and its square overflows; the kept share
    // is then 0 either way, but the gradient of 1/(1 + inf) is NaN and poisons training (water
    // and metal scenes of data/small, 2026-11-28). At the cap the kept share is 1e-12.
    let ratio = (noise.mul_scalar(guard.strength) / evidence).clamp_max(GUARD_RATIO_CAP);
    let kept = (ratio.clone() * ratio).add_scalar(1.0).recip();
    // A non-finite Eq. 6 (overflow: Δ² = inf, or NaN) is kept as it is, for the caller to report.
    let kept = kept.clone().mask_fill(kept.is_nan(), 1.0);
    (smoothest + delta * kept).reshape([batch, 3, height, width])
}

/// Added to the guard's evidence Δ² + λvₛ, so that it is never zero (a noise-free smoothest
/// level that Eq. 6 matches) and its square, in the ratio's gradient, does not underflow to
/// zero in f32 (1e-30² does: the gradient became −∞ · 0 = NaN).
pub const GUARD_EVIDENCE_FLOOR: f32 = 1e-18;

/// Largest guard ratio κV/(Δ² + λvₛ) used: its square (1e12) stays finite in f32, and so does
/// the gradient of the kept share 1/(1 + ratio²).
pub const GUARD_RATIO_CAP: f32 = 1e6;

/// Raw variances from the network features' log(1 + v) planes (docs/method.md §5.1), exact to
/// float precision also where v is tiny (exp(x) − 1 alone would round those to zero).
pub fn variances_from_features(log_variances: Tensor<4>) -> Tensor<4> {
    let x = log_variances;
    let series =
        x.clone() * (x.clone().mul_scalar(1.0 / 6.0).add_scalar(0.5) * x.clone()).add_scalar(1.0);
    let small = x.clone().lower_elem(1e-3);
    x.exp().sub_scalar(1.0).mask_where(small, series)
}

/// Share of the total weight each pair j carries at each pixel, `[B, m−1, H, W]` (sums to 1):
/// for the full network channel 0 is the sharpest correlated level z̃1, channel 3 the smoothest
/// z̃4 (paper Fig. 6).
pub fn level_weight_shares(weights: Tensor<4>, window: usize) -> Tensor<4> {
    level_weight_shares_block(weights, window, [window / 2; 4])
}

/// [`level_weight_shares`] for a block of pixels cut out of a larger image, `margins` as in
/// [`combine_block`].
pub fn level_weight_shares_block(
    weights: Tensor<4>,
    window: usize,
    margins: [usize; 4],
) -> Tensor<4> {
    let [batch, channels, height, width] = weights.dims();
    let pairs = channels / (window * window);
    let sums = masked_weights(weights, window, pairs, margins).sum_dim(3); // [B, m−1, 1, 1, HW]
    let total = sums.clone().sum_dim(1);
    (sums / total).reshape([batch, pairs, height, width])
}

/// Forward pass of network + combination: `[B, 3, P, P]` reconstruction of a batch, clamped
/// at zero.
///
/// Eq. 6 is a control-variate form (ỹ_i + z̃_c − z̃_i) and goes negative next to bright spots
/// that the smooth levels spread out; the loss (docs/method.md §5.5, Eq. 8) sees ŷ clamped ≥ 0, so the
/// clamped image is what the network was trained to produce — and radiance is never negative.
pub fn reconstruct(
    model: &Network,
    config: &ModelConfig,
    features: Tensor<4>,
    levels: Tensor<4>,
) -> Tensor<4> {
    let guard = guard_of(config, &features);
    let weights = model.weights(features);
    let margins = [config.window / 2; 4];
    combine_guarded_block(levels, weights, guard, config.window, margins).clamp_min(0.0)
}

/// The [`Guard`] of `config` for network input `features` (all pixels of the block), or `None`
/// when its strength is 0: the variances are the features' variance planes, which follow the
/// colour planes of the combined levels ([`crate::features::feature_channels`]).
pub fn guard_of(config: &ModelConfig, features: &Tensor<4>) -> Option<Guard> {
    (config.guard > 0.0).then(|| {
        let m = config.levels.len();
        Guard {
            variances: variances_from_features(features.clone().narrow(1, 3 * m, m)),
            strength: config.guard,
            target_noise: config.guard_target_noise,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Tensor;

    fn device() -> Device {
        Device::flex()
    }

    fn tensor4(data: Vec<f32>, shape: [usize; 4]) -> Tensor<4> {
        Tensor::from_data(TensorData::new(data, shape), &device())
    }

    fn values(t: Tensor<4>) -> Vec<f32> {
        t.into_data().try_to_vec::<f32>().unwrap()
    }

    /// Small deterministic pseudo-random numbers in [lo, hi).
    fn noise(n: usize, seed: u32, lo: f32, hi: f32) -> Vec<f32> {
        let mut s = seed.wrapping_mul(747796405).wrapping_add(2891336453);
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                lo + (hi - lo) * (s >> 8) as f32 / (1u32 << 24) as f32
            })
            .collect()
    }

    /// Eq. 6 evaluated literally with loops, skipping window pixels outside the image.
    fn combine_reference(
        levels: &[f32],
        weights: &[f32],
        h: usize,
        w: usize,
        window: usize,
    ) -> Vec<f32> {
        let r = (window / 2) as isize;
        let hw = h * w;
        let at =
            |level: usize, ch: usize, y: usize, x: usize| levels[(level * 3 + ch) * hw + y * w + x];
        let mut out = vec![0.0f32; 3 * hw];
        for cy in 0..h {
            for cx in 0..w {
                for ch in 0..3 {
                    let (mut num, mut den) = (0.0f64, 0.0f64);
                    for j in 0..4 {
                        for ki in 0..window {
                            for kj in 0..window {
                                let iy = cy as isize + ki as isize - r;
                                let ix = cx as isize + kj as isize - r;
                                if iy < 0 || ix < 0 || iy >= h as isize || ix >= w as isize {
                                    continue;
                                }
                                let (iy, ix) = (iy as usize, ix as usize);
                                let k = ki * window + kj;
                                let wt =
                                    weights[(j * window * window + k) * hw + cy * w + cx] as f64;
                                let v = at(0, ch, iy, ix) + at(j + 1, ch, cy, cx)
                                    - at(j + 1, ch, iy, ix);
                                num += wt * v as f64;
                                den += wt;
                            }
                        }
                    }
                    out[ch * hw + cy * w + cx] = (num / den) as f32;
                }
            }
        }
        out
    }

    #[test]
    fn hand_computed_two_pixel_image_with_borders() {
        // 1x2 image, window 3, all weights 1: pixel 0 sees itself and pixel 1 in each of the
        // four pairs, so W = 8. Per pair Σ_i (y_i + z_c − z_i) = y0 + y1 + z_c − z_other:
        // pixel 0: (4+2−4) + (4+0−0) + (4+1−1) + (4+5−9) = 10 → 1.25
        // pixel 1: (4+4−2) + (4+0−0) + (4+1−1) + (4+9−5) = 22 → 2.75
        let per_level = [[1.0, 3.0], [2.0, 4.0], [0.0, 0.0], [1.0, 1.0], [5.0, 9.0]];
        let mut levels = Vec::new();
        for level in per_level {
            for _ in 0..3 {
                levels.extend(level);
            }
        }
        let levels = tensor4(levels, [1, 15, 1, 2]);
        let weights = tensor4(vec![1.0; 4 * 9 * 2], [1, 36, 1, 2]);
        let out = values(combine(levels, weights, 3));
        for ch in 0..3 {
            assert!((out[ch * 2] - 1.25).abs() < 1e-6, "{out:?}");
            assert!((out[ch * 2 + 1] - 2.75).abs() < 1e-6, "{out:?}");
        }
    }

    #[test]
    fn hand_computed_single_entry_weights() {
        // Only pair 4's entry pointing at the right neighbour (offset (0,+1), k = 5) is non-zero
        // at pixel 0: ŷ_0 = y_1 + z4_0 − z4_1 = 3 + 5 − 9 = −1. At pixel 1 that entry points
        // outside the image and is masked out, so only pair 2's centre (k = 4) counts:
        // ŷ_1 = y_1 + z2_1 − z2_1 = 3.
        let per_level = [[1.0, 3.0], [2.0, 4.0], [0.0, 0.0], [1.0, 1.0], [5.0, 9.0]];
        let mut levels = Vec::new();
        for level in per_level {
            for _ in 0..3 {
                levels.extend(level);
            }
        }
        let mut weights = vec![0.0f32; 36 * 2];
        weights[(3 * 9 + 5) * 2] = 2.0; // pair 4, k = 5, pixel 0
        weights[(3 * 9 + 5) * 2 + 1] = 7.0; // pair 4, k = 5, pixel 1: outside → ignored
        weights[(9 + 4) * 2 + 1] = 0.5; // pair 2, centre, pixel 1
        let out = values(combine(
            tensor4(levels, [1, 15, 1, 2]),
            tensor4(weights, [1, 36, 1, 2]),
            3,
        ));
        for ch in 0..3 {
            assert!((out[ch * 2] + 1.0).abs() < 1e-6, "{out:?}");
            assert!((out[ch * 2 + 1] - 3.0).abs() < 1e-6, "{out:?}");
        }
    }

    #[test]
    fn matches_literal_eq6_on_random_image_with_borders() {
        let (h, w, window) = (5, 4, 5);
        let hw = h * w;
        let levels = noise(15 * hw, 1, 0.0, 2.0);
        let weights = noise(4 * window * window * hw, 2, 0.01, 1.0);
        let expected = combine_reference(&levels, &weights, h, w, window);
        let got = values(combine(
            tensor4(levels, [1, 15, h, w]),
            tensor4(weights, [1, 4 * window * window, h, w]),
            window,
        ));
        for (g, e) in got.iter().zip(&expected) {
            assert!((g - e).abs() < 1e-5, "{g} vs {e}");
        }
    }

    #[test]
    fn a_block_combines_like_the_whole_image() {
        // 9×8 image, window 5 (reach 2); the block rows 1..5, columns 3..8: its reach is
        // clipped by one row at the top, by two columns at the right border, not elsewhere.
        let (h, w, window) = (9, 8, 5);
        let hw = h * w;
        let levels = noise(15 * hw, 11, 0.0, 2.0);
        let weights = noise(4 * 25 * hw, 12, 0.01, 1.0);
        let whole = values(combine(
            tensor4(levels.clone(), [1, 15, h, w]),
            tensor4(weights.clone(), [1, 100, h, w]),
            window,
        ));
        let (y0, y1, x0, x1) = (1, 5, 3, 8);
        let (ly0, ly1, lx0, lx1) = (0, 7, 1, 8); // grown by 2, clipped
        let crop = |data: &[f32], planes: usize, r: (usize, usize, usize, usize)| -> Vec<f32> {
            let mut out = Vec::new();
            for p in 0..planes {
                for y in r.0..r.1 {
                    out.extend_from_slice(&data[p * hw + y * w + r.2..p * hw + y * w + r.3]);
                }
            }
            out
        };
        let block = values(combine_block(
            tensor4(
                crop(&levels, 15, (ly0, ly1, lx0, lx1)),
                [1, 15, ly1 - ly0, lx1 - lx0],
            ),
            tensor4(
                crop(&weights, 100, (y0, y1, x0, x1)),
                [1, 100, y1 - y0, x1 - x0],
            ),
            window,
            [1, 0, 0, 2],
        ));
        let expected = crop(&whole, 3, (y0, y1, x0, x1));
        for (g, e) in block.iter().zip(&expected) {
            assert!((g - e).abs() < 1e-5, "{g} vs {e}");
        }
    }

    #[test]
    fn identical_levels_are_reproduced_whatever_the_weights() {
        let (b, h, w, window) = (2, 6, 7, 5);
        let hw = h * w;
        let image = noise(b * 3 * hw, 3, 0.0, 10.0);
        let mut levels = Vec::new();
        for bi in 0..b {
            for _ in 0..5 {
                levels.extend_from_slice(&image[bi * 3 * hw..(bi + 1) * 3 * hw]);
            }
        }
        for seed in [4, 5, 6] {
            let weights = noise(b * 4 * window * window * hw, seed, 1e-4, 100.0);
            let out = values(combine(
                tensor4(levels.clone(), [b, 15, h, w]),
                tensor4(weights, [b, 4 * window * window, h, w]),
                window,
            ));
            for (o, e) in out.iter().zip(&image) {
                assert!((o - e).abs() <= 1e-5 * e.abs().max(1.0), "{o} vs {e}");
            }
        }
    }

    #[test]
    fn weight_shares_sum_to_one() {
        let (h, w, window) = (3, 4, 3);
        let weights = noise(36 * h * w, 7, 0.0, 1.0);
        let shares = values(level_weight_shares(tensor4(weights, [1, 36, h, w]), window));
        for p in 0..h * w {
            let s: f32 = (0..4).map(|j| shares[j * h * w + p]).sum();
            assert!((s - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn finite_difference_gradient_through_the_combination() {
        let (h, w, window) = (3, 4, 3);
        let hw = h * w;
        let ad = device().autodiff();
        let levels = noise(15 * hw, 8, 0.0, 1.0);
        let weights = noise(36 * hw, 9, 0.2, 1.0);
        let probe = noise(3 * hw, 10, -1.0, 1.0);
        let objective = |levels: Tensor<4>, weights: Tensor<4>, device: &Device| -> Tensor<1> {
            let probe =
                Tensor::<4>::from_data(TensorData::new(probe.clone(), [1, 3, h, w]), device);
            (combine(levels, weights, window) * probe).sum()
        };
        let lv = Tensor::<4>::from_data(TensorData::new(levels.clone(), [1, 15, h, w]), &ad)
            .require_grad();
        let wt = Tensor::<4>::from_data(TensorData::new(weights.clone(), [1, 36, h, w]), &ad)
            .require_grad();
        let grads = objective(lv.clone(), wt.clone(), &ad).backward();
        let g_levels = lv
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let g_weights = wt
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();

        let eval = |levels: &[f32], weights: &[f32]| -> f64 {
            let d = device();
            let v = objective(
                tensor4(levels.to_vec(), [1, 15, h, w]),
                tensor4(weights.to_vec(), [1, 36, h, w]),
                &d,
            );
            v.into_data().try_to_vec::<f32>().unwrap()[0] as f64
        };
        let eps = 1e-2f32;
        for i in (0..levels.len()).step_by(7) {
            let (mut up, mut down) = (levels.clone(), levels.clone());
            up[i] += eps;
            down[i] -= eps;
            let fd = (eval(&up, &weights) - eval(&down, &weights)) / (2.0 * eps as f64);
            assert!(
                (fd - g_levels[i] as f64).abs() < 2e-3 + 1e-2 * fd.abs(),
                "levels[{i}]: fd {fd} vs {}",
                g_levels[i]
            );
        }
        for i in (0..weights.len()).step_by(11) {
            let (mut up, mut down) = (weights.clone(), weights.clone());
            up[i] += eps;
            down[i] -= eps;
            let fd = (eval(&levels, &up) - eval(&levels, &down)) / (2.0 * eps as f64);
            assert!(
                (fd - g_weights[i] as f64).abs() < 2e-3 + 1e-2 * fd.abs(),
                "weights[{i}]: fd {fd} vs {}",
                g_weights[i]
            );
        }
    }

    /// Where Eq. 6 matches a noise-free smoothest level (Δ = 0, v = 0: a black background, a
    /// converged region) the guard's evidence is its floor and its ratio huge: the output and
    /// the gradients with respect to levels and weights must stay finite (they were NaN with a
    /// 1e-30 floor, whose square underflows, and an uncapped ratio, whose square overflows).
    #[test]
    fn guard_gradients_stay_finite_where_the_evidence_vanishes() {
        let ad = device().autodiff();
        for (vy, vz) in [(1e-3f32, 0.0f32), (0.0, 0.0), (1e-3, 1e-30)] {
            let levels =
                Tensor::<4>::from_data(TensorData::new(vec![0.5f32; 6], [1, 6, 1, 1]), &ad)
                    .require_grad();
            let weights = Tensor::<4>::from_data(TensorData::new(vec![1.0f32], [1, 1, 1, 1]), &ad)
                .require_grad();
            let guard = Guard {
                variances: Tensor::<4>::from_data(TensorData::new(vec![vy, vz], [1, 2, 1, 1]), &ad),
                strength: 16.0,
                target_noise: 8.0,
            };
            let out =
                combine_guarded_block(levels.clone(), weights.clone(), Some(guard), 1, [0; 4]);
            let grads = out.sum().backward();
            for g in [
                levels
                    .grad(&grads)
                    .unwrap()
                    .into_data()
                    .try_to_vec::<f32>()
                    .unwrap(),
                weights
                    .grad(&grads)
                    .unwrap()
                    .into_data()
                    .try_to_vec::<f32>()
                    .unwrap(),
            ] {
                assert!(g.iter().all(|v| v.is_finite()), "v = ({vy}, {vz}): {g:?}");
            }
        }
    }

    /// The safeguard by hand on one pixel (1×1 image, window 1, one pair of weight 1): ŷ = ỹ,
    /// z̃ₛ = z̃, Δ = ỹ − z̃, V = (v_ỹ + v_z) + v_z; the output z̃ + Δ / (1 + (κV / (Δ² + λv_z))²).
    #[test]
    fn guard_by_hand_on_one_pixel() {
        let (y, z, vy, vz, kappa, lambda) = (5.0f32, 3.0f32, 0.5f32, 0.25f32, 4.0f32, 2.0f32);
        let mut levels = vec![y; 3];
        levels.extend([z; 3]);
        let guard = Guard {
            variances: tensor4(vec![vy, vz], [1, 2, 1, 1]),
            strength: kappa,
            target_noise: lambda,
        };
        let out = values(combine_guarded_block(
            tensor4(levels, [1, 6, 1, 1]),
            tensor4(vec![1.0], [1, 1, 1, 1]),
            Some(guard),
            1,
            [0; 4],
        ));
        let (delta, noise) = (y - z, vy + 2.0 * vz);
        // κV = 4, Δ² + λv_z = 4.5: the output keeps 1 / (1 + (8/9)²) of Δ.
        let ratio = kappa * noise / (delta * delta + lambda * vz);
        let want = z + delta / (1.0 + ratio * ratio);
        assert!((want - (3.0 + 2.0 * 81.0 / 145.0)).abs() < 1e-6, "{want}");
        for o in out {
            assert!((o - want).abs() < 1e-6, "{o} vs {want}");
        }
    }

    /// The guarded output always lies between Eq. 6 and the smoothest level (a blend of two
    /// estimates that converge converges), equals Eq. 6 with zero variances, tends to the
    /// smoothest level as Eq. 6's noise grows against a calm smoothest level, and keeps Eq. 6
    /// where the smoothest level alone is noisy (λ > 0).
    #[test]
    fn guard_blends_between_eq6_and_the_smoothest_level() {
        let (h, w, window) = (5, 4, 3);
        let hw = h * w;
        let levels = noise(15 * hw, 21, 0.0, 2.0);
        let weights = noise(4 * window * window * hw, 22, 0.01, 1.0);
        // `others` for ỹ, z̃1..z̃3 and `smoothest` for z̃4.
        let run = |others: f32, smoothest: f32| {
            let mut variances = vec![others; 4 * hw];
            variances.extend(vec![smoothest; hw]);
            let guard = Guard {
                variances: tensor4(variances, [1, 5, h, w]),
                strength: 4.0,
                target_noise: 16.0,
            };
            values(combine_guarded_block(
                tensor4(levels.clone(), [1, 15, h, w]),
                tensor4(weights.clone(), [1, 36, h, w]),
                Some(guard),
                window,
                [1; 4],
            ))
        };
        let eq6 = values(combine(
            tensor4(levels.clone(), [1, 15, h, w]),
            tensor4(weights.clone(), [1, 36, h, w]),
            window,
        ));
        let smoothest = &levels[12 * hw..];
        let close = |a: &[f32], b: &[f32], tolerance: f32| {
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() < tolerance, "{x} vs {y}");
            }
        };
        close(&run(0.0, 0.0), &eq6, 1e-5);
        for (others, target) in [(1e-3, 1e-3), (0.1, 0.0), (10.0, 10.0), (0.0, 5.0)] {
            for ((g, e), s) in run(others, target).iter().zip(&eq6).zip(smoothest) {
                let (lo, hi) = (e.min(*s), e.max(*s));
                assert!(
                    *g >= lo - 1e-5 && *g <= hi + 1e-5,
                    "{g} not in [{lo}, {hi}]"
                );
            }
        }
        close(&run(1e6, 1e-3), smoothest, 1e-3);
        // A noisy smoothest level: at least 99 % of Eq. 6's departure from it is kept.
        for ((g, e), s) in run(1e-3, 1e6).iter().zip(&eq6).zip(smoothest) {
            assert!((g - e).abs() <= 1e-2 * (e - s).abs() + 1e-5, "{g} vs {e}");
        }
    }

    #[test]
    fn variances_come_back_from_the_features_log() {
        let v = [0.0f32, 1e-9, 3e-7, 1e-3, 0.5, 40.0];
        let logs: Vec<f32> = v.iter().map(|x| x.ln_1p()).collect();
        let back = values(variances_from_features(tensor4(logs, [1, 6, 1, 1])));
        for (b, x) in back.iter().zip(v) {
            assert!((b - x).abs() <= 1e-6 * x.max(1e-6), "{b} vs {x}");
        }
    }
}
