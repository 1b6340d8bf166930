//! Projection light (Mitsuba's `projector`): a pinhole projecting an image along its local
//! +z, the reciprocal of a perspective camera with the same field of view.
//!
//! Parameters, in the XML's words: `irradiance` (a colour or texture: the irradiance on the
//! virtual image plane at z = 1 in front of the pinhole, default 1), `scale` (a factor on it,
//! default 1), `to_world` (position and orientation), `fov` + `fov_axis` or `focal_length` (as
//! the perspective camera; the image's aspect ratio is the texture's width over its height, 1
//! for a constant).
//!
//! As in Mitsuba, the radiant intensity in a direction through image point (u, v) is
//! π · scale · irradiance(u, v) / cos³θ (θ from the axis), so that the projection of a constant
//! image onto the plane z = 1 is the constant irradiance π · scale · irradiance; the image
//! point of a local position (x, y, z) is u = ½ − ½·x/(z·tan(fov_x/2)),
//! v = ½ − ½·aspect·y/(z·tan(fov_x/2)) (Mitsuba's `perspective_projection`). Photons leave
//! through image points chosen by the image's brightness (a grid of cells, with a uniform share
//! that keeps every lit point reachable), so a mostly dark slide does not waste them.

use super::bounds::LightBounds;
use super::{channel_mean, EmissionSample, LightSample};
use crate::math::Ray;
use crate::sampling::Distribution1D;
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::f32::consts::PI;

/// A projection light.
#[derive(Debug, Clone)]
pub struct ProjectorLight {
    /// The pinhole (the origin of `to_world`).
    pub position: Vec3,
    /// World-to-local map of points (the inverse of `to_world`).
    to_local: Mat4,
    /// Local-to-world map of directions (`to_world`'s 3×3 part).
    to_world_dir: Mat3,
    /// `to_world` applied to the local +z axis (not normalised: Mitsuba's `ds.n`).
    axis: Vec3,
    /// The projected image.
    irradiance: Texture,
    /// `scale`.
    scale: f32,
    /// tan(fov_x / 2).
    tan_half_fov: f32,
    /// Image width over height.
    aspect: f32,
    /// Area of the image rectangle on the plane z = 1: (2·tan)² / aspect.
    image_area: f32,
    /// Mean of the irradiance over the image (for the power).
    mean_irradiance: Rgb,
    /// Where photons leave: cells of an `IMAGE_CELLS`² grid over the image, by the brightest
    /// irradiance in each (with a uniform share); `None` for a constant image (uniform).
    photon_cells: Option<Distribution1D>,
}

/// Cells per side of the grid photons are importance-sampled by.
const IMAGE_CELLS: usize = 64;

/// The share of the photons spread uniformly over the image, so that every point where the
/// (filtered) image is not black keeps a non-zero density.
const UNIFORM_SHARE: f32 = 0.1;

impl ProjectorLight {
    /// Builds the light from `to_world`, the image, `scale` and the horizontal field of view in
    /// degrees.
    pub fn new(to_world: Mat4, irradiance: Texture, scale: f32, fov_x_deg: f32) -> Self {
        let aspect = irradiance.aspect_ratio();
        let tan_half_fov = (0.5 * fov_x_deg).to_radians().tan();
        let mut light = ProjectorLight {
            position: to_world.transform_point3(Vec3::ZERO),
            to_local: to_world.inverse(),
            to_world_dir: Mat3::from_mat4(to_world),
            axis: to_world.transform_vector3(Vec3::Z),
            irradiance,
            scale,
            tan_half_fov,
            aspect,
            image_area: 4.0 * tan_half_fov * tan_half_fov / aspect,
            mean_irradiance: Rgb::ZERO,
            photon_cells: None,
        };
        light.mean_irradiance = match &light.irradiance {
            Texture::Constant(c) => *c,
            // A midpoint grid over the image, as the photons sample it.
            t => {
                let n = 512;
                let mut acc = glam::DVec3::ZERO;
                for i in 0..n {
                    for j in 0..n {
                        let uv =
                            Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                        acc += t.eval(uv).as_dvec3();
                    }
                }
                (acc / (n * n) as f64).as_vec3()
            }
        };
        if !matches!(light.irradiance, Texture::Constant(_)) {
            light.photon_cells = Some(light.cell_distribution());
        }
        light
    }

    /// The photon distribution over the image's cells: each cell weighs the brightest of a 3×3
    /// stencil of its points (a mean would miss small bright features), mixed with a uniform
    /// share.
    fn cell_distribution(&self) -> Distribution1D {
        let n = IMAGE_CELLS;
        let mut brightest = Vec::with_capacity(n * n);
        for j in 0..n {
            for i in 0..n {
                let mut m = 0.0f32;
                for a in 0..3 {
                    for b in 0..3 {
                        let uv = Vec2::new(
                            (i as f32 + (a as f32 + 0.5) / 3.0) / n as f32,
                            (j as f32 + (b as f32 + 0.5) / 3.0) / n as f32,
                        );
                        m = m.max(channel_mean(self.irradiance.eval(uv)));
                    }
                }
                brightest.push(m);
            }
        }
        let total: f32 = brightest.iter().sum();
        let uniform = UNIFORM_SHARE / (n * n) as f32;
        let weights: Vec<f32> = brightest
            .iter()
            .map(|&m| {
                if total > 0.0 {
                    (1.0 - UNIFORM_SHARE) * m / total + uniform
                } else {
                    uniform
                }
            })
            .collect();
        Distribution1D::new(&weights)
    }

    /// An image point for `u` and its density over the image's unit square.
    fn sample_image(&self, u: Vec2) -> (Vec2, f32) {
        match &self.photon_cells {
            None => (u, 1.0),
            Some(cells) => {
                let n = IMAGE_CELLS;
                let (k, pmf, u_rest) = cells.sample(u.x);
                let (i, j) = (k % n, k / n);
                let uv = Vec2::new((i as f32 + u_rest) / n as f32, (j as f32 + u.y) / n as f32);
                (uv, pmf * (n * n) as f32)
            }
        }
    }

    /// The image point of a local position, if it lies in front of the pinhole and inside the
    /// image.
    fn image_point(&self, local: Vec3) -> Option<Vec2> {
        if local.z <= 0.0 {
            return None;
        }
        let k = 0.5 / (local.z * self.tan_half_fov);
        let uv = Vec2::new(0.5 - local.x * k, 0.5 - self.aspect * local.y * k);
        (uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all()).then_some(uv)
    }

    /// Direct illumination at `p` (Mitsuba's `sample_direction`).
    pub fn sample_li(&self, p: Vec3) -> Option<LightSample> {
        let local = self.to_local.transform_point3(p);
        let uv = self.image_point(local)?;
        let d = self.position - p;
        let dist = d.length();
        let wi = d / dist;
        let cos = -self.axis.dot(wi);
        let weight = self.irradiance.eval(uv) * (PI * self.scale / (local.z * local.z * cos));
        if cos <= 0.0 || cos.is_nan() || !weight.is_finite() {
            return None;
        }
        Some(LightSample {
            wi,
            p: self.position,
            dist,
            weight,
            pdf: 1.0,
            delta: true,
            infinite: false,
            light: 0,
        })
    }

    /// A photon through an image point sampled by `u` (by the image's brightness, as Mitsuba
    /// samples it, with a uniform share): flux π · scale · irradiance · image area / density
    /// (the intensity over the density of its direction).
    pub fn sample_emission(&self, u: Vec2) -> EmissionSample {
        let (uv, pdf) = self.sample_image(u);
        let local = Vec3::new(
            (1.0 - 2.0 * uv.x) * self.tan_half_fov,
            (1.0 - 2.0 * uv.y) * self.tan_half_fov / self.aspect,
            1.0,
        );
        let d = (self.to_world_dir * local).normalize();
        EmissionSample {
            ray: Ray::new(self.position, d),
            flux: self.irradiance.eval(uv) * (PI * self.scale * self.image_area / pdf),
            light: 0,
        }
    }

    /// Emission bounds for light selection: the power spread over the frustum's solid angle,
    /// within the narrowest cone about the axis that holds the frustum's corners, nothing
    /// outside it.
    pub fn bounds(&self) -> LightBounds {
        let (a, b) = (self.tan_half_fov, self.tan_half_fov / self.aspect);
        let solid_angle = 4.0 * (a * b / (1.0 + a * a + b * b).sqrt()).atan();
        let intensity = channel_mean(self.power()) / solid_angle;
        let axis = self.axis.normalize_or(Vec3::Z);
        // The frustum is the convex cone of its corner rays: a cone about `axis` narrower than
        // a hemisphere holds it when it holds the corners.
        let cos_o = [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)]
            .iter()
            .map(|&(x, y)| {
                let corner = self.to_world_dir * Vec3::new(x * a, y * b, 1.0);
                axis.dot(corner.normalize_or_zero())
            })
            .fold(1.0f32, f32::min);
        if cos_o <= 0.0 || !cos_o.is_finite() {
            return LightBounds::omnidirectional(self.position, 0.0, intensity);
        }
        LightBounds::cone(self.position, 0.0, intensity, axis, cos_o - 1e-5, 1.0)
    }

    /// Emitted power: π · scale · image area · mean irradiance.
    pub fn power(&self) -> Rgb {
        self.mean_irradiance * (PI * self.scale * self.image_area)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_checker as checker;
    use super::*;

    #[test]
    fn a_constant_image_lights_the_plane_at_unit_distance_evenly() {
        // Turned and moved: the pinhole at (1, 2, 3) looking along world −x.
        let to_world = Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0))
            * Mat4::from_rotation_y(-std::f32::consts::FRAC_PI_2);
        let light = ProjectorLight::new(to_world, Texture::Constant(Rgb::splat(2.0)), 1.5, 60.0);
        let t = 30f32.to_radians().tan();
        for (x, y) in [(0.0, 0.0), (0.9, 0.0), (-0.5, 0.7), (0.99, -0.99)] {
            let local = Vec3::new(x * t, y * t, 1.0);
            let p = to_world.transform_point3(local);
            let ls = light.sample_li(p).unwrap();
            // Irradiance on the plane z = 1 (normal along the axis): weight · cos.
            let cos = ls.wi.dot(-to_world.transform_vector3(Vec3::Z));
            let e = ls.weight * cos;
            assert!(
                (e - Rgb::splat(PI * 1.5 * 2.0)).abs().max_element() < 1e-4,
                "{e}"
            );
            // Twice as far: a quarter.
            let ls2 = light
                .sample_li(to_world.transform_point3(2.0 * local))
                .unwrap();
            assert!((ls2.weight * cos - e / 4.0).abs().max_element() < 1e-4);
        }
        // Outside the image or behind the pinhole: no light.
        assert!(light
            .sample_li(to_world.transform_point3(Vec3::new(1.1 * t, 0.0, 1.0)))
            .is_none());
        assert!(light
            .sample_li(to_world.transform_point3(Vec3::new(0.0, 0.0, -1.0)))
            .is_none());
    }

    #[test]
    fn the_image_maps_as_mitsubas_perspective_projection() {
        // fov 90° (tan = 1), aspect 1: local (x, y, 1) reads uv = ½ − ½·(x, y).
        let light = ProjectorLight::new(Mat4::IDENTITY, checker(), 1.0, 90.0);
        // (x, y) = (0.5, −0.25) → uv (0.25, 0.625): different halves → color1 (blue).
        let blue = light.sample_li(Vec3::new(0.5, -0.25, 1.0)).unwrap().weight;
        assert!(blue.z > 0.0 && blue.x == 0.0, "{blue}");
        // (−0.5, −0.25) → uv (0.75, 0.625): same half → color0 (red).
        let red = light.sample_li(Vec3::new(-0.5, -0.25, 1.0)).unwrap().weight;
        assert!(red.x > 0.0 && red.z == 0.0, "{red}");
        // Photons leave through the image point they carry: the direction maps back to it,
        // and the flux is π·scale·E·area over the point's density.
        for k in 0..64 {
            let u = Vec2::new((k % 8) as f32 / 8.0 + 0.06, (k / 8) as f32 / 8.0 + 0.06);
            let (uv, pdf) = light.sample_image(u);
            let e = light.sample_emission(u);
            let back = light.image_point(e.ray.d).unwrap();
            assert!((back - uv).abs().max_element() < 1e-5, "{back} vs {uv}");
            let want = checker().eval(uv) * (PI * light.image_area / pdf);
            assert!((e.flux - want).abs().max_element() < 1e-4 * want.max_element());
        }
    }

    #[test]
    fn photons_follow_the_image_and_carry_its_power() {
        // A slide dark but for a bright spot in one corner: most photons leave through the
        // spot, and their mean flux is still the light's power.
        let mut texels = vec![Rgb::ZERO; 16 * 8];
        texels[8 + 16 * 2] = Rgb::new(8.0, 4.0, 2.0);
        let image = std::sync::Arc::new(crate::texture::Bitmap {
            width: 16,
            height: 8,
            texels,
        });
        let slide = Texture::Bitmap {
            image,
            filter: crate::texture::BitmapFilter::Nearest,
            wrap: crate::texture::BitmapWrap::Clamp,
            to_uv: Mat3::IDENTITY,
        };
        let light = ProjectorLight::new(Mat4::IDENTITY, slide, 2.0, 50.0);
        assert_eq!(light.aspect, 2.0);
        // Stratified: fine in u.x, which picks the cell (the count of photons in the spot's
        // cells is what the estimate rests on), coarse in u.y.
        let (nx, ny) = (4096, 16);
        let mut sum = Rgb::ZERO;
        let mut lit = 0;
        for i in 0..nx {
            for j in 0..ny {
                let u = Vec2::new((i as f32 + 0.5) / nx as f32, (j as f32 + 0.5) / ny as f32);
                let e = light.sample_emission(u);
                sum += e.flux;
                lit += usize::from(e.flux.max_element() > 0.0);
            }
        }
        let mean = sum / (nx * ny) as f32;
        let power = light.power();
        assert!(
            (mean - power).abs().max_element() < 2e-3 * power.max_element(),
            "{mean} vs {power}"
        );
        // The spot covers 1/128 of the image; about 90 % of the photons leave through it.
        let share = lit as f32 / (nx * ny) as f32;
        assert!(share > 0.85 && share < 0.95, "{share}");
    }

    #[test]
    fn power_is_the_integral_of_the_intensity() {
        // Power = ∫ I dω, with I = π·scale·E/cos³θ: midpoint rule over directions in the
        // frustum, independent of the photon mapping.
        let light = ProjectorLight::new(Mat4::IDENTITY, checker(), 0.7, 50.0);
        let t = light.tan_half_fov;
        let n = 400;
        let mut acc = Rgb::ZERO;
        for i in 0..n {
            for j in 0..n {
                // A point on the plane z = 1 and its solid angle dA·cos³θ.
                let x = (2.0 * (i as f32 + 0.5) / n as f32 - 1.0) * t;
                let y = (2.0 * (j as f32 + 0.5) / n as f32 - 1.0) * t / light.aspect;
                let d = Vec3::new(x, y, 1.0);
                let cos = 1.0 / d.length();
                let da = light.image_area / (n * n) as f32;
                let uv = light.image_point(d).unwrap();
                acc += checker().eval(uv) * (PI * 0.7 / cos.powi(3)) * (da * cos.powi(3));
            }
        }
        let p = light.power();
        assert!(
            (p - acc).abs().max_element() < 1e-3 * p.max_element(),
            "{p} vs {acc}"
        );
        assert!((p.x - p.z).abs() < 1e-3 * p.x && p.y == 0.0);
    }
}
