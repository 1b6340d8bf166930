//! `<shape>` plugins: `rectangle`, `cube`, `sphere`, `disk`, `obj`, `ply`, `serialized`, and Mitsuba's
//! instancing, `shapegroup` + `instance` (each instance's shapes are built as copies with the
//! instance's `to_world` applied after their own: the same geometry, memory per copy). Meshes are moved to
//! world space here (positions by `to_world`, normals by its inverse transpose) and follow
//! Mitsuba 3's loaders: polygons fan-triangulated around their first corner, file normals used
//! when present, otherwise angle-weighted smooth vertex normals computed in world space unless
//! `face_normals` is true; OBJ texture coordinates stored as (u, 1 − v) (`flip_tex_coords`,
//! default true for OBJ, false for PLY); `flip_normals` negates the normals and keeps the vertex
//! order (`TriangleMesh::flipped`).
//! Extra PLY properties become mesh attributes (`mesh_attributes.rs`), which the `mesh_attribute`
//! textures of the shape's BSDF and area emitter read.

use super::emitters::area_radiance;
use super::mesh_attributes::{
    attribute_value, group_attributes, AttributeSource, MeshAttributes, PlyField, RawAttribute,
};
use super::props::Props;
use super::{Builder, Element, MeshScope, SceneError};
use crate::description::{Geometry, ShapeDesc, TriangleMesh};
use crate::media::MediumInterface;
use crate::texture::Texture;
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::path::Path;

/// Builds a shape (with its BSDF and area emitter) and adds it to the scene.
pub(super) fn build_shape<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<(), SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type"], &mut b.diag)?;
    let kind = el.attr("type").unwrap_or_default();
    const SHAPES: [&str; 10] = [
        "rectangle",
        "cube",
        "sphere",
        "disk",
        "obj",
        "ply",
        "serialized",
        "cylinder",
        "shapegroup",
        "instance",
    ];
    if !SHAPES.contains(&kind) {
        let err = el.error(format!(
            "unknown plugin \"{kind}\" (supported shapes: {})",
            SHAPES.join(", ")
        ));
        return b.diag.unknown(err);
    }
    if b.instance.is_some() && (kind == "shapegroup" || kind == "instance") {
        return Err(not_a_plain_shape(el));
    }
    match kind {
        "shapegroup" => return check_shapegroup(b, el),
        "instance" => return build_instance(b, el),
        _ => {}
    }
    let mut p = Props::parse(b, el)?;
    let own_to_world = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
    let to_world = match &b.instance {
        Some((instance_to_world, _)) => *instance_to_world * own_to_world,
        None => own_to_world,
    };
    let flip_normals = p.bool_or("flip_normals", false)?;
    // Mitsuba's weight for sampling silhouettes in differentiable rendering: no effect on an
    // image rendered forward.
    p.float("silhouette_sampling_weight")?;
    // Mitsuba transforms an instanced mesh's normals by the instance's inverse transpose, so a
    // mirroring instance keeps the side its group's mesh faces; normals taken from the winding
    // of world-space triangles would turn around with it.
    let mirrored_instance = b
        .instance
        .as_ref()
        .is_some_and(|(m, _)| Mat3::from_mat4(*m).determinant() < 0.0);

    // The attributes a PLY file carries (read by the shape's `mesh_attribute` textures).
    let mut file_attributes = None;
    let geometry = match kind {
        "rectangle" => Geometry::Mesh(rectangle(to_world, flip_normals)),
        "cube" => {
            let mut mesh = cube(to_world, flip_normals);
            // Its vertex normals went through the inverse transpose: only the faces turn.
            mesh.flipped ^= mirrored_instance;
            Geometry::Mesh(mesh)
        }
        "disk" => Geometry::Disk {
            to_world,
            flip_normals,
        },
        "cylinder" => {
            // Mitsuba: to_world · translate(p0) · frame(p1 − p0) · scale(radius, radius, length).
            let p0 = p.vector("p0")?.unwrap_or(Vec3::ZERO);
            let p1 = p.vector("p1")?.unwrap_or(Vec3::Z);
            let radius = p.positive_float_or("radius", 1.0)? as f32;
            let axis = p1 - p0;
            let length = axis.length();
            if length <= 0.0 || !length.is_finite() {
                return Err(p.element_of("p1").error("a cylinder needs p1 != p0"));
            }
            let (s, t) = crate::math::coordinate_system(axis / length);
            let frame = Mat4::from_cols(
                s.extend(0.0),
                t.extend(0.0),
                (axis / length).extend(0.0),
                glam::Vec4::W,
            );
            let local = Mat4::from_translation(p0)
                * frame
                * Mat4::from_scale(Vec3::new(radius, radius, length));
            let to_world = to_world * local;
            crate::shapes::Cylinder::new(to_world, flip_normals)
                .map_err(|e| p.element_of("to_world").error(e))?;
            Geometry::Cylinder {
                to_world,
                flip_normals,
            }
        }
        "sphere" => {
            let center = p.vector("center")?.unwrap_or(Vec3::ZERO);
            let radius = p.positive_float_or("radius", 1.0)? as f32;
            // Mitsuba: to_world · translate(center) · scale(radius); must stay a sphere.
            let m3 = Mat3::from_mat4(to_world);
            let scales = [m3.x_axis.length(), m3.y_axis.length(), m3.z_axis.length()];
            let s = scales[0];
            if scales.iter().any(|v| (v - s).abs() > 1e-4 * s.max(1e-12)) || s == 0.0 {
                return Err(p
                    .element_of("to_world")
                    .error("a sphere's to_world must not scale non-uniformly"));
            }
            Geometry::Sphere {
                center: to_world.transform_point3(center),
                radius: radius * s,
                // Uniform scale s: the 3x3 part divided by s is orthogonal (Mitsuba's polar
                // decomposition gives the same rotation).
                rotation: m3 * (1.0 / s),
                flip_normals,
            }
        }
        _ => {
            let file_el = p.element_of("filename");
            let Some(filename) = p.string("filename")? else {
                return Err(el.error("missing parameter \"filename\""));
            };
            let face_normals = p.bool_or("face_normals", false)?;
            let flip_tex = p.bool_or("flip_tex_coords", kind == "obj")?;
            let index_el = p.element_of("shape_index");
            let shape_index = if kind == "serialized" {
                match p.int("shape_index")?.unwrap_or(0) {
                    i if i >= 0 => i as usize,
                    i => {
                        return Err(index_el.error(format!("\"shape_index\" must be >= 0, got {i}")))
                    }
                }
            } else {
                0
            };
            let path = file_el.resolve_path(filename, &b.diag.search_paths);
            let raw = match kind {
                "obj" => super::obj::load_obj(&path),
                "ply" => load_ply(&path),
                _ => load_serialized(&path, shape_index),
            };
            let mut raw = raw.map_err(|m| {
                file_el.error(format!("cannot load mesh \"{}\": {m}", path.display()))
            })?;
            let loaded = std::mem::take(&mut raw.attributes);
            let sides = MeshSides {
                face_normals,
                flip_normals,
                mirrored_instance,
            };
            let (mesh, polygon_of) = finish_mesh(raw, to_world, sides, flip_tex)
                .map_err(|m| file_el.error(format!("mesh \"{}\": {m}", path.display())))?;
            if !loaded.is_empty() {
                file_attributes = Some(MeshAttributes {
                    attributes: loaded,
                    triangles: mesh.indices.clone(),
                    polygon_of,
                });
            }
            Geometry::Mesh(mesh)
        }
    };

    // Nested or referenced BSDF and area emitter, built in the scope of this shape's mesh
    // attributes (`None` on analytic shapes, which have none).
    let attributes = match &geometry {
        Geometry::Mesh(_) => Some(file_attributes.unwrap_or_default()),
        _ => None,
    };
    let outer = b.mesh_scope.replace(MeshScope {
        shape: el,
        attributes,
    });
    let built = shape_bsdf_and_emission(b, &mut p);
    b.mesh_scope = outer;
    let (bsdf, emitter, media) = built?;
    let (emission, collimated) = match emitter {
        Some((radiance, collimated)) => (Some(radiance), collimated),
        None => (None, false),
    };
    p.finish(b)?;
    let bsdf = match bsdf {
        Some(i) => i,
        None => b.default_bsdf(emission.is_some()),
    };
    let name = el
        .attr("id")
        .map(str::to_owned)
        .unwrap_or_else(|| format!("{kind}#{}", b.shapes.len()));
    let name = match &b.instance {
        Some((_, instance)) => format!("{instance}/{name}"),
        None => name,
    };
    b.shapes.push(ShapeDesc {
        name,
        geometry,
        bsdf,
        emission,
        collimated,
        media,
    });
    Ok(())
}

/// A shape's area emitter: its radiance, and whether it is a collimated `directionalarea`.
type AreaEmission = (Texture, bool);

/// What a shape holds besides its geometry: the index of its BSDF, its area emitter and the
/// media on either side.
type ShapeContents = (Option<usize>, Option<AreaEmission>, MediumInterface);

/// A shape's nested or referenced BSDF (its index), area emitter and interior/exterior media.
fn shape_bsdf_and_emission<'a>(
    b: &mut Builder<'a>,
    p: &mut Props<'a>,
) -> Result<ShapeContents, SceneError> {
    let mut bsdf = None;
    let mut emission = None;
    let mut media = MediumInterface::default();
    // Named or not (`<bsdf name="bsdf">` is common in exported scenes).
    for obj in p.objects(&["bsdf", "emitter", "ref", "medium"]) {
        let target = b.deref(obj)?;
        match target.tag.as_str() {
            // Named on the `<ref>` or on the nested `<medium>` itself.
            "medium" => {
                let role = super::media::shape_medium_role(obj)?;
                let index = b.medium_index(obj)?;
                super::media::set_side(&mut media, role, index, obj)?;
            }
            "bsdf" => {
                if bsdf.is_some() {
                    return Err(obj.error("a shape can have only one BSDF"));
                }
                bsdf = Some(b.bsdf_index(obj)?);
            }
            "emitter" => {
                if b.instance.is_some() {
                    return Err(obj.error("emitters cannot be instanced (as in Mitsuba): give the shape its own <shape> outside the shapegroup"));
                }
                if emission.is_some() {
                    return Err(obj.error("a shape can have only one emitter"));
                }
                emission = area_radiance(b, target)?;
            }
            _ => {
                let err = obj.error(format!("unexpected {} inside a shape", target.describe()));
                b.diag.unknown(err)?;
            }
        }
    }
    Ok((bsdf, emission, media))
}

/// A `shapegroup` at the top level: nothing is built (its shapes appear through instances),
/// but its contents are checked now, so a group that is never instanced still reports errors.
fn check_shapegroup<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<(), SceneError> {
    el.check_attributes(&["type", "id", "name"], &["type", "id"], &mut b.diag)?;
    for child in &el.children {
        let kind = child.attr("type").unwrap_or_default();
        if child.tag != "shape" || kind == "shapegroup" || kind == "instance" {
            return Err(not_a_plain_shape(child));
        }
    }
    Ok(())
}

/// The error for `el` inside a shapegroup when it is not a plain shape.
fn not_a_plain_shape(el: &Element) -> SceneError {
    el.error(format!(
        "a shapegroup holds plain shapes only, not {}",
        el.describe()
    ))
}

/// An `instance`: `to_world` and a `<ref>` to a `shapegroup`, whose shapes are built with
/// `to_world` = the instance's · their own.
fn build_instance<'a>(b: &mut Builder<'a>, el: &'a Element) -> Result<(), SceneError> {
    let mut p = Props::parse(b, el)?;
    let to_world = p.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
    let mut group = None;
    for obj in p.objects(&["ref", "shape"]) {
        let target = b.deref(obj)?;
        if target.tag != "shape" || target.attr("type") != Some("shapegroup") {
            return Err(obj.error(format!(
                "an instance refers to a shapegroup, not {}",
                target.describe()
            )));
        }
        if group.is_some() {
            return Err(obj.error("an instance refers to exactly one shapegroup"));
        }
        group = Some(target);
    }
    p.finish(b)?;
    let Some(group) = group else {
        return Err(el.error("an instance needs a <ref id=\"…\"/> to a shapegroup"));
    };
    let name = el
        .attr("id")
        .map(str::to_owned)
        .unwrap_or_else(|| format!("instance#{}", b.shapes.len()));
    b.instance = Some((to_world, name));
    let built = group
        .children
        .iter()
        .try_for_each(|child| match child.tag.as_str() {
            "shape" => build_shape(b, child),
            _ => Err(not_a_plain_shape(child)),
        });
    b.instance = None;
    built
}

/// Mitsuba's `rectangle`: [−1, 1]² in the z = 0 plane, normal +z, uv = ((x+1)/2, (y+1)/2).
/// Mitsuba's rectangle is analytic with normal `to_world⁻ᵀ·ẑ`, so a mirroring `to_world` must
/// not turn it around: the winding is reversed to compensate.
fn rectangle(to_world: Mat4, flip_normals: bool) -> TriangleMesh {
    let local = [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
    ];
    let uvs = vec![
        Vec2::new(0.0, 0.0),
        Vec2::new(1.0, 0.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(0.0, 1.0),
    ];
    let mut mesh = TriangleMesh {
        positions: local
            .iter()
            .map(|p| to_world.transform_point3(*p))
            .collect(),
        normals: None,
        uvs: Some(uvs),
        indices: vec![[0, 1, 2], [2, 3, 0]],
        flipped: false,
    };
    let mirrored = Mat3::from_mat4(to_world).determinant() < 0.0;
    if mirrored != flip_normals {
        reverse_winding(&mut mesh);
    }
    mesh
}

/// Mitsuba's `cube`: [−1, 1]³ as 6 quads with their own vertices, normals and uvs (the same
/// vertex order as Mitsuba's, so textures land identically).
fn cube(to_world: Mat4, flip_normals: bool) -> TriangleMesh {
    // Per face: outward normal and its four corners, in Mitsuba's order.
    #[rustfmt::skip]
    let faces: [([f32; 3], [[f32; 3]; 4]); 6] = [
        ([0.0, -1.0, 0.0], [[1.0, -1.0, -1.0], [1.0, -1.0, 1.0], [-1.0, -1.0, 1.0], [-1.0, -1.0, -1.0]]),
        ([0.0, 1.0, 0.0], [[1.0, 1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]),
        ([1.0, 0.0, 0.0], [[1.0, -1.0, -1.0], [1.0, 1.0, -1.0], [1.0, 1.0, 1.0], [1.0, -1.0, 1.0]]),
        ([0.0, 0.0, 1.0], [[1.0, -1.0, 1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0], [-1.0, -1.0, 1.0]]),
        ([-1.0, 0.0, 0.0], [[-1.0, -1.0, 1.0], [-1.0, 1.0, 1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, -1.0]]),
        ([0.0, 0.0, -1.0], [[1.0, 1.0, -1.0], [1.0, -1.0, -1.0], [-1.0, -1.0, -1.0], [-1.0, 1.0, -1.0]]),
    ];
    let corner_uv = [
        Vec2::new(0.0, 1.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(1.0, 0.0),
        Vec2::new(0.0, 0.0),
    ];
    let mut mesh = TriangleMesh {
        normals: Some(Vec::new()),
        uvs: Some(Vec::new()),
        ..Default::default()
    };
    for (f, (n, corners)) in faces.iter().enumerate() {
        let base = (4 * f) as u32;
        for (c, p) in corners.iter().enumerate() {
            mesh.positions.push(Vec3::from(*p));
            if let Some(ns) = mesh.normals.as_mut() {
                ns.push(Vec3::from(*n));
            }
            if let Some(uvs) = mesh.uvs.as_mut() {
                uvs.push(corner_uv[c]);
            }
        }
        mesh.indices.push([base, base + 1, base + 2]);
        mesh.indices.push([base + 3, base, base + 2]);
    }
    transform_mesh(&mut mesh, to_world);
    if flip_normals {
        flip(&mut mesh);
    }
    mesh
}

/// A mesh as read from a file (object space), before normals are settled.
#[derive(Debug, Default)]
pub(super) struct RawMesh {
    pub(super) positions: Vec<Vec3>,
    pub(super) normals: Option<Vec<Vec3>>,
    pub(super) uvs: Option<Vec<Vec2>>,
    /// The corners of every polygon (any corner count ≥ 3), one polygon after the other, as
    /// indices into the vertex arrays (one buffer, not one allocation per polygon).
    corners: Vec<u32>,
    /// Where each polygon's corners end in `corners` (it starts where the previous one ends).
    polygon_ends: Vec<usize>,
    /// Extra per-vertex and per-polygon properties (PLY only), for `mesh_attribute`.
    attributes: Vec<RawAttribute>,
}

/// Which way a loaded mesh's normals point.
#[derive(Debug, Clone, Copy)]
struct MeshSides {
    /// `face_normals`: no vertex normals (flat shading).
    face_normals: bool,
    /// `flip_normals`.
    flip_normals: bool,
    /// Built for an instance whose `to_world` mirrors (negative determinant).
    mirrored_instance: bool,
}

impl RawMesh {
    /// Makes room for `n` more polygons of (mostly) three corners.
    fn reserve_polygons(&mut self, n: usize) {
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
fn finish_mesh(
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
fn transform_mesh(mesh: &mut TriangleMesh, m: Mat4) {
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

fn reverse_winding(mesh: &mut TriangleMesh) {
    for t in &mut mesh.indices {
        t.swap(1, 2);
    }
}

/// `flip_normals`: the other side becomes the front; the vertex order stays (see
/// [`TriangleMesh::flipped`]).
fn flip(mesh: &mut TriangleMesh) {
    mesh.flipped = !mesh.flipped;
    if let Some(ns) = mesh.normals.as_mut() {
        for v in ns.iter_mut() {
            *v = -*v;
        }
    }
}

/// Reads mesh `index` of a Mitsuba `.serialized` file: little-endian; per mesh a header
/// (`0x041C`, version 3 or 4) and a zlib stream holding flags, (v4) a name, vertex and triangle
/// counts, positions, optional normals (flag 0x0001), uvs (0x0002) and colours (0x0008, skipped)
/// in f32 (0x1000) or f64 (0x2000), then triangles (u32 indices; meshes past 2³² vertices are
/// refused); the
/// file ends with each mesh's offset (u64 in v4, u32 in v3) and the mesh count (u32). The
/// file's face-normal flag (0x0010) is ignored, as Mitsuba 3 does: the `face_normals`
/// parameter decides.
fn load_serialized(path: &Path, index: usize) -> Result<RawMesh, String> {
    use std::io::Read;
    let data = std::fs::read(path).map_err(|e| e.to_string())?;
    let u16_at = |at: usize| {
        data.get(at..at + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
    };
    if data.len() < 8 || u16_at(0) != Some(0x041C) {
        return Err("not a Mitsuba serialized mesh file (no 0x041C header)".into());
    }
    let version = u16_at(2).unwrap_or(0);
    if version != 3 && version != 4 {
        return Err(format!(
            "serialized format version {version} (3 or 4 are supported)"
        ));
    }
    let n = data.len();
    let count = u32::from_le_bytes(data[n - 4..].try_into().expect("4 bytes")) as usize;
    if index >= count {
        return Err(format!(
            "shape_index {index}, but the file holds {count} mesh(es)"
        ));
    }
    let entry = if version == 4 { 8 } else { 4 };
    let table = n
        .checked_sub(4 + entry * count)
        .ok_or("truncated offset table")?;
    let at = table + entry * index;
    let offset = if version == 4 {
        u64::from_le_bytes(data[at..at + 8].try_into().expect("8 bytes")) as usize
    } else {
        u32::from_le_bytes(data[at..at + 4].try_into().expect("4 bytes")) as usize
    };
    if offset + 4 > table || u16_at(offset) != Some(0x041C) {
        return Err(format!("mesh {index}: bad offset {offset}"));
    }
    let mut body = Vec::new();
    flate2::read::ZlibDecoder::new(&data[offset + 4..table])
        .read_to_end(&mut body)
        .map_err(|e| format!("mesh {index}: corrupt zlib stream: {e}"))?;
    let mut cursor = 0usize;
    let mut take = |len: usize| -> Result<&[u8], String> {
        let bytes = body
            .get(cursor..cursor + len)
            .ok_or_else(|| format!("mesh {index}: truncated data"))?;
        cursor += len;
        Ok(bytes)
    };
    let flags = u32::from_le_bytes(take(4)?.try_into().expect("4 bytes"));
    if version == 4 {
        while take(1)?[0] != 0 {} // the mesh name
    }
    let vertices = u64::from_le_bytes(take(8)?.try_into().expect("8 bytes")) as usize;
    let triangles = u64::from_le_bytes(take(8)?.try_into().expect("8 bytes")) as usize;
    let double = flags & 0x2000 != 0;
    let mut reals = |k: usize| -> Result<Vec<f32>, String> {
        let width = if double { 8 } else { 4 };
        let bytes = take(k.checked_mul(width).ok_or("vertex count overflows")?)?;
        Ok(bytes
            .chunks_exact(width)
            .map(|c| {
                if double {
                    f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32
                } else {
                    f32::from_le_bytes(c.try_into().expect("4 bytes"))
                }
            })
            .collect())
    };
    let triples = |v: Vec<f32>| v.chunks_exact(3).map(Vec3::from_slice).collect::<Vec<_>>();
    let positions = triples(reals(3 * vertices)?);
    let normals = if flags & 0x0001 != 0 {
        Some(triples(reals(3 * vertices)?))
    } else {
        None
    };
    let uvs = if flags & 0x0002 != 0 {
        Some(
            reals(2 * vertices)?
                .chunks_exact(2)
                .map(Vec2::from_slice)
                .collect(),
        )
    } else {
        None
    };
    if flags & 0x0008 != 0 {
        reals(3 * vertices)?; // vertex colours: not used
    }
    if vertices > u32::MAX as usize {
        return Err(format!(
            "mesh {index}: {vertices} vertices (at most 2³² are supported)"
        ));
    }
    let indices: Vec<u32> = take(
        triangles
            .checked_mul(12)
            .ok_or("triangle count overflows")?,
    )?
    .chunks_exact(4)
    .map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes")))
    .collect();
    let polygon_ends = (1..=triangles).map(|t| 3 * t).collect();
    Ok(RawMesh {
        positions,
        normals,
        uvs,
        corners: indices,
        polygon_ends,
        attributes: Vec::new(),
    })
}

/// Reads a PLY (ASCII or binary) with `vertex` (x, y, z, optional nx/ny/nz and u/v, s/t or
/// texture_u/texture_v) and `face` (`vertex_indices` or `vertex_index`) elements.
/// Other vertex and face properties become attributes as Mitsuba 3.9.1 groups them.
/// Elements are read and converted one at a time: holding the whole payload as parsed
/// elements (a map of named properties each) took ~500 bytes per triangle.
fn load_ply(path: &Path) -> Result<RawMesh, String> {
    use ply_rs_bw::parser::{Parser, Reader};
    use ply_rs_bw::ply::{DefaultElement, Encoding, Property};
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    // Each element takes at least one byte: counts past the file's size are not reserved for.
    let file_len = file.metadata().map_or(0, |m| m.len()) as usize;
    let mut reader = Reader::new(std::io::BufReader::new(file));
    let parser = Parser::<DefaultElement>::new();
    let header = parser
        .read_header(&mut reader)
        .map_err(|e| format!("invalid PLY: {e}"))?;
    let scalar =
        |e: &DefaultElement, k: &str| -> Option<f32> { e.get(k).and_then(|p| p.to_f32_lossy()) };
    let vertex_def = header
        .elements
        .get("vertex")
        .ok_or("no \"vertex\" element")?;
    if !header.elements.contains_key("face") {
        return Err("no \"face\" element".into());
    }
    let mut raw = RawMesh::default();
    let has = |k: &str| vertex_def.count > 0 && vertex_def.properties.contains_key(k);
    let has_normals = has("nx") && has("ny") && has("nz");
    let uv_keys = [
        ("u", "v"),
        ("s", "t"),
        ("texture_u", "texture_v"),
        ("texture_s", "texture_t"),
    ]
    .into_iter()
    .find(|(u, v)| has(u) && has(v));
    // Mitsuba reserves x, y, z, nx, ny, nz and the uv pair it reads (renamed u, v).
    let mut reserved = vec!["x", "y", "z", "nx", "ny", "nz", "u", "v"];
    reserved.extend(uv_keys.iter().flat_map(|(u, v)| [*u, *v]));
    let fields = |name: &str| {
        header
            .elements
            .get(name)
            .map(PlyField::of)
            .unwrap_or_default()
    };
    let vertex_sources = group_attributes("vertex_", &fields("vertex"), &reserved);
    let face_sources = group_attributes("face_", &fields("face"), &[]);
    let mut vertex_attributes = new_attributes(&vertex_sources);
    let mut face_attributes = new_attributes(&face_sources);
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    // One face's indices (reused across faces).
    let mut idx: Vec<i64> = Vec::new();
    let mut line = String::new();
    // In file order: every element is read, those other than vertices and faces skipped.
    for def in header.elements.values() {
        let kind = def.name.as_str();
        if kind == "vertex" {
            let n = def.count.min(file_len);
            raw.positions.reserve_exact(n);
            normals.reserve_exact(if has_normals { n } else { 0 });
            uvs.reserve_exact(if uv_keys.is_some() { n } else { 0 });
        } else if kind == "face" {
            raw.reserve_polygons(def.count.min(file_len));
        }
        for i in 0..def.count {
            let element = match header.encoding {
                Encoding::Ascii => {
                    line.clear();
                    let read = std::io::BufRead::read_line(reader.get_mut(), &mut line)
                        .map_err(|e| e.to_string())?;
                    if read == 0 {
                        return Err(format!(
                            "invalid PLY: unexpected end of file in element \"{kind}\" {i} of {}",
                            def.count
                        ));
                    }
                    parser.read_ascii_element(&line, def)
                }
                Encoding::BinaryLittleEndian => {
                    parser.read_little_endian_element(reader.get_mut(), def)
                }
                Encoding::BinaryBigEndian => parser.read_big_endian_element(reader.get_mut(), def),
            }
            .map_err(|e| {
                if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    // The binary readers' own words ("failed to fill whole buffer") hide it.
                    format!(
                        "invalid PLY: unexpected end of file in element \"{kind}\" {i} of {} \
                         (truncated file?)",
                        def.count
                    )
                } else {
                    format!("invalid PLY: element \"{kind}\" {i}: {e}")
                }
            })?;
            if kind == "vertex" {
                let v = &element;
                let get =
                    |k: &str| scalar(v, k).ok_or_else(|| format!("vertex without numeric \"{k}\""));
                read_attributes(v, &vertex_sources, &mut vertex_attributes)?;
                raw.positions
                    .push(Vec3::new(get("x")?, get("y")?, get("z")?));
                if has_normals {
                    normals.push(Vec3::new(get("nx")?, get("ny")?, get("nz")?));
                }
                if let Some((ku, kv)) = uv_keys {
                    uvs.push(Vec2::new(get(ku)?, get(kv)?));
                }
            } else if kind == "face" {
                let f = &element;
                let list = f
                    .get("vertex_indices")
                    .or_else(|| f.get("vertex_index"))
                    .ok_or("face without \"vertex_indices\"")?;
                idx.clear();
                match list {
                    Property::ListChar(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListUChar(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListShort(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListUShort(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListInt(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    Property::ListUInt(l) => idx.extend(l.iter().map(|&x| x as i64)),
                    _ => return Err("face indices are not an integer list".into()),
                }
                if idx.len() < 3 {
                    continue;
                }
                read_attributes(f, &face_sources, &mut face_attributes)?;
                if let Some(bad) = idx.iter().find(|&&i| i < 0 || i > i64::from(u32::MAX)) {
                    return Err(format!("invalid vertex index {bad}"));
                }
                raw.push_polygon(idx.iter().map(|&i| i as u32));
            }
        }
    }
    if has_normals {
        raw.normals = Some(normals);
    }
    if uv_keys.is_some() {
        raw.uvs = Some(uvs);
    }
    raw.attributes = vertex_attributes;
    raw.attributes.extend(face_attributes);
    let mut names = std::collections::HashSet::new();
    if let Some(a) = raw.attributes.iter().find(|a| !names.insert(&a.name)) {
        // Mitsuba: "add_attribute(): attribute … already exists".
        return Err(format!(
            "two property groups both make attribute \"{}\"",
            a.name
        ));
    }
    Ok(raw)
}

/// Empty attributes for the groups `sources` found in a PLY element.
fn new_attributes(sources: &[AttributeSource]) -> Vec<RawAttribute> {
    sources
        .iter()
        .map(|s| RawAttribute {
            name: s.name.clone(),
            channels: s.properties.len(),
            values: Vec::new(),
        })
        .collect()
}

/// Appends one PLY element's values of each attribute (converted as Mitsuba stores them).
fn read_attributes(
    e: &ply_rs_bw::ply::DefaultElement,
    sources: &[AttributeSource],
    out: &mut [RawAttribute],
) -> Result<(), String> {
    for (s, a) in sources.iter().zip(out) {
        for k in &s.properties {
            let v = e
                .get(k)
                .and_then(attribute_value)
                .ok_or_else(|| format!("attribute \"{}\": no numeric property \"{k}\"", s.name))?;
            a.values.push(v);
        }
    }
    Ok(())
}
