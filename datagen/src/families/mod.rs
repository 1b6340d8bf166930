//! The procedural scene families and the deterministic mapping from (config, scene index) to a
//! generated scene. Scenes are numbered over the families in [`Family::ALL`] order.

mod exterior;
mod glass;
mod lamp;
mod lights;
mod material;
mod metal;
mod room;
mod shelf;
mod tabletop;
mod textured;
mod water;

use crate::config::Config;
use crate::rng::{hash_seq, hash_str, Rng};
use crate::scene::{spherical, Family, GeneratedScene, SceneBuilder};
use glam::Vec3;

/// Every scene of the config as (scene id, family), in index order.
pub fn scene_list(config: &Config) -> Vec<(String, Family)> {
    let f = &config.families;
    let counts = [
        f.room.as_ref().map_or(0, |c| c.count),
        f.glass.as_ref().map_or(0, |c| c.count),
        f.water.as_ref().map_or(0, |c| c.count),
        f.metal.as_ref().map_or(0, |c| c.count),
        f.shelf.as_ref().map_or(0, |c| c.count),
        f.lamp.as_ref().map_or(0, |c| c.count),
        f.tabletop.as_ref().map_or(0, |c| c.count),
        f.exterior.as_ref().map_or(0, |c| c.count),
        f.material.as_ref().map_or(0, |c| c.count),
        f.textured.as_ref().map_or(0, |c| c.count),
    ];
    let mut out = Vec::new();
    for (family, count) in Family::ALL.into_iter().zip(counts) {
        for _ in 0..count {
            let id = format!("{:03}-{}", out.len(), family.name());
            out.push((id, family));
        }
    }
    // The user's scenes last, named after their folders (or `name`).
    for s in f.external.iter().flat_map(|c| &c.scenes) {
        let id = format!("{:03}-{}", out.len(), s.id_name());
        out.push((id, Family::External));
    }
    out
}

/// Generates scene number `index` (see [`scene_list`]); deterministic in (config, index).
/// `None` for an external scene (the user's file is rendered as it is).
pub fn generate(config: &Config, index: usize) -> Option<GeneratedScene> {
    let (id, family) = scene_list(config)[index].clone();
    // A scene of a regime with its own side is generated at that size (only the film changes).
    let (width, height) = crate::plan::scene_size(config, index);
    let resized;
    let config = if (width, height) == (config.width, config.height) {
        config
    } else {
        resized = Config {
            width,
            height,
            ..config.clone()
        };
        &resized
    };
    let mut rng = Rng::new(hash_seq(&[config.seed, hash_str("scene"), index as u64]));
    let f = &config.families;
    // The family tables exist for every listed family (scene_list only lists those).
    Some(match family {
        Family::Room => room::generate(config, f.room.as_ref().unwrap(), &mut rng, id),
        Family::Glass => glass::generate(config, f.glass.as_ref().unwrap(), &mut rng, id),
        Family::Water => water::generate(config, f.water.as_ref().unwrap(), &mut rng, id),
        Family::Metal => metal::generate(config, f.metal.as_ref().unwrap(), &mut rng, id),
        Family::Shelf => shelf::generate(config, f.shelf.as_ref().unwrap(), &mut rng, id),
        Family::Lamp => lamp::generate(config, f.lamp.as_ref().unwrap(), &mut rng, id),
        Family::Tabletop => tabletop::generate(config, f.tabletop.as_ref().unwrap(), &mut rng, id),
        Family::Exterior => exterior::generate(config, f.exterior.as_ref().unwrap(), &mut rng, id),
        Family::Material => material::generate(config, f.material.as_ref().unwrap(), &mut rng, id),
        Family::Textured => textured::generate(config, f.textured.as_ref().unwrap(), &mut rng, id),
        Family::External => return None,
    })
}

/// A pinhole camera looking at `target` from in front (azimuth 60–120°, the +z side), at an
/// elevation (degrees), distance and horizontal fov drawn from the ranges — in that order, so
/// every family using it draws its camera the same way.
pub(crate) fn front_camera(
    b: &mut SceneBuilder,
    rng: &mut Rng,
    target: Vec3,
    elevation: [f32; 2],
    distance: [f32; 2],
    fov: [f32; 2],
) {
    let eye =
        target + spherical(rng.range([60.0, 120.0]), rng.range(elevation)) * rng.range(distance);
    b.camera(eye, target, rng.range(fov), None);
}
