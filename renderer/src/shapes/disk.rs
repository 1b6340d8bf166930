//! Analytic disk (Mitsuba's `disk`): the unit disk in local z = 0 mapped by an affine transform.

use super::{AreaSample, HitGeometry};
use crate::math::Ray;
use crate::sampling::square_to_uniform_disk_concentric;
use glam::{Mat4, Vec2, Vec3, Vec3A};
use std::f32::consts::PI;

/// A (possibly elliptical) disk in world space.
#[derive(Debug, Clone, Copy)]
pub struct Disk {
    /// Object-to-world.
    to_world: Mat4,
    /// World-to-object.
    to_local: Mat4,
    /// Unit world normal of the front side.
    normal: Vec3,
    /// World area.
    area: f32,
}

impl Disk {
    /// A disk from its object-to-world transform.
    pub fn new(to_world: Mat4, flip_normals: bool) -> Self {
        let a = to_world.transform_vector3(Vec3::X);
        let b = to_world.transform_vector3(Vec3::Y);
        let n = to_world
            .inverse()
            .transpose()
            .transform_vector3(Vec3::Z)
            .normalize_or(Vec3::Z);
        Disk {
            to_world,
            to_local: to_world.inverse(),
            normal: if flip_normals { -n } else { n },
            area: PI * a.cross(b).length(),
        }
    }

    /// Bounding box of the ellipse.
    pub fn bounds(&self) -> (Vec3A, Vec3A) {
        let c = self.to_world.transform_point3(Vec3::ZERO);
        let a = self.to_world.transform_vector3(Vec3::X);
        let b = self.to_world.transform_vector3(Vec3::Y);
        let ext = Vec3::new(a.x.hypot(b.x), a.y.hypot(b.y), a.z.hypot(b.z));
        (Vec3A::from(c - ext), Vec3A::from(c + ext))
    }

    /// Unit normal of the front side.
    pub fn normal(&self) -> Vec3 {
        self.normal
    }

    /// Area.
    pub fn area(&self) -> f32 {
        self.area
    }

    /// Hit distance in (tmin, tmax), or +∞.
    #[inline]
    pub fn intersect(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> f32 {
        let lo = self.to_local.transform_point3(Vec3::from(o));
        let ld = self.to_local.transform_vector3(Vec3::from(d));
        if ld.z == 0.0 {
            return f32::INFINITY;
        }
        let t = -lo.z / ld.z;
        if !(t > tmin && t < tmax) {
            return f32::INFINITY;
        }
        let q = lo + ld * t;
        if q.x * q.x + q.y * q.y <= 1.0 {
            t
        } else {
            f32::INFINITY
        }
    }

    fn local_uv(q: Vec3) -> Vec2 {
        let r = (q.x * q.x + q.y * q.y).sqrt();
        let mut phi = q.y.atan2(q.x);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        Vec2::new(r, phi / (2.0 * PI))
    }

    /// Shading data at the hit of `ray` at distance `t`.
    pub fn hit_geometry(&self, ray: &Ray, t: f32) -> HitGeometry {
        let mut q = self.to_local.transform_point3(ray.at(t));
        q.z = 0.0;
        let p = self.to_world.transform_point3(q);
        // Mitsuba's polar parameterisation (u = r, v = φ/2π): ∂p/∂u is radial, so the shading
        // tangent (anisotropy, normal maps) turns with φ as in Mitsuba; zero at the centre.
        let r = (q.x * q.x + q.y * q.y).sqrt();
        let (cos_phi, sin_phi) = if r > 0.0 {
            (q.x / r, q.y / r)
        } else {
            (0.0, 0.0)
        };
        let dpdu = self
            .to_world
            .transform_vector3(Vec3::new(cos_phi, sin_phi, 0.0));
        let dpdv = self
            .to_world
            .transform_vector3(Vec3::new(-sin_phi, cos_phi, 0.0) * (2.0 * PI * r));
        HitGeometry {
            p,
            ng: self.normal,
            ns: self.normal,
            dpdu,
            dpdv,
            uv: Self::local_uv(q),
            bary: Vec2::ZERO,
        }
    }

    /// A point uniformly distributed over the disk (an affine map keeps uniformity).
    pub fn sample_area(&self, u: Vec2) -> AreaSample {
        let d = square_to_uniform_disk_concentric(u);
        let q = Vec3::new(d.x, d.y, 0.0);
        AreaSample {
            p: self.to_world.transform_point3(q),
            n: self.normal,
            uv: Self::local_uv(q),
            prim: 0,
            bary: Vec2::ZERO,
            pdf: 1.0 / self.area,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_disk() {
        let d = Disk::new(
            Mat4::from_translation(Vec3::new(0.0, 0.0, 2.0)) * Mat4::from_scale(Vec3::splat(2.0)),
            false,
        );
        assert!((d.area() - 4.0 * PI).abs() < 1e-4);
        let t = d.intersect(Vec3A::new(1.5, 0.0, 0.0), Vec3A::Z, 0.0, f32::INFINITY);
        assert!((t - 2.0).abs() < 1e-5);
        assert!(d
            .intersect(Vec3A::new(2.5, 0.0, 0.0), Vec3A::Z, 0.0, f32::INFINITY)
            .is_infinite());
        let g = d.hit_geometry(&Ray::new(Vec3::new(1.0, 0.0, 0.0), Vec3::Z), 2.0);
        assert!((g.ng - Vec3::Z).length() < 1e-6 && (g.uv.x - 0.5).abs() < 1e-5);
    }
}
