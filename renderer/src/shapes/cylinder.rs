//! Analytic cylinder (Mitsuba's `cylinder`): the open tube x² + y² = 1, 0 ≤ z ≤ 1 in local
//! space (no caps), mapped by `to_world`, which the importer composes as Mitsuba does:
//! to_world · translate(p0) · frame(p1 − p0) · scale(radius, radius, |p1 − p0|). The map must
//! keep the cross-section circular and the tube upright (a rotation and a scale per axis with
//! equal x and y scale): the area and uniform area sampling are then exact.
//! uv = (φ / 2π, z) with φ = atan2(y, x) in [0, 2π); dp/du along increasing φ; the normal points
//! outwards (inwards with `flip_normals`).

use super::{AreaSample, HitGeometry};
use crate::math::Ray;
use glam::{Mat3, Mat4, Vec2, Vec3, Vec3A};
use std::f32::consts::PI;

/// A right circular cylinder in world space.
#[derive(Debug, Clone, Copy)]
pub struct Cylinder {
    /// Object-to-world.
    to_world: Mat4,
    /// World-to-object.
    to_local: Mat4,
    /// Normals: object to world (inverse transpose of the linear part).
    normal_to_world: Mat3,
    /// Normals point inwards.
    flip_normals: bool,
    /// World area of the tube.
    area: f32,
}

impl Cylinder {
    /// A cylinder from its object-to-world transform, or why the transform is not allowed.
    pub fn new(to_world: Mat4, flip_normals: bool) -> Result<Self, String> {
        let (x, y, z) = (
            to_world.transform_vector3(Vec3::X),
            to_world.transform_vector3(Vec3::Y),
            to_world.transform_vector3(Vec3::Z),
        );
        let (r, r2, len) = (x.length(), y.length(), z.length());
        let tol = 1e-4 * r.max(len).max(1e-12);
        if !to_world.is_finite() || r == 0.0 || len == 0.0 {
            return Err("a cylinder needs a finite, non-zero radius and length".into());
        }
        if (r - r2).abs() > tol * 10.0 {
            return Err(
                "a cylinder's cross-section must stay circular (equal x and y scale)".into(),
            );
        }
        if x.dot(y).abs() > tol * r || x.dot(z).abs() > tol * len || y.dot(z).abs() > tol * len {
            return Err("a cylinder's to_world must not shear it".into());
        }
        Ok(Cylinder {
            to_world,
            to_local: to_world.inverse(),
            normal_to_world: Mat3::from_mat4(to_world).inverse().transpose(),
            flip_normals,
            area: 2.0 * PI * r * len,
        })
    }

    /// Bounding box of the tube (of its local bounding box's corners).
    pub fn bounds(&self) -> (Vec3A, Vec3A) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for k in 0..8 {
            let c = Vec3::new(
                if k & 1 == 0 { -1.0 } else { 1.0 },
                if k & 2 == 0 { -1.0 } else { 1.0 },
                if k & 4 == 0 { 0.0 } else { 1.0 },
            );
            let p = self.to_world.transform_point3(c);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        (Vec3A::from(lo), Vec3A::from(hi))
    }

    /// Area.
    pub fn area(&self) -> f32 {
        self.area
    }

    /// Hit distance in (tmin, tmax), or +∞: the nearer of the tube's two crossings whose height
    /// is within [0, 1] (the tube is open, so a ray can enter it and hit the inside).
    #[inline]
    pub fn intersect(&self, o: Vec3A, d: Vec3A, tmin: f32, tmax: f32) -> f32 {
        // Local space, in f64: the quadratic loses precision for rays nearly along the axis.
        let lo = self.to_local.transform_point3(Vec3::from(o)).as_dvec3();
        let ld = self.to_local.transform_vector3(Vec3::from(d)).as_dvec3();
        let a = ld.x * ld.x + ld.y * ld.y;
        if a == 0.0 {
            return f32::INFINITY;
        }
        let b = 2.0 * (lo.x * ld.x + lo.y * ld.y);
        let c = lo.x * lo.x + lo.y * lo.y - 1.0;
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            return f32::INFINITY;
        }
        // Numerically stable roots.
        let q = -0.5 * (b + b.signum() * disc.sqrt());
        let (mut t0, mut t1) = (q / a, if q != 0.0 { c / q } else { -b / (2.0 * a) });
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        for t in [t0, t1] {
            let tf = t as f32;
            if tf > tmin && tf < tmax {
                let z = lo.z + t * ld.z;
                if (0.0..=1.0).contains(&z) {
                    return tf;
                }
            }
        }
        f32::INFINITY
    }

    /// uv of a local point on the tube.
    fn local_uv(q: Vec3) -> Vec2 {
        let mut phi = q.y.atan2(q.x);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        Vec2::new(phi / (2.0 * PI), q.z)
    }

    /// World normal at local point `q` (radial direction), oriented by `flip_normals`.
    fn normal_at(&self, q: Vec3) -> Vec3 {
        let n = (self.normal_to_world * Vec3::new(q.x, q.y, 0.0)).normalize_or(Vec3::X);
        if self.flip_normals {
            -n
        } else {
            n
        }
    }

    /// Shading data at the hit of `ray` at distance `t` (the point projected onto the tube).
    pub fn hit_geometry(&self, ray: &Ray, t: f32) -> HitGeometry {
        let mut q = self.to_local.transform_point3(ray.at(t));
        let r = (q.x * q.x + q.y * q.y).sqrt();
        if r > 0.0 {
            q.x /= r;
            q.y /= r;
        }
        let n = self.normal_at(q);
        HitGeometry {
            p: self.to_world.transform_point3(q),
            ng: n,
            ns: n,
            dpdu: self
                .to_world
                .transform_vector3(Vec3::new(-q.y, q.x, 0.0) * (2.0 * PI)),
            dpdv: self.to_world.transform_vector3(Vec3::Z),
            uv: Self::local_uv(q),
            bary: Vec2::ZERO,
        }
    }

    /// A point uniformly distributed over the tube (uniform in φ and height).
    pub fn sample_area(&self, u: Vec2) -> AreaSample {
        let (s, c) = (2.0 * PI * u.x).sin_cos();
        let q = Vec3::new(c, s, u.y);
        AreaSample {
            p: self.to_world.transform_point3(q),
            n: self.normal_at(q),
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

    fn tube() -> Cylinder {
        // Radius 0.5, from z = 1 to z = 3.
        let m = Mat4::from_translation(Vec3::new(0.0, 0.0, 1.0))
            * Mat4::from_scale(Vec3::new(0.5, 0.5, 2.0));
        Cylinder::new(m, false).unwrap()
    }

    #[test]
    fn hits_outside_and_inside_and_misses_past_the_ends() {
        let c = tube();
        assert!((c.area() - 2.0 * PI * 0.5 * 2.0).abs() < 1e-5);
        // From the side: the near wall at x = −0.5.
        let t = c.intersect(Vec3A::new(-3.0, 0.0, 2.0), Vec3A::X, 0.0, f32::INFINITY);
        assert!((t - 2.5).abs() < 1e-5, "{t}");
        let g = c.hit_geometry(&Ray::new(Vec3::new(-3.0, 0.0, 2.0), Vec3::X), t);
        assert!(
            (g.ng + Vec3::X).length() < 1e-5,
            "outward normal {:?}",
            g.ng
        );
        assert!((g.uv - Vec2::new(0.5, 0.5)).length() < 1e-5, "{:?}", g.uv);
        // From inside: the far wall.
        let t = c.intersect(Vec3A::new(0.0, 0.0, 2.0), Vec3A::Y, 0.0, f32::INFINITY);
        assert!((t - 0.5).abs() < 1e-5);
        // Past the open ends: along the axis nothing is hit; above the top, nothing.
        assert!(c
            .intersect(Vec3A::new(0.0, 0.0, 0.0), Vec3A::Z, 0.0, f32::INFINITY)
            .is_infinite());
        assert!(c
            .intersect(Vec3A::new(-3.0, 0.0, 3.5), Vec3A::X, 0.0, f32::INFINITY)
            .is_infinite());
        // Through the open top end, the inside wall.
        let d = Vec3A::new(0.3, 0.0, -1.0).normalize();
        let t = c.intersect(Vec3A::new(0.0, 0.0, 3.5), d, 0.0, f32::INFINITY);
        let p = Vec3A::new(0.0, 0.0, 3.5) + d * t;
        assert!((p.x - 0.5).abs() < 1e-4 && p.z < 3.0 && p.z > 1.0, "{p:?}");
    }

    #[test]
    fn area_samples_lie_on_the_tube_uniformly() {
        let c = tube();
        let mut heights = [0u32; 4];
        for i in 0..4000 {
            let u = Vec2::new((i as f32 * 0.618_034).fract(), (i as f32 + 0.5) / 4000.0);
            let s = c.sample_area(u);
            assert!((s.p.x.hypot(s.p.y) - 0.5).abs() < 1e-5);
            assert!((s.n - Vec3::new(s.p.x, s.p.y, 0.0) * 2.0).length() < 1e-4);
            heights[(((s.p.z - 1.0) / 2.0) * 4.0).min(3.0) as usize] += 1;
        }
        assert_eq!(heights, [1000; 4]);
    }

    #[test]
    fn shearing_or_elliptic_transforms_are_refused() {
        let squash = Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0));
        assert!(Cylinder::new(squash, false)
            .unwrap_err()
            .contains("circular"));
        let shear = Mat4::from_cols(
            glam::Vec4::X,
            glam::Vec4::Y,
            glam::Vec4::new(0.5, 0.0, 1.0, 0.0),
            glam::Vec4::W,
        );
        assert!(Cylinder::new(shear, false).unwrap_err().contains("shear"));
    }
}
