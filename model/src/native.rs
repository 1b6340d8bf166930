//! The native CPU inference engine: the trained network's forward pass and the Eq. 6
//! combination computed with im2col + `gemm` matrix products and one fused combination loop,
//! outside Burn's tensor machinery.
//!
//! Why it exists: on the CPU the Burn (flex) convolution spends more time on layout copies,
//! im2col bookkeeping and the scatter of its result than in its matrix kernels, and the tensor
//! form of Eq. 6 materialises a 4·3·|Ω| gather per pixel. Here activations stay channels-last
//! (`[y][x][channel]`), so an im2col row is a run of contiguous copies and a layer's output is
//! the product's rows; the last layer's weights are consumed per pixel straight out of the
//! product, never stored for the image. The arithmetic is the same as the Burn path, only
//! summed in another order (equal within 1e-5, `tests::native_equals_burn`).
//!
//! Determinism: rows are cut into fixed chunks (independent of the thread count) and each
//! chunk's product runs single-threaded, so the result is bit-identical on any thread count.

use crate::network::{ModelConfig, Network, Weighting, LEVELS};
use rayon::prelude::*;

/// A pixel rectangle `[x0, y0, x1, y1)` in image coordinates.
pub type Rect = [usize; 4];

/// Output pixels per chunk: im2col buffer and product of one chunk stay a few MB.
const CHUNK_PIXELS: usize = 1024;

/// One convolution as a matrix: `matrix[(ky·k + kx)·cin + ci][cout]` (the im2col order) and
/// the bias.
#[derive(Clone, Debug)]
struct ConvMatrix {
    kernel: usize,
    cin: usize,
    cout: usize,
    matrix: Vec<f32>,
    bias: Vec<f32>,
}

impl ConvMatrix {
    /// Rearranges a Burn `Conv2d` (weight `[cout, cin, k, k]`, cross-correlation).
    fn from_conv(conv: &burn::nn::conv::Conv2d) -> Self {
        let [cout, cin, kernel, _] = conv.weight.val().dims();
        let weight: Vec<f32> = conv
            .weight
            .val()
            .into_data()
            .convert::<f32>()
            .try_to_vec::<f32>()
            .expect("f32 convolution weights");
        let bias = match &conv.bias {
            Some(b) => b
                .val()
                .into_data()
                .convert::<f32>()
                .try_to_vec::<f32>()
                .expect("f32 convolution bias"),
            None => vec![0.0; cout],
        };
        let mut matrix = vec![0.0f32; kernel * kernel * cin * cout];
        for co in 0..cout {
            for ci in 0..cin {
                for ky in 0..kernel {
                    for kx in 0..kernel {
                        matrix[((ky * kernel + kx) * cin + ci) * cout + co] =
                            weight[((co * cin + ci) * kernel + ky) * kernel + kx];
                    }
                }
            }
        }
        Self {
            kernel,
            cin,
            cout,
            matrix,
            bias,
        }
    }

    /// Rows of the im2col matrix (one per output pixel).
    fn depth(&self) -> usize {
        self.kernel * self.kernel * self.cin
    }

    /// Fills `columns` (`pixels × depth`) with the im2col rows of the output pixels
    /// `first..first + pixels` of `out` (row-major), reading channels-last `x` laid out on
    /// `input`; taps outside `input` are zero (they lie outside the image).
    fn im2col(&self, x: &[f32], input: Rect, out: Rect, first: usize, columns: &mut [f32]) {
        let (k, cin) = (self.kernel, self.cin);
        let r = k / 2;
        let out_w = out[2] - out[0];
        let in_w = input[2] - input[0];
        let depth = self.depth();
        for (p, row) in columns.chunks_exact_mut(depth).enumerate() {
            let (oy, ox) = (out[1] + (first + p) / out_w, out[0] + (first + p) % out_w);
            for ky in 0..k {
                let taps = &mut row[ky * k * cin..(ky + 1) * k * cin];
                let iy = (oy + ky).wrapping_sub(r);
                if iy < input[1] || iy >= input[3] {
                    taps.fill(0.0);
                    continue;
                }
                // Taps kx read column ox + kx − r; those inside the input rectangle are one run.
                let kx_lo = (input[0] + r).saturating_sub(ox).min(k);
                let kx_hi = (input[2] + r - ox).min(k).max(kx_lo);
                taps[..kx_lo * cin].fill(0.0);
                let src = ((iy - input[1]) * in_w + (ox + kx_lo - r - input[0])) * cin;
                let len = (kx_hi - kx_lo) * cin;
                taps[kx_lo * cin..kx_hi * cin].copy_from_slice(&x[src..src + len]);
                taps[kx_hi * cin..].fill(0.0);
            }
        }
    }

    /// `dst` (`pixels × cout`) = bias + columns · matrix.
    fn product(&self, columns: &[f32], pixels: usize, dst: &mut [f32]) {
        let (depth, cout) = (self.depth(), self.cout);
        for row in dst.chunks_exact_mut(cout) {
            row.copy_from_slice(&self.bias);
        }
        // SAFETY: the three buffers hold pixels×depth, depth×cout and pixels×cout f32 values in
        // row-major order, matching the strides given, and do not overlap.
        unsafe {
            gemm::gemm(
                pixels,
                cout,
                depth,
                dst.as_mut_ptr(),
                1,
                cout as isize,
                true,
                columns.as_ptr(),
                1,
                depth as isize,
                self.matrix.as_ptr(),
                1,
                cout as isize,
                1.0,
                1.0,
                false,
                false,
                false,
                gemm::Parallelism::None,
            );
        }
    }

    /// The convolution ("same" padding in the whole image) followed by ReLU, evaluated on
    /// `out` from channels-last `x` on `input` = `out` grown by the kernel radius and clipped
    /// to the image. Returns channels-last values on `out`.
    fn forward_relu(&self, x: &[f32], input: Rect, out: Rect) -> Vec<f32> {
        let pixels = (out[2] - out[0]) * (out[3] - out[1]);
        let mut y = vec![0.0f32; pixels * self.cout];
        // One im2col buffer per worker, reused across its chunks: im2col overwrites every
        // entry, and a fresh multi-MB allocation per chunk would be zero-filled and page-faulted.
        y.par_chunks_mut(CHUNK_PIXELS * self.cout)
            .enumerate()
            .for_each_init(Vec::new, |columns, (chunk, dst)| {
                let n = dst.len() / self.cout;
                columns.resize(n * self.depth(), 0.0);
                self.im2col(x, input, out, chunk * CHUNK_PIXELS, columns);
                self.product(columns, n, dst);
                for v in dst.iter_mut() {
                    *v = v.max(0.0);
                }
            });
        y
    }
}

/// A trained network rearranged for the native engine.
#[derive(Clone, Debug)]
pub struct NativeNetwork {
    hidden: Vec<ConvMatrix>,
    output: ConvMatrix,
    weighting: Weighting,
    window: usize,
    pairs: usize,
    /// Safeguard strength κ ([`crate::combine::combine_guarded_block`]; 0: Eq. 6 alone).
    guard: f32,
    /// The safeguard's trust λ in the smoothest level.
    guard_target_noise: f32,
}

/// Planar colours of the whole image that the combination reads.
pub struct CombinationInputs<'a> {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Planar colours `[3·m][pixels]`: ỹ RGB, then each correlated level's RGB.
    pub levels: &'a [f32],
    /// The output plane of each correlated level's weight share (level j of the network →
    /// plane `share_planes[j]`).
    pub share_planes: &'a [usize],
    /// Planar variances of the levels' means `[m][pixels]`, ỹ first, for the safeguard (read
    /// only when the network's guard is on).
    pub variances: &'a [f32],
}

impl NativeNetwork {
    /// Copies the weights of `network` (architecture `config`) into matrix form.
    pub fn new(network: &Network, config: &ModelConfig) -> Self {
        Self {
            hidden: network.hidden.iter().map(ConvMatrix::from_conv).collect(),
            output: ConvMatrix::from_conv(&network.output),
            weighting: network.weighting,
            window: config.window,
            pairs: config.pairs(),
            guard: config.guard,
            guard_target_noise: config.guard_target_noise,
        }
    }

    /// Hidden layers on shrinking regions: features (planar `[C][pixels]` of the whole image)
    /// on `region`, layer l exact on `interior` grown by the reach of the layers after it.
    /// Returns the last hidden activation (channels-last) and the rectangle it covers.
    pub fn hidden_layers(
        &self,
        features: &[f32],
        width: usize,
        height: usize,
        region: Rect,
        interior: Rect,
    ) -> (Vec<f32>, Rect) {
        let channels = features.len() / (width * height).max(1);
        let (rw, rh) = (region[2] - region[0], region[3] - region[1]);
        let mut x = vec![0.0f32; rw * rh * channels];
        for (c, plane) in features.chunks_exact(width * height).enumerate() {
            for y in 0..rh {
                let src = &plane[(region[1] + y) * width + region[0]..][..rw];
                for (i, v) in src.iter().enumerate() {
                    x[(y * rw + i) * channels + c] = *v;
                }
            }
        }
        let reach = self.output.kernel / 2;
        let layers = self.hidden.len() + 1;
        let mut region = region;
        for (l, conv) in self.hidden.iter().enumerate() {
            let out = grow(interior, (layers - 1 - l) * reach, width, height);
            x = conv.forward_relu(&x, region, out);
            region = out;
        }
        (x, region)
    }

    /// Last layer, positive weights and Eq. 6 for the pixels of `out` (inside `region`, which
    /// covers `out` grown by the kernel radius or the image border), from the last hidden
    /// activation `x` on `region`. Writes ŷ (clamped at zero) into the planar `image` and
    /// the weight share of correlated level j into plane `colours.share_planes[j]` of the
    /// planar `shares`, both of the whole image.
    pub fn combine(
        &self,
        x: &[f32],
        region: Rect,
        out: Rect,
        colours: &CombinationInputs,
        image: &mut [f32],
        shares: &mut [f32],
    ) {
        let pixels = colours.width * colours.height;
        let width = colours.width;
        let out_w = out[2] - out[0];
        let count = out_w * (out[3] - out[1]);
        let conv = &self.output;
        let chunks: Vec<(Vec<f32>, Vec<f32>)> = (0..count.div_ceil(CHUNK_PIXELS))
            .into_par_iter()
            .map_init(
                || (Vec::new(), Vec::new()),
                |(columns, raw), chunk| {
                    let first = chunk * CHUNK_PIXELS;
                    let n = CHUNK_PIXELS.min(count - first);
                    // Per-worker buffers, fully overwritten (im2col; bias then product).
                    columns.resize(n * conv.depth(), 0.0);
                    conv.im2col(x, region, out, first, columns);
                    raw.resize(n * conv.cout, 0.0);
                    conv.product(columns, n, raw);
                    let mut colour = vec![0.0f32; 3 * n];
                    let mut share = vec![0.0f32; self.pairs * n];
                    for (p, weights) in raw.chunks_exact_mut(conv.cout).enumerate() {
                        let q = first + p;
                        let (py, px) = (out[1] + q / out_w, out[0] + q % out_w);
                        let (rgb, sums) = self.combine_pixel(weights, px, py, colours);
                        for c in 0..3 {
                            colour[c * n + p] = rgb[c];
                        }
                        for j in 0..self.pairs {
                            share[j * n + p] = sums[j];
                        }
                    }
                    (colour, share)
                },
            )
            .collect();
        for (chunk, (colour, share)) in chunks.iter().enumerate() {
            let first = chunk * CHUNK_PIXELS;
            let n = colour.len() / 3;
            for p in 0..n {
                let q = first + p;
                let at = (out[1] + q / out_w) * width + out[0] + q % out_w;
                for c in 0..3 {
                    image[c * pixels + at] = colour[c * n + p];
                }
                for (j, &plane) in colours.share_planes.iter().enumerate() {
                    shares[plane * pixels + at] = share[j * n + p];
                }
            }
        }
    }

    /// Eq. 6 and the safeguard at pixel (px, py) from its raw network outputs (overwritten with
    /// the positive weights): returns ŷ clamped at zero and each correlated level's share of
    /// the weight (the same as [`crate::combine::combine_guarded_block`]).
    fn combine_pixel(
        &self,
        weights: &mut [f32],
        px: usize,
        py: usize,
        colours: &CombinationInputs,
    ) -> ([f32; 3], [f32; LEVELS - 1]) {
        let (width, height) = (colours.width, colours.height);
        let pixels = width * height;
        let window = self.window;
        let r = window / 2;
        let area = window * window;
        // Window rows and columns that lie inside the image: the others get zero weight.
        let (ky0, ky1) = (r.saturating_sub(py), (height + r - py).min(window));
        let (kx0, kx1) = (r.saturating_sub(px), (width + r - px).min(window));
        match self.weighting {
            Weighting::Relu => {
                for w in weights.iter_mut() {
                    *w = w.max(0.0) + 1e-4;
                }
            }
            Weighting::Softmax => {
                // The maximum cancels in the normalisation; subtracting it keeps exp() finite.
                // Taken over the entries inside the image (Burn's path takes it over all), so
                // the largest kept weight is exactly 1 and the sum can never underflow to 0.
                let mut max = f32::NEG_INFINITY;
                for j in 0..self.pairs {
                    for ky in ky0..ky1 {
                        let row = &weights[j * area + ky * window..][kx0..kx1];
                        max = row.iter().copied().fold(max, f32::max);
                    }
                }
                for w in weights.iter_mut() {
                    *w = (*w - max).exp();
                }
            }
        }
        let centre = py * width + px;
        let y_planes = &colours.levels[..3 * pixels];
        let mut numerator = [0.0f32; 3];
        let mut sums = [0.0f32; LEVELS - 1];
        let mut squares = [0.0f32; LEVELS - 1];
        for j in 0..self.pairs {
            let z_planes = &colours.levels[3 * (j + 1) * pixels..3 * (j + 2) * pixels];
            let w_j = &weights[j * area..(j + 1) * area];
            let mut sum = 0.0f32;
            let mut square = 0.0f32;
            let mut acc = [0.0f32; 3];
            for ky in ky0..ky1 {
                // First in-image pixel of this window row (px + kx0 ≥ r by construction).
                let start = (py + ky - r) * width + px + kx0 - r;
                let len = kx1 - kx0;
                let w_row = &w_j[ky * window + kx0..ky * window + kx1];
                sum += w_row.iter().sum::<f32>();
                if self.guard > 0.0 {
                    square += w_row.iter().map(|w| w * w).sum::<f32>();
                }
                for c in 0..3 {
                    let yc = &y_planes[c * pixels + start..][..len];
                    let zc = &z_planes[c * pixels + start..][..len];
                    acc[c] += w_row
                        .iter()
                        .zip(yc.iter().zip(zc))
                        .map(|(w, (y, z))| w * (y - z))
                        .sum::<f32>();
                }
            }
            for c in 0..3 {
                numerator[c] += acc[c] + sum * z_planes[c * pixels + centre];
            }
            sums[j] = sum;
            squares[j] = square;
        }
        let total: f32 = sums.iter().sum();
        let mut rgb = numerator.map(|v| v / total);
        if self.guard > 0.0 {
            let v = |level: usize| colours.variances[level * pixels + centre];
            let total_squared = total * total;
            let mut noise = 0.0f32;
            for j in 0..self.pairs {
                noise += squares[j] / total_squared * (v(j + 1) + v(0))
                    + sums[j] * sums[j] / total_squared * v(j + 1);
            }
            let target_noise = self.guard_target_noise * v(self.pairs) + 1e-30;
            let smoothest = &colours.levels[3 * self.pairs * pixels..];
            // A non-finite Eq. 6 (overflow) is left as it is, for the caller to report.
            for (c, out) in rgb.iter_mut().enumerate().filter(|(_, v)| v.is_finite()) {
                let base = smoothest[c * pixels + centre];
                let delta = *out - base;
                let ratio = self.guard * noise / (delta * delta + target_noise);
                *out = base + delta * (1.0 / (1.0 + ratio * ratio));
            }
        }
        let rgb = rgb.map(|v| v.max(0.0));
        for s in sums.iter_mut() {
            *s /= total;
        }
        (rgb, sums)
    }
}

/// `r` grown by `by` pixels on every side, clipped to the `width`×`height` image.
pub fn grow(r: Rect, by: usize, width: usize, height: usize) -> Rect {
    [
        r[0].saturating_sub(by),
        r[1].saturating_sub(by),
        (r[2] + by).min(width),
        (r[3] + by).min(height),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A network with no layers, only the combination settings (combine_pixel reads nothing
    /// else).
    fn combiner(weighting: Weighting, window: usize, pairs: usize) -> NativeNetwork {
        let empty = ConvMatrix {
            kernel: 1,
            cin: 0,
            cout: 0,
            matrix: Vec::new(),
            bias: Vec::new(),
        };
        NativeNetwork {
            hidden: Vec::new(),
            output: empty,
            weighting,
            window,
            pairs,
            guard: 0.0,
            guard_target_noise: 0.0,
        }
    }

    #[test]
    fn hand_computed_corner_pixel() {
        // 2×2 image, 3×3 window, one correlated level, pixel (0, 0): the window entries
        // (ky, kx) ∈ {1, 2}² are the four pixels, the other five lie outside. ỹ = 1, 2, 3, 4 and
        // z̃ = 1 in every channel; equal weights → ŷ = mean(ỹ − z̃) + z̃_c = 1.5 + 1 = 2.5.
        let levels: Vec<f32> = [1.0, 2.0, 3.0, 4.0]
            .repeat(3)
            .into_iter()
            .chain([1.0; 12])
            .collect();
        let colours = CombinationInputs {
            width: 2,
            height: 2,
            levels: &levels,
            share_planes: &[0],
            variances: &[],
        };
        // Raw outputs: 0 inside, 1000 outside. ReLU: outside 1000 + 1e-4 but masked; inside
        // 1e-4 each. Softmax: exp(1000 − max) would overflow or, with the maximum taken over
        // all entries, underflow every kept weight to zero; inside-only maximum keeps them 1.
        let mut raw = [1000.0f32; 9];
        for (ky, kx) in [(1, 1), (1, 2), (2, 1), (2, 2)] {
            raw[ky * 3 + kx] = 0.0;
        }
        for weighting in [Weighting::Relu, Weighting::Softmax] {
            let mut w = raw;
            let (rgb, shares) = combiner(weighting, 3, 1).combine_pixel(&mut w, 0, 0, &colours);
            for c in rgb {
                assert!((c - 2.5).abs() < 1e-6, "{weighting:?}: {c}");
            }
            assert_eq!(shares[0], 1.0, "{weighting:?}");
        }
        // Clamped at zero: z̃ = 0, 0, 0, 14 → mean(ỹ − z̃) + z̃_c = (1 + 2 + 3 − 10) / 4 + 0 = −1.
        let mut negative = levels.clone();
        for c in 0..3 {
            negative[12 + c * 4..12 + c * 4 + 4].copy_from_slice(&[0.0, 0.0, 0.0, 14.0]);
        }
        let colours = CombinationInputs {
            levels: &negative,
            ..colours
        };
        let mut w = raw;
        let (rgb, _) = combiner(Weighting::Relu, 3, 1).combine_pixel(&mut w, 0, 0, &colours);
        assert_eq!(rgb, [0.0; 3]);
    }
}
