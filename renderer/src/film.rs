//! The film: an RGB image accumulated with a box filter (each sample lands in exactly one
//! pixel, so neighbouring pixels keep independent noise), and the parallel pixel loop that fills
//! it deterministically: every pixel draws from its own random stream and sums its samples in
//! a fixed order, so the image is bit-identical for any number of threads — and for a run that
//! was killed and resumed from its state file, which keeps the rows finished so far.

use crate::spectrum::Rgb;
use crate::state_file::{self, Cursor, StateFile};
use anyhow::{bail, Result};
use indicatif::ProgressBar;
use rayon::prelude::*;
use serde::{de::DeserializeOwned, Deserialize, Serialize};
use std::sync::Mutex;
use std::time::Instant;

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

/// [`render_pixels`] for `channels` values per pixel: `pixel(x, y, out)` adds the pixel's
/// values into `out` (zeroed, `channels` long; randomness from (x, y) alone). Returns one plane
/// per channel, rows top to bottom.
pub fn render_pixels_channels<F>(
    width: u32,
    height: u32,
    channels: usize,
    progress: Option<&ProgressBar>,
    work_per_pixel: u64,
    pixel: F,
) -> Vec<Vec<f32>>
where
    F: Fn(u32, u32, &mut [f32]) + Sync,
{
    let (w, h) = (width as usize, height as usize);
    let mut interleaved = vec![0.0f32; w * h * channels];
    if channels > 0 {
        interleaved
            .par_chunks_mut(w * channels)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, out) in row.chunks_mut(channels).enumerate() {
                    pixel(x as u32, y as u32, out);
                }
                if let Some(p) = progress {
                    p.inc(work_per_pixel * width as u64);
                }
            });
    }
    (0..channels)
        .map(|c| {
            interleaved
                .iter()
                .skip(c)
                .step_by(channels)
                .copied()
                .collect()
        })
        .collect()
}

/// First line of a row-by-row render's state file.
const ROWS_MAGIC: &str = "rows-run-state 1";

/// The JSON header of a row-by-row render's state file.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RowsHeader<I> {
    /// What the run computes (the caller's settings).
    run: I,
    /// Image width.
    width: u32,
    /// Image height.
    height: u32,
    /// Rows finished.
    rows_done: u32,
}

/// The body: one byte per row (1 = finished), then every pixel as three f32 (zero in
/// unfinished rows).
fn encode_rows(film: &Film, done: &[bool]) -> Vec<u8> {
    let mut out = Vec::with_capacity(done.len() + film.pixels.len() * 12);
    out.extend(done.iter().map(|&d| d as u8));
    for p in &film.pixels {
        for c in p.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    out
}

/// [`render_pixels`] that keeps finished rows in `state`: a run whose state file exists renders
/// only the rows it lacks, and the state is saved every `state.interval` seconds and at the
/// end. `identity` holds the settings that decide the pixel values (samples, seed, depths…; the
/// scene's fingerprint is added): a state saved under other ones is refused. The image is
/// bit-identical to an uninterrupted run's.
pub fn render_pixels_resumable<F, I>(
    width: u32,
    height: u32,
    progress: Option<&ProgressBar>,
    work_per_pixel: u64,
    pixel: F,
    state: &StateFile,
    identity: &I,
) -> Result<Film>
where
    F: Fn(u32, u32) -> Rgb + Sync,
    I: Serialize + DeserializeOwned,
{
    state.check_interval()?;
    let path = &state.path;
    // The identity with the image size and the scene, as one JSON object.
    let mut run = serde_json::to_value(identity)?;
    let Some(fields) = run.as_object_mut() else {
        bail!("a run identity must be a JSON object");
    };
    fields.insert(
        "scene_fingerprint".into(),
        state.scene_fingerprint.clone().into(),
    );
    let mut film = Film::new(width, height);
    let mut done = vec![false; height as usize];
    if let Some((header, body)) =
        state_file::load::<RowsHeader<serde_json::Value>>(path, ROWS_MAGIC)?
    {
        state_file::check_identity(path, &header.run, &run)?;
        let pixels = width as usize * height as usize;
        if (header.width, header.height) != (width, height)
            || body.len() != height as usize + pixels * 12
        {
            bail!(
                "{}: the saved run is {}x{} with {} bytes of data; this run renders {width}x{height}",
                path.display(),
                header.width,
                header.height,
                body.len()
            );
        }
        let (flags, data) = body.split_at(height as usize);
        for (d, &f) in done.iter_mut().zip(flags) {
            *d = f == 1;
        }
        let mut c = Cursor::new(data);
        for p in &mut film.pixels {
            *p = Rgb::new(c.f32(), c.f32(), c.f32());
        }
        if let Some(p) = progress {
            let rows = done.iter().filter(|&&d| d).count() as u64;
            p.inc(rows * width as u64 * work_per_pixel);
        }
    }
    let save = |film: &Film, done: &[bool]| {
        let header = RowsHeader {
            run: &run,
            width,
            height,
            rows_done: done.iter().filter(|&&d| d).count() as u32,
        };
        state_file::save(path, ROWS_MAGIC, &header, &encode_rows(film, done))
    };
    let todo: Vec<u32> = (0..height).filter(|&y| !done[y as usize]).collect();
    let shared = Mutex::new((film, done, Instant::now(), Ok::<(), anyhow::Error>(())));
    todo.par_iter().for_each(|&y| {
        let row: Vec<Rgb> = (0..width).map(|x| pixel(x, y)).collect();
        let mut guard = shared.lock().unwrap_or_else(|e| e.into_inner());
        let (film, done, last_save, result) = &mut *guard;
        let at = y as usize * width as usize;
        film.pixels[at..at + width as usize].copy_from_slice(&row);
        done[y as usize] = true;
        if result.is_ok() && last_save.elapsed().as_secs_f64() >= state.interval {
            // Saving under the lock: other rows wait for it, none is lost or half-written.
            *result = save(film, done);
            *last_save = Instant::now();
        }
        drop(guard);
        if let Some(p) = progress {
            p.inc(work_per_pixel * width as u64);
        }
    });
    let (film, done, _, result) = shared.into_inner().unwrap_or_else(|e| e.into_inner());
    result?;
    save(&film, &done)?;
    Ok(film)
}
