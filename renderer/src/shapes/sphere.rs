//! Analytic sphere (Mitsuba's `sphere`): exact ray intersection, spherical uvs, area sampling.

use super::{AreaSample, HitGeometry};
use crate::math::{coordinate_system, direction_to_spherical_uv, Ray};
use crate::sampling::square_to_uniform_sphere;
use glam::{Mat3, Vec2, Vec3, Vec3A};
use std::f32::consts::PI;

/// A sphere in world space.
#[derive(Debug, Clone, Copy)]
pub struct Sphere {
    /// Centre.
    pub center: Vec3,
    /// Radius.
    pub radius: f32,
    /// Normals point inwards.
    pub flip_normals: bool,
    /// Object-to-world rotation (orthogonal). Only the uv parameterisation and the tangent
    /// depend on it: Mitsuba computes a sphere's uvs in its rotated object frame.
    pub rotation: Mat3,
    /// World-to-object rotation (the transpose of `rotation`).
    pub to_local: Mat3,
}

impl Sphere {
    /// A sphere from centre, radius and orientation.
    pub fn new(center: Vec3, radius: f32, flip_normals: bool) -> Self {
        Sphere {
            center,
            radius: radius.abs(),
            flip_normals,
            rotation: Mat3::IDENTITY,
            to_local: Mat3::IDENTITY,
        }
    }

    /// The same sphere with an object frame rotated by `rotation` (orthogonal, object to world).
    pub fn with_rotation(self, rotation: Mat3) -> Self {
        Sphere {
            rotation,
            to_local: rotation.transpose(),
            ..self
        }
    }

    /// Bounding box.
    pub fn bounds(&self) -> (Vec3A, Vec3A) {
        let c = Vec3A::from(self.center);
        (c - Vec3A::splat(self.radius), c + Vec3A::splat(self.radius))
    }

    /// Surface area 4πr².
    pub fn area(&self) -> f32 {
        4.0 * PI * self.radius * self.radius
    }

    /// Nearest hit distance in (tmin, tmax), or +∞. Solved relative to the centre, with the
    /// numerically stable quadratic form, in f64 (cheap here and avoids grazing-angle misses).
    #[inline]
    pub fn intersect(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> f32 {
        let oc = (o - Vec3A::from(self.center)).as_dvec3();
        let d = d.as_dvec3();
        let a = d.length_squared();
        let b = 2.0 * oc.dot(d);
        let r = self.radius as f64;
        let c = oc.length_squared() - r * r;
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            return f32::INFINITY;
        }
        let sq = disc.sqrt();
        let q = if b < 0.0 {
            -0.5 * (b - sq)
        } else {
            -0.5 * (b + sq)
        };
        let (mut t0, mut t1) = (q / a, c / q);
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        let (t0, t1) = (t0 as f32, t1 as f32);
        if t0 > tmin && t0 < tmax {
            t0
        } else if t1 > tmin && t1 < tmax {
            t1
        } else {
            f32::INFINITY
        }
    }

    fn outward(&self, p: Vec3) -> Vec3 {
        (p - self.center).normalize_or(Vec3::Z)
    }

    /// Shading data at the hit of `ray` at distance `t`.
    pub fn hit_geometry(&self, ray: &Ray, t: f32) -> HitGeometry {
        let dir = self.outward(ray.at(t));
        // Reproject onto the surface to remove the error of o + t·d.
        let p = self.center + dir * self.radius;
        let n = if self.flip_normals { -dir } else { dir };
        // uv and ∂p/∂u in the object frame (Mitsuba: φ about local z, θ from local +z).
        let local = self.to_local * dir;
        let uv = direction_to_spherical_uv(local);
        // Mitsuba's (φ/2π, θ/π) parameterisation: ∂p/∂u = 2π·r·(−y, x, 0) and
        // ∂p/∂v = π·r·(z cos φ, z sin φ, −sin θ) in the object frame; at the poles ∂p/∂u
        // vanishes and the tangent falls back to an arbitrary one.
        let rd = (local.x * local.x + local.y * local.y).sqrt();
        let dpdu = self.rotation * Vec3::new(-local.y, local.x, 0.0);
        let (dpdu, dpdv) = if rd > 1e-6 {
            let dpdv = Vec3::new(local.z * local.x / rd, local.z * local.y / rd, -rd);
            (
                dpdu * (2.0 * PI * self.radius),
                self.rotation * dpdv * (PI * self.radius),
            )
        } else {
            let (s, t) = coordinate_system(n);
            (s, t)
        };
        HitGeometry {
            p,
            ng: n,
            ns: n,
            dpdu,
            dpdv,
            uv,
            bary: Vec2::ZERO,
        }
    }

    /// Texture coordinates of the surface point nearest `p` (the uvs of [`Sphere::hit_geometry`]).
    pub fn uv_at(&self, p: Vec3) -> Vec2 {
        direction_to_spherical_uv(self.to_local * self.outward(p))
    }

    /// A point uniformly distributed over the sphere.
    pub fn sample_area(&self, u: Vec2) -> AreaSample {
        let local = square_to_uniform_sphere(u);
        let dir = self.rotation * local;
        let n = if self.flip_normals { -dir } else { dir };
        AreaSample {
            p: self.center + dir * self.radius,
            n,
            uv: direction_to_spherical_uv(local),
            prim: 0,
            bary: Vec2::ZERO,
            pdf: 1.0 / self.area(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_sphere_from_outside_and_inside() {
        let s = Sphere::new(Vec3::new(0.0, 0.0, 5.0), 1.0, false);
        let t = s.intersect(Vec3A::ZERO, Vec3A::Z, 0.0, f32::INFINITY);
        assert!((t - 4.0).abs() < 1e-5);
        let t = s.intersect(Vec3A::new(0.0, 0.0, 5.0), Vec3A::Z, 0.0, f32::INFINITY);
        assert!((t - 1.0).abs() < 1e-5);
        assert!(s
            .intersect(Vec3A::ZERO, Vec3A::X, 0.0, f32::INFINITY)
            .is_infinite());
        let g = s.hit_geometry(&Ray::new(Vec3::ZERO, Vec3::Z), 4.0);
        assert!((g.ng + Vec3::Z).length() < 1e-5);
    }

    /// Mitsuba computes uvs in the sphere's rotated object frame: with the object frame rotated
    /// 90° about x (local +z → world −y, local +y → world +z), the world point on +z lies at
    /// local +y: φ = π/2 → u = 1/4, θ = π/2 → v = 1/2; the world bottom (−y) is the local pole
    /// θ = 0 → v = 0. Unrotated, the same world point would have v = 0 instead.
    #[test]
    fn uv_is_computed_in_the_rotated_object_frame() {
        let rot = Mat3::from_rotation_x(std::f32::consts::FRAC_PI_2);
        let s = Sphere::new(Vec3::ZERO, 2.0, false).with_rotation(rot);
        let g = s.hit_geometry(&Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z), 3.0);
        assert!((g.p - Vec3::new(0.0, 0.0, 2.0)).length() < 1e-5);
        assert!((g.uv - Vec2::new(0.25, 0.5)).length() < 1e-5, "{:?}", g.uv);
        let g = s.hit_geometry(&Ray::new(Vec3::new(0.0, -5.0, 0.0), Vec3::Y), 3.0);
        assert!(g.uv.y.abs() < 1e-5, "{:?}", g.uv);
        // ∂p/∂u is tangent: perpendicular to the normal.
        assert!(g.dpdu.dot(g.ng).abs() < 1e-5);
        let plain = Sphere::new(Vec3::ZERO, 2.0, false);
        let g = plain.hit_geometry(&Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z), 3.0);
        assert!(g.uv.y.abs() < 1e-5, "{:?}", g.uv);
        // Area samples: the point and the uv agree with the hit geometry of the same point.
        let a = s.sample_area(Vec2::new(0.3, 0.7));
        let dir = a.p / 2.0;
        let g = s.hit_geometry(&Ray::new(dir * 5.0, -dir), 3.0);
        assert!((g.p - a.p).length() < 1e-4 && (g.uv - a.uv).length() < 1e-4);
    }
}
