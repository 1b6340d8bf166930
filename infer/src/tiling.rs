//! Tiled reconstruction: the image is cut into tiles, each grown by a halo at least as wide as
//! the receptive field (convolutions and combination window), reconstructed, and cropped back.
//!
//! Why this equals the untiled result: an output pixel depends on features within the
//! convolutions' reach and on colours within the combination window. Both are inside the grown
//! tile for every interior pixel; where the grown tile is clipped, it is clipped at the image
//! border, where the whole-image computation sees the same zero padding and the same
//! out-of-image window mask. Features are packed once for the whole image (depth is normalised
//! per image), so tiles see exactly the values the whole image has.

use burn::tensor::{Device, Tensor, TensorData};
use model::combine::{combine, level_weight_shares};
use model::features::PackedImage;
use model::model::LEVELS;

use crate::TrainedModel;

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

/// Reconstructs the whole image tile by tile on `device`, calling `on_tile(done, total)` after
/// each tile. Memory is bounded by the tile size, not by the image size. `packed` holds all
/// five levels; the model reads the ones its config names.
pub fn reconstruct_tiled(
    model: &TrainedModel,
    packed: &PackedImage,
    tile: usize,
    device: &Device,
    mut on_tile: impl FnMut(usize, usize),
) -> Reconstruction {
    let chosen = &model.config.levels;
    let selected;
    let packed = if *chosen == model::model::all_levels() {
        packed
    } else {
        selected = packed.select_levels(chosen);
        &selected
    };
    let (width, height) = (packed.width, packed.height);
    let feature_channels = packed.features.len() / (width * height).max(1);
    let colour_channels = packed.levels.len() / (width * height).max(1);
    let pairs = chosen.len() - 1;
    let pixels = width * height;
    let halo = model.config.receptive_radius();
    let window = model.config.window;
    let mut image = vec![0.0f32; 3 * pixels];
    let mut shares = vec![0.0f32; (LEVELS - 1) * pixels];
    let tiles = plan_tiles(width, height, tile, halo);
    for (done, t) in tiles.iter().enumerate() {
        let [rx0, ry0, rx1, ry1] = t.region;
        let (rw, rh) = (rx1 - rx0, ry1 - ry0);
        let features = crop_planes(&packed.features, feature_channels, width, height, t.region);
        let levels = crop_planes(&packed.levels, colour_channels, width, height, t.region);
        let features = Tensor::<4>::from_data(
            TensorData::new(features, [1, feature_channels, rh, rw]),
            device,
        );
        let levels = Tensor::<4>::from_data(
            TensorData::new(levels, [1, colour_channels, rh, rw]),
            device,
        );
        let weights = model.network.weights(features);
        // Clamped at zero like `model::training::reconstruct` (what the loss saw in training).
        let combined = combine(levels, weights.clone(), window).clamp_min(0.0);
        let tile_shares = level_weight_shares(weights, window);
        let combined = combined
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 reconstruction");
        let tile_shares = tile_shares
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 weight shares");
        let [ix0, iy0, ix1, iy1] = t.interior;
        // Source plane p goes to destination plane to(p).
        let paste = |dst: &mut [f32], src: &[f32], planes: usize, to: &dyn Fn(usize) -> usize| {
            for p in 0..planes {
                for y in iy0..iy1 {
                    let s = p * rw * rh + (y - ry0) * rw + (ix0 - rx0);
                    let d = to(p) * pixels + y * width + ix0;
                    dst[d..d + (ix1 - ix0)].copy_from_slice(&src[s..s + (ix1 - ix0)]);
                }
            }
        };
        paste(&mut image, &combined, 3, &|p| p);
        // Share plane j of the model belongs to its correlated level chosen[j + 1] (z̃1 = 1).
        paste(&mut shares, &tile_shares, pairs, &|j| chosen[j + 1] - 1);
        on_tile(done + 1, tiles.len());
    }
    Reconstruction {
        width,
        height,
        image,
        shares,
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

    #[test]
    fn crop_takes_the_window_of_every_plane() {
        // Two 3×2 planes holding 10·plane + index.
        let data: Vec<f32> = (0..2)
            .flat_map(|p| (0..6).map(move |i| (10 * p + i) as f32))
            .collect();
        let out = crop_planes(&data, 2, 3, 2, [1, 0, 3, 2]);
        assert_eq!(out, vec![1.0, 2.0, 4.0, 5.0, 11.0, 12.0, 14.0, 15.0]);
    }
}
