//! Family 6: small bright sources seen directly — furnished rooms lit only by one to three
//! lamps, each a small emitting sphere (the bulb) in an opaque shade open at both ends, so the
//! light spills from the openings onto the floor, the walls and the ceiling.

use super::room::{sampled_shell, ShellRanges};
use crate::config::{Config, LampConfig, LampKind};
use crate::mesh::{lathe, sharp};
use crate::rng::Rng;
use crate::scene::{Family, GeneratedScene, Material, SceneBuilder};
use glam::Vec3;

/// Wall thickness of the shades. A closed (thick) shell rather than a single sheet keeps both
/// faces front-facing, so the builder's one-sided diffuse lights the inside and the outside.
const SHADE_WALL: f32 = 0.01;

/// A floor position (y = 0) for something of footprint radius `r` that keeps clear of the walls,
/// of the strip in front where the camera stands and (when possible) of everything placed.
fn place(rng: &mut Rng, placed: &mut Vec<(Vec3, f32)>, r: f32, hx: f32, hz: f32) -> Vec3 {
    let x_max = (hx - r - 0.1).max(0.0);
    let (z_min, z_max) = (-hz + r + 0.1, hz * 0.3 - r);
    let mut pos = Vec3::ZERO;
    for _ in 0..32 {
        pos = Vec3::new(
            rng.range([-x_max, x_max]),
            0.0,
            rng.range([z_min.min(z_max), z_max]),
        );
        if placed.iter().all(|(p, pr)| p.distance(pos) > pr + r + 0.05) {
            break;
        }
    }
    placed.push((pos, r));
    pos
}

/// Generates one lamp-lit room.
pub fn generate(config: &Config, c: &LampConfig, rng: &mut Rng, id: String) -> GeneratedScene {
    let mut b = SceneBuilder::new(config);
    let (hx, hz, h) = sampled_shell(
        &mut b,
        rng,
        &ShellRanges {
            size_x: c.size_x,
            size_z: c.size_z,
            height: c.height,
            wall_albedo: c.wall_albedo,
            floor_albedo: c.floor_albedo,
            floor_alpha: c.floor_alpha,
        },
    );
    let fitting = Material::Diffuse(rng.color([0.03, 0.12]));

    let mut placed: Vec<(Vec3, f32)> = Vec::new();
    let mut bulbs = Vec::new();
    let mut kinds = Vec::new();
    let lamps = rng.range_u32(c.lamps);
    for k in 0..lamps {
        let kind = *rng.pick(&c.kinds);
        kinds.push(format!("{kind:?}"));
        // Table and pendant shades are smaller than a floor lamp's.
        let scale = match kind {
            LampKind::Floor => 1.0,
            LampKind::Table => 0.7,
            LampKind::Pendant => 0.8,
        };
        let r_low = rng.range(c.shade_radius) * scale;
        let r_up = r_low * rng.range(c.shade_taper);
        let shade_h = r_low * rng.range(c.shade_height);
        // The bulb must clear the shade's narrower opening.
        let bulb_r = rng
            .range(c.bulb_radius)
            .min(0.6 * r_low.min(r_up) - SHADE_WALL)
            .max(0.005);
        let bulb_at = rng.range(c.bulb_position);
        let warmth = rng.range(c.bulb_warmth).clamp(0.0, 1.0);
        let color = [1.0, 1.0 - 0.5 * warmth, 1.0 - warmth];
        let power = rng.range(c.lamp_power);
        let footprint = r_low.max(r_up) + SHADE_WALL;

        // Where the shade's lower rim sits, and where the lamp stands (floor or table top).
        let (pos, shade_y, stand_y) = match kind {
            LampKind::Floor => {
                let pos = place(rng, &mut placed, footprint.max(0.2), hx, hz);
                let y = rng.range([1.1, 1.5]).min(h - shade_h - 0.3);
                (pos, y, Some(0.0))
            }
            LampKind::Table => {
                // The lamp brings its own side table.
                let half = rng.range([0.2, 0.3]).max(footprint);
                let top = rng.range([0.45, 0.7]);
                let pos = place(rng, &mut placed, half * std::f32::consts::SQRT_2, hx, hz);
                b.cube(
                    pos + Vec3::Y * (top / 2.0),
                    Vec3::new(half, top / 2.0, half),
                    rng.range([0.0, 90.0]),
                    &Material::Diffuse(rng.color([0.15, 0.6])),
                );
                (pos, top + rng.range([0.2, 0.35]), Some(top))
            }
            LampKind::Pendant => {
                // Its footprint keeps furniture from standing under it.
                let pos = place(rng, &mut placed, footprint, hx, hz);
                let y = h - rng.range([0.3, 0.8]) - shade_h;
                (pos, y, None)
            }
        };
        let bulb = pos + Vec3::Y * (shade_y + bulb_at * shade_h);

        // Shade: a tapered tube with a closed cross-section, open at the top and the bottom.
        let profile = [
            sharp(r_low, 0.0),
            sharp(r_low + SHADE_WALL, 0.0),
            sharp(r_up + SHADE_WALL, shade_h),
            sharp(r_up, shade_h),
            sharp(r_low, 0.0),
        ];
        b.mesh(
            &format!("shade{k}"),
            lathe(&profile, 48, None),
            pos + Vec3::Y * shade_y,
            0.0,
            &Material::Diffuse(rng.color(c.shade_albedo)),
        );
        // A pole up to the bulb, or a cord down from the ceiling to it.
        let (from, to) = match stand_y {
            Some(y) => {
                b.cube(
                    pos + Vec3::Y * (y + 0.015),
                    Vec3::new(0.12 * scale, 0.015, 0.12 * scale),
                    0.0,
                    &fitting,
                );
                (y + 0.03, bulb.y - bulb_r)
            }
            None => (bulb.y + bulb_r, h),
        };
        let half = (to - from).max(0.0) / 2.0;
        if half > 0.0 {
            let thick = if stand_y.is_some() { 0.012 } else { 0.004 };
            b.cube(
                Vec3::new(pos.x, from + half, pos.z),
                Vec3::new(thick, half, thick),
                0.0,
                &fitting,
            );
        }
        b.sphere_light(bulb, bulb_r, power, color);
        bulbs.push(bulb);
    }

    // Furniture: tables and boxes (cabinets, sofas) below lamp height.
    let n = rng.range_u32(c.objects);
    for _ in 0..n {
        let s = rng.range(c.object_size);
        let material = if rng.chance(0.3) {
            Material::Plastic {
                albedo: rng.color([0.1, 0.8]),
                alpha: rng.range([0.05, 0.3]),
            }
        } else {
            Material::Diffuse(rng.color([0.1, 0.8]))
        };
        if rng.chance(c.table_probability) {
            let half = Vec3::new(s * rng.range([0.6, 1.0]), 0.025, s * rng.range([0.4, 0.7]));
            let pos = place(rng, &mut placed, half.x.hypot(half.z), hx, hz);
            let top = (s * rng.range([0.7, 1.0])).min(0.9);
            b.cube(pos + Vec3::Y * (top - half.y), half, 0.0, &material);
            let leg_h = (top - 2.0 * half.y) / 2.0;
            for (dx, dz) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                let leg = Vec3::new(dx * (half.x - 0.04), leg_h, dz * (half.z - 0.04));
                b.cube(pos + leg, Vec3::new(0.025, leg_h, 0.025), 0.0, &material);
            }
        } else {
            let half = Vec3::new(
                s * rng.range([0.5, 1.0]),
                (s * rng.range([0.3, 0.8])).min(0.45),
                s * 0.5,
            );
            let pos = place(rng, &mut placed, half.x.hypot(half.z), hx, hz);
            b.cube(
                pos + Vec3::Y * half.y,
                half,
                rng.range([0.0, 90.0]),
                &material,
            );
        }
    }

    // Camera near the front wall; half the time looking at a bulb, so bulbs are often in view.
    let eye = Vec3::new(
        rng.range([-0.3, 0.3]) * hx,
        rng.range([0.35, 0.6]) * h,
        hz - 0.3,
    );
    let target = if rng.chance(0.5) && !bulbs.is_empty() {
        *rng.pick(&bulbs)
    } else {
        Vec3::new(rng.range([-0.3, 0.3]) * hx, rng.range([0.3, 0.6]) * h, -hz)
    };
    b.camera(eye, target, rng.range(c.fov), None);
    b.finish(
        id,
        Family::Lamp,
        &format!(
            "lamp-lit room: {} lamps, generated by datagen",
            kinds.join(", ")
        ),
    )
}
