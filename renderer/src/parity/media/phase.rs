//! Phase functions of participating media, as Mitsuba 3's `isotropic`, `hg`, `rayleigh`,
//! `tabphase` and `blendphase` plugins: the angular distribution of light scattered at a point
//! in a medium.
//!
//! Directions follow the light's travel: `d_in` is the direction the path arrived along (from
//! the previous vertex towards the scattering point) and `d_out` the direction it leaves in, so
//! forward scattering (`d_out = d_in`) has cos θ = 1 and, for Henyey–Greenstein, is favoured by
//! g > 0 — the convention of Mitsuba's `hg` ("g > 0: forward scattering").

use super::grid::VolumeTexture;
use crate::frame::Frame;
use crate::sampling::square_to_uniform_sphere;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::Arc;

/// A phase function (Mitsuba's `<phase>`).
#[derive(Debug, Clone, PartialEq)]
pub enum PhaseFunction {
    /// `isotropic`: every direction alike, 1/(4π).
    Isotropic,
    /// `hg`: Henyey–Greenstein with mean cosine `g` in (−1, 1).
    HenyeyGreenstein {
        /// `g`: the mean cosine of the scattering angle (0 isotropic, > 0 forward).
        g: f32,
    },
    /// `rayleigh`: scattering by particles much smaller than the wavelength,
    /// 3/(16π)·(1 + cos²θ) (unpolarised).
    Rayleigh,
    /// `tabphase`: a table of values over the cosine of the scattering angle.
    Tabulated(Arc<TabulatedPhase>),
    /// `blendphase`: a mixture of two phase functions with a (spatially varying) weight.
    Blend(Arc<BlendPhase>),
}

/// Mitsuba's `tabphase`: values at cosines regularly spaced over [−1, 1] (cos θ = 1 is forward
/// scattering), interpolated linearly and normalised; sampled by inverting the piecewise
/// quadratic CDF.
#[derive(Debug, Clone, PartialEq)]
pub struct TabulatedPhase {
    /// The values as given (unnormalised), at least two.
    values: Vec<f32>,
    /// `cdf[i]`: the integral of the interpolated values from −1 to the end of interval `i`.
    cdf: Vec<f32>,
    /// Width of one interval, 2/(n − 1).
    interval: f32,
    /// 1 / (the integral over [−1, 1] × 2π): turns a value into a solid-angle density.
    norm: f32,
}

impl TabulatedPhase {
    /// The table from `values` (regularly spaced over cos θ ∈ [−1, 1]); errors name what is
    /// wrong: fewer than two values, a negative or non-finite one, or no positive one.
    pub fn new(values: Vec<f32>) -> Result<TabulatedPhase, String> {
        if values.len() < 2 {
            return Err(format!("needs at least two values, got {}", values.len()));
        }
        if let Some((i, v)) = values
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v >= 0.0))
        {
            return Err(format!(
                "value {} is {v}: values must be finite and >= 0",
                i + 1
            ));
        }
        if !values.iter().any(|&v| v > 0.0) {
            return Err("every value is zero".into());
        }
        let n = values.len();
        let interval = 2.0 / (n - 1) as f64;
        // Trapezoids, summed in double precision as Mitsuba's scalar variants do.
        let mut sum = 0.0f64;
        let cdf: Vec<f32> = values
            .windows(2)
            .map(|w| {
                sum += 0.5 * (w[0] as f64 + w[1] as f64) * interval;
                sum as f32
            })
            .collect();
        if !(sum.is_finite() && sum > 0.0) {
            return Err(format!("the values' integral is {sum}"));
        }
        Ok(TabulatedPhase {
            values,
            cdf,
            interval: interval as f32,
            norm: (1.0 / (sum * 2.0 * std::f64::consts::PI)) as f32,
        })
    }

    /// The solid-angle density for the cosine between the travel directions.
    #[inline]
    fn eval(&self, cos_theta: f32) -> f32 {
        if !(-1.0..=1.0).contains(&cos_theta) {
            return 0.0;
        }
        let x = (cos_theta + 1.0) / self.interval;
        let i = (x as usize).min(self.values.len() - 2);
        let t = x - i as f32;
        ((1.0 - t) * self.values[i] + t * self.values[i + 1]) * self.norm
    }

    /// The cosine whose CDF is `u` (in [0, 1)).
    #[inline]
    fn sample(&self, u: f32) -> f32 {
        let total = *self.cdf.last().expect("at least one interval");
        let target = u * total;
        // The first interval whose end lies beyond the target (never one without mass).
        let i = self
            .cdf
            .partition_point(|&c| c <= target)
            .min(self.cdf.len() - 1);
        let before = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        let (y0, y1) = (self.values[i], self.values[i + 1]);
        // Solve y0·t + (y1 − y0)·t²/2 = s for t in [0, 1], in the form without cancellation.
        let s = ((target - before) / self.interval).max(0.0);
        let root = (y0 * y0 + 2.0 * s * (y1 - y0)).max(0.0).sqrt();
        let t = if y0 + root > 0.0 {
            (2.0 * s / (y0 + root)).clamp(0.0, 1.0)
        } else {
            0.5
        };
        (-1.0 + (i as f32 + t) * self.interval).clamp(-1.0, 1.0)
    }
}

/// Mitsuba's `blendphase`: (1 − w)·first + w·second, with w the `weight` volume's value at the
/// scattering point (a float, a `constvolume` — the mean of its channels — or a
/// `gridvolume` — its one channel, or the luminance of three), clamped to [0, 1].
#[derive(Debug, Clone, PartialEq)]
pub struct BlendPhase {
    /// The blending weight.
    pub weight: VolumeTexture,
    /// The two phase functions, in file order (weight 0 selects the first).
    pub nested: [PhaseFunction; 2],
}

impl BlendPhase {
    /// The weight of the second phase function at `p`, in [0, 1].
    #[inline]
    fn weight_at(&self, p: Vec3) -> f32 {
        let w = self.weight.eval_1(p);
        if w.is_nan() {
            0.0
        } else {
            w.clamp(0.0, 1.0)
        }
    }
}

/// A direction drawn from a phase function, with its density (the weight is always 1: each
/// phase function is sampled exactly).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseSample {
    /// The outgoing direction (unit, world space).
    pub d_out: Vec3,
    /// Solid-angle density of `d_out`, equal to the phase function's value there.
    pub pdf: f32,
}

impl PhaseFunction {
    /// Checks the values a scene file cannot be trusted with (recursively).
    pub fn validate(&self) -> Result<(), String> {
        match self {
            PhaseFunction::HenyeyGreenstein { g } if !(*g > -1.0 && *g < 1.0) => {
                Err(format!("the phase function's g = {g} is outside (-1, 1)"))
            }
            PhaseFunction::Blend(b) => b.nested.iter().try_for_each(PhaseFunction::validate),
            _ => Ok(()),
        }
    }

    /// The phase function's value (= its sampling density) at point `p` for light arriving
    /// along `d_in` and leaving along `d_out` (unit vectors).
    #[inline]
    pub fn eval(&self, p: Vec3, d_in: Vec3, d_out: Vec3) -> f32 {
        match self {
            PhaseFunction::Isotropic => 1.0 / (4.0 * PI),
            PhaseFunction::HenyeyGreenstein { g } => hg(*g, d_in.dot(d_out)),
            PhaseFunction::Rayleigh => rayleigh(d_in.dot(d_out)),
            PhaseFunction::Tabulated(t) => t.eval(d_in.dot(d_out)),
            PhaseFunction::Blend(b) => {
                let w = b.weight_at(p);
                let [first, second] = &b.nested;
                let f0 = if w < 1.0 {
                    first.eval(p, d_in, d_out)
                } else {
                    0.0
                };
                let f1 = if w > 0.0 {
                    second.eval(p, d_in, d_out)
                } else {
                    0.0
                };
                (1.0 - w) * f0 + w * f1
            }
        }
    }

    /// Samples an outgoing direction at point `p` for light arriving along `d_in`.
    #[inline]
    pub fn sample(&self, p: Vec3, d_in: Vec3, u: Vec2) -> PhaseSample {
        match self {
            PhaseFunction::Isotropic => PhaseSample {
                d_out: square_to_uniform_sphere(u),
                pdf: 1.0 / (4.0 * PI),
            },
            &PhaseFunction::HenyeyGreenstein { g } => {
                // Inverting the CDF of cos θ (θ measured from `d_in`).
                let cos_theta = if g.abs() < 1e-3 {
                    1.0 - 2.0 * u.x
                } else {
                    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
                    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
                };
                PhaseSample {
                    d_out: around(d_in, cos_theta, u.y),
                    pdf: hg(g, cos_theta),
                }
            }
            PhaseFunction::Rayleigh => {
                // The CDF (c³ + 3c + 4)/8 = u inverted by Cardano's formula.
                let z = 2.0 * (2.0 * u.x - 1.0);
                let root = (z * z + 1.0).sqrt();
                let cos_theta = ((z + root).cbrt() + (z - root).cbrt()).clamp(-1.0, 1.0);
                PhaseSample {
                    d_out: around(d_in, cos_theta, u.y),
                    pdf: rayleigh(cos_theta),
                }
            }
            PhaseFunction::Tabulated(t) => {
                let cos_theta = t.sample(u.x);
                PhaseSample {
                    d_out: around(d_in, cos_theta, u.y),
                    pdf: t.eval(cos_theta),
                }
            }
            PhaseFunction::Blend(b) => {
                // One of the two by its weight, u.x reused (rescaled) for the chosen one; both
                // are sampled exactly, so the mixture's density is its value and the weight 1.
                let w = b.weight_at(p);
                let [first, second] = &b.nested;
                let d_out = if u.x < w {
                    second.sample(p, d_in, Vec2::new(u.x / w, u.y)).d_out
                } else {
                    let u0 = ((u.x - w) / (1.0 - w)).min(1.0 - f32::EPSILON / 2.0);
                    first.sample(p, d_in, Vec2::new(u0, u.y)).d_out
                };
                PhaseSample {
                    d_out,
                    pdf: self.eval(p, d_in, d_out),
                }
            }
        }
    }
}

/// The unit direction at angle acos(`cos_theta`) from `axis`, at azimuth 2π·`u_phi`.
#[inline]
fn around(axis: Vec3, cos_theta: f32, u_phi: f32) -> Vec3 {
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let phi = 2.0 * PI * u_phi;
    let local = Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta);
    Frame::from_normal(axis).to_world(local).normalize()
}

/// The Rayleigh density for the cosine between the travel directions.
#[inline]
fn rayleigh(cos_theta: f32) -> f32 {
    3.0 / (16.0 * PI) * (1.0 + cos_theta * cos_theta)
}

/// The Henyey–Greenstein density for the cosine between the travel directions.
#[inline]
fn hg(g: f32, cos_theta: f32) -> f32 {
    let denom = 1.0 + g * g - 2.0 * g * cos_theta;
    (1.0 - g * g) / (4.0 * PI * denom * denom.max(1e-12).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parity::media::grid::{GridFilter, VolFile, VolumeGrid};
    use crate::sampling::{Pcg32, UniformSource};
    use crate::spectrum::Rgb;
    use crate::texture::BitmapWrap;
    use glam::{Mat4, UVec3};

    fn table(values: &[f32]) -> PhaseFunction {
        PhaseFunction::Tabulated(Arc::new(TabulatedPhase::new(values.to_vec()).unwrap()))
    }

    fn blend(w: f32, first: PhaseFunction, second: PhaseFunction) -> PhaseFunction {
        PhaseFunction::Blend(Arc::new(BlendPhase {
            weight: VolumeTexture::Constant(Rgb::splat(w)),
            nested: [first, second],
        }))
    }

    /// Every kind, with tables that peak forward, hold zero-mass intervals or are flat, and
    /// blends (nested too) at interior and extreme weights.
    fn phases() -> Vec<PhaseFunction> {
        vec![
            PhaseFunction::Isotropic,
            PhaseFunction::HenyeyGreenstein { g: 0.0 },
            PhaseFunction::HenyeyGreenstein { g: 0.7 },
            PhaseFunction::HenyeyGreenstein { g: -0.4 },
            PhaseFunction::HenyeyGreenstein { g: 0.95 },
            PhaseFunction::Rayleigh,
            table(&[0.0, 1.0, 2.0, 8.0]),
            table(&[1.0, 0.0, 0.0, 3.0, 0.5]),
            table(&[2.0, 2.0]),
            blend(
                0.3,
                PhaseFunction::HenyeyGreenstein { g: 0.8 },
                PhaseFunction::Rayleigh,
            ),
            blend(1.0, PhaseFunction::Isotropic, table(&[0.0, 1.0])),
            blend(
                0.5,
                blend(
                    0.0,
                    PhaseFunction::HenyeyGreenstein { g: -0.5 },
                    PhaseFunction::Isotropic,
                ),
                table(&[3.0, 1.0, 0.0]),
            ),
        ]
    }

    /// ∫ f(cos θ)·2π d(cos θ) over [lo, hi] by a fine midpoint rule (every phase function here
    /// is symmetric about the incoming direction).
    fn integrate(
        phase: &PhaseFunction,
        d_in: Vec3,
        lo: f64,
        hi: f64,
        f: impl Fn(f64) -> f64,
    ) -> f64 {
        let frame = Frame::from_normal(d_in);
        let n = 20_000;
        let h = (hi - lo) / n as f64;
        (0..n)
            .map(|i| {
                let c = lo + (i as f64 + 0.5) * h;
                let s = (1.0 - c * c).max(0.0).sqrt();
                let d_out = frame.to_world(Vec3::new(s as f32, 0.0, c as f32));
                phase.eval(Vec3::ZERO, d_in, d_out) as f64 * f(c)
            })
            .sum::<f64>()
            * h
            * 2.0
            * std::f64::consts::PI
    }

    /// Each phase function integrates to one over the sphere (a fine midpoint rule in cos θ,
    /// which resolves the g = 0.95 forward peak).
    #[test]
    fn phase_functions_integrate_to_one() {
        let d_in = Vec3::new(0.3, -0.5, 0.8).normalize();
        for phase in phases() {
            let integral = (0..10)
                .map(|k| {
                    integrate(
                        &phase,
                        d_in,
                        -1.0 + 0.2 * k as f64,
                        -0.8 + 0.2 * k as f64,
                        |_| 1.0,
                    )
                })
                .sum::<f64>();
            assert!((integral - 1.0).abs() < 2e-3, "{phase:?}: {integral}");
        }
    }

    /// Sampling matches the density: the returned pdf equals `eval`, the mean cosine is the
    /// density's (g for Henyey–Greenstein), and a χ² test over 10 bins of cos θ and 4 of φ
    /// against the density integrated per bin passes.
    #[test]
    fn sampling_matches_the_density() {
        let d_in = Vec3::new(-0.2, 0.9, 0.1).normalize();
        let frame = Frame::from_normal(d_in);
        for phase in phases() {
            let mut rng = Pcg32::new(7, 11);
            let n = 400_000;
            let (cos_bins, phi_bins) = (10usize, 4usize);
            let mut counts = vec![0u64; cos_bins * phi_bins];
            let mut mean_cos = 0.0f64;
            for _ in 0..n {
                let s = phase.sample(Vec3::ZERO, d_in, rng.next_2d());
                assert!((s.d_out.length() - 1.0).abs() < 1e-4);
                let pdf = phase.eval(Vec3::ZERO, d_in, s.d_out);
                assert!(pdf > 0.0, "{phase:?}: sampled a direction of density 0");
                // Relative, but absolute where a table's density falls to zero: the direction's
                // cosine is recomputed with a rounding error of ~1e-7.
                assert!(
                    (s.pdf - pdf).abs() <= 1e-3 * pdf + 1e-6,
                    "{phase:?}: {} vs {pdf}",
                    s.pdf
                );
                let local = frame.to_local(s.d_out);
                mean_cos += local.z as f64;
                let ci = (((local.z + 1.0) * 0.5 * cos_bins as f32) as usize).min(cos_bins - 1);
                let phi = local.y.atan2(local.x).rem_euclid(2.0 * PI);
                let pi = ((phi / (2.0 * PI) * phi_bins as f32) as usize).min(phi_bins - 1);
                counts[ci * phi_bins + pi] += 1;
            }
            mean_cos /= n as f64;
            let expected_mean = integrate(&phase, d_in, -1.0, 1.0, |c| c);
            if let PhaseFunction::HenyeyGreenstein { g } = phase {
                assert!(
                    (expected_mean - g as f64).abs() < 1e-3,
                    "{phase:?}: {expected_mean}"
                );
            }
            assert!(
                (mean_cos - expected_mean).abs() < 0.01,
                "{phase:?}: {mean_cos} vs {expected_mean}"
            );
            let mut chi2 = 0.0;
            let mut dof = 0;
            for ci in 0..cos_bins {
                let lo = -1.0 + 2.0 * ci as f64 / cos_bins as f64;
                let hi = lo + 2.0 / cos_bins as f64;
                let expected =
                    integrate(&phase, d_in, lo, hi, |_| 1.0) * n as f64 / phi_bins as f64;
                for pi in 0..phi_bins {
                    let o = counts[ci * phi_bins + pi] as f64;
                    if expected > 5.0 {
                        chi2 += (o - expected).powi(2) / expected;
                        dof += 1;
                    } else {
                        assert!(
                            o <= 20.0,
                            "{phase:?}: {o} samples where {expected} expected"
                        );
                    }
                }
            }
            // 99.9 % quantile of χ² with ≤ 39 degrees of freedom is below 73.4.
            assert!(chi2 < 73.4, "{phase:?}: χ² = {chi2} over {dof} bins");
        }
    }

    /// A table is normalised as Mitsuba's `tabphase`: values 1 and 3 at cos θ = −1 and 1
    /// integrate (trapezoid) to 4 over cos θ, so forward scattering has density 3/(4·2π),
    /// and halfway the interpolated 2/(4·2π); the inverse CDF of the linear density.
    #[test]
    fn tables_normalise_and_invert_like_mitsuba() {
        let t = TabulatedPhase::new(vec![1.0, 3.0]).unwrap();
        let two_pi = 2.0 * PI;
        assert!((t.eval(1.0) - 3.0 / (4.0 * two_pi)).abs() < 1e-7);
        assert!((t.eval(0.0) - 2.0 / (4.0 * two_pi)).abs() < 1e-7);
        assert!((t.eval(-1.0) - 1.0 / (4.0 * two_pi)).abs() < 1e-7);
        assert_eq!(t.eval(1.5), 0.0);
        // CDF(c) = ((c + 1) + (c + 1)²/2) / 4: CDF(0) = 3/8.
        assert!(t.sample(0.375).abs() < 1e-6, "{}", t.sample(0.375));
        assert_eq!(t.sample(0.0), -1.0);
        for values in [
            vec![1.0],
            vec![],
            vec![0.0, 0.0],
            vec![1.0, -1.0],
            vec![f32::NAN, 1.0],
        ] {
            assert!(TabulatedPhase::new(values.clone()).is_err(), "{values:?}");
        }
    }

    /// A blend's weight is read where the path scatters: a 2×1×1 grid of 0 and 1 (nearest)
    /// gives the first phase function in its left half and the second in its right half.
    #[test]
    fn blend_weights_vary_in_space() {
        let grid = VolumeGrid::new(
            VolFile {
                res: UVec3::new(2, 1, 1),
                channels: 1,
                bbox: (Vec3::ZERO, Vec3::ONE),
                data: vec![0.0, 1.0],
            },
            Mat4::IDENTITY,
            false,
            GridFilter::Nearest,
            BitmapWrap::Clamp,
            "w.vol".into(),
        )
        .unwrap();
        let first = PhaseFunction::HenyeyGreenstein { g: 0.6 };
        let second = PhaseFunction::Rayleigh;
        let phase = PhaseFunction::Blend(Arc::new(BlendPhase {
            weight: VolumeTexture::Grid(Arc::new(grid)),
            nested: [first.clone(), second.clone()],
        }));
        let (left, right) = (Vec3::new(0.2, 0.5, 0.5), Vec3::new(0.8, 0.5, 0.5));
        let d_in = Vec3::Z;
        let mut rng = Pcg32::new(3, 5);
        for _ in 0..1000 {
            let d_out = square_to_uniform_sphere(rng.next_2d());
            assert_eq!(phase.eval(left, d_in, d_out), first.eval(left, d_in, d_out));
            assert_eq!(
                phase.eval(right, d_in, d_out),
                second.eval(right, d_in, d_out)
            );
            let u = rng.next_2d();
            let s = phase.sample(right, d_in, u);
            assert_eq!(s.d_out, second.sample(right, d_in, u).d_out);
        }
        assert!(phase.validate().is_ok());
        let bad = blend(
            0.5,
            PhaseFunction::Isotropic,
            PhaseFunction::HenyeyGreenstein { g: 1.0 },
        );
        assert!(bad.validate().unwrap_err().contains("g = 1"));
    }
}
