//! Placement of the compact lights shared by the glass, metal and tabletop families.

use crate::config::SmallLight;
use crate::rng::Rng;
use crate::scene::{spherical, SceneBuilder};
use glam::Vec3;

/// Places one light of a randomly chosen kind at the given elevation (degrees) and distance
/// from `target`, at a random azimuth in the back half (so it lights the scene towards the
/// camera, which sits on the +z side), aimed at `target`.
#[allow(clippy::too_many_arguments)]
pub fn place_small_light(
    b: &mut SceneBuilder,
    rng: &mut Rng,
    kinds: &[SmallLight],
    target: Vec3,
    elevation: [f32; 2],
    distance: [f32; 2],
    size: [f32; 2],
    power: [f32; 2],
) -> (SmallLight, Vec3) {
    let kind = *rng.pick(kinds);
    let azimuth = rng.range([200.0, 340.0]);
    let dir = spherical(azimuth, rng.range(elevation));
    let pos = target + dir * rng.range(distance);
    let watts = rng.range(power);
    add_small_light(b, rng, kind, pos, target, size, watts);
    (kind, pos)
}

/// Adds one light of kind `kind` at `pos` aimed at `target` emitting `watts`; an area light
/// gets a half-size from `size`, a spot a cutoff of 20°–35°.
pub fn add_small_light(
    b: &mut SceneBuilder,
    rng: &mut Rng,
    kind: SmallLight,
    pos: Vec3,
    target: Vec3,
    size: [f32; 2],
    watts: f32,
) {
    match kind {
        SmallLight::Area => b.area_light(pos, target, rng.range(size), watts),
        SmallLight::Spot => b.spot_light(pos, target, watts, rng.range([20.0, 35.0])),
        SmallLight::Point => b.point_light(pos, watts),
    }
}
