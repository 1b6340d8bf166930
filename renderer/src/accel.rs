//! Ray–scene acceleration: a small [`Accel`] trait (closest hit, occlusion) and its
//! implementation on the `obvhs` crate's compressed wide BVH (CWBVH; measured faster than its
//! BVH2 here, see BASELINES.md). Primitives are stored in BVH leaf order so traversal needs no
//! index indirection; triangles are pre-transformed to (p0, e1, e2).

use crate::math::Ray;
use crate::shapes::{Disk, Shape, Sphere};
use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray as BvhRay, RayHit};
use obvhs::BvhBuildParams;
use std::time::Duration;

/// The closest intersection found by an [`Accel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrimitiveHit {
    /// Index of the shape in the scene.
    pub shape: u32,
    /// Primitive within the shape (triangle index; 0 for analytic shapes).
    pub prim: u32,
    /// Distance along the ray.
    pub t: f32,
}

/// A ray-tracing acceleration structure over the scene's primitives.
pub trait Accel: Send + Sync {
    /// The closest hit with `ray.tmin < t < ray.tmax`, if any.
    fn intersect(&self, ray: &Ray) -> Option<PrimitiveHit>;
    /// Whether anything is hit with `ray.tmin < t < ray.tmax` (shadow rays; stops at the first hit).
    fn occluded(&self, ray: &Ray) -> bool;
}

/// Geometry of one primitive as the traversal loop needs it.
#[derive(Debug, Clone, Copy)]
enum PrimGeom {
    /// A triangle as its first vertex and two edges.
    Triangle { p0: Vec3A, e1: Vec3A, e2: Vec3A },
    /// An analytic sphere.
    Sphere(Sphere),
    /// An analytic disk (index into [`CwBvhAccel::disks`], which are large).
    Disk(u32),
}

/// [`Accel`] on obvhs's CWBVH (8-wide, compressed nodes).
pub struct CwBvhAccel {
    /// The hierarchy; leaf primitive `i` is `geoms[i]`.
    bvh: CwBvh,
    /// Primitive geometry in BVH order.
    geoms: Vec<PrimGeom>,
    /// (shape, primitive) of each entry of `geoms`.
    ids: Vec<(u32, u32)>,
    /// Disks referenced by [`PrimGeom::Disk`].
    disks: Vec<Disk>,
}

impl CwBvhAccel {
    /// Builds the BVH over every primitive of `shapes`.
    pub fn build(shapes: &[Shape]) -> Self {
        let mut bounds = Vec::new();
        let mut geoms = Vec::new();
        let mut ids = Vec::new();
        let mut disks = Vec::new();
        for (si, shape) in shapes.iter().enumerate() {
            for prim in 0..shape.primitive_count() as u32 {
                let (min, max) = shape.primitive_bounds(prim);
                bounds.push(Aabb::new(min, max));
                ids.push((si as u32, prim));
                geoms.push(match shape {
                    Shape::Mesh(m) => {
                        let [a, b, c] = m.triangle(prim);
                        let p0 = Vec3A::from(a);
                        PrimGeom::Triangle {
                            p0,
                            e1: Vec3A::from(b) - p0,
                            e2: Vec3A::from(c) - p0,
                        }
                    }
                    Shape::Sphere(s) => PrimGeom::Sphere(*s),
                    Shape::Disk(d) => {
                        disks.push(*d);
                        PrimGeom::Disk(disks.len() as u32 - 1)
                    }
                });
            }
        }
        if bounds.is_empty() {
            return CwBvhAccel {
                bvh: CwBvh::default(),
                geoms,
                ids,
                disks,
            };
        }
        let bvh = build_cwbvh(
            &bounds,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        // Reorder primitives into leaf order so traversal indexes them directly.
        let geoms = bvh
            .primitive_indices
            .iter()
            .map(|&i| geoms[i as usize])
            .collect();
        let ids = bvh
            .primitive_indices
            .iter()
            .map(|&i| ids[i as usize])
            .collect();
        CwBvhAccel {
            bvh,
            geoms,
            ids,
            disks,
        }
    }

    /// Number of primitives.
    pub fn primitive_count(&self) -> usize {
        self.geoms.len()
    }

    #[inline(always)]
    fn intersect_prim(&self, ray: &BvhRay, i: usize) -> f32 {
        match &self.geoms[i] {
            PrimGeom::Triangle { p0, e1, e2 } => crate::shapes::mesh::intersect_triangle(
                ray.origin,
                ray.direction,
                ray.tmin,
                ray.tmax,
                *p0,
                *e1,
                *e2,
            ),
            PrimGeom::Sphere(s) => s.intersect(ray.origin, ray.direction, ray.tmin, ray.tmax),
            PrimGeom::Disk(d) => {
                self.disks[*d as usize].intersect(ray.origin, ray.direction, ray.tmin, ray.tmax)
            }
        }
    }
}

#[inline]
fn to_bvh_ray(ray: &Ray) -> BvhRay {
    BvhRay::new(Vec3A::from(ray.o), Vec3A::from(ray.d), ray.tmin, ray.tmax)
}

impl Accel for CwBvhAccel {
    fn intersect(&self, ray: &Ray) -> Option<PrimitiveHit> {
        if self.geoms.is_empty() {
            return None;
        }
        let r = to_bvh_ray(ray);
        let mut hit = RayHit::none();
        if self
            .bvh
            .ray_traverse(r, &mut hit, |r, i| self.intersect_prim(r, i))
        {
            let (shape, prim) = self.ids[hit.primitive_id as usize];
            Some(PrimitiveHit {
                shape,
                prim,
                t: hit.t,
            })
        } else {
            None
        }
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if self.geoms.is_empty() {
            return false;
        }
        !self
            .bvh
            .ray_traverse_miss(to_bvh_ray(ray), |r, i| self.intersect_prim(r, i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::description::TriangleMesh;
    use crate::shapes::Mesh;
    use glam::Vec3;

    #[test]
    fn closest_hit_over_mixed_shapes() {
        // A quad at z = 3 and a sphere at z = 6 (radius 1), both on the +z axis.
        let quad = TriangleMesh {
            positions: vec![
                Vec3::new(-1.0, -1.0, 3.0),
                Vec3::new(1.0, -1.0, 3.0),
                Vec3::new(1.0, 1.0, 3.0),
                Vec3::new(-1.0, 1.0, 3.0),
            ],
            normals: None,
            uvs: None,
            indices: vec![[0, 1, 2], [0, 2, 3]],
        };
        let shapes = vec![
            Shape::Sphere(Sphere::new(Vec3::new(0.0, 0.0, 6.0), 1.0, false)),
            Shape::Mesh(Mesh::new(&quad)),
        ];
        let accel = CwBvhAccel::build(&shapes);
        let h = accel
            .intersect(&Ray::new(Vec3::new(0.2, 0.1, 0.0), Vec3::Z))
            .unwrap();
        assert_eq!(h.shape, 1);
        assert!((h.t - 3.0).abs() < 1e-5);
        // Starting past the quad: the sphere.
        let h = accel
            .intersect(&Ray::new(Vec3::new(0.0, 0.0, 4.0), Vec3::Z))
            .unwrap();
        assert_eq!((h.shape, h.prim), (0, 0));
        assert!((h.t - 1.0).abs() < 1e-5);
        // Sideways: nothing.
        assert!(accel.intersect(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
        let mut short = Ray::new(Vec3::ZERO, Vec3::Z);
        short.tmax = 2.5;
        assert!(!accel.occluded(&short));
        short.tmax = 3.5;
        assert!(accel.occluded(&short));
    }
}
