//! Kernel bandwidths of the multi-level estimates: nested initial radii from the k-NN distance,
//! the choice of radius schedule ([`RadiusSchedule`]), and SPPM's deterministic progressive
//! shrink (Knaus & Zwicker's r² ← r²·(i+α)/(i+1)). CPPM's data-driven rule is in
//! [`super::cppm`].

use serde::{Deserialize, Serialize};

/// Number of estimate levels.
pub const LEVELS: usize = 5;

/// Ratio between consecutive levels' radii: r_ℓ = r₅ / √2^(5−ℓ).
pub const LEVEL_RATIO: f32 = std::f32::consts::SQRT_2;

/// How the kernel radii evolve over passes. Either way each level starts from its nested
/// initial radius and the pixel value is the mean of the per-pass kernel estimates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum RadiusSchedule {
    /// SPPM: every radius shrinks after every pass by r² ← r²·(i+α)/(i+1), all levels
    /// together (they stay nested).
    #[default]
    Sppm,
    /// CPPM (chi-squared progressive photon mapping): each level keeps its radius while the
    /// photons inside look uniform (a χ² test on 12 equal-area cells) and shrinks it
    /// otherwise, independently of the other levels.
    Cppm,
}

impl RadiusSchedule {
    /// The name on command lines, in configs and in bundle metadata.
    pub fn name(self) -> &'static str {
        match self {
            RadiusSchedule::Sppm => "sppm",
            RadiusSchedule::Cppm => "cppm",
        }
    }
}

/// The five nested radii (sharpest first) from the largest one, r₅.
#[inline]
pub fn nested_radii(r5: f32) -> [f32; LEVELS] {
    let mut r = [0.0; LEVELS];
    let mut current = r5;
    for level in (0..LEVELS).rev() {
        r[level] = current;
        current /= LEVEL_RATIO;
    }
    r
}

/// Squared-radius shrink factor applied after pass `i` (1-based): r²_{i+1} = r²_i·(i+α)/(i+1).
#[inline]
pub fn shrink_factor(i: u32, alpha: f32) -> f32 {
    (i as f32 + alpha) / (i as f32 + 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radii_are_nested_by_sqrt2() {
        let r = nested_radii(1.0);
        assert_eq!(r[4], 1.0);
        for l in 0..4 {
            assert!((r[l + 1] / r[l] - std::f32::consts::SQRT_2).abs() < 1e-6);
        }
        assert!((r[0] - 0.25).abs() < 1e-6, "r1 = r5/√2⁴ = r5/4");
    }

    #[test]
    fn shrink_schedule_follows_closed_form() {
        // Π_{i=1}^{n-1} (i+α)/(i+1) = Γ(n+α)/(Γ(1+α)·Γ(n+1)) ~ n^(α−1)/Γ(1+α).
        let alpha = 2.0 / 3.0;
        let mut r2 = 1.0f64;
        let n = 10_000u32;
        for i in 1..n {
            r2 *= shrink_factor(i, alpha) as f64;
        }
        let gamma_1_alpha = 0.902_745_292_950_934_f64; // Γ(5/3)
        let asymptotic = (n as f64).powf(alpha as f64 - 1.0) / gamma_1_alpha;
        assert!((r2 / asymptotic - 1.0).abs() < 1e-3, "{r2} vs {asymptotic}");
        assert_eq!(shrink_factor(1, alpha), (1.0 + alpha) / 2.0);
    }
}
