//! Geometric helpers shared by the renderer core: rays, orthonormal bases, robust ray spawning.

use glam::{Vec2, Vec3};

/// Relative offset used when spawning rays off a surface (Mitsuba's `RayEpsilon`, ≈ 1500 ulp).
pub const RAY_EPSILON: f32 = f32::EPSILON * 1500.0;
/// Shortening of shadow rays towards their target (Mitsuba's `ShadowEpsilon`).
pub const SHADOW_EPSILON: f32 = RAY_EPSILON * 10.0;

/// A ray `o + t·d` with `t` in `[tmin, tmax]`; `d` is unit length for camera and scattering rays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Origin.
    pub o: Vec3,
    /// Direction.
    pub d: Vec3,
    /// Smallest accepted hit distance.
    pub tmin: f32,
    /// Largest accepted hit distance.
    pub tmax: f32,
}

impl Ray {
    /// A ray with an unbounded far end.
    #[inline]
    pub fn new(o: Vec3, d: Vec3) -> Self {
        Ray {
            o,
            d,
            tmin: 0.0,
            tmax: f32::INFINITY,
        }
    }

    /// The point at distance `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }
}

/// Moves `p` off the surface with geometric normal `n`, to the side `d` points to, by an amount
/// relative to the magnitude of `p` (floating-point error grows with it), as Mitsuba does.
#[inline]
pub fn offset_point(p: Vec3, n: Vec3, d: Vec3) -> Vec3 {
    let mag = (1.0 + p.abs().max_element()) * RAY_EPSILON;
    let mag = if n.dot(d) >= 0.0 { mag } else { -mag };
    p + n * mag
}

/// A ray leaving the surface point `p` (geometric normal `n`) in direction `d`.
#[inline]
pub fn spawn_ray(p: Vec3, n: Vec3, d: Vec3) -> Ray {
    Ray::new(offset_point(p, n, d), d)
}

/// A ray leaving surface point `p` (geometric normal `n`) towards point `target`, ending just
/// short of it (for shadow tests).
#[inline]
pub fn spawn_ray_to(p: Vec3, n: Vec3, target: Vec3) -> Ray {
    let o = offset_point(p, n, target - p);
    let d = target - o;
    let dist = d.length();
    Ray {
        o,
        d: d / dist,
        tmin: 0.0,
        tmax: dist * (1.0 - SHADOW_EPSILON),
    }
}

/// Two unit vectors completing the unit vector `n` to a right-handed orthonormal basis
/// (Duff et al. 2017, branchless).
#[inline]
pub fn coordinate_system(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// `x²`.
#[inline]
pub fn sqr(x: f32) -> f32 {
    x * x
}

/// `sqrt(max(x, 0))`: square root that tolerates tiny negative rounding errors.
#[inline]
pub fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}

/// Spherical direction (θ from +z, φ from +x) of a unit vector, as texture coordinates in [0,1]².
#[inline]
pub fn direction_to_spherical_uv(d: Vec3) -> Vec2 {
    let theta = d.z.clamp(-1.0, 1.0).acos();
    let mut phi = d.y.atan2(d.x);
    if phi < 0.0 {
        phi += 2.0 * std::f32::consts::PI;
    }
    Vec2::new(
        phi * 0.5 * std::f32::consts::FRAC_1_PI,
        theta * std::f32::consts::FRAC_1_PI,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinate_system_is_orthonormal() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
        ] {
            let (s, t) = coordinate_system(n);
            assert!((s.length() - 1.0).abs() < 1e-5);
            assert!((t.length() - 1.0).abs() < 1e-5);
            assert!(s.dot(t).abs() < 1e-5 && s.dot(n).abs() < 1e-5 && t.dot(n).abs() < 1e-5);
            assert!((s.cross(t) - n).length() < 1e-5, "right-handed");
        }
    }

    #[test]
    fn spawn_ray_to_stops_short_of_target() {
        let r = spawn_ray_to(Vec3::ZERO, Vec3::Z, Vec3::new(0.0, 0.0, 2.0));
        assert!(r.o.z > 0.0);
        assert!(r.tmax < 2.0 && r.tmax > 1.99);
    }
}
