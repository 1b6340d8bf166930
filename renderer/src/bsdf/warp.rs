//! Sample warps used by the BSDFs (uniform square → disk / cosine-weighted hemisphere).

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_2, FRAC_PI_4};

/// Shirley–Chiu concentric map of the unit square onto the unit disk (low distortion).
pub fn square_to_uniform_disk_concentric(u: Vec2) -> Vec2 {
    let x = 2.0 * u.x - 1.0;
    let y = 2.0 * u.y - 1.0;
    if x == 0.0 && y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, phi) = if x * x > y * y {
        (x, FRAC_PI_4 * (y / x))
    } else {
        (y, FRAC_PI_2 - FRAC_PI_4 * (x / y))
    };
    let (s, c) = phi.sin_cos();
    Vec2::new(r * c, r * s)
}

/// Cosine-weighted direction on the +z hemisphere (density `cos θ / π`).
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let p = square_to_uniform_disk_concentric(u);
    let z = (1.0 - p.length_squared()).max(0.0).sqrt();
    Vec3::new(p.x, p.y, z)
}

/// Density of [`square_to_cosine_hemisphere`] (zero below the horizon).
#[inline]
pub fn square_to_cosine_hemisphere_pdf(v: Vec3) -> f32 {
    if v.z > 0.0 {
        v.z * FRAC_1_PI
    } else {
        0.0
    }
}
