//! Phase functions of participating media, as Mitsuba 3's `isotropic`, `hg` and `rayleigh`
//! plugins: the angular distribution of light scattered at a point in a medium.
//!
//! Directions follow the light's travel: `d_in` is the direction the path arrived along (from
//! the previous vertex towards the scattering point) and `d_out` the direction it leaves in, so
//! forward scattering (`d_out = d_in`) has cos θ = 1 and, for Henyey–Greenstein, is favoured by
//! g > 0 — the convention of Mitsuba's `hg` ("g > 0: forward scattering").

use crate::frame::Frame;
use crate::sampling::square_to_uniform_sphere;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A phase function (Mitsuba's `<phase>`).
#[derive(Debug, Clone, Copy, PartialEq)]
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
    /// The phase function's value (= its sampling density) for light arriving along `d_in` and
    /// leaving along `d_out` (unit vectors).
    #[inline]
    pub fn eval(&self, d_in: Vec3, d_out: Vec3) -> f32 {
        match *self {
            PhaseFunction::Isotropic => 1.0 / (4.0 * PI),
            PhaseFunction::HenyeyGreenstein { g } => hg(g, d_in.dot(d_out)),
            PhaseFunction::Rayleigh => rayleigh(d_in.dot(d_out)),
        }
    }

    /// Samples an outgoing direction for light arriving along `d_in`.
    #[inline]
    pub fn sample(&self, d_in: Vec3, u: Vec2) -> PhaseSample {
        match *self {
            PhaseFunction::Isotropic => PhaseSample {
                d_out: square_to_uniform_sphere(u),
                pdf: 1.0 / (4.0 * PI),
            },
            PhaseFunction::HenyeyGreenstein { g } => {
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
    use crate::sampling::{Pcg32, UniformSource};

    const PHASES: [PhaseFunction; 6] = [
        PhaseFunction::Isotropic,
        PhaseFunction::HenyeyGreenstein { g: 0.0 },
        PhaseFunction::HenyeyGreenstein { g: 0.7 },
        PhaseFunction::HenyeyGreenstein { g: -0.4 },
        PhaseFunction::HenyeyGreenstein { g: 0.95 },
        PhaseFunction::Rayleigh,
    ];

    /// Each phase function integrates to one over the sphere (a fine midpoint rule in cos θ,
    /// which resolves the g = 0.95 forward peak).
    #[test]
    fn phase_functions_integrate_to_one() {
        let d_in = Vec3::new(0.3, -0.5, 0.8).normalize();
        let frame = Frame::from_normal(d_in);
        for phase in PHASES {
            let n = 200_000;
            let mut sum = 0.0f64;
            for i in 0..n {
                let c = -1.0 + 2.0 * (i as f32 + 0.5) / n as f32;
                let s = (1.0 - c * c).sqrt();
                let d_out = frame.to_world(Vec3::new(s, 0.0, c));
                sum += phase.eval(d_in, d_out) as f64 * 2.0 * std::f64::consts::PI;
            }
            let integral = sum * 2.0 / n as f64;
            assert!((integral - 1.0).abs() < 2e-3, "{phase:?}: {integral}");
        }
    }

    /// Sampling matches the density: the returned pdf equals `eval`, the mean cosine is g,
    /// and a χ² test over 10 bins of cos θ and 4 of φ passes.
    #[test]
    fn sampling_matches_the_density() {
        let d_in = Vec3::new(-0.2, 0.9, 0.1).normalize();
        let frame = Frame::from_normal(d_in);
        for phase in PHASES {
            let g = match phase {
                PhaseFunction::Isotropic | PhaseFunction::Rayleigh => 0.0,
                PhaseFunction::HenyeyGreenstein { g } => g,
            };
            let mut rng = Pcg32::new(7, 11);
            let n = 400_000;
            let (cos_bins, phi_bins) = (10usize, 4usize);
            let mut counts = vec![0u64; cos_bins * phi_bins];
            let mut mean_cos = 0.0f64;
            for _ in 0..n {
                let s = phase.sample(d_in, rng.next_2d());
                assert!((s.d_out.length() - 1.0).abs() < 1e-4);
                let pdf = phase.eval(d_in, s.d_out);
                assert!(
                    (s.pdf - pdf).abs() <= 1e-3 * pdf,
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
            assert!((mean_cos - g as f64).abs() < 0.01, "{phase:?}: {mean_cos}");
            // Expected counts: the cos θ marginal integrated exactly per bin.
            let cdf = |c: f64| -> f64 {
                let g = g as f64;
                if phase == PhaseFunction::Rayleigh {
                    (c * c * c + 3.0 * c + 4.0) / 8.0
                } else if g.abs() < 1e-3 {
                    (c + 1.0) / 2.0
                } else {
                    (1.0 - g * g) / (2.0 * g)
                        * (1.0 / (1.0 + g * g - 2.0 * g * c).sqrt() - 1.0 / (1.0 + g))
                }
            };
            let mut chi2 = 0.0;
            let mut dof = 0;
            for ci in 0..cos_bins {
                let lo = -1.0 + 2.0 * ci as f64 / cos_bins as f64;
                let hi = lo + 2.0 / cos_bins as f64;
                let expected = (cdf(hi) - cdf(lo)) * n as f64 / phi_bins as f64;
                for pi in 0..phi_bins {
                    if expected > 5.0 {
                        let o = counts[ci * phi_bins + pi] as f64;
                        chi2 += (o - expected).powi(2) / expected;
                        dof += 1;
                    }
                }
            }
            // 99.9 % quantile of χ² with ≤ 39 degrees of freedom is below 73.4.
            assert!(chi2 < 73.4, "{phase:?}: χ² = {chi2} over {dof} bins");
        }
    }
}
