//! Spot light (Mitsuba's `spot`): a point light shining along its local +z, full intensity
//! inside `beam_width`, falling off linearly in angle to zero at `cutoff_angle`, optionally
//! projecting a `texture` (a slide: the cutoff cone maps onto the texture's unit square).

use super::bounds::LightBounds;
use super::channel_mean;
use super::{EmissionSample, LightSample};
use crate::math::Ray;
use crate::sampling::{square_to_uniform_cone, uniform_cone_pdf};
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::f32::consts::PI;

/// A spot light.
#[derive(Debug, Clone)]
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
    /// ∫ falloff · texture dω over the sphere (per channel, for the power).
    falloff_integral: Rgb,
    /// The projected texture, if any.
    texture: Option<Texture>,
    /// World-to-local map of directions (the inverse of `to_world`'s 3×3 part): the texture's
    /// uv follow `to_world`'s own x and y axes, as in Mitsuba.
    to_local: Mat3,
    /// tan(cutoff): the cone's half-width in the plane z = 1.
    uv_factor: f32,
}

impl SpotLight {
    /// Builds the light from its transform, angles in degrees and projected texture.
    pub fn new(
        to_world: Mat4,
        intensity: Rgb,
        cutoff_deg: f32,
        beam_width_deg: f32,
        texture: Option<Texture>,
    ) -> Self {
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
            falloff_integral: Rgb::ZERO,
            texture,
            to_local: Mat3::from_mat4(to_world).inverse(),
            uv_factor: cutoff.tan(),
        };
        s.falloff_integral = match &s.texture {
            None => {
                // ∫ falloff dω = 2π ∫ falloff(θ) sin θ dθ, midpoint rule (smooth integrand).
                let n = 2048;
                let dt = cutoff / n as f32;
                let mut acc = 0.0f64;
                for i in 0..n {
                    let th = (i as f32 + 0.5) * dt;
                    acc += (s.falloff(th.cos()) * th.sin() * dt) as f64;
                }
                Rgb::splat((2.0 * std::f64::consts::PI * acc) as f32)
            }
            Some(_) => {
                // The cone's solid angle times the mean of falloff · texture over directions
                // uniform in it (a midpoint grid through the emission's own mapping).
                let n = 512;
                let mut acc = glam::DVec3::ZERO;
                for i in 0..n {
                    for j in 0..n {
                        let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                        let d = s.frame * square_to_uniform_cone(u, s.cos_cutoff);
                        acc += (s.slide(d) * s.falloff(d.dot(s.frame.z_axis))).as_dvec3();
                    }
                }
                (acc / (n * n) as f64).as_vec3() / uniform_cone_pdf(s.cos_cutoff)
            }
        };
        s
    }

    /// The projected texture's colour in world direction `d` (leaving the light; inside the
    /// cutoff cone), white without a texture. Mitsuba's uv: ½ + ½·(x, y)/(z·tan cutoff) of the
    /// direction in `to_world`'s frame.
    #[inline]
    fn slide(&self, d: Vec3) -> Rgb {
        match &self.texture {
            None => Rgb::ONE,
            Some(t) => {
                let l = self.to_local * d;
                let scale = 0.5 / (l.z * self.uv_factor);
                if !scale.is_finite() {
                    // Perpendicular to the beam (a cutoff of 90° or more): off the slide.
                    return Rgb::ZERO;
                }
                t.eval(Vec2::new(0.5 + l.x * scale, 0.5 + l.y * scale))
            }
        }
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
            weight: self.intensity * self.slide(-wi) * (f / dist2),
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
        let flux = self.intensity
            * self.slide(d)
            * (self.falloff(local.z) / uniform_cone_pdf(self.cos_cutoff));
        EmissionSample {
            ray: Ray::new(self.position, d),
            flux,
            light: 0,
        }
    }

    /// Emission bounds for light selection: the power spread over the cutoff cone's solid
    /// angle, about the beam axis, full within the beam width and gone at the cutoff.
    pub fn bounds(&self) -> LightBounds {
        let solid_angle = 2.0 * PI * (1.0 - self.cos_cutoff);
        let intensity = channel_mean(self.power()) / solid_angle;
        let beam = self.cos_beam.clamp(-1.0, 1.0).acos();
        LightBounds::cone(
            self.position,
            0.0,
            intensity,
            self.frame.z_axis,
            self.cos_beam,
            (self.cutoff - beam).cos(),
        )
    }

    /// Emitted power I·∫falloff·texture dω.
    pub fn power(&self) -> Rgb {
        self.intensity * self.falloff_integral
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_checker as checker;
    use super::*;

    #[test]
    fn a_texture_is_projected_along_to_worlds_own_axes() {
        // Cutoff 45° (tan = 1) and no falloff inside it: a point (x, y, 1)·d in the light's
        // frame reads the texture at uv = ½ + ½·(x, y).
        let rot = Mat4::from_rotation_z(std::f32::consts::FRAC_PI_2); // local x = world y
        let s = SpotLight::new(rot, Rgb::splat(2.0), 45.0, 45.0, Some(checker()));
        let d = 3.0f32;
        // (x, y) = (0.5, −0.25): uv (0.75, 0.375), different halves → color1 (blue).
        // In the world: local x is world +y, local y is world −x.
        let at = |x: f32, y: f32| Vec3::new(-y * d, x * d, d);
        let li = s.sample_li(at(0.5, -0.25)).unwrap();
        let dist2 = at(0.5, -0.25).length_squared();
        assert!(
            (li.weight - Rgb::new(0.0, 0.0, 2.0) / dist2)
                .abs()
                .max_element()
                < 1e-6
        );
        // (−0.5, −0.25): uv (0.25, 0.375), same half → color0 (red).
        let li = s.sample_li(at(-0.5, -0.25)).unwrap();
        assert!(li.weight.x > 0.0 && li.weight.z == 0.0, "{}", li.weight);
        // A frame built from the beam axis alone (x, y arbitrary) would not see the rotation.
        let unrotated =
            SpotLight::new(Mat4::IDENTITY, Rgb::splat(2.0), 45.0, 45.0, Some(checker()));
        let li = unrotated.sample_li(at(0.5, -0.25)).unwrap();
        assert!(li.weight.x > 0.0, "{}", li.weight);
        // Photons carry the texture too: flux = I · texture · falloff / pdf.
        for k in 0..64 {
            let u = Vec2::new((k % 8) as f32 / 8.0 + 0.06, (k / 8) as f32 / 8.0 + 0.06);
            let e = s.sample_emission(u);
            let l = e.ray.d / e.ray.d.z;
            let expected = checker().eval(Vec2::new(0.5 + 0.5 * l.y, 0.5 - 0.5 * l.x));
            let pdf = uniform_cone_pdf(s.cos_cutoff);
            assert!(
                (e.flux - 2.0 * expected / pdf).abs().max_element() < 1e-4,
                "{} vs {}",
                e.flux,
                expected
            );
        }
        // Half of the cone's texture is red and half blue: the power splits evenly, and sums
        // to the untextured spot's.
        let plain = SpotLight::new(rot, Rgb::splat(2.0), 45.0, 45.0, None).power();
        let p = s.power();
        assert!(
            (p.x - plain.x / 2.0).abs() < 2e-3 * plain.x,
            "{p} vs {plain}"
        );
        assert!(
            (p.z - plain.z / 2.0).abs() < 2e-3 * plain.z,
            "{p} vs {plain}"
        );
        assert_eq!(p.y, 0.0);
    }

    #[test]
    fn falloff_is_linear_in_angle_between_beam_and_cutoff() {
        let s = SpotLight::new(Mat4::IDENTITY, Rgb::ONE, 20.0, 10.0, None);
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
