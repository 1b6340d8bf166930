//! Contact sheets: a PNG grid of a dataset's reference images (tone-mapped for display), in
//! scene-id order so families appear in blocks, each tile labelled with its scene id.

use anyhow::{bail, Context, Result};
use bundle::{read_rgb_exr_image, Image};
use std::path::{Path, PathBuf};

/// Layout of a contact sheet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SheetLayout {
    /// Tiles per row.
    pub columns: usize,
    /// Tile width in pixels (images are resampled to it, keeping their aspect ratio).
    pub tile_width: usize,
    /// Gap between tiles in pixels.
    pub gap: usize,
}

/// Display transform: exposure so that the 95th-percentile luminance maps to 0.9, a Reinhard
/// shoulder, then the sRGB curve. Returns 8-bit RGB.
pub fn tonemap(img: &Image) -> Vec<[u8; 3]> {
    let lum: Vec<f32> = img
        .data
        .chunks(img.channels)
        .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
        .filter(|v| v.is_finite())
        .collect();
    let mut sorted = lum.clone();
    sorted.sort_by(f32::total_cmp);
    let p95 = sorted
        .get((sorted.len() as f32 * 0.95) as usize)
        .copied()
        .unwrap_or(1.0);
    let exposure = if p95 > 1e-6 { 0.9 / p95 } else { 1.0 };
    let encode = |v: f32| {
        let v = if v.is_finite() {
            (v * exposure).max(0.0)
        } else {
            0.0
        };
        // A gentle shoulder, 1 ↦ 1.
        fileio::srgb::encode8(v / (1.0 + 0.25 * v) * 1.25)
    };
    img.data
        .chunks(img.channels)
        .map(|p| [encode(p[0]), encode(p[1]), encode(p[2])])
        .collect()
}

/// Box-resamples an 8-bit RGB image to `tw`×`th`.
fn resample(src: &[[u8; 3]], w: usize, h: usize, tw: usize, th: usize) -> Vec<[u8; 3]> {
    let mut out = vec![[0u8; 3]; tw * th];
    for ty in 0..th {
        let (y0, y1) = (ty * h / th, ((ty + 1) * h / th).max(ty * h / th + 1));
        for tx in 0..tw {
            let (x0, x1) = (tx * w / tw, ((tx + 1) * w / tw).max(tx * w / tw + 1));
            let mut acc = [0u32; 3];
            let mut n = 0;
            for y in y0..y1.min(h) {
                for x in x0..x1.min(w) {
                    for c in 0..3 {
                        acc[c] += u32::from(src[y * w + x][c]);
                    }
                    n += 1;
                }
            }
            let n = n.max(1);
            out[ty * tw + tx] = [(acc[0] / n) as u8, (acc[1] / n) as u8, (acc[2] / n) as u8];
        }
    }
    out
}

/// Builds the sheet from reference EXRs and writes it as PNG. Returns the image count.
pub fn write_contact_sheet(
    entries: &[(String, PathBuf)],
    layout: SheetLayout,
    out: &Path,
) -> Result<usize> {
    if entries.is_empty() {
        bail!("no reference images to put on a contact sheet");
    }
    let images = entries
        .iter()
        .map(|(_, f)| read_rgb_exr_image(f).map_err(anyhow::Error::from))
        .collect::<Result<Vec<_>>>()?;
    let first = &images[0];
    let tw = layout.tile_width.max(1);
    let th = (tw * first.height / first.width.max(1)).max(1);
    let cols = layout.columns.max(1).min(images.len());
    let rows = images.len().div_ceil(cols);
    let g = layout.gap;
    let (sw, sh) = (cols * tw + (cols + 1) * g, rows * th + (rows + 1) * g);
    let mut sheet = image::RgbImage::from_pixel(sw as u32, sh as u32, image::Rgb([24, 24, 24]));
    for (k, img) in images.iter().enumerate() {
        let tile = resample(&tonemap(img), img.width, img.height, tw, th);
        let (ox, oy) = (g + (k % cols) * (tw + g), g + (k / cols) * (th + g));
        for y in 0..th {
            for x in 0..tw {
                sheet.put_pixel(
                    (ox + x) as u32,
                    (oy + y) as u32,
                    image::Rgb(tile[y * tw + x]),
                );
            }
        }
    }
    let labels: Vec<&str> = entries.iter().map(|(l, _)| l.as_str()).collect();
    label_tiles(&mut sheet, &labels, layout, cols, th)?;
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)?;
    }
    let (w, h) = (sheet.width() as usize, sheet.height() as usize);
    fileio::png::write_rgb8(out, w, h, sheet.as_raw())
        .with_context(|| format!("writing {}", out.display()))?;
    Ok(images.len())
}

/// Writes each tile's label (its scene id) in its top-left corner, white on a dark band so it
/// reads on any image; tiles too small for text (under 48 px wide) stay unlabelled.
fn label_tiles(
    sheet: &mut image::RgbImage,
    labels: &[&str],
    layout: SheetLayout,
    cols: usize,
    tile_height: usize,
) -> Result<()> {
    use plotters::prelude::*;
    let tw = layout.tile_width.max(1);
    if tw < 48 || tile_height < 16 {
        return Ok(());
    }
    plots::register_font().map_err(anyhow::Error::msg)?;
    let (w, h) = sheet.dimensions();
    let size = (tw as f64 / 12.0).clamp(9.0, 16.0);
    let g = layout.gap;
    let root = BitMapBackend::with_buffer(sheet.as_mut(), (w, h)).into_drawing_area();
    let style = TextStyle::from(("sans-serif", size).into_font()).color(&WHITE);
    for (k, label) in labels.iter().enumerate() {
        let (ox, oy) = (
            g + (k % cols) * (tw + g),
            g + (k / cols) * (tile_height + g),
        );
        let band = (size * 1.4) as i32;
        let (x0, y0) = (ox as i32, oy as i32);
        root.draw(&Rectangle::new(
            [(x0, y0), (x0 + tw as i32 - 1, y0 + band)],
            RGBColor(0, 0, 0).mix(0.55).filled(),
        ))
        .map_err(|e| anyhow::anyhow!("drawing a label: {e}"))?;
        root.draw_text(label, &style, (x0 + 3, y0 + (size * 0.2) as i32))
            .map_err(|e| anyhow::anyhow!("drawing a label: {e}"))?;
    }
    root.present()
        .map_err(|e| anyhow::anyhow!("drawing the labels: {e}"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_are_labelled_when_large_enough() {
        let layout = |tile_width| SheetLayout {
            columns: 2,
            tile_width,
            gap: 2,
        };
        let bright = |img: &image::RgbImage| img.pixels().filter(|p| p.0[0] > 200).count();
        // Two 160-px tiles: the ids are written in white.
        let mut sheet = image::RgbImage::new(2 * 160 + 6, 100);
        label_tiles(&mut sheet, &["000-room", "001-glass"], layout(160), 2, 96).unwrap();
        assert!(bright(&sheet) > 20, "no label text drawn");
        // The second label lands in the second tile.
        let right = (0..sheet.height())
            .flat_map(|y| (164..sheet.width()).map(move |x| (x, y)))
            .filter(|&(x, y)| sheet.get_pixel(x, y).0[0] > 200)
            .count();
        assert!(right > 10, "no label in the second tile");
        // Tiles too small for text stay as they are.
        let mut small = image::RgbImage::new(2 * 40 + 6, 30);
        label_tiles(&mut small, &["000-room", "001-glass"], layout(40), 2, 24).unwrap();
        assert_eq!(bright(&small), 0);
    }
}
