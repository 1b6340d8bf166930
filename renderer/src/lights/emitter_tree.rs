//! Choosing one of many emitters — the lights of a scene, the triangles of a mesh light — by
//! what each can deliver to a point, in logarithmic time: a tree over the emitters, four
//! children to a node, each child with the union of its emitters' emission bounds
//! ([`LightBounds`]), descended from the root by the children's importance at the point
//! (pbrt-v4's light BVH). At every level the importance is mixed with the children's weights
//! ([`POWER_SHARE`] by weight: power for lights, area for triangles), so no emitter's
//! probability falls to zero where it might light the point.
//!
//! Why: by power or area alone, a closed emitting mesh spends half its samples on triangles
//! facing away from the point, a large one (a long tube, a panel round a room) most of them on
//! triangles far from it, and a scene with hundreds of lights most of them on lights elsewhere;
//! the few samples that land where the light comes from carry large weights. Weighing every
//! emitter at every sample would cost as much as there are emitters.

use super::bounds::{bounding_sphere, LightBounds, LightBounds4};
use super::selection::{pick, IMPORTANCE_CAP, POWER_SHARE};
use crate::sampling::ONE_MINUS_EPSILON;
use crate::shapes::{normal_cone, Mesh};
use glam::{Vec3, Vec4};

/// Fewest triangles for which a mesh light chooses its triangles by importance: a rectangle's
/// two lie in one plane and light every point in the same proportion, by area.
pub const MIN_TRIANGLES: usize = 3;

/// Most emitters a tree is built for (≈ 80 bytes each); beyond, a mesh light's triangles are
/// chosen by area and a scene's lights by power.
pub const MAX_EMITTERS: usize = 1 << 20;

/// Marks a child that is an emitter (its index in the low bits), not a node.
const EMITTER: u32 = 1 << 31;

/// Children that are neither (unused lanes: no weight, no importance).
const NONE: u32 = u32::MAX;

/// A node: up to four children with their bounds.
#[derive(Debug, Clone)]
struct Node {
    /// The children's emission bounds.
    bounds: LightBounds4,
    /// The children's weights (the sums of their emitters').
    weight: Vec4,
    /// The children: a node index, an emitter (`EMITTER` | index) or `NONE`.
    child: [u32; 4],
}

/// An emitter as the tree is built: its bounds, its weight (≥ 0) and where it sits (the point
/// the tree splits emitters by).
#[derive(Debug, Clone, Copy)]
pub struct TreeEmitter {
    /// Emission bounds.
    pub bounds: LightBounds,
    /// Weight of the defensive share (power, area).
    pub weight: f32,
    /// Position that sorts it into the tree (a centroid, a centre).
    pub key: Vec3,
}

/// Emitters, for choosing one by what it can deliver to a point.
#[derive(Debug, Clone)]
pub struct EmitterTree {
    /// The tree's nodes, the root first.
    nodes: Vec<Node>,
    /// Each emitter's way down from the root: the child taken at each level, two bits a level,
    /// the root's in the lowest bits.
    trail: Vec<u64>,
    /// Each emitter's weight.
    weight: Vec<f32>,
}

impl EmitterTree {
    /// The tree over `emitters` (at least two, at most [`MAX_EMITTERS`]), or `None` for fewer
    /// or more.
    pub fn new(emitters: &[TreeEmitter]) -> Option<Self> {
        if !(2..=MAX_EMITTERS).contains(&emitters.len()) {
            return None;
        }
        let weight: Vec<f32> = emitters
            .iter()
            .map(|e| if e.weight > 0.0 { e.weight } else { 0.0 })
            .collect();
        let mut members: Vec<Member> = (0..emitters.len() as u32)
            .map(|k| (k, emitters[k as usize].key))
            .collect();
        let mut tree = EmitterTree {
            nodes: Vec::with_capacity(emitters.len() / 2),
            trail: vec![0; emitters.len()],
            weight,
        };
        tree.build(&mut members, emitters, 0, 0);
        Some(tree)
    }

    /// The tree over the triangles of a mesh light, weighed by area, or `None` when the mesh
    /// has fewer than [`MIN_TRIANGLES`] or more than [`MAX_EMITTERS`] triangles, or no area.
    pub fn triangles(mesh: &Mesh) -> Option<Self> {
        let count = mesh.triangle_count();
        if !(MIN_TRIANGLES..=MAX_EMITTERS).contains(&count)
            || mesh.area().is_nan()
            || mesh.area() <= 0.0
        {
            return None;
        }
        let emitters: Vec<TreeEmitter> = (0..count as u32)
            .map(|t| {
                let [a, b, c] = mesh.triangle(t);
                let (center, radius) = bounding_sphere(a.min(b).min(c), a.max(b).max(c));
                let area = mesh.triangle_area(t);
                // The radiance is the same scale for every triangle: the area is the intensity.
                let (axis, cos_o) = normal_cone(mesh.triangle_normals(t));
                let bounds = if cos_o <= -1.0 {
                    LightBounds::omnidirectional(center, radius, area)
                } else {
                    LightBounds::cone(center, radius, area, axis, cos_o, 0.0)
                };
                TreeEmitter {
                    bounds,
                    weight: area,
                    key: (a + b + c) / 3.0,
                }
            })
            .collect();
        Self::new(&emitters)
    }

    /// Builds the subtree over `members` (index into `emitters`, key), reached from the root
    /// by `trail` (`level` levels down); returns the child entry for it, its bounds and its
    /// weight.
    fn build(
        &mut self,
        members: &mut [Member],
        emitters: &[TreeEmitter],
        level: u32,
        trail: u64,
    ) -> (u32, LightBounds, f32) {
        if let [(e, _)] = members {
            self.trail[*e as usize] = trail;
            return (
                *e | EMITTER,
                emitters[*e as usize].bounds,
                self.weight[*e as usize],
            );
        }
        let index = self.nodes.len();
        self.nodes.push(Node {
            bounds: LightBounds4::new(&[]),
            weight: Vec4::ZERO,
            child: [NONE; 4],
        });
        let (left, right) = halve(members);
        let (a, b) = halve(left);
        let (c, d) = halve(right);
        let mut bounds = Vec::with_capacity(4);
        let mut weight = [0.0f32; 4];
        let mut child = [NONE; 4];
        for group in [a, b, c, d] {
            if group.is_empty() {
                continue;
            }
            let lane = bounds.len();
            let (entry, group_bounds, group_weight) = self.build(
                group,
                emitters,
                level + 1,
                trail | (lane as u64) << (2 * level),
            );
            child[lane] = entry;
            weight[lane] = group_weight;
            bounds.push(group_bounds);
        }
        let union = bounds.iter().skip(1).fold(bounds[0], |u, b| u.union(b));
        let total = weight.iter().map(|&w| w as f64).sum::<f64>() as f32;
        self.nodes[index] = Node {
            bounds: LightBounds4::new(&bounds),
            weight: Vec4::from_array(weight),
            child,
        };
        (index as u32, union, total)
    }

    /// Weight of emitter `e` (a triangle's area).
    #[inline]
    pub fn weight(&self, e: u32) -> f32 {
        self.weight[e as usize]
    }

    /// Number of levels from the root down to emitter `e` (the power of [`POWER_SHARE`] that
    /// bounds its defensive share).
    #[cfg(test)]
    pub(crate) fn depth(&self, e: u32) -> u32 {
        let (mut trail, mut node, mut depth) = (self.trail[e as usize], 0usize, 1);
        loop {
            let child = self.nodes[node].child[(trail & 3) as usize];
            if child & EMITTER != 0 {
                return depth;
            }
            trail >>= 2;
            node = child as usize;
            depth += 1;
        }
    }

    /// The probabilities of a node's four children at `p` with unit normal `n` (`Vec3::ZERO`:
    /// none): each one's share of the importance scaled to 1 − [`POWER_SHARE`] plus its share
    /// of the weight scaled to [`POWER_SHARE`] (by weight alone where no child can reach the
    /// point by its bounds, or one's importance overflows).
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
        let weight_sum = node.weight.element_sum();
        let by_weight = if weight_sum > 0.0 {
            1.0 / weight_sum
        } else {
            0.0
        };
        if importance_sum > 0.0 && importance_sum.is_finite() {
            importance * ((1.0 - POWER_SHARE) / importance_sum)
                + node.weight * (POWER_SHARE * by_weight)
        } else {
            node.weight * by_weight
        }
    }

    /// Picks an emitter for a point `p` with unit normal `n` (`Vec3::ZERO`: none) with `u` in
    /// [0, 1); returns (emitter, probability, `u` rescaled to [0, 1) within the choice), or
    /// `None` when no emitter can be chosen (no weight and no importance anywhere).
    #[inline]
    pub fn sample(&self, p: Vec3, n: Vec3, mut u: f32) -> Option<(u32, f32, f32)> {
        let mut node = &self.nodes[0];
        let mut pmf = 1.0f32;
        loop {
            let shares = Self::shares(node, p, n).to_array();
            let (k, below) = pick(&shares, u)?;
            let q = shares[k];
            u = ((u - below) / q).clamp(0.0, ONE_MINUS_EPSILON);
            pmf *= q;
            let child = node.child[k];
            if child & EMITTER != 0 {
                return Some((child & !EMITTER, pmf, u));
            }
            node = &self.nodes[child as usize];
        }
    }

    /// The probability that [`Self::sample`] picks emitter `e` at `p` with normal `n`.
    #[inline]
    pub fn pmf(&self, p: Vec3, n: Vec3, e: u32) -> f32 {
        let mut trail = self.trail[e as usize];
        let mut node = &self.nodes[0];
        let mut pmf = 1.0f32;
        loop {
            let k = (trail & 3) as usize;
            trail >>= 2;
            pmf *= Self::shares(node, p, n)[k];
            let child = node.child[k];
            if child & EMITTER != 0 {
                debug_assert_eq!(child & !EMITTER, e);
                return pmf;
            }
            node = &self.nodes[child as usize];
        }
    }
}

/// An emitter with its key, as the tree is built.
type Member = (u32, Vec3);

/// Splits `members` into two halves along the longest axis of their keys (ties by index, so
/// the tree is the same on every run); a single member stays whole.
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
        let tree = EmitterTree::triangles(&mesh).unwrap();
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
                let (t, q, _) = tree.sample(p, n, rng.next_f32()).unwrap();
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
        assert!(EmitterTree::triangles(&quad).is_none());
        let flat = Mesh::from_data(TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            indices: vec![[0, 1, 2]; 4],
            ..Default::default()
        });
        assert!(EmitterTree::triangles(&flat).is_none());
    }
}
