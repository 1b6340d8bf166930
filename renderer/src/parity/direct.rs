//! Direct illumination, as Mitsuba 3's `direct` integrator: at the first surface a camera ray
//! meets, `emitter_samples` light samples and `bsdf_samples` BSDF samples, combined by the
//! power heuristic over the two strategies' sample counts; emitters seen directly are added.
//! No indirect light (a BSDF sample only looks for emitters), so mirrors and glass show only
//! the emitters they reflect or refract, as in Mitsuba.
//!
//! Parameters, in the words of Mitsuba's XML: `shading_samples` (sets both counts, default 1),
//! `emitter_samples`, `bsdf_samples` (each defaults to `shading_samples`; not both zero), and
//! `hide_emitters` (the camera sees through area emitters and not the environment).

use crate::bsdf::TransportMode;
use crate::integrators::RayIntegrator;
use crate::math::Ray;
use crate::sampling::{power_heuristic, Pcg32, UniformSource};
use crate::scene::{EmitterHit, Scene};
use crate::spectrum::Rgb;

/// Settings of the direct-illumination integrator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DirectIntegrator {
    /// Light samples per camera ray (Mitsuba's `emitter_samples`).
    pub emitter_samples: u32,
    /// BSDF samples per camera ray (Mitsuba's `bsdf_samples`).
    pub bsdf_samples: u32,
}

impl Default for DirectIntegrator {
    fn default() -> Self {
        DirectIntegrator {
            emitter_samples: 1,
            bsdf_samples: 1,
        }
    }
}

impl DirectIntegrator {
    /// The integrator with these sample counts; at least one of them must be positive.
    pub fn new(emitter_samples: u32, bsdf_samples: u32) -> anyhow::Result<Self> {
        if emitter_samples == 0 && bsdf_samples == 0 {
            anyhow::bail!("the direct integrator needs at least one emitter or BSDF sample");
        }
        Ok(DirectIntegrator {
            emitter_samples,
            bsdf_samples,
        })
    }
}

impl RayIntegrator for DirectIntegrator {
    /// Radiance arriving along `ray`: emission seen directly plus the direct light reflected
    /// at the first surface, estimated with random numbers from `rng`.
    fn li(&self, scene: &Scene, ray: Ray, rng: &mut Pcg32) -> Rgb {
        let hide = scene.hide_emitters();
        let hit = if hide {
            scene.intersect_behind_emitters(&ray)
        } else {
            scene.intersect(&ray)
        };
        let Some(si) = hit else {
            return if hide || !scene.has_environment() {
                Rgb::ZERO
            } else {
                scene.environment(ray.d)
            };
        };
        let mut result = if hide {
            Rgb::ZERO
        } else {
            scene.emitted(&si, si.wo)
        };
        let bsdf = scene.bsdf(&si);
        let wo = si.to_local(si.wo);
        let sp = si.shading_point();
        // Each strategy's density is scaled by its share of the samples (the power heuristic
        // for unequal sample counts, Veach's n·p), and each sample's weight by 1/count.
        let total = (self.emitter_samples + self.bsdf_samples) as f32;
        let share_light = self.emitter_samples as f32 / total;
        let share_bsdf = self.bsdf_samples as f32 / total;

        // Light sampling (only a BSDF with a non-delta part can reflect a sampled direction).
        if bsdf.has_non_delta() {
            let per_sample = 1.0 / self.emitter_samples as f32;
            for _ in 0..self.emitter_samples {
                let u_light = rng.next_f32();
                let u_light2 = rng.next_2d();
                let Some(ls) = scene.sample_li(si.p, si.ng, u_light, u_light2) else {
                    continue;
                };
                let wi = si.to_local(ls.wi);
                let f = bsdf.eval(wo, wi, &sp, TransportMode::Radiance);
                if f.max_element() <= 0.0 || scene.light_occluded(si.p, si.ng, &ls) {
                    continue;
                }
                let w = if ls.delta {
                    1.0
                } else {
                    power_heuristic(ls.pdf * share_light, bsdf.pdf(wo, wi, &sp) * share_bsdf)
                };
                result += f * (wi.z.abs() * w * per_sample) * ls.weight;
            }
        }

        // BSDF sampling: only emitters found along the sampled direction count.
        let per_sample = 1.0 / self.bsdf_samples as f32;
        for _ in 0..self.bsdf_samples {
            let u_lobe = rng.next_f32();
            let u_bsdf = rng.next_2d();
            let Some(bs) = bsdf.sample(wo, &sp, u_lobe, u_bsdf, TransportMode::Radiance) else {
                continue;
            };
            if bs.weight.max_element() <= 0.0 {
                continue;
            }
            let next = si.spawn_ray(si.to_world(bs.wi));
            // Light sampling cannot produce a delta lobe's direction: full weight.
            let (le, pdf_light) = match scene.intersect_emitter(&next) {
                EmitterHit::Emitter(e) => {
                    let le = scene.emitted(&e, e.wo);
                    (
                        le,
                        if bs.delta {
                            0.0
                        } else {
                            scene.pdf_li_surface(si.p, si.ng, &e)
                        },
                    )
                }
                EmitterHit::Escaped => {
                    let le = scene.environment(next.d);
                    let pdf = if bs.delta {
                        0.0
                    } else {
                        scene.pdf_li_environment(si.p, si.ng, next.d)
                    };
                    (le, pdf)
                }
                EmitterHit::Blocked => continue,
            };
            if le == Rgb::ZERO {
                continue;
            }
            let w = if bs.delta {
                1.0
            } else {
                power_heuristic(bs.pdf * share_bsdf, pdf_light * share_light)
            };
            result += bs.weight * le * (w * per_sample);
        }
        result
    }

    fn identity(&self) -> serde_json::Value {
        serde_json::json!({
            "integrator": "direct",
            "emitter_samples": self.emitter_samples,
            "bsdf_samples": self.bsdf_samples,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::{Bsdf, Diffuse};
    use crate::description::{test_sphere_scene, EmitterDesc};
    use crate::film::Film;
    use crate::integrators::path::PathTracer;
    use crate::texture::Texture;
    use crate::threads::with_threads;
    use glam::Vec3;

    /// A diffuse sphere of albedo `rho` (radius 1 at the origin) lit by `emitter` alone.
    fn sphere(rho: f32, emitter: EmitterDesc, res: u32) -> Scene {
        let bsdf = Bsdf::Diffuse(Diffuse {
            reflectance: Texture::Constant(Rgb::splat(rho)),
        });
        Scene::build(&test_sphere_scene(bsdf, emitter, res)).unwrap()
    }

    /// A convex diffuse sphere in a constant environment of radiance 1 reflects exactly its
    /// albedo (it sees the environment over its whole upper hemisphere): every split between
    /// light and BSDF samples must converge to it, which checks the MIS weights over unequal
    /// sample counts and the 1/count factors.
    #[test]
    fn every_sample_split_reflects_the_albedo_of_a_sphere_in_a_constant_environment() {
        let scene = sphere(0.5, EmitterDesc::Constant { radiance: Rgb::ONE }, 8);
        for (e, b) in [(1, 1), (1, 0), (0, 1), (3, 2), (1, 4)] {
            let film = DirectIntegrator::new(e, b)
                .unwrap()
                .render(&scene, 2048, 1, None);
            // The centre 4×4 pixels see only the sphere, the corners only the environment.
            // Light samples alone are the noisiest split (uniform directions, half of them
            // below the surface): σ ≈ 0.014 per pixel, 0.0036 for the mean of the 16.
            let mut sum = Rgb::ZERO;
            for y in 2..6 {
                for x in 2..6 {
                    let p = film.get(x, y);
                    sum += p;
                    assert!(
                        (p - Rgb::splat(0.5)).abs().max_element() < 0.07,
                        "({e}, {b}) pixel ({x}, {y}): {p:?}"
                    );
                }
            }
            let mean = sum / 16.0;
            assert!(
                (mean - Rgb::splat(0.5)).abs().max_element() < 0.012,
                "({e}, {b}) mean of the sphere's pixels: {mean:?}"
            );
            assert_eq!(film.get(0, 0), Rgb::ONE, "({e}, {b})");
        }
    }

    /// A delta light is sampled exactly by every light sample: more samples give the same
    /// image (Mitsuba 3.9's `direct` adds it once per sample instead, mitsuba3 issue #1861).
    #[test]
    fn more_light_samples_do_not_brighten_a_point_light() {
        let light = EmitterDesc::Point {
            position: Vec3::new(0.0, 3.0, -2.0),
            intensity: Rgb::splat(10.0),
        };
        let scene = sphere(0.8, light, 8);
        // Along one camera ray nothing is random (one light, sampled exactly): the estimates
        // are equal, and equal to the closed form ρ/π · I·cos θ / d².
        let ray = Ray::new(
            Vec3::new(0.0, 0.0, -4.0),
            Vec3::new(0.0, 0.3, 4.0).normalize(),
        );
        let hit = scene.intersect(&ray).unwrap();
        let to_light = Vec3::new(0.0, 3.0, -2.0) - hit.p;
        let cos = hit.ng.dot(to_light.normalize());
        let expected = 0.8 / std::f32::consts::PI * 10.0 * cos / to_light.length_squared();
        for samples in [1, 4] {
            let mut rng = crate::sampling::rng_for(1, 0, 0);
            let li = DirectIntegrator::new(samples, 0)
                .unwrap()
                .li(&scene, ray, &mut rng);
            assert!(
                (li - Rgb::splat(expected)).abs().max_element() < 1e-5,
                "{samples} samples: {li:?}, expected {expected}"
            );
        }
    }

    /// Direct illumination is the path tracer's first two path segments: on a scene with every
    /// kind of light and several materials the two images' means agree within their noise.
    #[test]
    fn matches_the_path_tracer_at_max_depth_two() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes/validation/mixed-features/scene.xml");
        let defines = [("res".to_string(), "16".to_string())];
        let desc = crate::xml::load_scene(&path, &defines, false).unwrap();
        let scene = Scene::from_description(desc).unwrap();
        let mean = |film: &Film| film.mean();
        let direct = mean(&DirectIntegrator::default().render(&scene, 1024, 1, None));
        let tracer = PathTracer {
            max_depth: 2,
            rr_depth: 5,
        };
        let reference = mean(&tracer.render(&scene, 1024, 2, None));
        assert!(direct.min_element() > 0.01, "{direct:?}");
        let rel = ((direct - reference).abs() / reference).max_element();
        assert!(rel < 0.01, "direct {direct:?} vs path {reference:?}");
    }

    #[test]
    fn bit_identical_with_one_and_two_threads() {
        let scene = sphere(0.5, EmitterDesc::Constant { radiance: Rgb::ONE }, 8);
        let direct = DirectIntegrator::new(2, 1).unwrap();
        let one = with_threads(1, || direct.render(&scene, 16, 3, None)).unwrap();
        let two = with_threads(2, || direct.render(&scene, 16, 3, None)).unwrap();
        assert_eq!(one, two);
    }

    #[test]
    fn no_samples_at_all_is_refused() {
        let err = DirectIntegrator::new(0, 0).unwrap_err();
        assert!(err.to_string().contains("at least one"), "{err}");
    }
}
