//! A mesh as the file loaders (`obj.rs`, `ply.rs`, `serialized.rs`) read it ([`RawMesh`]:
//! object space, polygons, optional normals, uvs and attributes) and how it becomes a
//! world-space [`TriangleMesh`], following Mitsuba 3's loaders ([`finish_mesh`]): polygons
//! fan-triangulated around their first corner, file normals used when present, otherwise
//! angle-weighted smooth vertex normals computed in world space unless `face_normals` is true;
//! texture coordinates stored as (u, 1 − v) when `flip_tex_coords` asks; `flip_normals`
//! negates the normals and keeps the vertex order (`TriangleMesh::flipped`).

use super::mesh_attributes::RawAttribute;
use crate::description::TriangleMesh;
use glam::{Mat3, Mat4, Vec2, Vec3};

/// A mesh as read from a file (object space), before normals are settled.
#[derive(Debug, Default)]
pub(crate) struct RawMesh {
    pub(super) positions: Vec<Vec3>,
    pub(super) normals: Option<Vec<Vec3>>,
    pub(super) uvs: Option<Vec<Vec2>>,
    /// The corners of every polygon (any corner count ≥ 3), one polygon after the other, as
    /// indices into the vertex arrays (one buffer, not one allocation per polygon).
    pub(super) corners: Vec<u32>,
    /// Where each polygon's corners end in `corners` (it starts where the previous one ends).
    pub(super) polygon_ends: Vec<usize>,
    /// Extra per-vertex and per-polygon properties (PLY only), for `mesh_attribute`.
    pub(crate) attributes: Vec<RawAttribute>,
}

/// Which way a loaded mesh's normals point.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MeshSides {
    /// `face_normals`: no vertex normals (flat shading).
    pub(crate) face_normals: bool,
    /// `flip_normals`.
    pub(crate) flip_normals: bool,
    /// Built for an instance whose `to_world` mirrors (negative determinant).
    pub(crate) mirrored_instance: bool,
}

impl RawMesh {
    /// Makes room for `n` more polygons of (mostly) three corners.
    pub(super) fn reserve_polygons(&mut self, n: usize) {
        self.corners.reserve(3 * n);
        self.polygon_ends.reserve_exact(n);
    }

    /// Appends a polygon (at least three corners).
    pub(super) fn push_polygon(&mut self, corners: impl IntoIterator<Item = u32>) {
        self.corners.extend(corners);
        self.polygon_ends.push(self.corners.len());
    }

    /// The polygons in order, each as its corners.
    fn polygons(&self) -> impl Iterator<Item = &[u32]> {
        let starts = std::iter::once(0).chain(self.polygon_ends.iter().copied());
        starts
            .zip(&self.polygon_ends)
            .map(|(start, &end)| &self.corners[start..end])
    }
}

/// Triangulates, transforms and settles the normals of a loaded mesh; also returns, for each
/// triangle, the polygon it was cut from (what per-face attributes are indexed by).
pub(crate) fn finish_mesh(
    raw: RawMesh,
    to_world: Mat4,
    sides: MeshSides,
    flip_tex: bool,
) -> Result<(TriangleMesh, Vec<u32>), String> {
    let n = raw.positions.len();
    if raw.positions.iter().any(|p| !p.is_finite()) {
        return Err("vertex positions are not finite".into());
    }
    // A polygon of k corners makes k − 2 triangles.
    let triangles = raw.corners.len() - 2 * raw.polygon_ends.len();
    let mut indices = Vec::with_capacity(triangles);
    let mut polygon_of = Vec::with_capacity(triangles);
    for (f, poly) in raw.polygons().enumerate() {
        if let Some(bad) = poly.iter().find(|&&i| i as usize >= n) {
            return Err(format!(
                "face refers to vertex {bad}, but there are only {n} vertices"
            ));
        }
        // Fan around the first corner (Mitsuba: quads split along corners 0–2).
        for k in 1..poly.len().saturating_sub(1) {
            indices.push([poly[0], poly[k], poly[k + 1]]);
            polygon_of.push(f as u32);
        }
    }
    if indices.is_empty() {
        return Err("the mesh has no faces".into());
    }
    // The polygons are triangulated: freed before the normals are computed.
    let RawMesh {
        positions,
        normals,
        uvs,
        corners,
        polygon_ends,
        ..
    } = raw;
    drop((corners, polygon_ends));
    let uvs = uvs.map(|uv| {
        if flip_tex {
            uv.into_iter().map(|t| Vec2::new(t.x, 1.0 - t.y)).collect()
        } else {
            uv
        }
    });
    // Unit-length file normals (zero or non-finite ones make the set unusable: recompute).
    let file_normals = normals
        .filter(|ns| ns.iter().all(|v| v.is_finite() && v.length_squared() > 0.0))
        .map(|ns| ns.into_iter().map(Vec3::normalize).collect());
    let mut mesh = TriangleMesh {
        positions,
        normals: file_normals,
        uvs,
        indices,
        flipped: false,
    };
    transform_mesh(&mut mesh, to_world);
    let computed = mesh.normals.is_none();
    if sides.face_normals {
        mesh.normals = None;
    } else if computed {
        mesh.normals = Some(smooth_normals(&mesh.positions, &mesh.indices));
    }
    if sides.mirrored_instance {
        // Face normals (and normals computed here) come from the world-space winding, which
        // the mirror turned around; file normals went through the inverse transpose.
        mesh.flipped ^= true;
        if computed {
            for n in mesh.normals.iter_mut().flatten() {
                *n = -*n;
            }
        }
    }
    if sides.flip_normals {
        flip(&mut mesh);
    }
    Ok((mesh, polygon_of))
}

/// Moves a mesh to world space: positions by `m`, normals by its inverse transpose (normals are
/// dropped, and later recomputed, if `m` is singular).
pub(crate) fn transform_mesh(mesh: &mut TriangleMesh, m: Mat4) {
    if m == Mat4::IDENTITY {
        return;
    }
    for p in &mut mesh.positions {
        *p = m.transform_point3(*p);
    }
    let m3 = Mat3::from_mat4(m);
    let det = m3.determinant();
    if let Some(ns) = mesh.normals.as_mut() {
        if det.abs() > f32::MIN_POSITIVE && det.is_finite() {
            let inv_t = m3.inverse().transpose();
            for v in ns.iter_mut() {
                *v = (inv_t * *v).normalize_or(Vec3::Z);
            }
        } else {
            mesh.normals = None;
        }
    }
}

/// Angle-weighted vertex normals (Mitsuba's `recompute_vertex_normals`): each triangle adds its
/// unit normal times its corner angle to its three vertices. Vertices on degenerate triangles
/// only keep +z.
fn smooth_normals(positions: &[Vec3], indices: &[[u32; 3]]) -> Vec<Vec3> {
    let mut acc = vec![Vec3::ZERO; positions.len()];
    for tri in indices {
        let p = tri.map(|i| positions[i as usize]);
        let Some(n) = (p[1] - p[0]).cross(p[2] - p[0]).try_normalize() else {
            continue;
        };
        for k in 0..3 {
            let e1 = p[(k + 1) % 3] - p[k];
            let e2 = p[(k + 2) % 3] - p[k];
            let (Some(d1), Some(d2)) = (e1.try_normalize(), e2.try_normalize()) else {
                continue;
            };
            let angle = d1.dot(d2).clamp(-1.0, 1.0).acos();
            acc[tri[k] as usize] += n * angle;
        }
    }
    acc.into_iter().map(|v| v.normalize_or(Vec3::Z)).collect()
}

/// `flip_normals`: the other side becomes the front; the vertex order stays (see
/// [`TriangleMesh::flipped`]).
pub(crate) fn flip(mesh: &mut TriangleMesh) {
    mesh.flipped = !mesh.flipped;
    if let Some(ns) = mesh.normals.as_mut() {
        for v in ns.iter_mut() {
            *v = -*v;
        }
    }
}
