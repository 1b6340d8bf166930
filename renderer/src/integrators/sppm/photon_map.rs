//! The photon map of one SPPM pass: stored photons and a hashed uniform grid over them with a
//! fixed-radius query (gathering) and a capped k-nearest-neighbour distance query (initial radii).
//!
//! The grid is built by a counting sort of the photons by hash bucket, so its layout (and hence
//! the order in which a query visits photons) depends only on the photon list, never on thread
//! scheduling: gathers sum photons in a fixed order and are bit-reproducible.

use crate::spectrum::Rgb;
use glam::{IVec3, Vec3};

/// A photon deposited on a non-delta surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Photon {
    /// Hit position (world space).
    pub position: Vec3,
    /// Unit direction towards where the photon came from (away from the surface).
    pub wi: Vec3,
    /// Geometric normal of the surface it landed on.
    pub normal: Vec3,
    /// Flux carried (W per emitted-photon unit; divided by N_photon at gathering).
    pub flux: Rgb,
}

/// A uniform grid hashed into `2^k` buckets; each bucket is a contiguous slice of photons.
#[derive(Debug, Clone)]
pub struct PhotonGrid {
    /// Photons sorted by bucket (stable: ascending input index within a bucket).
    photons: Vec<Photon>,
    /// `bucket_start[b]..bucket_start[b+1]` are the photons of bucket `b`.
    bucket_start: Vec<u32>,
    /// Grid origin (minimum corner of the photon bounds).
    origin: Vec3,
    /// Edge length of a cell.
    cell_size: f32,
    /// `bucket count - 1` (bucket count is a power of two).
    mask: u64,
}

impl PhotonGrid {
    /// Builds the grid with cells of edge `cell_size` (> 0; typically ≈ the query radius).
    pub fn build(photons: Vec<Photon>, cell_size: f32) -> Self {
        let cell_size = if cell_size.is_finite() && cell_size > 0.0 {
            cell_size
        } else {
            1.0
        };
        let origin = photons
            .iter()
            .fold(Vec3::splat(f32::INFINITY), |m, p| m.min(p.position));
        let origin = if origin.is_finite() {
            origin
        } else {
            Vec3::ZERO
        };
        let buckets = (photons.len().max(1) * 2).next_power_of_two();
        let mut grid = PhotonGrid {
            photons: Vec::new(),
            bucket_start: vec![0; buckets + 1],
            origin,
            cell_size,
            mask: buckets as u64 - 1,
        };
        // Counting sort by bucket: count, prefix sum, scatter in input order (stable).
        let keys: Vec<usize> = photons
            .iter()
            .map(|p| grid.bucket(grid.cell_of(p.position)))
            .collect();
        for &k in &keys {
            grid.bucket_start[k + 1] += 1;
        }
        for b in 0..buckets {
            grid.bucket_start[b + 1] += grid.bucket_start[b];
        }
        let mut next: Vec<u32> = grid.bucket_start[..buckets].to_vec();
        let mut sorted = vec![
            Photon {
                position: Vec3::ZERO,
                wi: Vec3::ZERO,
                normal: Vec3::ZERO,
                flux: Rgb::ZERO
            };
            photons.len()
        ];
        for (p, &k) in photons.into_iter().zip(&keys) {
            sorted[next[k] as usize] = p;
            next[k] += 1;
        }
        grid.photons = sorted;
        grid
    }

    /// Number of stored photons.
    pub fn len(&self) -> usize {
        self.photons.len()
    }

    /// True when no photon is stored.
    pub fn is_empty(&self) -> bool {
        self.photons.is_empty()
    }

    /// Edge length of a grid cell.
    pub fn cell_size(&self) -> f32 {
        self.cell_size
    }

    /// Integer cell coordinates of a point.
    #[inline]
    fn cell_of(&self, p: Vec3) -> IVec3 {
        let c = ((p - self.origin) / self.cell_size).floor();
        // Clamp so far-away query points cannot overflow the integer conversion.
        c.clamp(Vec3::splat(-1.0e9), Vec3::splat(1.0e9)).as_ivec3()
    }

    /// Hash bucket of a cell (Teschner et al. 2003 spatial hash).
    #[inline]
    fn bucket(&self, c: IVec3) -> usize {
        let h = (c.x as u32 as u64).wrapping_mul(73_856_093)
            ^ (c.y as u32 as u64).wrapping_mul(19_349_663)
            ^ (c.z as u32 as u64).wrapping_mul(83_492_791);
        (h & self.mask) as usize
    }

    /// Calls `f(photon, squared distance)` for every photon within `radius` of `p`, in a fixed
    /// order (cells in x-y-z order, photons in bucket order).
    #[inline]
    pub fn for_each_within(&self, p: Vec3, radius: f32, mut f: impl FnMut(&Photon, f32)) {
        if self.photons.is_empty() || radius.is_nan() || radius <= 0.0 {
            return;
        }
        let r2 = radius * radius;
        let lo = self.cell_of(p - Vec3::splat(radius));
        let hi = self.cell_of(p + Vec3::splat(radius));
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let cell = IVec3::new(x, y, z);
                    let b = self.bucket(cell);
                    let range = self.bucket_start[b] as usize..self.bucket_start[b + 1] as usize;
                    for photon in &self.photons[range] {
                        // Buckets are shared by colliding cells: visit each photon only from
                        // its own cell, or it would be counted twice.
                        if self.cell_of(photon.position) != cell {
                            continue;
                        }
                        let d2 = photon.position.distance_squared(p);
                        if d2 <= r2 {
                            f(photon, d2);
                        }
                    }
                }
            }
        }
    }

    /// Distance from `p` to its `k`-th nearest photon, if at least `k` photons lie within
    /// `max_radius`; `None` otherwise (the caller falls back to the cap).
    pub fn kth_nearest_distance(&self, p: Vec3, k: usize, max_radius: f32) -> Option<f32> {
        if k == 0 {
            return Some(0.0);
        }
        if self.photons.len() < k || max_radius.is_nan() || max_radius <= 0.0 {
            return None;
        }
        // Search radii growing by 2 from one cell up to the cap. As soon as k photons lie within
        // the searched radius the answer is exact (every nearer photon has been seen), so the
        // result equals a single query at the cap; but a query costs the cells it covers, and a
        // pixel initialised late (its first visible point in a later pass, when the cells have
        // shrunk to the typical radius) would otherwise scan the cap's whole volume of small
        // cells — the dominant cost of a pass with many photons.
        let mut d2s: Vec<f32> = Vec::new();
        let mut r = self.cell_size.min(max_radius);
        loop {
            d2s.clear();
            self.for_each_within(p, r, |_, d2| d2s.push(d2));
            if d2s.len() >= k {
                let (_, kth, _) = d2s.select_nth_unstable_by(k - 1, f32::total_cmp);
                return Some(kth.sqrt());
            }
            if r >= max_radius {
                return None;
            }
            r = (2.0 * r).min(max_radius);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{rng_for, UniformSource};

    fn random_photons(n: usize, seed: u64) -> Vec<Photon> {
        let mut rng = rng_for(seed, 0, 0);
        (0..n)
            .map(|i| {
                // Clustered on a plane and in a blob, to exercise dense and empty cells.
                let u = rng.next_2d();
                let position = if i % 3 == 0 {
                    Vec3::new(u.x * 2.0, 0.25, u.y * 2.0)
                } else {
                    Vec3::new(u.x, rng.next_f32(), u.y) * 0.5 + Vec3::splat(0.7)
                };
                Photon {
                    position,
                    wi: Vec3::Y,
                    normal: Vec3::Y,
                    flux: Rgb::splat(i as f32),
                }
            })
            .collect()
    }

    #[test]
    fn radius_query_equals_brute_force() {
        let photons = random_photons(3000, 1);
        let mut rng = rng_for(2, 0, 0);
        for cell_size in [0.01, 0.07, 0.3, 5.0] {
            let grid = PhotonGrid::build(photons.clone(), cell_size);
            assert_eq!(grid.len(), photons.len());
            for _ in 0..50 {
                let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.2
                    - Vec3::splat(0.1);
                let r = 0.02 + 0.3 * rng.next_f32();
                let mut got: Vec<u32> = Vec::new();
                grid.for_each_within(p, r, |ph, d2| {
                    assert!((d2 - ph.position.distance_squared(p)).abs() < 1e-6);
                    got.push(ph.flux.x as u32);
                });
                got.sort_unstable();
                let mut want: Vec<u32> = photons
                    .iter()
                    .filter(|ph| ph.position.distance_squared(p) <= r * r)
                    .map(|ph| ph.flux.x as u32)
                    .collect();
                want.sort_unstable();
                assert_eq!(got, want, "cell {cell_size} p {p} r {r}");
            }
        }
    }

    #[test]
    fn knn_equals_brute_force() {
        let photons = random_photons(2000, 3);
        // Cells much smaller than the cap (the growing search takes several steps), comparable,
        // and larger than the cap (one step).
        for cell_size in [0.004, 0.05, 0.5] {
            let grid = PhotonGrid::build(photons.clone(), cell_size);
            let mut rng = rng_for(4, 0, 0);
            let (k, cap) = (20, 0.2);
            let mut found = 0;
            for _ in 0..200 {
                let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 1.5;
                let mut d: Vec<f32> = photons.iter().map(|ph| ph.position.distance(p)).collect();
                d.sort_by(f32::total_cmp);
                let want = (d[k - 1] <= cap).then_some(d[k - 1]);
                let got = grid.kth_nearest_distance(p, k, cap);
                // Bit-identical to the k-th of one query at the cap (what the growing search
                // must reproduce exactly, for determinism across versions).
                let mut all = Vec::new();
                grid.for_each_within(p, cap, |_, d2| all.push(d2));
                all.sort_by(f32::total_cmp);
                let single = all.get(k - 1).map(|d2| d2.sqrt());
                assert_eq!(got, single, "cell {cell_size}");
                match (got, want) {
                    (Some(g), Some(w)) => {
                        assert!((g - w).abs() <= 1e-5 * w.max(1.0), "{g} vs {w}");
                        found += 1;
                    }
                    (None, None) => {}
                    // Distances straddling the cap by rounding are tolerated.
                    (g, w) => assert!((d[k - 1] - cap).abs() < 1e-5, "{g:?} vs {w:?}"),
                }
            }
            assert!(found > 20, "test should exercise the found case ({found})");
        }
    }

    #[test]
    fn build_is_deterministic_and_empty_grid_is_safe() {
        let photons = random_photons(500, 5);
        let a = PhotonGrid::build(photons.clone(), 0.1);
        let b = PhotonGrid::build(photons, 0.1);
        assert_eq!(a.photons, b.photons);
        assert_eq!(a.bucket_start, b.bucket_start);
        let empty = PhotonGrid::build(Vec::new(), 0.1);
        assert!(empty.is_empty());
        assert_eq!(empty.kth_nearest_distance(Vec3::ZERO, 20, 1.0), None);
        empty.for_each_within(Vec3::ZERO, 1.0, |_, _| panic!("no photons"));
    }
}
