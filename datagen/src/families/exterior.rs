//! Family 8: sun caustics outdoors — glass spheres and blocks, raised glass slabs and small
//! wavy pools on a plain or paved ground, among diffuse and metal objects, lit by a constant
//! sky and a directional sun behind the objects (so the caustics fall towards the camera),
//! seen from eye height.

use crate::config::{Config, ExteriorConfig, ExteriorGlass};
use crate::mesh::{height_field, Waves};
use crate::rng::Rng;
use crate::scene::{spherical, Family, GeneratedScene, Material, SceneBuilder};
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::TAU;

/// Radius of the disc the objects stand in.
const SPREAD: f32 = 1.6;

/// Rejection-samples a ground position for a footprint of radius `r` clear of `placed`.
fn place(rng: &mut Rng, placed: &mut Vec<(Vec3, f32)>, r: f32) -> Vec3 {
    let mut pos = Vec3::ZERO;
    for _ in 0..48 {
        let (a, d) = (rng.range([0.0, TAU]), SPREAD * rng.uniform().sqrt() as f32);
        pos = Vec3::new(a.cos() * d, 0.0, a.sin() * d);
        if placed.iter().all(|(p, q)| p.distance(pos) > q + r + 0.1) {
            break;
        }
    }
    placed.push((pos, r));
    pos
}

/// Generates one exterior scene.
pub fn generate(config: &Config, c: &ExteriorConfig, rng: &mut Rng, id: String) -> GeneratedScene {
    let mut b = SceneBuilder::new(config);
    let g = rng.range(c.ground_size);
    let ground = if rng.chance(c.checker_probability) {
        Material::Checker {
            a: rng.color(c.ground_albedo),
            b: rng.color([0.05, 0.2]),
            // Mitsuba's checkerboard has 2 squares per unit uv; the uv spans 2g.
            uv_scale: g / rng.range(c.check_size),
        }
    } else {
        Material::Diffuse(rng.color(c.ground_albedo))
    };
    b.rectangle(Vec3::ZERO, Vec3::Z * g, Vec3::X * g, &ground, None);

    let mut placed: Vec<(Vec3, f32)> = Vec::new();
    let mut kinds = Vec::new();
    let stone = Material::Diffuse(rng.color([0.3, 0.6]));
    for k in 0..rng.range_u32(c.glass_objects) {
        let shape = *rng.pick(&c.glass_shapes);
        let s = rng.range(c.glass_size);
        let glass = Material::Glass {
            ior: rng.range(c.ior),
        };
        let yaw = rng.range([0.0, 90.0]);
        match shape {
            ExteriorGlass::Sphere => {
                let pos = place(rng, &mut placed, s);
                b.sphere(pos + Vec3::Y * s, s, &glass);
            }
            ExteriorGlass::Block => {
                let pos = place(rng, &mut placed, s * 1.42);
                b.cube(pos + Vec3::Y * (s + 0.001), Vec3::splat(s), yaw, &glass);
            }
            ExteriorGlass::Slab => {
                // A thick pane on four short legs: the caustic forms in its shadow.
                let half = Vec3::new(1.5 * s, 0.15 * s, s);
                let pos = place(rng, &mut placed, 1.8 * s);
                let leg_h = 0.6 * s;
                b.cube(pos + Vec3::Y * (2.0 * leg_h + half.y), half, yaw, &glass);
                let r = Mat3::from_rotation_y(yaw.to_radians());
                for (dx, dz) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                    let corner = r * Vec3::new(dx * (half.x - 0.04), 0.0, dz * (half.z - 0.04));
                    b.cube(
                        pos + corner + Vec3::Y * leg_h,
                        Vec3::new(0.03, leg_h, 0.03),
                        yaw,
                        &stone,
                    );
                }
            }
            ExteriorGlass::Pool => {
                let p = rng.range(c.pool_size);
                let pos = place(rng, &mut placed, 1.42 * (p + 0.1));
                let (wall_h, t) = (rng.range([0.2, 0.35]), 0.06);
                let r = Mat3::from_rotation_y(yaw.to_radians());
                for (dir, len) in [(Vec3::X, p + 2.0 * t), (Vec3::Z, p)] {
                    for side in [-1.0, 1.0] {
                        let half = if dir == Vec3::X {
                            Vec3::new(t, wall_h / 2.0, len)
                        } else {
                            Vec3::new(len, wall_h / 2.0, t)
                        };
                        b.cube(
                            pos + r * (dir * side * (p + t)) + Vec3::Y * (wall_h / 2.0),
                            half,
                            yaw,
                            &stone,
                        );
                    }
                }
                // A tiled bottom a hair above the ground, then the water sheet.
                b.rectangle(
                    pos + Vec3::Y * 0.002,
                    r * Vec3::Z * p,
                    r * Vec3::X * p,
                    &Material::Checker {
                        a: rng.color([0.5, 0.8]),
                        b: rng.color([0.05, 0.25]),
                        uv_scale: rng.range([3.0, 6.0]),
                    },
                    None,
                );
                let waves = Waves {
                    waves: (0..rng.range_u32([3, 5]))
                        .map(|_| {
                            let angle = rng.range([0.0, TAU]);
                            let kn = TAU / rng.range([0.2, 0.6]);
                            (
                                Vec2::new(angle.cos(), angle.sin()) * kn,
                                rng.range(c.wave_amplitude),
                                rng.range([0.0, TAU]),
                            )
                        })
                        .collect(),
                };
                b.mesh(
                    &format!("pool{k}"),
                    height_field(&waves, p, p, 64),
                    pos + Vec3::Y * (0.75 * wall_h),
                    yaw,
                    &Material::Glass { ior: 1.33 },
                );
            }
        }
        kinds.push(format!("{shape:?}"));
    }

    for _ in 0..rng.range_u32(c.objects) {
        let s = rng.range(c.object_size);
        let material = if rng.chance(c.metal_probability) {
            Material::Metal {
                name: rng.pick(&c.metals).clone(),
                alpha: rng.range([0.0, 0.2]),
            }
        } else {
            Material::Diffuse(rng.color([0.15, 0.8]))
        };
        if rng.chance(0.5) {
            let pos = place(rng, &mut placed, s);
            b.sphere(pos + Vec3::Y * s, s, &material);
        } else {
            let pos = place(rng, &mut placed, s * 1.42);
            let half = Vec3::new(s, s * rng.range([0.5, 1.5]), s * rng.range([0.6, 1.0]));
            b.cube(
                pos + Vec3::Y * half.y,
                half,
                rng.range([0.0, 90.0]),
                &material,
            );
        }
    }

    let centre = placed.iter().map(|(p, _)| *p).sum::<Vec3>() / placed.len().max(1) as f32;
    let cam_azimuth = rng.range([0.0, 360.0]);
    // The sun stands behind the objects as seen from the camera, within ±60° of straight on.
    let sun_azimuth = cam_azimuth + 180.0 + rng.range([-60.0, 60.0]);
    let towards_sun = spherical(sun_azimuth, rng.range(c.sun_elevation));
    b.sun(-towards_sun, rng.range(c.sun_irradiance));
    b.environment(rng.range(c.sky_radiance));

    let eye = centre
        + spherical(cam_azimuth, 0.0) * rng.range(c.camera_distance)
        + Vec3::Y * rng.range(c.camera_height);
    b.camera(eye, centre + Vec3::Y * 0.2, rng.range(c.fov), None);
    b.finish(
        id,
        Family::Exterior,
        &format!(
            "exterior: {} under sun and sky, generated by datagen",
            kinds.join(", ")
        ),
    )
}
