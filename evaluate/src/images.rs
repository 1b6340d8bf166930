//! Comparison images: sRGB panels, false-colour relative-error maps, a row of panels as PNG
//! (kept in memory for embedding into the HTML page), and base64 for data URIs.

use std::path::Path;

use anyhow::{Context, Result};
use fileio::srgb::encode8;

/// White gap between panels, in pixels.
const GAP: usize = 4;

/// An 8-bit RGB panel, interleaved, `width`×`height`.
pub type Panel = Vec<u8>;

/// Planar linear RGB → interleaved sRGB bytes (clamped to [0, 1] like `infer --png`).
pub fn srgb_panel(planes: &[f32], pixels: usize) -> Panel {
    let mut out = Vec::with_capacity(3 * pixels);
    for p in 0..pixels {
        for c in 0..3 {
            out.push(encode8(planes[c * pixels + p]));
        }
    }
    out
}

/// Per-pixel relative squared error, the summand of relMSE (docs/method.md §5.6):
/// mean over RGB of (x − r)² / (mean_RGB(r)² + 0.01).
pub fn relative_error_map(image: &[f32], reference: &[f32], pixels: usize) -> Vec<f32> {
    (0..pixels)
        .map(|p| {
            let r: [f32; 3] = std::array::from_fn(|c| reference[c * pixels + p]);
            let mean = (r[0] + r[1] + r[2]) / 3.0;
            let denom = mean * mean + 0.01;
            (0..3)
                .map(|c| {
                    let d = image[c * pixels + p] - r[c];
                    d * d / denom
                })
                .sum::<f32>()
                / 3.0
        })
        .collect()
}

/// Colour ramp anchors (dark blue → purple → orange → pale yellow), perceptually ordered.
const RAMP: [[f32; 3]; 5] = [
    [0.0, 0.0, 0.05],
    [0.25, 0.05, 0.45],
    [0.75, 0.2, 0.35],
    [0.98, 0.55, 0.1],
    [0.99, 0.98, 0.65],
];

/// The ramp colour at `t` ∈ [0, 1].
fn ramp(t: f32) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0) * (RAMP.len() - 1) as f32;
    let i = (t as usize).min(RAMP.len() - 2);
    let f = t - i as f32;
    std::array::from_fn(|c| {
        let v = RAMP[i][c] + f * (RAMP[i + 1][c] - RAMP[i][c]);
        (v * 255.0 + 0.5) as u8
    })
}

/// False colour of an error map on a log scale over three decades below `max` (values at or
/// above `max` are the brightest colour, at or below `max`/1000 the darkest).
pub fn error_panel(errors: &[f32], max: f32) -> Panel {
    let max = max.max(1e-12);
    let (lo, hi) = ((max * 1e-3).ln(), max.ln());
    errors
        .iter()
        .flat_map(|&e| {
            let t = if e > 0.0 {
                (e.ln() - lo) / (hi - lo)
            } else {
                0.0
            };
            ramp(t)
        })
        .collect()
}

/// A robust colour-scale maximum: the 99th percentile of all given error maps.
pub fn error_scale(maps: &[&[f32]]) -> f32 {
    let mut all: Vec<f32> = maps
        .iter()
        .flat_map(|m| m.iter().copied())
        .filter(|v| v.is_finite())
        .collect();
    if all.is_empty() {
        return 1.0;
    }
    all.sort_by(f32::total_cmp);
    let v = all[((all.len() - 1) as f64 * 0.99) as usize];
    if v > 0.0 {
        v
    } else {
        1.0
    }
}

/// Panels left to right with white gaps, encoded as PNG bytes.
pub fn row_png(panels: &[Panel], width: usize, height: usize) -> Result<Vec<u8>> {
    let n = panels.len();
    let total_w = n * width + n.saturating_sub(1) * GAP;
    let mut bytes = vec![255u8; total_w * height * 3];
    for (k, panel) in panels.iter().enumerate() {
        let x_off = k * (width + GAP);
        for y in 0..height {
            let src = &panel[y * width * 3..(y + 1) * width * 3];
            let d = (y * total_w + x_off) * 3;
            bytes[d..d + width * 3].copy_from_slice(src);
        }
    }
    fileio::png::encode_rgb8(total_w, height, &bytes).context("encoding PNG")
}

/// Writes `bytes` to `path` atomically (`fileio::atomic`), the error naming the file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    fileio::atomic::write_bytes(path, bytes).with_context(|| format!("writing {}", path.display()))
}

/// Standard base64 (RFC 4648, with padding), for `data:` URIs.
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[((n >> (18 - 6 * i)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(base64(plain.as_bytes()), encoded);
        }
        assert_eq!(base64(&[0xff, 0xfe, 0xfd]), "//79");
    }

    #[test]
    fn error_map_is_the_relmse_summand() {
        // Two pixels; the mean of the map equals relMSE of the planar images.
        let reference = vec![1.0, 0.0, 1.0, 0.0, 1.0, 0.0];
        let image = vec![1.5, 0.0, 1.0, 0.2, 0.5, 0.0];
        let map = relative_error_map(&image, &reference, 2);
        let mean = (map[0] + map[1]) as f64 / 2.0;
        let relmse = model::metrics::relmse_planar(&image, &reference);
        assert!((mean - relmse).abs() < 1e-6, "{mean} vs {relmse}");
        // Planar layout: pixel 0 is (1.5, 1, 0.5) against (1, 1, 1): squared errors 0.25, 0,
        // 0.25 over 1² + 0.01; pixel 1 is (0, 0.2, 0) against black: 0.04 over 0.01.
        assert!((map[0] - 0.5 / 1.01 / 3.0).abs() < 1e-6, "{}", map[0]);
        assert!((map[1] - 0.04 / 0.01 / 3.0).abs() < 1e-5, "{}", map[1]);
    }

    #[test]
    fn error_colours_are_monotone_in_brightness() {
        let errors: Vec<f32> = (0..=30)
            .map(|i| 10f32.powf(-3.0 + i as f32 / 10.0))
            .collect();
        let panel = error_panel(&errors, 1.0);
        let lum: Vec<u32> = panel
            .chunks(3)
            .map(|c| c.iter().map(|&v| u32::from(v)).sum())
            .collect();
        assert!(lum.windows(2).all(|w| w[0] <= w[1]), "{lum:?}");
        assert!(lum[0] < lum[30]);
    }

    #[test]
    fn row_png_decodes_to_the_panels() {
        let a = vec![10u8; 2 * 2 * 3];
        let b = vec![200u8; 2 * 2 * 3];
        let png = row_png(&[a, b], 2, 2).unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (2 * 2 + GAP as u32, 2));
        assert_eq!(img.get_pixel(1, 1).0, [10, 10, 10]);
        assert_eq!(img.get_pixel(2, 0).0, [255, 255, 255]);
        assert_eq!(img.get_pixel(2 + GAP as u32, 1).0, [200, 200, 200]);
    }
}
