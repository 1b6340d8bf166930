//! `<shape>` plugins: `rectangle`, `cube`, `sphere`, `disk`, `obj`, `ply`, `serialized`, and Mitsuba's
//! instancing, `shapegroup` + `instance` (each instance's shapes are built as copies with the
//! instance's `to_world` applied after their own: the same geometry, memory per copy). Mesh
//! files are read by the loaders of `shapes/` (`obj.rs`, `ply.rs`, `serialized.rs`) and moved to
//! world space by `shapes/mesh_file.rs` (positions by `to_world`, normals by its inverse
//! transpose), following Mitsuba 3's loaders; OBJ texture coordinates are stored as (u, 1 − v)
//! (`flip_tex_coords`, default true for OBJ, false for PLY); `flip_normals` negates the normals
//! and keeps the vertex order (`TriangleMesh::flipped`).
//! Extra PLY properties become mesh attributes (`shapes/mesh_attributes.rs`), which the
//! `mesh_attribute` textures of the shape's BSDF and area emitter read.

use super::emitters::area_radiance;
use super::props::Props;
use super::{Builder, Element, MeshScope, SceneError};
use crate::description::{Geometry, ShapeDesc, TriangleMesh};
use crate::parity::media::MediumInterface;
use crate::shapes::mesh_attributes::MeshAttributes;
use crate::shapes::mesh_file::{finish_mesh, flip, transform_mesh, MeshSides};
use crate::texture::Texture;
use glam::{Mat3, Mat4, Vec2, Vec3};

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
                "obj" => crate::shapes::obj::load_obj(&path),
                "ply" => crate::shapes::ply::load_ply(&path),
                _ => crate::shapes::serialized::load_serialized(&path, shape_index),
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

fn reverse_winding(mesh: &mut TriangleMesh) {
    for t in &mut mesh.indices {
        t.swap(1, 2);
    }
}
