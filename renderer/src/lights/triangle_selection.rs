//! Which triangle of a mesh light next-event estimation samples from a point: a tree over the
//! mesh's triangles, four children to a node, each child with the emission bounds of its
//! triangles ([`LightBounds`]), descended from the root by what each child can deliver to the
//! point (pbrt-v4's light BVH, inside one light). At every level the importance is mixed with
//! the children's areas ([`POWER_SHARE`] by area, as Mitsuba picks a triangle at every point),
//! so no triangle's probability can fall to zero where it might light the point.
//!
//! Why: by area alone, a closed emitting mesh spends half its samples on triangles facing away
//! from the point, and a large one (a long tube, a panel curving round a room) most of them on
//! triangles far from it; the few that land where the light comes from carry large weights.

use super::bounds::{bounding_sphere, LightBounds, LightBounds4};
use super::selection::{BELOW_ONE, IMPORTANCE_CAP, POWER_SHARE};
use crate::shapes::{normal_cone, Mesh};
use glam::{Vec3, Vec4};

/// Fewest triangles for which a mesh light chooses its triangles by importance: a rectangle's
/// two lie in one plane and light every point in the same proportion, by area.
pub const MIN_TRIANGLES: usize = 3;

/// Most triangles a mesh light builds its tree for (≈ 80 bytes per triangle); larger emitting
/// meshes choose by area.
pub const MAX_TRIANGLES: usize = 1 << 20;

/// Marks a child that is a triangle (its index in the low bits), not a node.
const TRIANGLE: u32 = 1 << 31;

/// Children that are neither (unused lanes: no area, no importance).
const NONE: u32 = u32::MAX;

/// A node: up to four children with their bounds.
#[derive(Debug, Clone)]
struct Node {
    /// The children's emission bounds.
    bounds: LightBounds4,
    /// The children's areas.
    area: Vec4,
    /// The children: a node index, a triangle (`TRIANGLE` | index) or `NONE`.
    child: [u32; 4],
}

/// The triangles of one mesh light, for choosing one by what it can deliver to a point.
#[derive(Debug, Clone)]
pub struct TriangleSelection {
    /// The tree's nodes, the root first.
    nodes: Vec<Node>,
    /// Each triangle's way down from the root: the child taken at each level, two bits a level,
    /// the root's in the lowest bits.
    trail: Vec<u64>,
    /// Each triangle's area.
    area: Vec<f32>,
}

impl TriangleSelection {
    /// The tree over `mesh`'s triangles, or `None` when the mesh has fewer than
    /// [`MIN_TRIANGLES`] or more than [`MAX_TRIANGLES`] triangles, or no area.
    pub fn new(mesh: &Mesh) -> Option<Self> {
        let count = mesh.triangle_count();
        if !(MIN_TRIANGLES..=MAX_TRIANGLES).contains(&count)
            || mesh.area().is_nan()
            || mesh.area() <= 0.0
        {
            return None;
        }
        let area: Vec<f32> = (0..count as u32).map(|t| mesh.triangle_area(t)).collect();
        let leaves: Vec<LightBounds> = (0..count as u32)
            .map(|t| {
                let [a, b, c] = mesh.triangle(t);
                let (center, radius) = bounding_sphere(a.min(b).min(c), a.max(b).max(c));
                // The radiance is the same scale for every triangle: the area is the intensity.
                let intensity = area[t as usize];
                let (axis, cos_o) = normal_cone(mesh.triangle_normals(t));
                if cos_o <= -1.0 {
                    LightBounds::omnidirectional(center, radius, intensity)
                } else {
                    LightBounds::cone(center, radius, intensity, axis, cos_o, 0.0)
                }
            })
            .collect();
        let mut members: Vec<Member> = (0..count as u32)
            .map(|t| {
                let [a, b, c] = mesh.triangle(t);
                (t, (a + b + c) / 3.0)
            })
            .collect();
        let mut tree = TriangleSelection {
            nodes: Vec::with_capacity(count / 2),
            trail: vec![0; count],
            area,
        };
        tree.build(&mut members, &leaves, 0, 0);
        Some(tree)
    }

    /// Builds the subtree over `members` (triangle, centroid), reached from the root by
    /// `trail` (`level` levels down); returns the child entry for it, its bounds and its area.
    fn build(
        &mut self,
        members: &mut [Member],
        leaves: &[LightBounds],
        level: u32,
        trail: u64,
    ) -> (u32, LightBounds, f32) {
        if let [(t, _)] = members {
            self.trail[*t as usize] = trail;
            return (*t | TRIANGLE, leaves[*t as usize], self.area[*t as usize]);
        }
        let index = self.nodes.len();
        self.nodes.push(Node {
            bounds: LightBounds4::new(&[]),
            area: Vec4::ZERO,
            child: [NONE; 4],
        });
        let (left, right) = halve(members);
        let (a, b) = halve(left);
        let (c, d) = halve(right);
        let mut bounds = Vec::with_capacity(4);
        let mut area = [0.0f32; 4];
        let mut child = [NONE; 4];
        for group in [a, b, c, d] {
            if group.is_empty() {
                continue;
            }
            let lane = bounds.len();
            let (entry, group_bounds, group_area) = self.build(
                group,
                leaves,
                level + 1,
                trail | (lane as u64) << (2 * level),
            );
            child[lane] = entry;
            area[lane] = group_area;
            bounds.push(group_bounds);
        }
        let union = bounds.iter().skip(1).fold(bounds[0], |u, b| u.union(b));
        let total = area.iter().map(|&a| a as f64).sum::<f64>() as f32;
        self.nodes[index] = Node {
            bounds: LightBounds4::new(&bounds),
            area: Vec4::from_array(area),
            child,
        };
        (index as u32, union, total)
    }

    /// Area of triangle `tri`.
    #[inline]
    pub fn triangle_area(&self, tri: u32) -> f32 {
        self.area[tri as usize]
    }

    /// The probabilities of a node's four children at `p` with unit normal `n` (`Vec3::ZERO`:
    /// none): each one's share of the importance scaled to 1 − [`POWER_SHARE`] plus its share
    /// of the area scaled to [`POWER_SHARE`] (by area alone where no child can reach the point
    /// by its bounds).
    #[inline]
    fn shares(node: &Node, p: Vec3, n: Vec3) -> Vec4 {
        let importance = node.bounds.importance(p, n);
        // NaN (a degenerate point) counts as nothing, an overflow as very much.
        let importance = Vec4::select(
            importance.cmpgt(Vec4::ZERO),
            importance.min(Vec4::splat(IMPORTANCE_CAP)),
            Vec4::ZERO,
        );
        let importance_sum = importance.element_sum();
        let area_sum = node.area.element_sum();
        let by_area = if area_sum > 0.0 { 1.0 / area_sum } else { 0.0 };
        if importance_sum > 0.0 && importance_sum.is_finite() {
            importance * ((1.0 - POWER_SHARE) / importance_sum)
                + node.area * (POWER_SHARE * by_area)
        } else {
            node.area * by_area
        }
    }

    /// Picks a triangle for a point `p` with unit normal `n` (`Vec3::ZERO`: none) with `u` in
    /// [0, 1); returns (triangle, probability), or `None` when no triangle can be chosen.
    #[inline]
    pub fn sample(&self, p: Vec3, n: Vec3, mut u: f32) -> Option<(u32, f32)> {
        let mut node = &self.nodes[0];
        let mut pmf = 1.0f32;
        loop {
            let shares = Self::shares(node, p, n).to_array();
            // The first child whose cumulative share passes `u`; rounding can leave `u` past
            // the last one, which then takes it.
            let mut below = 0.0f32;
            let mut chosen = None;
            for (k, &q) in shares.iter().enumerate() {
                if q > 0.0 {
                    chosen = Some((k, below));
                    if u < below + q {
                        break;
                    }
                    below += q;
                }
            }
            let (k, below) = chosen?;
            let q = shares[k];
            u = ((u - below) / q).clamp(0.0, BELOW_ONE);
            pmf *= q;
            let child = node.child[k];
            if child & TRIANGLE != 0 {
                return Some((child & !TRIANGLE, pmf));
            }
            node = &self.nodes[child as usize];
        }
    }

    /// The probability that [`Self::sample`] picks triangle `tri` at `p` with normal `n`.
    #[inline]
    pub fn pmf(&self, p: Vec3, n: Vec3, tri: u32) -> f32 {
        let mut trail = self.trail[tri as usize];
        let mut node = &self.nodes[0];
        let mut pmf = 1.0f32;
        loop {
            let k = (trail & 3) as usize;
            trail >>= 2;
            pmf *= Self::shares(node, p, n)[k];
            let child = node.child[k];
            if child & TRIANGLE != 0 {
                debug_assert_eq!(child & !TRIANGLE, tri);
                return pmf;
            }
            node = &self.nodes[child as usize];
        }
    }
}

/// A triangle with its centroid, as the tree is built.
type Member = (u32, Vec3);

/// Splits `members` into two halves along the longest axis of their centroids (ties by
/// triangle index, so the tree is the same on every run); a single member stays whole.
fn halve(members: &mut [Member]) -> (&mut [Member], &mut [Member]) {
    if members.len() <= 1 {
        return members.split_at_mut(members.len());
    }
    let (lo, hi) = members.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), m| (lo.min(m.1), hi.max(m.1)),
    );
    let axis = (hi - lo).max_position();
    let mid = members.len() / 2;
    members.select_nth_unstable_by(mid, |a, b| {
        a.1[axis].total_cmp(&b.1[axis]).then(a.0.cmp(&b.0))
    });
    members.split_at_mut(mid)
}

/// A closed, faceted torus about +y (`rings` × `sides` quads, two triangles each) centred at
/// the origin, wound outwards (for tests of mesh lights).
#[cfg(test)]
pub(crate) fn torus(
    rings: u32,
    sides: u32,
    big: f32,
    small: f32,
) -> crate::description::TriangleMesh {
    let mut positions = Vec::new();
    for i in 0..rings {
        let a = i as f32 / rings as f32 * std::f32::consts::TAU;
        for j in 0..sides {
            let b = j as f32 / sides as f32 * std::f32::consts::TAU;
            let r = big + small * b.cos();
            positions.push(Vec3::new(r * a.cos(), small * b.sin(), r * a.sin()));
        }
    }
    let at = |i: u32, j: u32| (i % rings) * sides + (j % sides);
    let mut indices = Vec::new();
    for i in 0..rings {
        for j in 0..sides {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            indices.push([a, c, b]);
            indices.push([a, d, c]);
        }
    }
    crate::description::TriangleMesh {
        positions,
        indices,
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::description::TriangleMesh;
    use crate::sampling::rng_for;
    use crate::sampling::UniformSource;

    /// Probabilities sum to one at any point; sampling returns exactly `pmf`'s value and
    /// follows it (chi-square over the triangles); triangles facing away from a point get
    /// little more than their defensive share.
    #[test]
    fn sampling_follows_the_probabilities_and_favours_what_lights_the_point() {
        let mesh = Mesh::from_data(torus(24, 8, 1.0, 0.3));
        let tree = TriangleSelection::new(&mesh).unwrap();
        let count = mesh.triangle_count();
        let mut rng = rng_for(5, 0, 0);
        for trial in 0..6 {
            let p = (rng.next_2d().extend(rng.next_f32()) - 0.5) * 5.0;
            let n = if trial % 2 == 0 {
                Vec3::ZERO
            } else {
                (rng.next_2d().extend(rng.next_f32()) - 0.5).normalize()
            };
            let pmf: Vec<f64> = (0..count as u32)
                .map(|t| tree.pmf(p, n, t) as f64)
                .collect();
            let sum: f64 = pmf.iter().sum();
            assert!((sum - 1.0).abs() < 1e-5, "{p} {n}: sum {sum}");
            let draws = 200_000;
            let mut hist = vec![0u64; count];
            for _ in 0..draws {
                let (t, q) = tree.sample(p, n, rng.next_f32()).unwrap();
                assert_eq!(q.to_bits(), tree.pmf(p, n, t).to_bits());
                hist[t as usize] += 1;
            }
            // Chi-square over cells with an expected count of ≥ 5 (the rest pooled).
            let (mut chi2, mut cells, mut pooled_e, mut pooled_o) = (0.0, 0, 0.0, 0.0);
            for (t, &o) in hist.iter().enumerate() {
                let e = pmf[t] * draws as f64;
                if e >= 5.0 {
                    chi2 += (o as f64 - e).powi(2) / e;
                    cells += 1;
                } else {
                    pooled_e += e;
                    pooled_o += o as f64;
                }
            }
            if pooled_e > 0.0 {
                chi2 += (pooled_o - pooled_e).powi(2) / pooled_e.max(1e-9);
                cells += 1;
            }
            // ≈ 5.5 standard deviations above the mean of a chi-square with `cells` − 1
            // degrees of freedom.
            let dof = (cells - 1) as f64;
            assert!(
                chi2 < dof + 5.5 * (2.0 * dof).sqrt(),
                "{p}: chi2 {chi2}, dof {dof}"
            );
        }
        // From a point on the axis above the ring, the upper half of every tube outweighs the
        // lower half that faces away.
        let p = Vec3::new(0.0, 2.0, 0.0);
        let (mut up, mut down) = (0.0, 0.0);
        for t in 0..count as u32 {
            let [a, b, c] = mesh.triangle(t);
            let facing = (b - a).cross(c - a).dot(p - a) > 0.0;
            let q = tree.pmf(p, Vec3::ZERO, t) as f64;
            if facing {
                up += q;
            } else {
                down += q;
            }
        }
        assert!(up > 4.0 * down, "facing {up}, facing away {down}");
    }

    /// Too few or too many triangles, or no area: no tree (chosen by area).
    #[test]
    fn small_and_degenerate_meshes_choose_by_area() {
        let quad = Mesh::from_data(TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        });
        assert!(TriangleSelection::new(&quad).is_none());
        let flat = Mesh::from_data(TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            indices: vec![[0, 1, 2]; 4],
            ..Default::default()
        });
        assert!(TriangleSelection::new(&flat).is_none());
    }
}
