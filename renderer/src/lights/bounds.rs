//! Bounds of a light's emission, for choosing lights by how much they can light a given point
//! (pbrt-v4's light bounds). A finite light's ([`LightBounds`]): where it is (a bounding
//! sphere), how strongly it radiates (a radiant intensity), and into which directions (a cone
//! of emission axes widened by a falloff angle); an infinite light's ([`EmitterBounds`]): the
//! irradiance it delivers to a surface. Each `importance` is a conservative estimate of the
//! irradiance the light can deliver to a point: zero only where the light provably sends
//! nothing (behind a one-sided emitter, outside a spot's cutoff or a projector's frustum).

use glam::{Vec3, Vec4};

/// What bounds a finite light's emission.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightBounds {
    /// Centre of a sphere containing every emitting point.
    center: Vec3,
    /// Its radius (0 for point-like lights).
    radius: f32,
    /// Radiant intensity (channel mean, W/sr) along the strongest direction: the scale of the
    /// importance.
    intensity: f32,
    /// Axis of the cone of emission axes (surface normals, beam axes); unused when
    /// `cos_o` is −1.
    axis: Vec3,
    /// cos θₒ: every emission axis lies within θₒ of `axis`; −1 for all directions.
    cos_o: f32,
    /// sin θₒ.
    sin_o: f32,
    /// cos θₑ: emission falls off to zero θₑ beyond the axes (π/2 for a surface, a spot's
    /// transition angle, 0 for a sharp-edged beam).
    cos_e: f32,
}

/// The falloff factor a light keeps however far off its axes a receiver lies, as long as it
/// can receive anything at all: the cosine approximation of a falloff reaches zero where the
/// true emission may not (a spot's linear falloff), so the estimate must not.
const MIN_FALLOFF: f32 = 0.05;

/// An intensity the importance can scale by: NaN, infinite and negative ones count as zero (as
/// such powers do in the selection by power).
fn usable(intensity: f32) -> f32 {
    if intensity.is_finite() && intensity > 0.0 {
        intensity
    } else {
        0.0
    }
}

impl LightBounds {
    /// A light radiating `intensity` into every direction from points within `radius` of
    /// `center` (points, spheres, closed or curved surfaces).
    pub fn omnidirectional(center: Vec3, radius: f32, intensity: f32) -> Self {
        LightBounds {
            center,
            radius,
            intensity: usable(intensity),
            axis: Vec3::Z,
            cos_o: -1.0,
            sin_o: 0.0,
            cos_e: -1.0,
        }
    }

    /// A light whose emission axes lie within θₒ = acos(`cos_o`) of the unit `axis` and whose
    /// emission reaches zero θₑ = acos(`cos_e`) beyond them.
    pub fn cone(
        center: Vec3,
        radius: f32,
        intensity: f32,
        axis: Vec3,
        cos_o: f32,
        cos_e: f32,
    ) -> Self {
        let cos_o = cos_o.clamp(-1.0, 1.0);
        LightBounds {
            center,
            radius,
            intensity: usable(intensity),
            axis,
            cos_o,
            sin_o: (1.0 - cos_o * cos_o).max(0.0).sqrt(),
            cos_e: cos_e.clamp(-1.0, 1.0),
        }
    }

    /// Centre of the bounding sphere.
    pub fn center(&self) -> Vec3 {
        self.center
    }

    /// Bounds of two lights together: a sphere holding both spheres, a cone of axes holding
    /// both cones, the wider falloff, the summed intensity.
    pub fn union(&self, other: &LightBounds) -> LightBounds {
        let (a, b) = (self, other);
        let d = (b.center - a.center).length();
        let (center, radius) = if d + b.radius <= a.radius {
            (a.center, a.radius)
        } else if d + a.radius <= b.radius {
            (b.center, b.radius)
        } else {
            let r = 0.5 * (d + a.radius + b.radius);
            (a.center + (b.center - a.center) * ((r - a.radius) / d), r)
        };
        // Slack for the rounding of the new centre.
        let radius = radius * (1.0 + 1e-5) + 1e-6;
        let (axis, cos_o) = cone_union((a.axis, a.cos_o), (b.axis, b.cos_o));
        LightBounds::cone(
            center,
            radius,
            a.intensity + b.intensity,
            axis,
            cos_o,
            a.cos_e.min(b.cos_e),
        )
    }

    /// A conservative estimate of the irradiance the light delivers at `p` on a surface with
    /// unit normal `n` (either side; `Vec3::ZERO` for no surface): intensity / distance²,
    /// times the cosine of the smallest angle the bounds allow between the emission axes and
    /// the direction to `p` (zero when it lies beyond the falloff), times the cosine of the
    /// smallest angle between `n` and a direction towards the light.
    #[inline]
    pub fn importance(&self, p: Vec3, n: Vec3) -> f32 {
        if self.intensity <= 0.0 {
            return 0.0;
        }
        let to_p = p - self.center;
        let d2 = to_p.length_squared();
        let r2 = self.radius * self.radius;
        if d2 <= r2 {
            // Inside the bounds: any direction and any distance down to zero are possible; the
            // radius caps the estimate.
            return self.intensity / r2.max(f32::MIN_POSITIVE);
        }
        let d = d2.sqrt();
        let wi = to_p / d;
        // θ_b: the half-angle the bounding sphere subtends from `p`.
        let sin2_b = r2 / d2;
        let cos_b = (1.0 - sin2_b).max(0.0).sqrt();
        let sin_b = sin2_b.sqrt();
        let mut estimate = self.intensity / d2;
        if self.cos_o > -1.0 {
            let cos_w = self.axis.dot(wi).clamp(-1.0, 1.0);
            if cos_w < self.cos_o {
                // θ_w − θ_o > 0, then less θ_b.
                let sin_w = (1.0 - cos_w * cos_w).max(0.0).sqrt();
                let cos_x = cos_w * self.cos_o + sin_w * self.sin_o;
                let sin_x = (sin_w * self.cos_o - cos_w * self.sin_o).max(0.0);
                if cos_x < cos_b {
                    let cos_off = cos_x * cos_b + sin_x * sin_b;
                    if cos_off <= self.cos_e {
                        return 0.0;
                    }
                    estimate *= cos_off.max(MIN_FALLOFF);
                }
            }
        }
        if n != Vec3::ZERO {
            let cos_i = n.dot(wi).abs().min(1.0);
            if cos_i < cos_b {
                let sin_i = (1.0 - cos_i * cos_i).max(0.0).sqrt();
                estimate *= cos_i * cos_b + sin_i * sin_b;
            }
        }
        estimate
    }
}

/// Four finite lights' bounds side by side, for evaluating their importance in 4-wide lanes
/// (the light selection weighs every finite light at every light sample). Each lane computes
/// exactly what [`LightBounds::importance`] computes, operation for operation, so the results
/// are the same bits; unused lanes have zero intensity and importance 0.
#[derive(Debug, Clone, Copy)]
pub struct LightBounds4 {
    /// Bounding sphere centres, by coordinate.
    center: [Vec4; 3],
    /// Squared radii.
    r2: Vec4,
    /// Intensities.
    intensity: Vec4,
    /// Axes of the emission cones, by coordinate.
    axis: [Vec4; 3],
    /// cos θₒ (−1: all directions).
    cos_o: Vec4,
    /// sin θₒ.
    sin_o: Vec4,
    /// cos θₑ.
    cos_e: Vec4,
}

impl LightBounds4 {
    /// Packs up to four bounds (fewer leave lanes that never light anything).
    pub fn new(bounds: &[LightBounds]) -> Self {
        debug_assert!(bounds.len() <= 4);
        let lane = |f: &dyn Fn(&LightBounds) -> f32, unused: f32| {
            Vec4::from_array(std::array::from_fn(|k| bounds.get(k).map_or(unused, f)))
        };
        LightBounds4 {
            center: [
                lane(&|b| b.center.x, 0.0),
                lane(&|b| b.center.y, 0.0),
                lane(&|b| b.center.z, 0.0),
            ],
            r2: lane(&|b| b.radius * b.radius, 0.0),
            intensity: lane(&|b| b.intensity, 0.0),
            axis: [
                lane(&|b| b.axis.x, 0.0),
                lane(&|b| b.axis.y, 0.0),
                lane(&|b| b.axis.z, 1.0),
            ],
            cos_o: lane(&|b| b.cos_o, -1.0),
            sin_o: lane(&|b| b.sin_o, 0.0),
            cos_e: lane(&|b| b.cos_e, -1.0),
        }
    }

    /// [`LightBounds::importance`] of the four lights at `p` with unit normal `n`.
    #[inline]
    pub fn importance(&self, p: Vec3, n: Vec3) -> Vec4 {
        let one = Vec4::ONE;
        let zero = Vec4::ZERO;
        let tx = Vec4::splat(p.x) - self.center[0];
        let ty = Vec4::splat(p.y) - self.center[1];
        let tz = Vec4::splat(p.z) - self.center[2];
        let d2 = tx * tx + ty * ty + tz * tz;
        let inside_value = self.intensity / self.r2.max(Vec4::splat(f32::MIN_POSITIVE));
        let d = d2.sqrt();
        let (wx, wy, wz) = (tx / d, ty / d, tz / d);
        let sin2_b = self.r2 / d2;
        let cos_b = (one - sin2_b).max(zero).sqrt();
        let sin_b = sin2_b.sqrt();
        let mut estimate = self.intensity / d2;
        // The emission cone, where a light has one and the direction lies outside it.
        let cos_w = (self.axis[0] * wx + self.axis[1] * wy + self.axis[2] * wz).clamp(-one, one);
        let sin_w = (one - cos_w * cos_w).max(zero).sqrt();
        let cos_x = cos_w * self.cos_o + sin_w * self.sin_o;
        let sin_x = (sin_w * self.cos_o - cos_w * self.sin_o).max(zero);
        let cos_off = cos_x * cos_b + sin_x * sin_b;
        let off_axis = self.cos_o.cmpgt(-one) & cos_w.cmplt(self.cos_o) & cos_x.cmplt(cos_b);
        let beyond = off_axis & cos_off.cmple(self.cos_e);
        let falloff = Vec4::select(off_axis, cos_off.max(Vec4::splat(MIN_FALLOFF)), one);
        estimate *= falloff;
        if n != Vec3::ZERO {
            let cos_i = (Vec4::splat(n.x) * wx + Vec4::splat(n.y) * wy + Vec4::splat(n.z) * wz)
                .abs()
                .min(one);
            let sin_i = (one - cos_i * cos_i).max(zero).sqrt();
            let tilt = Vec4::select(cos_i.cmplt(cos_b), cos_i * cos_b + sin_i * sin_b, one);
            estimate *= tilt;
        }
        let estimate = Vec4::select(beyond, zero, estimate);
        let estimate = Vec4::select(d2.cmple(self.r2), inside_value, estimate);
        Vec4::select(self.intensity.cmple(zero), zero, estimate)
    }
}

/// What bounds any light's emission.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EmitterBounds {
    /// A light at a finite position.
    Finite(LightBounds),
    /// A distant light: irradiance `irradiance` (channel mean) on a surface facing `toward`
    /// (the unit direction towards the light).
    Directional {
        /// Unit direction towards the light.
        toward: Vec3,
        /// Irradiance on a surface facing the light.
        irradiance: f32,
    },
    /// An environment: `irradiance` is what it delivers to one side of a surface on average
    /// over orientations (π·L for a constant radiance L).
    Environment {
        /// Mean irradiance on one side of a surface.
        irradiance: f32,
    },
}

impl EmitterBounds {
    /// The importance of the light at `p` with unit normal `n` (`Vec3::ZERO`: none): an
    /// estimate of the irradiance it delivers there, occlusion ignored.
    #[inline]
    pub fn importance(&self, p: Vec3, n: Vec3) -> f32 {
        match *self {
            EmitterBounds::Finite(b) => b.importance(p, n),
            EmitterBounds::Directional { toward, irradiance } => {
                if n == Vec3::ZERO {
                    usable(irradiance)
                } else {
                    usable(irradiance) * n.dot(toward).abs().min(1.0)
                }
            }
            EmitterBounds::Environment { irradiance } => usable(irradiance),
        }
    }

    /// Whether the light is at infinity.
    pub fn is_infinite(&self) -> bool {
        !matches!(self, EmitterBounds::Finite(_))
    }
}

/// The narrowest cone holding two cones (axis, cos θ), as pbrt-v4's `Union` of direction
/// cones; cos θ = −1 for all directions.
fn cone_union(a: (Vec3, f32), b: (Vec3, f32)) -> (Vec3, f32) {
    use std::f32::consts::PI;
    let all = (Vec3::Z, -1.0);
    if a.1 <= -1.0 || b.1 <= -1.0 {
        return all;
    }
    let (theta_a, theta_b) = (a.1.clamp(-1.0, 1.0).acos(), b.1.clamp(-1.0, 1.0).acos());
    let theta_d = a.0.dot(b.0).clamp(-1.0, 1.0).acos();
    if (theta_d + theta_b).min(PI) <= theta_a {
        return a;
    }
    if (theta_d + theta_a).min(PI) <= theta_b {
        return b;
    }
    let theta_o = 0.5 * (theta_a + theta_d + theta_b);
    if theta_o >= PI {
        return all;
    }
    let Some(turn) = a.0.cross(b.0).try_normalize() else {
        return all;
    };
    let axis = glam::Quat::from_axis_angle(turn, theta_o - theta_a) * a.0;
    // Slack for the rounding of the rotation.
    (axis, (theta_o.cos() - 1e-5).max(-1.0))
}

/// A sphere (centre, radius) containing the box `lo`..`hi`.
pub fn bounding_sphere(lo: Vec3, hi: Vec3) -> (Vec3, f32) {
    (0.5 * (lo + hi), 0.5 * (hi - lo).length())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_light_falls_off_with_distance_squared_and_receiver_cosine() {
        let b = LightBounds::omnidirectional(Vec3::ZERO, 0.0, 4.0);
        assert_eq!(b.importance(Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO), 1.0);
        // Receiver normal at 60° to the direction towards the light.
        let n = Vec3::new(3f32.sqrt() / 2.0, 0.0, 0.5);
        let got = b.importance(Vec3::new(0.0, 0.0, 2.0), n);
        assert!((got - 0.5).abs() < 1e-6, "{got}");
        // Either side of the receiving surface.
        assert_eq!(got, b.importance(Vec3::new(0.0, 0.0, 2.0), -n));
    }

    #[test]
    fn a_one_sided_emitter_gives_nothing_behind_itself_and_more_in_front() {
        // A unit disk facing +z: bounding sphere radius 1.
        let b = LightBounds::cone(Vec3::ZERO, 1.0, 1.0, Vec3::Z, 1.0, 0.0);
        let front = b.importance(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO);
        let side = b.importance(Vec3::new(5.0, 0.0, 0.0), Vec3::ZERO);
        let behind = b.importance(Vec3::new(0.0, 0.0, -5.0), Vec3::ZERO);
        assert!((front - 1.0 / 25.0).abs() < 1e-7, "{front}");
        // At the side the disk's edge still faces the point within θ_b: not zero.
        assert!(side > 0.0 && side < front, "{side}");
        assert_eq!(behind, 0.0);
        // Just behind the plane but within the bounds' angular slack: still possible.
        assert!(b.importance(Vec3::new(5.0, 0.0, -0.5), Vec3::ZERO) > 0.0);
    }

    #[test]
    fn a_beam_is_zero_outside_its_cone_and_full_inside() {
        let cos30 = 30f32.to_radians().cos();
        let b = LightBounds::cone(Vec3::ZERO, 0.0, 2.0, Vec3::Z, cos30, 1.0);
        let inside = Vec3::new(20f32.to_radians().tan(), 0.0, 1.0);
        let outside = Vec3::new(35f32.to_radians().tan(), 0.0, 1.0);
        let got = b.importance(inside, Vec3::ZERO);
        assert!((got - 2.0 / inside.length_squared()).abs() < 1e-6, "{got}");
        assert_eq!(b.importance(outside, Vec3::ZERO), 0.0);
        // A falloff of 10° beyond the axes lets 35° through, not 45°.
        let soft = LightBounds::cone(
            Vec3::ZERO,
            0.0,
            2.0,
            Vec3::Z,
            cos30,
            10f32.to_radians().cos(),
        );
        assert!(soft.importance(outside, Vec3::ZERO) > 0.0);
        let far = Vec3::new(45f32.to_radians().tan(), 0.0, 1.0);
        assert_eq!(soft.importance(far, Vec3::ZERO), 0.0);
    }

    #[test]
    fn inside_the_bounds_every_light_stays_possible() {
        let b = LightBounds::cone(Vec3::ZERO, 1.0, 3.0, Vec3::Z, 1.0, 0.0);
        assert_eq!(b.importance(Vec3::new(0.0, 0.0, -0.5), Vec3::X), 3.0);
        let dark = LightBounds::omnidirectional(Vec3::ZERO, 1.0, 0.0);
        assert_eq!(dark.importance(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO), 0.0);
    }

    /// The bounds of every kind of finite light are conservative: wherever a light sample
    /// from a point carries light, the light's importance there is positive.
    #[test]
    fn every_lights_bounds_cover_where_it_shines() {
        use crate::description::TriangleMesh;
        use crate::lights::{AreaLight, PointLight, ProjectorLight, SpotLight};
        use crate::sampling::{rng_for, UniformSource};
        use crate::shapes::{Cylinder, Disk, Mesh, Shape, Sphere};
        use crate::spectrum::Rgb;
        use crate::texture::Texture;
        use glam::{Mat4, Quat};

        let tilt = Mat4::from_rotation_translation(
            Quat::from_rotation_arc(Vec3::Z, Vec3::new(0.3, -1.0, 0.2).normalize()),
            Vec3::new(0.2, 1.5, -0.3),
        );
        // A curved strip of two triangles at an angle, and a flat quad facing down.
        let mesh = |positions: Vec<Vec3>, indices| {
            Shape::Mesh(Mesh::new(&TriangleMesh {
                positions,
                normals: None,
                uvs: None,
                indices,
                flipped: false,
            }))
        };
        let strip = mesh(
            vec![
                Vec3::new(-1.0, 1.0, 0.0),
                Vec3::new(0.0, 1.2, 0.0),
                Vec3::new(0.0, 1.2, 1.0),
                Vec3::new(1.0, 0.8, 0.5),
            ],
            vec![[0, 1, 2], [1, 3, 2]],
        );
        let quad = mesh(
            vec![
                Vec3::new(-1.0, 2.0, -1.0),
                Vec3::new(1.0, 2.0, -1.0),
                Vec3::new(1.0, 2.0, 1.0),
                Vec3::new(-1.0, 2.0, 1.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let shapes = [
            strip,
            quad,
            Shape::Sphere(Sphere::new(Vec3::new(0.5, 1.0, 0.0), 0.4, false)),
            Shape::Disk(Disk::new(tilt, false)),
            Shape::Cylinder(Cylinder::new(tilt, false).unwrap()),
        ];
        // Every shape's points by area (no triangle tree: one light object for all shapes).
        let area = AreaLight {
            shape: 0,
            radiance: Texture::Constant(Rgb::ONE),
            triangles: None,
            collimated: false,
        };
        let spot = SpotLight::new(tilt, Rgb::ONE, 25.0, 10.0, None);
        let projector = ProjectorLight::new(tilt, Texture::Constant(Rgb::ONE), 1.0, 40.0);
        let point = PointLight {
            position: Vec3::new(0.1, 0.2, 0.3),
            intensity: Rgb::ONE,
        };
        let mut rng = rng_for(17, 0, 0);
        let mut lit = [0u32; 8];
        for _ in 0..20_000 {
            let p = (rng.next_2d().extend(rng.next_f32()) - 0.5) * 6.0;
            let (u_sel, u) = (rng.next_f32(), rng.next_2d());
            let mut check = |k: usize, bounds: LightBounds, shines: bool| {
                if shines {
                    lit[k] += 1;
                    assert!(bounds.importance(p, Vec3::ZERO) > 0.0, "light {k} at {p}");
                }
            };
            for (k, shape) in shapes.iter().enumerate() {
                let shines = area
                    .sample_li(shape, p, Vec3::ZERO, u_sel, u)
                    .is_some_and(|ls| ls.weight.max_element() > 0.0);
                check(k, area.bounds(shape), shines);
            }
            let shines = |ls: Option<super::super::LightSample>| {
                ls.is_some_and(|ls| ls.weight.max_element() > 0.0)
            };
            check(5, spot.bounds(), shines(spot.sample_li(p)));
            check(6, projector.bounds(), shines(projector.sample_li(p)));
            check(7, point.bounds(), shines(point.sample_li(p)));
        }
        // Every light was seen shining, and the one-sided and beamed ones not everywhere.
        assert!(lit.iter().all(|&n| n > 100), "{lit:?}");
        // (The quad faces down from y = 2: 5/6 of the cube lies below it.)
        assert!(
            lit[1] < 18_000 && lit[5] < 5_000 && lit[6] < 5_000,
            "{lit:?}"
        );
    }

    /// The 4-wide importance is the scalar one, bit for bit, for every kind of bounds, inside
    /// and outside them, with and without a receiving normal, in every lane position.
    #[test]
    fn four_lanes_give_the_scalar_importance_bit_for_bit() {
        use crate::sampling::{rng_for, UniformSource};
        let tilted = Vec3::new(0.3, -1.0, 0.2).normalize();
        let kinds = [
            LightBounds::omnidirectional(Vec3::new(0.5, 1.0, -0.2), 0.4, 3.0),
            LightBounds::omnidirectional(Vec3::new(-1.0, 2.0, 0.5), 0.0, 7.0),
            LightBounds::cone(
                Vec3::new(0.0, 2.0, 0.0),
                0.7,
                5.0,
                -Vec3::Y,
                1.0 - 1e-5,
                0.0,
            ),
            LightBounds::cone(Vec3::new(1.0, 1.5, 1.0), 0.0, 9.0, tilted, 0.9, 0.95),
            LightBounds::cone(Vec3::new(-1.5, 1.0, 0.0), 0.0, 2.0, tilted, 0.8, 1.0),
            LightBounds::cone(Vec3::new(0.2, 0.3, 0.4), 1.2, 4.0, Vec3::X, 0.3, 0.0),
            LightBounds::omnidirectional(Vec3::ZERO, 1.0, 0.0),
        ];
        let mut rng = rng_for(23, 0, 0);
        for _ in 0..20_000 {
            let p = (rng.next_2d().extend(rng.next_f32()) - 0.5) * 6.0;
            let n = if rng.next_f32() < 0.2 {
                Vec3::ZERO
            } else {
                (rng.next_2d().extend(rng.next_f32()) - 0.5).normalize_or(Vec3::Y)
            };
            let first = (rng.next_f32() * kinds.len() as f32) as usize;
            let count = 1 + (rng.next_f32() * 4.0) as usize;
            let pack: Vec<LightBounds> = (0..count)
                .map(|k| kinds[(first + k) % kinds.len()])
                .collect();
            let lanes = LightBounds4::new(&pack).importance(p, n).to_array();
            for (k, b) in pack.iter().enumerate() {
                assert_eq!(
                    lanes[k].to_bits(),
                    b.importance(p, n).to_bits(),
                    "{b:?} at {p}, normal {n}"
                );
            }
            assert!(lanes[count..].iter().all(|&x| x == 0.0));
        }
    }

    /// The union of two bounds is positive wherever either is: a cluster of lights is never
    /// ruled out where one of its lights can shine.
    #[test]
    fn a_union_covers_both_lights() {
        use crate::sampling::{rng_for, UniformSource};
        let mut rng = rng_for(29, 0, 0);
        let random_bounds = |rng: &mut crate::sampling::Pcg32| {
            let c = (rng.next_2d().extend(rng.next_f32()) - 0.5) * 4.0;
            let axis = (rng.next_2d().extend(rng.next_f32()) - 0.5).normalize_or(Vec3::Z);
            let r = if rng.next_f32() < 0.3 {
                0.0
            } else {
                rng.next_f32()
            };
            match (rng.next_f32() * 3.0) as u32 {
                0 => LightBounds::omnidirectional(c, r, 1.0),
                1 => LightBounds::cone(c, r, 1.0, axis, 1.0, 0.0),
                _ => LightBounds::cone(c, 0.0, 1.0, axis, rng.next_f32(), rng.next_f32()),
            }
        };
        let mut covered = 0;
        for _ in 0..400 {
            let (a, b) = (random_bounds(&mut rng), random_bounds(&mut rng));
            let u = a.union(&b);
            for _ in 0..50 {
                let p = (rng.next_2d().extend(rng.next_f32()) - 0.5) * 10.0;
                let n = (rng.next_2d().extend(rng.next_f32()) - 0.5).normalize_or(Vec3::Y);
                if a.importance(p, n) > 0.0 || b.importance(p, n) > 0.0 {
                    covered += 1;
                    assert!(u.importance(p, n) > 0.0, "{a:?} ∪ {b:?} = {u:?} at {p}");
                }
            }
        }
        assert!(covered > 5_000, "{covered}");
        // Two opposite flat emitters: together they shine everywhere.
        let up = LightBounds::cone(Vec3::ZERO, 1.0, 1.0, Vec3::Y, 1.0, 0.0);
        let down = LightBounds::cone(Vec3::ZERO, 1.0, 1.0, -Vec3::Y, 1.0, 0.0);
        let both = up.union(&down);
        assert!(both.importance(Vec3::new(0.0, -5.0, 0.0), Vec3::ZERO) > 0.0);
        assert!(both.importance(Vec3::new(0.0, 5.0, 0.0), Vec3::ZERO) > 0.0);
    }
}
