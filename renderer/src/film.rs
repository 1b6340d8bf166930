//! The film: an RGB image accumulated with a box filter (each sample lands in exactly one
//! pixel, so neighbouring pixels keep independent noise), and the parallel pixel loop that fills
//! it deterministically: every pixel draws from its own random stream and sums its samples in
//! a fixed order, so the image is bit-identical for any number of threads.

use crate::spectrum::Rgb;
use indicatif::ProgressBar;
use rayon::prelude::*;

/// An RGB image in linear radiance, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixel values.
    pub pixels: Vec<Rgb>,
}

impl Film {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Film {
            width,
            height,
            pixels: vec![Rgb::ZERO; width as usize * height as usize],
        }
    }

    /// The value of pixel (x, y).
    pub fn get(&self, x: u32, y: u32) -> Rgb {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Mean over all pixels.
    pub fn mean(&self) -> Rgb {
        let s: glam::DVec3 = self.pixels.iter().map(|p| p.as_dvec3()).sum();
        (s / self.pixels.len().max(1) as f64).as_vec3()
    }

    /// The pixels as interleaved RGB floats.
    pub fn to_rgb_f32(&self) -> Vec<f32> {
        self.pixels.iter().flat_map(|p| p.to_array()).collect()
    }
}

/// Runs `f(pool)` inside a rayon pool with `threads` workers (0 = rayon's default: all cores).
pub fn with_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> anyhow::Result<R> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    Ok(pool.install(f))
}

/// Fills a film in parallel over rows: `pixel(x, y)` returns the pixel's final value (it must
/// derive its randomness from (x, y) alone). `progress` advances by `work_per_pixel` per pixel.
pub fn render_pixels<F>(
    width: u32,
    height: u32,
    progress: Option<&ProgressBar>,
    work_per_pixel: u64,
    pixel: F,
) -> Film
where
    F: Fn(u32, u32) -> Rgb + Sync,
{
    let mut film = Film::new(width, height);
    film.pixels
        .par_chunks_mut(width as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                *out = pixel(x as u32, y as u32);
            }
            if let Some(p) = progress {
                p.inc(work_per_pixel * width as u64);
            }
        });
    film
}
