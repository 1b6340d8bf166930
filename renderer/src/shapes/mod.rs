//! Renderable shapes: triangle meshes, analytic spheres, disks and open cylinders. Each shape can be intersected
//! primitive by primitive (for the BVH), describe the local surface at a hit, and be sampled
//! uniformly by area (for area lights and photon emission).
//!
//! The mesh-file loaders live here too, next to the meshes they build: Wavefront OBJ
//! (`obj.rs`), PLY with its extra properties as mesh attributes (`ply.rs`,
//! `mesh_attributes.rs`) and Mitsuba's `serialized` (`serialized.rs`), each reading a
//! [`mesh_file::RawMesh`] that `mesh_file.rs` turns into a world-space triangle mesh. The XML
//! reader (`xml/shapes.rs`) calls them.

pub mod cylinder;
pub mod disk;
pub mod mesh;
pub(crate) mod mesh_attributes;
pub(crate) mod mesh_file;
pub(crate) mod obj;
pub(crate) mod ply;
pub(crate) mod serialized;
pub mod sphere;

pub use cylinder::Cylinder;
pub use disk::Disk;
pub use mesh::Mesh;
pub use sphere::Sphere;

use crate::description::Geometry;
use crate::math::Ray;
use crate::texture::TexPoint;
use glam::{Vec2, Vec3, Vec3A};

/// Local geometry at a ray hit, before materials and lights are attached.
#[derive(Debug, Clone, Copy)]
pub struct HitGeometry {
    /// Hit position.
    pub p: Vec3,
    /// Unit geometric normal (from the triangle winding / analytic surface, after `flip_normals`).
    pub ng: Vec3,
    /// Unit shading normal (interpolated vertex normal, or `ng`).
    pub ns: Vec3,
    /// Surface tangent ∂p/∂u (not normalised; may be zero when undefined), as Mitsuba's
    /// `dp_du`: its length is what a bump map's height gradient is measured against.
    pub dpdu: Vec3,
    /// Surface tangent ∂p/∂v (not normalised), as Mitsuba's `dp_dv`.
    pub dpdv: Vec3,
    /// Texture coordinates.
    pub uv: Vec2,
    /// Barycentrics (b1, b2) of the hit in its triangle, clamped into it (zero on analytic
    /// shapes): what `mesh_attribute` textures interpolate with.
    pub bary: Vec2,
}

/// A point sampled on a surface.
#[derive(Debug, Clone, Copy)]
pub struct AreaSample {
    /// Position.
    pub p: Vec3,
    /// Unit normal there (interpolated vertex normal for meshes that have them, as Mitsuba): the
    /// side that emits for area lights.
    pub n: Vec3,
    /// Texture coordinates.
    pub uv: Vec2,
    /// Triangle the point lies in (meshes; 0 on analytic shapes).
    pub prim: u32,
    /// Barycentrics (b1, b2) of the point in that triangle (zero on analytic shapes).
    pub bary: Vec2,
    /// Density with respect to surface area.
    pub pdf: f32,
}

impl AreaSample {
    /// Where textures are looked up at the sampled point (an emitter's radiance texture).
    #[inline]
    pub fn tex(&self) -> TexPoint {
        TexPoint::new(self.uv, self.prim, self.bary)
    }
}

/// One shape of the scene.
#[derive(Debug, Clone)]
pub enum Shape {
    /// Triangle mesh.
    Mesh(Mesh),
    /// Analytic sphere.
    Sphere(Sphere),
    /// Analytic disk.
    Disk(Disk),
    /// Analytic open cylinder.
    Cylinder(Cylinder),
}

impl Shape {
    /// Builds the shape from its description, taking over a mesh's data instead of copying it.
    pub fn from_geometry(geometry: Geometry) -> Self {
        match geometry {
            Geometry::Mesh(m) => Shape::Mesh(Mesh::from_data(m)),
            other => Shape::new(&other),
        }
    }

    /// Builds the shape from its description.
    pub fn new(geometry: &Geometry) -> Self {
        match geometry {
            Geometry::Mesh(m) => Shape::Mesh(Mesh::new(m)),
            Geometry::Sphere {
                center,
                radius,
                rotation,
                flip_normals,
            } => {
                Shape::Sphere(Sphere::new(*center, *radius, *flip_normals).with_rotation(*rotation))
            }
            Geometry::Disk {
                to_world,
                flip_normals,
            } => Shape::Disk(Disk::new(*to_world, *flip_normals)),
            Geometry::Cylinder {
                to_world,
                flip_normals,
            } => Shape::Cylinder(
                Cylinder::new(*to_world, *flip_normals)
                    .expect("cylinder transforms are checked by the importer and Scene::build"),
            ),
        }
    }

    /// Number of BVH primitives (triangles for meshes, 1 otherwise).
    pub fn primitive_count(&self) -> usize {
        match self {
            Shape::Mesh(m) => m.triangle_count(),
            _ => 1,
        }
    }

    /// Bounding box (min, max) of primitive `prim`.
    pub fn primitive_bounds(&self, prim: u32) -> (Vec3A, Vec3A) {
        match self {
            Shape::Mesh(m) => m.triangle_bounds(prim),
            Shape::Sphere(s) => s.bounds(),
            Shape::Disk(d) => d.bounds(),
            Shape::Cylinder(c) => c.bounds(),
        }
    }

    /// Bounding box (min, max) of the whole shape.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        (0..self.primitive_count() as u32).fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| {
                let (a, b) = self.primitive_bounds(p);
                (lo.min(a.into()), hi.max(b.into()))
            },
        )
    }

    /// A cone (axis, cos θₒ) containing every normal the surface has (the side it emits from
    /// as an area light); cos θₒ = −1 when they do not fit in a hemisphere.
    pub fn normal_cone(&self) -> (Vec3, f32) {
        match self {
            Shape::Mesh(m) => normal_cone(m.normals()),
            Shape::Disk(d) => (d.normal(), 1.0),
            Shape::Sphere(_) | Shape::Cylinder(_) => (Vec3::Z, -1.0),
        }
    }

    /// Surface area.
    pub fn area(&self) -> f32 {
        match self {
            Shape::Mesh(m) => m.area(),
            Shape::Sphere(s) => s.area(),
            Shape::Disk(d) => d.area(),
            Shape::Cylinder(c) => c.area(),
        }
    }

    /// Local geometry at the hit of `ray` with primitive `prim` at distance `t`; `bary` are a
    /// triangle hit's barycentrics as the intersection test found them (analytic shapes ignore
    /// them).
    #[inline]
    pub fn hit_geometry(&self, prim: u32, ray: &Ray, t: f32, bary: Vec2) -> HitGeometry {
        match self {
            Shape::Mesh(m) => m.hit_geometry_bary(prim, ray, t, bary),
            Shape::Sphere(s) => s.hit_geometry(ray, t),
            Shape::Disk(d) => d.hit_geometry(ray, t),
            Shape::Cylinder(c) => c.hit_geometry(ray, t),
        }
    }

    /// A point distributed uniformly over the surface area, from `u` ∈ [0,1)² (plus a third
    /// number `u_prim` ∈ [0,1) used by meshes to pick a triangle).
    #[inline]
    pub fn sample_area(&self, u_prim: f32, u: Vec2) -> AreaSample {
        match self {
            Shape::Mesh(m) => m.sample_area(u_prim, u),
            Shape::Sphere(s) => s.sample_area(u),
            Shape::Disk(d) => d.sample_area(u),
            Shape::Cylinder(c) => c.sample_area(u),
        }
    }
}

/// The cone about the normalised mean of `normals` that contains them all, as (axis, cos θₒ);
/// (+z, −1) — every direction — when they do not fit in a hemisphere about their mean.
pub fn normal_cone(normals: impl Iterator<Item = Vec3> + Clone) -> (Vec3, f32) {
    let sum: Vec3 = normals.clone().sum();
    let Some(axis) = sum.try_normalize() else {
        return (Vec3::Z, -1.0);
    };
    let cos_o = normals.fold(1.0f32, |c, n| c.min(axis.dot(n)));
    if cos_o <= 0.0 {
        (Vec3::Z, -1.0)
    } else {
        // Rounding of the normals must not put one just outside the cone.
        (axis, (cos_o - 1e-5).max(0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Mat4, Quat};

    /// ∂p/∂u and ∂p/∂v are the derivatives of each analytic shape's parameterisation (what a
    /// bump map's strength is measured against): stepping the hit point by ε·∂p/∂u (and
    /// re-hitting the surface through it from the ray origin) moves uv by (ε, 0), and likewise
    /// for v — on a rotated sphere, a transformed disk and a transformed cylinder, at several
    /// points.
    #[test]
    fn surface_derivatives_are_those_of_the_uv_parameterisation() {
        let rotation = Mat3::from_quat(Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1));
        let transform = Mat4::from_scale_rotation_translation(
            Vec3::new(0.7, 1.3, 0.9),
            Quat::from_euler(glam::EulerRot::XYZ, -0.4, 0.2, 0.9),
            Vec3::new(0.5, -0.2, 0.3),
        );
        // A cylinder's cross-section must stay circular: equal x and y scale.
        let cylinder_transform = Mat4::from_scale_rotation_translation(
            Vec3::new(0.6, 0.6, 1.7),
            Quat::from_euler(glam::EulerRot::XYZ, 0.5, 0.1, -0.8),
            Vec3::new(-0.1, 0.4, 0.2),
        );
        let shapes = [
            (
                "sphere",
                Shape::Sphere(
                    Sphere::new(Vec3::new(0.2, 0.1, -0.3), 0.8, false).with_rotation(rotation),
                ),
            ),
            ("disk", Shape::Disk(Disk::new(transform, false))),
            (
                "cylinder",
                Shape::Cylinder(Cylinder::new(cylinder_transform, false).unwrap()),
            ),
        ];
        let hit = |name: &str, shape: &Shape, o: Vec3, target: Vec3| {
            let ray = Ray::new(o, (target - o).normalize());
            let t = match shape {
                Shape::Sphere(s) => s.intersect(ray.o.into(), ray.d.into(), 0.0, f32::INFINITY),
                Shape::Disk(d) => d.intersect(ray.o.into(), ray.d.into(), 0.0, f32::INFINITY),
                Shape::Cylinder(c) => c.intersect(ray.o.into(), ray.d.into(), 0.0, f32::INFINITY),
                Shape::Mesh(_) => unreachable!(),
            };
            assert!(t.is_finite(), "{name}: {o} towards {target}: no hit");
            shape.hit_geometry(0, &ray, t, Vec2::ZERO)
        };
        let eps = 1e-3;
        let mut checked = 0;
        for (name, shape) in &shapes {
            for i in 0..24 {
                // Points on the surface from area sampling, seen from outside along the normal.
                // (Inside [0.1, 0.9]²: away from the disk's rim.)
                let u = Vec2::new(
                    0.1 + 0.8 * (i as f32 * 0.618_034).fract(),
                    0.1 + 0.8 * (i as f32 * 0.414_214 + 0.1).fract(),
                );
                let s = shape.sample_area(0.0, u);
                let o = s.p + s.n * 2.0;
                let g = hit(name, shape, o, s.p);
                // Keep away from the seams and poles where uv wraps or degenerates.
                if g.uv.x < 0.05 || g.uv.x > 0.95 || g.uv.y < 0.05 || g.uv.y > 0.95 {
                    continue;
                }
                for (d, step) in [(g.dpdu, Vec2::new(eps, 0.0)), (g.dpdv, Vec2::new(0.0, eps))] {
                    let moved = hit(name, shape, o, g.p + d * eps);
                    let duv = moved.uv - g.uv;
                    assert!(
                        (duv - step).length() < 0.03 * eps,
                        "{name} at uv {}: step {step} gave {duv}",
                        g.uv
                    );
                }
                checked += 1;
            }
        }
        assert!(checked > 30, "{checked}");
    }

    #[test]
    fn normal_cones() {
        let flat = [Vec3::Z; 3];
        assert_eq!(normal_cone(flat.iter().copied()), (Vec3::Z, 1.0 - 1e-5));
        let s = 0.5f32.sqrt();
        let (axis, cos_o) = normal_cone([Vec3::new(s, 0.0, s), Vec3::new(-s, 0.0, s)].into_iter());
        assert!((axis - Vec3::Z).length() < 1e-6 && (cos_o - s).abs() < 2e-5);
        let closed = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        assert_eq!(normal_cone(closed.iter().copied()).1, -1.0);
    }
}
