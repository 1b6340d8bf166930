//! A 3×3 convolution whose first input is a nearest-neighbour ×2 upsampling (each step on the
//! U-Net's way up), computed on the coarse values under the fine pixels.
//!
//! Why: the upsampling repeats every coarse value over a 2×2 block of fine pixels, so the 3×3
//! taps of a fine pixel read only 2×2 distinct coarse pixels. Which taps share a coarse pixel
//! depends only on the fine pixel's parity (y mod 2, x mod 2): along each axis a fine pixel of
//! even index reads coarse pixels Y − 1 (tap −1) and Y (taps 0, +1), one of odd index Y (taps
//! −1, 0) and Y + 1 (tap +1), Y being its own coarse pixel. Summing the kernel's weights of the
//! taps that share a coarse pixel gives, per parity, a kernel of 2×2 coarse taps: the
//! upsampled input's share of the im2col row and of the multiply-adds falls from 9 to 4 taps
//! (the full-resolution 48 → 16 convolution of the `unet` preset from 6.9 k to 4.4 k
//! multiply-adds per pixel). The other inputs (the skip connection) keep their 3×3 taps.
//!
//! Exact where the fold is: the weights' sums are the same terms added in another order (equal
//! to the plain path within float rounding, `native_engine_equals_burn` in
//! infer/tests/tiling.rs). Not exact where a tap of the upsampled input lies outside its fine
//! rectangle (a zero: the grid's border) while the coarse pixel under it lies inside the coarse
//! one — the last row or column of a grid of odd size, whose upsampling would continue into the
//! missing row — so those pixels take the plain 3×3 path ([`ConvMatrix::im2col_sources`]).

use super::{copy_run, Buffers, ConvMatrix, Rect, Source, CHUNK_PIXELS};
use rayon::prelude::*;

/// The kernel side the fold is written for.
const KERNEL: usize = 3;

/// The folded weights of one convolution whose first source is upsampled.
#[derive(Clone, Debug)]
pub(super) struct FoldedUpsampling {
    /// Channels of the upsampled source.
    channels: usize,
    /// Rows of each folded matrix: 4 coarse taps of the upsampled source, then the other
    /// sources' 3×3 taps.
    depth: usize,
    /// Per output parity `2·(y mod 2) + (x mod 2)`: rows `(a·2 + b)·channels + ci` for the
    /// coarse tap (a, b) (a, b ∈ {0, 1}: coarse row Y − 1 + (y mod 2) + a, column likewise),
    /// then the plain matrix's rows of the other sources, each row `cout` values.
    matrices: [Vec<f32>; 4],
}

/// The kernel taps (0, 1, 2 for offsets −1, 0, +1) of a fine pixel of parity `q` that read
/// coarse tap `a` (coarse pixel Y − 1 + q + a, Y the fine pixel's own).
fn taps_of(q: usize, a: usize) -> &'static [usize] {
    match (q, a) {
        (0, 0) => &[0],
        (0, _) => &[1, 2],
        (_, 0) => &[0, 1],
        _ => &[2],
    }
}

impl FoldedUpsampling {
    /// Folds `plain` (a [`ConvMatrix::from_concat_conv`] whose first source, of `channels`
    /// channels, is the upsampled one); `None` for another kernel size.
    pub(super) fn new(plain: &ConvMatrix, channels: usize) -> Option<Self> {
        if plain.kernel != KERNEL {
            return None;
        }
        let cout = plain.cout;
        let plain_rows = KERNEL * KERNEL * channels;
        let rest = plain.depth() - plain_rows;
        let depth = 4 * channels + rest;
        let matrices = std::array::from_fn(|parity| {
            let (qy, qx) = (parity / 2, parity % 2);
            let mut m = vec![0.0f32; depth * cout];
            for a in 0..2 {
                for b in 0..2 {
                    for ci in 0..channels {
                        let to = ((a * 2 + b) * channels + ci) * cout;
                        for &ky in taps_of(qy, a) {
                            for &kx in taps_of(qx, b) {
                                let from = ((ky * KERNEL + kx) * channels + ci) * cout;
                                for co in 0..cout {
                                    m[to + co] += plain.matrix[from + co];
                                }
                            }
                        }
                    }
                }
            }
            m[4 * channels * cout..].copy_from_slice(&plain.matrix[plain_rows * cout..]);
            m
        });
        Some(Self {
            channels,
            depth,
            matrices,
        })
    }

    /// The convolution of `sources` (the first upsampled, the others not) on `out`, followed by
    /// ReLU, as [`ConvMatrix::forward_relu_sources`] computes it with `plain`. Returns
    /// channels-last values on `out`.
    pub(super) fn forward_relu(
        &self,
        plain: &ConvMatrix,
        sources: &[Source],
        out: Rect,
        buffers: &Buffers,
    ) -> Vec<f32> {
        let up = sources[0];
        let fine = up.upsampled.expect("the first source is upsampled");
        debug_assert_eq!(up.channels, self.channels);
        assert!(sources[1..].iter().all(|s| s.upsampled.is_none()));
        let cout = plain.cout;
        let out_w = out[2] - out[0];
        let pixels = out_w * (out[3] - out[1]);
        let mut y = buffers.take(pixels * cout);
        if pixels == 0 {
            return y;
        }
        // Whether a fine row (column) beside the output's lies outside the fine rectangle
        // while the coarse row (column) under it lies inside the coarse one.
        let unfoldable = |edge: usize, lo: usize, hi: usize, coarse_lo: usize, coarse_hi: usize| {
            [edge.checked_sub(1), Some(edge + 1)]
                .into_iter()
                .flatten()
                .any(|f| (f < lo || f >= hi) && (coarse_lo..coarse_hi).contains(&(f / 2)))
        };
        y.par_chunks_mut(out_w * cout).enumerate().for_each_init(
            Vec::new,
            |columns, (row, dst)| {
                let oy = out[1] + row;
                let first = row * out_w;
                if unfoldable(oy, fine[1], fine[3], up.rect[1], up.rect[3]) {
                    plain.product_sources(sources, out, first, columns, dst);
                } else {
                    for qx in 0..2 {
                        // The row's pixels of column parity qx, a chunk at a time.
                        let start = (out[0] + qx) % 2;
                        let count = (out_w + 1 - start) / 2;
                        for chunk in (0..count).step_by(CHUNK_PIXELS) {
                            let n = CHUNK_PIXELS.min(count - chunk);
                            let at = start + 2 * chunk;
                            columns.resize(n * self.depth, 0.0);
                            self.im2col(sources, oy, out[0] + at, n, columns);
                            let parity = 2 * (oy % 2) + (out[0] + at) % 2;
                            plain.product_strided(
                                &self.matrices[parity],
                                columns,
                                n,
                                &mut dst[at * cout..],
                                2 * cout,
                            );
                        }
                    }
                    for ox in [out[0], out[2] - 1] {
                        if unfoldable(ox, fine[0], fine[2], up.rect[0], up.rect[2]) {
                            let at = ox - out[0];
                            let pixel = &mut dst[at * cout..(at + 1) * cout];
                            plain.product_sources(sources, out, first + at, columns, pixel);
                        }
                    }
                }
                for v in dst.iter_mut() {
                    *v = v.max(0.0);
                }
            },
        );
        y
    }

    /// The folded im2col rows of the `n` fine pixels (x0 + 2i, oy) (one parity): the 2×2
    /// coarse taps of the upsampled source (zero outside its coarse rectangle), then the other
    /// sources' 3×3 taps (zero outside their rectangles).
    fn im2col(&self, sources: &[Source], oy: usize, x0: usize, n: usize, columns: &mut [f32]) {
        let up = sources[0];
        let c = self.channels;
        let rect = up.rect;
        let in_w = rect[2] - rect[0];
        // Coarse row of tap a: Y − 1 + (oy mod 2) + a.
        let coarse = |fine: usize, a: usize| (fine / 2 + fine % 2 + a).checked_sub(1);
        let inside = |v: Option<usize>, lo: usize, hi: usize| v.filter(|v| (lo..hi).contains(v));
        for (i, row) in columns.chunks_exact_mut(self.depth).take(n).enumerate() {
            let ox = x0 + 2 * i;
            for a in 0..2 {
                let taps = &mut row[a * 2 * c..(a + 1) * 2 * c];
                let Some(cy) = inside(coarse(oy, a), rect[1], rect[3]) else {
                    taps.fill(0.0);
                    continue;
                };
                let line = &up.x[(cy - rect[1]) * in_w * c..][..in_w * c];
                for b in 0..2 {
                    let tap = &mut taps[b * c..(b + 1) * c];
                    match inside(coarse(ox, b), rect[0], rect[2]) {
                        Some(cx) => copy_run(tap, &line[(cx - rect[0]) * c..][..c]),
                        None => tap.fill(0.0),
                    }
                }
            }
            let mut offset = 4 * c;
            for source in &sources[1..] {
                let len = KERNEL * KERNEL * source.channels;
                super::dense_taps(source, KERNEL, oy, ox, &mut row[offset..offset + len]);
                offset += len;
            }
        }
    }
}
