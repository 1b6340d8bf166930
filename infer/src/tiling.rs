//! Tiled reconstruction: the image is cut into tiles, each grown by a halo as wide as the
//! convolutions' reach, reconstructed, and cropped back; inside a tile the last layer and the
//! combination run one band of rows at a time.
//!
//! Why this equals the untiled result: an output pixel depends on features within the
//! convolutions' reach and on colours within the combination window. Every convolution is
//! evaluated only where its result is exact — on the tile grown by the reach of the layers still
//! to come — reading the previous layer's values on that region grown by the kernel radius;
//! where a region is clipped, it is clipped at the image border, where the whole-image
//! computation sees the same zero padding (and the combination the same out-of-image window
//! mask). Features are packed once for the whole image (depth is normalised per image), so tiles
//! see exactly the values the whole image has.
//!
//! Why this shape: the last layer (50 → (m−1)·|Ω| = 1444 channels for the paper network) is
//! about three quarters of the arithmetic and its output, with the combination's window
//! gather, is what fills memory. It is computed once per pixel (no halo recomputation), a band
//! of rows at a time, so memory is bounded by the band while tiles can be large (the hidden
//! layers' halo recomputation shrinks with the tile: 1.08× at 512 px, 1.37× at 128 px).
//!
//! Two engines run this plan: Burn's tensor operations on any backend (bands as above), and the
//! native CPU engine of `native.rs` (same tiles and regions, the last layer and the combination
//! fused per chunk of pixels, so no bands are needed).
//!
//! A U-Net (`model::unet`) follows the same rule at every scale: each step is computed on the
//! rectangle of its grid that the later steps need, so a tile's halo is the U-Net's reach
//! (`ModelConfig::conv_reach`, 43 px for the `unet` preset) and the pooling grid stays anchored
//! at the image's corner whatever the tile (no alignment of tiles is needed).

use std::borrow::Cow;

use burn::nn::conv::Conv2d;
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, TensorData};
use model::combine::{combine_guarded_block, level_weight_shares_block, Guard};
use model::features::PackedImage;
use model::network::{positive_weights, LEVELS};

use model::model_dir::TrainedModel;
use model::native::{grow, CombinationInputs, NativeNetwork, Rect};

/// Which code runs the network and the combination.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize, clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// The native CPU engine (`native.rs`: im2col + gemm, fused Eq. 6); ignores the device.
    Native,
    /// Burn's tensor operations on the chosen backend's device (the training code path).
    Burn,
}

impl Engine {
    /// The engine used when none is named: native on the CPU backend `flex` (≈ 2× faster than
    /// Burn there, docs/performance.md), Burn on every other backend.
    pub fn default_for(backend: model::backend::Backend) -> Self {
        match backend {
            model::backend::Backend::Flex => Engine::Native,
            _ => Engine::Burn,
        }
    }
}

/// Pixels per band of the last layer and the combination: about 0.8 GB of transient tensors
/// for the paper network (1444 weights and 4·3·361 gathered differences per pixel).
pub const BAND_PIXELS: usize = 16_384;

/// The combined image and the per-level weight shares, planar (`plane[c][y·width + x]`).
#[derive(Clone, Debug, PartialEq)]
pub struct Reconstruction {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// ŷ: three planes R, G, B.
    pub image: Vec<f32>,
    /// Share of the total weight on each correlated level z̃1..z̃4 (four planes, summing to 1;
    /// zero on levels a model combining a subset of levels does not read).
    pub shares: Vec<f32>,
}

/// One tile: the interior it writes and the grown region it reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tile {
    /// Interior `[x0, x1) × [y0, y1)`.
    pub interior: [usize; 4],
    /// Grown region `[x0, x1) × [y0, y1)` (interior + halo, clipped to the image).
    pub region: [usize; 4],
}

/// Cuts a `width`×`height` image into tiles of at most `tile`×`tile` interior pixels grown by
/// `halo`; `tile == 0` means one tile for the whole image.
pub fn plan_tiles(width: usize, height: usize, tile: usize, halo: usize) -> Vec<Tile> {
    let (tw, th) = if tile == 0 {
        (width.max(1), height.max(1))
    } else {
        (tile, tile)
    };
    let mut tiles = Vec::new();
    for y0 in (0..height).step_by(th) {
        for x0 in (0..width).step_by(tw) {
            let (x1, y1) = ((x0 + tw).min(width), (y0 + th).min(height));
            tiles.push(Tile {
                interior: [x0, y0, x1, y1],
                region: [
                    x0.saturating_sub(halo),
                    y0.saturating_sub(halo),
                    (x1 + halo).min(width),
                    (y1 + halo).min(height),
                ],
            });
        }
    }
    tiles
}

/// Copies `planes` planes of the `[x0,x1)×[y0,y1)` window out of planar whole-image data.
fn crop_planes(
    data: &[f32],
    planes: usize,
    width: usize,
    height: usize,
    r: [usize; 4],
) -> Vec<f32> {
    let [x0, y0, x1, y1] = r;
    let mut out = Vec::with_capacity(planes * (x1 - x0) * (y1 - y0));
    for p in 0..planes {
        let plane = &data[p * width * height..(p + 1) * width * height];
        for y in y0..y1 {
            out.extend_from_slice(&plane[y * width + x0..y * width + x1]);
        }
    }
    out
}

/// How to run inference: tile side, engine and (for the Burn engine) device.
#[derive(Clone, Copy, Debug)]
pub struct Inference<'a> {
    /// Tile side in pixels (0 = whole image).
    pub tile: usize,
    /// Which code computes the network and the combination.
    pub engine: Engine,
    /// Device of the Burn engine.
    pub device: &'a Device,
}

impl Inference<'_> {
    /// [`reconstruct_tiled`] with these settings and no progress report.
    pub fn reconstruct(&self, model: &TrainedModel, packed: &PackedImage) -> Reconstruction {
        reconstruct_tiled(
            model,
            packed,
            self.tile,
            self.engine,
            self.device,
            |_, _| {},
        )
    }
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

/// `conv` ("same" padding in the whole image) evaluated on `out` only, from its input `x`
/// given on `input` = `out` grown by the kernel radius and clipped to the image: zero padding
/// only where `input` stops short of that (the image border), none elsewhere.
fn conv_block(conv: &Conv2d, x: Tensor<4>, input: Rect, out: Rect) -> Tensor<4> {
    let k = conv.kernel_size[0] / 2;
    let [top, bottom, left, right] = insets(input, out).map(|inset| k - inset);
    let options = ConvOptions::new_with_padding(
        conv.stride,
        [(top, bottom), (left, right)],
        conv.dilation,
        conv.groups,
    );
    conv2d(
        x,
        conv.weight.val(),
        conv.bias.as_ref().map(|b| b.val()),
        options,
    )
}

/// The rows and columns of `inner` out of a tensor laid out on `outer`.
fn crop(x: Tensor<4>, outer: Rect, inner: Rect) -> Tensor<4> {
    let [top, _, left, _] = insets(outer, inner);
    x.narrow(2, top, inner[3] - inner[1])
        .narrow(3, left, inner[2] - inner[0])
}

/// Reconstructs the whole image tile by tile on `device`, calling `on_tile(done, total)` after
/// each tile. Memory is bounded by the tile and [`BAND_PIXELS`], not by the image size.
/// `packed` holds all five levels; the model reads the ones its config names.
pub fn reconstruct_tiled(
    model: &TrainedModel,
    packed: &PackedImage,
    tile: usize,
    engine: Engine,
    device: &Device,
    on_tile: impl FnMut(usize, usize),
) -> Reconstruction {
    match engine {
        Engine::Burn => reconstruct_banded(model, packed, tile, BAND_PIXELS, device, on_tile),
        Engine::Native => reconstruct_native(model, packed, tile, on_tile),
    }
}

/// The packed image reduced to the levels `model` combines (borrowed when it reads all five).
fn model_levels<'a>(model: &TrainedModel, packed: &'a PackedImage) -> Cow<'a, PackedImage> {
    if model.config.levels == model::network::all_levels() {
        Cow::Borrowed(packed)
    } else {
        Cow::Owned(packed.select_levels(&model.config.levels))
    }
}

/// The output share plane of each correlated level a model combines: its plane j belongs to
/// correlated level `levels[j + 1]` (z̃1 = plane 0).
fn share_planes(levels: &[usize]) -> Vec<usize> {
    levels[1..].iter().map(|l| l - 1).collect()
}

/// [`reconstruct_tiled`] on the native engine: the same tiles and exact regions, the last layer
/// and the combination fused per chunk of pixels (memory bounded by the tile).
pub fn reconstruct_native(
    model: &TrainedModel,
    packed: &PackedImage,
    tile: usize,
    mut on_tile: impl FnMut(usize, usize),
) -> Reconstruction {
    let chosen = &model.config.levels;
    let packed = &*model_levels(model, packed);
    let (width, height) = (packed.width, packed.height);
    let pixels = width * height;
    let network = NativeNetwork::new(&model.network, &model.config);
    let share_planes = share_planes(chosen);
    let (levels, added) = packed.combination_inputs();
    let variances = guard_variances(model, packed);
    let differences = model::native::level_differences(&levels, pixels);
    let colours = CombinationInputs {
        width,
        height,
        levels: &levels,
        differences: &differences,
        share_planes: &share_planes,
        variances: &variances,
    };
    let mut image = model::native::zeros(3 * pixels);
    let mut shares = model::native::zeros((LEVELS - 1) * pixels);
    let tiles = plan_tiles(width, height, tile, model.config.conv_reach());
    for (done, t) in tiles.iter().enumerate() {
        let (x, region) =
            network.hidden_layers(&packed.features, width, height, t.region, t.interior);
        network.combine(&x, region, t.interior, &colours, &mut image, &mut shares);
        network.recycle(x);
        on_tile(done + 1, tiles.len());
    }
    add_direct(&mut image, added);
    Reconstruction {
        width,
        height,
        image,
        shares,
    }
}

/// [`reconstruct_tiled`] with the last layer and the combination run on bands of about
/// `band_pixels` pixels (at least one row).
pub fn reconstruct_banded(
    model: &TrainedModel,
    packed: &PackedImage,
    tile: usize,
    band_pixels: usize,
    device: &Device,
    mut on_tile: impl FnMut(usize, usize),
) -> Reconstruction {
    let chosen = &model.config.levels;
    let packed = &*model_levels(model, packed);
    let (width, height) = (packed.width, packed.height);
    let feature_channels = packed.features.len() / (width * height).max(1);
    let colour_channels = packed.levels.len() / (width * height).max(1);
    let (combined_levels, added) = packed.combination_inputs();
    let variances = guard_variances(model, packed);
    let share_planes = share_planes(chosen);
    let pairs = share_planes.len();
    let pixels = width * height;
    let network = &model.network;
    let kernel_reach = model.config.kernel / 2;
    // The output layer's reach: the band it computes needs the last hidden activation on the
    // band grown by it (1×1 for a U-Net: none).
    let output_reach = network.output.kernel_size[0] / 2;
    let layers = network.hidden.len() + 1;
    let window = model.config.window;
    let window_reach = window / 2;
    let mut image = vec![0.0f32; 3 * pixels];
    let mut shares = vec![0.0f32; (LEVELS - 1) * pixels];
    let tiles = plan_tiles(width, height, tile, model.config.conv_reach());
    for (done, t) in tiles.iter().enumerate() {
        let interior = t.interior;
        // Hidden layer l (0-based) is exact on the interior grown by the reach of the layers
        // after it; the features are needed on the tile's full region.
        let mut region = t.region;
        let [rx0, ry0, rx1, ry1] = region;
        let features = crop_planes(&packed.features, feature_channels, width, height, region);
        let mut x = Tensor::<4>::from_data(
            TensorData::new(features, [1, feature_channels, ry1 - ry0, rx1 - rx0]),
            device,
        );
        if let Some(unet) = &network.unet {
            // Every step of the U-Net's plan on the rectangle the later ones need
            // (model::unet, exact for the same reason as the layers below).
            let out = grow(interior, output_reach, width, height);
            x = model::unet::forward_region(unet, &network.hidden, x, region, out, width, height);
            region = out;
        } else {
            for (l, conv) in network.hidden.iter().enumerate() {
                let out = grow(interior, (layers - 1 - l) * kernel_reach, width, height);
                x = burn::tensor::activation::relu(conv_block(conv, x, region, out));
                region = out;
            }
        }
        let [ix0, iy0, ix1, iy1] = interior;
        let band_rows = (band_pixels / (ix1 - ix0)).max(1);
        for by0 in (iy0..iy1).step_by(band_rows) {
            let band = [ix0, by0, ix1, by0.saturating_add(band_rows).min(iy1)];
            let (bw, bh) = (band[2] - band[0], band[3] - band[1]);
            let input = grow(band, output_reach, width, height);
            let raw = conv_block(&network.output, crop(x.clone(), region, input), input, band);
            let weights = positive_weights(raw, network.weighting);
            let reach = grow(band, window_reach, width, height);
            let margins = insets(reach, band).map(|inset| window_reach - inset);
            let levels = crop_planes(&combined_levels, colour_channels, width, height, reach);
            let levels = Tensor::<4>::from_data(
                TensorData::new(
                    levels,
                    [1, colour_channels, reach[3] - reach[1], reach[2] - reach[0]],
                ),
                device,
            );
            let guard = (model.config.guard > 0.0).then(|| Guard {
                variances: Tensor::<4>::from_data(
                    TensorData::new(
                        crop_planes(&variances, chosen.len(), width, height, band),
                        [1, chosen.len(), bh, bw],
                    ),
                    device,
                ),
                strength: model.config.guard,
                target_noise: model.config.guard_target_noise,
            });
            // Clamped at zero like `model::combine::reconstruct` (what the loss saw).
            let combined = combine_guarded_block(levels, weights.clone(), guard, window, margins)
                .clamp_min(0.0)
                .into_data()
                .try_to_vec::<f32>()
                .expect("f32 reconstruction");
            let band_shares = level_weight_shares_block(weights, window, margins)
                .into_data()
                .try_to_vec::<f32>()
                .expect("f32 weight shares");
            // Source plane p goes to destination plane to(p).
            let paste =
                |dst: &mut [f32], src: &[f32], planes: usize, to: &dyn Fn(usize) -> usize| {
                    for p in 0..planes {
                        for row in 0..bh {
                            let s = (p * bh + row) * bw;
                            let d = to(p) * pixels + (by0 + row) * width + ix0;
                            dst[d..d + bw].copy_from_slice(&src[s..s + bw]);
                        }
                    }
                };
            paste(&mut image, &combined, 3, &|p| p);
            paste(&mut shares, &band_shares, pairs, &|j| share_planes[j]);
        }
        on_tile(done + 1, tiles.len());
    }
    add_direct(&mut image, added);
    Reconstruction {
        width,
        height,
        image,
        shares,
    }
}

/// The variances the guard reads (none when the model's guard is off).
fn guard_variances(model: &TrainedModel, packed: &PackedImage) -> Vec<f32> {
    if model.config.guard > 0.0 {
        packed.variances(model.config.levels.len())
    } else {
        Vec::new()
    }
}

/// Adds the photon-free part the combination left out ([`PackedImage::combination_inputs`]) to
/// the combined, clamped image.
fn add_direct(image: &mut [f32], added: Option<Vec<f32>>) {
    use rayon::prelude::*;
    if let Some(added) = added {
        image
            .par_iter_mut()
            .zip(added.par_iter())
            .for_each(|(v, d)| *v += d);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_image_once() {
        for (w, h, tile, halo) in [(37, 23, 8, 5), (16, 16, 16, 3), (5, 9, 0, 2), (1, 1, 4, 10)] {
            let mut count = vec![0u32; w * h];
            for t in plan_tiles(w, h, tile, halo) {
                let [x0, y0, x1, y1] = t.interior;
                let [rx0, ry0, rx1, ry1] = t.region;
                assert!(rx0 <= x0 && ry0 <= y0 && rx1 >= x1 && ry1 >= y1);
                assert!(rx1 <= w && ry1 <= h);
                // The halo is full wherever the image allows it.
                assert_eq!(x0 - rx0, x0.min(halo));
                assert_eq!(rx1 - x1, (w - x1).min(halo));
                for y in y0..y1 {
                    for x in x0..x1 {
                        count[y * w + x] += 1;
                    }
                }
            }
            assert!(count.iter().all(|&c| c == 1), "{w}x{h} tile {tile}");
        }
    }

    /// Bands and tiles of any size reconstruct exactly what the whole image does, with a network
    /// whose every layer has non-zero biases (a band or tile that dropped them would differ).
    #[test]
    fn bands_and_tiles_equal_the_whole_image() {
        use model::features::pack;
        use model::synthetic::synthetic_bundle;
        use model::{ModelConfig, Preset};
        // 37×29 with 12-px tiles and 50-pixel bands (four rows of a tile, one row of the whole
        // image): bands meet inside tiles, tiles inside the image, and both at its borders.
        let (bundle, _) = synthetic_bundle(37, 29, 0.3, 3);
        let packed = pack(&bundle).unwrap();
        let device = Device::flex();
        let config = ModelConfig::preset(Preset::Tiny);
        let model = TrainedModel {
            dir: std::path::PathBuf::new(),
            network: model::synthetic::with_distinct_biases(config.init(5, &device)),
            config,
        };
        for conv in model.network.hidden.iter().chain([&model.network.output]) {
            let bias = conv.bias.as_ref().expect("convolutions have a bias").val();
            let bias = bias.into_data().try_to_vec::<f32>().unwrap();
            assert!(bias.iter().all(|&b| b != 0.0), "a zero bias: {bias:?}");
        }
        let whole = reconstruct_banded(&model, &packed, 0, usize::MAX, &device, |_, _| {});
        for (tile, band) in [(0, 50), (12, 50), (12, usize::MAX), (12, 1)] {
            let parts = reconstruct_banded(&model, &packed, tile, band, &device, |_, _| {});
            for (a, b) in parts.image.iter().zip(&whole.image) {
                assert!(
                    (a - b).abs() <= 1e-5 * b.abs().max(1e-3),
                    "tile {tile} band {band}: {a} vs {b}"
                );
            }
            for (a, b) in parts.shares.iter().zip(&whole.shares) {
                assert!(
                    (a - b).abs() <= 1e-5,
                    "tile {tile} band {band}: share {a} vs {b}"
                );
            }
        }
    }

    #[test]
    fn crop_takes_the_window_of_every_plane() {
        // Two 3×2 planes holding 10·plane + index.
        let data: Vec<f32> = (0..2)
            .flat_map(|p| (0..6).map(move |i| (10 * p + i) as f32))
            .collect();
        let out = crop_planes(&data, 2, 3, 2, [1, 0, 3, 2]);
        assert_eq!(out, vec![1.0, 2.0, 4.0, 5.0, 11.0, 12.0, 14.0, 15.0]);
    }

    /// A model directory that combines two levels (Dual) reconstructs from its levels only.
    #[test]
    fn dual_model_directory_reconstructs_from_its_levels() {
        use model::model_dir::{CONFIG_FILE, WEIGHTS_FILE};
        use model::synthetic::synthetic_sample;
        use model::weights::save_burnpack;
        use model::{ModelConfig, Preset};
        let dir = std::env::temp_dir().join(format!("model-dir-dual-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let device = Device::flex();
        let config = ModelConfig::preset(Preset::Tiny).with_levels(vec![0, 3]);
        save_burnpack(&config.init(4, &device), &dir.join(WEIGHTS_FILE)).unwrap();
        std::fs::write(
            dir.join(CONFIG_FILE),
            serde_json::to_string(&config).unwrap(),
        )
        .unwrap();
        let model = TrainedModel::open(&dir, &device).unwrap();
        assert_eq!(model.config.levels, vec![0, 3]);

        // ỹ copied into z̃3: the dual combination must return ỹ (consistency), tiled or not,
        // whatever z̃1, z̃2, z̃4 hold; all weight sits on z̃3.
        let mut packed = synthetic_sample(13, 11, 0.2, 8).packed;
        let pixels = packed.pixels();
        let y = packed.level(0).to_vec();
        packed.levels[9 * pixels..12 * pixels].copy_from_slice(&y);
        for (tile, engine) in [
            (0, Engine::Burn),
            (4, Engine::Burn),
            (0, Engine::Native),
            (4, Engine::Native),
        ] {
            let rec = reconstruct_tiled(&model, &packed, tile, engine, &device, |_, _| {});
            for (o, e) in rec.image.iter().zip(&y) {
                assert!(
                    (o - e).abs() <= 1e-4 * e.abs().max(1.0),
                    "tile {tile} {engine:?}: {o} vs {e}"
                );
            }
            assert_eq!(rec.shares.len(), 4 * pixels);
            for (j, plane) in rec.shares.chunks(pixels).enumerate() {
                let want = if j == 2 { 1.0 } else { 0.0 };
                assert!(
                    plane.iter().all(|s| (s - want).abs() < 1e-5),
                    "share plane {j}"
                );
            }
        }

        // A model.json whose levels disagree with in_channels is refused, naming the file.
        let mut bad = config.clone();
        bad.in_channels = 27;
        std::fs::write(dir.join(CONFIG_FILE), serde_json::to_string(&bad).unwrap()).unwrap();
        let err = TrainedModel::open(&dir, &device).err().unwrap().to_string();
        assert!(
            err.contains("model.json") && err.contains("in_channels"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
