//! Ray–scene acceleration: a small [`Accel`] trait (closest hit, occlusion) and its
//! implementation, [`Bvh4Accel`]: a hierarchy built by the `obvhs` crate (BVH2: PLOC,
//! reinsertion, SAH leaf collapse) and collapsed into 4-wide nodes with full-precision boxes
//! ([`bvh4`]), which traverse faster on a CPU than obvhs's compressed 8-wide CWBVH
//! (docs/performance.md). Primitives are stored in BVH leaf order so traversal needs no index
//! indirection; triangles are pre-transformed to (p0, e1, e2).

use crate::math::Ray;
use crate::shapes::{Cylinder, Disk, Shape, Sphere};
use anyhow::{bail, Result};
use glam::{Vec2, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use obvhs::ray::Ray as BvhRay;
use obvhs::BvhBuildParams;
use std::time::Duration;

mod bvh4;

/// The closest intersection found by an [`Accel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrimitiveHit {
    /// Index of the shape in the scene.
    pub shape: u32,
    /// Primitive within the shape (triangle index; 0 for analytic shapes).
    pub prim: u32,
    /// Distance along the ray.
    pub t: f32,
    /// Barycentric coordinates (b1, b2) of a triangle hit (zero for analytic shapes).
    pub bary: Vec2,
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
    /// An analytic sphere (index into [`Analytic::spheres`]: kept out of line so that a
    /// primitive is one 64-byte triangle, not a ~100-byte sphere).
    Sphere(u32),
    /// An analytic disk (index into [`Analytic::disks`], which are large).
    Disk(u32),
    /// An analytic open cylinder (index into [`Analytic::cylinders`]).
    Cylinder(u32),
}

/// The analytic shapes [`PrimGeom`] refers to by index.
#[derive(Debug, Clone, Default)]
struct Analytic {
    /// Spheres.
    spheres: Vec<Sphere>,
    /// Disks.
    disks: Vec<Disk>,
    /// Open cylinders.
    cylinders: Vec<Cylinder>,
}

/// The primitives of the shapes `keep` accepts, in scene order.
struct Gathered {
    /// The box of each primitive.
    bounds: Vec<Aabb>,
    /// (shape, primitive) of each primitive.
    ids: Vec<(u32, u32)>,
    /// The analytic shapes among them, in scene order.
    analytic: Analytic,
    /// Per shape, its index in the `analytic` list of its kind (unused for meshes).
    analytic_index: Vec<u32>,
}

/// Collects the primitives of the shapes `keep` accepts (see [`Gathered`]). Their geometry is
/// made later, in BVH order ([`Gathered::geom`]): a second copy in scene order cost 64 bytes
/// per triangle during the build.
fn gather(shapes: &[Shape], keep: impl Fn(usize) -> bool) -> Gathered {
    let count = shapes
        .iter()
        .enumerate()
        .filter(|(i, _)| keep(*i))
        .map(|(_, s)| s.primitive_count())
        .sum();
    let mut g = Gathered {
        bounds: Vec::with_capacity(count),
        ids: Vec::with_capacity(count),
        analytic: Analytic::default(),
        analytic_index: vec![0; shapes.len()],
    };
    for (si, shape) in shapes.iter().enumerate().filter(|(i, _)| keep(*i)) {
        for prim in 0..shape.primitive_count() as u32 {
            let (min, max) = shape.primitive_bounds(prim);
            g.bounds.push(Aabb::new(min, max));
            g.ids.push((si as u32, prim));
            let analytic = &mut g.analytic;
            let index = match shape {
                Shape::Mesh(_) => continue,
                Shape::Sphere(s) => {
                    analytic.spheres.push(*s);
                    analytic.spheres.len()
                }
                Shape::Disk(d) => {
                    analytic.disks.push(*d);
                    analytic.disks.len()
                }
                Shape::Cylinder(c) => {
                    analytic.cylinders.push(*c);
                    analytic.cylinders.len()
                }
            };
            g.analytic_index[si] = index as u32 - 1;
        }
    }
    g
}

impl Gathered {
    /// The geometry of primitive `prim` of shape `shape` (one of the gathered primitives).
    fn geom(&self, shapes: &[Shape], (shape, prim): (u32, u32)) -> PrimGeom {
        let index = self.analytic_index[shape as usize];
        match &shapes[shape as usize] {
            Shape::Mesh(m) => {
                let [a, b, c] = m.triangle(prim);
                let p0 = Vec3A::from(a);
                PrimGeom::Triangle {
                    p0,
                    e1: Vec3A::from(b) - p0,
                    e2: Vec3A::from(c) - p0,
                }
            }
            Shape::Sphere(_) => PrimGeom::Sphere(index),
            Shape::Disk(_) => PrimGeom::Disk(index),
            Shape::Cylinder(_) => PrimGeom::Cylinder(index),
        }
    }
}

/// Distance along `ray` to `geom` (+∞ on a miss) and, for triangles, the barycentrics.
#[inline(always)]
fn intersect_geom(geom: &PrimGeom, analytic: &Analytic, ray: &BvhRay) -> (f32, Vec2) {
    match geom {
        PrimGeom::Triangle { p0, e1, e2 } => crate::shapes::mesh::intersect_triangle_bary(
            ray.origin,
            ray.direction,
            ray.tmin,
            ray.tmax,
            *p0,
            *e1,
            *e2,
        ),
        PrimGeom::Sphere(s) => (
            analytic.spheres[*s as usize].intersect(ray.origin, ray.direction, ray.tmin, ray.tmax),
            Vec2::ZERO,
        ),
        PrimGeom::Disk(d) => (
            analytic.disks[*d as usize].intersect(ray.origin, ray.direction, ray.tmin, ray.tmax),
            Vec2::ZERO,
        ),
        PrimGeom::Cylinder(c) => (
            analytic.cylinders[*c as usize].intersect(
                ray.origin,
                ray.direction,
                ray.tmin,
                ray.tmax,
            ),
            Vec2::ZERO,
        ),
    }
}

/// [`Accel`] on a 4-wide BVH with full-precision boxes ([`bvh4`]), collapsed from obvhs's BVH2.
pub struct Bvh4Accel {
    /// The hierarchy; leaf primitive `i` is `geoms[i]`.
    nodes: Vec<bvh4::Node4>,
    /// Primitive geometry in BVH order.
    geoms: Vec<PrimGeom>,
    /// (shape, primitive) of each entry of `geoms`.
    ids: Vec<(u32, u32)>,
    /// Spheres and disks referenced by [`PrimGeom`].
    analytic: Analytic,
}

impl Bvh4Accel {
    /// Builds the BVH over every primitive of `shapes`.
    pub fn build(shapes: &[Shape]) -> Result<Self> {
        Self::build_subset(shapes, |_| true)
    }

    /// Builds the BVH over the primitives of the shapes `keep` accepts (by index); hits report
    /// indices into `shapes`, and a primitive's distance and barycentrics are computed exactly as
    /// in a BVH over all shapes.
    pub fn build_subset(shapes: &[Shape], keep: impl Fn(usize) -> bool) -> Result<Self> {
        let mut gathered = gather(shapes, keep);
        let count = gathered.ids.len();
        if count == 0 {
            return Ok(Bvh4Accel {
                nodes: Vec::new(),
                geoms: Vec::new(),
                ids: Vec::new(),
                analytic: gathered.analytic,
            });
        }
        if count >= bvh4::MAX_PRIMITIVES {
            bail!(
                "the scene has {count} primitives; the BVH holds at most {}",
                bvh4::MAX_PRIMITIVES - 1
            );
        }
        let params = BvhBuildParams {
            max_prims_per_leaf: LEAF_SIZE,
            ..build_params(count)
        };
        // Each temporary is freed as soon as it is used, before the next large allocation.
        let mut entries = bvh4::BuildEntries::new(std::mem::take(&mut gathered.bounds));
        let bvh2 = build_bvh2(&entries.boxes, params, &mut Duration::default());
        if bvh2.primitive_indices.len() != entries.boxes.len() {
            bail!(
                "BVH build lost primitives ({} of {})",
                bvh2.primitive_indices.len(),
                entries.boxes.len()
            );
        }
        // The collapse reads the BVH2's boxes, not the entries'.
        entries.boxes = Vec::new();
        let bvh4::Collapsed {
            nodes,
            order,
            depth,
            ..
        } = bvh4::collapse(&bvh2, &entries);
        drop((bvh2, entries));
        // Closest-hit traversal pops one entry and pushes at most four per level.
        if 3 * depth + 1 > bvh4::STACK_SIZE {
            bail!(
                "the BVH is {depth} levels deep; traversal supports {} (degenerate geometry?)",
                (bvh4::STACK_SIZE - 1) / 3
            );
        }
        debug_assert_eq!(order.len(), count);
        let ids: Vec<(u32, u32)> = order.iter().map(|&i| gathered.ids[i as usize]).collect();
        drop(order);
        gathered.ids = Vec::new();
        let geoms = ids.iter().map(|&id| gathered.geom(shapes, id)).collect();
        Ok(Bvh4Accel {
            nodes,
            geoms,
            ids,
            analytic: gathered.analytic,
        })
    }

    /// Number of primitives.
    pub fn primitive_count(&self) -> usize {
        self.geoms.len()
    }

    /// Distance to leaf primitive `i` (+∞ on a miss) and, for triangles, the barycentrics.
    #[inline(always)]
    fn intersect_prim(&self, ray: &BvhRay, i: usize) -> (f32, Vec2) {
        intersect_geom(&self.geoms[i], &self.analytic, ray)
    }
}

/// Most primitives in one BVH4 leaf. On Mitsuba's Cornell box (`bench_path`, 1 thread):
/// 1 → 0.81 M samples/s, 2 → 0.84 M, 3 → 0.84 M, 4 → 0.70 M (larger leaves are chosen by the
/// SAH collapse and cost more triangle tests than they save node tests).
const LEAF_SIZE: u32 = 2;

impl Accel for Bvh4Accel {
    fn intersect(&self, ray: &Ray) -> Option<PrimitiveHit> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut r = to_bvh_ray(ray);
        let box_ray = bvh4::simd::BoxRay::new(r.origin, r.inv_direction, r.tmin);
        let mut stack = bvh4::TraversalStack::new((0u32, 0.0f32));
        let mut closest = u32::MAX;
        let mut bary = Vec2::ZERO;
        while let Some((node, tnear)) = stack.pop() {
            if tnear >= r.tmax {
                continue;
            }
            let node = &self.nodes[node as usize];
            let (t, mut mask) = box_ray.test(node, r.tmax);
            // Leaves are tested at once; inner children go on the stack, farthest first.
            let mut pending = [(0u32, 0.0f32); 4];
            let mut n = 0;
            while mask != 0 {
                let slot = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                match bvh4::decode(node.child[slot]) {
                    bvh4::Child::Leaf { first, count } => {
                        for i in first..first + count {
                            let (ti, b) = self.intersect_prim(&r, i as usize);
                            if ti < r.tmax {
                                closest = i;
                                bary = b;
                                r.tmax = ti;
                            }
                        }
                    }
                    bvh4::Child::Node(c) => {
                        // Insertion by descending entry distance.
                        let mut j = n;
                        while j > 0 && pending[j - 1].1 < t[slot] {
                            pending[j] = pending[j - 1];
                            j -= 1;
                        }
                        pending[j] = (c, t[slot]);
                        n += 1;
                    }
                }
            }
            for &entry in &pending[..n] {
                stack.push(entry);
            }
        }
        if closest == u32::MAX {
            return None;
        }
        let (shape, prim) = self.ids[closest as usize];
        Some(PrimitiveHit {
            shape,
            prim,
            t: r.tmax,
            bary,
        })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let r = to_bvh_ray(ray);
        let box_ray = bvh4::simd::BoxRay::new(r.origin, r.inv_direction, r.tmin);
        let mut stack = bvh4::TraversalStack::new(0u32);
        while let Some(node) = stack.pop() {
            let node = &self.nodes[node as usize];
            let (_, mut mask) = box_ray.test(node, r.tmax);
            while mask != 0 {
                let slot = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                match bvh4::decode(node.child[slot]) {
                    bvh4::Child::Leaf { first, count } => {
                        for i in first..first + count {
                            if self.intersect_prim(&r, i as usize).0 < r.tmax {
                                return true;
                            }
                        }
                    }
                    bvh4::Child::Node(c) => stack.push(c),
                }
            }
        }
        false
    }
}

/// BVH build settings for `n` primitives. Reinsertion (moving subtrees to where they cost the
/// least SAH) over the whole tree is the quality lever that pays here: on Mitsuba's Cornell box
/// it made the path tracer 7 % faster than obvhs's `medium_build` (5 % of all nodes). It costs
/// build time that grows with the primitive count, so large meshes keep the medium setting.
/// Spatial pre-splits need triangles, not boxes, and stay off.
fn build_params(n: usize) -> BvhBuildParams {
    if n <= 200_000 {
        BvhBuildParams {
            pre_split: false,
            ..BvhBuildParams::very_slow_build()
        }
    } else {
        BvhBuildParams::medium_build()
    }
}

/// The ray in obvhs's form. The inverse direction is obvhs's `safe_inverse` per component
/// (±1/ε for |d| ≤ ε, the same values), computed as one vector division instead of three
/// branchy scalar ones.
#[inline]
fn to_bvh_ray(ray: &Ray) -> BvhRay {
    let d = Vec3A::from(ray.d);
    let safe = d.abs().max(Vec3A::splat(f32::EPSILON)).copysign(d);
    BvhRay {
        origin: Vec3A::from(ray.o),
        direction: d,
        inv_direction: Vec3A::ONE / safe,
        tmin: ray.tmin,
        tmax: ray.tmax,
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
            flipped: false,
        };
        let shapes = vec![
            Shape::Sphere(Sphere::new(Vec3::new(0.0, 0.0, 6.0), 1.0, false)),
            Shape::Mesh(Mesh::new(&quad)),
        ];
        let accel = Bvh4Accel::build(&shapes).unwrap();
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

    /// A soup of `n` small random triangles in the cube [-1, 1]³, plus spheres, a disk and a
    /// cylinder.
    fn random_scene(n: usize, rng: &mut crate::sampling::Pcg32) -> Vec<Shape> {
        use crate::sampling::UniformSource;
        let mut p = |s: f32| {
            Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 * s - Vec3::splat(s)
        };
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for i in 0..n as u32 {
            let c = p(1.0);
            positions.extend([c + p(0.15), c + p(0.15), c + p(0.15)]);
            indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        let soup = TriangleMesh {
            positions,
            normals: None,
            uvs: None,
            indices,
            flipped: false,
        };
        vec![
            Shape::Mesh(Mesh::new(&soup)),
            Shape::Sphere(Sphere::new(Vec3::new(0.3, -0.2, 0.1), 0.25, false)),
            Shape::Sphere(Sphere::new(Vec3::new(-0.6, 0.5, -0.4), 0.1, true)),
            Shape::Disk(Disk::new(
                glam::Mat4::from_scale_rotation_translation(
                    Vec3::splat(0.4),
                    glam::Quat::from_rotation_x(0.7),
                    Vec3::new(0.0, 0.6, 0.2),
                ),
                false,
            )),
            Shape::Cylinder(
                Cylinder::new(
                    glam::Mat4::from_scale_rotation_translation(
                        Vec3::new(0.2, 0.2, 0.9),
                        glam::Quat::from_rotation_y(0.9),
                        Vec3::new(-0.5, -0.3, -0.4),
                    ),
                    false,
                )
                .unwrap(),
            ),
        ]
    }

    /// Every primitive of `shapes` in scene order: geometry, (shape, primitive) ids and the
    /// analytic shapes the geometry refers to.
    fn scene_order(shapes: &[Shape]) -> (Vec<PrimGeom>, Vec<(u32, u32)>, Analytic) {
        let g = gather(shapes, |_| true);
        let geoms = g.ids.iter().map(|&id| g.geom(shapes, id)).collect();
        (geoms, g.ids, g.analytic)
    }

    /// The closest hit of `ray` by testing every primitive in scene order: (distance, index),
    /// or (+∞, `usize::MAX`) on a miss.
    fn brute_force(geoms: &[PrimGeom], analytic: &Analytic, ray: &Ray) -> (f32, usize) {
        let mut r = to_bvh_ray(ray);
        let mut best = (f32::INFINITY, usize::MAX);
        for (i, g) in geoms.iter().enumerate() {
            let t = intersect_geom(g, analytic, &r).0;
            if t < r.tmax {
                best = (t, i);
                r.tmax = t;
            }
        }
        best
    }

    /// Closest hit and occlusion agree with testing every primitive (the same primitive
    /// routine, so the distances are bit-identical), for rays starting inside and outside the
    /// geometry, long and short, and with axis-parallel directions.
    #[test]
    fn traversal_matches_brute_force() {
        use crate::sampling::UniformSource;
        let mut rng = crate::sampling::rng_for(7, 0, 0);
        for n in [1, 3, 40, 3000] {
            let shapes = random_scene(n, &mut rng);
            let accel = Bvh4Accel::build(&shapes).unwrap();
            let (geoms, ids, analytic) = scene_order(&shapes);
            for k in 0..4000 {
                let o = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0
                    - Vec3::ONE)
                    * if k % 2 == 0 { 1.0 } else { 3.0 };
                let mut d =
                    Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
                if k % 7 == 0 {
                    d = Vec3::ZERO
                        .with_x(1.0)
                        .with_y(if k % 14 == 0 { 0.0 } else { -0.5 });
                }
                let mut ray = Ray::new(o, d.normalize());
                if k % 3 == 0 {
                    ray.tmax = rng.next_f32() * 2.0;
                }
                let br = to_bvh_ray(&ray);
                let best = brute_force(&geoms, &analytic, &ray);
                let hit = accel.intersect(&ray);
                match hit {
                    None => assert_eq!(best.1, usize::MAX, "missed a hit, n = {n}, ray {k}"),
                    Some(h) => {
                        assert_eq!(h.t, best.0, "n = {n}, ray {k}");
                        // Equal distances may belong to different primitives (shared edges).
                        let (s, p) = ids[best.1];
                        if (h.shape, h.prim) != (s, p) {
                            let other =
                                geoms[ids.iter().position(|&x| x == (h.shape, h.prim)).unwrap()];
                            assert_eq!(intersect_geom(&other, &analytic, &br).0, h.t);
                        }
                    }
                }
                assert_eq!(
                    accel.occluded(&ray),
                    best.1 != usize::MAX,
                    "n = {n}, ray {k}"
                );
            }
        }
    }

    /// Many primitives with one box (a triangle repeated 50 000 times, among a soup) build in
    /// one entry (obvhs's PLOC needed hours for such a set) and still report every hit: the
    /// set becomes a subtree of leaves under its box.
    #[test]
    fn repeated_primitives_build_fast_and_hit() {
        use crate::sampling::UniformSource;
        let mut rng = crate::sampling::rng_for(9, 0, 0);
        let mut shapes = random_scene(300, &mut rng);
        let copies = 50_000u32;
        let tri = TriangleMesh {
            positions: vec![
                Vec3::new(-0.5, -0.5, 0.2),
                Vec3::new(0.5, -0.5, 0.2),
                Vec3::new(0.0, 0.5, 0.2),
            ],
            normals: None,
            uvs: None,
            indices: vec![[0, 1, 2]; copies as usize],
            flipped: false,
        };
        shapes.push(Shape::Mesh(Mesh::new(&tri)));
        // Before the grouping this build took minutes (quadratic in the copies).
        let accel = Bvh4Accel::build(&shapes).unwrap();
        assert_eq!(accel.primitive_count(), 300 + 4 + copies as usize);
        let (geoms, _, analytic) = scene_order(&shapes);
        for k in 0..200 {
            let o = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 2.0);
            let ray = Ray::new(o, Vec3::new(0.1 * rng.next_f32(), 0.0, -1.0).normalize());
            let best = brute_force(&geoms, &analytic, &ray).0;
            let hit = accel.intersect(&ray).map_or(f32::INFINITY, |h| h.t);
            assert_eq!(hit, best, "ray {k}");
            assert_eq!(accel.occluded(&ray), best < f32::INFINITY, "ray {k}");
        }
        // Every copy is reachable: a ray through the repeated triangle alone hits one of them.
        let h = accel
            .intersect(&Ray::new(Vec3::new(0.0, -0.1, 0.25), -Vec3::Z))
            .unwrap();
        assert_eq!(h.shape as usize, shapes.len() - 1);
    }

    #[test]
    fn inverse_direction_equals_obvhs_safe_inverse() {
        use crate::sampling::UniformSource;
        let mut rng = crate::sampling::rng_for(4, 0, 0);
        let tiny = f32::EPSILON;
        let specials = [
            0.0,
            -0.0,
            tiny,
            -tiny,
            0.5 * tiny,
            -0.5 * tiny,
            2.0 * tiny,
            1.0,
            -1.0,
        ];
        for k in 0..5000 {
            let mut d = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
            if k < specials.len() * 3 {
                d[k % 3] = specials[k / 3];
            }
            let mut ray = Ray::new(Vec3::ZERO, Vec3::X);
            ray.d = d;
            let ours = to_bvh_ray(&ray).inv_direction;
            let theirs = BvhRay::new(Vec3A::ZERO, Vec3A::from(d), 0.0, 1.0).inv_direction;
            assert_eq!(
                ours.to_array().map(f32::to_bits),
                theirs.to_array().map(f32::to_bits),
                "d = {d}"
            );
        }
    }

    /// An empty scene and an emitter subset with nothing in it build and miss everything.
    #[test]
    fn empty_hierarchies_miss() {
        let mut rng = crate::sampling::rng_for(3, 0, 0);
        let shapes = random_scene(5, &mut rng);
        for accel in [
            Bvh4Accel::build(&[]).unwrap(),
            Bvh4Accel::build_subset(&shapes, |_| false).unwrap(),
        ] {
            let ray = Ray::new(Vec3::ZERO, Vec3::Z);
            assert!(accel.intersect(&ray).is_none());
            assert!(!accel.occluded(&ray));
        }
    }
}
