//! Screen-space filtered levels (docs/method.md §9, "More correlated levels"): a correlated level
//! z̃ʲ smoothed across pixels by a cross-bilateral filter guided by the G-buffer, put in the
//! place of one of the bundle's levels before packing, its spatial bandwidth shrinking as passes
//! grow: σ(N) = σ₀ · (N / 64)^(−1/6), the rate at which SPPM's radii shrink.
//!
//! Why: Eq. 6 keeps z̃ʲ_c — the level at the pixel itself — in the output with weight one, and
//! every z̃ level carries eye subpath B's ray-tracing noise (glossy lobes, depth of field, the
//! pixel footprint), so no choice of weights removes it: the floor of the method. Averaged over
//! neighbouring pixels that see the same surface (same albedo, normal and depth), that noise
//! falls; the filter's blur is a bias that Eq. 6's difference terms z̃ʲ_c − z̃ʲ_i partly cancel and
//! the network can weigh against the unfiltered levels.
//!
//! Consistency: the filter's weight on any other pixel is at most exp(−1/(2σ²)), which vanishes
//! as σ(N) → 0, so the filtered level tends to the level itself, which converges to the true
//! image; Eq. 6 converges whatever its weights when all its levels do (§5.4). Beyond
//! [`MIN_SIGMA`] the filter is the identity exactly.
//!
//! With the photon-free layers (`ydirect`, `zdirect`), only the photon part of the level is
//! filtered (z̃ − d_B, then d_B added back): the combination takes d_B out of every z̃ level and
//! adds the fused direct light after Eq. 6, which must not be spread across pixels (a light seen
//! in one pixel would halo).

use bundle::{Bundle, Image};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Pass count at which σ = σ₀.
pub const SIGMA_PASSES: f64 = 64.0;

/// Exponent of σ's decay with passes: SPPM's radii shrink as N^(−(1−α)/2) = N^(−1/6) with
/// α = 2/3, so the filter's bias falls as the kernel estimate's own.
pub const SIGMA_DECAY: f64 = 1.0 / 6.0;

/// Below this σ the filter is the identity (a neighbour's weight would be below e^−12.5).
pub const MIN_SIGMA: f64 = 0.2;

/// Widest filter radius in pixels (the window is (2r + 1)²).
pub const MAX_RADIUS: usize = 8;

/// Guide tolerances: albedo difference (Euclidean, RGB in [0, 1]), shading-normal difference
/// (Euclidean between unit vectors: 0.3 ≈ 17°), depth difference relative to the pixel's depth.
const ALBEDO_SIGMA: f32 = 0.1;
const NORMAL_SIGMA: f32 = 0.3;
const DEPTH_SIGMA: f32 = 0.05;

/// One screen-space level: level `source` (1..4 = z̃1..z̃4) filtered with bandwidth `sigma` (in
/// pixels at [`SIGMA_PASSES`] passes), put in the place of level `slot` (1..4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScreenLevel {
    /// The level slot it replaces (1..4).
    pub slot: usize,
    /// The level it filters (1..4).
    pub source: usize,
    /// σ₀ in pixels at [`SIGMA_PASSES`] passes.
    pub sigma: f32,
    /// Strength k of the range term: a neighbour whose colour differs from the pixel's by more
    /// than their noise explains loses weight as exp(−max(0, d² − V) / (k² V)), with d² the
    /// squared difference (mean over RGB) and V the sum of the two pixels' variances. 0: no
    /// range term (the G-buffer alone).
    #[serde(default = "default_range")]
    pub range: f32,
}

/// The range strength of screen levels that name none: on a glossy shelf (data/small
/// 032-shelf, 100 000 photons, 64 and 256 passes) Eq. 6 with uniform guided weights over the
/// filtered z̃4 had 0.40× and 0.62× the error of the unfiltered one with k = 2, against 0.44× and
/// 0.88× with the G-buffer alone at its best σ (docs/results.md).
pub const DEFAULT_RANGE: f32 = 2.0;

/// Serde default of [`ScreenLevel::range`].
fn default_range() -> f32 {
    DEFAULT_RANGE
}

/// σ at `passes` for a σ₀ of `sigma`.
pub fn sigma_at(sigma: f32, passes: u32) -> f64 {
    f64::from(sigma) * (f64::from(passes.max(1)) / SIGMA_PASSES).powf(-SIGMA_DECAY)
}

/// Checks a list of screen levels: slots and sources in 1..4, slots distinct, σ₀ positive and
/// finite.
pub fn validate(levels: &[ScreenLevel]) -> Result<(), String> {
    let mut slots = Vec::new();
    for (i, l) in levels.iter().enumerate() {
        if !(1..=4).contains(&l.slot) || !(1..=4).contains(&l.source) {
            return Err(format!(
                "screen_levels[{i}]: slot and source must be 1..4 (z1..z4), got slot {} source {}",
                l.slot, l.source
            ));
        }
        if !(l.sigma.is_finite() && l.sigma > 0.0) {
            return Err(format!(
                "screen_levels[{i}]: sigma must be a positive number of pixels, got {}",
                l.sigma
            ));
        }
        if !(l.range.is_finite() && l.range >= 0.0) {
            return Err(format!(
                "screen_levels[{i}]: range must be 0 (off) or positive, got {}",
                l.range
            ));
        }
        if slots.contains(&l.slot) {
            return Err(format!(
                "screen_levels[{i}]: slot {} is replaced twice",
                l.slot
            ));
        }
        slots.push(l.slot);
    }
    Ok(())
}

/// The bundle with its screen levels in place (a copy; `levels` empty: the bundle unchanged).
/// Sources are read from the original levels, so one level can feed several slots. The caller
/// has checked the bundle's shapes ([`crate::features::pack`] does it again).
pub fn apply(bundle: &Bundle, levels: &[ScreenLevel]) -> Bundle {
    let mut out = bundle.clone();
    for l in levels {
        let sigma = sigma_at(l.sigma, bundle.meta.passes);
        let source = &bundle.levels[l.source];
        let direct = bundle.direct.as_ref().map(|d| &d.z);
        let (colour, variance) = filter(bundle, source, l.source, direct, sigma, l.range);
        out.levels[l.slot] = colour;
        let channels = out.variance.channels;
        for (p, v) in variance.into_iter().enumerate() {
            out.variance.data[p * channels + l.slot] = v;
        }
    }
    out
}

/// Filters `level` (its variance: plane `index` of the bundle's variance layer) with bandwidth
/// `sigma` and range strength `range`, guided by the bundle's G-buffer; `direct`, when present,
/// is left unfiltered. Returns the filtered level and its variance Σ k² v / (Σ k)² (pixels taken
/// as independent).
fn filter(
    bundle: &Bundle,
    level: &Image,
    index: usize,
    direct: Option<&Image>,
    sigma: f64,
    range: f32,
) -> (Image, Vec<f32>) {
    let (w, h) = (level.width, level.height);
    let var_channels = bundle.variance.channels;
    let variance: Vec<f32> = (0..w * h)
        .map(|p| bundle.variance.data[p * var_channels + index])
        .collect();
    if sigma < MIN_SIGMA {
        return (level.clone(), variance);
    }
    let radius = ((2.5 * sigma).ceil() as usize).min(MAX_RADIUS);
    let inv_space = (1.0 / (2.0 * sigma * sigma)) as f32;
    let photon: Vec<f32> = match direct {
        Some(d) => level.data.iter().zip(&d.data).map(|(a, b)| a - b).collect(),
        None => level.data.clone(),
    };
    let (albedo, normal, depth) = (&bundle.albedo.data, &bundle.normal.data, &bundle.depth.data);
    let rows: Vec<(Vec<f32>, Vec<f32>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut colour = vec![0.0f32; 3 * w];
            let mut var = vec![0.0f32; w];
            for x in 0..w {
                let c = y * w + x;
                let dc = depth[c].max(1e-6);
                let mut sum = 0.0f32;
                let mut acc = [0.0f32; 3];
                let mut acc_var = 0.0f32;
                for ny in y.saturating_sub(radius)..(y + radius + 1).min(h) {
                    for nx in x.saturating_sub(radius)..(x + radius + 1).min(w) {
                        let n = ny * w + nx;
                        let (dx, dy) = (nx as f32 - x as f32, ny as f32 - y as f32);
                        let da = (0..3)
                            .map(|k| (albedo[3 * n + k] - albedo[3 * c + k]).powi(2))
                            .sum::<f32>();
                        let dn = (0..3)
                            .map(|k| (normal[3 * n + k] - normal[3 * c + k]).powi(2))
                            .sum::<f32>();
                        let dd = ((depth[n] - depth[c]) / dc).powi(2);
                        let e = (dx * dx + dy * dy) * inv_space
                            + da / (2.0 * ALBEDO_SIGMA * ALBEDO_SIGMA)
                            + dn / (2.0 * NORMAL_SIGMA * NORMAL_SIGMA)
                            + dd / (2.0 * DEPTH_SIGMA * DEPTH_SIGMA);
                        let e = if range > 0.0 {
                            let d2 = (0..3)
                                .map(|k| (level.data[3 * n + k] - level.data[3 * c + k]).powi(2))
                                .sum::<f32>()
                                / 3.0;
                            let v = variance[n] + variance[c];
                            // Differences the noise explains cost nothing; zero variance (a
                            // converged or empty pixel) admits equal colours only.
                            let excess = (d2 - v).max(0.0);
                            e + if excess > 0.0 {
                                excess / (range * range * v).max(f32::MIN_POSITIVE)
                            } else {
                                0.0
                            }
                        } else {
                            e
                        };
                        let k = (-e).exp();
                        sum += k;
                        for (a, p) in acc.iter_mut().zip(&photon[3 * n..3 * n + 3]) {
                            *a += k * p;
                        }
                        acc_var += k * k * variance[n];
                    }
                }
                // The centre's own weight is 1, so `sum` ≥ 1.
                let back = direct.map_or([0.0; 3], |d| {
                    [d.data[3 * c], d.data[3 * c + 1], d.data[3 * c + 2]]
                });
                for k in 0..3 {
                    colour[3 * x + k] = acc[k] / sum + back[k];
                }
                var[x] = acc_var / (sum * sum);
            }
            (colour, var)
        })
        .collect();
    let mut out = Image::new(w, h, 3);
    let mut out_var = Vec::with_capacity(w * h);
    for (y, (colour, var)) in rows.into_iter().enumerate() {
        out.data[3 * y * w..3 * (y + 1) * w].copy_from_slice(&colour);
        out_var.extend(var);
    }
    (out, out_var)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::synthetic_bundle;

    fn screen(slot: usize, source: usize, sigma: f32) -> ScreenLevel {
        ScreenLevel {
            slot,
            source,
            sigma,
            range: 0.0,
        }
    }

    #[test]
    fn sigma_shrinks_like_the_sppm_radii() {
        assert!((sigma_at(2.0, 64) - 2.0).abs() < 1e-12);
        // 64× the passes: 64^(−1/6) = 1/2.
        assert!((sigma_at(2.0, 4096) - 1.0).abs() < 1e-12);
        assert!(sigma_at(2.0, 1 << 30) < MIN_SIGMA);
    }

    #[test]
    fn bad_screen_levels_are_rejected() {
        assert!(validate(&[screen(4, 4, 1.5)]).is_ok());
        assert!(validate(&[screen(0, 4, 1.5)]).is_err());
        assert!(validate(&[screen(4, 5, 1.5)]).is_err());
        assert!(validate(&[screen(4, 4, 0.0)]).is_err());
        assert!(validate(&[screen(4, 4, f32::NAN)]).is_err());
        assert!(validate(&[screen(3, 4, 1.0), screen(3, 2, 2.0)]).is_err());
    }

    #[test]
    fn a_flat_surface_is_averaged_and_variance_falls() {
        // One surface (constant G-buffer), the level alternating 1 ± 0.5 from pixel to pixel:
        // the filter averages it towards 1 and its variance plane falls below the input's.
        let (mut b, _) = synthetic_bundle(16, 16, 0.1, 1);
        b.meta.passes = 64;
        for p in 0..256 {
            for k in 0..3 {
                b.albedo.data[3 * p + k] = 0.5;
                b.normal.data[3 * p + k] = [0.0, 0.0, 1.0][k];
                b.levels[4].data[3 * p + k] = if (p + p / 16) % 2 == 0 { 1.5 } else { 0.5 };
            }
            b.depth.data[p] = 2.0;
            b.variance.data[p * 5 + 4] = 0.25;
        }
        b.direct = None;
        let out = apply(&b, &[screen(4, 4, 1.5)]);
        let centre = 8 * 16 + 8;
        for k in 0..3 {
            let v = out.levels[4].data[3 * centre + k];
            assert!((v - 1.0).abs() < 0.05, "{v}");
        }
        assert!(out.variance.data[centre * 5 + 4] < 0.25 / 10.0);
        // The other levels and variance planes are untouched.
        assert_eq!(out.levels[..4], b.levels[..4]);
        for p in 0..256 {
            assert_eq!(
                out.variance.data[p * 5..p * 5 + 4],
                b.variance.data[p * 5..p * 5 + 4]
            );
        }
    }

    #[test]
    fn the_range_term_keeps_edges_the_g_buffer_misses() {
        // One surface for the G-buffer, but a highlight (10) on the right half over a dim (1)
        // left half, variance 0.01: the G-buffer alone spreads the highlight across the edge, the
        // range term keeps it; within a half the noise-sized differences are still averaged.
        let (mut b, _) = synthetic_bundle(16, 16, 0.1, 5);
        b.meta.passes = 64;
        b.direct = None;
        for p in 0..256 {
            let right = p % 16 >= 8;
            for k in 0..3 {
                b.albedo.data[3 * p + k] = 0.5;
                b.normal.data[3 * p + k] = [0.0, 0.0, 1.0][k];
                let noise = if (p + p / 16) % 2 == 0 { 0.05 } else { -0.05 };
                b.levels[4].data[3 * p + k] = if right { 10.0 } else { 1.0 } + noise;
            }
            b.depth.data[p] = 2.0;
            b.variance.data[p * 5 + 4] = 0.01;
        }
        let plain = apply(&b, &[screen(4, 4, 2.0)]);
        let ranged = apply(
            &b,
            &[ScreenLevel {
                range: 2.0,
                ..screen(4, 4, 2.0)
            }],
        );
        let edge_left = 8 * 16 + 7;
        assert!(plain.levels[4].data[3 * edge_left] > 2.0);
        let v = ranged.levels[4].data[3 * edge_left];
        assert!((v - 1.0).abs() < 0.03, "{v}");
        let inner = 8 * 16 + 3;
        let v = ranged.levels[4].data[3 * inner];
        assert!((v - 1.0).abs() < 0.02, "noise averaged: {v}");
        let mut bad = screen(4, 4, 2.0);
        bad.range = -1.0;
        assert!(validate(&[bad]).is_err());
    }

    #[test]
    fn edges_of_the_g_buffer_are_kept() {
        // Two surfaces (left and right halves, different albedo and depth) of different
        // brightness: the filter does not carry one across the edge.
        let (mut b, _) = synthetic_bundle(16, 16, 0.1, 2);
        b.meta.passes = 64;
        for p in 0..256 {
            let left = p % 16 < 8;
            for k in 0..3 {
                b.albedo.data[3 * p + k] = if left { 0.2 } else { 0.8 };
                b.normal.data[3 * p + k] = [0.0, 0.0, 1.0][k];
                b.levels[4].data[3 * p + k] = if left { 0.1 } else { 4.0 };
            }
            b.depth.data[p] = if left { 1.0 } else { 3.0 };
        }
        b.direct = None;
        let out = apply(&b, &[screen(4, 4, 3.0)]);
        for y in 0..16 {
            let l = out.levels[4].data[3 * (y * 16 + 7)];
            let r = out.levels[4].data[3 * (y * 16 + 8)];
            assert!((l - 0.1).abs() < 1e-3 && (r - 4.0).abs() < 1e-3, "{l} {r}");
        }
    }

    #[test]
    fn the_filter_vanishes_as_passes_grow_and_direct_light_is_not_spread() {
        let (mut b, _) = synthetic_bundle(12, 10, 0.1, 3);
        b.meta.passes = 64;
        let out = apply(&b, &[screen(4, 4, 1.5)]);
        assert_ne!(out.levels[4], b.levels[4]);
        // At 64^4 passes σ = 1.5/16 < MIN_SIGMA: the identity.
        b.meta.passes = 64 * 64 * 64 * 64;
        let out = apply(&b, &[screen(4, 4, 1.5)]);
        assert_eq!(out.levels[4], b.levels[4]);
        // Direct light of one bright pixel stays at that pixel: only the photon part spreads.
        let (mut b, _) = synthetic_bundle(12, 10, 0.1, 4);
        b.meta.passes = 64;
        b.direct = Some(bundle::DirectLight {
            y: Image::new(12, 10, 3),
            z: Image::new(12, 10, 3),
            variance: Image::new(12, 10, 2),
        });
        let d = b.direct.as_mut().unwrap();
        let bright = 5 * 12 + 6;
        for k in 0..3 {
            d.z.data[3 * bright + k] = 100.0;
        }
        let base = b.levels[4].clone();
        for k in 0..3 {
            b.levels[4].data[3 * bright + k] += 100.0;
        }
        let with = apply(&b, &[screen(4, 4, 1.5)]);
        b.levels[4] = base;
        b.direct.as_mut().unwrap().z.data[3 * bright..3 * bright + 3].fill(0.0);
        let without = apply(&b, &[screen(4, 4, 1.5)]);
        for p in 0..120 {
            for k in 0..3 {
                let extra = if p == bright { 100.0 } else { 0.0 };
                let diff = with.levels[4].data[3 * p + k] - without.levels[4].data[3 * p + k];
                assert!((diff - extra).abs() < 1e-3, "pixel {p}: {diff}");
            }
        }
    }
}
