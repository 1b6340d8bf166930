//! Where the eye subpaths' random numbers come from, pass after pass ([`EyeSampler`]):
//! independent PCG32 draws, or a low-discrepancy sequence over the passes — pass i of a pixel
//! takes point i of the pixel's own scrambled (0, 2)-sequence in each of the first
//! [`LOW_DISCREPANCY_DIMENSIONS`] draws of a subpath (film position, lens, the visible point's
//! light samples and MIS probe), so the passes stratify them instead of drawing each anew.
//! Later draws, and photons, stay PCG32's.
//!
//! The points follow Burley ("Practical Hash-based Owen Scrambling", JCGT 2020): the first two
//! Sobol dimensions, Owen-scrambled by a hash, with the point's index itself shuffled by a
//! nested uniform scramble drawn per dimension, so that different dimensions are decorrelated
//! (Kollig and Keller's padding, as in Mitsuba's `ldsampler`) while any first 2^k passes of a
//! pixel still form a stratified (0, k, 2)-net: a progressive render need not know its pass
//! count in advance. Each pass's point is uniformly distributed whatever the scrambles, so each
//! pass's estimate keeps its expectation and the mean over passes converges as before.

use crate::sampling::{hash3, mix64, rng_for, Pcg32, UniformSource};
use glam::Vec2;
use serde::{Deserialize, Serialize};

/// Draws of an eye subpath (each one- or two-dimensional) taken from the low-discrepancy
/// sequence: enough for the film and lens samples, a glossy vertex and the visible point's
/// two light samples and MIS probe; later draws come from PCG32.
pub const LOW_DISCREPANCY_DIMENSIONS: u32 = 12;

/// How an eye subpath's random numbers relate across passes.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum,
)]
pub enum EyeSampler {
    /// Every pass draws anew (Mitsuba's `independent`; every bundle before 2026-12-06).
    #[default]
    #[serde(rename = "independent")]
    #[value(name = "independent")]
    Independent,
    /// The passes of a pixel stratify its first draws: a scrambled, padded (0, 2)-sequence
    /// (as Mitsuba's `ldsampler`).
    #[serde(rename = "ldsampler")]
    #[value(name = "ldsampler")]
    LowDiscrepancy,
}

impl EyeSampler {
    /// The name in bundle metadata, run states and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            EyeSampler::Independent => "independent",
            EyeSampler::LowDiscrepancy => "ldsampler",
        }
    }
}

/// The second Sobol dimension's direction numbers (generator matrix of the primitive polynomial
/// x + 1: v₀ = 2³¹, v_{k+1} = v_k ⊕ v_k/2), bit-reversed (the scrambling works on reversed
/// fractions) and XOR-combined per byte of the index: entry [b][v] is the XOR of the reversed
/// directions of the set bits of v placed at byte b.
const SOBOL_SECOND_REVERSED_BYTES: [[u32; 256]; 4] = {
    let mut directions = [0u32; 32];
    let mut v = 1u32 << 31;
    let mut k = 0;
    while k < 32 {
        directions[k] = v.reverse_bits();
        v ^= v >> 1;
        k += 1;
    }
    let mut table = [[0u32; 256]; 4];
    let mut b = 0;
    while b < 4 {
        let mut byte = 0;
        while byte < 256 {
            let mut x = 0u32;
            let mut bit = 0;
            while bit < 8 {
                if byte & (1 << bit) != 0 {
                    x ^= directions[8 * b + bit];
                }
                bit += 1;
            }
            table[b][byte] = x;
            byte += 1;
        }
        b += 1;
    }
    table
};

/// The second Sobol dimension of index `i` as a 32-bit fraction, bit-reversed (the first
/// dimension, reversed, is `i` itself).
#[inline]
fn sobol_second_reversed(i: u32) -> u32 {
    let t = &SOBOL_SECOND_REVERSED_BYTES;
    t[0][(i & 0xff) as usize]
        ^ t[1][((i >> 8) & 0xff) as usize]
        ^ t[2][((i >> 16) & 0xff) as usize]
        ^ t[3][(i >> 24) as usize]
}

/// Laine and Karras's hash permutation with Burley's constants: bit k of the result depends on
/// bits 0..=k of `x` only.
#[inline]
fn lk_permutation(mut x: u32, seed: u32) -> u32 {
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x
}

/// Owen scrambling of a 32-bit fraction given bit-reversed (`reversed` = x.reverse_bits()):
/// each bit of x flipped by a function of the bits above it (a bijection that keeps every
/// dyadic interval's points in one dyadic interval).
#[inline]
fn owen_scramble_reversed(reversed: u32, seed: u32) -> u32 {
    lk_permutation(reversed, seed).reverse_bits()
}

/// A 32-bit fraction as an `f32` in [0, 1) (its top 24 bits).
#[inline]
fn to_unit(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// Point `index` (given bit-reversed) of the scrambled 2D sequence of the 96-bit seed
/// (`shuffle`, `scramble`): the index shuffled by a nested uniform scramble, then each Sobol
/// coordinate Owen-scrambled with its own half of `scramble`. (The first coordinate of index
/// i is i reversed, so its reversed form is i itself.)
#[inline]
fn scrambled_point(reversed_index: u32, shuffle: u32, scramble: u64) -> (u32, u32) {
    let i = owen_scramble_reversed(reversed_index, shuffle);
    (
        owen_scramble_reversed(i, scramble as u32),
        owen_scramble_reversed(sobol_second_reversed(i), (scramble >> 32) as u32),
    )
}

/// The random numbers of one eye subpath in one pass.
pub struct PassSampler {
    /// The stream's PCG32 generator of this pass.
    rng: Pcg32,
    /// The pass's point index (pass − 1), bit-reversed.
    reversed_index: u32,
    /// The pixel's scrambles (the same in every pass), under [`EyeSampler::LowDiscrepancy`].
    scrambles: Option<u64>,
    /// Draws taken so far.
    dimension: u32,
}

impl PassSampler {
    /// Pass `pass` (1-based) of the subpath stream `stream` (pixel and subpath) of a run
    /// seeded `seed`. The stream's PCG32 generator of that pass, `rng_for(seed, pass, stream)`,
    /// supplies every draw under [`EyeSampler::Independent`] and the draws past the sequence's
    /// dimensions.
    pub fn new(sampler: EyeSampler, seed: u64, stream: u64, pass: u32) -> Self {
        PassSampler {
            rng: rng_for(seed, pass as u64, stream),
            reversed_index: pass.wrapping_sub(1).reverse_bits(),
            // Apart from every PCG32 stream.
            scrambles: (sampler == EyeSampler::LowDiscrepancy)
                .then(|| hash3(seed ^ 0x1d5a_3c0f_7b2e_9a41, 0, stream)),
            dimension: 0,
        }
    }

    /// This draw's point of the sequence, or `None` when PCG32 supplies it.
    #[inline]
    fn point(&mut self) -> Option<(u32, u32)> {
        let scrambles = self.scrambles?;
        if self.dimension >= LOW_DISCREPANCY_DIMENSIONS {
            return None;
        }
        // Two 64-bit hashes of (pixel's scrambles, draw) give the draw's three 32-bit seeds.
        let a = mix64(scrambles ^ (self.dimension as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let b = mix64(a ^ 0xd1b5_4a32_d192_ed03);
        self.dimension += 1;
        Some(scrambled_point(self.reversed_index, (a >> 32) as u32, b))
    }
}

impl UniformSource for PassSampler {
    #[inline]
    fn next_f32(&mut self) -> f32 {
        match self.point() {
            Some((x, _)) => to_unit(x),
            None => self.rng.next_f32(),
        }
    }

    #[inline]
    fn next_2d(&mut self) -> Vec2 {
        match self.point() {
            Some((x, y)) => Vec2::new(to_unit(x), to_unit(y)),
            None => self.rng.next_2d(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::rng_for;

    /// The first 2^k passes' points of one dimension, as drawn by the integrator.
    fn points(sampler: EyeSampler, stream: u64, dimension: u32, k: u32) -> Vec<Vec2> {
        (1..=1u32 << k)
            .map(|pass| {
                let mut s = PassSampler::new(sampler, 9, stream, pass);
                for _ in 0..dimension {
                    s.next_2d();
                }
                s.next_2d()
            })
            .collect()
    }

    /// The byte table gives the second Sobol dimension bit by bit: v₀ = 2³¹, v_{k+1} = v_k ⊕
    /// v_k/2, XORed over the index's set bits.
    #[test]
    fn the_second_dimension_follows_its_direction_numbers() {
        let slow = |mut i: u32| {
            let (mut v, mut r) = (1u32 << 31, 0u32);
            while i != 0 {
                if i & 1 != 0 {
                    r ^= v;
                }
                i >>= 1;
                v ^= v >> 1;
            }
            r
        };
        let table = |i: u32| sobol_second_reversed(i).reverse_bits();
        for i in (0..5000u32).chain([u32::MAX, 0x8000_0000, 0x1234_5678, 0xdead_beef]) {
            assert_eq!(table(i), slow(i), "index {i}");
        }
        // The first points: 1/2, then 3/4 and 1/4 (the (0, 2)-sequence's second coordinate).
        assert_eq!(table(1), 1 << 31);
        assert_eq!(table(2), 3 << 30);
        assert_eq!(table(3), 1 << 30);
    }

    /// Every first 2^k passes form a (0, k, 2)-net in every low-discrepancy dimension: each
    /// elementary interval of area 2^-k (2^a by 2^(k-a) cells) holds exactly one point — the
    /// property a scrambling or shuffling bug destroys first.
    #[test]
    fn the_first_power_of_two_passes_form_a_net() {
        for stream in [0u64, 1, 12_345] {
            for dimension in [0, 1, 5, LOW_DISCREPANCY_DIMENSIONS - 1] {
                for k in [1u32, 4, 7, 8] {
                    let pts = points(EyeSampler::LowDiscrepancy, stream, dimension, k);
                    for a in 0..=k {
                        let (nx, ny) = (1u32 << a, 1u32 << (k - a));
                        let mut seen = vec![false; 1 << k];
                        for p in &pts {
                            let cell = (p.x * nx as f32) as u32 * ny + (p.y * ny as f32) as u32;
                            assert!(
                                !std::mem::replace(&mut seen[cell as usize], true),
                                "stream {stream}, dimension {dimension}, 2^{k} passes: two \
                                 points in one {nx}x{ny} cell"
                            );
                        }
                    }
                }
            }
        }
    }

    /// Different pixels and dimensions get different scrambles (no two alike), and the draws
    /// past the sequence's dimensions, like every independent draw, are PCG32's own.
    #[test]
    fn scrambles_differ_and_later_draws_are_the_streams() {
        let a = points(EyeSampler::LowDiscrepancy, 3, 0, 4);
        assert_ne!(a, points(EyeSampler::LowDiscrepancy, 4, 0, 4));
        assert_ne!(a, points(EyeSampler::LowDiscrepancy, 3, 1, 4));
        for pass in [1u32, 2, 77] {
            let mut rng = rng_for(9, pass as u64, 3);
            let mut s = PassSampler::new(EyeSampler::Independent, 9, 3, pass);
            for _ in 0..20 {
                assert_eq!(s.next_2d(), rng.next_2d());
            }
            let mut rng = rng_for(9, pass as u64, 3);
            let mut s = PassSampler::new(EyeSampler::LowDiscrepancy, 9, 3, pass);
            for _ in 0..LOW_DISCREPANCY_DIMENSIONS {
                s.next_f32();
            }
            assert_eq!(s.next_2d(), rng.next_2d());
        }
    }

    /// Each pass's point is uniform over the scrambles: over many pixels, the mean of a pass's
    /// coordinates and of their squares match the uniform distribution's 1/2 and 1/3 (to four
    /// standard errors), at a pass that is not the first of a net.
    #[test]
    fn each_pass_is_uniform_over_pixels() {
        let n = 20_000u64;
        for pass in [1u32, 6, 1000] {
            let (mut sx, mut sxx, mut sy, mut syy) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for stream in 0..n {
                let mut s = PassSampler::new(EyeSampler::LowDiscrepancy, 1, stream, pass);
                let p = s.next_2d();
                sx += p.x as f64;
                sxx += (p.x * p.x) as f64;
                sy += p.y as f64;
                syy += (p.y * p.y) as f64;
            }
            let tol_mean = 4.0 * (1.0f64 / 12.0 / n as f64).sqrt();
            let tol_square = 4.0 * (4.0f64 / 45.0 / n as f64).sqrt();
            for (m, m2) in [(sx, sxx), (sy, syy)] {
                assert!(
                    (m / n as f64 - 0.5).abs() < tol_mean,
                    "pass {pass}: mean {}",
                    m / n as f64
                );
                assert!(
                    (m2 / n as f64 - 1.0 / 3.0).abs() < tol_square,
                    "pass {pass}"
                );
            }
        }
    }
}
