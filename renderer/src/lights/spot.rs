//! Spot light (Mitsuba's `spot`): a point light shining along its local +z, full intensity
//! inside `beam_width`, falling off linearly in angle to zero at `cutoff_angle`.

use super::{EmissionSample, LightSample};
use crate::math::Ray;
use crate::sampling::{square_to_uniform_cone, uniform_cone_pdf};
use crate::spectrum::Rgb;
use glam::{Mat3, Mat4, Vec2, Vec3};

/// A spot light.
#[derive(Debug, Clone, Copy)]
pub struct SpotLight {
    /// Position.
    pub position: Vec3,
    /// Local-to-world rotation (columns: local x, y, z = beam axis), orthonormalised.
    pub frame: Mat3,
    /// Intensity at the beam centre.
    pub intensity: Rgb,
    /// Cutoff angle in radians.
    cutoff: f32,
    /// cos(cutoff).
    cos_cutoff: f32,
    /// cos(beam width).
    cos_beam: f32,
    /// 1 / (cutoff − beam width) in radians.
    inv_transition: f32,
    /// ∫ falloff dω over the sphere (for the power).
    falloff_integral: f32,
}

impl SpotLight {
    /// Builds the light from its transform and angles in degrees.
    pub fn new(to_world: Mat4, intensity: Rgb, cutoff_deg: f32, beam_width_deg: f32) -> Self {
        let position = to_world.transform_point3(Vec3::ZERO);
        let z = to_world.transform_vector3(Vec3::Z).normalize_or(Vec3::Z);
        let (x, y) = crate::math::coordinate_system(z);
        let cutoff = cutoff_deg.to_radians();
        let beam = beam_width_deg.to_radians().min(cutoff);
        let inv_transition = if cutoff > beam {
            1.0 / (cutoff - beam)
        } else {
            f32::INFINITY
        };
        let mut s = SpotLight {
            position,
            frame: Mat3::from_cols(x, y, z),
            intensity,
            cutoff,
            cos_cutoff: cutoff.cos(),
            cos_beam: beam.cos(),
            inv_transition,
            falloff_integral: 0.0,
        };
        // ∫ falloff dω = 2π ∫ falloff(θ) sin θ dθ, midpoint rule (smooth integrand).
        let n = 2048;
        let dt = cutoff / n as f32;
        let mut acc = 0.0f64;
        for i in 0..n {
            let th = (i as f32 + 0.5) * dt;
            acc += (s.falloff(th.cos()) * th.sin() * dt) as f64;
        }
        s.falloff_integral = (2.0 * std::f64::consts::PI * acc) as f32;
        s
    }

    /// Falloff factor in [0, 1] for a direction at angle acos(`cos_theta`) from the axis.
    #[inline]
    pub fn falloff(&self, cos_theta: f32) -> f32 {
        if cos_theta <= self.cos_cutoff {
            0.0
        } else if cos_theta >= self.cos_beam {
            1.0
        } else {
            ((self.cutoff - cos_theta.clamp(-1.0, 1.0).acos()) * self.inv_transition)
                .clamp(0.0, 1.0)
        }
    }

    /// Direct illumination at `p`.
    pub fn sample_li(&self, p: Vec3) -> Option<LightSample> {
        let d = self.position - p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let dist = dist2.sqrt();
        let wi = d / dist;
        let f = self.falloff((-wi).dot(self.frame.z_axis));
        if f == 0.0 {
            return None;
        }
        Some(LightSample {
            wi,
            p: self.position,
            dist,
            weight: self.intensity * (f / dist2),
            pdf: 1.0,
            delta: true,
            infinite: false,
            light: 0,
        })
    }

    /// A photon in a direction uniform within the cutoff cone.
    pub fn sample_emission(&self, u: Vec2) -> EmissionSample {
        let local = square_to_uniform_cone(u, self.cos_cutoff);
        let d = self.frame * local;
        let flux = self.intensity * (self.falloff(local.z) / uniform_cone_pdf(self.cos_cutoff));
        EmissionSample {
            ray: Ray::new(self.position, d),
            flux,
            light: 0,
        }
    }

    /// Emitted power I·∫falloff dω.
    pub fn power(&self) -> Rgb {
        self.intensity * self.falloff_integral
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn falloff_is_linear_in_angle_between_beam_and_cutoff() {
        let s = SpotLight::new(Mat4::IDENTITY, Rgb::ONE, 20.0, 10.0);
        assert_eq!(s.falloff(1.0), 1.0);
        assert_eq!(s.falloff(5f32.to_radians().cos()), 1.0);
        assert!((s.falloff(15f32.to_radians().cos()) - 0.5).abs() < 1e-3);
        assert_eq!(s.falloff(25f32.to_radians().cos()), 0.0);
        // Power lies between the beam cone and the cutoff cone solid angles.
        let lo = 2.0 * std::f32::consts::PI * (1.0 - 10f32.to_radians().cos());
        let hi = 2.0 * std::f32::consts::PI * (1.0 - 20f32.to_radians().cos());
        assert!(s.power().x > lo && s.power().x < hi);
    }
}
