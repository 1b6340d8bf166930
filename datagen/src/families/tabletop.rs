//! Family 7: caustics seen directly, through glass and in a mirror — glass spheres, solid
//! cylinders and tumblers (some holding a liquid) on a table top under one or two small lights,
//! in some scenes before a mirror standing at the back of the table.

use super::front_camera;
use super::lights::add_small_light;
use crate::config::{Config, TabletopConfig, TabletopObject};
use crate::mesh::{lathe, sharp};
use crate::rng::Rng;
use crate::scene::{spherical, Family, GeneratedScene, Material, SceneBuilder};
use glam::{Mat3, Vec3};

/// How far the objects stand above the table top: a glass base lying in the top's plane would
/// leave every ray reaching it two surfaces at the same distance, which renderers resolve by
/// rounding, each its own way (Mitsuba picks the table ≈ 3 % more often than ours: 2.7 % of
/// the light through the glasses). Well above both renderers' ray offsets (≈ 2.5e-4 here).
const LIFT: f32 = 1e-3;

/// Height of the table top above the floor (the top is the plane y = 0).
const TABLE_HEIGHT: f32 = 0.75;

/// Generates one tabletop scene.
pub fn generate(config: &Config, c: &TabletopConfig, rng: &mut Rng, id: String) -> GeneratedScene {
    let mut b = SceneBuilder::new(config);
    let (tx, tz) = (rng.range(c.table_size_x), rng.range(c.table_size_z));
    let top = if rng.chance(c.checker_probability) {
        Material::Checker {
            a: rng.color(c.table_albedo),
            b: rng.color([0.05, 0.2]),
            uv_scale: rng.range([2.0, 6.0]),
        }
    } else if rng.chance(c.plastic_probability) {
        Material::Plastic {
            albedo: rng.color(c.table_albedo),
            alpha: rng.range(c.table_alpha),
        }
    } else {
        Material::Diffuse(rng.color(c.table_albedo))
    };
    // The visible top is a rectangle (its uv spans the table, so checks keep their size on any
    // table); the board under it sits a hair lower so the two never coincide.
    b.rectangle(Vec3::ZERO, Vec3::Z * tz, Vec3::X * tx, &top, None);
    let wood = Material::Diffuse(rng.color([0.1, 0.4]));
    b.cube(
        Vec3::new(0.0, -0.032, 0.0),
        Vec3::new(tx, 0.03, tz),
        0.0,
        &wood,
    );
    let leg_h = (TABLE_HEIGHT - 0.062) / 2.0;
    for (dx, dz) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
        b.cube(
            Vec3::new(dx * (tx - 0.06), -TABLE_HEIGHT + leg_h, dz * (tz - 0.06)),
            Vec3::new(0.03, leg_h, 0.03),
            0.0,
            &wood,
        );
    }
    b.rectangle(
        Vec3::Y * -TABLE_HEIGHT,
        Vec3::Z * 10.0,
        Vec3::X * 10.0,
        &Material::Diffuse(rng.color([0.2, 0.5])),
        None,
    );

    // The mirror stands near the back edge, facing the camera side (+z).
    let mirror_z = -tz + 0.08;
    let mirror = rng.chance(c.mirror_probability);
    // How far forward of the back edge the objects must stay (the mirror's yaw swings one end
    // towards them).
    let mut reach = -tz + 0.05;
    if mirror {
        let (w, mh) = (
            rng.range(c.mirror_width).min(tx),
            rng.range(c.mirror_height),
        );
        let yaw = rng.range(c.mirror_yaw);
        let r = Mat3::from_rotation_y(yaw.to_radians());
        let center = Vec3::new(
            rng.range([-0.3, 0.3]) * (tx - w),
            mh / 2.0 + 0.002,
            mirror_z,
        );
        let material = Material::Metal {
            name: rng.pick(&c.mirror_materials).clone(),
            alpha: 0.0,
        };
        reach = mirror_z + w * yaw.to_radians().sin().abs() + 0.05;
        // Front side u × v = +z (rotated by the yaw).
        b.rectangle(
            center,
            r * Vec3::X * w,
            Vec3::Y * (mh / 2.0),
            &material,
            None,
        );
        // A thin backing board, so the mirror's back is not a black one-sided sheet.
        b.cube(
            center - r * Vec3::Z * 0.012,
            Vec3::new(w, mh / 2.0, 0.01),
            yaw,
            &wood,
        );
    }

    let n = rng.range_u32(c.objects);
    let mut placed: Vec<(Vec3, f32)> = Vec::new();
    let mut kinds = Vec::new();
    for k in 0..n {
        let radius = rng.range(c.object_size);
        // Rejection-sample a footprint on the table (in front of the mirror) clear of the others.
        let x_max = (tx - radius - 0.05).max(0.0);
        let z_min = reach + radius;
        let z_max = (tz - radius - 0.05).max(z_min);
        let mut pos = Vec3::ZERO;
        for _ in 0..32 {
            pos = Vec3::new(rng.range([-x_max, x_max]), LIFT, rng.range([z_min, z_max]));
            if placed
                .iter()
                .all(|(p, r)| p.distance(pos) > r + radius + 0.03)
            {
                break;
            }
        }
        placed.push((pos, radius));
        let glass = Material::Glass {
            ior: rng.range(c.ior),
        };
        let height = radius * rng.range(c.object_height);
        let shape = *rng.pick(&c.shapes);
        match shape {
            TabletopObject::Sphere => b.sphere(pos + Vec3::Y * radius, radius, &glass),
            TabletopObject::Cylinder => {
                let profile = [
                    sharp(0.0, 0.0),
                    sharp(radius, 0.0),
                    sharp(radius, height),
                    sharp(0.0, height),
                ];
                b.mesh(
                    &format!("cylinder{k}"),
                    lathe(&profile, 64, None),
                    pos,
                    0.0,
                    &glass,
                );
            }
            TabletopObject::Tumbler => {
                let (wall, base) = (0.06 * radius, 0.15 * radius);
                // Bottom outwards, up the outside, over the rim, down the inside, to the axis.
                let profile = [
                    sharp(0.0, 0.0),
                    sharp(radius, 0.0),
                    sharp(radius, height),
                    sharp(radius - wall, height),
                    sharp(radius - wall, base),
                    sharp(0.0, base),
                ];
                b.mesh(
                    &format!("tumbler{k}"),
                    lathe(&profile, 64, None),
                    pos,
                    0.0,
                    &glass,
                );
                if rng.chance(c.liquid_probability) {
                    // A thin air gap keeps the liquid's surface off the glass: each body is then
                    // a closed dielectric with air outside, which is what the builder writes.
                    let gap = 0.01 * radius;
                    let (r, y0) = (radius - wall - gap, base + gap);
                    let y1 = y0 + rng.range(c.liquid_fill) * (height - y0 - gap);
                    if y1 - y0 > 2.0 * gap {
                        let profile = [sharp(0.0, y0), sharp(r, y0), sharp(r, y1), sharp(0.0, y1)];
                        let liquid = Material::Glass {
                            ior: rng.range(c.liquid_ior),
                        };
                        b.mesh(
                            &format!("liquid{k}"),
                            lathe(&profile, 64, None),
                            pos,
                            0.0,
                            &liquid,
                        );
                    }
                }
            }
        }
        kinds.push(format!("{shape:?}"));
    }

    let target =
        placed.iter().map(|(p, _)| *p).sum::<Vec3>() / placed.len().max(1) as f32 + Vec3::Y * 0.05;
    // With a mirror the lights stand to the camera's sides, throwing the caustics back towards
    // the mirror and never standing behind it; without one they stand behind the objects, so
    // the caustics fall towards the camera.
    let lights = rng.range_u32(c.light_count);
    let mut back = -tz - 1.0;
    let mut light_kinds = Vec::new();
    for _ in 0..lights {
        let kind = *rng.pick(&c.lights);
        let azimuth = if mirror {
            let side = if rng.chance(0.5) { -1.0 } else { 1.0 };
            90.0 + side * rng.range([35.0, 80.0])
        } else {
            rng.range([200.0, 340.0])
        };
        let pos =
            target + spherical(azimuth, rng.range(c.light_elevation)) * rng.range(c.light_distance);
        let watts = rng.range(c.light_power);
        add_small_light(&mut b, rng, kind, pos, target, c.light_size, watts);
        back = back.min(pos.z - 0.5);
        light_kinds.push(format!("{kind:?}"));
    }
    // The back wall stands behind the table and the lights, catching what passes them.
    b.rectangle(
        Vec3::new(0.0, 2.0, back),
        Vec3::X * 10.0,
        Vec3::Y * 3.0,
        &Material::Diffuse(rng.color([0.3, 0.7])),
        None,
    );
    b.environment(rng.range(c.env_radiance));

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
        Family::Tabletop,
        &format!(
            "tabletop: {} {}under {} lights, generated by datagen",
            kinds.join(", "),
            if mirror { "before a mirror " } else { "" },
            light_kinds.join(" and ")
        ),
    )
}
