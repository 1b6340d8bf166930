//! The multi-scale weight predictor (the `unet` preset): a small U-Net that sees far for little
//! arithmetic, with the same output contract as the paper's convolution stack ((m − 1)·|Ω| raw
//! weights per pixel, the same positive transform, Eq. 6 and guard).
//!
//! Why: in the single-resolution presets the context a pixel sees grows by 2 px per 5×5 layer
//! and every layer runs on every pixel; `small` costs ≈ 512 k multiply-adds per pixel for a
//! 12-px receptive radius, 76 % of it in the 5×5 output layer. Here most 3×3 convolutions run
//! at 1/2, 1/4 and 1/8 resolution, where a pixel costs a quarter, a sixteenth, a sixty-fourth,
//! so the receptive radius reaches 43 px, and the output layer is 1×1: ≈ 34 k multiply-adds
//! per pixel for the preset (docs/performance.md, "Inference").
//!
//! Layout ([`UNet::plan`]): scale s = 0 (full resolution) … S − 1. On the way down, scale s
//! runs `convs[s]` 3×3 convolutions of `widths[s]` filters (ReLU after each), then a 2×2
//! average pooling leads to scale s + 1. On the way up, the coarser result is upsampled ×2
//! (nearest neighbour), concatenated with the last activation of scale s on the way down (the
//! skip connection, upsampled channels first), and one 3×3 convolution of `widths[s]` filters
//! with ReLU mixes them. The network's 1×1 output layer reads the full-resolution result.
//!
//! Image sides that are not multiples of 2^(S−1) (explicit, no resizing): scale s + 1 has
//! ⌈side_s / 2⌉ pixels per side; values outside a scale's grid are zero, both for the
//! convolutions ("same" zero padding, as the paper's stack) and for the pooling (a 2×2 block
//! cut by the bottom or right border is averaged with the missing pixels as 0, i.e. still
//! divided by 4); upsampling produces ⌈side_s / 2⌉·2 values and keeps the first side_s.
//!
//! Exact on any sub-rectangle (tiles): every step is computed on the rectangle the steps
//! after it need ([`needed_rects`]: a convolution needs its output grown by the kernel radius,
//! a pooling the doubled rectangle, an upsampling the halved one rounded outwards), clipped to
//! its scale's grid. Clipping happens only at the image border, where the whole-image
//! computation sees the same zeros, so a tile's values equal the whole image's. Both engines
//! (Burn here, the native one in `native.rs`) run this one plan.

use burn::nn::conv::Conv2d;
use burn::tensor::activation::relu;
use burn::tensor::module::conv2d;
use burn::tensor::ops::{ConvOptions, PadMode};
use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

/// A pixel rectangle `[x0, y0, x1, y1)` in the coordinates of one scale's grid.
pub type Rect = [usize; 4];

/// True when `outer` covers `inner`.
pub fn covers(outer: Rect, inner: Rect) -> bool {
    outer[0] <= inner[0] && outer[1] <= inner[1] && outer[2] >= inner[2] && outer[3] >= inner[3]
}

/// The U-Net's layout; saved in `model.json` as `"unet": {"widths": [...], "convs": [...]}`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UNet {
    /// Filters of the convolutions at each scale, full resolution first (its length is the
    /// number of scales S ≥ 2; scale s has 1/2^s of the resolution).
    pub widths: Vec<usize>,
    /// Convolutions at each scale on the way down (each ≥ 1); the way up has one per scale
    /// except the coarsest.
    pub convs: Vec<usize>,
}

/// What one step of the plan computes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Op {
    /// The input features (scale 0).
    Input,
    /// Hidden convolution `layer` of the network (its "same" zero padding on this scale's grid)
    /// followed by ReLU, reading the channels of the steps `inputs` concatenated in order.
    Conv {
        /// Index into [`crate::Network::hidden`].
        layer: usize,
        /// Steps whose outputs are concatenated (channels of the first, then the second …).
        inputs: Vec<usize>,
    },
    /// 2×2 average pooling of a step one scale finer (missing pixels at the border count 0).
    Pool(usize),
    /// Nearest-neighbour ×2 upsampling of a step one scale coarser.
    Upsample(usize),
}

/// One step of the plan: its operation, the scale it lives on and its channels.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Step {
    /// The operation.
    pub op: Op,
    /// Scale (0 = full resolution).
    pub scale: usize,
    /// Output channels.
    pub channels: usize,
}

impl UNet {
    /// The `unet` preset's layout: 16, 32, 48, 64 filters at full, 1/2, 1/4, 1/8 resolution,
    /// one convolution down at full resolution and two at each coarser scale. Narrow at full
    /// resolution, where a filter costs 64 times what it costs at 1/8 (and the 1×1 output layer
    /// reads it), wide where context is gathered cheaply.
    pub fn preset() -> Self {
        Self {
            widths: vec![16, 32, 48, 64],
            convs: vec![1, 2, 2, 2],
        }
    }

    /// Number of scales S.
    pub fn scales(&self) -> usize {
        self.widths.len()
    }

    /// Hidden convolutions in all: the way down and the S − 1 on the way up.
    pub fn hidden_layers(&self) -> usize {
        self.convs.iter().sum::<usize>() + self.scales().saturating_sub(1)
    }

    /// Checks the layout.
    pub fn validate(&self) -> Result<(), String> {
        if self.widths.len() < 2 || self.widths.len() > 8 {
            return Err(format!(
                "unet.widths needs 2 to 8 scales, got {:?}",
                self.widths
            ));
        }
        if self.convs.len() != self.widths.len() {
            return Err(format!(
                "unet.convs needs one count per scale ({}), got {:?}",
                self.widths.len(),
                self.convs
            ));
        }
        if self.widths.contains(&0) || self.convs.contains(&0) {
            return Err(format!(
                "unet.widths and unet.convs must be positive, got {:?} and {:?}",
                self.widths, self.convs
            ));
        }
        Ok(())
    }

    /// The steps in the order they are computed (each reads only earlier ones); the last one
    /// is the full-resolution activation the output layer reads.
    pub fn plan(&self, in_channels: usize) -> Vec<Step> {
        let mut steps = vec![Step {
            op: Op::Input,
            scale: 0,
            channels: in_channels,
        }];
        let mut layer = 0;
        let mut skips = Vec::with_capacity(self.scales());
        for (s, (&width, &convs)) in self.widths.iter().zip(&self.convs).enumerate() {
            if s > 0 {
                let x = steps.len() - 1;
                let channels = steps[x].channels;
                steps.push(Step {
                    op: Op::Pool(x),
                    scale: s,
                    channels,
                });
            }
            for _ in 0..convs {
                let x = steps.len() - 1;
                steps.push(Step {
                    op: Op::Conv {
                        layer,
                        inputs: vec![x],
                    },
                    scale: s,
                    channels: width,
                });
                layer += 1;
            }
            skips.push(steps.len() - 1);
        }
        for s in (0..self.scales() - 1).rev() {
            let x = steps.len() - 1;
            let channels = steps[x].channels;
            steps.push(Step {
                op: Op::Upsample(x),
                scale: s,
                channels,
            });
            steps.push(Step {
                op: Op::Conv {
                    layer,
                    inputs: vec![steps.len() - 1, skips[s]],
                },
                scale: s,
                channels: self.widths[s],
            });
            layer += 1;
        }
        steps
    }

    /// Input and output channels of each hidden convolution, in layer order.
    pub fn conv_shapes(&self, in_channels: usize) -> Vec<(usize, usize)> {
        let steps = self.plan(in_channels);
        steps
            .iter()
            .filter_map(|step| match &step.op {
                Op::Conv { inputs, .. } => Some((
                    inputs.iter().map(|&i| steps[i].channels).sum(),
                    step.channels,
                )),
                _ => None,
            })
            .collect()
    }

    /// Full-resolution pixels of context one output pixel depends on through the hidden
    /// convolutions with `kernel`×`kernel` kernels and an output layer of `output_kernel`: the
    /// widest reach over every alignment of the pixel to the coarsest grid (the halo a tile
    /// needs).
    pub fn reach(&self, kernel: usize, output_kernel: usize) -> usize {
        let steps = self.plan(1);
        // A grid far larger than the reach, so nothing is clipped.
        let side = 1usize << 24;
        let sizes = scale_sizes(side, side, self.scales());
        let base = side / 2;
        (base..base + (1 << self.scales()))
            .map(|p| {
                let out = grow([p, p, p + 1, p + 1], output_kernel / 2, side, side);
                let need = needed_rects(&steps, kernel, out, &sizes);
                let r = need[0].expect("the features are needed");
                (p - r[0]).max(r[2] - 1 - p)
            })
            .max()
            .unwrap_or(0)
    }
}

/// Width and height of every scale's grid: scale s + 1 has ⌈side_s / 2⌉ pixels per side.
pub fn scale_sizes(width: usize, height: usize, scales: usize) -> Vec<(usize, usize)> {
    let mut sizes = vec![(width, height)];
    for _ in 1..scales {
        let (w, h) = sizes[sizes.len() - 1];
        sizes.push((w.div_ceil(2), h.div_ceil(2)));
    }
    sizes
}

/// `r` grown by `by` pixels on every side, clipped to the `width`×`height` grid.
pub fn grow(r: Rect, by: usize, width: usize, height: usize) -> Rect {
    [
        r[0].saturating_sub(by),
        r[1].saturating_sub(by),
        (r[2] + by).min(width),
        (r[3] + by).min(height),
    ]
}

/// The smallest rectangle holding `a` and `b` (`a` absent: `b`).
fn union(a: Option<Rect>, b: Rect) -> Rect {
    match a {
        None => b,
        Some(a) => [
            a[0].min(b[0]),
            a[1].min(b[1]),
            a[2].max(b[2]),
            a[3].max(b[3]),
        ],
    }
}

/// The rectangle of a convolution's input that its output on `out` reads (the output grown by
/// the kernel radius, clipped to the grid: beyond it the input is zero).
pub fn conv_input(out: Rect, kernel: usize, size: (usize, usize)) -> Rect {
    grow(out, kernel / 2, size.0, size.1)
}

/// The rectangle of the finer grid (`size`) that a pooling's output on `out` reads.
pub fn pool_input(out: Rect, size: (usize, usize)) -> Rect {
    [
        2 * out[0],
        2 * out[1],
        (2 * out[2]).min(size.0),
        (2 * out[3]).min(size.1),
    ]
}

/// The rectangle of the coarser grid that an upsampling's output on `out` reads.
pub fn upsample_input(out: Rect) -> Rect {
    [
        out[0] / 2,
        out[1] / 2,
        out[2].div_ceil(2),
        out[3].div_ceil(2),
    ]
}

/// For every step, the rectangle of its scale's grid on which it must be computed so that the
/// last step is exact on `out` (`None`: not needed). `sizes` from [`scale_sizes`].
pub fn needed_rects(
    steps: &[Step],
    kernel: usize,
    out: Rect,
    sizes: &[(usize, usize)],
) -> Vec<Option<Rect>> {
    let mut need: Vec<Option<Rect>> = vec![None; steps.len()];
    if let Some(last) = need.last_mut() {
        *last = Some(out);
    }
    for (i, step) in steps.iter().enumerate().rev() {
        let Some(r) = need[i] else { continue };
        match &step.op {
            Op::Input => {}
            Op::Conv { inputs, .. } => {
                let input = conv_input(r, kernel, sizes[step.scale]);
                for &j in inputs {
                    need[j] = Some(union(need[j], input));
                }
            }
            Op::Pool(j) => need[*j] = Some(union(need[*j], pool_input(r, sizes[step.scale - 1]))),
            Op::Upsample(j) => need[*j] = Some(union(need[*j], upsample_input(r))),
        }
    }
    need
}

/// The index of the last step that reads each step (itself when none does).
pub fn last_uses(steps: &[Step]) -> Vec<usize> {
    let mut last: Vec<usize> = (0..steps.len()).collect();
    for (i, step) in steps.iter().enumerate() {
        match &step.op {
            Op::Input => {}
            Op::Conv { inputs, .. } => inputs.iter().for_each(|&j| last[j] = i),
            Op::Pool(j) | Op::Upsample(j) => last[*j] = i,
        }
    }
    last
}

/// How far `inner` lies inside `outer` on each side, `[top, bottom, left, right]`.
fn insets(outer: Rect, inner: Rect) -> [usize; 4] {
    [
        inner[1] - outer[1],
        outer[3] - inner[3],
        inner[0] - outer[0],
        outer[2] - inner[2],
    ]
}

/// The rows and columns of `inner` out of a tensor laid out on `outer`.
fn crop(x: Tensor<4>, outer: Rect, inner: Rect) -> Tensor<4> {
    if outer == inner {
        return x;
    }
    let [top, _, left, _] = insets(outer, inner);
    x.narrow(2, top, inner[3] - inner[1])
        .narrow(3, left, inner[2] - inner[0])
}

/// The hidden part of the U-Net with Burn tensors: `features` `[B, C, h, w]` given on `region`
/// (full-resolution coordinates of a `width`×`height` image; it must hold what the plan needs)
/// → the last step's activation on `out` (which must lie inside the image). The whole image is
/// `region = out = [0, 0, width, height]` ([`crate::Network::forward`]); tiles pass their
/// region and the rectangle the output layer reads.
pub fn forward_region(
    unet: &UNet,
    hidden: &[Conv2d],
    features: Tensor<4>,
    region: Rect,
    out: Rect,
    width: usize,
    height: usize,
) -> Tensor<4> {
    let steps = unet.plan(features.dims()[1]);
    let kernel = hidden[0].kernel_size[0];
    let sizes = scale_sizes(width, height, unet.scales());
    let need = needed_rects(&steps, kernel, out, &sizes);
    let last_use = last_uses(&steps);
    let mut values: Vec<Option<(Tensor<4>, Rect)>> = vec![None; steps.len()];
    let mut features = Some(features);
    for (i, step) in steps.iter().enumerate() {
        let Some(r) = need[i] else { continue };
        // The value of step j on rectangle `on` (which lies inside the rectangle it was
        // computed on).
        let take = |values: &[Option<(Tensor<4>, Rect)>], j: usize, on: Rect| {
            let (x, at) = values[j].as_ref().expect("inputs come first");
            crop(x.clone(), *at, on)
        };
        let value = match &step.op {
            Op::Input => {
                let x = features.take().expect("one input step");
                assert!(
                    covers(region, r),
                    "features on {region:?} do not cover the needed {r:?}"
                );
                crop(x, region, r)
            }
            Op::Conv { layer, inputs } => {
                let input = conv_input(r, kernel, sizes[step.scale]);
                let parts: Vec<Tensor<4>> =
                    inputs.iter().map(|&j| take(&values, j, input)).collect();
                let x = if parts.len() == 1 {
                    parts.into_iter().next().expect("one part")
                } else {
                    Tensor::cat(parts, 1)
                };
                let conv = &hidden[*layer];
                let k = kernel / 2;
                // Zero padding only where the input stops short of the grown output (the
                // grid's border).
                let [top, bottom, left, right] = insets(input, r).map(|inset| k - inset);
                let options = ConvOptions::new_with_padding(
                    conv.stride,
                    [(top, bottom), (left, right)],
                    conv.dilation,
                    conv.groups,
                );
                relu(conv2d(
                    x,
                    conv.weight.val(),
                    conv.bias.as_ref().map(|b| b.val()),
                    options,
                ))
            }
            Op::Pool(j) => {
                let input = pool_input(r, sizes[step.scale - 1]);
                let x = take(&values, *j, input);
                // A block cut by the grid's border gets its missing pixels as zeros.
                let (pad_x, pad_y) = (2 * r[2] - input[2], 2 * r[3] - input[3]);
                let x = if pad_x + pad_y > 0 {
                    x.pad([(0, pad_y), (0, pad_x)], PadMode::Constant(0.0))
                } else {
                    x
                };
                let [b, c, h, w] = x.dims();
                x.reshape([b, c, h / 2, 2, w / 2, 2])
                    .sum_dim(5)
                    .sum_dim(3)
                    .reshape([b, c, h / 2, w / 2])
                    .mul_scalar(0.25)
            }
            Op::Upsample(j) => {
                let input = upsample_input(r);
                let x = take(&values, *j, input);
                let [b, c, h, w] = x.dims();
                x.reshape([b, c, h, 1, w, 1])
                    .repeat_dim(3, 2)
                    .repeat_dim(5, 2)
                    .reshape([b, c, 2 * h, 2 * w])
                    .narrow(2, r[1] % 2, r[3] - r[1])
                    .narrow(3, r[0] % 2, r[2] - r[0])
            }
        };
        values[i] = Some((value, r));
        // Free what no later step reads.
        for (j, v) in values.iter_mut().enumerate().take(i) {
            if last_use[j] == i {
                *v = None;
            }
        }
    }
    let (x, at) = values.pop().flatten().expect("the plan has steps");
    debug_assert_eq!(at, out);
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preset_plan_shapes_and_reach() {
        let unet = UNet::preset();
        unet.validate().unwrap();
        assert_eq!(unet.hidden_layers(), 10);
        assert_eq!(
            unet.conv_shapes(27),
            [
                (27, 16),
                (16, 32),
                (32, 32),
                (32, 48),
                (48, 48),
                (48, 64),
                (64, 64),
                (64 + 48, 48),
                (48 + 32, 32),
                (32 + 16, 16),
            ]
        );
        // Down: 1 + 2·2 + 2·4 + 2·8; up: 1 + 2 + 4 on the convolutions and ≤ 1 + 2 + 4 on the
        // outward rounding of the upsamplings.
        assert_eq!(unet.reach(3, 1), 43);
        // A 1-scale-shallower network reaches less.
        let three = UNet {
            widths: vec![8, 8, 8],
            convs: vec![1, 1, 1],
        };
        assert!(three.reach(3, 1) < 20);
    }

    #[test]
    fn bad_layouts_are_rejected() {
        for (widths, convs) in [
            (vec![8], vec![1]),
            (vec![8, 8], vec![1]),
            (vec![8, 0], vec![1, 1]),
            (vec![8, 8], vec![1, 0]),
        ] {
            assert!(UNet { widths, convs }.validate().is_err());
        }
    }

    #[test]
    fn needed_rects_follow_scales_and_clip_at_the_border() {
        // An 11×7 image, 3 scales: grids 11×7, 6×4, 3×2.
        let unet = UNet {
            widths: vec![4, 4, 4],
            convs: vec![1, 1, 1],
        };
        let steps = unet.plan(5);
        let sizes = scale_sizes(11, 7, 3);
        assert_eq!(sizes, [(11, 7), (6, 4), (3, 2)]);
        let whole = needed_rects(&steps, 3, [0, 0, 11, 7], &sizes);
        for (step, r) in steps.iter().zip(&whole) {
            let (w, h) = sizes[step.scale];
            assert_eq!(*r, Some([0, 0, w, h]), "{step:?}");
        }
        // One pixel in the middle: the features it needs stay inside the image.
        let one = needed_rects(&steps, 3, [5, 3, 6, 4], &sizes);
        let input = one[0].unwrap();
        assert!(input[0] < 5 && input[2] > 6 && input[2] <= 11 && input[3] <= 7);
    }
}
