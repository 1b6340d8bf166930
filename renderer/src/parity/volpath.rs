//! Volumetric path tracer, as Mitsuba 3's `volpath` integrator: the path tracer of `path.rs`
//! extended to homogeneous participating media (`parity/media/`).
//!
//! * The medium a ray travels in is tracked: the camera's, then whatever a crossed surface
//!   names on the side the ray leaves towards (`MediumInterface::target`); surfaces that name
//!   no medium leave it unchanged.
//! * Along each segment a free-flight distance is drawn (`Medium::sample_free_flight`): the
//!   path scatters in the medium (a phase-function vertex with light sampling and MIS against
//!   phase sampling) or reaches the surface weighted by the transmittance.
//! * Surfaces a path passes straight through (`null`, a mask's transparent share, a thin
//!   dielectric's transmission: Mitsuba's "null" interactions) do not count as bounces and keep
//!   the previous vertex for MIS; shadow rays go through them, multiplied by their
//!   [`crate::bsdf::Bsdf::null_transmission`] and by each medium's transmittance on the way.
//! * A medium that no surface bounds extends to infinity for sampled rays (they scatter in it
//!   sooner or later), while light sampling reaches infinite lights through
//!   [`Scene::infinite_light_distance`] of it (Mitsuba's convention), so a sun or a sky shines
//!   through a haze that fills the scene. Such a light sample is the only way to that light,
//!   so it counts in full (Mitsuba weighs it by MIS against a BSDF sample that cannot get
//!   there, and loses that share of a sky's light; a sun, a delta light, renders the same).
//! * `max_depth` counts surface and medium scattering vertices as Mitsuba does (1: emitters
//!   seen directly), Russian roulette from `rr_depth` as in `path`; `hide_emitters` hides what
//!   is seen before the first scattering vertex.
//!
//! The estimator is unbiased for the same image as Mitsuba's `volpath` (its sampling differs:
//! distances are drawn for one hero channel per path, as Mitsuba, but the path is weighted by
//! the balance heuristic over the three channels (`parity/media/mod.rs`), and transmittance on shadow
//! rays is evaluated in closed form, which a homogeneous medium allows).

use crate::bsdf::TransportMode;
use crate::integrators::{russian_roulette, RayIntegrator};
use crate::lights::LightSample;
use crate::math::{offset_point, Ray};
use crate::parity::media::FreeFlight;
use crate::sampling::{power_heuristic, Pcg32, UniformSource};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec3;

/// Most surfaces one ray or shadow ray passes straight through before it is given up: each
/// crossing starts past the previous surface, so the bound only guards against a stack of
/// coincident null surfaces the ray offset cannot clear.
const MAX_NULL_CROSSINGS: u32 = 1024;

/// Settings of the volumetric path tracer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolPathTracer {
    /// Longest path in scattering vertices (−1: unbounded), Mitsuba's `max_depth`.
    pub max_depth: i32,
    /// Depth from which Russian roulette starts, Mitsuba's `rr_depth`.
    pub rr_depth: u32,
}

impl Default for VolPathTracer {
    fn default() -> Self {
        VolPathTracer {
            max_depth: -1,
            rr_depth: 5,
        }
    }
}

/// The previous scattering vertex of a path, for the MIS weight of emission its sampled
/// direction finds.
struct PreviousVertex {
    /// Its position.
    p: Vec3,
    /// Its geometric normal (`Vec3::ZERO` in a medium or at the camera).
    n: Vec3,
    /// The solid-angle density of the direction sampled there.
    pdf: f32,
    /// Whether light sampling could not have found that direction (the camera, a delta lobe,
    /// a medium that does not sample emitters): the emission then counts in full.
    unweighted: bool,
}

/// The path's weight: its throughput (which divides by the hero channel's densities) under
/// the balance heuristic over the channels, given each channel's density ratio to the hero.
#[inline]
fn spectral_mis(throughput: Rgb, ratio: Rgb) -> Rgb {
    // The hero's own ratio is 1, so the mean is at least 1/3.
    throughput / (ratio.element_sum() / 3.0)
}

impl VolPathTracer {
    /// Russian roulette after a scattering vertex at `depth`, on the path's weight; false when
    /// the path ends.
    #[inline]
    fn survives(
        &self,
        depth: u32,
        throughput: &mut Rgb,
        ratio: Rgb,
        eta: f32,
        rng: &mut Pcg32,
    ) -> bool {
        let weight_max = spectral_mis(*throughput, ratio).max_element();
        match russian_roulette(depth, self.rr_depth, weight_max, eta, rng) {
            Some(q) => {
                *throughput /= q;
                true
            }
            None => false,
        }
    }
}

/// What reaches a point from a light sample through media and null surfaces.
struct ShadowTransmittance {
    /// The fraction of the light sample's radiance that arrives.
    tr: Rgb,
    /// The shadow ray ended in a medium that no surface bounds (towards an infinite light):
    /// no sampled ray can reach the light that way.
    open: bool,
}

/// What fraction of light sample `ls`'s radiance reaches point `p` (geometric normal `ng`,
/// `Vec3::ZERO` in a medium) when the shadow ray starts in `medium`: the transmittance of every
/// medium along the way times the straight-through share of every surface it crosses (zero at
/// the first surface that lets nothing through).
fn shadow_transmittance(
    scene: &Scene,
    p: Vec3,
    ng: Vec3,
    ls: &LightSample,
    mut medium: Option<u32>,
    rng: &mut Pcg32,
) -> ShadowTransmittance {
    let blocked = ShadowTransmittance {
        tr: Rgb::ZERO,
        open: false,
    };
    let mut ray = if ls.infinite {
        Ray::new(offset_point(p, ng, ls.wi), ls.wi)
    } else {
        crate::math::spawn_ray_to(p, ng, ls.p)
    };
    let mut tr = Rgb::ONE;
    // How much further an open medium extends towards an infinite light.
    let mut reach = if ls.infinite {
        scene.infinite_light_distance(p)
    } else {
        f32::INFINITY
    };
    for _ in 0..MAX_NULL_CROSSINGS {
        let hit = scene.intersect(&ray);
        if let Some(m) = medium {
            let d = hit.as_ref().map_or(ray.tmax, |si| si.t).min(reach);
            tr *= scene.media[m as usize].transmittance(&ray, d, rng);
        }
        let Some(si) = hit else {
            return ShadowTransmittance {
                tr,
                open: medium.is_some() && ls.infinite,
            };
        };
        reach -= si.t;
        let wo = si.to_local(si.wo);
        tr *= scene.bsdf(&si).null_transmission(wo, &si.shading_point());
        if tr.max_element() <= 0.0 {
            return blocked;
        }
        let interface = scene.shape_info[si.shape as usize].media;
        if interface.is_transition() {
            medium = interface.target(si.ng, ray.d);
        }
        ray = if ls.infinite {
            si.spawn_ray(ray.d)
        } else {
            si.spawn_ray_to(ls.p)
        };
    }
    blocked
}

impl RayIntegrator for VolPathTracer {
    /// Radiance arriving along `ray` (from the camera, in the camera's medium), estimated with
    /// one path drawn from `rng`.
    fn li(&self, scene: &Scene, mut ray: Ray, rng: &mut Pcg32) -> Rgb {
        let max_depth = match self.max_depth {
            0 => return Rgb::ZERO,
            d if d < 0 => u32::MAX,
            d => d as u32,
        };
        let mut medium = scene.camera_medium;
        // The channel whose extinction draws the free-flight distances of this path.
        let hero = ((rng.next_f32() * 3.0) as usize).min(2);
        let mut ratio = Rgb::ONE;
        let mut throughput = Rgb::ONE;
        let mut result = Rgb::ZERO;
        let mut eta = 1.0f32;
        let mut depth = 0u32;
        let mut crossings = 0u32;
        let mut prev = PreviousVertex {
            p: ray.o,
            n: Vec3::ZERO,
            pdf: 1.0,
            unweighted: true,
        };
        let hide_direct = scene.hide_emitters();
        loop {
            // Before the first scattering vertex, `hide_emitters` hides what the camera sees.
            let hidden = hide_direct && depth == 0;
            let hit = if hidden {
                scene.intersect_behind_emitters(&ray)
            } else {
                scene.intersect(&ray)
            };
            if let Some(m) = medium {
                let med = &scene.media[m as usize];
                let t_max = hit.as_ref().map_or(f32::INFINITY, |si| si.t);
                match med.sample_free_flight(&ray, t_max, hero, rng) {
                    FreeFlight::Pass { weight, ratio: r } => {
                        throughput *= weight;
                        ratio *= r;
                    }
                    FreeFlight::Scatter {
                        t,
                        weight,
                        ratio: r,
                    } => {
                        throughput *= weight;
                        ratio *= r;
                        depth += 1;
                        if depth >= max_depth || throughput.max_element() <= 0.0 {
                            break;
                        }
                        let p = ray.o + ray.d * t;
                        // Light sampling, MIS-weighted against phase sampling.
                        let u_light = rng.next_f32();
                        let u_light2 = rng.next_2d();
                        if med.sample_emitters {
                            if let Some(ls) = scene.sample_li(p, Vec3::ZERO, u_light, u_light2) {
                                let f = med.phase.eval(p, ray.d, ls.wi);
                                if f > 0.0 {
                                    let st = shadow_transmittance(
                                        scene,
                                        p,
                                        Vec3::ZERO,
                                        &ls,
                                        medium,
                                        rng,
                                    );
                                    let tr = st.tr;
                                    if tr.max_element() > 0.0 {
                                        let w = if ls.delta || st.open {
                                            1.0
                                        } else {
                                            power_heuristic(ls.pdf, f)
                                        };
                                        result += spectral_mis(throughput, ratio)
                                            * tr
                                            * ls.weight
                                            * (f * w);
                                    }
                                }
                            }
                        }
                        let ps = med.phase.sample(p, ray.d, rng.next_2d());
                        prev = PreviousVertex {
                            p,
                            n: Vec3::ZERO,
                            pdf: ps.pdf,
                            unweighted: !med.sample_emitters,
                        };
                        ray = Ray::new(p, ps.d_out);
                        if !self.survives(depth, &mut throughput, ratio, eta, rng) {
                            break;
                        }
                        continue;
                    }
                }
                // Past every surface in an open medium (a channel without extinction): the
                // infinite lights are light sampling's alone there.
                if hit.is_none() || throughput.max_element() <= 0.0 {
                    break;
                }
            }

            // Emission found by the sampled direction, MIS-weighted against light sampling
            // from the previous scattering vertex.
            let Some(si) = hit else {
                if scene.has_environment() && !hidden {
                    let w = if prev.unweighted {
                        1.0
                    } else {
                        power_heuristic(prev.pdf, scene.pdf_li_environment(prev.p, prev.n, ray.d))
                    };
                    result += spectral_mis(throughput, ratio) * scene.environment(ray.d) * w;
                }
                break;
            };
            if si.light.is_some() && !hidden {
                let le = scene.emitted(&si, si.wo);
                if le != Rgb::ZERO {
                    let w = if prev.unweighted {
                        1.0
                    } else {
                        power_heuristic(prev.pdf, scene.pdf_li_surface(prev.p, prev.n, &si))
                    };
                    result += spectral_mis(throughput, ratio) * le * w;
                }
            }
            let bsdf = scene.bsdf(&si);
            let wo = si.to_local(si.wo);
            let sp = si.shading_point();
            let interface = scene.shape_info[si.shape as usize].media;

            // Light sampling from the surface (its shadow ray starts in the medium on the
            // side it leaves towards).
            let u_light = rng.next_f32();
            let u_light2 = rng.next_2d();
            if bsdf.has_non_delta() && depth + 1 < max_depth {
                if let Some(ls) = scene.sample_li(si.p, si.ng, u_light, u_light2) {
                    let wi = si.to_local(ls.wi);
                    let f = bsdf.eval(wo, wi, &sp, TransportMode::Radiance);
                    if f.max_element() > 0.0 {
                        let start = if interface.is_transition() {
                            interface.target(si.ng, ls.wi)
                        } else {
                            medium
                        };
                        let st = shadow_transmittance(scene, si.p, si.ng, &ls, start, rng);
                        let tr = st.tr;
                        if tr.max_element() > 0.0 {
                            let w = if ls.delta || st.open {
                                1.0
                            } else {
                                power_heuristic(ls.pdf, bsdf.pdf(wo, wi, &sp))
                            };
                            result += spectral_mis(throughput, ratio)
                                * f
                                * tr
                                * ls.weight
                                * (wi.z.abs() * w);
                        }
                    }
                }
            }

            // Continue by BSDF sampling.
            let u_lobe = rng.next_f32();
            let u_bsdf = rng.next_2d();
            let Some(bs) = bsdf.sample(wo, &sp, u_lobe, u_bsdf, TransportMode::Radiance) else {
                break;
            };
            let d = si.to_world(bs.wi);
            throughput *= bs.weight;
            eta *= bs.eta;
            if interface.is_transition() {
                medium = interface.target(si.ng, d);
            }
            ray = si.spawn_ray(d);
            if bs.passes_through(wo) {
                // A null interaction: not a bounce; the previous vertex stays for MIS.
                crossings += 1;
                if crossings > MAX_NULL_CROSSINGS || throughput.max_element() <= 0.0 {
                    break;
                }
                continue;
            }
            prev = PreviousVertex {
                p: si.p,
                n: si.ng,
                pdf: bs.pdf,
                unweighted: bs.delta,
            };
            depth += 1;
            if depth >= max_depth || !self.survives(depth, &mut throughput, ratio, eta, rng) {
                break;
            }
        }
        result
    }

    fn identity(&self) -> serde_json::Value {
        serde_json::json!({
            "integrator": "volpath",
            "max_depth": self.max_depth,
            "rr_depth": self.rr_depth,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::{Bsdf, Dielectric, Mask};
    use crate::description::{test_sphere_scene, EmitterDesc, Projection, SceneDescription};
    use crate::film::Film;
    use crate::parity::media::phase::{BlendPhase, TabulatedPhase};
    use crate::parity::media::{Medium, MediumInterface, PhaseFunction, VolumeTexture};
    use crate::texture::Texture;
    use crate::threads::with_threads;

    /// Mitsuba's `null` BSDF, as the importer builds it.
    fn null() -> Bsdf {
        Bsdf::Mask(Mask {
            opacity: Texture::Constant(Rgb::ZERO),
            nested: Box::new(Bsdf::Diffuse(crate::bsdf::Diffuse {
                reflectance: Texture::Constant(Rgb::ZERO),
            })),
        })
    }

    fn medium(sigma_t: Rgb, albedo: Rgb, phase: PhaseFunction) -> Medium {
        Medium::homogeneous(sigma_t, albedo, phase, "test")
    }

    /// The unit sphere of `test_sphere_scene` with boundary `bsdf`, filled with `inside`, in a
    /// constant environment of radiance 1.
    fn filled_sphere(bsdf: Bsdf, inside: Medium) -> SceneDescription {
        let mut desc = test_sphere_scene(bsdf, EmitterDesc::Constant { radiance: Rgb::ONE }, 8);
        desc.shapes[0].media = MediumInterface {
            interior: Some(0),
            exterior: None,
        };
        desc.media = vec![inside];
        desc
    }

    fn assert_every_pixel_is_one(film: &Film, what: &str) {
        for (i, p) in film.pixels.iter().enumerate() {
            assert!(
                (*p - Rgb::ONE).abs().max_element() < 0.05,
                "{what}: pixel {i}: {p:?}"
            );
        }
        let mean = film.mean();
        assert!(
            (mean - Rgb::ONE).abs().max_element() < 0.01,
            "{what}: mean {mean:?}"
        );
    }

    /// The white furnace with a medium: a lossless (albedo 1) medium behind a null surface in
    /// a constant environment of radiance 1 scatters light but neither absorbs nor adds any,
    /// so every pixel is 1 — with an extinction that differs fourfold between channels, a
    /// forward-scattering phase function, with and without light sampling in the medium, and
    /// behind a glass boundary (which is lossless too).
    #[test]
    fn white_furnace_with_scattering_media() {
        let sigma = Rgb::new(0.5, 1.0, 2.0);
        let hg = PhaseFunction::HenyeyGreenstein { g: 0.7 };
        // Back-scattering, with an interval of no mass.
        let table = PhaseFunction::Tabulated(std::sync::Arc::new(
            TabulatedPhase::new(vec![4.0, 1.0, 0.0, 0.0, 0.5]).unwrap(),
        ));
        let cases = [
            (
                "isotropic",
                null(),
                medium(sigma, Rgb::ONE, PhaseFunction::Isotropic),
            ),
            ("hg 0.7", null(), medium(sigma, Rgb::ONE, hg.clone())),
            (
                "no light sampling",
                null(),
                Medium {
                    sample_emitters: false,
                    ..medium(sigma, Rgb::ONE, hg.clone())
                },
            ),
            ("tabphase", null(), medium(sigma, Rgb::ONE, table.clone())),
            (
                "blendphase",
                null(),
                medium(
                    sigma,
                    Rgb::ONE,
                    PhaseFunction::Blend(std::sync::Arc::new(BlendPhase {
                        weight: VolumeTexture::Constant(Rgb::splat(0.4)),
                        nested: [table, hg],
                    })),
                ),
            ),
            (
                "glass boundary",
                Bsdf::Dielectric(Dielectric {
                    eta: 1.5,
                    specular_reflectance: Texture::Constant(Rgb::ONE),
                    specular_transmittance: Texture::Constant(Rgb::ONE),
                }),
                medium(Rgb::splat(1.5), Rgb::ONE, PhaseFunction::Isotropic),
            ),
        ];
        for (what, bsdf, inside) in cases {
            let scene = Scene::build(&filled_sphere(bsdf, inside)).unwrap();
            let film = VolPathTracer::default().render(&scene, 4096, 3, None);
            assert_every_pixel_is_one(&film, what);
        }
    }

    /// The furnace with a heterogeneous medium: a lossless grid (2×2×2 cells of extinctions
    /// between 0 and 4 that differ per channel, trilinear) over [−1, 1]³ inside the null unit
    /// sphere: delta tracking's null collisions and ratio tracking's shadow rays add up to 1.
    #[test]
    fn white_furnace_with_a_heterogeneous_medium() {
        use crate::parity::media::grid::{GridFilter, VolFile, VolumeGrid};
        use crate::parity::media::{Density, Heterogeneous, VolumeTexture};
        let data: Vec<f32> = (0..8)
            .flat_map(|i| {
                let v = i as f32 * 0.5;
                [v, 4.0 - v, (v * 1.7) % 4.0]
            })
            .collect();
        let grid = VolumeGrid::new(
            VolFile {
                res: glam::UVec3::splat(2),
                channels: 3,
                bbox: (glam::Vec3::ZERO, glam::Vec3::ONE),
                data,
            },
            glam::Mat4::from_translation(glam::Vec3::splat(-1.0))
                * glam::Mat4::from_scale(glam::Vec3::splat(2.0)),
            false,
            GridFilter::Trilinear,
            crate::texture::BitmapWrap::Clamp,
            "furnace".into(),
        )
        .unwrap();
        assert_eq!(grid.bounds, (glam::Vec3::splat(-1.0), glam::Vec3::ONE));
        let sigma_t = VolumeTexture::Grid(std::sync::Arc::new(grid));
        let inside = Medium {
            density: Density::Heterogeneous(Box::new(Heterogeneous::new(
                sigma_t,
                VolumeTexture::Constant(Rgb::ONE),
                1.0,
                Some((glam::Vec3::splat(-1.0), glam::Vec3::ONE)),
            ))),
            ..medium(
                Rgb::ONE,
                Rgb::ONE,
                PhaseFunction::HenyeyGreenstein { g: 0.4 },
            )
        };
        let scene = Scene::build(&filled_sphere(null(), inside)).unwrap();
        // Null collisions add noise: 16 384 samples keep every pixel's within the 5 %.
        let film = VolPathTracer::default().render(&scene, 16384, 8, None);
        assert_every_pixel_is_one(&film, "heterogeneous");
    }

    /// The furnace seen from inside the medium: the camera sits in the sphere (the scene's
    /// camera medium) and looks out through the fog.
    #[test]
    fn white_furnace_from_inside_the_medium() {
        let mut desc = filled_sphere(
            null(),
            medium(Rgb::new(0.8, 1.6, 0.4), Rgb::ONE, PhaseFunction::Isotropic),
        );
        desc.camera = crate::description::test_camera(
            glam::Vec3::new(0.2, -0.1, 0.3),
            glam::Vec3::new(1.0, 0.0, 2.0),
            60.0,
            8,
        );
        desc.camera_medium = Some(0);
        let scene = Scene::build(&desc).unwrap();
        let film = VolPathTracer::default().render(&scene, 4096, 5, None);
        assert_every_pixel_is_one(&film, "camera in the medium");
    }

    /// Pure absorption (albedo 0): looking through a chord of length ≈ 200 of a large sphere
    /// of absorbing medium (orthographic view of its centre, so every pixel's chord is within
    /// 0.003 % of 200) at a constant environment of radiance 1 shows exp(−σt·200) per
    /// channel, for an extinction that differs fivefold between channels.
    #[test]
    fn absorbing_medium_follows_beer_lambert() {
        let sigma = Rgb::new(0.002, 0.005, 0.01);
        let mut desc = filled_sphere(null(), medium(sigma, Rgb::ZERO, PhaseFunction::Isotropic));
        desc.shapes[0].geometry = crate::description::Geometry::Sphere {
            center: glam::Vec3::ZERO,
            radius: 100.0,
            rotation: glam::Mat3::IDENTITY,
            flip_normals: false,
        };
        desc.camera = crate::description::test_camera(
            glam::Vec3::new(0.0, 0.0, -300.0),
            glam::Vec3::ZERO,
            40.0,
            2,
        );
        desc.camera.projection = Projection::Orthographic;
        let scene = Scene::build(&desc).unwrap();
        // Each sample passes (estimate exp(−σt·200) / mean over channels) or is absorbed: a
        // pixel's relative standard deviation is √((1 − p)/(p·spp)) ≈ 0.5 % for p ≈ 0.39.
        let film = VolPathTracer::default().render(&scene, 65536, 9, None);
        let expected = (-sigma * 200.0).exp();
        for p in &film.pixels {
            assert!(
                ((*p - expected) / expected).abs().max_element() < 0.025,
                "{p:?} vs {expected:?}"
            );
        }
        let mean = film.mean();
        assert!(
            ((mean - expected) / expected).abs().max_element() < 0.01,
            "{mean:?} vs {expected:?}"
        );
    }

    /// `max_depth` counts scattering in the medium: at 1 only what the camera sees directly
    /// (the environment, dimmed by the medium) remains; the image brightens with every depth
    /// allowed, towards the furnace's 1.
    #[test]
    fn max_depth_counts_medium_vertices() {
        let scene = Scene::build(&filled_sphere(
            null(),
            medium(Rgb::splat(2.0), Rgb::ONE, PhaseFunction::Isotropic),
        ))
        .unwrap();
        let centre = |depth: i32| {
            let film = VolPathTracer {
                max_depth: depth,
                rr_depth: 5,
            }
            .render(&scene, 2048, 4, None);
            (film.get(3, 3) + film.get(4, 4) + film.get(3, 4) + film.get(4, 3)) * 0.25
        };
        // The central pixels' chords through the sphere are ≈ 2 long: exp(−4) ≈ 0.018 passes.
        let direct = centre(1);
        assert!(direct.max_element() < 0.03, "{direct:?}");
        let (two, four, unbounded) = (centre(2), centre(4), centre(-1));
        assert!(two.x > 2.0 * direct.x, "{two:?} vs {direct:?}");
        assert!(
            four.x > two.x && unbounded.x > four.x,
            "{two:?} {four:?} {unbounded:?}"
        );
        assert!((unbounded.x - 1.0).abs() < 0.05, "{unbounded:?}");
    }

    /// Infinite lights behind a haze that fills the scene (the camera's medium, no surface
    /// bounding it) shine through 2·max(R, |p − c|) of it, Mitsuba's convention: a diffuse wall
    /// (ρ = 0.5, 20 × 20, so R = 10√2) in a purely absorbing haze, seen head-on from 5 units
    /// away, shows ρ/π·E·exp(−σ·2R)·exp(−σ·5) under a sun of irradiance E along its normal,
    /// and ρ·L·exp(−σ·2R)·exp(−σ·5) under a sky of radiance L — which only light sampling can
    /// reach (sampled rays always end in the open haze), so its samples count in full.
    #[test]
    fn infinite_lights_shine_through_an_open_medium() {
        use crate::description::{Geometry, ShapeDesc, TriangleMesh};
        let sigma = 0.02f32;
        let wall = ShapeDesc {
            name: "wall".into(),
            geometry: Geometry::Mesh(TriangleMesh {
                positions: vec![
                    glam::Vec3::new(-10.0, -10.0, 0.0),
                    glam::Vec3::new(10.0, -10.0, 0.0),
                    glam::Vec3::new(10.0, 10.0, 0.0),
                    glam::Vec3::new(-10.0, 10.0, 0.0),
                ],
                normals: None,
                uvs: None,
                indices: vec![[0, 2, 1], [0, 3, 2]],
                flipped: false,
            }),
            bsdf: 0,
            emission: None,
            collimated: false,
            media: MediumInterface::default(),
        };
        let scene_with = |emitter: EmitterDesc| {
            let mut camera = crate::description::test_camera(
                glam::Vec3::new(0.0, 0.0, -5.0),
                glam::Vec3::ZERO,
                40.0,
                2,
            );
            camera.projection = Projection::Orthographic;
            let desc = SceneDescription {
                camera,
                sample_count: None,
                integrator: None,
                bsdfs: vec![Bsdf::Diffuse(crate::bsdf::Diffuse {
                    reflectance: Texture::Constant(Rgb::splat(0.5)),
                })],
                shapes: vec![wall.clone()],
                emitters: vec![emitter],
                warnings: vec![],
                media: vec![medium(
                    Rgb::splat(sigma),
                    Rgb::ZERO,
                    PhaseFunction::Isotropic,
                )],
                camera_medium: Some(0),
            };
            Scene::build(&desc).unwrap()
        };
        let radius = 10.0 * 2f32.sqrt() * (1.0 + 1e-4);
        let attenuation = (-sigma * (2.0 * radius + 5.0)).exp();
        let sun = scene_with(EmitterDesc::Directional {
            direction: glam::Vec3::Z,
            irradiance: Rgb::splat(2.0),
        });
        assert_eq!(sun.infinite_light_distance(glam::Vec3::ZERO), 2.0 * radius);
        let film = VolPathTracer::default().render(&sun, 16384, 1, None);
        let expected = 0.5 / std::f32::consts::PI * 2.0 * attenuation;
        let mean = film.mean();
        assert!(
            (mean - Rgb::splat(expected)).abs().max_element() < 0.02 * expected,
            "sun: {mean:?} vs {expected}"
        );
        let sky = scene_with(EmitterDesc::Constant {
            radiance: Rgb::splat(1.5),
        });
        let film = VolPathTracer::default().render(&sky, 16384, 2, None);
        let expected = 0.5 * 1.5 * attenuation;
        let mean = film.mean();
        assert!(
            (mean - Rgb::splat(expected)).abs().max_element() < 0.02 * expected,
            "sky: {mean:?} vs {expected}"
        );
    }

    #[test]
    fn images_are_bit_identical_for_one_and_two_threads() {
        let scene = Scene::build(&filled_sphere(
            null(),
            medium(
                Rgb::new(0.5, 1.0, 2.0),
                Rgb::splat(0.8),
                PhaseFunction::HenyeyGreenstein { g: -0.3 },
            ),
        ))
        .unwrap();
        let pt = VolPathTracer::default();
        let a = with_threads(1, || pt.render(&scene, 8, 42, None)).unwrap();
        let b = with_threads(2, || pt.render(&scene, 8, 42, None)).unwrap();
        assert!(a
            .pixels
            .iter()
            .zip(&b.pixels)
            .all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits)));
    }

    /// Without media, `volpath` renders what `path` renders (the same expectation): the
    /// furnace sphere of albedo 0.5 in a constant environment.
    #[test]
    fn without_media_it_agrees_with_the_path_tracer() {
        let desc = test_sphere_scene(
            Bsdf::Diffuse(crate::bsdf::Diffuse {
                reflectance: Texture::Constant(Rgb::splat(0.5)),
            }),
            EmitterDesc::Constant { radiance: Rgb::ONE },
            8,
        );
        let scene = Scene::build(&desc).unwrap();
        let ours = VolPathTracer::default().render(&scene, 2048, 1, None);
        let path = crate::integrators::path::PathTracer::default().render(&scene, 2048, 2, None);
        let (a, b) = (ours.mean(), path.mean());
        assert!(
            (a - b).abs().max_element() < 0.01 * b.max_element(),
            "{a:?} vs {b:?}"
        );
    }
}
