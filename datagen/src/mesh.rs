//! Procedural meshes for the scene families: surfaces of revolution (wine glasses, vases,
//! metal rings, curved mirrors), height fields (water) and displaced spheres (blobs).

use crate::ply::Mesh;
use crate::rng::Rng;
use glam::{Vec2, Vec3};
use std::f32::consts::TAU;

/// One point of a lathe profile: radius from the y axis, height, and whether the surface has a
/// crease there (the vertex is split so both sides keep their own normal).
#[derive(Debug, Clone, Copy)]
pub struct ProfilePoint {
    /// Distance from the axis (≥ 0).
    pub r: f32,
    /// Height along +y.
    pub y: f32,
    /// A crease (e.g. a rim or a base edge).
    pub sharp: bool,
}

/// Shorthand for a smooth profile point.
pub fn smooth(r: f32, y: f32) -> ProfilePoint {
    ProfilePoint { r, y, sharp: false }
}

/// Shorthand for a creased profile point.
pub fn sharp(r: f32, y: f32) -> ProfilePoint {
    ProfilePoint { r, y, sharp: true }
}

/// Pushes a triangle wound so that its geometric normal agrees with the vertex normals.
fn push_oriented(mesh: &mut Mesh, t: [u32; 3]) {
    let p = |i: u32| mesh.positions[i as usize];
    let face = (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0]));
    if face.length_squared() < 1e-20 {
        return; // degenerate (e.g. at the axis)
    }
    let n = mesh.normals[t[0] as usize] + mesh.normals[t[1] as usize] + mesh.normals[t[2] as usize];
    if face.dot(n) >= 0.0 {
        mesh.triangles.push(t);
    } else {
        mesh.triangles.push([t[0], t[2], t[1]]);
    }
}

/// A surface of revolution about +y. The profile is traversed so that the surface's outside
/// lies to the right of the direction of travel in the (r, y) plane (e.g. outward along the
/// bottom, up the outside, back down the inside). `sweep` is the angle range in radians;
/// a partial sweep gets flat end caps (the profile must then be a convex closed polygon).
pub fn lathe(profile: &[ProfilePoint], segments: u32, sweep: Option<(f32, f32)>) -> Mesh {
    let n = profile.len();
    // Per profile segment, its outward 2D normal (right-hand side of travel).
    let seg_normal = |i: usize| {
        let d = Vec2::new(
            profile[i + 1].r - profile[i].r,
            profile[i + 1].y - profile[i].y,
        );
        Vec2::new(d.y, -d.x).normalize_or_zero()
    };
    // Split creased points into two rings of vertices (incoming and outgoing normal).
    let mut rings: Vec<(Vec2, Vec2)> = Vec::new(); // (r,y), normal(nr, ny)
    let mut ring_of_segment_start: Vec<usize> = Vec::new();
    let mut ring_of_segment_end: Vec<usize> = Vec::new();
    for (i, point) in profile.iter().enumerate() {
        let pos = Vec2::new(point.r, point.y);
        let before = (i > 0).then(|| seg_normal(i - 1));
        let after = (i + 1 < n).then(|| seg_normal(i));
        match (before, after) {
            (Some(b), Some(a)) if point.sharp => {
                ring_of_segment_end.push(rings.len());
                rings.push((pos, b));
                ring_of_segment_start.push(rings.len());
                rings.push((pos, a));
            }
            (b, a) => {
                let nrm = (b.unwrap_or(Vec2::ZERO) + a.unwrap_or(Vec2::ZERO)).normalize_or_zero();
                if b.is_some() {
                    ring_of_segment_end.push(rings.len());
                }
                if a.is_some() {
                    ring_of_segment_start.push(rings.len());
                }
                rings.push((pos, nrm));
            }
        }
    }
    let full = sweep.is_none();
    let (a0, a1) = sweep.unwrap_or((0.0, TAU));
    let columns = if full { segments } else { segments + 1 };
    let mut mesh = Mesh::default();
    for &(p, nrm) in &rings {
        for j in 0..columns {
            let phi = a0 + (a1 - a0) * j as f32 / segments as f32;
            let (s, c) = phi.sin_cos();
            mesh.positions.push(Vec3::new(p.x * c, p.y, p.x * s));
            mesh.normals
                .push(Vec3::new(nrm.x * c, nrm.y, nrm.x * s).normalize_or(Vec3::Y));
        }
    }
    let idx = |ring: usize, j: u32| ring as u32 * columns + (j % columns);
    for s in 0..n - 1 {
        let (r0, r1) = (ring_of_segment_start[s], ring_of_segment_end[s]);
        for j in 0..segments {
            let (a, b, c, d) = (idx(r0, j), idx(r0, j + 1), idx(r1, j), idx(r1, j + 1));
            push_oriented(&mut mesh, [a, b, d]);
            push_oriented(&mut mesh, [a, d, c]);
        }
    }
    if !full {
        for (phi, outward_sign) in [(a0, -1.0f32), (a1, 1.0f32)] {
            let (s, c) = phi.sin_cos();
            // Cap normal: the tangent of the sweep direction at this angle.
            let normal = Vec3::new(-s, 0.0, c) * outward_sign;
            let base = mesh.positions.len() as u32;
            for p in profile {
                mesh.positions.push(Vec3::new(p.r * c, p.y, p.r * s));
                mesh.normals.push(normal);
            }
            for k in 1..n as u32 - 1 {
                push_oriented(&mut mesh, [base, base + k, base + k + 1]);
            }
        }
    }
    mesh
}

/// Random travelling-wave parameters of a water surface.
#[derive(Debug, Clone)]
pub struct Waves {
    /// (direction × wavenumber, amplitude, phase) per wave.
    pub waves: Vec<(Vec2, f32, f32)>,
}

impl Waves {
    /// Height at (x, z).
    pub fn height(&self, x: f32, z: f32) -> f32 {
        self.waves
            .iter()
            .map(|(k, a, ph)| a * (k.x * x + k.y * z + ph).sin())
            .sum()
    }

    /// Gradient (dh/dx, dh/dz) at (x, z).
    pub fn gradient(&self, x: f32, z: f32) -> Vec2 {
        self.waves
            .iter()
            .map(|(k, a, ph)| *k * (a * (k.x * x + k.y * z + ph).cos()))
            .sum()
    }
}

/// A height-field sheet y = waves(x, z) over [-half_x, half_x] × [-half_z, half_z], normals up.
pub fn height_field(waves: &Waves, half_x: f32, half_z: f32, resolution: u32) -> Mesh {
    let n = resolution.max(2);
    let mut mesh = Mesh::default();
    for i in 0..=n {
        for j in 0..=n {
            let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
            let (x, z) = ((2.0 * u - 1.0) * half_x, (2.0 * v - 1.0) * half_z);
            let g = waves.gradient(x, z);
            mesh.positions.push(Vec3::new(x, waves.height(x, z), z));
            mesh.normals.push(Vec3::new(-g.x, 1.0, -g.y).normalize());
            mesh.uvs.push(Vec2::new(u, v));
        }
    }
    let idx = |i: u32, j: u32| i * (n + 1) + j;
    for i in 0..n {
        for j in 0..n {
            push_oriented(&mut mesh, [idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
            push_oriented(&mut mesh, [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
    mesh
}

/// A closed blob: a unit-radius sphere displaced by a few random smooth lobes, scaled to
/// `radius`. Normals are area-weighted averages of the faces around each vertex.
pub fn blob(rng: &mut Rng, radius: f32, lobes: u32, bumpiness: f32, rings: u32) -> Mesh {
    let lobe_dirs: Vec<(Vec3, f32, f32)> = (0..lobes)
        .map(|_| {
            let z = rng.range([-1.0, 1.0]);
            let phi = rng.range([0.0, TAU]);
            let s = (1.0 - z * z).max(0.0).sqrt();
            let dir = Vec3::new(s * phi.cos(), z, s * phi.sin());
            (
                dir,
                rng.range([-bumpiness, bumpiness]),
                rng.range([1.5, 3.0]),
            )
        })
        .collect();
    let displace = |d: Vec3| {
        let bump: f32 = lobe_dirs
            .iter()
            .map(|(c, a, sharpness)| a * (sharpness * (d.dot(*c) - 1.0)).exp())
            .sum();
        d * radius * (1.0 + bump).max(0.3)
    };
    let segments = rings * 2;
    let mut mesh = Mesh::default();
    // Poles are single vertices; latitude rings in between.
    mesh.positions.push(displace(Vec3::NEG_Y));
    for i in 1..rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..segments {
            let phi = TAU * j as f32 / segments as f32;
            let d = Vec3::new(
                theta.sin() * phi.cos(),
                -theta.cos(),
                theta.sin() * phi.sin(),
            );
            mesh.positions.push(displace(d));
        }
    }
    mesh.positions.push(displace(Vec3::Y));
    let top = mesh.positions.len() as u32 - 1;
    let ring = |i: u32, j: u32| 1 + (i - 1) * segments + (j % segments);
    let mut tris = Vec::new();
    for j in 0..segments {
        tris.push([0, ring(1, j + 1), ring(1, j)]);
        tris.push([top, ring(rings - 1, j), ring(rings - 1, j + 1)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segments {
            tris.push([ring(i, j), ring(i, j + 1), ring(i + 1, j + 1)]);
            tris.push([ring(i, j), ring(i + 1, j + 1), ring(i + 1, j)]);
        }
    }
    // Make the winding face outwards (positive enclosed volume), then derive normals from it.
    let probe = Mesh {
        positions: mesh.positions.clone(),
        triangles: tris.clone(),
        ..Mesh::default()
    };
    if signed_volume(&probe) < 0.0 {
        for t in &mut tris {
            t.swap(1, 2);
        }
    }
    let mut normals = vec![Vec3::ZERO; mesh.positions.len()];
    for t in &tris {
        let p = |k: usize| mesh.positions[t[k] as usize];
        let face = (p(1) - p(0)).cross(p(2) - p(0));
        for &k in t {
            normals[k as usize] += face;
        }
    }
    mesh.normals = normals
        .into_iter()
        .map(|n| n.normalize_or(Vec3::Y))
        .collect();
    mesh.triangles = tris;
    mesh
}

/// The signed volume enclosed by a closed mesh (positive when triangles face outwards).
pub fn signed_volume(mesh: &Mesh) -> f32 {
    mesh.triangles
        .iter()
        .map(|t| {
            let p = |k: usize| mesh.positions[t[k] as usize];
            p(0).dot(p(1).cross(p(2))) / 6.0
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lathe_cylinder_volume_and_outward_orientation() {
        // Closed cylinder of radius 1, height 2: bottom disk, side, top disk.
        let profile = [
            sharp(0.0, 0.0),
            sharp(1.0, 0.0),
            sharp(1.0, 2.0),
            sharp(0.0, 2.0),
        ];
        let mesh = lathe(&profile, 256, None);
        let v = signed_volume(&mesh);
        let exact = std::f32::consts::PI * 2.0;
        assert!((v - exact).abs() / exact < 1e-3, "{v}");
        // Side vertices' normals are horizontal and point away from the axis.
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            if p.y > 0.5 && p.y < 1.5 {
                assert!(n.y.abs() < 1e-5 && n.dot(Vec3::new(p.x, 0.0, p.z)) > 0.0);
            }
        }
    }

    #[test]
    fn partial_lathe_ring_sector_is_closed() {
        // A quarter of an annular ring (r 1..1.2, height 0.5): volume = quarter of the annulus.
        let profile = [
            sharp(1.0, 0.0),
            sharp(1.2, 0.0),
            sharp(1.2, 0.5),
            sharp(1.0, 0.5),
            sharp(1.0, 0.0),
        ];
        let mesh = lathe(&profile, 128, Some((0.0, std::f32::consts::FRAC_PI_2)));
        let exact = std::f32::consts::PI * (1.44 - 1.0) * 0.5 / 4.0;
        let v = signed_volume(&mesh);
        assert!((v - exact).abs() / exact < 2e-3, "{v} vs {exact}");
    }

    #[test]
    fn blob_is_closed_and_outward() {
        let mut rng = Rng::new(5);
        let mesh = blob(&mut rng, 1.0, 0, 0.0, 64);
        let v = signed_volume(&mesh);
        let exact = 4.0 / 3.0 * std::f32::consts::PI;
        assert!((v - exact).abs() / exact < 5e-3, "{v}");
    }

    /// `Waves::gradient` equals the hand-written closed form Σ a·k·cos(k·p + φ) and a central
    /// finite difference of `Waves::height`, and the height field's positions and normals are
    /// y = Σ a·sin(k·p + φ) and (−∂h/∂x, 1, −∂h/∂z) normalised, from the closed form.
    #[test]
    fn height_field_normals_match_gradient() {
        // Two waves, one oblique, so both gradient components and both wave-vector components
        // of each wave matter (a swapped component or a missing factor k shows).
        let spec = [
            ((2.0f64, 0.0f64), 0.1f64, 0.3f64),
            ((0.7, -1.3), 0.05, -0.8),
        ];
        let waves = Waves {
            waves: spec
                .iter()
                .map(|&((kx, kz), a, ph)| (Vec2::new(kx as f32, kz as f32), a as f32, ph as f32))
                .collect(),
        };
        let height = |x: f64, z: f64| -> f64 {
            spec.iter()
                .map(|&((kx, kz), a, ph)| a * (kx * x + kz * z + ph).sin())
                .sum()
        };
        let gradient = |x: f64, z: f64| -> (f64, f64) {
            spec.iter()
                .map(|&((kx, kz), a, ph)| {
                    let c = a * (kx * x + kz * z + ph).cos();
                    (kx * c, kz * c)
                })
                .fold((0.0, 0.0), |s, g| (s.0 + g.0, s.1 + g.1))
        };
        // The gradient against the closed form and a central difference of `height`.
        let step = 1e-2f32;
        for i in 0..=10 {
            for j in 0..=10 {
                let (x, z) = (-1.0 + 0.2 * i as f32, -1.0 + 0.2 * j as f32);
                let g = waves.gradient(x, z);
                let (gx, gz) = gradient(f64::from(x), f64::from(z));
                assert!(
                    (f64::from(g.x) - gx).abs() < 1e-6 && (f64::from(g.y) - gz).abs() < 1e-6,
                    "gradient at ({x}, {z}) = {g}, closed form ({gx}, {gz})"
                );
                let fd = Vec2::new(
                    (waves.height(x + step, z) - waves.height(x - step, z)) / (2.0 * step),
                    (waves.height(x, z + step) - waves.height(x, z - step)) / (2.0 * step),
                );
                assert!(
                    (g - fd).abs().max_element() < 1e-3,
                    "gradient at ({x}, {z}) = {g}, central difference of height {fd}"
                );
            }
        }
        let mesh = height_field(&waves, 1.0, 1.0, 8);
        assert_eq!(mesh.positions.len(), 81);
        for (k, (p, n)) in mesh.positions.iter().zip(&mesh.normals).enumerate() {
            let (x, z) = (f64::from(p.x), f64::from(p.z));
            let (gx, gz) = gradient(x, z);
            let len = (gx * gx + 1.0 + gz * gz).sqrt();
            let expect = Vec3::new((-gx / len) as f32, (1.0 / len) as f32, (-gz / len) as f32);
            assert!(
                (*n - expect).length() < 1e-5,
                "vertex {k} at {p}: normal {n}, want {expect}"
            );
            assert!(
                (f64::from(p.y) - height(x, z)).abs() < 1e-6,
                "vertex {k} at {p}: height {}, want {}",
                p.y,
                height(x, z)
            );
        }
        assert_eq!(mesh.triangles.len(), 2 * 64);
        // All faces point up.
        for t in &mesh.triangles {
            let p = |k: usize| mesh.positions[t[k] as usize];
            assert!(
                (p(1) - p(0)).cross(p(2) - p(0)).y > 0.0,
                "triangle {t:?} faces down"
            );
        }
    }
}
