//! A 4-wide BVH with full-precision child boxes, collapsed from obvhs's BVH2 (which does the
//! building: PLOC, reinsertion, SAH leaf collapse), and its SSE2 traversal. Four children are
//! tested against one ray in a single pass of 4-lane arithmetic over boxes stored
//! structure-of-arrays; unlike obvhs's CWBVH, nothing is decompressed per node, which is where
//! a CPU spends its time on the small scenes this toolkit renders.

use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;
use std::mem::MaybeUninit;

/// Marks a child slot as a leaf: the low bits hold `first << LEAF_COUNT_BITS | count`.
const LEAF: u32 = 1 << 31;
/// Bits of a leaf's primitive count.
const LEAF_COUNT_BITS: u32 = 4;
/// A child slot with nothing in it (its box is empty, so it is never entered).
const EMPTY: u32 = u32::MAX;
/// Traversal stack entries (a closest-hit traversal holds at most 3 per level + 1).
pub const STACK_SIZE: usize = 256;
/// Primitives a leaf slot can address (exclusive bound).
pub const MAX_PRIMITIVES: usize = 1 << (31 - LEAF_COUNT_BITS);

/// A fixed-capacity traversal stack left uninitialised: zeroing [`STACK_SIZE`] entries per ray
/// cost more than traversing a small scene. The build guarantees the capacity (3 per level + 1).
pub struct TraversalStack<T: Copy> {
    /// Entries below `top` are written.
    entries: [MaybeUninit<T>; STACK_SIZE],
    /// Number of entries on the stack.
    top: usize,
}

impl<T: Copy> TraversalStack<T> {
    /// A stack holding `first`.
    #[inline(always)]
    pub fn new(first: T) -> Self {
        let mut stack = TraversalStack {
            entries: [const { MaybeUninit::uninit() }; STACK_SIZE],
            top: 0,
        };
        stack.push(first);
        stack
    }

    /// Pushes `entry` (panics past the capacity instead of writing out of bounds).
    #[inline(always)]
    pub fn push(&mut self, entry: T) {
        self.entries[self.top].write(entry);
        self.top += 1;
    }

    /// Pops the last entry pushed.
    #[inline(always)]
    pub fn pop(&mut self) -> Option<T> {
        if self.top == 0 {
            return None;
        }
        self.top -= 1;
        // SAFETY: entries below the old `top` were written by `push`.
        Some(unsafe { self.entries[self.top].assume_init() })
    }
}

/// One node: the boxes of up to four children, one lane per child.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(16))]
pub struct Node4 {
    /// `bounds[2 * axis]` = the children's minima along `axis`, `bounds[2 * axis + 1]` maxima.
    pub bounds: [[f32; 4]; 6],
    /// Per child: a node index, a leaf (`LEAF` | first << 4 | count) or `EMPTY`.
    pub child: [u32; 4],
}

impl Node4 {
    /// A node whose four slots are empty (boxes inverted: no ray enters them).
    fn empty() -> Self {
        let mut bounds = [[0.0; 4]; 6];
        for axis in 0..3 {
            bounds[2 * axis] = [f32::INFINITY; 4];
            bounds[2 * axis + 1] = [f32::NEG_INFINITY; 4];
        }
        Node4 {
            bounds,
            child: [EMPTY; 4],
        }
    }

    /// Stores `aabb` and `child` in slot `slot`.
    fn set(&mut self, slot: usize, aabb: &Aabb, child: u32) {
        for axis in 0..3 {
            self.bounds[2 * axis][slot] = aabb.min[axis];
            self.bounds[2 * axis + 1][slot] = aabb.max[axis];
        }
        self.child[slot] = child;
    }
}

/// A child reference as traversal sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Child {
    /// An inner node (index into the node array).
    Node(u32),
    /// A leaf: primitives `first..first + count` in leaf order.
    Leaf { first: u32, count: u32 },
}

/// Decodes a child slot (not `EMPTY`).
#[inline(always)]
pub fn decode(c: u32) -> Child {
    if c & LEAF == 0 {
        Child::Node(c)
    } else {
        Child::Leaf {
            first: (c & !LEAF) >> LEAF_COUNT_BITS,
            count: c & ((1 << LEAF_COUNT_BITS) - 1),
        }
    }
}

/// The primitives as the BVH2 builder sees them: one entry per primitive, except that a large
/// set of primitives with bit-identical boxes becomes one entry (obvhs's PLOC merges one pair
/// per sweep when thousands of merge costs tie, which made a mesh of 200 000 copies of one
/// triangle take hours to build); its primitives are put back at the leaf that holds its box.
/// Small sets (the two triangles of an axis-aligned quad share a box) stay separate entries:
/// grouped, they would make leaves larger than the SAH chose.
pub struct BuildEntries {
    /// The box of each entry.
    pub boxes: Vec<Aabb>,
    /// The grouping, or `None` when every entry is one primitive (entry `e` = primitive `e`).
    groups: Option<Groups>,
    /// Number of input primitives.
    primitives: usize,
}

/// Which primitives each entry of a [`BuildEntries`] holds.
struct Groups {
    /// Entry `e` holds `items[start[e]..start[e + 1]]` (input primitive indices, ascending).
    start: Vec<u32>,
    /// Primitive indices by entry.
    items: Vec<u32>,
}

/// Primitives sharing one box beyond which they are built as one entry.
const GROUP_ABOVE: usize = 16;

/// A box's bits, the identity the grouping compares.
fn box_key(b: &Aabb) -> [u32; 6] {
    [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z].map(f32::to_bits)
}

/// A 64-bit hash of a box key (FxHash's multiply-rotate step per word): equal keys hash
/// equally, which is all the pre-filter in [`BuildEntries::new`] relies on.
fn key_hash(key: &[u32; 6]) -> u64 {
    const K: u64 = 0x51_7c_c1_b7_27_22_0a_95;
    key.iter().fold(0u64, |h, &w| {
        (h.rotate_left(5) ^ u64::from(w)).wrapping_mul(K)
    })
}

impl BuildEntries {
    /// Entries for `bounds`, grouping sets of more than [`GROUP_ABOVE`] identical boxes.
    pub fn new(bounds: Vec<Aabb>) -> Self {
        // Pre-filter: a set of more than GROUP_ABOVE identical boxes shares one hash, so only
        // boxes whose hash is that frequent can be grouped. Sorting the hashes (8 bytes per
        // box) finds them; a mesh of distinct boxes stops here, without a map keyed by boxes.
        let mut hashes: Vec<u64> = bounds.iter().map(|b| key_hash(&box_key(b))).collect();
        hashes.sort_unstable();
        let frequent: Vec<u64> = hashes
            .chunk_by(|a, b| a == b)
            .filter(|run| run.len() > GROUP_ABOVE)
            .map(|run| run[0])
            .collect();
        drop(hashes);
        if frequent.is_empty() {
            // The usual case: one entry per primitive.
            return BuildEntries {
                primitives: bounds.len(),
                boxes: bounds,
                groups: None,
            };
        }
        let candidate = |b: &Aabb| frequent.binary_search(&key_hash(&box_key(b))).is_ok();
        // Count the candidates exactly; only the (rare) large sets collect their members.
        let mut count: std::collections::HashMap<[u32; 6], u32> = std::collections::HashMap::new();
        for b in bounds.iter().filter(|b| candidate(b)) {
            *count.entry(box_key(b)).or_default() += 1;
        }
        let mut large: std::collections::HashMap<[u32; 6], Vec<u32>> = count
            .iter()
            .filter(|(_, &n)| n as usize > GROUP_ABOVE)
            .map(|(k, &n)| (*k, Vec::with_capacity(n as usize)))
            .collect();
        drop(count);
        if large.is_empty() {
            // Frequent hashes, but no large set of identical boxes (colliding hashes).
            return BuildEntries {
                primitives: bounds.len(),
                boxes: bounds,
                groups: None,
            };
        }
        // The key of a box that may belong to a large set.
        let set_of = |b: &Aabb| candidate(b).then(|| box_key(b));
        for (i, b) in bounds.iter().enumerate() {
            if let Some(members) = set_of(b).and_then(|k| large.get_mut(&k)) {
                members.push(i as u32);
            }
        }
        let mut boxes = Vec::with_capacity(bounds.len());
        let mut groups = Groups {
            start: Vec::with_capacity(bounds.len() + 1),
            items: Vec::with_capacity(bounds.len()),
        };
        groups.start.push(0);
        // In input order (a set at its first member), so the build does not depend on hashing.
        for (i, b) in bounds.iter().enumerate() {
            match set_of(b).and_then(|k| large.get(&k)) {
                None => groups.items.push(i as u32),
                Some(members) if members[0] == i as u32 => groups.items.extend_from_slice(members),
                Some(_) => continue,
            }
            boxes.push(*b);
            groups.start.push(groups.items.len() as u32);
        }
        BuildEntries {
            boxes,
            groups: Some(groups),
            primitives: bounds.len(),
        }
    }

    /// Appends the input primitives of entry `e` to `out`.
    fn extend_members(&self, e: u32, out: &mut Vec<u32>) {
        match &self.groups {
            None => out.push(e),
            Some(g) => out.extend_from_slice(
                &g.items[g.start[e as usize] as usize..g.start[e as usize + 1] as usize],
            ),
        }
    }
}

/// A collapsed hierarchy.
pub struct Collapsed {
    /// Nodes, root at index 0.
    pub nodes: Vec<Node4>,
    /// Input primitive index of each leaf-order position.
    pub order: Vec<u32>,
    /// Depth in nodes.
    pub depth: usize,
    /// The primitives of the leaf being emitted (reused across leaves).
    scratch: Vec<u32>,
}

/// Collapses `bvh2` (built over `entries.boxes`, see [`BuildEntries`]) into 4-wide nodes. Each BVH2 node keeps its two
/// children and repeatedly opens the largest-area inner child among them until four are
/// gathered (the standard SAH-greedy collapse). A BVH2 leaf becomes a leaf of its entries'
/// primitives, or — when they are more than a leaf holds (duplicates) — a 4-ary subtree of
/// leaves under the same box. The caller checks the primitive count against [`MAX_PRIMITIVES`].
pub fn collapse(bvh2: &Bvh2, entries: &BuildEntries) -> Collapsed {
    let mut c = Collapsed {
        nodes: Vec::with_capacity(bvh2.nodes.len() / 2 + 1),
        order: Vec::with_capacity(entries.primitives),
        depth: 1,
        scratch: Vec::new(),
    };
    c.nodes.push(Node4::empty());
    let root = &bvh2.nodes[0];
    if root.prim_count > 0 {
        let (code, d) = leaf_of(bvh2, entries, 0, &mut c);
        c.nodes[0].set(0, &root.aabb, code);
        c.depth = 1 + d;
    } else {
        c.depth = fill(bvh2, entries, 0, 0, &mut c);
    }
    c
}

/// Most primitives in one leaf slot.
const MAX_LEAF: usize = (1 << LEAF_COUNT_BITS) - 1;

/// Encodes a leaf slot.
fn leaf(first: u32, count: u32) -> u32 {
    debug_assert!(count as usize <= MAX_LEAF && (first as usize) < MAX_PRIMITIVES);
    LEAF | (first << LEAF_COUNT_BITS) | count
}

/// The child slot for the BVH2 leaf `n2` and the depth in nodes it adds below its parent.
fn leaf_of(bvh2: &Bvh2, entries: &BuildEntries, n2: usize, c: &mut Collapsed) -> (u32, usize) {
    let node = &bvh2.nodes[n2];
    let first = node.first_index as usize;
    // One buffer for every leaf (taken out of `c` while `emit` appends to it).
    let mut prims = std::mem::take(&mut c.scratch);
    prims.clear();
    for &g in &bvh2.primitive_indices[first..first + node.prim_count as usize] {
        entries.extend_members(g, &mut prims);
    }
    let slot = emit(&prims, &node.aabb, c);
    c.scratch = prims;
    slot
}

/// A leaf of `prims`, or a subtree of leaves all bounded by `aabb` when they do not fit one.
fn emit(prims: &[u32], aabb: &Aabb, c: &mut Collapsed) -> (u32, usize) {
    if prims.len() <= MAX_LEAF {
        let first = c.order.len() as u32;
        c.order.extend_from_slice(prims);
        return (leaf(first, prims.len() as u32), 0);
    }
    let index = c.nodes.len();
    c.nodes.push(Node4::empty());
    let mut depth = 0;
    for (slot, part) in prims.chunks(prims.len().div_ceil(4)).enumerate() {
        let (code, d) = emit(part, aabb, c);
        c.nodes[index].set(slot, aabb, code);
        depth = depth.max(d);
    }
    (index as u32, 1 + depth)
}

/// Fills `nodes[out]` with the (up to four) descendants of the BVH2 inner node `n2`; returns
/// the depth of the subtree in nodes.
fn fill(bvh2: &Bvh2, entries: &BuildEntries, n2: usize, out: usize, c: &mut Collapsed) -> usize {
    let first = bvh2.nodes[n2].first_index as usize;
    let mut kids = vec![first, first + 1];
    while kids.len() < 4 {
        let open = kids
            .iter()
            .enumerate()
            .filter(|(_, &k)| bvh2.nodes[k].prim_count == 0)
            .max_by(|a, b| {
                let (ha, hb) = (
                    bvh2.nodes[*a.1].aabb.half_area(),
                    bvh2.nodes[*b.1].aabb.half_area(),
                );
                ha.total_cmp(&hb)
            })
            .map(|(i, _)| i);
        let Some(i) = open else { break };
        let k = bvh2.nodes[kids[i]].first_index as usize;
        kids[i] = k;
        kids.insert(i + 1, k + 1);
    }
    let mut depth = 1;
    for (slot, &k) in kids.iter().enumerate() {
        let node = &bvh2.nodes[k];
        if node.prim_count > 0 {
            let (code, d) = leaf_of(bvh2, entries, k, c);
            c.nodes[out].set(slot, &node.aabb, code);
            depth = depth.max(1 + d);
        } else {
            let index = c.nodes.len();
            c.nodes.push(Node4::empty());
            c.nodes[out].set(slot, &node.aabb, index as u32);
            depth = depth.max(1 + fill(bvh2, entries, k, index, c));
        }
    }
    depth
}

/// The per-ray constants of the box test, splatted into SSE registers.
#[cfg(target_arch = "x86_64")]
pub mod simd {
    use super::Node4;
    use std::arch::x86_64::*;

    /// A ray prepared for 4-wide box tests: origin, inverse direction and the near/far plane
    /// rows of each axis chosen by the direction's sign.
    #[derive(Clone, Copy)]
    pub struct BoxRay {
        o: [__m128; 3],
        inv: [__m128; 3],
        near: [usize; 3],
        tmin: __m128,
    }

    impl BoxRay {
        /// Prepares `origin`, `inv_direction` (finite) and `tmin`.
        #[inline(always)]
        pub fn new(origin: glam::Vec3A, inv_direction: glam::Vec3A, tmin: f32) -> Self {
            // SAFETY: SSE2 is part of the x86_64 baseline.
            unsafe {
                BoxRay {
                    o: [
                        _mm_set1_ps(origin.x),
                        _mm_set1_ps(origin.y),
                        _mm_set1_ps(origin.z),
                    ],
                    inv: [
                        _mm_set1_ps(inv_direction.x),
                        _mm_set1_ps(inv_direction.y),
                        _mm_set1_ps(inv_direction.z),
                    ],
                    near: [
                        usize::from(inv_direction.x < 0.0),
                        usize::from(inv_direction.y < 0.0),
                        usize::from(inv_direction.z < 0.0),
                    ],
                    tmin: _mm_set1_ps(tmin),
                }
            }
        }

        /// Entry distances of the four children and the mask of those the ray enters
        /// before `tmax`.
        #[inline(always)]
        pub fn test(&self, node: &Node4, tmax: f32) -> ([f32; 4], u32) {
            // SAFETY: SSE2 arithmetic on registers; loads from the 16-byte aligned rows of `node`.
            unsafe {
                let b = &node.bounds;
                let mut tnear = self.tmin;
                let mut tfar = _mm_set1_ps(tmax);
                for axis in 0..3 {
                    let n = self.near[axis];
                    let lo = _mm_load_ps(b[2 * axis + n].as_ptr());
                    let hi = _mm_load_ps(b[2 * axis + 1 - n].as_ptr());
                    let t0 = _mm_mul_ps(_mm_sub_ps(lo, self.o[axis]), self.inv[axis]);
                    let t1 = _mm_mul_ps(_mm_sub_ps(hi, self.o[axis]), self.inv[axis]);
                    tnear = _mm_max_ps(tnear, t0);
                    tfar = _mm_min_ps(tfar, t1);
                }
                let mask = _mm_movemask_ps(_mm_cmple_ps(tnear, tfar)) as u32;
                let mut out = [0.0f32; 4];
                _mm_storeu_ps(out.as_mut_ptr(), tnear);
                (out, mask)
            }
        }
    }
}

/// Portable version of [`simd`] for other architectures.
#[cfg(not(target_arch = "x86_64"))]
pub mod simd {
    use super::Node4;

    /// A ray prepared for 4-wide box tests.
    #[derive(Clone, Copy)]
    pub struct BoxRay {
        o: [f32; 3],
        inv: [f32; 3],
        near: [usize; 3],
        tmin: f32,
    }

    impl BoxRay {
        /// Prepares `origin`, `inv_direction` (finite) and `tmin`.
        #[inline(always)]
        pub fn new(origin: glam::Vec3A, inv_direction: glam::Vec3A, tmin: f32) -> Self {
            BoxRay {
                o: origin.to_array(),
                inv: inv_direction.to_array(),
                near: [
                    usize::from(inv_direction.x < 0.0),
                    usize::from(inv_direction.y < 0.0),
                    usize::from(inv_direction.z < 0.0),
                ],
                tmin,
            }
        }

        /// Entry distances of the four children and the mask of those the ray enters
        /// before `tmax`.
        #[inline(always)]
        pub fn test(&self, node: &Node4, tmax: f32) -> ([f32; 4], u32) {
            let b = &node.bounds;
            let mut out = [0.0f32; 4];
            let mut mask = 0;
            for (lane, t) in out.iter_mut().enumerate() {
                let mut tnear = self.tmin;
                let mut tfar = tmax;
                for axis in 0..3 {
                    let n = self.near[axis];
                    let t0 = (b[2 * axis + n][lane] - self.o[axis]) * self.inv[axis];
                    let t1 = (b[2 * axis + 1 - n][lane] - self.o[axis]) * self.inv[axis];
                    tnear = if t0 > tnear { t0 } else { tnear };
                    tfar = if t1 < tfar { t1 } else { tfar };
                }
                *t = tnear;
                mask |= u32::from(tnear <= tfar) << lane;
            }
            (out, mask)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;
    use std::collections::HashMap;

    /// The grouping as first written (a map from every box to its primitives): sets of more
    /// than [`GROUP_ABOVE`] identical boxes become one entry at their first member, in input
    /// order. Returns each entry's box and primitives.
    fn reference(bounds: &[Aabb]) -> Vec<(Aabb, Vec<u32>)> {
        let mut sets: HashMap<[u32; 6], Vec<u32>> = HashMap::new();
        for (i, b) in bounds.iter().enumerate() {
            sets.entry(box_key(b)).or_default().push(i as u32);
        }
        let mut out = Vec::new();
        for (i, b) in bounds.iter().enumerate() {
            let set = &sets[&box_key(b)];
            if set.len() <= GROUP_ABOVE {
                out.push((*b, vec![i as u32]));
            } else if set[0] == i as u32 {
                out.push((*b, set.clone()));
            }
        }
        out
    }

    /// The hash pre-filter leaves the grouping and its order exactly as the plain map made it:
    /// sets of 17, 25 and 40 identical boxes (interleaved with others) are grouped, a set of 16
    /// is not, boxes differing only in the sign of a zero are different boxes, and distinct
    /// boxes stay one entry each, without a grouping.
    #[test]
    fn grouping_matches_the_plain_map() {
        let unit = |x: f32| Aabb::new(Vec3A::new(x, 0.0, 0.0), Vec3A::new(x + 1.0, 1.0, 1.0));
        let distinct: Vec<Aabb> = (0..1000).map(|i| unit(i as f32 * 0.37)).collect();
        let plain = BuildEntries::new(distinct.clone());
        assert!(plain.groups.is_none());
        assert_eq!(plain.boxes.len(), distinct.len());
        let mut bounds = Vec::new();
        for i in 0..200 {
            bounds.push(unit(i as f32));
            if i % 5 == 0 {
                bounds.push(unit(-1.0)); // 40 copies
            }
            if i % 11 == 0 && i < 187 {
                bounds.push(unit(-2.0)); // 17 copies
            }
            if i % 12 == 0 && i < 192 {
                bounds.push(unit(-3.0)); // 16 copies
            }
            if i % 4 == 0 {
                // Equal as floats, not as bits: two sets of 25, not one of 50.
                let z = if i % 8 == 0 { 0.0 } else { -0.0 };
                bounds.push(Aabb::new(Vec3A::new(z, -5.0, 0.0), Vec3A::ONE));
            }
        }
        let entries = BuildEntries::new(bounds.clone());
        let expected = reference(&bounds);
        assert!(expected.len() < bounds.len() - 50);
        assert_eq!(entries.boxes.len(), expected.len());
        for (e, (b, members)) in expected.iter().enumerate() {
            assert_eq!(box_key(&entries.boxes[e]), box_key(b), "entry {e}");
            let mut got = Vec::new();
            entries.extend_members(e as u32, &mut got);
            assert_eq!(&got, members, "entry {e}");
        }
        assert_eq!(entries.primitives, bounds.len());
    }
}
