//! Participating media: Mitsuba 3's `homogeneous` medium (constant extinction and albedo) and
//! `heterogeneous` medium (both from voxel grids, `grid.rs`), their phase functions, the
//! interior/exterior media a shape separates, and the free-flight sampling and transmittance
//! the volumetric path tracer (`parity/volpath.rs`) uses.
//!
//! A heterogeneous medium is tracked against majorants σ̄ — the largest extinction in each of
//! up to 16³ blocks of its grid's box (`grid::MajorantGrid`), walked block by block — with
//! tentative collisions at exponential distances of rate σ̄, each a real one with the hero
//! channel's probability σt/σ̄ (delta tracking) or a null one; shadow rays multiply 1 − σt/σ̄
//! per tentative collision (ratio tracking). Outside its grid's box it holds nothing.
//!
//! Extinction may differ per RGB channel. Distances are drawn from one channel's exponential —
//! the path's *hero* channel, chosen uniformly once per path — and every event also reports
//! the ratio of each channel's density to the hero's, so that the integrator can weight the
//! whole path by the balance heuristic over the three channels (pbrt-v4's spectral MIS):
//! unbiased in every channel, with weights bounded by 3 however long the path, where the
//! product of per-event weights of a single channel grows without bound.

pub mod grid;
pub mod phase;

use crate::math::Ray;
use crate::sampling::UniformSource;
use crate::spectrum::Rgb;
use glam::Vec3;
pub use grid::{VolumeGrid, VolumeTexture};
pub use phase::{PhaseFunction, PhaseSample};

/// A participating medium (`<medium>`).
#[derive(Debug, Clone, PartialEq)]
pub struct Medium {
    /// How much it absorbs and scatters, and where.
    pub density: Density,
    /// The phase function (`<phase>`; isotropic when none is given).
    pub phase: PhaseFunction,
    /// `sample_emitters`: whether scattering points inside the medium sample lights (NEE).
    pub sample_emitters: bool,
    /// The `id` or a generated name (for messages).
    pub name: String,
}

/// The extinction and albedo of a medium.
#[derive(Debug, Clone, PartialEq)]
pub enum Density {
    /// `homogeneous`: the same everywhere.
    Homogeneous {
        /// Extinction coefficient σt per unit of distance (`sigma_t` × `scale`), per channel.
        sigma_t: Rgb,
        /// Single-scattering albedo σs/σt, per channel, in [0, 1].
        albedo: Rgb,
    },
    /// `heterogeneous`: extinction and albedo from volumes (grids or constants).
    Heterogeneous(Box<Heterogeneous>),
}

/// A heterogeneous medium's data.
#[derive(Debug, Clone, PartialEq)]
pub struct Heterogeneous {
    /// `sigma_t` (before `scale`).
    pub sigma_t: VolumeTexture,
    /// `albedo` (clamped to [0, 1] where it is read).
    pub albedo: VolumeTexture,
    /// `scale`: multiplies `sigma_t`.
    pub scale: f32,
    /// The largest extinction anywhere (scale × the grid's maximum over every channel).
    pub majorant: f32,
    /// The world-space box of the `sigma_t` volume, outside of which the medium is empty
    /// (`None`: everywhere).
    pub bounds: Option<(Vec3, Vec3)>,
    /// Local majorants over the box, for a grid `sigma_t`.
    pub majorants: Option<grid::MajorantGrid>,
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
    /// A homogeneous medium (tests and generated scenes).
    pub fn homogeneous(sigma_t: Rgb, albedo: Rgb, phase: PhaseFunction, name: &str) -> Medium {
        Medium {
            density: Density::Homogeneous { sigma_t, albedo },
            phase,
            sample_emitters: true,
            name: name.to_owned(),
        }
    }

    /// Checks the values a scene file cannot be trusted with.
    pub fn validate(&self) -> Result<(), String> {
        self.phase.validate()?;
        match &self.density {
            Density::Homogeneous { sigma_t, albedo } => {
                let ok = |c: &Rgb| c.is_finite() && c.min_element() >= 0.0;
                if !(ok(sigma_t) && ok(albedo) && albedo.max_element() <= 1.0) {
                    return Err(format!(
                        "needs a finite, non-negative sigma_t and an albedo in [0, 1] (got \
                         sigma_t {sigma_t:?}, albedo {albedo:?})"
                    ));
                }
            }
            Density::Heterogeneous(h) => {
                if !(h.majorant.is_finite() && h.sigma_t.min() >= 0.0 && h.scale >= 0.0) {
                    return Err(format!(
                        "needs a finite, non-negative sigma_t (scale {}, values {} .. {})",
                        h.scale,
                        h.sigma_t.min(),
                        h.sigma_t.max()
                    ));
                }
            }
        }
        Ok(())
    }

    /// Transmittance along `ray` from its origin to distance `t_end` (≤ ∞): exact for a
    /// homogeneous medium, an unbiased ratio-tracking estimate drawn from `rng` for a
    /// heterogeneous one.
    #[inline]
    pub fn transmittance(&self, ray: &Ray, t_end: f32, rng: &mut impl UniformSource) -> Rgb {
        match &self.density {
            Density::Homogeneous { sigma_t, .. } => transmittance(*sigma_t, t_end),
            Density::Heterogeneous(h) => h.ratio_tracking(ray, t_end, rng),
        }
    }

    /// Draws where a path along `ray` first interacts with the medium before distance `t_max`
    /// (∞ for a ray that hits nothing), for hero channel `hero` (0–2), with random numbers from
    /// `rng` (one for a homogeneous medium).
    #[inline]
    pub fn sample_free_flight(
        &self,
        ray: &Ray,
        t_max: f32,
        hero: usize,
        rng: &mut impl UniformSource,
    ) -> FreeFlight {
        match &self.density {
            Density::Homogeneous { sigma_t, albedo } => {
                homogeneous_free_flight(*sigma_t, *albedo, t_max, hero, rng.next_f32())
            }
            Density::Heterogeneous(h) => h.delta_tracking(ray, t_max, hero, rng),
        }
    }
}

/// The part of `ray` inside the box (lo, hi) up to `t_max`: (t0, t1) with t0 < t1, or `None`.
#[inline]
fn clip_to_box(ray: &Ray, bounds: Option<(Vec3, Vec3)>, t_max: f32) -> Option<(f32, f32)> {
    let Some((lo, hi)) = bounds else {
        return (t_max > 0.0).then_some((0.0, t_max));
    };
    let inv = ray.d.recip();
    let a = (lo - ray.o) * inv;
    let b = (hi - ray.o) * inv;
    // NaN (0·∞ for a ray in a face's plane) is dropped by min/max.
    let t0 = a.min(b).max_element().max(0.0);
    let t1 = a.max(b).min_element().min(t_max);
    (t0 < t1).then_some((t0, t1))
}

impl Heterogeneous {
    /// A heterogeneous medium of extinction `sigma_t` × `scale` inside `bounds` (the
    /// `sigma_t` volume's box; `None`: everywhere) and albedo `albedo`, with its majorants.
    pub fn new(
        sigma_t: VolumeTexture,
        albedo: VolumeTexture,
        scale: f32,
        bounds: Option<(Vec3, Vec3)>,
    ) -> Heterogeneous {
        let majorants = match (&sigma_t, bounds) {
            (VolumeTexture::Grid(g), Some(b)) => Some(grid::MajorantGrid::new(g, b, scale)),
            _ => None,
        };
        Heterogeneous {
            majorant: sigma_t.max() * scale,
            sigma_t,
            albedo,
            scale,
            bounds,
            majorants,
        }
    }

    /// Calls `f(t_start, t_end, majorant)` for the stretches of `ray` before `t_max` that the
    /// medium can interact with (inside its box, in order, skipping those whose majorant is
    /// zero) until `f` returns false.
    #[inline]
    fn stretches(&self, ray: &Ray, t_max: f32, mut f: impl FnMut(f32, f32, f32) -> bool) {
        if self.majorant <= 0.0 {
            return;
        }
        let Some((t0, t1)) = clip_to_box(ray, self.bounds, t_max) else {
            return;
        };
        match &self.majorants {
            Some(m) => m.segments(ray.o, ray.d, t0, t1, |a, b, bound| {
                bound <= 0.0 || f(a, b, bound)
            }),
            None => {
                f(t0, t1, self.majorant);
            }
        }
    }

    /// σt at `p` (scale applied), at most `bound` (trilinear rounding).
    #[inline]
    fn sigma_t_at(&self, p: Vec3, bound: f32) -> Rgb {
        (self.sigma_t.eval(p) * self.scale).min(Rgb::splat(bound))
    }

    /// Delta tracking with the hero channel's collision probabilities; each event also reports
    /// every channel's probability over the hero's (see [`FreeFlight`]).
    fn delta_tracking(
        &self,
        ray: &Ray,
        t_max: f32,
        hero: usize,
        rng: &mut impl UniformSource,
    ) -> FreeFlight {
        let (mut weight, mut ratio) = (Rgb::ONE, Rgb::ONE);
        let mut scatter = None;
        self.stretches(ray, t_max, |t0, t1, bound| {
            let mut t = t0;
            loop {
                // Exponential steps restart at each block's edge (memorylessness).
                t -= (1.0 - rng.next_f32()).ln() / bound;
                if t >= t1 {
                    return true;
                }
                let p = ray.o + ray.d * t;
                let sigma_t = self.sigma_t_at(p, bound);
                if rng.next_f32() * bound < sigma_t[hero] {
                    let albedo = self.albedo.eval(p).clamp(Rgb::ZERO, Rgb::ONE);
                    scatter = Some(FreeFlight::Scatter {
                        t,
                        weight: weight * sigma_t * albedo / sigma_t[hero],
                        ratio: ratio * sigma_t / sigma_t[hero],
                    });
                    return false;
                }
                // A null collision: the hero's probability of it, σn/σ̄, is positive here.
                let sigma_n = Rgb::splat(bound) - sigma_t;
                let r = sigma_n / sigma_n[hero];
                weight *= r;
                ratio *= r;
            }
        });
        scatter.unwrap_or(FreeFlight::Pass { weight, ratio })
    }

    /// Ratio tracking: the product of 1 − σt/σ̄ over tentative collisions before `t_end`.
    fn ratio_tracking(&self, ray: &Ray, t_end: f32, rng: &mut impl UniformSource) -> Rgb {
        let mut tr = Rgb::ONE;
        self.stretches(ray, t_end, |t0, t1, bound| {
            if t1.is_infinite() {
                // An unbounded constant extinction: nothing passes (unless a channel is empty).
                tr = transmittance(self.sigma_t.eval(ray.o) * self.scale, f32::INFINITY);
                return false;
            }
            let mut t = t0;
            loop {
                t -= (1.0 - rng.next_f32()).ln() / bound;
                if t >= t1 {
                    return true;
                }
                let sigma_t = self.sigma_t_at(ray.o + ray.d * t, bound);
                tr *= Rgb::ONE - sigma_t / bound;
                if tr.max_element() <= 0.0 {
                    tr = Rgb::ZERO;
                    return false;
                }
            }
        });
        tr
    }
}

/// [`Medium::sample_free_flight`] in a homogeneous medium: the exponential of the hero
/// channel, `u` in [0, 1).
#[inline]
fn homogeneous_free_flight(
    sigma_t: Rgb,
    albedo: Rgb,
    t_max: f32,
    hero: usize,
    u: f32,
) -> FreeFlight {
    let sigma = sigma_t[hero];
    // −ln(1 − u)/σ; u < 1, so the logarithm is finite (σ = 0: never scatters).
    let t = if sigma > 0.0 {
        -(1.0 - u).ln() / sigma
    } else {
        f32::INFINITY
    };
    if t < t_max {
        let tr = transmittance(sigma_t, t);
        // The hero's density σ·exp(−σt) > 0: t is finite and was drawn from it.
        let density = sigma_t * tr;
        let hero_density = density[hero];
        FreeFlight::Scatter {
            t,
            weight: tr * (albedo * sigma_t) / hero_density,
            ratio: density / hero_density,
        }
    } else {
        let tr = transmittance(sigma_t, t_max);
        // The hero passes with probability exp(−σ t_max) > 0, else t would be below t_max.
        let hero_tr = tr[hero];
        FreeFlight::Pass {
            weight: tr / hero_tr,
            ratio: tr / hero_tr,
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
        Medium::homogeneous(sigma_t, albedo, PhaseFunction::Isotropic, "fog")
    }

    /// A ray along +x from the origin.
    fn ray_x() -> Ray {
        Ray::new(Vec3::ZERO, Vec3::X)
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
            match m.sample_free_flight(&ray_x(), t_max, hero, &mut rng) {
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
        let tr = transmittance(Rgb::new(0.3, 1.0, 3.0), t_max);
        let expected_scatter = Rgb::new(0.9, 0.5, 0.2) * (Rgb::ONE - tr);
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
        let mut rng = Pcg32::new(1, 1);
        assert_eq!(
            m.transmittance(&ray_x(), f32::INFINITY, &mut rng),
            Rgb::new(1.0, 0.0, 0.0)
        );
        // Hero channel 0: no scattering, the ray passes with only the red channel left.
        match m.sample_free_flight(&ray_x(), f32::INFINITY, 0, &mut rng) {
            FreeFlight::Pass { weight, ratio } => {
                assert_eq!(weight, Rgb::new(1.0, 0.0, 0.0));
                assert_eq!(ratio, Rgb::new(1.0, 0.0, 0.0));
            }
            other => panic!("{other:?}"),
        }
        // Hero channel 2: it scatters at a finite distance.
        assert!(matches!(
            m.sample_free_flight(&ray_x(), f32::INFINITY, 2, &mut rng),
            FreeFlight::Scatter { .. }
        ));
    }

    /// A heterogeneous medium along +x: a 2×1×1 grid (nearest) over [0, 2]×[0, 1]² with
    /// extinction `a` in x < 1 and `b` beyond (three channels), albedo `albedo`.
    pub(crate) fn two_cell_medium(a: Rgb, b: Rgb, albedo: Rgb) -> Medium {
        use grid::{GridFilter, VolFile};
        let file = VolFile {
            res: glam::UVec3::new(2, 1, 1),
            channels: 3,
            bbox: (Vec3::ZERO, Vec3::ONE),
            data: a.to_array().into_iter().chain(b.to_array()).collect(),
        };
        let grid = VolumeGrid::new(
            file,
            glam::Mat4::from_scale(Vec3::new(2.0, 1.0, 1.0)),
            false,
            GridFilter::Nearest,
            crate::texture::BitmapWrap::Clamp,
            "two-cell".into(),
        )
        .unwrap();
        let sigma_t = VolumeTexture::Grid(std::sync::Arc::new(grid));
        Medium {
            density: Density::Heterogeneous(Box::new(Heterogeneous::new(
                sigma_t,
                VolumeTexture::Constant(albedo),
                1.0,
                Some((Vec3::ZERO, Vec3::new(2.0, 1.0, 1.0))),
            ))),
            phase: PhaseFunction::Isotropic,
            sample_emitters: true,
            name: "two-cell".into(),
        }
    }

    /// Delta and ratio tracking through a grid are unbiased per channel: along a ray through
    /// both cells (entering at x = −1, outside the box) the mean transmittance estimate and
    /// the mean "passed" estimate of free-flight sampling (hero uniform, weight / mean ratio)
    /// are exp(−(a + b)); the mean scatter estimate is albedo·(1 − exp(−(a + b))); a ray that
    /// misses the box passes untouched.
    #[test]
    fn tracking_through_a_grid_is_unbiased_per_channel() {
        let (a, b) = (Rgb::new(0.3, 0.6, 0.9), Rgb::new(1.2, 0.4, 2.0));
        let albedo = Rgb::new(0.8, 0.5, 0.3);
        let m = two_cell_medium(a, b, albedo);
        let ray = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X);
        let expected = (-(a + b)).exp();
        let mut rng = Pcg32::new(11, 3);
        let n = 200_000;
        let (mut tr, mut passed, mut scattered) = (Rgb::ZERO, Rgb::ZERO, Rgb::ZERO);
        for _ in 0..n {
            tr += m.transmittance(&ray, 10.0, &mut rng);
            let hero = ((rng.next_f32() * 3.0) as usize).min(2);
            match m.sample_free_flight(&ray, 10.0, hero, &mut rng) {
                FreeFlight::Pass { weight, ratio } => {
                    passed += weight / (ratio.element_sum() / 3.0)
                }
                FreeFlight::Scatter { t, weight, ratio } => {
                    assert!((1.0..3.0).contains(&t), "{t}");
                    scattered += weight / (ratio.element_sum() / 3.0);
                }
            }
        }
        let (tr, passed, scattered) = (tr / n as f32, passed / n as f32, scattered / n as f32);
        let close = |x: Rgb, y: Rgb| (x - y).abs().max_element() < 0.01;
        assert!(close(tr, expected), "{tr:?} vs {expected:?}");
        assert!(close(passed, expected), "{passed:?} vs {expected:?}");
        let scatter = albedo * (Rgb::ONE - expected);
        assert!(close(scattered, scatter), "{scattered:?} vs {scatter:?}");
        let miss = Ray::new(Vec3::new(-1.0, 2.0, 0.5), Vec3::X);
        assert_eq!(m.transmittance(&miss, 10.0, &mut rng), Rgb::ONE);
        assert!(matches!(
            m.sample_free_flight(&miss, 10.0, 0, &mut rng),
            FreeFlight::Pass { weight, .. } if weight == Rgb::ONE
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
