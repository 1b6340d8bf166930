//! Family 10: textured surfaces, the way users' scenes look — a room corner (floor and two
//! walls) or a table top before a wall, each surface a bitmap albedo (tiles, bricks, wood
//! planks, veined stone or plaster) with its relief as a `bumpmap` (16-bit height map) or a
//! `normalmap` (8-bit normal map), the floor or table top sometimes under a glossy coat; on it
//! spheres and boxes with plain or bitmap albedos, glossy or metal (some metal boxes hammered by
//! a bump map); lit by an area light above and, in some scenes, a small spot or point light.
//!
//! The images are generated here, from the scene's random stream, and written next to
//! `scene.xml` under `textures/`: every pattern tiles seamlessly (periodic noise, whole tiles,
//! bricks and planks per image), one image covering `pattern_size` world units.

use super::front_camera;
use super::lights::add_small_light;
use crate::config::{Config, TexturePattern, TexturedConfig, TexturedLayout};
use crate::rng::{hash_seq, Rng};
use crate::scene::{spherical, Family, GeneratedScene, Material, SceneBuilder};
use crate::xml::{fmt_f32, Element};
use glam::{Vec2, Vec3};
use std::f32::consts::{PI, TAU};

/// Corner layout: half-size of the floor.
const FLOOR: f32 = 1.6;
/// Corner layout: height of the walls.
const WALL_HEIGHT: f32 = 2.4;
/// Table layout: half-sizes of the table top (x, z).
const TABLE: Vec2 = Vec2::new(0.9, 0.55);
/// Table layout: height of the table top above the room's floor.
const TABLE_HEIGHT: f32 = 0.75;
/// Table layout: thickness of the table top.
const TABLE_THICKNESS: f32 = 0.04;

// ---------------------------------------------------------------------------------------------
// Tileable procedural images.

/// Smooth Hermite step from 0 at `e0` to 1 at `e1`.
fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// A hashed value in [0, 1) of the integer point (x, y) of a lattice repeating every
/// `period` cells.
fn lattice(seed: u64, x: i64, y: i64, period: (i64, i64)) -> f32 {
    let h = hash_seq(&[
        seed,
        x.rem_euclid(period.0) as u64,
        y.rem_euclid(period.1) as u64,
    ]);
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Value noise in [0, 1) at (u, v) ∈ [0, 1)², with `period` lattice cells across the image
/// along u and v, so that it tiles.
fn value_noise(seed: u64, u: f32, v: f32, period: (u32, u32)) -> f32 {
    let (x, y) = (u * period.0 as f32, v * period.1 as f32);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let (i, j) = (x0 as i64, y0 as i64);
    let p = (i64::from(period.0), i64::from(period.1));
    let a = lattice(seed, i, j, p) * (1.0 - sx) + lattice(seed, i + 1, j, p) * sx;
    let b = lattice(seed, i, j + 1, p) * (1.0 - sx) + lattice(seed, i + 1, j + 1, p) * sx;
    a * (1.0 - sy) + b * sy
}

/// Fractal sum of `octaves` tileable value noises, the first with `period` cells across,
/// each next one twice as fine and half as strong; in [0, 1).
fn fbm(seed: u64, u: f32, v: f32, period: (u32, u32), octaves: u32) -> f32 {
    let (mut sum, mut total, mut amp) = (0.0, 0.0, 1.0);
    for o in 0..octaves {
        let p = (period.0 << o, period.1 << o);
        sum += amp * value_noise(seed.wrapping_add(u64::from(o)), u, v, p);
        total += amp;
        amp *= 0.5;
    }
    sum / total
}

/// A square image of `n`×`n` texels: linear albedo and height in [0, 1].
struct Texels {
    n: usize,
    albedo: Vec<Vec3>,
    height: Vec<f32>,
}

/// A pattern's colour: the drawn albedo tinted towards the material (wood brown, brick red).
fn tint(pattern: TexturePattern, c: [f32; 3]) -> Vec3 {
    let t = match pattern {
        TexturePattern::Wood => Vec3::new(1.0, 0.68, 0.42),
        TexturePattern::Bricks => Vec3::new(1.0, 0.55, 0.42),
        _ => Vec3::ONE,
    };
    Vec3::from(c) * t
}

/// Generates a tileable image of `pattern` around the albedo `base`.
fn pattern_texels(pattern: TexturePattern, n: usize, base: Vec3, rng: &mut Rng) -> Texels {
    let seed = rng.next_u64();
    let unit = move |k: u64, i: i64, j: i64| lattice(seed ^ k, i, j, (1 << 30, 1 << 30));
    // Per-pattern parameters, drawn once.
    let texel: Box<dyn Fn(f32, f32) -> (Vec3, f32)> = match pattern {
        TexturePattern::Tiles => {
            let k = *rng.pick(&[2u32, 3, 4]) as f32;
            let grout = rng.range([0.02, 0.05]);
            let bevel = rng.range([0.03, 0.08]);
            let grout_color = Vec3::splat(if rng.chance(0.5) {
                rng.range([0.55, 0.8])
            } else {
                rng.range([0.08, 0.25])
            });
            let vary = rng.range([0.05, 0.2]);
            Box::new(move |u, v| {
                let (a, b) = (u * k, v * k);
                let (i, j) = (a.floor() as i64, b.floor() as i64);
                let (fa, fb) = (a - a.floor(), b - b.floor());
                let d = fa.min(1.0 - fa).min(fb).min(1.0 - fb);
                let noise = fbm(seed, u, v, (16, 16), 3);
                if d < grout {
                    (grout_color * (0.9 + 0.2 * noise), 0.1 * noise)
                } else {
                    let r = Vec3::new(unit(1, i, j), unit(2, i, j), unit(3, i, j));
                    let color = base * (Vec3::ONE + vary * (2.0 * r - Vec3::ONE));
                    let rise = smoothstep(grout, grout + bevel, d);
                    (
                        color * (0.93 + 0.14 * noise),
                        0.2 + 0.8 * rise * (0.95 + 0.05 * noise),
                    )
                }
            })
        }
        TexturePattern::Bricks => {
            // Four courses of two bricks (2:1) per image, every other course shifted by half.
            let mortar = rng.range([0.008, 0.015]);
            let bevel = rng.range([0.005, 0.015]);
            let mortar_color = Vec3::splat(rng.range([0.35, 0.7]));
            let vary = rng.range([0.1, 0.3]);
            Box::new(move |u, v| {
                let row = (v * 4.0).floor();
                let x = u + if row as i64 % 2 == 1 { 0.25 } else { 0.0 };
                let col = (x * 2.0).floor();
                let fx = (x * 2.0 - col) / 2.0;
                let fy = (v * 4.0 - row) / 4.0;
                let d = fx.min(0.5 - fx).min(fy).min(0.25 - fy);
                let noise = fbm(seed, u, v, (32, 32), 3);
                if d < mortar {
                    (mortar_color * (0.85 + 0.3 * noise), 0.2 * noise)
                } else {
                    let (i, j) = ((col as i64).rem_euclid(2), row as i64);
                    let r = unit(1, i, j);
                    let color = base * (1.0 + vary * (2.0 * r - 1.0));
                    let rise = smoothstep(mortar, mortar + bevel, d);
                    (
                        color * (0.8 + 0.4 * noise),
                        0.3 + 0.7 * rise * (0.8 + 0.2 * noise),
                    )
                }
            })
        }
        TexturePattern::Wood => {
            // Planks along u, `rows` across the image, each row with one butt joint.
            let rows = rng.range_u32([3, 6]) as f32;
            let seam = rng.range([0.002, 0.004]);
            let bevel = rng.range([0.003, 0.008]);
            let rings = rng.range([3.0, 8.0]);
            Box::new(move |u, v| {
                let row = (v * rows).floor();
                let j = row as i64;
                let x = u + unit(1, 0, j);
                let x = x - x.floor();
                let fy = v * rows - row;
                let d = (fy.min(1.0 - fy) / rows).min(x.min(1.0 - x));
                let shade = 0.8 + 0.4 * unit(2, 0, j);
                let phase = unit(3, 0, j);
                let grain = 0.5
                    + 0.5 * (TAU * (rings * fy + 1.5 * fbm(seed, u, v, (2, 24), 3) + phase)).sin();
                if d < seam {
                    (base * 0.25, 0.0)
                } else {
                    let rise = smoothstep(seam, seam + bevel, d);
                    (
                        base * shade * (0.7 + 0.3 * grain),
                        rise * (0.9 + 0.1 * grain),
                    )
                }
            })
        }
        TexturePattern::Stone => {
            // Veined stone: thin dark veins along a turbulent stripe field.
            let (a, b) = (rng.range_u32([1, 3]) as f32, rng.range_u32([1, 3]) as f32);
            let turbulence = rng.range([0.8, 2.0]);
            Box::new(move |u, v| {
                let t = a * u + b * v + turbulence * fbm(seed, u, v, (4, 4), 5);
                let vein = (1.0 - (PI * t).sin().abs()).powi(8);
                let mottle = fbm(seed ^ 7, u, v, (8, 8), 4);
                let color = base * (0.85 + 0.3 * mottle) * (1.0 - 0.6 * vein);
                (
                    color,
                    0.6 * fbm(seed ^ 9, u, v, (8, 8), 4) + 0.4 * (1.0 - vein),
                )
            })
        }
        TexturePattern::Plaster => Box::new(move |u, v| {
            let h = 0.7 * fbm(seed, u, v, (6, 6), 5) + 0.3 * fbm(seed ^ 3, u, v, (24, 24), 3);
            let mottle = fbm(seed ^ 5, u, v, (4, 4), 3);
            (base * (0.9 + 0.15 * mottle), h)
        }),
    };
    let mut albedo = Vec::with_capacity(n * n);
    let mut height = Vec::with_capacity(n * n);
    for y in 0..n {
        for x in 0..n {
            let (u, v) = ((x as f32 + 0.5) / n as f32, (y as f32 + 0.5) / n as f32);
            let (c, h) = texel(u, v);
            albedo.push(c.clamp(Vec3::ZERO, Vec3::splat(0.95)));
            height.push(h.clamp(0.0, 1.0));
        }
    }
    Texels { n, albedo, height }
}

/// The albedo as an 8-bit sRGB PNG.
fn albedo_png(t: &Texels) -> Vec<u8> {
    let bytes: Vec<u8> = t
        .albedo
        .iter()
        .flat_map(|c| c.to_array().map(fileio::srgb::encode8))
        .collect();
    fileio::png::encode_rgb8(t.n, t.n, &bytes).expect("in-memory PNG encoding")
}

/// The height as a 16-bit grey PNG (read with `raw` = true: the value is the height).
fn height_png(t: &Texels) -> Vec<u8> {
    let data: Vec<u16> = t
        .height
        .iter()
        .map(|h| (h * 65535.0 + 0.5) as u16)
        .collect();
    let img =
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(t.n as u32, t.n as u32, data)
            .expect("n² heights");
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("in-memory PNG encoding");
    out.into_inner()
}

/// The normal map of the heights scaled to `depth` world units over an image covering `size`
/// world units, as an 8-bit PNG of (n + 1)/2 (read with `raw` = true). The normal is in the
/// shading frame (x along u, y along v: the image's columns and rows, z out of the surface):
/// (−∂h/∂x, −∂h/∂y, 1) normalised — the frame a `bumpmap` of the same heights tilts to.
fn normal_png(t: &Texels, size: f32, depth: f32) -> Vec<u8> {
    let n = t.n;
    let at = |x: usize, y: usize| t.height[(y % n) * n + x % n];
    let k = depth / (2.0 * size / n as f32);
    let mut bytes = Vec::with_capacity(n * n * 3);
    for y in 0..n {
        for x in 0..n {
            let dx = (at(x + 1, y) - at(x + n - 1, y)) * k;
            let dy = (at(x, y + 1) - at(x, y + n - 1)) * k;
            let normal = Vec3::new(-dx, -dy, 1.0).normalize();
            bytes.extend(
                normal
                    .to_array()
                    .map(|c| ((c * 0.5 + 0.5) * 255.0 + 0.5) as u8),
            );
        }
    }
    fileio::png::encode_rgb8(n, n, &bytes).expect("in-memory PNG encoding")
}

// ---------------------------------------------------------------------------------------------
// Materials.

/// A `bitmap` texture of `file`, repeated `repeat` times across the shape's uv square.
fn bitmap(name: Option<&str>, file: &str, raw: bool, repeat: Vec2) -> Element {
    let mut e = Element::plugin("texture", "bitmap");
    if let Some(name) = name {
        e = e.attr("name", name);
    }
    e = e.string("filename", file);
    if raw {
        e = e.boolean("raw", true);
    }
    e.child(
        Element::new("transform").attr("name", "to_uv").child(
            Element::new("scale")
                .attr("x", fmt_f32(repeat.x))
                .attr("y", fmt_f32(repeat.y)),
        ),
    )
}

/// How a surface's relief is drawn.
#[derive(Debug, Clone)]
enum Relief {
    /// No relief.
    None,
    /// A `bumpmap` of a height map, heights scaled to `depth` world units.
    Bump { file: String, depth: f32 },
    /// A `normalmap`.
    Normal { file: String },
}

/// The nested reflectance model under a surface's relief.
#[derive(Debug, Clone)]
enum Base {
    /// `diffuse`.
    Diffuse,
    /// A coat over the albedo: `plastic` (α < 0.01) or `roughplastic`.
    Plastic(f32),
    /// A named metal: `conductor` (α < 0.01) or `roughconductor`.
    Metal(String, f32),
}

/// One textured surface: its albedo (an image or a colour), relief and model; one image
/// covers `size` world units.
#[derive(Debug, Clone)]
struct Surface {
    albedo: Result<String, [f32; 3]>,
    relief: Relief,
    base: Base,
    size: f32,
}

impl Surface {
    /// The `<bsdf>` of this surface on a shape whose uv square spans `extent` world units
    /// along u and v (`whole_u`: round the repeats along u to a whole number, for the seam of
    /// a sphere).
    fn material(&self, extent: Vec2, whole_u: bool) -> Material {
        let mut repeat = (extent / self.size).max(Vec2::splat(0.25));
        if whole_u {
            repeat.x = repeat.x.round().max(1.0);
        }
        let color = |e: Element, name: &str| match &self.albedo {
            Ok(file) => e.child(bitmap(Some(name), file, false, repeat)),
            Err(c) => e.rgb(name, *c),
        };
        let inner = match &self.base {
            Base::Diffuse => color(Element::plugin("bsdf", "diffuse"), "reflectance"),
            Base::Plastic(alpha) if *alpha < 0.01 => {
                color(Element::plugin("bsdf", "plastic"), "diffuse_reflectance")
                    .float("int_ior", 1.5)
            }
            Base::Plastic(alpha) => color(
                Element::plugin("bsdf", "roughplastic")
                    .string("distribution", "ggx")
                    .float("alpha", *alpha),
                "diffuse_reflectance",
            )
            .float("int_ior", 1.5),
            Base::Metal(name, alpha) if *alpha < 0.01 => {
                Element::plugin("bsdf", "conductor").string("material", name)
            }
            Base::Metal(name, alpha) => Element::plugin("bsdf", "roughconductor")
                .string("material", name)
                .string("distribution", "ggx")
                .float("alpha", *alpha),
        };
        Material::Xml(match &self.relief {
            Relief::None => inner,
            Relief::Bump { file, depth } => Element::plugin("bsdf", "bumpmap")
                .child(bitmap(None, file, true, repeat))
                .float("scale", *depth)
                .child(inner),
            Relief::Normal { file } => Element::plugin("bsdf", "normalmap")
                .child(bitmap(Some("normalmap"), file, true, repeat))
                .child(inner),
        })
    }
}

/// Generates the images of a `pattern` surface named `name` (files `textures/<name>_*.png`):
/// its albedo and, when `relief`, a normal map (with probability `normalmap_probability`) or a
/// height map for a bump map.
fn textured_surface(
    b: &mut SceneBuilder,
    rng: &mut Rng,
    c: &TexturedConfig,
    name: &str,
    pattern: TexturePattern,
    relief: bool,
    base: Base,
) -> Surface {
    let n = rng.range_u32(c.texture_size) as usize;
    let size = rng.range(c.pattern_size);
    let color = tint(pattern, rng.color(c.albedo));
    let depth = rng.range(c.bump_depth);
    let normal = rng.chance(c.normalmap_probability);
    let texels = pattern_texels(pattern, n, color, rng);
    let albedo = format!("textures/{name}_albedo.png");
    b.image(&albedo, albedo_png(&texels));
    let relief = if !relief {
        Relief::None
    } else if normal {
        let file = format!("textures/{name}_normal.png");
        b.image(&file, normal_png(&texels, size, depth));
        Relief::Normal { file }
    } else {
        let file = format!("textures/{name}_height.png");
        b.image(&file, height_png(&texels));
        Relief::Bump { file, depth }
    };
    Surface {
        albedo: Ok(albedo),
        relief,
        base,
        size,
    }
}

/// A hammered metal: a plaster height field as a bump map (file `textures/<name>_height.png`)
/// over a rough or smooth conductor.
fn hammered_metal(
    b: &mut SceneBuilder,
    rng: &mut Rng,
    c: &TexturedConfig,
    name: &str,
    metal: Base,
) -> Surface {
    let n = rng.range_u32(c.texture_size) as usize;
    let size = rng.range(c.pattern_size);
    let depth = 0.5 * rng.range(c.bump_depth);
    let texels = pattern_texels(TexturePattern::Plaster, n, Vec3::ONE, rng);
    let file = format!("textures/{name}_height.png");
    b.image(&file, height_png(&texels));
    Surface {
        albedo: Err([1.0; 3]),
        relief: Relief::Bump { file, depth },
        base: metal,
        size,
    }
}

// ---------------------------------------------------------------------------------------------
// The scene.

/// Generates one textured scene.
pub fn generate(config: &Config, c: &TexturedConfig, rng: &mut Rng, id: String) -> GeneratedScene {
    let mut b = SceneBuilder::new(config);
    let layout = *rng.pick(&c.layouts);
    let floor_pattern = *rng.pick(&c.floor_patterns);
    let wall_pattern = *rng.pick(&c.wall_patterns);
    let floor_base = if rng.chance(c.glossy_floor_probability) {
        Base::Plastic(rng.range(c.alpha))
    } else {
        Base::Diffuse
    };
    let floor = textured_surface(&mut b, rng, c, "floor", floor_pattern, true, floor_base);
    let wall = textured_surface(&mut b, rng, c, "wall", wall_pattern, true, Base::Diffuse);
    let describe = |s: &Surface, pattern: TexturePattern| {
        let relief = match s.relief {
            Relief::Bump { .. } => "bump map",
            Relief::Normal { .. } => "normal map",
            Relief::None => "flat",
        };
        let coat = match s.base {
            Base::Plastic(_) => ", glossy",
            _ => "",
        };
        format!("{pattern:?} ({relief}{coat})").to_lowercase()
    };
    let mut notes = vec![
        format!("{layout:?}").to_lowercase(),
        format!(
            "{} {}",
            match layout {
                TexturedLayout::Corner => "floor",
                TexturedLayout::Table => "table top",
            },
            describe(&floor, floor_pattern)
        ),
        format!("wall {}", describe(&wall, wall_pattern)),
    ];

    // The surfaces, and the region the objects stand in: centre and half-sizes.
    let rect = |b: &mut SceneBuilder, s: &Surface, centre: Vec3, u: Vec3, v: Vec3| {
        let m = s.material(Vec2::new(2.0 * u.length(), 2.0 * v.length()), false);
        b.rectangle(centre, u, v, &m, None);
    };
    let (centre, bounds, wall_side) = match layout {
        TexturedLayout::Corner => {
            // Floor, the back wall (z = −FLOOR) and one side wall; u horizontal and v pointing
            // down on the walls, so courses of bricks and tiles run level.
            rect(
                &mut b,
                &floor,
                Vec3::ZERO,
                Vec3::X * FLOOR,
                -Vec3::Z * FLOOR,
            );
            let h = WALL_HEIGHT / 2.0;
            rect(
                &mut b,
                &wall,
                Vec3::new(0.0, h, -FLOOR),
                -Vec3::X * FLOOR,
                -Vec3::Y * h,
            );
            let side = if rng.chance(0.5) { -1.0 } else { 1.0 };
            rect(
                &mut b,
                &wall,
                Vec3::new(side * FLOOR, h, 0.0),
                Vec3::Z * (-side) * FLOOR,
                -Vec3::Y * h,
            );
            (
                Vec3::new(side * 0.35 * FLOOR, 0.0, -0.35 * FLOOR),
                Vec2::splat(FLOOR - 0.1),
                Some(side),
            )
        }
        TexturedLayout::Table => {
            rect(
                &mut b,
                &floor,
                Vec3::ZERO,
                Vec3::X * TABLE.x,
                -Vec3::Z * TABLE.y,
            );
            let edge = Material::Diffuse(rng.color([0.05, 0.3]));
            b.cube(
                Vec3::new(0.0, -TABLE_THICKNESS / 2.0 - 0.001, 0.0),
                Vec3::new(TABLE.x, TABLE_THICKNESS / 2.0, TABLE.y),
                0.0,
                &edge,
            );
            let leg = (TABLE_HEIGHT - TABLE_THICKNESS) / 2.0;
            for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
                b.cube(
                    Vec3::new(
                        sx * (TABLE.x - 0.08),
                        -TABLE_THICKNESS - leg - 0.001,
                        sz * (TABLE.y - 0.08),
                    ),
                    Vec3::new(0.03, leg, 0.03),
                    0.0,
                    &edge,
                );
            }
            b.rectangle(
                Vec3::Y * -TABLE_HEIGHT,
                Vec3::Z * 4.0,
                Vec3::X * 4.0,
                &Material::Diffuse(rng.color([0.15, 0.5])),
                None,
            );
            let back = -TABLE.y - rng.range([0.1, 0.5]);
            let (bottom, top) = (-TABLE_HEIGHT, WALL_HEIGHT - TABLE_HEIGHT);
            rect(
                &mut b,
                &wall,
                Vec3::new(0.0, (bottom + top) / 2.0, back),
                -Vec3::X * 3.0,
                -Vec3::Y * ((top - bottom) / 2.0),
            );
            (Vec3::new(0.0, 0.0, -0.1), TABLE - Vec2::splat(0.05), None)
        }
    };

    let n = rng.range_u32(c.objects);
    let mut placed: Vec<(Vec3, f32)> = Vec::new();
    for k in 0..n {
        let s = rng.range(c.object_size);
        let sphere = rng.chance(0.5);
        let spread = 0.25 + 0.2 * n as f32;
        let mut pos = centre;
        for _ in 0..48 {
            let (a, d) = (rng.range([0.0, TAU]), spread * rng.uniform().sqrt() as f32);
            pos = centre + Vec3::new(a.cos() * d, 0.0, a.sin() * d);
            pos.x = pos.x.clamp(-bounds.x + 1.42 * s, bounds.x - 1.42 * s);
            pos.z = pos.z.clamp(-bounds.y + 1.42 * s, bounds.y - 1.42 * s);
            if placed
                .iter()
                .all(|(p, r)| p.distance(pos) > r + 1.42 * s + 0.02)
            {
                break;
            }
        }
        placed.push((pos, 1.42 * s));
        let name = format!("object{k}");
        let surface = if rng.chance(c.metal_probability) {
            let metal = Base::Metal(rng.pick(&c.metals).clone(), rng.range(c.alpha));
            if !sphere && rng.chance(0.5) {
                hammered_metal(&mut b, rng, c, &name, metal)
            } else {
                Surface {
                    albedo: Err([1.0; 3]),
                    relief: Relief::None,
                    base: metal,
                    size: 1.0,
                }
            }
        } else {
            let base = if rng.chance(c.glossy_probability) {
                Base::Plastic(rng.range(c.alpha))
            } else {
                Base::Diffuse
            };
            if rng.chance(c.texture_probability) {
                let pattern = *rng.pick(&c.object_patterns);
                // Reliefs on boxes only: a sphere's uvs pinch at its poles.
                let relief = !sphere && rng.chance(0.5);
                textured_surface(&mut b, rng, c, &name, pattern, relief, base)
            } else {
                Surface {
                    albedo: Err(rng.color(c.albedo)),
                    relief: Relief::None,
                    base,
                    size: 1.0,
                }
            }
        };
        if sphere {
            // u runs round the sphere (2πr), v from pole to pole (πr).
            let m = surface.material(Vec2::new(TAU * s, PI * s), true);
            b.sphere(pos + Vec3::Y * (s + 0.001), s, &m);
        } else {
            let half = Vec3::new(s, s * rng.range([0.5, 1.2]), s * rng.range([0.5, 1.0]));
            let m = surface.material(Vec2::splat(2.0 * s), false);
            b.cube(
                pos + Vec3::Y * (half.y + 0.001),
                half,
                rng.range([0.0, 360.0]),
                &m,
            );
        }
        let relief = match surface.relief {
            Relief::None => "",
            Relief::Bump { .. } => " bump-mapped",
            Relief::Normal { .. } => " normal-mapped",
        };
        let albedo = if surface.albedo.is_ok() {
            " textured"
        } else {
            ""
        };
        let model = match &surface.base {
            Base::Diffuse => "diffuse".to_owned(),
            Base::Plastic(_) => "glossy".to_owned(),
            Base::Metal(m, _) => m.clone(),
        };
        let shape = if sphere { "sphere" } else { "box" };
        notes.push(format!("{model}{albedo}{relief} {shape}"));
    }

    let objects = placed.iter().map(|(p, _)| *p).sum::<Vec3>() / placed.len().max(1) as f32;
    let target = if placed.is_empty() { centre } else { objects };
    let light = target
        + Vec3::new(
            rng.range([-0.4, 0.4]),
            rng.range(c.light_height),
            rng.range([-0.4, 0.4]),
        );
    b.area_light(
        light,
        Vec3::new(light.x, 0.0, light.z) + Vec3::X * 0.01,
        rng.range(c.light_size),
        rng.range(c.light_power),
    );
    if rng.chance(c.small_light_probability) {
        let kind = *rng.pick(&c.small_lights);
        let dir = spherical(rng.range([30.0, 150.0]), rng.range([30.0, 60.0]));
        let mut pos = target + dir * rng.range([1.0, 1.8]);
        if layout == TexturedLayout::Corner {
            pos.x = pos.x.clamp(-FLOOR + 0.1, FLOOR - 0.1);
        }
        let watts = rng.range(c.small_light_power);
        add_small_light(&mut b, rng, kind, pos, target, [0.03, 0.08], watts);
        notes.push(format!("{kind:?} light").to_lowercase());
    }
    b.environment(rng.range(c.env_radiance));

    let look_at = target + Vec3::Y * 0.2;
    match wall_side {
        // Looking into the corner: from the open side, away from the side wall.
        Some(side) => {
            let azimuth = if side < 0.0 {
                rng.range([40.0, 80.0])
            } else {
                rng.range([100.0, 140.0])
            };
            let eye = look_at
                + spherical(azimuth, rng.range(c.camera_elevation)) * rng.range(c.camera_distance);
            b.camera(eye, look_at, rng.range(c.fov), None);
        }
        None => front_camera(
            &mut b,
            rng,
            look_at,
            c.camera_elevation,
            c.camera_distance,
            c.fov,
        ),
    }
    b.finish(
        id,
        Family::Textured,
        &format!("textured: {}, generated by datagen", notes.join(", ")),
    )
}
