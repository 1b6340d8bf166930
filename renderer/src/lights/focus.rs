//! Where photons from infinite lights (directional, constant, environment map) start when the
//! camera sees only part of the scene: a defensive mixture of the scene's bounding disk and a
//! smaller disk around the region the camera sees.
//!
//! Why: an infinite light's photons start uniformly on a disk covering the whole scene. In a
//! sunlit exterior whose ground plane is 45 m wide while the camera frames a few metres, about
//! one photon in two hundred lands where a visible point can gather it; the kernels then start
//! wide and the photon part of the image stays noisy and blurred. Sending a share of the photons
//! through a disk around the visible region puts many times more of them there.
//!
//! Why it stays unbiased (and SPPM consistent): a photon's origin q on the plane facing its
//! direction d is drawn from the mixture p·U(focus disk) + (1 − p)·U(scene disk), and its flux is
//! divided by that mixture's density at q (relative to the uniform scene disk the lights assume).
//! Every point of the scene disk keeps a density ≥ (1 − p)/(πR²) > 0, so every light path the
//! uniform start could produce is still produced, with the flux that makes its expectation the
//! same. The origin is moved back along d to the scene disk's plane, so no geometry between the
//! scene's bound and the focus is skipped.

use super::SceneSphere;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A share of an infinite light's photons aimed at a sphere around what the camera sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotonFocus {
    /// The region the camera sees (with a margin), as a bounding sphere.
    pub sphere: SceneSphere,
    /// Probability that a photon starts on the focus disk, in (0, 1).
    pub share: f32,
}

impl PhotonFocus {
    /// The start of a photon travelling along `d` (unit) drawn from the mixture by `u`, and the
    /// factor its flux (computed for a uniform start on `scene`'s disk) is to be multiplied by:
    /// the uniform disk's density over the mixture's at that point.
    pub fn origin(&self, scene: &SceneSphere, d: Vec3, u: Vec2) -> (Vec3, f32) {
        let p = self.share;
        // The drawn component, its share, the other one and its share; u.x is reused within
        // the drawn component, so the draw stays stratified.
        let (drawn, drawn_share, other, other_share, ux) = if u.x < p {
            (&self.sphere, p, scene, 1.0 - p, u.x / p)
        } else {
            (
                scene,
                1.0 - p,
                &self.sphere,
                p,
                ((u.x - p) / (1.0 - p)).min(1.0),
            )
        };
        let q = drawn.photon_origin(d, Vec2::new(ux, u.y));
        // The drawn component always counts (its own disk holds q, rounding aside); the other
        // one where q lies within its disk, measured across d.
        let v = q - other.center;
        let inside_other = (v - d * v.dot(d)).length_squared() <= other.radius * other.radius;
        let density = drawn_share / disk_area(drawn.radius)
            + if inside_other {
                other_share / disk_area(other.radius)
            } else {
                0.0
            };
        // Back along d to the plane one radius before the scene's centre.
        let origin = q - d * ((q - scene.center).dot(d) + scene.radius);
        (origin, 1.0 / (disk_area(scene.radius) * density))
    }
}

fn disk_area(r: f32) -> f32 {
    PI * r * r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::coordinate_system;
    use crate::sampling::{rng_for, UniformSource};

    fn scene() -> SceneSphere {
        SceneSphere {
            center: Vec3::new(1.0, -2.0, 0.5),
            radius: 10.0,
        }
    }

    fn focus() -> PhotonFocus {
        PhotonFocus {
            sphere: SceneSphere {
                center: Vec3::new(3.0, -1.0, 0.0),
                radius: 1.5,
            },
            share: 0.5,
        }
    }

    /// The flux factor is the uniform density over the mixture's: its mean over the draws is
    /// one (the photons' total flux is unchanged), and the origin lies on the scene disk's plane.
    #[test]
    fn flux_factor_has_mean_one_and_origins_start_before_the_scene() {
        let (scene, focus) = (scene(), focus());
        let d = Vec3::new(0.3, -0.8, 0.2).normalize();
        let n = 400_000;
        let mut rng = rng_for(7, 0, 0);
        let mut sum = 0.0f64;
        let mut in_focus = 0u32;
        for _ in 0..n {
            let (o, w) = focus.origin(&scene, d, rng.next_2d());
            assert!(w > 0.0 && w.is_finite());
            // On the plane one radius before the centre, within the scene disk or the focus's.
            assert!(((o - scene.center).dot(d) + scene.radius).abs() < 1e-3);
            let lat = (o - scene.center) - d * (o - scene.center).dot(d);
            assert!(lat.length() <= scene.radius * 1.0001);
            let to_f = o - focus.sphere.center;
            if (to_f - d * to_f.dot(d)).length() <= focus.sphere.radius {
                in_focus += 1;
            }
            sum += w as f64;
        }
        let mean = sum / n as f64;
        assert!((mean - 1.0).abs() < 0.01, "mean flux factor {mean}");
        // Half the draws aim at the focus, plus the scene draws that land there anyway.
        let expected = 0.5 + 0.5 * (1.5f64 / 10.0).powi(2);
        let got = in_focus as f64 / n as f64;
        assert!((got - expected).abs() < 0.005, "{got} vs {expected}");
    }

    /// The density behind the factor integrates correctly over any region: the weighted count
    /// of origins within a small disk matches its share of the uniform disk (the estimator an
    /// infinite light's photons rely on).
    #[test]
    fn weighted_hits_match_the_uniform_start() {
        let (scene, focus) = (scene(), focus());
        let d = Vec3::new(-0.5, 0.1, 0.85).normalize();
        let (s, t) = coordinate_system(d);
        // Test disks: inside the focus, straddling its edge, and far from it.
        for (offset, r) in [
            (Vec2::ZERO, 0.8f32),
            (Vec2::new(1.4, 0.0), 0.5),
            (Vec2::new(-4.0, 3.0), 2.0),
        ] {
            let c = focus.sphere.center + s * offset.x + t * offset.y;
            let n = 400_000;
            let mut rng = rng_for(11, 0, 1);
            let mut sum = 0.0f64;
            for _ in 0..n {
                let (o, w) = focus.origin(&scene, d, rng.next_2d());
                let v = o - c;
                if (v - d * v.dot(d)).length() <= r {
                    sum += w as f64;
                }
            }
            let got = sum / n as f64;
            let expected = (r as f64 / scene.radius as f64).powi(2);
            assert!(
                (got / expected - 1.0).abs() < 0.03,
                "disk at {offset:?}: {got} vs {expected}"
            );
        }
    }
}
