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
//! summed in another order (equal within 1e-5: `native_engine_equals_burn` in infer/tests/tiling.rs).
//!
//! Determinism: rows are cut into fixed chunks (independent of the thread count) and each
//! chunk's product runs single-threaded, so the result is bit-identical on any thread count.
//!
//! A U-Net ([`crate::unet`]) runs the same plan as the Burn path, each step on the rectangle
//! the later steps need: a convolution reads its inputs' channels concatenated straight out of
//! their buffers (no concatenated copy), pooling is a plain loop over rows, and an upsampling is
//! never written: the convolution after it reads the coarse values, its weights folded onto
//! them ([`upsampled_conv`]).

use crate::combine::{GUARD_EVIDENCE_FLOOR, GUARD_RATIO_CAP};
use crate::network::{ModelConfig, Network, Weighting, LEVELS};
use crate::unet::{last_uses, needed_rects, pool_input, scale_sizes, upsample_input, Op, Step};
use rayon::prelude::*;
use upsampled_conv::FoldedUpsampling;

mod upsampled_conv;

/// A pixel rectangle `[x0, y0, x1, y1)` in image coordinates (or a coarser scale's grid).
pub type Rect = crate::unet::Rect;

/// Channels-last activations `x` of `channels` channels laid out on `rect`.
#[derive(Clone, Copy)]
struct Source<'a> {
    x: &'a [f32],
    rect: Rect,
    channels: usize,
    /// `Some(fine)`: read as their nearest-neighbour ×2 upsampling on the finer grid's
    /// rectangle `fine` (fine pixel (x, y) is `x`'s pixel (x / 2, y / 2)). A convolution after
    /// an upsampling reads the coarse values in place: the upsampled activations, the widest of
    /// the full-resolution ones, are never written.
    upsampled: Option<Rect>,
}

/// A step's result in [`NativeNetwork::unet_layers`].
#[derive(Clone)]
enum Activation {
    /// Channels-last values on a rectangle of the step's grid.
    Dense(Vec<f32>, Rect),
    /// An upsampling of step `coarse`, needed on `fine` (read in place, never written).
    Upsampled { coarse: usize, fine: Rect },
}

/// Output pixels per chunk: the im2col buffer of one chunk stays in a core's L2 cache (256 px ×
/// 432 columns of the U-Net's widest full-resolution layer = 432 KiB; 5–10 % faster than 1024 px).
const CHUNK_PIXELS: usize = 256;

/// Pixels of one row combined together by [`NativeNetwork::combine_lanes`]: one AVX-512
/// vector, two AVX2 vectors.
const LANES: usize = 16;

/// The raw outputs of [`LANES`] neighbouring pixels as the output layer's product holds them:
/// entry e's values of the pixels are the run `raw[e·stride..e·stride + LANES]`.
struct EntryLanes<'a> {
    raw: &'a mut [f32],
    stride: usize,
    entries: usize,
}

impl EntryLanes<'_> {
    /// Entry `e`'s values, one per pixel.
    #[inline(always)]
    fn entry(&self, e: usize) -> &[f32; LANES] {
        self.raw[e * self.stride..][..LANES]
            .try_into()
            .expect("LANES values")
    }

    /// [`EntryLanes::entry`], writable.
    #[inline(always)]
    fn entry_mut(&mut self, e: usize) -> &mut [f32; LANES] {
        (&mut self.raw[e * self.stride..][..LANES])
            .try_into()
            .expect("LANES values")
    }
}

/// One convolution as a matrix: `matrix[(ky·k + kx)·cin + ci][cout]` (the im2col order) and
/// the bias.
#[derive(Clone, Debug)]
struct ConvMatrix {
    kernel: usize,
    cin: usize,
    cout: usize,
    matrix: Vec<f32>,
    bias: Vec<f32>,
    /// For a convolution whose first input is an upsampling: its weights folded onto the
    /// coarse pixels ([`upsampled_conv`]).
    folded: Option<Box<FoldedUpsampling>>,
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
            folded: None,
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
        let source = Source {
            x,
            rect: input,
            channels: self.cin,
            upsampled: None,
        };
        let out_w = out[2] - out[0];
        for (p, row) in columns.chunks_exact_mut(self.depth()).enumerate() {
            let (oy, ox) = (out[1] + (first + p) / out_w, out[0] + (first + p) % out_w);
            dense_taps(&source, self.kernel, oy, ox, row);
        }
    }

    /// Rearranges a Burn `Conv2d` whose input is the concatenation of sources of `splits`
    /// channels into source-major rows, `matrix[offset_s + (ky·k + kx)·c_s + ci][cout]` with
    /// offset_s the rows of the sources before s: each source's taps of one kernel row are then
    /// one contiguous run of the im2col row ([`ConvMatrix::im2col_sources`]).
    fn from_concat_conv(conv: &burn::nn::conv::Conv2d, splits: &[usize]) -> Self {
        let plain = Self::from_conv(conv);
        let (k2, cin, cout) = (plain.kernel * plain.kernel, plain.cin, plain.cout);
        assert_eq!(
            splits.iter().sum::<usize>(),
            cin,
            "sources must cover the input"
        );
        let mut matrix = vec![0.0f32; plain.matrix.len()];
        let (mut offset, mut first) = (0, 0);
        for &c in splits {
            for tap in 0..k2 {
                for ci in 0..c {
                    let from = (tap * cin + first + ci) * cout;
                    let to = (offset + tap * c + ci) * cout;
                    matrix[to..to + cout].copy_from_slice(&plain.matrix[from..from + cout]);
                }
            }
            offset += k2 * c;
            first += c;
        }
        Self { matrix, ..plain }
    }

    /// The im2col rows of [`ConvMatrix::from_concat_conv`]'s order for the output pixels
    /// `first..first + pixels` of `out`, reading each source on its own rectangle (taps outside
    /// it are zero: they lie outside the grid).
    fn im2col_sources(&self, sources: &[Source], out: Rect, first: usize, columns: &mut [f32]) {
        let k = self.kernel;
        let r = k / 2;
        let out_w = out[2] - out[0];
        for (p, row) in columns.chunks_exact_mut(self.depth()).enumerate() {
            let (oy, ox) = (out[1] + (first + p) / out_w, out[0] + (first + p) % out_w);
            let mut offset = 0;
            for source in sources {
                let c = source.channels;
                // Upsampled: the fine grid's rectangle the taps read (outside it they are zero).
                let Some(input) = source.upsampled else {
                    dense_taps(source, k, oy, ox, &mut row[offset..offset + k * k * c]);
                    offset += k * k * c;
                    continue;
                };
                let in_w = source.rect[2] - source.rect[0];
                // Taps kx read column ox + kx − r; those inside the rectangle are one run.
                let kx_lo = (input[0] + r).saturating_sub(ox).min(k);
                let kx_hi = (input[2] + r).saturating_sub(ox).min(k).max(kx_lo);
                for ky in 0..k {
                    let taps = &mut row[offset + ky * k * c..offset + (ky + 1) * k * c];
                    let iy = (oy + ky).wrapping_sub(r);
                    if iy < input[1] || iy >= input[3] {
                        taps.fill(0.0);
                        continue;
                    }
                    taps[..kx_lo * c].fill(0.0);
                    // One coarse pixel per tap: fine column ox + kx − r is coarse column
                    // (ox + kx − r) / 2.
                    let cy = iy / 2 - source.rect[1];
                    for kx in kx_lo..kx_hi {
                        let cx = (ox + kx - r) / 2 - source.rect[0];
                        let src = (cy * in_w + cx) * c;
                        copy_run(&mut taps[kx * c..(kx + 1) * c], &source.x[src..src + c]);
                    }
                    taps[kx_hi * c..].fill(0.0);
                }
                offset += k * k * c;
            }
        }
    }

    /// `dst` (`pixels × cout`) = bias + columns · matrix.
    fn product(&self, columns: &[f32], pixels: usize, dst: &mut [f32]) {
        self.product_strided(&self.matrix, columns, pixels, dst, self.cout);
    }

    /// Pixel p's `cout` values at `dst[p·stride..]` = bias + (columns · `matrix`)'s row p, for
    /// `matrix` of `columns.len() / pixels` rows (this layer's or a folded one).
    fn product_strided(
        &self,
        matrix: &[f32],
        columns: &[f32],
        pixels: usize,
        dst: &mut [f32],
        stride: usize,
    ) {
        if pixels == 0 {
            return;
        }
        let cout = self.cout;
        let depth = matrix.len() / cout;
        // What the unsafe product below relies on.
        assert!(
            stride >= cout
                && dst.len() >= (pixels - 1) * stride + cout
                && columns.len() >= pixels * depth
        );
        for p in 0..pixels {
            dst[p * stride..p * stride + cout].copy_from_slice(&self.bias);
        }
        // SAFETY: columns holds pixels×depth values row-major, the matrix depth×cout row-major,
        // dst pixel p's values at p·stride.. (stride ≥ cout, within dst as asserted), as the
        // strides say; the buffers do not overlap.
        unsafe {
            gemm::gemm(
                pixels,
                cout,
                depth,
                dst.as_mut_ptr(),
                1,
                stride as isize,
                true,
                columns.as_ptr(),
                1,
                depth as isize,
                matrix.as_ptr(),
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

    /// `dst` (`cout` rows of `stride` ≥ `pixels` values, output-channel-major) = bias +
    /// (columns · matrix)ᵀ: each output channel's values of all pixels in one run, the layout
    /// the combination reads lanes of neighbouring pixels from (and gemm's natural,
    /// column-major, destination).
    fn product_transposed(&self, columns: &[f32], pixels: usize, dst: &mut [f32], stride: usize) {
        let (depth, cout) = (self.depth(), self.cout);
        // What the unsafe product below relies on.
        assert!(stride >= pixels && dst.len() >= cout * stride && columns.len() >= pixels * depth);
        for (row, &b) in dst.chunks_exact_mut(stride).zip(&self.bias) {
            row[..pixels].fill(b);
        }
        // SAFETY: columns holds pixels×depth values row-major, the matrix depth×cout row-major,
        // dst cout rows of `stride` ≥ pixels values (element (pixel, channel) at
        // channel·stride + pixel), as the strides say; the buffers do not overlap.
        unsafe {
            gemm::gemm(
                pixels,
                cout,
                depth,
                dst.as_mut_ptr(),
                stride as isize,
                1,
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
    fn forward_relu(&self, x: &[f32], input: Rect, out: Rect, buffers: &Buffers) -> Vec<f32> {
        let pixels = (out[2] - out[0]) * (out[3] - out[1]);
        let mut y = buffers.take(pixels * self.cout);
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

    /// [`ConvMatrix::forward_relu`] reading the channels of `sources` concatenated.
    fn forward_relu_sources(&self, sources: &[Source], out: Rect, buffers: &Buffers) -> Vec<f32> {
        if let [single @ Source {
            upsampled: None, ..
        }] = sources
        {
            return self.forward_relu(single.x, single.rect, out, buffers);
        }
        if let Some(folded) = &self.folded {
            return folded.forward_relu(self, sources, out, buffers);
        }
        let pixels = (out[2] - out[0]) * (out[3] - out[1]);
        let mut y = buffers.take(pixels * self.cout);
        y.par_chunks_mut(CHUNK_PIXELS * self.cout)
            .enumerate()
            .for_each_init(Vec::new, |columns, (chunk, dst)| {
                self.product_sources(sources, out, chunk * CHUNK_PIXELS, columns, dst);
                for v in dst.iter_mut() {
                    *v = v.max(0.0);
                }
            });
        y
    }

    /// `dst` = bias + the convolution of `sources` at the output pixels `first..` of `out`
    /// (`dst.len() / cout` of them, row-major), before ReLU; `columns` is scratch.
    fn product_sources(
        &self,
        sources: &[Source],
        out: Rect,
        first: usize,
        columns: &mut Vec<f32>,
        dst: &mut [f32],
    ) {
        let n = dst.len() / self.cout;
        columns.resize(n * self.depth(), 0.0);
        self.im2col_sources(sources, out, first, columns);
        self.product(columns, n, dst);
    }
}

/// `len` zeros written on every core: a large buffer's first touch (the kernel mapping and
/// zeroing its pages, or the allocator's memset of reused memory) is otherwise serial.
pub fn zeros(len: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(len);
    v.par_extend(rayon::iter::repeat_n(0.0f32, len));
    v
}

/// `dst.copy_from_slice(src)` for the short runs of im2col and upsampling (a pixel's channels,
/// a kernel row's taps): runs of whole 16-value blocks are copied block by block, which compiles
/// to inline vector moves, where `copy_from_slice` calls `memmove` once per run (≈ 10 % of the
/// U-Net's time went to those calls).
#[inline(always)]
fn copy_run(dst: &mut [f32], src: &[f32]) {
    const BLOCK: usize = 16;
    if dst.len().is_multiple_of(BLOCK) && dst.len() == src.len() {
        for (d, s) in dst.chunks_exact_mut(BLOCK).zip(src.chunks_exact(BLOCK)) {
            let s: &[f32; BLOCK] = s.try_into().expect("whole blocks");
            let d: &mut [f32; BLOCK] = d.try_into().expect("whole blocks");
            *d = *s;
        }
    } else {
        dst.copy_from_slice(src);
    }
}

/// The `k`×`k` taps around output pixel (ox, oy) of a source read as it lies (not
/// upsampled), in the im2col order `[ky][kx][channel]`, into `taps` (`k²·channels` values);
/// taps outside the source's rectangle are zero (they lie outside the grid).
#[inline(always)]
fn dense_taps(source: &Source, k: usize, oy: usize, ox: usize, taps: &mut [f32]) {
    let (c, input) = (source.channels, source.rect);
    let r = k / 2;
    let in_w = input[2] - input[0];
    // Taps kx read column ox + kx − r; those inside the rectangle are one run.
    let kx_lo = (input[0] + r).saturating_sub(ox).min(k);
    let kx_hi = (input[2] + r).saturating_sub(ox).min(k).max(kx_lo);
    for (ky, taps) in taps.chunks_exact_mut(k * c).enumerate() {
        let iy = (oy + ky).wrapping_sub(r);
        if iy < input[1] || iy >= input[3] {
            taps.fill(0.0);
            continue;
        }
        taps[..kx_lo * c].fill(0.0);
        let src = ((iy - input[1]) * in_w + (ox + kx_lo - r - input[0])) * c;
        let len = (kx_hi - kx_lo) * c;
        copy_run(&mut taps[kx_lo * c..kx_hi * c], &source.x[src..src + len]);
        taps[kx_hi * c..].fill(0.0);
    }
}

/// 2×2 average pooling onto `out` (a rectangle of the coarser grid) of `source` (the finer
/// grid's values; pixels past its rectangle lie past the grid's border and count as 0).
fn pool(source: Source, out: Rect, buffers: &Buffers) -> Vec<f32> {
    let c = source.channels;
    let (rect, x) = (source.rect, source.x);
    let in_w = rect[2] - rect[0];
    let out_w = out[2] - out[0];
    let mut y = buffers.take(out_w * (out[3] - out[1]) * c);
    let value = |iy: usize, ix: usize, ch: usize| {
        if iy < rect[3] && ix < rect[2] {
            x[((iy - rect[1]) * in_w + ix - rect[0]) * c + ch]
        } else {
            0.0
        }
    };
    y.par_chunks_mut(out_w * c)
        .enumerate()
        .for_each(|(row, dst)| {
            let iy = 2 * (out[1] + row);
            for (i, px) in dst.chunks_exact_mut(c).enumerate() {
                let ix = 2 * (out[0] + i);
                for (ch, v) in px.iter_mut().enumerate() {
                    // The Burn path's order: each row's pair, then the two rows.
                    let top = value(iy, ix, ch) + value(iy, ix + 1, ch);
                    let bottom = value(iy + 1, ix, ch) + value(iy + 1, ix + 1, ch);
                    *v = (top + bottom) * 0.25;
                }
            }
        });
    y
}

/// ỹ − z̃ʲ for every correlated level j of planar `levels` (`[3·m][pixels]`), planar
/// `[(m − 1)·3][pixels]` (what [`CombinationInputs::differences`] holds).
pub fn level_differences(levels: &[f32], pixels: usize) -> Vec<f32> {
    let mut out = zeros(levels.len().saturating_sub(3 * pixels));
    if pixels == 0 {
        return out;
    }
    let y = &levels[..3 * pixels];
    // Plane by plane on every core: plane i is channel i % 3 of a z̃ level.
    out.par_chunks_mut(pixels)
        .zip(levels[3 * pixels..].par_chunks(pixels))
        .enumerate()
        .for_each(|(i, (out, z))| {
            let y = &y[(i % 3) * pixels..][..pixels];
            for ((d, y), z) in out.iter_mut().zip(y).zip(z) {
                *d = y - z;
            }
        });
    out
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
    /// A U-Net's plan ([`crate::unet::UNet::plan`]); `None`: the hidden layers run in order.
    plan: Option<Vec<Step>>,
    /// Activation buffers no longer read, for the next layers and tiles.
    buffers: Buffers,
}

/// Activation buffers handed from layers that are done to layers that start. A fresh
/// multi-MB allocation is mapped from the kernel page by page, each page zeroed on first touch;
/// a buffer taken from here is already mapped (19 % fewer page faults in a 1280×720
/// reconstruction). Every user overwrites the whole buffer, so its old values never matter.
#[derive(Default)]
struct Buffers(std::sync::Mutex<Vec<Vec<f32>>>);

impl Buffers {
    /// A buffer of `len` values (their contents unspecified): the smallest held one that
    /// fits, else a new one. When none fits, the largest held one is freed first, so what is
    /// held plus what is in use never exceeds what fresh allocations would have needed by more
    /// than the buffers too small for anything still to come.
    fn take(&self, len: usize) -> Vec<f32> {
        let mut held = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let fits = (0..held.len())
            .filter(|&i| held[i].capacity() >= len)
            .min_by_key(|&i| held[i].capacity());
        match fits {
            Some(i) => {
                let mut buffer = held.swap_remove(i);
                drop(held);
                // Shrinking keeps the values; growing within the capacity writes zeros only
                // over already mapped memory.
                if buffer.len() >= len {
                    buffer.truncate(len);
                } else {
                    let more = len - buffer.len();
                    buffer.par_extend(rayon::iter::repeat_n(0.0, more));
                }
                buffer
            }
            None => {
                if let Some(i) = (0..held.len()).max_by_key(|&i| held[i].capacity()) {
                    drop(held.swap_remove(i));
                }
                drop(held);
                zeros(len)
            }
        }
    }

    /// Hands back a buffer no longer read.
    fn give(&self, buffer: Vec<f32>) {
        self.0
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(buffer);
    }
}

impl Clone for Buffers {
    /// A clone starts with no buffers of its own.
    fn clone(&self) -> Self {
        Buffers::default()
    }
}

impl std::fmt::Debug for Buffers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let held = self.0.lock().map_or(0, |b| b.len());
        write!(f, "Buffers({held} held)")
    }
}

/// Planar colours of the whole image that the combination reads.
pub struct CombinationInputs<'a> {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Planar colours `[3·m][pixels]`: ỹ RGB, then each correlated level's RGB.
    pub levels: &'a [f32],
    /// ỹ − z̃ʲ of every correlated level j, planar `[(m − 1)·3][pixels]`
    /// ([`level_differences`]): the window sums read these, once per pixel instead of once per
    /// window entry.
    pub differences: &'a [f32],
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
        let plan = config.unet.as_ref().map(|u| u.plan(config.in_channels));
        // A U-Net's convolutions of concatenated inputs take their rows source by source.
        // Those whose first input is an upsampling read it folded onto the coarse pixels.
        let mut splits: Vec<Vec<usize>> = vec![Vec::new(); network.hidden.len()];
        let mut upsampled = vec![false; network.hidden.len()];
        for step in plan.iter().flatten() {
            if let Op::Conv { layer, inputs } = &step.op {
                let plan = plan.as_ref().expect("steps come from a plan");
                splits[*layer] = inputs.iter().map(|&i| plan[i].channels).collect();
                upsampled[*layer] = matches!(plan[inputs[0]].op, Op::Upsample(_))
                    && inputs[1..]
                        .iter()
                        .all(|&i| !matches!(plan[i].op, Op::Upsample(_)));
            }
        }
        Self {
            hidden: network
                .hidden
                .iter()
                .zip(&splits)
                .zip(&upsampled)
                .map(|((conv, split), &upsampled)| match split.len() {
                    0 | 1 => ConvMatrix::from_conv(conv),
                    _ => {
                        let mut m = ConvMatrix::from_concat_conv(conv, split);
                        if upsampled {
                            m.folded = FoldedUpsampling::new(&m, split[0]).map(Box::new);
                        }
                        m
                    }
                })
                .collect(),
            output: ConvMatrix::from_conv(&network.output),
            weighting: network.weighting,
            window: config.window,
            pairs: config.pairs(),
            guard: config.guard,
            guard_target_noise: config.guard_target_noise,
            plan,
            buffers: Buffers::default(),
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
        let mut x = self.buffers.take(rw * rh * channels);
        // Row by row, every channel of a pixel written together (sequential writes; one read
        // stream per plane).
        let planes: Vec<&[f32]> = features.chunks_exact(width * height).collect();
        x.par_chunks_mut(rw * channels)
            .enumerate()
            .for_each(|(y, dst)| {
                let at = (region[1] + y) * width + region[0];
                for (i, px) in dst.chunks_exact_mut(channels).enumerate() {
                    for (v, plane) in px.iter_mut().zip(&planes) {
                        *v = plane[at + i];
                    }
                }
            });
        if let Some(plan) = &self.plan {
            return self.unet_layers(plan, x, width, height, region, interior);
        }
        let reach = self.output.kernel / 2;
        let layers = self.hidden.len() + 1;
        let mut region = region;
        for (l, conv) in self.hidden.iter().enumerate() {
            let out = grow(interior, (layers - 1 - l) * reach, width, height);
            let y = conv.forward_relu(&x, region, out, &self.buffers);
            self.buffers.give(std::mem::replace(&mut x, y));
            region = out;
        }
        (x, region)
    }

    /// The U-Net's hidden steps from the channels-last features `x` on `region`: each step on
    /// the rectangle the later ones need for the output layer to be exact on `interior`.
    /// Returns the last step's activation and its rectangle.
    fn unet_layers(
        &self,
        plan: &[Step],
        x: Vec<f32>,
        width: usize,
        height: usize,
        region: Rect,
        interior: Rect,
    ) -> (Vec<f32>, Rect) {
        let kernel = self.hidden[0].kernel;
        let scales = plan.iter().map(|s| s.scale).max().unwrap_or(0) + 1;
        let sizes = scale_sizes(width, height, scales);
        let out = grow(interior, self.output.kernel / 2, width, height);
        let need = needed_rects(plan, kernel, out, &sizes);
        // An upsampling is not computed: the convolutions reading it read its coarse input in
        // place ([`Source::upsampled`]), which therefore lives as long as they need it.
        let mut last_use = last_uses(plan);
        for (i, step) in plan.iter().enumerate() {
            if let Op::Upsample(j) = step.op {
                last_use[j] = last_use[j].max(last_use[i]);
            }
        }
        let mut values: Vec<Option<Activation>> = vec![None; plan.len()];
        let mut features = Some(x);
        for (i, step) in plan.iter().enumerate() {
            let Some(r) = need[i] else { continue };
            let dense = |j: usize| match values[j].as_ref().expect("inputs come first") {
                Activation::Dense(x, rect) => (x, *rect),
                Activation::Upsampled { .. } => unreachable!("only convolutions read upsamplings"),
            };
            let source = |j: usize| match values[j].as_ref().expect("inputs come first") {
                Activation::Dense(x, rect) => Source {
                    x,
                    rect: *rect,
                    channels: plan[j].channels,
                    upsampled: None,
                },
                &Activation::Upsampled { coarse, fine } => {
                    let (x, rect) = dense(coarse);
                    Source {
                        x,
                        rect,
                        channels: plan[j].channels,
                        upsampled: Some(fine),
                    }
                }
            };
            let value = match &step.op {
                Op::Input => {
                    assert!(
                        crate::unet::covers(region, r),
                        "features on {region:?} do not cover the needed {r:?}"
                    );
                    Activation::Dense(features.take().expect("one input step"), region)
                }
                Op::Conv { layer, inputs } => {
                    let sources: Vec<Source> = inputs.iter().map(|&j| source(j)).collect();
                    let y = self.hidden[*layer].forward_relu_sources(&sources, r, &self.buffers);
                    Activation::Dense(y, r)
                }
                Op::Pool(j) => {
                    debug_assert!(contains(
                        Some(dense(*j).1),
                        pool_input(r, sizes[step.scale - 1])
                    ));
                    Activation::Dense(pool(source(*j), r, &self.buffers), r)
                }
                Op::Upsample(j) => {
                    debug_assert!(contains(Some(dense(*j).1), upsample_input(r)));
                    Activation::Upsampled {
                        coarse: *j,
                        fine: r,
                    }
                }
            };
            values[i] = Some(value);
            for (j, v) in values.iter_mut().enumerate().take(i) {
                if last_use[j] == i {
                    if let Some(Activation::Dense(x, _)) = v.take() {
                        self.buffers.give(x);
                    }
                }
            }
        }
        match values.pop().flatten().expect("the plan has steps") {
            Activation::Dense(x, rect) => (x, rect),
            Activation::Upsampled { .. } => unreachable!("a plan ends with a convolution"),
        }
    }

    /// Hands back the activation [`NativeNetwork::hidden_layers`] returned, once combined, for
    /// the next tile's layers.
    pub fn recycle(&self, x: Vec<f32>) {
        self.buffers.give(x);
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
                || (Vec::new(), Vec::new(), Vec::new()),
                |(columns, raw, weights), chunk| {
                    let first = chunk * CHUNK_PIXELS;
                    let n = CHUNK_PIXELS.min(count - first);
                    // Per-worker buffers, fully overwritten (im2col; bias then product). A 1×1
                    // layer on its own input rectangle reads the activations as they lie: its
                    // im2col rows would be a copy of them. `raw` is entry-major, `[entry][stride]`.
                    // Entries lie `stride` values apart; a multiple of 1 KiB would put the
                    // LANES values of every fourth entry in the same L1 cache sets.
                    let stride = n + LANES;
                    raw.resize(stride * conv.cout, 0.0);
                    if conv.kernel == 1 && region == out {
                        let x = &x[first * conv.cin..(first + n) * conv.cin];
                        conv.product_transposed(x, n, raw, stride);
                    } else {
                        columns.resize(n * conv.depth(), 0.0);
                        conv.im2col(x, region, out, first, columns);
                        conv.product_transposed(columns, n, raw, stride);
                    }
                    let mut colour = vec![0.0f32; 3 * n];
                    let mut share = vec![0.0f32; self.pairs * n];
                    let mut store = |p: usize, (rgb, sums): ([f32; 3], [f32; LEVELS - 1])| {
                        for c in 0..3 {
                            colour[c * n + p] = rgb[c];
                        }
                        for j in 0..self.pairs {
                            share[j * n + p] = sums[j];
                        }
                    };
                    let cout = conv.cout;
                    let mut p = 0;
                    while p < n {
                        let q = first + p;
                        let (py, px) = (out[1] + q / out_w, out[0] + q % out_w);
                        // LANES pixels of one row whose windows lie inside the image together;
                        // the rest (image borders, row ends) one by one. Same results.
                        if p + LANES <= n
                            && px + LANES <= out[2]
                            && self.window_inside(px, py, LANES, colours)
                        {
                            // Entry e of the LANES pixels is one run of `raw`, read in
                            // place (no copy into `[entry][lane]` arrays first).
                            let block = EntryLanes {
                                raw: &mut raw[p..],
                                stride,
                                entries: cout,
                            };
                            let results = self.combine_lanes(block, px, py, colours);
                            for (l, result) in results.into_iter().enumerate() {
                                store(p + l, result);
                            }
                            p += LANES;
                        } else {
                            weights.clear();
                            weights.extend((0..cout).map(|e| raw[e * stride + p]));
                            store(p, self.combine_pixel(weights, px, py, colours));
                            p += 1;
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

    /// Whether the windows of the `lanes` pixels (px.., py) of one row lie wholly inside the image.
    fn window_inside(
        &self,
        px: usize,
        py: usize,
        lanes: usize,
        colours: &CombinationInputs,
    ) -> bool {
        let r = self.window / 2;
        px >= r && py >= r && px + lanes - 1 + r < colours.width && py + r < colours.height
    }

    /// [`NativeNetwork::combine_pixel`] for the [`LANES`] pixels (px + l, py) of one row whose
    /// windows lie inside the image, from their raw outputs `lanes` (under the softmax
    /// weighting overwritten with the positive weights). Each lane does the scalar function's
    /// arithmetic in its order (bit-identical, `tests::lanes_equal_single_pixels`); the lanes
    /// only let the compiler use vector instructions, which the scalar window sums (sequential
    /// float additions) cannot.
    fn combine_lanes(
        &self,
        lanes: EntryLanes,
        px: usize,
        py: usize,
        colours: &CombinationInputs,
    ) -> [([f32; 3], [f32; LEVELS - 1]); LANES] {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F (checked just above).
                return unsafe { self.combine_lanes_avx512(lanes, px, py, colours) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (checked just above).
                return unsafe { self.combine_lanes_avx2(lanes, px, py, colours) };
            }
        }
        self.combine_lanes_portable(lanes, px, py, colours)
    }

    /// [`NativeNetwork::combine_lanes`] compiled for AVX-512: all sixteen lanes in one vector.
    /// The same operations in the same order (Rust never fuses a multiply and an add), so the
    /// same bits as the portable build.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn combine_lanes_avx512(
        &self,
        lanes: EntryLanes,
        px: usize,
        py: usize,
        colours: &CombinationInputs,
    ) -> [([f32; 3], [f32; LEVELS - 1]); LANES] {
        self.combine_lanes_portable(lanes, px, py, colours)
    }

    /// [`NativeNetwork::combine_lanes`] compiled for AVX2 (two vectors of eight lanes), the
    /// same bits as the portable build.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn combine_lanes_avx2(
        &self,
        lanes: EntryLanes,
        px: usize,
        py: usize,
        colours: &CombinationInputs,
    ) -> [([f32; 3], [f32; LEVELS - 1]); LANES] {
        self.combine_lanes_portable(lanes, px, py, colours)
    }

    /// [`NativeNetwork::combine_lanes`] for any CPU (inlined into the AVX2 build).
    #[inline(always)]
    fn combine_lanes_portable(
        &self,
        mut lanes: EntryLanes,
        px: usize,
        py: usize,
        colours: &CombinationInputs,
    ) -> [([f32; 3], [f32; LEVELS - 1]); LANES] {
        let pixels = colours.width * colours.height;
        let width = colours.width;
        let window = self.window;
        let r = window / 2;
        let area = window * window;
        // Positive weights, lane by lane what [`NativeNetwork::positive`] does to one pixel
        // (its whole window is inside the image). ReLU's is taken where the window sums read
        // each raw value ([`RowSums::add_tap`]: one pass over the entries instead of two); the
        // softmax needs every entry's maximum first, so it rewrites them here.
        let relu = self.weighting == Weighting::Relu;
        if !relu {
            // The maximum of each lane over all entries (f32::max ignores NaN, so the
            // order does not matter), as `positive` takes it.
            let mut max = [f32::NEG_INFINITY; LANES];
            for e in 0..lanes.entries {
                let w = lanes.entry(e);
                for l in 0..LANES {
                    max[l] = max[l].max(w[l]);
                }
            }
            for e in 0..lanes.entries {
                let w = lanes.entry_mut(e);
                for l in 0..LANES {
                    w[l] = (w[l] - max[l]).exp();
                }
            }
        }
        let lanes = &lanes;
        let centre = py * width + px;
        let mut numerator = [[0.0f32; LANES]; 3];
        let mut sums = [[0.0f32; LANES]; LEVELS - 1];
        let mut squares = [[0.0f32; LANES]; LEVELS - 1];
        for j in 0..self.pairs {
            let z_planes = &colours.levels[3 * (j + 1) * pixels..3 * (j + 2) * pixels];
            let d_planes = &colours.differences[3 * j * pixels..3 * (j + 1) * pixels];
            let mut sum = [0.0f32; LANES];
            let mut square = [0.0f32; LANES];
            let mut acc = [[0.0f32; LANES]; 3];
            // Each window row's five sums (W, Σw², Σw·d per channel) are added up in window
            // order (the scalar path's) and then added to the pixel's in row order; two rows
            // run in one loop so that their ten chains of dependent additions overlap.
            let guard = self.guard > 0.0;
            // Row ky of the window: its first tap's offset in the planes and entry.
            let at = |ky: usize| ((py + ky - r) * width + px - r, j * area + ky * window);
            for pair in 0..window / 2 {
                let (upper, lower) = (at(2 * pair), at(2 * pair + 1));
                let (mut above, mut below) = (RowSums::default(), RowSums::default());
                for kx in 0..window {
                    above.add_tap(lanes, relu, d_planes, pixels, upper, kx);
                    below.add_tap(lanes, relu, d_planes, pixels, lower, kx);
                }
                above.add_to(&mut sum, &mut square, &mut acc, guard);
                below.add_to(&mut sum, &mut square, &mut acc, guard);
            }
            if window % 2 == 1 {
                let mut last = RowSums::default();
                for kx in 0..window {
                    last.add_tap(lanes, relu, d_planes, pixels, at(window - 1), kx);
                }
                last.add_to(&mut sum, &mut square, &mut acc, guard);
            }
            for c in 0..3 {
                let zc = &z_planes[c * pixels + centre..][..LANES];
                for l in 0..LANES {
                    numerator[c][l] += acc[c][l] + sum[l] * zc[l];
                }
            }
            sums[j] = sum;
            squares[j] = square;
        }
        let (rgb, shares) = self.finish(numerator, sums, squares, centre, colours);
        std::array::from_fn(|l| (rgb.map(|c| c[l]), shares.map(|s| s[l])))
    }

    /// The positive transform of one pixel's raw outputs, in place; `inside` = (ky0, ky1, kx0,
    /// kx1), the window rows and columns inside the image (the softmax's maximum is taken over
    /// them).
    fn positive(&self, weights: &mut [f32], inside: (usize, usize, usize, usize)) {
        let (ky0, ky1, kx0, kx1) = inside;
        let window = self.window;
        let area = window * window;
        match self.weighting {
            Weighting::Relu => {
                for w in weights.iter_mut() {
                    *w = relu_weight(*w);
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
        self.positive(weights, (ky0, ky1, kx0, kx1));
        let centre = py * width + px;
        let mut numerator = [0.0f32; 3];
        let mut sums = [0.0f32; LEVELS - 1];
        let mut squares = [0.0f32; LEVELS - 1];
        for j in 0..self.pairs {
            let z_planes = &colours.levels[3 * (j + 1) * pixels..3 * (j + 2) * pixels];
            let d_planes = &colours.differences[3 * j * pixels..3 * (j + 1) * pixels];
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
                    let dc = &d_planes[c * pixels + start..][..len];
                    acc[c] += w_row.iter().zip(dc).map(|(w, d)| w * d).sum::<f32>();
                }
            }
            for c in 0..3 {
                numerator[c] += acc[c] + sum * z_planes[c * pixels + centre];
            }
            sums[j] = sum;
            squares[j] = square;
        }
        self.finish_pixel(numerator, sums, squares, centre, colours)
    }

    /// Eq. 6's normalisation, the safeguard and the clamp at pixel `centre` from its window
    /// sums: Σ_j numerators, the weight sums W_j and (with the guard) Σ_i (w^j_i)².
    fn finish_pixel(
        &self,
        numerator: [f32; 3],
        sums: [f32; LEVELS - 1],
        squares: [f32; LEVELS - 1],
        centre: usize,
        colours: &CombinationInputs,
    ) -> ([f32; 3], [f32; LEVELS - 1]) {
        let (rgb, shares) = self.finish(
            numerator.map(|v| [v]),
            sums.map(|v| [v]),
            squares.map(|v| [v]),
            centre,
            colours,
        );
        (rgb.map(|[v]| v), shares.map(|[v]| v))
    }

    /// [`NativeNetwork::finish_pixel`] for the `N` pixels `centre..centre + N` of one row, each
    /// value an array of the pixels' (lane l: pixel centre + l). Every lane does the one-pixel
    /// arithmetic in its order — one home for it, and lanes the compiler can turn into vector
    /// instructions (the per-pixel scalar version took ≈ 3 % of a 1280×720 reconstruction).
    #[inline(always)]
    fn finish<const N: usize>(
        &self,
        numerator: [[f32; N]; 3],
        mut sums: [[f32; N]; LEVELS - 1],
        squares: [[f32; N]; LEVELS - 1],
        centre: usize,
        colours: &CombinationInputs,
    ) -> ([[f32; N]; 3], [[f32; N]; LEVELS - 1]) {
        let pixels = colours.width * colours.height;
        let mut total = [0.0f32; N];
        for (l, total) in total.iter_mut().enumerate() {
            *total = sums.iter().map(|s| s[l]).sum();
        }
        let mut rgb = numerator.map(|n| std::array::from_fn::<f32, N, _>(|l| n[l] / total[l]));
        if self.guard > 0.0 {
            let v = |level: usize| -> &[f32; N] {
                colours.variances[level * pixels + centre..][..N]
                    .try_into()
                    .expect("N values")
            };
            let total_squared = total.map(|t| t * t);
            let mut noise = [0.0f32; N];
            for j in 0..self.pairs {
                let (vj, v0) = (v(j + 1), v(0));
                for l in 0..N {
                    noise[l] += squares[j][l] / total_squared[l] * (vj[l] + v0[l])
                        + sums[j][l] * sums[j][l] / total_squared[l] * vj[l];
                }
            }
            let target_noise =
                v(self.pairs).map(|v| self.guard_target_noise * v + GUARD_EVIDENCE_FLOOR);
            let levels = &colours.levels[3 * self.pairs * pixels..];
            for (c, out) in rgb.iter_mut().enumerate() {
                let base: &[f32; N] = levels[c * pixels + centre..][..N]
                    .try_into()
                    .expect("N values");
                for l in 0..N {
                    let delta = out[l] - base[l];
                    let ratio = self.guard * noise[l] / (delta * delta + target_noise[l]);
                    // As the Burn path caps it (a NaN stays NaN, as there).
                    let ratio = if ratio > GUARD_RATIO_CAP {
                        GUARD_RATIO_CAP
                    } else {
                        ratio
                    };
                    let guarded = base[l] + delta * (1.0 / (1.0 + ratio * ratio));
                    // A non-finite Eq. 6 (overflow) is left as it is, for the caller to report.
                    if out[l].is_finite() {
                        out[l] = guarded;
                    }
                }
            }
        }
        let rgb = rgb.map(|c| c.map(|v| v.max(0.0)));
        for s in sums.iter_mut() {
            for l in 0..N {
                s[l] /= total[l];
            }
        }
        (rgb, sums)
    }
}

pub use crate::unet::grow;

/// One window row's running sums for [`LANES`] pixels, each added in window order: W (the
/// weights), Σw² and Σw·(ỹ − z̃ʲ) per channel. Named fields: the compiler keeps them in
/// registers (arrays of them went through the stack).
#[derive(Clone, Copy, Default)]
struct RowSums {
    w: [f32; LANES],
    w_square: [f32; LANES],
    wd0: [f32; LANES],
    wd1: [f32; LANES],
    wd2: [f32; LANES],
}

impl RowSums {
    /// Adds the window tap `kx` of the row given as the offset of the first pixel's leftmost tap
    /// in the planar differences `d_planes` (three planes of `pixels`) and the entry of that tap
    /// in `lanes`; with `relu`, `lanes` holds raw outputs, each made a positive weight as it is
    /// read (max(w, 0) + 10⁻⁴, [`NativeNetwork::positive`]).
    #[inline(always)]
    fn add_tap(
        &mut self,
        lanes: &EntryLanes,
        relu: bool,
        d_planes: &[f32],
        pixels: usize,
        (start, first): (usize, usize),
        kx: usize,
    ) {
        let w = weight(lanes.entry(first + kx), relu);
        let [d0, d1, d2] = taps(d_planes, pixels, start + kx);
        for l in 0..LANES {
            self.w[l] += w[l];
            self.w_square[l] += w[l] * w[l];
            self.wd0[l] += w[l] * d0[l];
            self.wd1[l] += w[l] * d1[l];
            self.wd2[l] += w[l] * d2[l];
        }
    }

    /// Adds this row's sums to the pixel's: W, (with the guard) Σw², and Σw·(ỹ − z̃ʲ) per
    /// channel.
    #[inline(always)]
    fn add_to(
        &self,
        sum: &mut [f32; LANES],
        square: &mut [f32; LANES],
        acc: &mut [[f32; LANES]; 3],
        guard: bool,
    ) {
        for (to, from) in sum.iter_mut().zip(&self.w) {
            *to += from;
        }
        if guard {
            for (to, from) in square.iter_mut().zip(&self.w_square) {
                *to += from;
            }
        }
        for (acc, row) in acc.iter_mut().zip([&self.wd0, &self.wd1, &self.wd2]) {
            for (to, from) in acc.iter_mut().zip(row) {
                *to += from;
            }
        }
    }
}

/// The ReLU weighting's positive weight of one raw output: max(w, 0) + 10⁻⁴.
#[inline(always)]
fn relu_weight(w: f32) -> f32 {
    w.max(0.0) + 1e-4
}

/// The [`LANES`] weights of one window entry: with `relu` made positive from raw outputs as
/// [`NativeNetwork::positive`] does (max(w, 0) + 10⁻⁴), else already positive.
#[inline(always)]
fn weight(entry: &[f32; LANES], relu: bool) -> [f32; LANES] {
    if relu {
        entry.map(relu_weight)
    } else {
        *entry
    }
}

/// The three channels' ỹ − z̃ʲ of the [`LANES`] pixels from offset `at` of planar `d_planes`.
#[inline(always)]
fn taps(d_planes: &[f32], pixels: usize, at: usize) -> [&[f32; LANES]; 3] {
    [0, 1, 2].map(|c| {
        d_planes[c * pixels + at..][..LANES]
            .try_into()
            .expect("LANES values")
    })
}

/// Whether rectangle `outer` (absent: no) holds `inner`.
fn contains(outer: Option<Rect>, inner: Rect) -> bool {
    outer.is_some_and(|o| {
        o[0] <= inner[0] && o[1] <= inner[1] && o[2] >= inner[2] && o[3] >= inner[3]
    })
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
            folded: None,
        };
        NativeNetwork {
            hidden: Vec::new(),
            output: empty,
            weighting,
            window,
            pairs,
            guard: 0.0,
            guard_target_noise: 0.0,
            plan: None,
            buffers: Buffers::default(),
        }
    }

    /// The lane-parallel combination computes every pixel's result bit for bit as the
    /// one-pixel function does (both weightings, guard on and off, raw outputs and colours with
    /// zeros, negative values and a wide range of magnitudes).
    #[test]
    fn lanes_equal_single_pixels() {
        let (width, height, window, pairs) = (LANES + 9, 9, 7, 4);
        let pixels = width * height;
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut draw = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let u = (state >> 40) as f32 / (1u64 << 24) as f32;
            match state % 7 {
                0 => 0.0,
                1 => -u,
                2 => 300.0 * u,
                _ => u,
            }
        };
        let levels: Vec<f32> = (0..3 * (pairs + 1) * pixels).map(|_| draw()).collect();
        let variances: Vec<f32> = (0..(pairs + 1) * pixels).map(|_| draw().abs()).collect();
        let differences = level_differences(&levels, pixels);
        let colours = CombinationInputs {
            width,
            height,
            levels: &levels,
            differences: &differences,
            share_planes: &[0, 1, 2, 3],
            variances: &variances,
        };
        let entries = pairs * window * window;
        let raw: Vec<f32> = (0..LANES * entries).map(|_| 4.0 * draw() - 1.0).collect();
        let r = window / 2;
        for weighting in [Weighting::Relu, Weighting::Softmax] {
            for guard in [0.0, 16.0] {
                let net = NativeNetwork {
                    guard,
                    guard_target_noise: 8.0,
                    ..combiner(weighting, window, pairs)
                };
                for (px, py) in [(r, r), (width - r - LANES, height - r - 1), (r + 3, 5)] {
                    assert!(net.window_inside(px, py, LANES, &colours));
                    // The network's raw outputs of the LANES pixels as the product lays them
                    // out, entry-major with a stride longer than LANES.
                    let stride = LANES + 3;
                    let mut entry_major = vec![f32::NAN; entries * stride];
                    for e in 0..entries {
                        for l in 0..LANES {
                            entry_major[e * stride + l] = raw[l * entries + e];
                        }
                    }
                    fn block(raw: &mut [f32], stride: usize, entries: usize) -> EntryLanes<'_> {
                        EntryLanes {
                            raw,
                            stride,
                            entries,
                        }
                    }
                    let mut lanes = entry_major.clone();
                    let together =
                        net.combine_lanes(block(&mut lanes, stride, entries), px, py, &colours);
                    let mut portable = entry_major.clone();
                    let again = net.combine_lanes_portable(
                        block(&mut portable, stride, entries),
                        px,
                        py,
                        &colours,
                    );
                    assert!(
                        together == again,
                        "{weighting:?} {guard}: the vector build differs"
                    );
                    #[cfg(target_arch = "x86_64")]
                    if std::arch::is_x86_feature_detected!("avx2") {
                        let mut avx2 = entry_major.clone();
                        // SAFETY: the CPU has AVX2 (checked just above).
                        let eight = unsafe {
                            net.combine_lanes_avx2(
                                block(&mut avx2, stride, entries),
                                px,
                                py,
                                &colours,
                            )
                        };
                        assert!(
                            eight == again,
                            "{weighting:?} {guard}: the AVX2 build differs"
                        );
                    }
                    for (l, (rgb, shares)) in together.iter().enumerate() {
                        let mut weights = raw[l * entries..(l + 1) * entries].to_vec();
                        let (one_rgb, one_shares) =
                            net.combine_pixel(&mut weights, px + l, py, &colours);
                        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(bits(rgb), bits(&one_rgb), "{weighting:?} {guard} lane {l}");
                        assert_eq!(bits(shares), bits(&one_shares), "{weighting:?} {guard}");
                    }
                }
                assert!(!net.window_inside(r - 1, r, LANES, &colours));
                assert!(!net.window_inside(width - r - LANES + 1, r, LANES, &colours));
            }
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
        let differences = level_differences(&levels, 4);
        let colours = CombinationInputs {
            width: 2,
            height: 2,
            levels: &levels,
            differences: &differences,
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
        let differences = level_differences(&negative, 4);
        let colours = CombinationInputs {
            levels: &negative,
            differences: &differences,
            ..colours
        };
        let mut w = raw;
        let (rgb, _) = combiner(Weighting::Relu, 3, 1).combine_pixel(&mut w, 0, 0, &colours);
        assert_eq!(rgb, [0.0; 3]);
    }
}
