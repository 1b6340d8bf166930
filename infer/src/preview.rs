//! PNG previews: standard SPPM | ours | reference side by side, and the weight map (paper
//! Fig. 6: how much weight the network put on the sharpest vs the smoothest level).

use std::path::Path;

use anyhow::{Context, Result};
use fileio::srgb::encode8;

/// Gap between panels in pixels (white).
const GAP: usize = 4;

/// A planar RGB image to show: `plane[c][y·width + x]`, linear values.
pub struct Panel<'a> {
    /// Planar RGB data.
    pub planes: &'a [f32],
}

/// Writes `panels` (each `width`×`height`, planar linear RGB) left to right into one sRGB PNG,
/// atomically (temp file + rename).
pub fn write_side_by_side(
    path: &Path,
    width: usize,
    height: usize,
    panels: &[Panel],
) -> Result<()> {
    let n = panels.len();
    let total_w = n * width + n.saturating_sub(1) * GAP;
    let mut bytes = vec![255u8; total_w * height * 3];
    let pixels = width * height;
    for (k, panel) in panels.iter().enumerate() {
        let x_off = k * (width + GAP);
        for y in 0..height {
            for x in 0..width {
                let d = (y * total_w + x_off + x) * 3;
                for c in 0..3 {
                    bytes[d + c] = encode8(panel.planes[c * pixels + y * width + x]);
                }
            }
        }
    }
    save_png(path, total_w, height, &bytes)
}

/// Writes the weight map: red = share of the weight on z̃1 (sharpest correlated level),
/// blue = share on z̃4 (smoothest), green = share on z̃2 + z̃3. `shares` holds four planes.
pub fn write_weight_map(path: &Path, width: usize, height: usize, shares: &[f32]) -> Result<()> {
    let pixels = width * height;
    let mut bytes = Vec::with_capacity(pixels * 3);
    for p in 0..pixels {
        let s = |l: usize| shares[l * pixels + p].clamp(0.0, 1.0);
        let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
        bytes.extend([to_u8(s(0)), to_u8(s(1) + s(2)), to_u8(s(3))]);
    }
    save_png(path, width, height, &bytes)
}

fn save_png(path: &Path, width: usize, height: usize, bytes: &[u8]) -> Result<()> {
    fileio::png::write_rgb8(path, width, height, bytes)
        .with_context(|| format!("writing {}", path.display()))
}
