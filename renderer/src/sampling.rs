//! Random numbers and sample warps: deterministic per-pixel / per-photon PCG32 streams, the
//! square-to-domain warps used by cameras, lights and BSDFs, MIS heuristics and a discrete
//! distribution for light selection.

use glam::{Vec2, Vec3};
use rand_core::RngCore;
pub use rand_pcg::Pcg32;
use std::f32::consts::{FRAC_PI_4, PI};

/// SplitMix64 finaliser: a bijective 64-bit mix with good avalanche.
#[inline]
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hash of (seed, pass, index) to 64 bits; distinct inputs give unrelated outputs.
#[inline]
pub fn hash3(seed: u64, pass: u64, index: u64) -> u64 {
    let h = mix64(seed ^ 0x9e37_79b9_7f4a_7c15);
    let h = mix64(h ^ pass.wrapping_mul(0xd1b5_4a32_d192_ed03));
    mix64(h ^ index.wrapping_mul(0xaef1_7502_108e_f2d9))
}

/// The random stream of one work item (a pixel's samples in one pass, one photon…): a PCG32
/// generator whose state and stream are derived from hash(seed, pass, index). Results depend
/// only on these three numbers, never on thread scheduling.
#[inline]
pub fn rng_for(seed: u64, pass: u64, index: u64) -> Pcg32 {
    let h = hash3(seed, pass, index);
    Pcg32::new(h, mix64(h ^ 0x5851_f42d_4c95_7f2d))
}

/// Uniform floats from a generator.
pub trait UniformSource {
    /// A uniform float in [0, 1) (24 random mantissa bits).
    fn next_f32(&mut self) -> f32;
    /// Two uniform floats in [0, 1)².
    #[inline]
    fn next_2d(&mut self) -> Vec2 {
        let x = self.next_f32();
        let y = self.next_f32();
        Vec2::new(x, y)
    }
}

impl UniformSource for Pcg32 {
    #[inline]
    fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }
}

/// Power heuristic (β = 2) weight of a strategy with density `a` against one with density `b`:
/// a²/(a² + b²). A strategy that cannot produce the sample (`a` = 0) gets weight 0, also when
/// `b` = 0; an infinite `a` (a delta strategy) gets weight 1 against any finite `b`, ½ against
/// an infinite one. Densities whose squares would overflow or underflow f32 (beyond ≈ 10¹⁹ or
/// below ≈ 10⁻¹⁹) are weighed by their ratio, so two such densities still share the weight.
#[inline]
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    let sum = a2 + b2;
    // The common case, computed as it always was (images keep their bits).
    if a2 >= f32::MIN_POSITIVE && sum.is_finite() {
        return a2 / sum;
    }
    power_heuristic_by_ratio(a, b)
}

/// [`power_heuristic`] for densities whose squares leave the normal f32 range: 1/(1 + (b/a)²).
#[cold]
fn power_heuristic_by_ratio(a: f32, b: f32) -> f32 {
    // Zero, negative or NaN: this strategy cannot have produced the sample.
    if a.is_nan() || a <= 0.0 {
        return 0.0;
    }
    if a.is_infinite() {
        return if b.is_infinite() { 0.5 } else { 1.0 };
    }
    let r = b / a;
    if r.is_nan() {
        return 0.0;
    }
    1.0 / (1.0 + r * r)
}

/// Concentric (Shirley–Chiu) map of the unit square to the unit disk (low distortion).
#[inline]
pub fn square_to_uniform_disk_concentric(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    // The angle is π/4·(y/x) or π/2 − π/4·(x/y); the second is written with sin ↔ cos, so
    // only angles in [−π/4, π/4] are evaluated.
    if o.x.abs() > o.y.abs() {
        let (s, c) = sin_cos_quarter(FRAC_PI_4 * (o.y / o.x));
        Vec2::new(o.x * c, o.x * s)
    } else {
        let (s, c) = sin_cos_quarter(FRAC_PI_4 * (o.x / o.y));
        Vec2::new(o.y * s, o.y * c)
    }
}

/// sin and cos of `a` ∈ [−π/4, π/4]: the polynomial kernels of Cephes' `sinf`/`cosf` (a few
/// ulp), without the range reduction of the general functions — which made `sincosf` ≈ 3 % of
/// path-tracing time, the concentric map being the only caller on the hot path.
#[inline]
fn sin_cos_quarter(a: f32) -> (f32, f32) {
    let z = a * a;
    let s = ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * a + a;
    let c = ((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z + 1.0;
    (s, c)
}

/// Cosine-weighted direction on the +z hemisphere.
#[inline]
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_uniform_disk_concentric(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Density of [`square_to_cosine_hemisphere`] (solid angle; zero below the horizon).
#[inline]
pub fn cosine_hemisphere_pdf(v: Vec3) -> f32 {
    v.z.max(0.0) * std::f32::consts::FRAC_1_PI
}

/// Uniform direction on the unit sphere.
#[inline]
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.y;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.x).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// The largest `f32` below one: where a uniform number built by arithmetic must stay in [0, 1).
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// Density of [`square_to_uniform_sphere`].
pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform direction in the cone around +z with cos(half-angle) = `cos_max`.
#[inline]
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_t = (1.0 - u.y) + u.y * cos_max;
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.x).sin_cos();
    Vec3::new(sin_t * c, sin_t * s, cos_t)
}

/// Density of [`square_to_uniform_cone`] (inside the cone).
#[inline]
pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// Uniform barycentric coordinates (b1, b2) on a triangle (b0 = 1 − b1 − b2).
#[inline]
pub fn square_to_uniform_triangle(u: Vec2) -> Vec2 {
    let t = (1.0 - u.x).max(0.0).sqrt();
    Vec2::new(1.0 - t, u.y * t)
}

/// A piecewise-constant discrete distribution over `n` items (light selection by power).
#[derive(Debug, Clone, Default)]
pub struct Distribution1D {
    /// Normalised probabilities.
    pmf: Vec<f32>,
    /// Cumulative sums, `cdf[n] = 1`.
    cdf: Vec<f32>,
    /// Sum of the unnormalised weights.
    total: f32,
}

impl Distribution1D {
    /// Builds the distribution from non-negative weights; all-zero weights become uniform.
    pub fn new(weights: &[f32]) -> Self {
        let n = weights.len();
        let clean: Vec<f64> = weights
            .iter()
            .map(|&w| {
                if w.is_finite() && w > 0.0 {
                    w as f64
                } else {
                    0.0
                }
            })
            .collect();
        let mut total: f64 = clean.iter().sum();
        let uniform = total <= 0.0;
        if uniform {
            total = n as f64;
        }
        let mut pmf = Vec::with_capacity(n);
        let mut cdf = Vec::with_capacity(n + 1);
        let mut acc = 0.0f64;
        cdf.push(0.0);
        for w in clean {
            let p = if uniform { 1.0 / n as f64 } else { w / total };
            pmf.push(p as f32);
            acc += p;
            cdf.push(acc as f32);
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        Distribution1D {
            pmf,
            cdf,
            total: if uniform { 0.0 } else { total as f32 },
        }
    }

    /// Number of items.
    pub fn len(&self) -> usize {
        self.pmf.len()
    }

    /// Whether there are no items.
    pub fn is_empty(&self) -> bool {
        self.pmf.is_empty()
    }

    /// Sum of the weights the distribution was built from.
    pub fn total(&self) -> f32 {
        self.total
    }

    /// Probability of item `i`.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf[i]
    }

    /// Picks an item with `u` in [0,1); returns (index, probability, `u` rescaled to [0,1) within
    /// the chosen item so it can be reused).
    #[inline]
    pub fn sample(&self, u: f32) -> (usize, f32, f32) {
        // Last index with cdf[i] <= u among 0..n.
        let n = self.pmf.len();
        // The cdf ascends, so the count of entries <= u is the partition point; for the short
        // tables of emitter meshes (a quad: 3 entries) a branch-free count beats the binary
        // search's mispredicted branches.
        let at_or_below = if self.cdf.len() <= 9 {
            self.cdf.iter().map(|&c| usize::from(c <= u)).sum()
        } else {
            self.cdf.partition_point(|&c| c <= u)
        };
        let mut i = at_or_below.saturating_sub(1);
        while i + 1 < n && self.pmf[i] == 0.0 {
            i += 1;
        }
        let i = i.min(n - 1);
        let p = self.pmf[i];
        let du = if p > 0.0 {
            ((u - self.cdf[i]) / p).clamp(0.0, 1.0 - f32::EPSILON)
        } else {
            0.0
        };
        (i, p, du)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_sin_cos_is_accurate_and_disk_points_stay_inside() {
        for k in 0..=20_000 {
            let a = (k as f32 / 10_000.0 - 1.0) * FRAC_PI_4;
            let (s, c) = sin_cos_quarter(a);
            let (s64, c64) = (a as f64).sin_cos();
            assert!(
                (s as f64 - s64).abs() < 1.5e-7,
                "sin({a}) = {s}, want {s64}"
            );
            assert!(
                (c as f64 - c64).abs() < 1.5e-7,
                "cos({a}) = {c}, want {c64}"
            );
        }
        let mut rng = rng_for(5, 0, 0);
        for _ in 0..20_000 {
            let u = Vec2::new(rng.next_f32(), rng.next_f32());
            let d = square_to_uniform_disk_concentric(u);
            // The radius is |2u − 1| along the dominant axis, exactly as with libm's sin/cos.
            let o = 2.0 * u - Vec2::ONE;
            let r = o.x.abs().max(o.y.abs());
            assert!(
                (d.length() - r).abs() < 3e-7,
                "u {u}: |d| = {}, want {r}",
                d.length()
            );
        }
    }

    #[test]
    fn rng_streams_are_deterministic_and_distinct() {
        let a: Vec<f32> = (0..4)
            .map(|_| 0.0)
            .scan(rng_for(1, 2, 3), |r, _| Some(r.next_f32()))
            .collect();
        let b: Vec<f32> = (0..4)
            .map(|_| 0.0)
            .scan(rng_for(1, 2, 3), |r, _| Some(r.next_f32()))
            .collect();
        let c: Vec<f32> = (0..4)
            .map(|_| 0.0)
            .scan(rng_for(1, 2, 4), |r, _| Some(r.next_f32()))
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
        let mut r = rng_for(7, 0, 0);
        let mean: f64 = (0..100_000).map(|_| r.next_f32() as f64).sum::<f64>() / 100_000.0;
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
    }

    /// The power heuristic gives the hand-computed a²/(a² + b²) (not the balance heuristic's
    /// a/(a + b)), its complements sum to one, and the documented 0 and ∞ cases hold.
    #[test]
    fn mis_weights_are_the_power_heuristic_and_sum_to_one() {
        // (a, b, a²/(a² + b²) by hand).
        for (a, b, want) in [
            (0.3f32, 2.0f32, 0.09f64 / 4.09),
            (1.0, 2.0, 0.2),
            (2.0, 1.0, 0.8),
            (3.0, 4.0, 9.0 / 25.0),
            (5.0, 5.0, 0.5),
            (1e-3, 10.0, 1e-6 / (1e-6 + 100.0)),
            (0.0, 1.0, 0.0),
        ] {
            let got = f64::from(power_heuristic(a, b));
            assert!(
                (got - want).abs() <= 1e-6 * want.max(1e-6),
                "power_heuristic({a}, {b}) = {got}, want {want}"
            );
            let s = power_heuristic(a, b) + power_heuristic(b, a);
            assert!((s - 1.0).abs() < 1e-6, "{a} {b}: weights sum to {s}");
        }
        // Densities whose squares overflow or underflow f32 share the weight by their ratio
        // (a²/(a² + b²) gave both 1, or both 0).
        for (a, b, want) in [
            (1e20f32, 1e20f32, 0.5f64),
            (1e20, 1e19, 100.0 / 101.0),
            (3e25, 1e25, 0.9),
            (1e-25, 1e-25, 0.5),
            (1e-25, 3e-25, 0.1),
            (1e-30, 1e-28, 1.0 / 10_001.0),
        ] {
            let got = f64::from(power_heuristic(a, b));
            assert!(
                (got - want).abs() <= 1e-6 * want,
                "power_heuristic({a}, {b}) = {got}, want {want}"
            );
            let s = power_heuristic(a, b) + power_heuristic(b, a);
            assert!((s - 1.0).abs() < 1e-6, "{a} {b}: weights sum to {s}");
        }
        assert_eq!(power_heuristic(f32::INFINITY, f32::INFINITY), 0.5);
        assert_eq!(power_heuristic(f32::NAN, 1.0), 0.0);
        assert_eq!(power_heuristic(1.0, f32::NAN), 0.0);
        // Neither strategy can produce the sample: no weight (not NaN).
        assert_eq!(power_heuristic(0.0, 0.0), 0.0, "power_heuristic(0, 0)");
        // A delta strategy (infinite density) takes all the weight against a finite one.
        assert_eq!(
            power_heuristic(f32::INFINITY, 3.0),
            1.0,
            "power_heuristic(inf, 3)"
        );
        assert_eq!(
            power_heuristic(f32::INFINITY, 0.0),
            1.0,
            "power_heuristic(inf, 0)"
        );
        assert_eq!(
            power_heuristic(3.0, f32::INFINITY),
            0.0,
            "power_heuristic(3, inf)"
        );
        assert_eq!(
            power_heuristic(0.0, f32::INFINITY),
            0.0,
            "power_heuristic(0, inf)"
        );
    }

    /// Monte Carlo integral of a density over its domain must be 1 (uniform sphere estimator).
    #[test]
    fn warps_match_their_densities() {
        let mut r = rng_for(3, 0, 0);
        let n = 200_000;
        // ∫ pdf_cos dω = 1, estimated with uniform sphere samples.
        let mut acc = 0.0f64;
        let cos_max = 0.8f32;
        let mut cone_acc = 0.0f64;
        for _ in 0..n {
            let d = square_to_uniform_sphere(r.next_2d());
            acc += (cosine_hemisphere_pdf(d) / UNIFORM_SPHERE_PDF) as f64;
            if d.z >= cos_max {
                cone_acc += (uniform_cone_pdf(cos_max) / UNIFORM_SPHERE_PDF) as f64;
            }
        }
        assert!((acc / n as f64 - 1.0).abs() < 0.01);
        assert!((cone_acc / n as f64 - 1.0).abs() < 0.03);
        // Cosine samples: E[z] = 2/3 under the cosine density.
        let ez: f64 = (0..n)
            .map(|_| square_to_cosine_hemisphere(r.next_2d()).z as f64)
            .sum::<f64>()
            / n as f64;
        assert!((ez - 2.0 / 3.0).abs() < 0.005);
        // Cone samples stay inside the cone and are unit length.
        for _ in 0..1000 {
            let d = square_to_uniform_cone(r.next_2d(), cos_max);
            assert!(d.z >= cos_max - 1e-6 && (d.length() - 1.0).abs() < 1e-5);
        }
        // Triangle: mean barycentrics are 1/3.
        let m = (0..n)
            .map(|_| square_to_uniform_triangle(r.next_2d()))
            .fold(Vec2::ZERO, |a, b| a + b)
            / n as f32;
        assert!((m - Vec2::splat(1.0 / 3.0)).abs().max_element() < 0.005);
    }

    /// The documented contract of `sample`, by linear scan: the item is the last `i` with
    /// `cdf[i] <= u` among the items of non-zero probability, its probability is `pmf[i]` and
    /// the remapped `u` is `(u - cdf[i]) / pmf[i]` in [0, 1).
    fn sample_by_linear_scan(d: &Distribution1D, u: f32) -> (usize, f32, f64) {
        let mut pick = None;
        for i in 0..d.len() {
            if d.pmf[i] > 0.0 && d.cdf[i] <= u {
                pick = Some(i);
            }
        }
        let i = pick.expect("some item of non-zero probability starts at or below u");
        let p = d.pmf[i];
        let du = (f64::from(u) - f64::from(d.cdf[i])) / f64::from(p);
        (i, p, du)
    }

    /// `Distribution1D::sample` on short tables (the branch-free count, n + 1 <= 9 cdf entries)
    /// and long ones (the binary search) picks what a linear scan of the documented contract
    /// picks, with zero weights, `u` = 0, `u` exactly on cdf entries, just below them and just
    /// below 1; the probability and the remapped `u` are the contract's too.
    #[test]
    fn sample_matches_a_linear_scan_on_short_and_long_tables() {
        let mut rng = rng_for(31, 0, 0);
        let below_one = 1.0 - f32::EPSILON / 2.0;
        let mut checked = [0usize; 2];
        for n in 1..=12usize {
            // Fixed patterns (leading, inner, trailing and all-but-one zeros), then random ones.
            let mut tables: Vec<Vec<f32>> = vec![
                (0..n).map(|i| (i + 1) as f32).collect(),
                (0..n).map(|i| if i == 0 { 0.0 } else { 1.0 }).collect(),
                (0..n).map(|i| if i + 1 == n { 0.0 } else { 2.0 }).collect(),
                (0..n).map(|i| if i % 2 == 1 { 0.0 } else { 0.5 }).collect(),
                (0..n).map(|i| if i == n / 2 { 3.0 } else { 0.0 }).collect(),
            ];
            for _ in 0..30 {
                tables.push(
                    (0..n)
                        .map(|_| {
                            let x = rng.next_f32();
                            if x < 0.3 {
                                0.0
                            } else {
                                x
                            }
                        })
                        .collect(),
                );
            }
            for w in tables {
                let d = Distribution1D::new(&w);
                assert_eq!(d.cdf.len(), n + 1, "{w:?}: cdf length");
                // The cdf is the running sum of the normalised weights, ending at exactly 1.
                let total: f64 = w.iter().map(|&x| f64::from(x)).sum();
                let mut acc = 0.0f64;
                for i in 0..n {
                    let want_pmf = if total > 0.0 {
                        f64::from(w[i]) / total
                    } else {
                        1.0 / n as f64
                    };
                    assert!(
                        (f64::from(d.cdf[i]) - acc).abs() < 1e-6
                            && (f64::from(d.pmf(i)) - want_pmf).abs() < 1e-6,
                        "{w:?}: cdf[{i}] = {}, pmf = {} (want {acc}, {want_pmf})",
                        d.cdf[i],
                        d.pmf(i)
                    );
                    acc += want_pmf;
                }
                assert_eq!(d.cdf[n], 1.0, "{w:?}: cdf[n]");
                let mut us = vec![0.0, below_one];
                for &c in &d.cdf[..n] {
                    us.push(c);
                    if c > 0.0 {
                        us.push(c.next_down());
                    }
                    if c.next_up() < 1.0 {
                        us.push(c.next_up());
                    }
                }
                us.extend((0..20).map(|_| rng.next_f32()));
                // `u` lies in [0, 1): cdf entries of trailing zero weights are 1 already.
                us.retain(|&u| u < 1.0);
                for u in us {
                    let (i, p, du) = d.sample(u);
                    let (want_i, want_p, want_du) = sample_by_linear_scan(&d, u);
                    assert_eq!(
                        (i, p),
                        (want_i, want_p),
                        "{w:?} (cdf {:?}): sample({u}) index and probability",
                        d.cdf
                    );
                    assert!(
                        p > 0.0,
                        "{w:?}: sample({u}) picked item {i} of probability 0"
                    );
                    let want_du = want_du.clamp(0.0, f64::from(1.0 - f32::EPSILON));
                    assert!(
                        (f64::from(du) - want_du).abs() <= 1e-5 && (0.0..1.0).contains(&du),
                        "{w:?} (cdf {:?}): sample({u}) remapped u = {du}, want {want_du}",
                        d.cdf
                    );
                    checked[usize::from(d.cdf.len() > 9)] += 1;
                }
            }
        }
        // Both arms of `sample` ran (short tables up to n = 8, binary search from n = 9).
        assert!(checked[0] > 1000 && checked[1] > 1000, "{checked:?}");
    }

    #[test]
    fn distribution_samples_proportionally() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0]);
        assert_eq!(d.sample(0.0).0, 0);
        assert_eq!(d.sample(0.2).0, 0);
        assert_eq!(d.sample(0.3).0, 2);
        assert_eq!(d.sample(0.999_999).0, 2);
        assert!((d.pmf(2) - 0.75).abs() < 1e-6);
        let (_, _, du) = d.sample(0.625);
        assert!((du - 0.5).abs() < 1e-5);
        let u = Distribution1D::new(&[0.0, 0.0]);
        assert_eq!(u.pmf(1), 0.5);
    }
}
