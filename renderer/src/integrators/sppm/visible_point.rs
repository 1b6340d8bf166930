//! SPPM eye subpaths: from the camera through delta and glossy bounces to the first diffuse or
//! rough surface, where a visible point is stored (docs/method.md §3.2).
//!
//! Along the way the path collects everything that is not a photon-density estimate: emission
//! seen directly or through delta bounces, direct light at glossy vertices (NEE + MIS with the
//! continuing BSDF sample), and direct light at the visible point itself (NEE + MIS, completed by
//! one BSDF-sampled ray that only looks for emitters; the photons hold the indirect part).
//! A diffuse surface with a delta part — the smooth coating of `plastic`, the pass-through of a
//! `mask`, a delta model in a `blendbsdf` — splits the path on one BSDF sample: the delta part
//! continues it, the diffuse part takes the visible point.

use crate::bsdf::{Bsdf, BsdfSample, Lobe, ShadingPoint, TransportMode};
use crate::frame::Frame;
use crate::math::Ray;
use crate::sampling::{power_heuristic, UniformSource, ONE_MINUS_EPSILON};
use crate::scene::{EmitterHit, Scene, SurfaceInteraction};
use crate::spectrum::Rgb;
use glam::Vec3;

use super::accumulate::GBufferSample;

/// Where an eye subpath stopped on a diffuse or rough surface.
#[derive(Debug, Clone, Copy)]
pub struct VisiblePoint {
    /// Position.
    pub p: Vec3,
    /// Geometric normal (as stored by the scene, not flipped towards the viewer).
    pub ng: Vec3,
    /// Shading frame.
    pub frame: Frame,
    /// Direction towards the viewer, world space.
    pub wo_world: Vec3,
    /// Direction towards the viewer, shading frame.
    pub wo: Vec3,
    /// Texture coordinates and local differential geometry (what the BSDF reads).
    pub sp: ShadingPoint,
    /// Index of the material in [`Scene::bsdfs`].
    pub material: u32,
    /// Path throughput β from the camera to this point.
    pub beta: Rgb,
    /// Whether the photons estimate only the broad part of the BSDF here (the eye path took
    /// the sharp part on; [`Bsdf::eval_split`]).
    pub broad_only: bool,
}

/// Which part of a BSDF the photons estimate at a visible point (see [`Bsdf::eval_split`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Part {
    /// The whole model.
    All,
    /// The broad lobes only (the eye path may follow the sharp ones instead).
    Broad,
    /// The sharp lobes only: the eye path follows them.
    Sharp,
}

/// Continues the eye path at `si` through the sharp part of its model along the (non-delta)
/// sample `bs` drawn for the MIS probe, chosen with probability `share`: the weight is
/// f_sharp·|cos θi| / (pdf·share). False when there is no sample or the path ends.
#[allow(clippy::too_many_arguments)]
fn follow_sharp(
    bsdf: &Bsdf,
    wo: Vec3,
    sp: &ShadingPoint,
    bs: Option<BsdfSample>,
    share: f32,
    si: &SurfaceInteraction,
    beta: &mut Rgb,
    last: &mut LastScatter,
    ray: &mut Ray,
) -> bool {
    let Some(bs) = bs.filter(|bs| !bs.delta) else {
        return false;
    };
    let sharp = bsdf.eval_split(wo, bs.wi, sp).1;
    let cont = BsdfSample {
        weight: sharp * (bs.wi.z.abs() / (bs.pdf * share)),
        ..bs
    };
    scatter(si, &cont, beta, last, ray)
}

/// How often an eye path follows the sharp part of a model with one: its sampling share,
/// kept inside [0.1, 0.9] so that neither part is starved (any value in (0, 1) is unbiased).
fn sharp_probability(share: f32) -> f32 {
    share.clamp(0.1, 0.9)
}

/// The part an eye path takes at a diffuse vertex and the probability of that choice: the
/// whole model (probability 1) without a sharp part, else the sharp part with probability `q`
/// and the broad one otherwise (one random number, drawn only then).
fn choose_part(sharp: Option<f32>, rng: &mut impl UniformSource) -> (Part, f32) {
    match sharp {
        None => (Part::All, 1.0),
        Some(q) if rng.next_f32() < q => (Part::Sharp, q),
        Some(q) => (Part::Broad, 1.0 - q),
    }
}

/// The result of one eye subpath.
#[derive(Debug, Clone, Copy, Default)]
pub struct EyePath {
    /// Radiance gathered without photons (emission, NEE), already multiplied by throughput.
    pub direct: Rgb,
    /// The visible point, if the path reached a diffuse or rough surface.
    pub vp: Option<VisiblePoint>,
    /// G-buffer features at the visible point (zeros without one).
    pub gbuffer: GBufferSample,
}

/// Emission-search state after a scattering event: how the last direction was sampled, for
/// MIS against light sampling.
#[derive(Clone, Copy)]
struct LastScatter {
    /// Position of the scattering vertex.
    p: Vec3,
    /// Its geometric normal (`Vec3::ZERO` for the camera), for the light selection's density.
    n: Vec3,
    /// Solid-angle density of the sampled direction (unused when `delta`).
    pdf: f32,
    /// The direction came from a delta lobe or from the camera: emission counts fully.
    delta: bool,
}

/// MIS weight of emission found by BSDF sampling (`pdf_light`: light sampling's density of the
/// same direction).
#[inline]
fn bsdf_mis(last: &LastScatter, pdf_light: impl FnOnce() -> f32) -> f32 {
    if last.delta {
        1.0
    } else {
        power_heuristic(last.pdf, pdf_light())
    }
}

/// Radiance from emitters found along `ray` (emitting surface or environment), MIS-weighted.
#[inline]
fn emission_along(
    scene: &Scene,
    ray: &Ray,
    hit: Option<&SurfaceInteraction>,
    last: &LastScatter,
) -> Rgb {
    match hit {
        Some(si) => {
            if si.light.is_none() {
                return Rgb::ZERO;
            }
            let le = scene.emitted(si, si.wo);
            if le == Rgb::ZERO {
                return le;
            }
            le * bsdf_mis(last, || scene.pdf_li_surface(last.p, last.n, si))
        }
        None => {
            if !scene.has_environment() {
                return Rgb::ZERO;
            }
            scene.environment(ray.d)
                * bsdf_mis(last, || scene.pdf_li_environment(last.p, last.n, ray.d))
        }
    }
}

/// Next-event estimation at `si`: the mean of `n` light samples, each MIS-weighted against
/// BSDF sampling, sample k drawing its light choice from the stratum [k/n, (k+1)/n) so that
/// with several lights the samples tend to pick different ones. Each keeps its weight against
/// the one BSDF probe (a light-sampled and a BSDF-sampled path's weights still sum to one), so
/// the mean has the single sample's expectation; `n` = 1 is the plain sample, its random
/// streams unchanged.
#[inline]
#[allow(clippy::too_many_arguments)]
fn direct_light(
    scene: &Scene,
    si: &SurfaceInteraction,
    sp: &ShadingPoint,
    bsdf: &Bsdf,
    wo: Vec3,
    rng: &mut impl UniformSource,
    n: u32,
) -> Rgb {
    let mut sample = |k: u32| {
        // For n = 1 this is ξ itself.
        let u_sel = ((k as f32 + rng.next_f32()) / n as f32).min(ONE_MINUS_EPSILON);
        let u = rng.next_2d();
        let Some(ls) = scene.sample_li(si.p, si.ng, u_sel, u) else {
            return Rgb::ZERO;
        };
        let wi = si.to_local(ls.wi);
        let f = bsdf.eval(wo, wi, sp, TransportMode::Radiance);
        if f.max_element() <= 0.0 || scene.light_occluded(si.p, si.ng, &ls) {
            return Rgb::ZERO;
        }
        let w = if ls.delta {
            1.0
        } else {
            power_heuristic(ls.pdf, bsdf.pdf(wo, wi, sp))
        };
        f * (wi.z.abs() * w) * ls.weight
    };
    if n == 1 {
        return sample(0);
    }
    (0..n).fold(Rgb::ZERO, |sum, k| sum + sample(k)) / n as f32
}

/// Emission found by the BSDF-sampled probe ray `bs` from `si` (the BSDF-sampling half of the
/// MIS pair at a visible point): it only looks for emitters.
fn probe_emission(scene: &Scene, si: &SurfaceInteraction, bs: &BsdfSample) -> Rgb {
    let probe = si.spawn_ray(si.to_world(bs.wi));
    let probe_last = LastScatter {
        p: si.p,
        n: si.ng,
        pdf: bs.pdf,
        delta: bs.delta,
    };
    match scene.intersect_emitter(&probe) {
        EmitterHit::Emitter(e) => emission_along(scene, &probe, Some(&e), &probe_last),
        EmitterHit::Escaped => emission_along(scene, &probe, None, &probe_last),
        EmitterHit::Blocked => Rgb::ZERO,
    }
}

/// The visible point at `si` with path throughput `beta`.
fn visible_point(
    si: &SurfaceInteraction,
    sp: &ShadingPoint,
    wo: Vec3,
    beta: Rgb,
    broad_only: bool,
) -> VisiblePoint {
    VisiblePoint {
        p: si.p,
        ng: si.ng,
        frame: si.frame,
        wo_world: si.wo,
        wo,
        sp: *sp,
        material: si.material,
        beta,
        broad_only,
    }
}

/// Traces one eye subpath starting with `ray`; `max_depth` bounds the number of delta/glossy
/// bounces before the path gives up without a visible point; `emitter_samples` light samples
/// estimate direct light at the visible point.
pub fn trace_eye_path<R: UniformSource>(
    scene: &Scene,
    mut ray: Ray,
    rng: &mut R,
    max_depth: u32,
    emitter_samples: u32,
) -> EyePath {
    let mut out = EyePath::default();
    let mut gbuffer_set = false;
    // Set when the path continues from a sharp split: the emission it meets next was already
    // counted by that vertex's NEE and MIS probe.
    let mut emission_counted = false;
    let mut beta = Rgb::ONE;
    let mut path_length = 0.0f32;
    let mut last = LastScatter {
        p: ray.o,
        n: Vec3::ZERO,
        pdf: 1.0,
        delta: true,
    };
    // Mitsuba's `hide_emitters`: what the camera sees directly — also through surfaces it
    // passes straight through (masks, thin glass) — is hidden: area emitters are seen through
    // and the environment is black; reflections of both stay.
    let hide_direct = scene.hide_emitters();
    let mut seen_directly = true;
    for depth in 0..=max_depth {
        let hidden = hide_direct && seen_directly;
        let hit = if hidden {
            scene.intersect_behind_emitters(&ray)
        } else {
            scene.intersect(&ray)
        };
        if !(std::mem::take(&mut emission_counted) || hidden) {
            out.direct += beta * emission_along(scene, &ray, hit.as_ref(), &last);
        }
        let Some(si) = hit else {
            break;
        };
        path_length += if depth == 0 {
            scene.camera.depth_of(si.p)
        } else {
            si.t
        };
        let bsdf = scene.bsdf(&si);
        let wo = si.to_local(si.wo);
        let sp = si.shading_point();
        let lobe = bsdf.lobe_for(wo);
        if lobe == Lobe::Diffuse {
            let p_delta = bsdf.delta_probability(wo, &sp);
            let gbuffer = GBufferSample {
                albedo: bsdf.albedo(&sp),
                normal: si.frame.to_world(bsdf.shading_normal(wo, &sp)),
                depth: path_length,
            };
            // The G-buffer describes the first diffuse surface, also when the path goes on
            // through its specular coating (below) — unless the surface passes most of the
            // light on (a mostly transparent `mask`): then what lies behind it.
            if !gbuffer_set && p_delta < 0.5 {
                out.gbuffer = gbuffer;
                gbuffer_set = true;
            }
            // A model with a glossy (sharp) lobe besides its broad ones: direct light is
            // estimated here for the whole model (NEE and the MIS probe), but of the indirect
            // light the photons estimate only the broad part: with probability q the eye path
            // follows the sharp part instead (see `Bsdf::eval_split`). The branch is drawn
            // only for such models, so every other scene keeps its random streams.
            let sharp = bsdf.sharp_share(wo, &sp).map(sharp_probability);
            // Next-event estimation at this visible point, scaled by the caller.
            let direct_here =
                |rng: &mut R| direct_light(scene, &si, &sp, bsdf, wo, rng, emitter_samples);
            // Direct light for the whole model, the MIS probe's sample `bs`, and the
            // throughput the visible point's photons get.
            let (bs, vp_beta) = if p_delta > 0.0 {
                // A diffuse surface with a delta part (the smooth coating of `plastic`, a
                // mask's pass-through, a delta model in a blend): the photons hold the
                // non-delta part only, so one BSDF sample splits the path. A delta sample (with
                // probability p_delta, its weight already divided by it) continues the path as
                // a specular bounce, finding what lies along it, emitters and lit surfaces
                // alike. Otherwise the visible point is stored here, with β/(1 − p_delta) for
                // NEE and the photons, and the sample serves as the MIS probe.
                let u_lobe = rng.next_f32();
                let u = rng.next_2d();
                let bs = bsdf.sample(wo, &sp, u_lobe, u, TransportMode::Radiance);
                if let Some(bs) = bs.filter(|bs| bs.delta) {
                    if depth == max_depth || !scatter(&si, &bs, &mut beta, &mut last, &mut ray) {
                        break;
                    }
                    seen_directly &= bs.passes_through(wo);
                    continue;
                }
                if p_delta >= 1.0 {
                    // No diffuse base to store (a black one): the failed sample ends the path.
                    break;
                }
                let vp_beta = beta / (1.0 - p_delta);
                out.direct += vp_beta * direct_here(rng);
                (bs, vp_beta)
            } else {
                out.direct += beta * direct_here(rng);
                // The BSDF-sampling half of the MIS pair: it only looks for emitters.
                let u_lobe = rng.next_f32();
                let u = rng.next_2d();
                (
                    bsdf.sample(wo, &sp, u_lobe, u, TransportMode::Radiance),
                    beta,
                )
            };
            if let Some(bs) = bs {
                out.direct += beta * bs.weight * probe_emission(scene, &si, &bs);
            }
            if !gbuffer_set {
                out.gbuffer = gbuffer;
                gbuffer_set = true;
            }
            let (part, share) = choose_part(sharp, rng);
            if part == Part::Sharp {
                if depth == max_depth
                    || !follow_sharp(
                        bsdf, wo, &sp, bs, share, &si, &mut beta, &mut last, &mut ray,
                    )
                {
                    break;
                }
                // A glossy bounce: what follows is a reflection, not seen directly.
                seen_directly = false;
                emission_counted = true;
                continue;
            }
            out.vp = Some(visible_point(
                &si,
                &sp,
                wo,
                vp_beta / share,
                part == Part::Broad,
            ));
            break;
        }
        if depth == max_depth {
            break;
        }
        if lobe == Lobe::Glossy {
            // One light sample at a glossy vertex on the way: the visible point's own samples
            // are where the photon-free part's noise was measured to sit.
            out.direct += beta * direct_light(scene, &si, &sp, bsdf, wo, rng, 1);
        }
        let u_lobe = rng.next_f32();
        let u = rng.next_2d();
        let Some(bs) = bsdf.sample(wo, &sp, u_lobe, u, TransportMode::Radiance) else {
            break;
        };
        if !scatter(&si, &bs, &mut beta, &mut last, &mut ray) {
            break;
        }
        seen_directly &= bs.passes_through(wo);
    }
    out
}

/// Continues an eye path at `si` with BSDF sample `bs`: throughput, MIS state and the next ray.
/// False when the throughput vanishes or stops being finite (the path ends).
fn scatter(
    si: &SurfaceInteraction,
    bs: &BsdfSample,
    beta: &mut Rgb,
    last: &mut LastScatter,
    ray: &mut Ray,
) -> bool {
    *beta *= bs.weight;
    if !beta.is_finite() || beta.max_element() <= 0.0 {
        return false;
    }
    *last = LastScatter {
        p: si.p,
        n: si.ng,
        pdf: bs.pdf,
        delta: bs.delta,
    };
    *ray = si.spawn_ray(si.to_world(bs.wi));
    true
}
