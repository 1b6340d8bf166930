//! Orthonormal shading frames: the local coordinate system BSDFs work in (+z = shading normal).

use glam::Vec3;

/// An orthonormal basis: tangent `s`, bitangent `t`, normal `n` (right-handed, `s × t = n`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Tangent (local +x; Mitsuba's `alpha_u` direction).
    pub s: Vec3,
    /// Bitangent (local +y; Mitsuba's `alpha_v` direction).
    pub t: Vec3,
    /// Normal (local +z).
    pub n: Vec3,
}

impl Frame {
    /// A frame around unit normal `n` with an arbitrary but continuous tangent
    /// (Duff et al. 2017, "Building an orthonormal basis, revisited" — the same construction as
    /// Mitsuba's `coordinate_system`, so anisotropic materials on tangent-less shapes line up).
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Self { s, t, n }
    }

    /// A frame around unit normal `n` whose tangent follows `dpdu` projected onto the tangent
    /// plane (Gram–Schmidt, as Mitsuba's shading frame); falls back to [`Frame::from_normal`]
    /// when `dpdu` is (nearly) parallel to `n` or zero.
    pub fn from_normal_tangent(n: Vec3, dpdu: Vec3) -> Self {
        let s = dpdu - n * n.dot(dpdu);
        let len2 = s.length_squared();
        if (len2.is_nan() || len2 <= 1e-12) || !len2.is_finite() {
            return Self::from_normal(n);
        }
        let s = s / len2.sqrt();
        Self {
            s,
            t: n.cross(s),
            n,
        }
    }

    /// World-space vector → local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local coordinates → world-space vector.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal_and_round_trip() {
        let normals = [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.2).normalize(),
            Vec3::new(-0.1, 0.2, -0.97).normalize(),
        ];
        for n in normals {
            for f in [
                Frame::from_normal(n),
                Frame::from_normal_tangent(n, Vec3::new(1.0, 0.3, 0.2)),
            ] {
                assert!((f.s.length() - 1.0).abs() < 1e-5);
                assert!((f.t.length() - 1.0).abs() < 1e-5);
                assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(f.n).abs() < 1e-5);
                assert!((f.s.cross(f.t) - f.n).length() < 1e-5, "right-handed");
                let v = Vec3::new(0.2, -0.7, 0.4);
                assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
                assert!((f.to_local(f.n) - Vec3::Z).length() < 1e-5);
            }
        }
        // The tangent follows dpdu.
        let f = Frame::from_normal_tangent(Vec3::Z, Vec3::new(2.0, 0.0, 1.0));
        assert!((f.s - Vec3::X).length() < 1e-6);
    }
}
