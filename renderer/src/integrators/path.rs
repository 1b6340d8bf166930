//! Unidirectional path tracer, as Mitsuba 3's `path` integrator: next-event estimation with
//! multiple importance sampling (power heuristic) for area and environment lights, delta lights
//! by NEE only, Russian roulette from `rr_depth` on with probability min(max(β)·η², 0.95), and
//! `max_depth` counted as Mitsuba does (1: emitters seen directly; 2: direct lighting; …).

use super::{russian_roulette, RayIntegrator};
use crate::bsdf::TransportMode;
use crate::math::Ray;
use crate::sampling::{power_heuristic, Pcg32, UniformSource};
use crate::scene::{EmitterHit, Scene, SurfaceInteraction};
use crate::spectrum::Rgb;

/// Settings of the path tracer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathTracer {
    /// Longest path in segments (−1: unbounded), Mitsuba's `max_depth`.
    pub max_depth: i32,
    /// Depth from which Russian roulette starts, Mitsuba's `rr_depth`.
    pub rr_depth: u32,
}

impl Default for PathTracer {
    fn default() -> Self {
        PathTracer {
            max_depth: -1,
            rr_depth: 5,
        }
    }
}

impl RayIntegrator for PathTracer {
    /// Radiance arriving along `ray`, estimated with one path drawn from `rng`.
    fn li(&self, scene: &Scene, mut ray: Ray, rng: &mut Pcg32) -> Rgb {
        if self.max_depth == 0 {
            return Rgb::ZERO;
        }
        let max_depth = if self.max_depth < 0 {
            u32::MAX
        } else {
            self.max_depth as u32
        };
        let mut throughput = Rgb::ONE;
        let mut result = Rgb::ZERO;
        let mut eta = 1.0f32;
        let mut depth = 0u32;
        // The previous scattering vertex, for MIS of emission found by BSDF sampling.
        let mut prev_p = ray.o;
        let mut prev_n = glam::Vec3::ZERO;
        let mut prev_pdf = 1.0f32;
        let mut prev_delta = true;
        // Mitsuba's `hide_emitters`: what the camera sees directly — also through surfaces it
        // passes straight through (masks, thin glass) — is hidden: area emitters are seen
        // through and the environment is black; reflections of both stay.
        let hide_direct = scene.hide_emitters();
        let mut seen_directly = true;
        loop {
            let hidden = hide_direct && seen_directly;
            // Emission found by BSDF sampling (or seen from the camera), MIS-weighted against
            // light sampling from the previous vertex.
            let environment = |ray: &Ray| {
                let w = if prev_delta {
                    1.0
                } else {
                    power_heuristic(prev_pdf, scene.pdf_li_environment(prev_p, prev_n, ray.d))
                };
                throughput * scene.environment(ray.d) * w
            };
            let emission = |si: &SurfaceInteraction| {
                let le = scene.emitted(si, si.wo);
                if le == Rgb::ZERO {
                    return Rgb::ZERO;
                }
                let w = if prev_delta {
                    1.0
                } else {
                    power_heuristic(prev_pdf, scene.pdf_li_surface(prev_p, prev_n, si))
                };
                throughput * le * w
            };
            if depth + 1 >= max_depth {
                if hidden {
                    break;
                }
                // The last vertex: only its emission counts, so the ray looks for emitters
                // only (the same answer as a closest hit, for less work).
                result += match scene.intersect_emitter(&ray) {
                    EmitterHit::Emitter(si) => emission(&si),
                    EmitterHit::Escaped => environment(&ray),
                    EmitterHit::Blocked => Rgb::ZERO,
                };
                break;
            }
            // Hidden emitters are seen through, to what lies behind them (as Mitsuba 3).
            let hit = if hidden {
                scene.intersect_behind_emitters(&ray)
            } else {
                scene.intersect(&ray)
            };
            let Some(si) = hit else {
                if scene.has_environment() && !hidden {
                    result += environment(&ray);
                }
                break;
            };
            if si.light.is_some() && !hidden {
                result += emission(&si);
            }
            let bsdf = scene.bsdf(&si);
            let wo = si.to_local(si.wo);
            let sp = si.shading_point();

            // Next-event estimation.
            let u_light = rng.next_f32();
            let u_light2 = rng.next_2d();
            if bsdf.has_non_delta() {
                if let Some(ls) = scene.sample_li(si.p, si.ng, u_light, u_light2) {
                    let wi = si.to_local(ls.wi);
                    let f = bsdf.eval(wo, wi, &sp, TransportMode::Radiance);
                    if f.max_element() > 0.0 && !scene.light_occluded(si.p, si.ng, &ls) {
                        let w = if ls.delta {
                            1.0
                        } else {
                            power_heuristic(ls.pdf, bsdf.pdf(wo, wi, &sp))
                        };
                        result += throughput * f * (wi.z.abs() * w) * ls.weight;
                    }
                }
            }

            // Continue the path by BSDF sampling.
            let u_lobe = rng.next_f32();
            let u_bsdf = rng.next_2d();
            let Some(bs) = bsdf.sample(wo, &sp, u_lobe, u_bsdf, TransportMode::Radiance) else {
                break;
            };
            seen_directly &= bs.passes_through(wo);
            let wi_world = si.to_world(bs.wi);
            ray = si.spawn_ray(wi_world);
            throughput *= bs.weight;
            eta *= bs.eta;
            prev_p = si.p;
            prev_n = si.ng;
            prev_pdf = bs.pdf;
            prev_delta = bs.delta;
            depth += 1;

            match russian_roulette(depth, self.rr_depth, throughput.max_element(), eta, rng) {
                Some(q) => throughput /= q,
                None => break,
            }
        }
        result
    }

    fn identity(&self) -> serde_json::Value {
        serde_json::json!({
            "integrator": "path",
            "max_depth": self.max_depth,
            "rr_depth": self.rr_depth,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::{Bsdf, Diffuse};
    use crate::description::{
        test_camera, EmitterDesc, Geometry, SceneDescription, ShapeDesc, TriangleMesh,
    };
    use crate::film::Film;
    use crate::texture::Texture;
    use crate::threads::with_threads;
    use glam::Vec3;

    fn diffuse(r: f32) -> Bsdf {
        Bsdf::Diffuse(Diffuse {
            reflectance: Texture::Constant(Rgb::splat(r)),
        })
    }

    /// A diffuse sphere of albedo `rho` seen from outside, in a constant environment of radiance 1.
    fn sphere_in_environment(rho: f32) -> Scene {
        sphere_lit_by(rho, EmitterDesc::Constant { radiance: Rgb::ONE })
    }

    /// A diffuse sphere of albedo `rho` seen from outside, lit by `emitter` alone.
    fn sphere_lit_by(rho: f32, emitter: EmitterDesc) -> Scene {
        sphere_of(diffuse(rho), emitter)
    }

    /// A sphere of material `bsdf` seen from outside, lit by `emitter` alone.
    fn sphere_of(bsdf: Bsdf, emitter: EmitterDesc) -> Scene {
        Scene::build(&crate::description::test_sphere_scene(bsdf, emitter, 8)).unwrap()
    }

    /// The camera inside a closed sphere whose inner surface has albedo `rho` and emits radiance 1:
    /// the radiance everywhere is Σ_{k<D} ρᵏ for max_depth D.
    fn emitting_enclosure(rho: f32) -> Scene {
        let desc = SceneDescription {
            camera: test_camera(Vec3::new(0.1, 0.2, 0.0), Vec3::new(0.0, 0.0, 1.0), 40.0, 4),
            sample_count: None,
            integrator: None,
            bsdfs: vec![diffuse(rho)],
            shapes: vec![crate::description::emitting_unit_enclosure(0)],
            emitters: vec![],
            warnings: vec![],
            media: vec![],
            camera_medium: None,
        };
        Scene::build(&desc).unwrap()
    }

    /// The stricter furnace verdict: every pixel is 1 within 5 %, and the mean within 1 %.
    fn assert_every_pixel_is_one(film: &Film) {
        for (i, p) in film.pixels.iter().enumerate() {
            assert!(
                (*p - Rgb::ONE).abs().max_element() < 0.05,
                "pixel {i}: {p:?}"
            );
        }
        assert_mean_is_one(film);
    }

    /// The furnace's verdict: the image's mean is 1 within 1 %.
    fn assert_mean_is_one(film: &Film) {
        let mean = film.mean();
        assert!((mean - Rgb::ONE).abs().max_element() < 0.01, "{mean:?}");
    }

    #[test]
    fn white_furnace_sphere_in_environment() {
        let scene = sphere_in_environment(1.0);
        let film = PathTracer::default().render(&scene, 256, 1, None);
        assert_every_pixel_is_one(&film);
    }

    /// The furnace again, lit by an environment *map* of radiance 1 (a 5×3 image, rotated):
    /// its lookup, importance sampling and MIS weights must add up to the same 1.
    #[test]
    fn white_furnace_sphere_under_a_uniform_envmap() {
        let scene = sphere_lit_by(
            1.0,
            EmitterDesc::Envmap {
                image: std::sync::Arc::new(crate::texture::Bitmap {
                    width: 5,
                    height: 3,
                    texels: vec![Rgb::splat(0.5); 15],
                }),
                to_world: glam::Mat3::from_rotation_x(0.4),
                scale: 2.0,
                filename: "uniform.exr".into(),
            },
        );
        let film = PathTracer::default().render(&scene, 256, 1, None);
        assert_mean_is_one(&film);
    }

    /// The furnace with a blend of a white diffuse and a perfect mirror (a delta model inside
    /// a blend): lossless, so every pixel is 1. (Mitsuba 3.9.1's blendbsdf loses energy here:
    /// it adds the mirror's selection probability to the diffuse density.)
    #[test]
    fn white_furnace_blend_of_diffuse_and_mirror() {
        use crate::bsdf::{Blend, Conductor};
        let mirror = Bsdf::Conductor(Conductor {
            ior: None,
            specular_reflectance: Texture::Constant(Rgb::ONE),
        });
        let blend = Bsdf::Blend(Blend {
            weight: Texture::Constant(Rgb::splat(0.35)),
            nested: Box::new([diffuse(1.0), mirror]),
        });
        let scene = sphere_of(blend, EmitterDesc::Constant { radiance: Rgb::ONE });
        let film = PathTracer::default().render(&scene, 2048, 1, None);
        assert_every_pixel_is_one(&film);
    }

    /// The furnace with a white two-sided diffuse sphere behind an opacity of 0.4 (seen from
    /// outside and, through the mask, from inside): light passing through the mask (a forward
    /// delta) and light reflected by it add up to 1 everywhere.
    #[test]
    fn white_furnace_masked_sphere() {
        use crate::bsdf::Mask;
        let mask = Bsdf::Mask(Mask {
            opacity: Texture::Constant(Rgb::splat(0.4)),
            nested: Box::new(Bsdf::TwoSided {
                front: Box::new(diffuse(1.0)),
                back: Box::new(diffuse(1.0)),
            }),
        });
        let scene = sphere_of(mask, EmitterDesc::Constant { radiance: Rgb::ONE });
        let film = PathTracer::default().render(&scene, 2048, 1, None);
        assert_every_pixel_is_one(&film);
    }

    /// `hide_emitters`: the environment seen directly renders black, while the sphere it lights
    /// keeps its furnace value (only the camera ray's own emission is dropped).
    #[test]
    fn hide_emitters_blacks_out_only_the_directly_seen_environment() {
        let mut scene = sphere_in_environment(1.0);
        let shown = PathTracer::default().render(&scene, 64, 1, None);
        scene.integrator = Some(crate::description::IntegratorDesc::hiding_emitters());
        let hidden = PathTracer::default().render(&scene, 64, 1, None);
        // Corner pixels see only the environment; the centre sees only the sphere.
        assert_eq!(shown.get(0, 0), Rgb::ONE);
        assert_eq!(hidden.get(0, 0), Rgb::ZERO);
        assert_eq!(
            shown.get(4, 4),
            hidden.get(4, 4),
            "same random streams, same light"
        );
        assert!((hidden.get(4, 4) - Rgb::ONE).abs().max_element() < 0.1);
    }

    /// `hide_emitters` sees through area emitters, as Mitsuba 3: a white emitting sphere
    /// between the camera and a diffuse ball, in a constant environment. Hidden, the camera
    /// sees the ball behind the emitter (and, past the ball's silhouette, the hidden
    /// environment: black), never the emitter's own lit surface.
    #[test]
    fn hide_emitters_sees_through_area_emitters() {
        let sphere = |center: Vec3, radius: f32, bsdf: usize, emission: Option<Rgb>| ShapeDesc {
            name: "sphere".into(),
            geometry: Geometry::Sphere {
                center,
                radius,
                rotation: glam::Mat3::IDENTITY,
                flip_normals: false,
            },
            bsdf,
            emission: emission.map(Texture::Constant),
            collimated: false,
            media: Default::default(),
        };
        let desc = |hide: bool| SceneDescription {
            camera: test_camera(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, 40.0, 8),
            sample_count: None,
            integrator: hide.then(crate::description::IntegratorDesc::hiding_emitters),
            bsdfs: vec![diffuse(1.0), diffuse(0.5)],
            // The ball (radius 0.5 at the origin) and, in front of it, a larger emitter that
            // covers the ball and some environment around it in the central pixels.
            shapes: vec![
                sphere(Vec3::ZERO, 0.5, 1, None),
                sphere(Vec3::new(0.0, 0.0, -2.5), 0.6, 0, Some(Rgb::splat(3.0))),
            ],
            emitters: vec![EmitterDesc::Constant { radiance: Rgb::ONE }],
            warnings: vec![],
            media: vec![],
            camera_medium: None,
        };
        let hidden_scene = Scene::build(&desc(true)).unwrap();
        // The closest hit is the emitter; behind it lies the ball, 3.5 − 0.5 from the camera.
        let ray = Ray::new(Vec3::new(0.0, 0.0, -4.0), Vec3::Z);
        assert_eq!(hidden_scene.intersect(&ray).unwrap().shape, 1);
        let behind = hidden_scene.intersect_behind_emitters(&ray).unwrap();
        assert_eq!(behind.shape, 0);
        assert!((behind.p.z + 0.5).abs() < 1e-4, "{:?}", behind.p);
        // A ray that passes the emitter and then escapes finds nothing.
        let past = Ray::new(
            Vec3::new(0.0, 0.0, -4.0),
            Vec3::new(0.5, 0.0, 1.5).normalize(),
        );
        assert_eq!(hidden_scene.intersect(&past).unwrap().shape, 1);
        assert!(hidden_scene.intersect_behind_emitters(&past).is_none());

        let shown = PathTracer::default().render(&Scene::build(&desc(false)).unwrap(), 64, 1, None);
        let hidden = PathTracer::default().render(&hidden_scene, 64, 1, None);
        // The emitter fills the centre of the 8×8 image in both; shown, it glows (3 + its lit
        // white surface); hidden, the centre is the ball, lit by the environment and the
        // emitter, and darker than the emitter.
        let centre = (hidden.get(3, 3) + hidden.get(4, 4)) * 0.5;
        assert!(shown.get(3, 3).min_element() > 3.0, "{:?}", shown.get(3, 3));
        assert!(
            centre.min_element() > 0.2 && centre.max_element() < 3.0,
            "{centre:?}"
        );
        // Every pixel of the hidden image that the emitter covers but the ball does not is
        // black: the ray went through the emitter into the hidden environment.
        let mut through_to_environment = 0;
        for y in 0..8 {
            for x in 0..8 {
                // The pixel's corners and centre (both spheres project to disks, so a pixel
                // whose five rays pass the emitter and miss the ball lies inside that ring).
                let through = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.5, 0.5)]
                    .iter()
                    .all(|&(dx, dy)| {
                        let film = glam::Vec2::new(x as f32 + dx, y as f32 + dy);
                        let ray = hidden_scene.camera.ray_at(film, glam::Vec2::splat(0.5));
                        hidden_scene.intersect(&ray).map(|si| si.shape) == Some(1)
                            && hidden_scene.intersect_behind_emitters(&ray).is_none()
                    });
                if through {
                    through_to_environment += 1;
                    assert_eq!(hidden.get(x, y), Rgb::ZERO, "pixel ({x}, {y})");
                    assert!(shown.get(x, y).min_element() > 3.0, "pixel ({x}, {y})");
                }
            }
        }
        assert!(through_to_environment >= 4, "{through_to_environment}");
    }

    /// `hide_emitters` also hides what the camera sees through surfaces it passes straight
    /// through (Mitsuba's null interactions): a black masked sphere in a constant environment
    /// renders black, although half the light passes each of its surfaces; a thin glass
    /// sphere shows only what it reflects.
    #[test]
    fn hide_emitters_hides_the_environment_seen_through_masks_and_thin_glass() {
        use crate::bsdf::{Mask, ThinDielectric};
        let hide = |mut scene: Scene| {
            scene.integrator = Some(crate::description::IntegratorDesc::hiding_emitters());
            scene
        };
        let mask = || {
            Bsdf::Mask(Mask {
                opacity: Texture::Constant(Rgb::splat(0.5)),
                nested: Box::new(diffuse(0.0)),
            })
        };
        let environment = EmitterDesc::Constant { radiance: Rgb::ONE };
        let shown =
            PathTracer::default().render(&sphere_of(mask(), environment.clone()), 64, 1, None);
        assert!(shown.get(4, 4).min_element() > 0.1, "{:?}", shown.get(4, 4));
        let hidden = PathTracer::default().render(
            &hide(sphere_of(mask(), environment.clone())),
            64,
            1,
            None,
        );
        assert!(
            hidden.pixels.iter().all(|p| *p == Rgb::ZERO),
            "{:?}",
            hidden.mean()
        );

        let glass = Bsdf::ThinDielectric(ThinDielectric {
            eta: 1.5,
            specular_reflectance: Texture::Constant(Rgb::ONE),
            specular_transmittance: Texture::Constant(Rgb::ONE),
        });
        let scene = hide(sphere_of(glass, environment));
        let film = PathTracer::default().render(&scene, 1024, 1, None);
        // The centre pixels see the sphere head-on: each of its two surfaces reflects about
        // 2R/(1 + R) ≈ 8 % of the light at normal incidence; the 92 % passing straight through
        // both is hidden.
        let centre = film.get(4, 4);
        assert!(
            centre.max_element() < 0.3 && centre.min_element() > 0.02,
            "{centre:?}"
        );
    }

    #[test]
    fn max_depth_limits_the_bounces_seen_in_the_environment() {
        let scene = sphere_in_environment(0.5);
        // Depth 1: only the environment seen directly; the sphere is black.
        let f1 = PathTracer {
            max_depth: 1,
            rr_depth: 5,
        }
        .render(&scene, 16, 2, None);
        let centre = f1.get(4, 4);
        assert_eq!(centre, Rgb::ZERO);
        assert_eq!(f1.get(0, 0), Rgb::ONE);
        // Depth 2 and more: a convex sphere reflects the environment once: 0.5.
        let f2 = PathTracer {
            max_depth: 2,
            rr_depth: 5,
        }
        .render(&scene, 256, 3, None);
        let c = f2.get(4, 4);
        assert!((c - Rgb::splat(0.5)).abs().max_element() < 0.03, "{c:?}");
    }

    #[test]
    fn emitting_enclosure_follows_the_geometric_series() {
        let rho = 0.5f32;
        let scene = emitting_enclosure(rho);
        for (depth, spp) in [(1, 4), (2, 256), (3, 256), (-1, 256)] {
            let expected = if depth < 0 {
                1.0 / (1.0 - rho)
            } else {
                (0..depth).map(|k| rho.powi(k)).sum::<f32>()
            };
            let film = PathTracer {
                max_depth: depth,
                rr_depth: 5,
            }
            .render(&scene, spp, 7, None);
            let m = film.mean();
            assert!(
                (m - Rgb::splat(expected)).abs().max_element() < 0.01 * expected,
                "max_depth {depth}: mean {m:?}, expected {expected}"
            );
        }
    }

    #[test]
    fn images_are_bit_identical_for_one_and_two_threads() {
        let scene = emitting_enclosure(0.7);
        let pt = PathTracer::default();
        let a = with_threads(1, || pt.render(&scene, 8, 42, None)).unwrap();
        let b = with_threads(2, || pt.render(&scene, 8, 42, None)).unwrap();
        assert!(a
            .pixels
            .iter()
            .zip(&b.pixels)
            .all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits)));
        let c = with_threads(2, || pt.render(&scene, 8, 43, None)).unwrap();
        assert_ne!(a, c, "the seed changes the image");
    }

    /// An edge seen through each reconstruction filter: a black screen covers the film left of
    /// x = 7.3 pixels in front of a constant environment of radiance 1 (orthographic view, so
    /// the edge is a straight line in the film). Each pixel's value must be the filter's mass
    /// right of the edge over the image (the filter truncated at the image borders, as
    /// Mitsuba's film only takes samples inside the image) — overshoot of the negative-lobed
    /// filters included.
    #[test]
    fn reconstruction_filters_blur_an_edge_by_their_integral() {
        use crate::filter::FilterDesc;
        let (width, height, edge) = (16u32, 4u32, 7.3f64);
        // Camera-space +x is the image's left: film x = X maps to local x = 1 − 2X/width.
        let x_edge = 1.0 - 2.0 * edge as f32 / width as f32;
        let (x0, x1) = (x_edge, 10.0f32);
        let screen = TriangleMesh {
            positions: vec![
                Vec3::new(x0, -10.0, 5.0),
                Vec3::new(x1, -10.0, 5.0),
                Vec3::new(x1, 10.0, 5.0),
                Vec3::new(x0, 10.0, 5.0),
            ],
            normals: None,
            uvs: None,
            indices: vec![[0, 1, 2], [2, 3, 0]],
            flipped: false,
        };
        let tent = FilterDesc::Tent { radius: 1.5 };
        for filter in crate::filter::TEST_FILTERS.into_iter().chain([tent]) {
            let mut cam = test_camera(Vec3::ZERO, Vec3::Z, 40.0, width);
            cam.height = height;
            cam.projection = crate::description::Projection::Orthographic;
            cam.filter = filter;
            let desc = SceneDescription {
                camera: cam,
                sample_count: None,
                integrator: None,
                bsdfs: vec![diffuse(0.0)],
                shapes: vec![ShapeDesc {
                    name: "screen".into(),
                    geometry: Geometry::Mesh(screen.clone()),
                    bsdf: 0,
                    emission: None,
                    collimated: false,
                    media: Default::default(),
                }],
                emitters: vec![EmitterDesc::Constant { radiance: Rgb::ONE }],
                warnings: vec![],
                media: vec![],
                camera_medium: None,
            };
            let scene = Scene::build(&desc).unwrap();
            let film = PathTracer::default().render(&scene, 4096, 9, None);
            for x in 0..width {
                let expected = crate::filter::edge_response(&filter, width, edge, x);
                let column: f64 =
                    (0..height).map(|y| film.get(x, y).x as f64).sum::<f64>() / height as f64;
                assert!(
                    (column - expected).abs() < 0.025,
                    "{filter:?}, pixel column {x}: {column} vs {expected}"
                );
            }
        }
    }
}
