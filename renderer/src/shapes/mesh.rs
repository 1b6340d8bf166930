//! Triangle meshes: Möller–Trumbore intersection, interpolated shading normals and uvs
//! (barycentric uvs when the mesh has none, as Mitsuba), area sampling.

use super::{AreaSample, HitGeometry};
use crate::description::TriangleMesh;
use crate::math::{coordinate_system, Ray};
use crate::sampling::{square_to_uniform_triangle, Distribution1D};
use glam::{Vec2, Vec3, Vec3A};

/// A world-space triangle mesh with its triangle-area distribution.
#[derive(Debug, Clone)]
pub struct Mesh {
    /// The mesh data.
    pub data: TriangleMesh,
    /// Triangle selection proportional to area.
    area_distribution: Distribution1D,
    /// Total area.
    area: f32,
    /// Unit geometric normal of each triangle (winding order), precomputed for shading and
    /// light sampling.
    face_normals: Vec<Vec3>,
    /// Vertex normals to interpolate, or `None` when the mesh has none or when every vertex
    /// normal equals its triangle's face normal within [`FLAT_TOLERANCE`] (flat-shaded exports
    /// carry such normals): the shading normal is then the face normal, without the
    /// interpolation and normalisation per hit and per light sample.
    smooth: bool,
}

/// Largest per-component difference between a vertex normal and its face normal for which a
/// mesh counts as flat-shaded (the interpolated normal then differs from the face normal by
/// less than single-precision noise on a unit vector's normalisation).
const FLAT_TOLERANCE: f32 = 1e-6;

/// Distance along a ray to triangle (p0, p0 + e1, p0 + e2), or +∞ when missed (Möller–Trumbore,
/// both sides), with the hit's barycentric coordinates (b1, b2) (the same values
/// [`Mesh::hit_geometry`] would recompute; meaningless on a miss).
#[inline(always)]
pub fn intersect_triangle_bary(
    o: Vec3A,
    d: Vec3A,
    tmin: f32,
    tmax: f32,
    p0: Vec3A,
    e1: Vec3A,
    e2: Vec3A,
) -> (f32, Vec2) {
    // Every quantity is computed before one combined test: with incoherent rays the early
    // outs of the textbook form mispredict more often than they save arithmetic. The tests are
    // made on the numerators against |det|, so only a hit pays for the division.
    let pvec = d.cross(e2);
    let det = e1.dot(pvec);
    let tvec = o - p0;
    let qvec = tvec.cross(e1);
    let sign = det.signum();
    let adet = det.abs();
    let u = tvec.dot(pvec) * sign;
    let v = d.dot(qvec) * sign;
    let t = e2.dot(qvec) * sign;
    // Non-short-circuit `&`: a single branch. A NaN (degenerate triangle) fails every test.
    let hit = (adet >= 1e-12) & (u >= 0.0) & (v >= 0.0) & (u + v <= adet) & (t > tmin * adet);
    if !hit {
        return (f32::INFINITY, Vec2::ZERO);
    }
    let inv = 1.0 / adet;
    let (t, u, v) = (t * inv, u * inv, v * inv);
    (
        if t > tmin && t < tmax {
            t
        } else {
            f32::INFINITY
        },
        Vec2::new(u, v),
    )
}
/// Barycentric coordinates (b1, b2) of the hit of `ray` with a triangle.
#[inline]
fn barycentrics(ray: &Ray, p0: Vec3, p1: Vec3, p2: Vec3) -> Vec2 {
    let (e1, e2) = (p1 - p0, p2 - p0);
    let pvec = ray.d.cross(e2);
    let inv = 1.0 / e1.dot(pvec);
    let tvec = ray.o - p0;
    let u = tvec.dot(pvec) * inv;
    let v = ray.d.dot(tvec.cross(e1)) * inv;
    clamp_barycentrics(Vec2::new(u, v))
}

/// Barycentrics (b1, b2) clamped into the triangle (rounding can put a hit just outside).
#[inline]
fn clamp_barycentrics(b: Vec2) -> Vec2 {
    let u = b.x.clamp(0.0, 1.0);
    Vec2::new(u, b.y.clamp(0.0, 1.0 - u))
}

impl Mesh {
    /// Wraps a copy of mesh data and precomputes its area distribution.
    pub fn new(data: &TriangleMesh) -> Self {
        Self::from_data(data.clone())
    }

    /// Wraps mesh data (without copying it) and precomputes its area distribution.
    pub fn from_data(data: TriangleMesh) -> Self {
        let areas: Vec<f32> = (0..data.indices.len())
            .map(|i| {
                let [a, b, c] = Self::corners(&data, i as u32);
                0.5 * (b - a).cross(c - a).length()
            })
            .collect();
        let area = areas.iter().map(|&a| a as f64).sum::<f64>() as f32;
        let side = if data.flipped { -1.0 } else { 1.0 };
        let face_normals = (0..data.indices.len())
            .map(|i| {
                let [p0, p1, p2] = Self::corners(&data, i as u32);
                side * (p1 - p0).cross(p2 - p0).normalize_or(Vec3::Z)
            })
            .collect::<Vec<Vec3>>();
        let smooth = data.normals.as_ref().is_some_and(|n| {
            data.indices.iter().zip(&face_normals).any(|(tri, ng)| {
                tri.iter()
                    .any(|&v| (n[v as usize] - *ng).abs().max_element() > FLAT_TOLERANCE)
            })
        });
        Mesh {
            data,
            area_distribution: Distribution1D::new(&areas),
            area,
            face_normals,
            smooth,
        }
    }

    /// The vertex normals to interpolate (`None`: use the face normal, see `smooth`).
    #[inline]
    fn vertex_normals(&self) -> Option<&[Vec3]> {
        self.data.normals.as_deref().filter(|_| self.smooth)
    }

    #[inline]
    fn corners(data: &TriangleMesh, tri: u32) -> [Vec3; 3] {
        let [a, b, c] = data.indices[tri as usize];
        [
            data.positions[a as usize],
            data.positions[b as usize],
            data.positions[c as usize],
        ]
    }

    /// The normals the surface has: its faces' (degenerate ones left out) and, where shading
    /// interpolates them, its vertex normals.
    pub fn normals(&self) -> impl Iterator<Item = Vec3> + Clone + '_ {
        let faces = (0..self.data.indices.len())
            .filter(|&i| {
                let [a, b, c] = Self::corners(&self.data, i as u32);
                (b - a).cross(c - a) != Vec3::ZERO
            })
            .map(|i| self.face_normals[i]);
        let vertices = self.vertex_normals().unwrap_or(&[]).iter();
        faces.chain(vertices.filter_map(|n| n.try_normalize()))
    }

    /// The normals shading can have on triangle `tri`: its face normal and, where shading
    /// interpolates them, its vertex normals.
    pub fn triangle_normals(&self, tri: u32) -> impl Iterator<Item = Vec3> + Clone + '_ {
        let [a, b, c] = self.data.indices[tri as usize];
        let vertices = self
            .vertex_normals()
            .map(|n| [n[a as usize], n[b as usize], n[c as usize]]);
        std::iter::once(self.face_normals[tri as usize]).chain(
            vertices
                .into_iter()
                .flatten()
                .filter_map(|n| n.try_normalize()),
        )
    }

    /// Area of triangle `tri`.
    #[inline]
    pub fn triangle_area(&self, tri: u32) -> f32 {
        let [a, b, c] = self.triangle(tri);
        0.5 * (b - a).cross(c - a).length()
    }

    /// Vertex positions of triangle `tri`.
    #[inline]
    pub fn triangle(&self, tri: u32) -> [Vec3; 3] {
        Self::corners(&self.data, tri)
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.data.indices.len()
    }

    /// Total surface area.
    pub fn area(&self) -> f32 {
        self.area
    }

    /// Bounding box of triangle `tri`.
    pub fn triangle_bounds(&self, tri: u32) -> (Vec3A, Vec3A) {
        let [a, b, c] = self.triangle(tri);
        (Vec3A::from(a.min(b).min(c)), Vec3A::from(a.max(b).max(c)))
    }

    /// Shading data at the hit of `ray` with triangle `tri` (distance `t`).
    pub fn hit_geometry(&self, tri: u32, ray: &Ray, t: f32) -> HitGeometry {
        let [p0, p1, p2] = self.triangle(tri);
        self.hit_geometry_bary(tri, ray, t, barycentrics(ray, p0, p1, p2))
    }

    /// [`Self::hit_geometry`] with the barycentrics `b` the intersection test already found.
    #[inline]
    pub fn hit_geometry_bary(&self, tri: u32, ray: &Ray, t: f32, b: Vec2) -> HitGeometry {
        let b = clamp_barycentrics(b);
        let [i0, i1, i2] = self.data.indices[tri as usize];
        let [p0, p1, p2] = self.triangle(tri);
        let b0 = 1.0 - b.x - b.y;
        let p = ray.at(t);
        let (e1, e2) = (p1 - p0, p2 - p0);
        let ng = self.face_normals[tri as usize];
        let ns = match self.vertex_normals() {
            Some(n) => {
                (n[i0 as usize] * b0 + n[i1 as usize] * b.x + n[i2 as usize] * b.y).normalize_or(ng)
            }
            None => ng,
        };
        // Mitsuba's parameterisation: by the texture coordinates when the mesh has them (an
        // arbitrary basis where they are degenerate), else barycentric.
        let (uv, dpdu, dpdv) = match &self.data.uvs {
            Some(uv) => {
                let (t0, t1, t2) = (uv[i0 as usize], uv[i1 as usize], uv[i2 as usize]);
                let (d1, d2) = (t1 - t0, t2 - t0);
                let det = d1.x * d2.y - d1.y * d2.x;
                let (dpdu, dpdv) = if det != 0.0 {
                    ((e1 * d2.y - e2 * d1.y) / det, (e2 * d1.x - e1 * d2.x) / det)
                } else if self.data.flipped {
                    // Mitsuba picks the basis before it flips the normal.
                    coordinate_system(-ng)
                } else {
                    coordinate_system(ng)
                };
                (t0 * b0 + t1 * b.x + t2 * b.y, dpdu, dpdv)
            }
            None => (b, e1, e2),
        };
        HitGeometry {
            p,
            ng,
            ns,
            dpdu,
            dpdv,
            uv,
            bary: b,
        }
    }

    /// A point uniformly distributed over the mesh's area.
    pub fn sample_area(&self, u_prim: f32, u: Vec2) -> AreaSample {
        let (tri, _, _) = self.area_distribution.sample(u_prim);
        self.sample_triangle(tri as u32, u, 1.0 / self.area)
    }

    /// A point uniformly distributed over triangle `tri`, reported with area density `pdf`
    /// (how the triangle was chosen decides it: one over the mesh's area when by area).
    #[inline]
    pub fn sample_triangle(&self, tri: u32, u: Vec2, pdf: f32) -> AreaSample {
        let [i0, i1, i2] = self.data.indices[tri as usize];
        let [p0, p1, p2] = self.triangle(tri);
        let b = square_to_uniform_triangle(u);
        let b0 = 1.0 - b.x - b.y;
        let p = p0 * b0 + p1 * b.x + p2 * b.y;
        let ng = self.face_normals[tri as usize];
        // Mitsuba reports the interpolated vertex normal when the mesh has normals.
        let n = match self.vertex_normals() {
            Some(n) => {
                (n[i0 as usize] * b0 + n[i1 as usize] * b.x + n[i2 as usize] * b.y).normalize_or(ng)
            }
            None => ng,
        };
        let uv = match &self.data.uvs {
            Some(uv) => uv[i0 as usize] * b0 + uv[i1 as usize] * b.x + uv[i2 as usize] * b.y,
            None => b,
        };
        AreaSample {
            p,
            n,
            uv,
            prim: tri,
            bary: b,
            pdf,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_triangle_hit_and_miss() {
        let (p0, p1, p2) = (Vec3A::ZERO, Vec3A::X, Vec3A::Y);
        let (e1, e2) = (p1 - p0, p2 - p0);
        let o = Vec3A::new(0.25, 0.25, 2.0);
        let t = intersect_triangle_bary(o, -Vec3A::Z, 0.0, f32::INFINITY, p0, e1, e2).0;
        assert!((t - 2.0).abs() < 1e-6);
        // From behind works too (two-sided intersection).
        let t = intersect_triangle_bary(
            Vec3A::new(0.25, 0.25, -1.0),
            Vec3A::Z,
            0.0,
            f32::INFINITY,
            p0,
            e1,
            e2,
        )
        .0;
        assert!((t - 1.0).abs() < 1e-6);
        // Outside the hypotenuse.
        let t = intersect_triangle_bary(
            Vec3A::new(0.6, 0.6, 2.0),
            -Vec3A::Z,
            0.0,
            f32::INFINITY,
            p0,
            e1,
            e2,
        )
        .0;
        assert!(t.is_infinite());
        // Beyond tmax.
        let t = intersect_triangle_bary(o, -Vec3A::Z, 0.0, 1.5, p0, e1, e2).0;
        assert!(t.is_infinite());
    }

    #[test]
    fn hit_geometry_interpolates_normals_and_uvs() {
        let data = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: Some(vec![Vec3::Z, Vec3::Z, Vec3::new(0.0, 1.0, 1.0).normalize()]),
            uvs: Some(vec![Vec2::ZERO, Vec2::X, Vec2::Y]),
            indices: vec![[0, 1, 2]],
            flipped: false,
        };
        let m = Mesh::new(&data);
        assert!((m.area() - 0.5).abs() < 1e-6);
        let ray = Ray::new(Vec3::new(0.2, 0.3, 1.0), -Vec3::Z);
        let g = m.hit_geometry(0, &ray, 1.0);
        assert!((g.uv - Vec2::new(0.2, 0.3)).length() < 1e-5);
        assert!((g.ng - Vec3::Z).length() < 1e-6);
        assert!(g.ns.y > 0.0 && (g.ns.length() - 1.0).abs() < 1e-5);
        assert!((g.dpdu - Vec3::X).length() < 1e-5);
        assert!((g.dpdv - Vec3::Y).length() < 1e-5);
    }

    /// ∂p/∂u and ∂p/∂v follow the texture coordinates (a sheared, scaled uv map here), and are
    /// the triangle's edges without them (Mitsuba's barycentric parameterisation).
    #[test]
    fn surface_derivatives_follow_the_parameterisation() {
        let positions = vec![
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 0.0),
        ];
        let uvs = vec![Vec2::ZERO, Vec2::new(0.5, 0.25), Vec2::new(0.0, 1.5)];
        let with_uvs = Mesh::new(&TriangleMesh {
            positions: positions.clone(),
            normals: None,
            uvs: Some(uvs.clone()),
            indices: vec![[0, 1, 2]],
            flipped: false,
        });
        let ray = Ray::new(Vec3::new(0.4, 0.5, 1.0), -Vec3::Z);
        let g = with_uvs.hit_geometry(0, &ray, 1.0);
        // p(u, v) is affine: p(uv_i) = p_i for every vertex.
        for i in 1..3 {
            let du = uvs[i] - uvs[0];
            let p = g.dpdu * du.x + g.dpdv * du.y;
            assert!(
                (p - positions[i]).length() < 1e-5,
                "{p} vs {}",
                positions[i]
            );
        }
        let without = Mesh::new(&TriangleMesh {
            positions,
            normals: None,
            uvs: None,
            indices: vec![[0, 1, 2]],
            flipped: false,
        });
        let g = without.hit_geometry(0, &ray, 1.0);
        assert_eq!(
            (g.dpdu, g.dpdv),
            (Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 3.0, 0.0))
        );
    }

    #[test]
    fn flipped_mesh_keeps_its_parameterisation() {
        // `flip_normals` on a mesh without uvs, as Mitsuba 3: the normals turn around, the
        // barycentric uvs and ∂p/∂u = p₁ − p₀, ∂p/∂v = p₂ − p₀ stay those of the file's vertex
        // order (reversing the winding instead swapped u with v and ∂p/∂u with ∂p/∂v, which
        // moves textures and turns anisotropic highlights).
        let tri = |flipped| TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: None,
            uvs: None,
            indices: vec![[0, 1, 2]],
            flipped,
        };
        let ray = Ray::new(Vec3::new(0.2, 0.3, 1.0), -Vec3::Z);
        let front = Mesh::new(&tri(false)).hit_geometry(0, &ray, 1.0);
        let back = Mesh::new(&tri(true)).hit_geometry(0, &ray, 1.0);
        assert_eq!(front.ng, Vec3::Z);
        assert_eq!(back.ng, -Vec3::Z);
        assert_eq!(back.ns, -Vec3::Z);
        for g in [front, back] {
            assert!((g.uv - Vec2::new(0.2, 0.3)).length() < 1e-6, "{}", g.uv);
            assert_eq!((g.dpdu, g.dpdv), (Vec3::X, Vec3::Y));
        }
        let mesh = Mesh::new(&tri(true));
        let s = mesh.sample_area(0.5, Vec2::new(0.3, 0.6));
        assert_eq!(s.n, -Vec3::Z);
        // A light sample's uv is its barycentrics in the file's order too.
        let b = s.p.truncate();
        assert!((s.uv - b).length() < 1e-6, "{} at {}", s.uv, s.p);
    }

    #[test]
    fn flat_shaded_normals_are_the_face_normal() {
        // A quad whose vertex normals equal the face normal (up to 1e-7): flat, the shading
        // normal is the face normal bit for bit, at hits and at area samples. Tilting one
        // vertex normal makes the mesh smooth again.
        let quad = |tilt: f32| TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            normals: Some(vec![
                Vec3::Z,
                Vec3::new(1e-7, 0.0, 1.0),
                Vec3::new(tilt, 0.0, 1.0).normalize(),
                Vec3::Z,
            ]),
            uvs: None,
            indices: vec![[0, 1, 2], [0, 2, 3]],
            flipped: false,
        };
        let flat = Mesh::new(&quad(0.0));
        assert!(!flat.smooth);
        let ray = Ray::new(Vec3::new(0.7, 0.2, 1.0), -Vec3::Z);
        let g = flat.hit_geometry(0, &ray, 1.0);
        assert_eq!(g.ns, g.ng);
        let s = flat.sample_area(0.1, Vec2::new(0.3, 0.6));
        assert_eq!(s.n, Vec3::Z);
        let smooth = Mesh::new(&quad(0.3));
        assert!(smooth.smooth);
        let g = smooth.hit_geometry(0, &ray, 1.0);
        assert!(g.ns.x > 0.01, "interpolated normal {}", g.ns);
    }
}
