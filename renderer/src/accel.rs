//! Ray–scene acceleration: a small [`Accel`] trait (closest hit, occlusion) and its
//! implementation on the `obvhs` crate's compressed wide BVH (CWBVH; measured faster than its
//! BVH2 here, see BASELINES.md). Primitives are stored in BVH leaf order so traversal needs no
//! index indirection; triangles are pre-transformed to (p0, e1, e2).

use crate::math::Ray;
use crate::shapes::{Disk, Shape, Sphere};
use glam::{UVec2, Vec2, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray as BvhRay;
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
        Self::build_subset(shapes, |_| true)
    }

    /// Builds the BVH over the primitives of the shapes `keep` accepts (by index); hits report
    /// indices into `shapes`, and a primitive's distance and barycentrics are computed exactly as
    /// in a BVH over all shapes.
    pub fn build_subset(shapes: &[Shape], keep: impl Fn(usize) -> bool) -> Self {
        let mut bounds = Vec::new();
        let mut geoms = Vec::new();
        let mut ids = Vec::new();
        let mut disks = Vec::new();
        for (si, shape) in shapes.iter().enumerate().filter(|(i, _)| keep(*i)) {
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
            build_params(bounds.len()),
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

    /// Distance to leaf primitive `i` (+∞ on a miss) and, for triangles, the barycentrics.
    #[inline(always)]
    fn intersect_prim(&self, ray: &BvhRay, i: usize) -> (f32, Vec2) {
        match &self.geoms[i] {
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
                s.intersect(ray.origin, ray.direction, ray.tmin, ray.tmax),
                Vec2::ZERO,
            ),
            PrimGeom::Disk(d) => (
                self.disks[*d as usize].intersect(ray.origin, ray.direction, ray.tmin, ray.tmax),
                Vec2::ZERO,
            ),
        }
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

#[inline]
fn to_bvh_ray(ray: &Ray) -> BvhRay {
    BvhRay::new(Vec3A::from(ray.o), Vec3A::from(ray.d), ray.tmin, ray.tmax)
}

impl CwBvhAccel {
    /// Hit mask of `node`'s children for `ray`, in the layout obvhs's `traverse!` macro expects.
    #[inline(always)]
    fn intersect_node(node: &CwBvhNode, ray: &BvhRay, oct_inv4: u32) -> u32 {
        #[cfg(target_arch = "x86_64")]
        {
            node_simd::intersect(node, ray, oct_inv4)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            node.intersect_ray(ray, oct_inv4)
        }
    }
}

impl Accel for CwBvhAccel {
    fn intersect(&self, ray: &Ray) -> Option<PrimitiveHit> {
        if self.geoms.is_empty() {
            return None;
        }
        // obvhs's `ray_traverse` loop (its `traverse!` macro) with our own child-box test.
        let mut r = to_bvh_ray(ray);
        let mut state = self.bvh.new_traversal(r.direction);
        let mut node;
        let mut closest = u32::MAX;
        let mut bary = Vec2::ZERO;
        obvhs::traverse!(
            self.bvh,
            node,
            state,
            Self::intersect_node(node, &r, state.oct_inv4),
            {
                let (t, b) = self.intersect_prim(&r, state.primitive_id as usize);
                if t < r.tmax {
                    closest = state.primitive_id;
                    bary = b;
                    r.tmax = t;
                }
            }
        );
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
        if self.geoms.is_empty() {
            return false;
        }
        let r = to_bvh_ray(ray);
        let mut state = self.bvh.new_traversal(r.direction);
        let mut node;
        let mut hit = false;
        'traversal: {
            obvhs::traverse!(
                self.bvh,
                node,
                state,
                Self::intersect_node(node, &r, state.oct_inv4),
                {
                    if self.intersect_prim(&r, state.primitive_id as usize).0 < r.tmax {
                        hit = true;
                        break 'traversal;
                    }
                }
            );
        }
        hit
    }
}

/// The CWBVH child-box test with SSE2. The same arithmetic as obvhs's `intersect_ray_simd`
/// (so the same children are visited), but the 8-bit child planes are widened to floats with
/// integer unpacks instead of 48 scalar conversions, and the hit mask is assembled without
/// branches: that is most of the node cost on small scenes.
#[cfg(target_arch = "x86_64")]
mod node_simd {
    use obvhs::cwbvh::node::CwBvhNode;
    use obvhs::ray::Ray;
    use std::arch::x86_64::*;

    /// obvhs's lower clamp of the box-entry distance (its `EPSILON`).
    const TMIN_CLAMP: f32 = 0.0001;

    /// The 8 quantised planes `v` as two vectors of 4 floats.
    #[inline(always)]
    fn widen(v: &[u8; 8]) -> (__m128, __m128) {
        // SAFETY: SSE2 is part of the x86_64 baseline; the load reads exactly the 8 bytes of `v`.
        unsafe {
            let b = _mm_loadl_epi64(v.as_ptr() as *const __m128i);
            let zero = _mm_setzero_si128();
            let w = _mm_unpacklo_epi8(b, zero);
            (
                _mm_cvtepi32_ps(_mm_unpacklo_epi16(w, zero)),
                _mm_cvtepi32_ps(_mm_unpackhi_epi16(w, zero)),
            )
        }
    }

    /// Entry/exit distances along one axis for 4 children: `q·scale + offset` (mul then add,
    /// not fused, as obvhs).
    #[inline(always)]
    fn slab(near: __m128, far: __m128, scale: __m128, offset: __m128) -> (__m128, __m128) {
        // SAFETY: SSE2 arithmetic on registers.
        unsafe {
            (
                _mm_add_ps(_mm_mul_ps(near, scale), offset),
                _mm_add_ps(_mm_mul_ps(far, scale), offset),
            )
        }
    }

    /// Hit mask of the node's children (internal children in the high byte, leaf primitives
    /// in the low 24 bits), as `CwBvhNode::intersect_ray`.
    #[inline(always)]
    pub fn intersect(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
        let scale = node.compute_extent() * ray.inv_direction;
        let offset = (glam::Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
        let (lo_x, hi_x) = (widen(&node.child_min_x), widen(&node.child_max_x));
        let (lo_y, hi_y) = (widen(&node.child_min_y), widen(&node.child_max_y));
        let (lo_z, hi_z) = (widen(&node.child_min_z), widen(&node.child_max_z));
        // Near/far planes by the sign of the direction.
        let (nx, fx) = if ray.direction.x < 0.0 {
            (hi_x, lo_x)
        } else {
            (lo_x, hi_x)
        };
        let (ny, fy) = if ray.direction.y < 0.0 {
            (hi_y, lo_y)
        } else {
            (lo_y, hi_y)
        };
        let (nz, fz) = if ray.direction.z < 0.0 {
            (hi_z, lo_z)
        } else {
            (lo_z, hi_z)
        };
        // SAFETY: SSE2 arithmetic on registers.
        let mask = unsafe {
            let (sx, sy, sz) = (
                _mm_set1_ps(scale.x),
                _mm_set1_ps(scale.y),
                _mm_set1_ps(scale.z),
            );
            let (ox, oy, oz) = (
                _mm_set1_ps(offset.x),
                _mm_set1_ps(offset.y),
                _mm_set1_ps(offset.z),
            );
            let clamp_min = _mm_set1_ps(TMIN_CLAMP);
            let clamp_max = _mm_set1_ps(ray.tmax);
            let half = |n: (__m128, __m128, __m128), f: (__m128, __m128, __m128)| {
                let (tmin_x, tmax_x) = slab(n.0, f.0, sx, ox);
                let (tmin_y, tmax_y) = slab(n.1, f.1, sy, oy);
                let (tmin_z, tmax_z) = slab(n.2, f.2, sz, oz);
                let tmin = _mm_max_ps(tmin_x, _mm_max_ps(tmin_y, tmin_z));
                let tmax = _mm_min_ps(tmax_x, _mm_min_ps(tmax_y, tmax_z));
                let tmin = _mm_max_ps(tmin, clamp_min);
                let tmax = _mm_min_ps(tmax, clamp_max);
                _mm_movemask_ps(_mm_cmple_ps(tmin, tmax)) as u32
            };
            half((nx.0, ny.0, nz.0), (fx.0, fy.0, fz.0))
                | (half((nx.1, ny.1, nz.1), (fx.1, fy.1, fz.1)) << 4)
        };
        let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
        let mut hit_mask = 0u32;
        for child in 0..8 {
            let keep = ((mask >> child) & 1).wrapping_neg();
            let bits = ((child_bits8 >> (child * 8)) as u32) & 0xff;
            let index = ((bit_index8 >> (child * 8)) as u32) & 0xff;
            hit_mask |= (bits << index) & keep;
        }
        hit_mask
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
