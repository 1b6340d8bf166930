//! Family 9: many materials — two to five procedural meshes (closed vases, noisy blobs, tori)
//! and boxes, each with a random BSDF from the configured kinds (diffuse, plastic, rough
//! plastic, conductor, rough conductor, dielectric, rough dielectric, principled; diffuse and
//! principled ones sometimes checkered), on a floor in a simple open-fronted room or in the
//! open, under an area light and a constant environment.

use super::front_camera;
use crate::config::{Config, MaterialConfig, MaterialKind, MaterialShape};
use crate::mesh::{blob, lathe, sharp, smooth, ProfilePoint};
use crate::ply::Mesh;
use crate::rng::Rng;
use crate::scene::{Family, GeneratedScene, Material, SceneBuilder};
use glam::{Vec2, Vec3};
use std::f32::consts::TAU;

/// Half-size of the floor (and of the room, when there is one).
const ROOM: f32 = 4.0;
/// Ceiling height of the room.
const CEILING: f32 = 3.0;

/// Gives `mesh` planar uvs (u along x + z, v along y, `scale` per unit length), so checks show
/// on every side without a seam.
fn planar_uvs(mesh: &mut Mesh, scale: f32) {
    mesh.uvs = mesh
        .positions
        .iter()
        .map(|p| Vec2::new((p.x + p.z) * scale, p.y * scale))
        .collect();
}

/// A random material of kind `kind`.
fn material(rng: &mut Rng, c: &MaterialConfig, kind: MaterialKind) -> Material {
    let rough = |rng: &mut Rng| rng.range(c.alpha).max(0.01);
    match kind {
        MaterialKind::Diffuse if rng.chance(c.texture_probability) => Material::Checker {
            a: rng.color(c.albedo),
            b: rng.color([0.02, 0.15]),
            uv_scale: rng.range([1.0, 3.0]),
        },
        MaterialKind::Diffuse => Material::Diffuse(rng.color(c.albedo)),
        MaterialKind::Plastic => Material::Plastic {
            albedo: rng.color(c.albedo),
            alpha: 0.0,
        },
        MaterialKind::RoughPlastic => Material::Plastic {
            albedo: rng.color(c.albedo),
            alpha: rough(rng),
        },
        MaterialKind::Conductor => Material::Metal {
            name: rng.pick(&c.metals).clone(),
            alpha: 0.0,
        },
        MaterialKind::RoughConductor => Material::Metal {
            name: rng.pick(&c.metals).clone(),
            alpha: rough(rng),
        },
        MaterialKind::Dielectric => Material::Glass {
            ior: rng.range(c.ior),
        },
        MaterialKind::RoughDielectric => Material::RoughGlass {
            ior: rng.range(c.ior),
            alpha: rough(rng),
        },
        MaterialKind::Principled => {
            let base = rng.color(c.albedo);
            let checker = if rng.chance(c.texture_probability) {
                Some((rng.color([0.02, 0.15]), rng.range([1.0, 3.0])))
            } else {
                None
            };
            Material::Principled {
                base,
                checker,
                roughness: rng.range(c.alpha).clamp(0.0, 1.0),
                metallic: if rng.chance(0.4) {
                    rng.range([0.6, 1.0])
                } else {
                    0.0
                },
                clearcoat: if rng.chance(0.4) {
                    rng.range([0.3, 1.0])
                } else {
                    0.0
                },
            }
        }
    }
}

/// Generates one material scene.
pub fn generate(config: &Config, c: &MaterialConfig, rng: &mut Rng, id: String) -> GeneratedScene {
    let mut b = SceneBuilder::new(config);
    b.rectangle(
        Vec3::ZERO,
        Vec3::Z * ROOM,
        Vec3::X * ROOM,
        &Material::Diffuse(rng.color(c.floor_albedo)),
        None,
    );
    let room = rng.chance(c.room_probability);
    if room {
        // Back and side walls and a ceiling, all facing inwards; the front (+z) stays open.
        let wall = Material::Diffuse(rng.color([0.4, 0.8]));
        let h = Vec3::Y * (CEILING / 2.0);
        b.rectangle(h - Vec3::Z * ROOM, Vec3::X * ROOM, h, &wall, None);
        b.rectangle(h - Vec3::X * ROOM, h, Vec3::Z * ROOM, &wall, None);
        b.rectangle(h + Vec3::X * ROOM, Vec3::Z * ROOM, h, &wall, None);
        b.rectangle(
            Vec3::Y * CEILING,
            Vec3::X * ROOM,
            Vec3::Z * ROOM,
            &wall,
            None,
        );
    }

    let n = rng.range_u32(c.objects);
    let mut placed: Vec<(Vec3, f32)> = Vec::new();
    let mut names = Vec::new();
    for k in 0..n {
        let s = rng.range(c.object_size);
        let shape = *rng.pick(&c.shapes);
        let kind = *rng.pick(&c.kinds);
        let m = material(rng, c, kind);
        // Objects stand in a ring round the origin, clear of each other.
        let spread = 0.4 + 0.35 * n as f32;
        let mut pos = Vec3::ZERO;
        for _ in 0..48 {
            let (a, d) = (rng.range([0.0, TAU]), spread * rng.uniform().sqrt() as f32);
            pos = Vec3::new(a.cos() * d, 0.0, a.sin() * d);
            if placed
                .iter()
                .all(|(p, r)| p.distance(pos) > r + 1.42 * s + 0.05)
            {
                break;
            }
        }
        placed.push((pos, 1.42 * s));
        let yaw = rng.range([0.0, 360.0]);
        match shape {
            MaterialShape::Box => {
                let half = Vec3::new(s, s * rng.range([0.4, 1.2]), s * rng.range([0.5, 1.0]));
                b.cube(pos + Vec3::Y * (half.y + 0.001), half, yaw, &m);
            }
            MaterialShape::Vase => {
                let h = s * rng.range([1.5, 3.0]);
                let (belly, neck, lip) = (
                    rng.range([0.3, 0.6]),
                    rng.range([0.3, 0.7]),
                    rng.range([0.4, 0.8]),
                );
                // Out along the bottom, up the outside, in over the (closed) top.
                let profile: Vec<ProfilePoint> = vec![
                    sharp(0.0, 0.0),
                    sharp(0.6 * s, 0.0),
                    smooth(s, belly * h),
                    smooth(neck * s, 0.85 * h),
                    sharp(lip * s, h),
                    sharp(0.0, h),
                ];
                let mut mesh = lathe(&profile, 64, None);
                planar_uvs(&mut mesh, 1.0 / s);
                b.mesh(&format!("vase{k}"), mesh, pos + Vec3::Y * 0.001, yaw, &m);
            }
            MaterialShape::Blob => {
                let lobes = rng.range_u32([3, 6]);
                let mut mesh = blob(rng, s, lobes, 0.3, 24);
                let lowest = mesh.positions.iter().map(|p| p.y).fold(f32::MAX, f32::min);
                planar_uvs(&mut mesh, 1.0 / s);
                b.mesh(
                    &format!("blob{k}"),
                    mesh,
                    pos - Vec3::Y * (lowest - 0.001),
                    yaw,
                    &m,
                );
            }
            MaterialShape::Torus => {
                let a = s * rng.range([0.2, 0.35]);
                let r = s - a;
                // A circle about (r, 0), counter-clockwise in (r, y): the outside on the right.
                let profile: Vec<ProfilePoint> = (0..=48)
                    .map(|i| {
                        let t = i as f32 / 48.0 * TAU;
                        smooth(r + a * t.cos(), a * t.sin())
                    })
                    .collect();
                let mut mesh = lathe(&profile, 64, None);
                let standing = rng.chance(0.5);
                if standing {
                    // Stand it on its rim: rotate 90° about x.
                    let rot = |v: Vec3| Vec3::new(v.x, -v.z, v.y);
                    mesh.positions.iter_mut().for_each(|p| *p = rot(*p));
                    mesh.normals.iter_mut().for_each(|n| *n = rot(*n));
                }
                planar_uvs(&mut mesh, 1.0 / s);
                let lift = if standing { s } else { a };
                b.mesh(
                    &format!("torus{k}"),
                    mesh,
                    pos + Vec3::Y * (lift + 0.001),
                    yaw,
                    &m,
                );
            }
        }
        names.push(format!("{shape:?} ({kind:?})"));
    }

    let centre = placed.iter().map(|(p, _)| *p).sum::<Vec3>() / placed.len().max(1) as f32;
    let light_y = if room {
        rng.range(c.light_height).min(CEILING - 0.05)
    } else {
        rng.range(c.light_height)
    };
    let light = centre + Vec3::new(rng.range([-1.0, 1.0]), light_y, rng.range([-1.0, 1.0]));
    b.area_light(
        light,
        Vec3::new(light.x, 0.0, light.z) + Vec3::X * 0.01,
        rng.range(c.light_size),
        rng.range(c.light_power),
    );
    b.environment(rng.range(c.env_radiance));

    let target = centre + Vec3::Y * 0.3;
    front_camera(
        &mut b,
        rng,
        target,
        c.camera_elevation,
        c.camera_distance,
        c.fov,
    );
    b.finish(
        id,
        Family::Material,
        &format!(
            "material: {} {}, generated by datagen",
            names.join(", "),
            if room { "in a room" } else { "in the open" }
        ),
    )
}
