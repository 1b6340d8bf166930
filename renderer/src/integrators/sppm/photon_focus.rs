//! The region the camera sees, found once per run, at which a share of the infinite lights'
//! photons is aimed ([`crate::lights::PhotonFocus`] holds the mixture and why it is unbiased).
//!
//! One eye subpath per pixel, from its own random streams (not the passes'), finds the visible
//! points; the box holding the middle half of them on each axis, grown by the radius cap
//! (photons that far from a visible point are still gathered), bounded by a sphere, is the
//! focus. The points are collected in pixel order and sorted per axis, so the focus does not
//! depend on the thread count, and a resumed run recomputes the same one.

use glam::{UVec2, Vec3};
use rayon::prelude::*;

use crate::lights::{Light, PhotonFocus, SceneSphere};
use crate::sampling::{rng_for, UniformSource};
use crate::scene::Scene;

use super::visible_point::trace_eye_path;
use super::SppmSettings;

/// The focus box leaves out this fraction of the visible points on either side of each axis:
/// a ground plane seen up to the horizon holds few pixels far away, and a box around all of
/// them would be most of the scene.
const QUANTILE: f32 = 0.25;

/// Domain-separation constant of the focus subpaths' streams.
const FOCUS_STREAM: u64 = 0x666f_6375_7321_7070;

/// The focus is used only when its disk is at most this fraction of the scene's: a larger one
/// would put barely more photons where the camera looks (at a share p and area fraction a, the
/// density there grows by p/a + 1 − p).
const MAX_AREA_FRACTION: f32 = 0.25;

/// The focus of a run of `settings` on `scene` with the radius cap `max_radius`; `None` when
/// the share is zero, the scene has no infinite light, the camera sees no surface, or what it
/// sees fills most of the scene's bounding disk.
pub fn photon_focus(
    scene: &Scene,
    settings: &SppmSettings,
    max_radius: f32,
) -> Option<PhotonFocus> {
    let share = settings.photon_focus;
    if share <= 0.0 || !scene.lights.iter().any(Light::is_infinite) {
        return None;
    }
    let res = scene.camera.resolution();
    let width = res.x as usize;
    let pixels = width * res.y as usize;
    let points: Vec<Vec3> = (0..pixels)
        .into_par_iter()
        .with_min_len(64)
        .filter_map(|index| {
            let pixel = UVec2::new((index % width) as u32, (index / width) as u32);
            let mut rng = rng_for(settings.seed ^ FOCUS_STREAM, 0, index as u64);
            let u_film = rng.next_2d();
            let u_lens = rng.next_2d();
            let sample = scene.camera.sample_ray(pixel, u_film, u_lens);
            let path = trace_eye_path(scene, sample.ray, &mut rng, settings.max_depth, 1);
            path.vp.map(|vp| vp.p).filter(|p| p.is_finite())
        })
        .collect();
    if points.is_empty() {
        return None;
    }
    // Per axis, the range holding all but the outer QUANTILE of the points on either side.
    let range = |axis: usize| {
        let mut v: Vec<f32> = points.iter().map(|p| p[axis]).collect();
        v.sort_unstable_by(f32::total_cmp);
        let k = ((v.len() - 1) as f32 * QUANTILE) as usize;
        (v[k], v[v.len() - 1 - k])
    };
    let (x, y, z) = (range(0), range(1), range(2));
    let (lo, hi) = (Vec3::new(x.0, y.0, z.0), Vec3::new(x.1, y.1, z.1));
    let (lo, hi) = (lo - Vec3::splat(max_radius), hi + Vec3::splat(max_radius));
    let sphere = SceneSphere {
        center: (lo + hi) * 0.5,
        radius: (hi - lo).length() * 0.5,
    };
    let bound = scene.bounding_sphere().radius;
    (sphere.radius * sphere.radius <= MAX_AREA_FRACTION * bound * bound)
        .then_some(PhotonFocus { sphere, share })
}
