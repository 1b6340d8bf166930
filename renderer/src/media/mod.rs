//! Participating media: Mitsuba 3's `homogeneous` medium (constant extinction and albedo, a
//! phase function), the interior/exterior media a shape separates, and the free-flight
//! distance sampling the volumetric path tracer (`integrators/volpath.rs`) uses.
//!
//! Extinction may differ per RGB channel. Distances are drawn from one channel's exponential —
//! the path's *hero* channel, chosen uniformly once per path — and every event also reports
//! the ratio of each channel's density to the hero's, so that the integrator can weight the
//! whole path by the balance heuristic over the three channels (pbrt-v4's spectral MIS):
//! unbiased in every channel, with weights bounded by 3 however long the path, where the
//! product of per-event weights of a single channel grows without bound.

pub mod phase;

use crate::spectrum::Rgb;
use glam::Vec3;
pub use phase::{PhaseFunction, PhaseSample};

/// A homogeneous participating medium (`<medium type="homogeneous">`).
#[derive(Debug, Clone, PartialEq)]
pub struct Medium {
    /// Extinction coefficient σt per unit of distance (`sigma_t` × `scale`), per channel.
    pub sigma_t: Rgb,
    /// Single-scattering albedo σs/σt (`albedo`), per channel, in [0, 1].
    pub albedo: Rgb,
    /// The phase function (`<phase>`; isotropic when none is given).
    pub phase: PhaseFunction,
    /// `sample_emitters`: whether scattering points inside the medium sample lights (NEE).
    pub sample_emitters: bool,
    /// The `id` or a generated name (for messages).
    pub name: String,
}

/// What a free-flight sample found along a ray segment that ends at distance `t_max`. The
/// throughput factor `weight` divides by the hero channel's density; `ratio` is each channel's
/// density over the hero's (the path's ratios multiply; its estimate is throughput / mean ratio).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FreeFlight {
    /// The path scatters in the medium at distance `t`: `weight` = transmittance · σs over
    /// the hero's σt·exp(−σt t).
    Scatter {
        /// Distance along the ray.
        t: f32,
        /// Throughput factor.
        weight: Rgb,
        /// Each channel's density of `t` over the hero's.
        ratio: Rgb,
    },
    /// The path reaches the end of the segment: `weight` = transmittance over the hero's.
    Pass {
        /// Throughput factor.
        weight: Rgb,
        /// Each channel's probability of passing over the hero's.
        ratio: Rgb,
    },
}

impl Medium {
    /// Scattering coefficient σs = albedo · σt.
    #[inline]
    pub fn sigma_s(&self) -> Rgb {
        self.albedo * self.sigma_t
    }

    /// Transmittance exp(−σt·d) over distance `d` (0 ≤ d ≤ ∞; a channel with σt = 0 keeps 1).
    #[inline]
    pub fn transmittance(&self, d: f32) -> Rgb {
        transmittance(self.sigma_t, d)
    }

    /// Draws a free-flight distance along a segment of length `t_max` (∞ for a ray that hits
    /// nothing) from the exponential of channel `hero` (0–2), with `u` in [0, 1).
    #[inline]
    pub fn sample_free_flight(&self, t_max: f32, hero: usize, u: f32) -> FreeFlight {
        let sigma = self.sigma_t[hero];
        // −ln(1 − u)/σ; u < 1, so the logarithm is finite (σ = 0: never scatters).
        let t = if sigma > 0.0 {
            -(1.0 - u).ln() / sigma
        } else {
            f32::INFINITY
        };
        if t < t_max {
            let tr = self.transmittance(t);
            // The hero's density σ·exp(−σt) > 0: t is finite and was drawn from it.
            let density = self.sigma_t * tr;
            let hero_density = density[hero];
            FreeFlight::Scatter {
                t,
                weight: tr * self.sigma_s() / hero_density,
                ratio: density / hero_density,
            }
        } else {
            let tr = self.transmittance(t_max);
            // The hero passes with probability exp(−σ t_max) > 0, else t would be below t_max.
            let hero_tr = tr[hero];
            FreeFlight::Pass {
                weight: tr / hero_tr,
                ratio: tr / hero_tr,
            }
        }
    }
}

/// exp(−σ·d) per channel, with 0·∞ read as 0 (an empty channel transmits everything).
#[inline]
pub fn transmittance(sigma_t: Rgb, d: f32) -> Rgb {
    Rgb::new(
        channel_transmittance(sigma_t.x, d),
        channel_transmittance(sigma_t.y, d),
        channel_transmittance(sigma_t.z, d),
    )
}

#[inline]
fn channel_transmittance(sigma: f32, d: f32) -> f32 {
    if sigma == 0.0 {
        1.0
    } else {
        (-sigma * d).exp()
    }
}

/// The media on either side of a shape's surface (Mitsuba's `interior` and `exterior`), as
/// indices into the scene's media. A shape with neither leaves the medium a ray is in alone;
/// one with either sets it on every crossing (`None` on a side: vacuum).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MediumInterface {
    /// The medium behind the surface (opposite its geometric normal).
    pub interior: Option<u32>,
    /// The medium in front of the surface (on its geometric normal's side).
    pub exterior: Option<u32>,
}

impl MediumInterface {
    /// Whether crossing the surface changes the medium (it names one on either side).
    #[inline]
    pub fn is_transition(&self) -> bool {
        self.interior.is_some() || self.exterior.is_some()
    }

    /// The medium a ray leaving the surface along `d` enters: the exterior on the geometric
    /// normal `ng`'s side, the interior on the other, as Mitsuba's `target_medium`.
    #[inline]
    pub fn target(&self, ng: Vec3, d: Vec3) -> Option<u32> {
        if ng.dot(d) > 0.0 {
            self.exterior
        } else {
            self.interior
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Pcg32, UniformSource};

    fn fog(sigma_t: Rgb, albedo: Rgb) -> Medium {
        Medium {
            sigma_t,
            albedo,
            phase: PhaseFunction::Isotropic,
            sample_emitters: true,
            name: "fog".into(),
        }
    }

    /// The weights are unbiased in every channel under the balance heuristic over hero
    /// channels (hero uniform, estimate = weight / mean ratio): the mean of the "passed"
    /// estimates over many samples is the transmittance over the segment, and the mean of the
    /// scatter estimates is ∫₀ᵀ σs·exp(−σt t) dt = albedo·(1 − exp(−σt T)), for an
    /// extinction that differs tenfold between channels; every estimate is at most 3.
    #[test]
    fn free_flight_weights_are_unbiased_per_channel() {
        let m = fog(Rgb::new(0.3, 1.0, 3.0), Rgb::new(0.9, 0.5, 0.2));
        let t_max = 1.7;
        let mut rng = Pcg32::new(3, 5);
        let n = 400_000;
        let (mut passed, mut scattered) = (Rgb::ZERO, Rgb::ZERO);
        for _ in 0..n {
            let hero = ((rng.next_f32() * 3.0) as usize).min(2);
            match m.sample_free_flight(t_max, hero, rng.next_f32()) {
                FreeFlight::Pass { weight, ratio } => {
                    assert_eq!(ratio[hero], 1.0);
                    let e = weight / (ratio.element_sum() / 3.0);
                    assert!(e.max_element() <= 3.0, "{e:?}");
                    passed += e;
                }
                FreeFlight::Scatter { t, weight, ratio } => {
                    assert!(t < t_max);
                    let e = weight / (ratio.element_sum() / 3.0);
                    assert!(e.max_element() <= 3.0, "{e:?}");
                    scattered += e;
                }
            }
        }
        let passed = passed / n as f32;
        let scattered = scattered / n as f32;
        let tr = m.transmittance(t_max);
        let expected_scatter = m.albedo * (Rgb::ONE - tr);
        assert!(
            (passed - tr).abs().max_element() < 0.01,
            "{passed:?} vs {tr:?}"
        );
        assert!(
            (scattered - expected_scatter).abs().max_element() < 0.01,
            "{scattered:?} vs {expected_scatter:?}"
        );
    }

    /// A channel without extinction never scatters and transmits everything, also over an
    /// unbounded segment; the others vanish there.
    #[test]
    fn empty_channels_and_unbounded_segments() {
        let m = fog(Rgb::new(0.0, 1.0, 2.0), Rgb::ONE);
        assert_eq!(m.transmittance(f32::INFINITY), Rgb::new(1.0, 0.0, 0.0));
        // Hero channel 0: no scattering, the ray passes with only the red channel left.
        match m.sample_free_flight(f32::INFINITY, 0, 0.5) {
            FreeFlight::Pass { weight, ratio } => {
                assert_eq!(weight, Rgb::new(1.0, 0.0, 0.0));
                assert_eq!(ratio, Rgb::new(1.0, 0.0, 0.0));
            }
            other => panic!("{other:?}"),
        }
        // Hero channel 2: it scatters at a finite distance.
        assert!(matches!(
            m.sample_free_flight(f32::INFINITY, 2, 0.5),
            FreeFlight::Scatter { .. }
        ));
    }

    #[test]
    fn interfaces_choose_the_side_of_the_normal() {
        let none = MediumInterface::default();
        assert!(!none.is_transition());
        let inside = MediumInterface {
            interior: Some(2),
            exterior: None,
        };
        assert!(inside.is_transition());
        assert_eq!(inside.target(Vec3::Z, -Vec3::Z), Some(2));
        assert_eq!(inside.target(Vec3::Z, Vec3::Z), None);
    }
}
