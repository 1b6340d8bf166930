//! What the integrators that estimate radiance along camera rays share (the path tracer and
//! the direct-illumination integrator): the per-pixel sample loop on the pixel's own random
//! stream, and rendering the whole image, plain or resumable from a state file.

use crate::film::{render_pixels, render_pixels_resumable, Film};
use crate::math::Ray;
use crate::sampling::{rng_for, Pcg32, UniformSource};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use crate::state_file::StateFile;
use glam::UVec2;
use indicatif::ProgressBar;

/// An estimator of the radiance arriving along a camera ray; the image is the mean of `spp`
/// estimates per pixel. Generic methods (no trait objects): each integrator's loop is compiled
/// on its own.
pub trait RayIntegrator: Sync {
    /// Radiance arriving along `ray`, estimated with random numbers drawn from `rng`.
    fn li(&self, scene: &Scene, ray: Ray, rng: &mut Pcg32) -> Rgb;

    /// The settings that determine the image (with the seed and spp they key a state file, so
    /// that a run is never resumed from another integrator's or settings' rows).
    fn identity(&self) -> serde_json::Value;

    /// Mean of `spp` samples through pixel (x, y) drawn from the pixel's own stream
    /// `rng_for(seed, pass, y·width + x)`. Non-finite samples (numerical accidents) are dropped.
    #[inline]
    fn pixel(&self, scene: &Scene, x: u32, y: u32, spp: u32, seed: u64, pass: u64) -> Rgb {
        let res = scene.camera.resolution();
        let mut rng = rng_for(seed, pass, y as u64 * res.x as u64 + x as u64);
        let mut sum = Rgb::ZERO;
        for _ in 0..spp {
            let u_film = rng.next_2d();
            let u_lens = rng.next_2d();
            let sample = scene.camera.sample_ray(UVec2::new(x, y), u_film, u_lens);
            let l = self.li(scene, sample.ray, &mut rng) * sample.weight;
            if l.is_finite() {
                sum += l;
            }
        }
        sum / spp.max(1) as f32
    }

    /// [`RayIntegrator::render`] that keeps its finished rows in `state` and resumes from it
    /// (see [`render_pixels_resumable`]); the image is bit-identical to an uninterrupted run's.
    fn render_resumable(
        &self,
        scene: &Scene,
        spp: u32,
        seed: u64,
        progress: Option<&ProgressBar>,
        state: &StateFile,
    ) -> anyhow::Result<Film> {
        let res = scene.camera.resolution();
        let mut identity = self.identity();
        identity["spp"] = spp.into();
        identity["seed"] = seed.into();
        render_pixels_resumable(
            res.x,
            res.y,
            progress,
            spp as u64,
            |x, y| self.pixel(scene, x, y, spp, seed, 0),
            state,
            &identity,
        )
    }

    /// Renders the whole image with `spp` samples per pixel in the current rayon pool.
    fn render(&self, scene: &Scene, spp: u32, seed: u64, progress: Option<&ProgressBar>) -> Film {
        let res = scene.camera.resolution();
        render_pixels(res.x, res.y, progress, spp as u64, |x, y| {
            self.pixel(scene, x, y, spp, seed, 0)
        })
    }
}
