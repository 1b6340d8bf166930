//! Light transport algorithms: each integrator turns a scene into images.

pub mod path;
pub mod ray_integrator;
pub mod sppm;

pub use ray_integrator::RayIntegrator;

use crate::sampling::{Pcg32, UniformSource};

/// Russian roulette after the scattering vertex at `depth`, Mitsuba's rule: from `rr_depth` on
/// the path survives with probability min(`weight_max`·η², 0.95). `None` when the path ends
/// (also when its weight is zero or NaN), else the factor to divide the throughput by (1 before
/// `rr_depth`).
#[inline(always)]
pub(crate) fn russian_roulette(
    depth: u32,
    rr_depth: u32,
    weight_max: f32,
    eta: f32,
    rng: &mut Pcg32,
) -> Option<f32> {
    let q = if depth >= rr_depth {
        let q = (weight_max * eta * eta).min(0.95);
        if rng.next_f32() >= q {
            return None;
        }
        q
    } else {
        1.0
    };
    (weight_max > 0.0 && !weight_max.is_nan()).then_some(q)
}
