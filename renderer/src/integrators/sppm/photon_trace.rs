//! The photon pass (docs/method.md §3.3): photons leave the lights by power, scatter with Russian
//! roulette, and are deposited at every diffuse/rough hit after at least one bounce (light
//! arriving directly from a light is next-event estimation's job) — from the first hit for a
//! collimated light (`directionalarea`), whose direct light NEE cannot sample.
//!
//! Photons are only stored where a visible point can exist (surfaces whose lobe class is
//! [`Lobe::Diffuse`]); deposits on glossy surfaces could never be gathered.

use crate::bsdf::{Lobe, TransportMode};
use crate::lights::PhotonFocus;
use crate::sampling::{rng_for, UniformSource};
use crate::scene::Scene;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

use super::photon_map::Photon;
use super::SppmSettings;

/// Photons traced per parallel work item (small enough that 2+ threads stay balanced); the
/// deposits of a chunk stay in photon order and chunks are read in order, so the photon list
/// does not depend on the thread count.
const CHUNK: u64 = 1024;

/// Bounce from which Russian roulette may end a photon path.
const RR_START: u32 = 3;

/// Domain-separation constant mixed into the seed of photon streams (pixels use the plain seed).
const PHOTON_STREAM: u64 = 0x7068_6f74_6f6e_7321;

/// Traces photon `index` of pass `pass`, appending its deposits to `out`; infinite lights'
/// photons start from `focus`'s mixture when given.
pub fn trace_photon(
    scene: &Scene,
    seed: u64,
    pass: u64,
    index: u64,
    max_depth: u32,
    focus: Option<&PhotonFocus>,
    out: &mut Vec<Photon>,
) {
    let mut rng = rng_for(seed ^ PHOTON_STREAM, pass, index);
    let u_sel = rng.next_f32();
    let u_pos = rng.next_2d();
    let u_dir = rng.next_2d();
    let Some(emission) = scene.sample_emission(u_sel, u_pos, u_dir, focus) else {
        return;
    };
    // A collimated light's (`directionalarea`) direct light is no NEE's: its photons are
    // deposited from their first hit.
    let first_deposit = u32::from(!scene.lights[emission.light as usize].is_collimated());
    let mut ray = emission.ray;
    let mut flux = emission.flux;
    for bounce in 0..max_depth {
        let Some(si) = scene.intersect(&ray) else {
            break;
        };
        let bsdf = scene.bsdf(&si);
        let wo = si.to_local(si.wo);
        if bounce >= first_deposit && bsdf.lobe_for(wo) == Lobe::Diffuse {
            out.push(Photon {
                position: si.p,
                wi: si.wo,
                normal: si.ng,
                flux,
            });
        }
        let u_lobe = rng.next_f32();
        let u = rng.next_2d();
        let Some(bs) = bsdf.sample(
            wo,
            &si.shading_point(),
            u_lobe,
            u,
            TransportMode::Importance,
        ) else {
            break;
        };
        let new_flux = flux * bs.weight;
        if bounce + 1 >= RR_START {
            // Survive with the probability of the throughput change, so surviving photons keep
            // roughly constant flux.
            let q = (new_flux.max_element() / flux.max_element()).min(0.95);
            if q.is_nan() || q <= 0.0 || rng.next_f32() >= q {
                break;
            }
            flux = new_flux / q;
        } else {
            flux = new_flux;
        }
        if !flux.is_finite() || flux.max_element() <= 0.0 {
            break;
        }
        ray = si.spawn_ray(si.to_world(bs.wi));
    }
}

/// Memory a stored photon takes during a pass: its record in the trace chunks, and in the
/// grid its sorted copy, position arrays and sort keys (with scratch).
pub const BYTES_PER_STORED_PHOTON: u64 = 2 * std::mem::size_of::<Photon>() as u64 + 12 + 32;

/// Memory of the per-chunk deposit lists a pass of `count` photons keeps (one list header per
/// [`CHUNK`] photons, before any deposit): what an absurd photon count asks for up front.
pub fn chunk_list_bytes(count: u64) -> u64 {
    count
        .div_ceil(CHUNK)
        .saturating_mul(std::mem::size_of::<Vec<Photon>>() as u64)
}

/// Traces `settings.photons_per_pass` photons of pass `pass` in parallel (current rayon pool)
/// into `chunks`, infinite lights' photons from `focus`'s mixture when given:
/// chunk `c` receives the deposits of photons `c·CHUNK..(c+1)·CHUNK` in photon order, so the
/// concatenation of the chunks is the deposit list in photon-index order whatever the thread
/// count. The chunks' allocations are reused from the previous pass. More than `max_stored`
/// deposits (what memory allows) stop the pass with an error instead of exhausting memory.
pub fn trace_photons(
    scene: &Scene,
    settings: &SppmSettings,
    pass: u64,
    focus: Option<&PhotonFocus>,
    max_stored: u64,
    chunks: &mut Vec<Vec<Photon>>,
) -> anyhow::Result<()> {
    let (seed, count, max_depth) = (settings.seed, settings.photons_per_pass, settings.max_depth);
    let n = count.div_ceil(CHUNK) as usize;
    chunks.truncate(n);
    chunks.resize_with(n, Vec::new);
    let stored = AtomicU64::new(0);
    chunks.par_iter_mut().enumerate().for_each(|(c, out)| {
        out.clear();
        if stored.load(Ordering::Relaxed) > max_stored {
            return;
        }
        let c = c as u64;
        for index in c * CHUNK..((c + 1) * CHUNK).min(count) {
            trace_photon(scene, seed, pass, index, max_depth, focus, out);
        }
        stored.fetch_add(out.len() as u64, Ordering::Relaxed);
    });
    let stored = stored.into_inner();
    if stored > max_stored {
        anyhow::bail!(
            "pass {pass}: {count} photons stored more than {max_stored} deposits, more than the \
             available memory holds ({} bytes per deposit); use fewer photons per pass",
            BYTES_PER_STORED_PHOTON
        );
    }
    Ok(())
}
