//! Photon gathering at a visible point (docs/method.md §3.5): one range query at the largest
//! radius of the levels the point feeds, each photon added to every level whose radius covers
//! it, with photons from the other side of the surface or from differently oriented surfaces
//! rejected. Under the CPPM schedule the levels' radii are tested one by one (they need not
//! be nested) and the contributing photons are counted into each level's cells.

use crate::bsdf::Bsdf;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use crate::texture::TexPoint;
use glam::Vec3;
use std::f32::consts::{FRAC_1_PI, PI};

use super::cppm::{cell_index, CppmLevel};
use super::photon_map::{Photon, PhotonGrid};
use super::visible_point::VisiblePoint;

/// Minimum cosine between a photon's surface normal and the visible point's geometric normal.
/// Photons on surfaces meeting the visible point's at more than 60° (corners, the other face
/// of a thin wall) are rejected: they belong to a different surface (Mitsuba's SPPM accepts
/// them and leaks light around corners and through thin walls).
pub const NORMAL_AGREEMENT_COS: f32 = 0.5;

/// Whether a BSDF transmits light through the surface with a non-delta lobe: then photons on
/// the other side of the surface contribute legitimately. (No wildcard arm: a new model must
/// say whether it transmits.)
fn transmits(bsdf: &Bsdf) -> bool {
    match bsdf {
        Bsdf::RoughDielectric(_) => true,
        Bsdf::Principled(b) => b.transmits(),
        Bsdf::PrincipledThin(b) => b.transmits(),
        Bsdf::Diffuse(_)
        | Bsdf::Conductor(_)
        | Bsdf::RoughConductor(_)
        | Bsdf::Plastic(_)
        | Bsdf::RoughPlastic(_)
        // Smooth dielectrics transmit by a delta only: no photon density on them.
        | Bsdf::Dielectric(_)
        | Bsdf::ThinDielectric(_) => false,
        Bsdf::TwoSided { front, back } => transmits(front) || transmits(back),
        Bsdf::NormalMap(b) => transmits(&b.nested),
        Bsdf::BumpMap(b) => transmits(&b.nested),
        Bsdf::Blend(b) => b.nested.iter().any(transmits),
        // The pass-through is a delta: photons beyond it are not this surface's.
        Bsdf::Mask(b) => transmits(&b.nested),
    }
}

/// The visible point's BSDF when it is Lambertian on the viewer's side: a photon arriving from
/// direction `wi` (shading frame) contributes `f` when `side · wi.z > 0` and nothing otherwise,
/// so the gather can sum fluxes and apply `f` once. `None` for any other BSDF.
fn lambertian(bsdf: &Bsdf, wo: Vec3, tex: TexPoint) -> Option<(Rgb, f32)> {
    // Mirrors `Diffuse::eval` (ρ/π on the upper hemisphere, both directions above the surface)
    // and `Bsdf::TwoSided` (the back model with both directions flipped).
    let diffuse = |b: &Bsdf| match b {
        Bsdf::Diffuse(d) => Some(d.reflectance.eval(tex) * FRAC_1_PI),
        _ => None,
    };
    match bsdf {
        Bsdf::Diffuse(_) if wo.z > 0.0 => Some((diffuse(bsdf)?, 1.0)),
        Bsdf::Diffuse(_) => Some((Rgb::ZERO, 1.0)),
        Bsdf::TwoSided { front, .. } if wo.z > 0.0 => Some((diffuse(front)?, 1.0)),
        Bsdf::TwoSided { back, .. } if wo.z < 0.0 => Some((diffuse(back)?, -1.0)),
        Bsdf::TwoSided { .. } => Some((Rgb::ZERO, 1.0)),
        _ => None,
    }
}

/// Adds the photon-density estimates of the visible point for the nested `radii` (ascending)
/// to `out[ℓ]`: β·Σ f(wo, wp)·Φp / (n_photons·π·r_ℓ²). One query at the largest radius.
pub fn gather(
    scene: &Scene,
    grid: &PhotonGrid,
    vp: &VisiblePoint,
    radii: &[f32],
    n_photons: u64,
    out: &mut [Rgb],
) {
    debug_assert_eq!(radii.len(), out.len());
    let Some(&r_max) = radii.last() else {
        return;
    };
    let r2: [f32; 8] = std::array::from_fn(|l| radii.get(l).map_or(0.0, |r| r * r));
    let levels = radii.len();
    let mut sums = [Rgb::ZERO; 8];
    let factor = for_each_accepted(scene, grid, vp, r_max, |_, d2, weight| {
        // Radii ascend: the covering levels are a suffix of the list.
        for (sum, r2) in sums.iter_mut().zip(&r2).take(levels).rev() {
            if d2 > *r2 {
                break;
            }
            *sum += weight;
        }
    });
    add_estimates(vp, factor, &sums, &r2, n_photons, out);
}

/// [`gather`] for levels whose radii follow CPPM (`levels[ℓ].r2`, in any order: the
/// data-driven shrinks need not keep them nested), which also counts every photon that
/// contributes into the covering levels' cells ([`CppmLevel::count`]). One query at the
/// largest radius; each level tests its own.
pub fn gather_counting(
    scene: &Scene,
    grid: &PhotonGrid,
    vp: &VisiblePoint,
    levels: &mut [CppmLevel],
    n_photons: u64,
    out: &mut [Rgb],
) {
    debug_assert_eq!(levels.len(), out.len());
    let r2: [f32; 8] = std::array::from_fn(|l| levels.get(l).map_or(0.0, |level| level.r2));
    let r2_max = r2.iter().fold(0.0f32, |m, &r2| m.max(r2));
    if r2_max <= 0.0 {
        return;
    }
    let mut sums = [Rgb::ZERO; 8];
    let factor = for_each_accepted(scene, grid, vp, r2_max.sqrt(), |photon, d2, weight| {
        let d = photon.position - vp.p;
        for ((sum, level), r2) in sums.iter_mut().zip(levels.iter_mut()).zip(&r2) {
            if d2 <= *r2 {
                *sum += weight;
                level.count(cell_index(d, d2, &vp.frame, *r2));
            }
        }
    });
    add_estimates(vp, factor, &sums, &r2, n_photons, out);
}

/// out[ℓ] += β·factor·sums[ℓ] / (n_photons·π·r2[ℓ]) for the levels with a radius.
fn add_estimates(
    vp: &VisiblePoint,
    factor: Rgb,
    sums: &[Rgb],
    r2: &[f32],
    n_photons: u64,
    out: &mut [Rgb],
) {
    for ((o, sum), r2) in out.iter_mut().zip(sums).zip(r2) {
        if *r2 > 0.0 {
            *o += vp.beta * (factor * *sum) / (n_photons as f32 * PI * r2);
        }
    }
}

/// Calls `add(photon, d², weight)` for every photon within `r_max` of the visible point that
/// contributes to its estimate — same surface, right side, non-zero BSDF value — in the grid's
/// visiting order, and returns the factor the weights' sum is to be multiplied by: the
/// Lambertian f when the weights are bare fluxes (f is one constant there), else one (the
/// weights are f·Φ).
fn for_each_accepted(
    scene: &Scene,
    grid: &PhotonGrid,
    vp: &VisiblePoint,
    r_max: f32,
    mut add: impl FnMut(&Photon, f32, Rgb),
) -> Rgb {
    let bsdf = &scene.bsdfs[vp.material as usize];
    let allow_other_side = transmits(bsdf);
    let viewer_side = vp.wo_world.dot(vp.ng) > 0.0;
    let same_surface = |photon: &Photon| {
        photon.normal.dot(vp.ng) >= NORMAL_AGREEMENT_COS
            && (allow_other_side || (photon.wi.dot(vp.ng) > 0.0) == viewer_side)
    };
    // The common case, a Lambertian surface: f is one constant on one hemisphere, so sum the
    // fluxes and multiply by f at the end (no BSDF evaluation per photon).
    // (A Lambertian model has no sharp part, so `broad_only` never applies to it.)
    match lambertian(bsdf, vp.wo, vp.sp.tex) {
        Some((f, side)) => {
            if f != Rgb::ZERO {
                let n = vp.frame.n;
                grid.for_each_within(vp.p, r_max, |photon, d2| {
                    if same_surface(photon) && side * photon.wi.dot(n) > 0.0 {
                        add(photon, d2, photon.flux);
                    }
                });
            }
            f
        }
        None => {
            // The side and the tilted frame, which do not depend on the photon: once.
            let point = bsdf.at_point(vp.wo, &vp.sp);
            grid.for_each_within(vp.p, r_max, |photon, d2| {
                if !same_surface(photon) {
                    return;
                }
                let wi = vp.frame.to_local(photon.wi);
                let f = if vp.broad_only {
                    point.eval_split(wi).0
                } else {
                    point.eval(wi)
                };
                if f != Rgb::ZERO {
                    add(photon, d2, f * photon.flux);
                }
            });
            Rgb::ONE
        }
    }
}
