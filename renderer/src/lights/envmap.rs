//! Environment map (Mitsuba's `envmap`): radiance arriving from every direction, looked up in
//! an equirectangular (latitude–longitude) image, bilinearly interpolated, times `scale`.
//!
//! Parameters as in the XML: `filename` (the image), `scale` (default 1), `to_world` (rotates
//! the map; the map's +y is up). Mapping, as Mitsuba 3: a world direction d is taken to the map
//! frame, v = to_world⁻¹·d, then u = atan2(v.x, −v.z) / 2π (0 at the poles) and t = acos(v.y) / π.
//! Column i's centre is at u = (i + ½) / width (columns wrap around: the last blends into the
//! first), row j's at t = j / (height − 1) (the first row is the +y pole, the last the −y pole).
//! Checked against Mitsuba 3.9.1's `eval` to float rounding (docs/validation.md).
//!
//! Sampling (NEE and photon emission) picks a cell of the interpolation grid — between the
//! centres of four neighbouring texels — with probability ∝ its largest texel luminance × its
//! solid angle, then a uniform point in it, so every direction with non-zero radiance has a
//! non-zero density (photons must reach everything the map lights).

use super::bounds::EmitterBounds;
use super::channel_mean;
use super::{EmissionSample, LightSample, SceneSphere};
use crate::math::Ray;
use crate::sampling::Distribution1D;
use crate::spectrum::{luminance, Rgb};
use crate::texture::Bitmap;
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;

/// An environment light from a latitude–longitude image.
#[derive(Debug, Clone)]
pub struct EnvmapLight {
    /// World → map frame (the inverse of `to_world`'s rotation).
    to_local: Mat3,
    /// Map frame → world.
    to_world: Mat3,
    /// Texels, row-major, `width` × `rows`, already multiplied by `scale`.
    texels: Vec<Rgb>,
    /// Image width (columns wrap around).
    width: usize,
    /// Texel rows (≥ 2; a one-row image is stored twice, which interpolates the same).
    rows: usize,
    /// Row of the cell grid (`rows − 1` of them), by the sum of its cells' weights.
    cell_rows: Distribution1D,
    /// Per cell row, the column of the cell (`width` of them).
    cell_columns: Vec<Distribution1D>,
    /// ∫ L dω over the sphere (RGB), from the cells' mean radiance.
    integral: Rgb,
}

/// Why an environment map cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EnvmapError {
    /// The image has no texels.
    #[error("the image is empty")]
    Empty,
    /// A texel is NaN, infinite or negative.
    #[error("texel ({x}, {y}) is {value:?}: radiance must be finite and non-negative")]
    BadTexel {
        /// Column.
        x: usize,
        /// Row (0 = top).
        y: usize,
        /// The value.
        value: [f32; 3],
    },
    /// `scale` is not a finite non-negative number.
    #[error("scale {0} must be finite and non-negative")]
    BadScale(f32),
    /// `to_world` does not map directions to directions (not a rotation).
    #[error("to_world must be a rotation (it may not scale, shear or mirror the map)")]
    NotARotation,
}

impl EnvmapLight {
    /// Whether [`Self::new`] accepts these parameters (cheap: no tables are built).
    pub fn check(image: &Bitmap, to_world: Mat3, scale: f32) -> Result<(), EnvmapError> {
        let (width, height) = (image.width as usize, image.height as usize);
        if width == 0 || height == 0 || image.texels.len() != width * height {
            return Err(EnvmapError::Empty);
        }
        if !scale.is_finite() || scale < 0.0 {
            return Err(EnvmapError::BadScale(scale));
        }
        // A rotation: orthonormal columns and determinant +1 (to rounding).
        let orthonormal = (to_world.transpose() * to_world - Mat3::IDENTITY)
            .to_cols_array()
            .iter()
            .all(|e| e.abs() < 1e-4);
        if !orthonormal || to_world.determinant() < 0.0 {
            return Err(EnvmapError::NotARotation);
        }
        match image
            .texels
            .iter()
            .position(|t| !t.is_finite() || t.min_element() < 0.0)
        {
            Some(k) => Err(EnvmapError::BadTexel {
                x: k % width,
                y: k / width,
                value: image.texels[k].to_array(),
            }),
            None => Ok(()),
        }
    }

    /// The light for `image` (linear RGB), rotated into the scene by `to_world` (whose
    /// translation is ignored: the map is at infinity) and multiplied by `scale`.
    pub fn new(image: &Bitmap, to_world: Mat3, scale: f32) -> Result<Self, EnvmapError> {
        Self::check(image, to_world, scale)?;
        let (width, height) = (image.width as usize, image.height as usize);
        let mut texels: Vec<Rgb> = image.texels.iter().map(|&t| t * scale).collect();
        let rows = if height == 1 {
            texels.extend_from_within(..);
            2
        } else {
            height
        };
        let texel = |x: usize, y: usize| texels[y * width + x % width];
        let mut row_weights = Vec::with_capacity(rows - 1);
        let mut cell_columns = Vec::with_capacity(rows - 1);
        let mut integral = Rgb::ZERO;
        let d_phi = 2.0 * PI / width as f32;
        for y in 0..rows - 1 {
            // Solid angle of a cell of this row: Δφ · (cos θ₀ − cos θ₁).
            let theta = |r: usize| PI * r as f32 / (rows - 1) as f32;
            let solid_angle = d_phi * (theta(y).cos() - theta(y + 1).cos()).max(0.0);
            let weights: Vec<f32> = (0..width)
                .map(|x| {
                    let corners = [
                        texel(x, y),
                        texel(x + 1, y),
                        texel(x, y + 1),
                        texel(x + 1, y + 1),
                    ];
                    integral += corners.iter().copied().sum::<Rgb>() * (0.25 * solid_angle);
                    let brightest = corners.iter().map(|&c| luminance(c)).fold(0.0, f32::max);
                    brightest * solid_angle
                })
                .collect();
            row_weights.push(weights.iter().map(|&w| w as f64).sum::<f64>() as f32);
            cell_columns.push(Distribution1D::new(&weights));
        }
        Ok(EnvmapLight {
            to_local: to_world.transpose(),
            to_world,
            texels,
            width,
            rows,
            cell_rows: Distribution1D::new(&row_weights),
            cell_columns,
            integral,
        })
    }

    /// Continuous texel coordinates (column, row) of world direction `d` (unit length), with
    /// texel centres at integers — columns in [0, width), rows in [0, rows − 1] — and sin θ.
    #[inline]
    fn image_coordinates(&self, d: Vec3) -> (f32, f32, f32) {
        let v = self.to_local * d;
        // Dr.Jit's atan2(±0, ±0) is 0 (Rust's may be π): the poles read column 0's edge.
        let u = if v.x == 0.0 && v.z == 0.0 {
            0.0
        } else {
            v.x.atan2(-v.z) * (0.5 / PI)
        };
        // Texel centres sit half a column in.
        let mut u = u - 0.5 / self.width as f32;
        u -= u.floor();
        let cos_theta = v.y.clamp(-1.0, 1.0);
        let t = cos_theta.acos() * (1.0 / PI);
        // sin θ from the other two components: accurate near the poles, unlike √(1 − cos²θ).
        let sin_theta = (v.x * v.x + v.z * v.z).sqrt();
        (u * self.width as f32, t * (self.rows - 1) as f32, sin_theta)
    }

    /// Radiance arriving from world direction `d` (unit length).
    #[inline]
    pub fn eval(&self, d: Vec3) -> Rgb {
        let (x, y, _) = self.image_coordinates(d);
        self.eval_at(x, y)
    }

    /// Bilinear radiance at continuous texel coordinates (texel centres at integers).
    #[inline]
    fn eval_at(&self, x: f32, y: f32) -> Rgb {
        let x0 = (x as usize).min(self.width - 1);
        let y0 = (y as usize).min(self.rows - 2);
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let x1 = (x0 + 1) % self.width;
        let at = |x: usize, y: usize| self.texels[y * self.width + x];
        let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
        let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x1, y0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Solid-angle density with which [`Self::sample_direction`] produces world direction `d`.
    #[inline]
    pub fn pdf_li(&self, d: Vec3) -> f32 {
        let (x, y, sin_theta) = self.image_coordinates(d);
        if sin_theta <= 0.0 {
            return 0.0;
        }
        let x0 = (x as usize).min(self.width - 1);
        let y0 = (y as usize).min(self.rows - 2);
        self.cell_density(x0, y0) / (2.0 * PI * PI * sin_theta)
    }

    /// Density over the unit square of image coordinates (u, t) inside cell (x, y).
    #[inline]
    fn cell_density(&self, x: usize, y: usize) -> f32 {
        self.cell_rows.pmf(y) * self.cell_columns[y].pmf(x) * (self.width * (self.rows - 1)) as f32
    }

    /// A world direction towards the map, drawn with density ∝ the cells' weights, its
    /// solid-angle density and the radiance from it; `None` on the (measure-zero) poles.
    #[inline]
    pub fn sample_direction(&self, u: Vec2) -> Option<(Vec3, f32, Rgb)> {
        let (y, _, ry) = self.cell_rows.sample(u.y);
        let (x, _, rx) = self.cell_columns[y].sample(u.x);
        let theta = PI * (y as f32 + ry) / (self.rows - 1) as f32;
        let phi = 2.0 * PI * (x as f32 + rx + 0.5) / self.width as f32;
        let (sin_theta, cos_theta) = theta.sin_cos();
        if sin_theta <= 0.0 {
            return None;
        }
        let (sin_phi, cos_phi) = phi.sin_cos();
        let local = Vec3::new(sin_theta * sin_phi, cos_theta, -sin_theta * cos_phi);
        let wi = (self.to_world * local).normalize();
        let pdf = self.cell_density(x, y) / (2.0 * PI * PI * sin_theta);
        if !(pdf.is_finite() && pdf > 0.0) {
            return None;
        }
        // The radiance where the sample landed, read from its texel coordinates (the direction's
        // own lookup would redo atan2/acos to reach the same point).
        Some((wi, pdf, self.eval_at(x as f32 + rx, y as f32 + ry)))
    }

    /// Direct illumination at `p`: a direction drawn from the map.
    pub fn sample_li(&self, p: Vec3, u: Vec2, sphere: &SceneSphere) -> Option<LightSample> {
        let (wi, pdf, radiance) = self.sample_direction(u)?;
        Some(LightSample {
            wi,
            p: p + wi * (2.0 * sphere.radius + (p - sphere.center).length()),
            dist: f32::INFINITY,
            weight: radiance / pdf,
            pdf,
            delta: false,
            infinite: true,
            light: 0,
        })
    }

    /// A photon arriving from a direction drawn from the map, starting on a disk that covers
    /// the scene's bounding sphere: flux L·πR² / pdf (zero on a failed draw).
    pub fn sample_emission(
        &self,
        u_dir: Vec2,
        u_pos: Vec2,
        sphere: &SceneSphere,
    ) -> EmissionSample {
        let Some((wi, pdf, radiance)) = self.sample_direction(u_dir) else {
            return EmissionSample {
                ray: Ray::new(sphere.center, Vec3::Y),
                flux: Rgb::ZERO,
                light: 0,
            };
        };
        EmissionSample {
            ray: Ray::new(sphere.photon_origin(-wi, u_pos), -wi),
            flux: radiance * (PI * sphere.radius * sphere.radius / pdf),
            light: 0,
        }
    }

    /// Emission bounds for light selection: a quarter of ∫L dω, the irradiance on one side of
    /// a surface averaged over orientations (π·L for a uniform map).
    pub fn bounds(&self) -> EmitterBounds {
        EmitterBounds::Environment {
            irradiance: 0.25 * channel_mean(self.integral),
        }
    }

    /// Power entering the bounding sphere, πR² ∫ L dω.
    pub fn power(&self, sphere: &SceneSphere) -> Rgb {
        self.integral * (PI * sphere.radius * sphere.radius)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{rng_for, square_to_uniform_sphere, UniformSource, UNIFORM_SPHERE_PDF};

    /// A `w`×`h` map with a smooth sky, a bright spot and a black band (radiance 0 somewhere).
    fn test_map(w: u32, h: u32) -> Bitmap {
        let mut texels = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let (fx, fy) = (x as f32 / w as f32, y as f32 / h as f32);
                let mut c = Rgb::new(0.2 + fx, 0.5 * (1.0 - fy), 0.1 + fy * fy);
                if (x, y) == (w / 3, h / 4) {
                    c = Rgb::new(40.0, 30.0, 20.0);
                }
                if y == h - 2 {
                    c = Rgb::ZERO;
                }
                texels.push(c);
            }
        }
        Bitmap {
            width: w,
            height: h,
            texels,
        }
    }

    /// Radiance of Mitsuba 3's `envmap` emitter: the data file
    /// `renderer/tests/data/envmap_reference.json`, written by `envmap_reference.py` there.
    #[derive(Debug, serde::Deserialize)]
    struct MitsubaReference {
        /// Image width and height of the test map (texels by the formula in the generator).
        size: (u32, u32),
        cases: Vec<ReferenceCase>,
        values: Vec<ReferenceValue>,
    }

    /// A case: the map's `scale` and the rotation of its `to_world` about +y in degrees.
    #[derive(Debug, serde::Deserialize)]
    struct ReferenceCase {
        scale: f32,
        degrees: f32,
    }

    /// The radiance a case's map sends along an escaping ray direction.
    #[derive(Debug, serde::Deserialize)]
    struct ReferenceValue {
        case: usize,
        direction: [f32; 3],
        radiance: [f32; 3],
    }

    /// Radiance equals Mitsuba 3's `envmap` for the same image, `scale` and `to_world`
    /// (values computed by Mitsuba itself, `envmap_reference.json`): texel centres, the seam,
    /// the poles. With a rotation, directions within ≈ 2.5° of a pole are skipped: Mitsuba's
    /// f32 rotation matrix is off by 10⁻⁷, enough to move the azimuth there.
    #[test]
    fn radiance_matches_mitsuba() {
        let reference: MitsubaReference = crate::test_data::read_json("envmap_reference.json");
        let (w, h) = reference.size;
        let texels = (0..h)
            .flat_map(|y| {
                (0..w).map(move |x| {
                    let (x, y) = (x as f32, y as f32);
                    Rgb::new(
                        1.0 + x + 0.1 * y,
                        2.0 + 0.5 * y + 0.05 * x,
                        0.3 + 0.2 * x * y,
                    )
                })
            })
            .collect();
        let image = Bitmap {
            width: w,
            height: h,
            texels,
        };
        let mut checked = 0;
        for (case, &ReferenceCase { scale, degrees }) in reference.cases.iter().enumerate() {
            let light =
                EnvmapLight::new(&image, Mat3::from_rotation_y(degrees.to_radians()), scale)
                    .unwrap();
            for &ReferenceValue {
                case: c,
                direction: d,
                radiance: want,
            } in reference.values.iter().filter(|v| v.case == case)
            {
                let d = Vec3::from(d);
                if degrees != 0.0 && d.y.abs() > 0.999 {
                    continue;
                }
                let got = light.eval(d);
                let want = Rgb::from(want);
                assert!(
                    (got - want).abs().max_element() <= 1e-4 * want.max_element(),
                    "case {c}, direction {d}: ours {got:?}, Mitsuba {want:?}"
                );
                checked += 1;
            }
        }
        assert!(checked > 150, "{checked}");
    }

    fn rotation() -> Mat3 {
        Mat3::from_rotation_y(0.7) * Mat3::from_rotation_x(-0.3)
    }

    /// Texel centres are where the mapping says: a direction built from (column, row) reads
    /// that texel exactly, including the wrap-around between the last and the first column.
    #[test]
    fn directions_of_texel_centres_read_those_texels() {
        let image = test_map(8, 5);
        let light = EnvmapLight::new(&image, rotation(), 2.0).unwrap();
        for y in 1..4 {
            for x in 0..8 {
                let theta = PI * y as f32 / 4.0;
                let phi = 2.0 * PI * (x as f32 + 0.5) / 8.0;
                let local = Vec3::new(
                    theta.sin() * phi.sin(),
                    theta.cos(),
                    -theta.sin() * phi.cos(),
                );
                let got = light.eval(rotation() * local);
                let want = image.texels[y * 8 + x] * 2.0;
                assert!(
                    (got - want).abs().max_element() < 1e-3 * (1.0 + want.max_element()),
                    "texel ({x}, {y}): {got:?} vs {want:?}"
                );
            }
        }
        // Half-way between the last and the first column (−z): their mean.
        let phi = 0.0f32;
        let theta = PI * 2.0 / 4.0;
        let local = Vec3::new(
            theta.sin() * phi.sin(),
            theta.cos(),
            -theta.sin() * phi.cos(),
        );
        let got = light.eval(rotation() * local);
        let want = (image.texels[2 * 8 + 7] + image.texels[2 * 8]) * 0.5 * 2.0;
        assert!(
            (got - want).abs().max_element() < 1e-3,
            "{got:?} vs {want:?}"
        );
    }

    /// Sampling matches its density: E[f(ω)/pdf(ω)] = ∫ f dω for f = the map itself (the
    /// estimator of the map's integral) and for f = 1 restricted to where the density is
    /// positive; `pdf_li` of a sampled direction equals the density it was drawn with.
    #[test]
    fn sampling_is_consistent_with_its_density() {
        let light = EnvmapLight::new(&test_map(16, 9), rotation(), 1.0).unwrap();
        let mut rng = rng_for(5, 0, 0);
        let n = 400_000;
        let mut est = Rgb::ZERO;
        for _ in 0..n {
            let Some((wi, pdf, l)) = light.sample_direction(rng.next_2d()) else {
                continue;
            };
            let again = light.pdf_li(wi);
            assert!((again - pdf).abs() <= 2e-3 * pdf, "{again} vs {pdf}");
            est += l / pdf;
        }
        est /= n as f32;
        // The same integral by uniform sphere sampling.
        let mut reference = Rgb::ZERO;
        for _ in 0..n {
            reference += light.eval(square_to_uniform_sphere(rng.next_2d())) / UNIFORM_SPHERE_PDF;
        }
        reference /= n as f32;
        for c in 0..3 {
            assert!(
                (est[c] - reference[c]).abs() < 0.03 * reference[c],
                "channel {c}: importance {est:?} vs uniform {reference:?}"
            );
        }
        // The density integrates to one over the sphere (uniform-sphere estimate).
        let mut total = 0.0f64;
        for _ in 0..n {
            total +=
                (light.pdf_li(square_to_uniform_sphere(rng.next_2d())) / UNIFORM_SPHERE_PDF) as f64;
        }
        let total = total / n as f64;
        assert!((total - 1.0).abs() < 0.02, "∫ pdf dω = {total}");
    }

    /// Wherever the map gives radiance, the density is positive (photons reach it), and the
    /// power matches the integral of the map.
    #[test]
    fn radiance_implies_positive_density() {
        let light = EnvmapLight::new(&test_map(16, 9), Mat3::IDENTITY, 1.0).unwrap();
        let mut rng = rng_for(6, 0, 0);
        for _ in 0..100_000 {
            let d = square_to_uniform_sphere(rng.next_2d());
            if light.eval(d).max_element() > 0.0 && d.y.abs() < 0.999_99 {
                assert!(light.pdf_li(d) > 0.0, "{d}");
            }
        }
    }

    /// Photons: their mean flux is the power (πR² ∫ L dω, by uniform-sphere quadrature), and
    /// every photon ray crosses the scene's bounding sphere.
    #[test]
    fn photon_flux_averages_to_the_power() {
        let light = EnvmapLight::new(&test_map(16, 9), rotation(), 1.5).unwrap();
        let sphere = SceneSphere {
            center: Vec3::new(0.5, -1.0, 2.0),
            radius: 3.0,
        };
        let mut rng = rng_for(8, 0, 0);
        let n = 400_000;
        let mut mean = Rgb::ZERO;
        for _ in 0..n {
            let e = light.sample_emission(rng.next_2d(), rng.next_2d(), &sphere);
            let to_center = sphere.center - e.ray.o;
            let off_axis = to_center - e.ray.d * to_center.dot(e.ray.d);
            assert!(off_axis.length() <= sphere.radius * (1.0 + 1e-4));
            mean += e.flux / n as f32;
        }
        let mut integral = Rgb::ZERO;
        for _ in 0..n {
            integral += light.eval(square_to_uniform_sphere(rng.next_2d()))
                / (UNIFORM_SPHERE_PDF * n as f32);
        }
        let want = integral * (PI * sphere.radius * sphere.radius);
        for c in 0..3 {
            assert!(
                (mean[c] - want[c]).abs() < 0.03 * want[c],
                "channel {c}: photons {mean:?}, quadrature {want:?}"
            );
        }
        let power = light.power(&sphere);
        assert!(
            (power - want).abs().max_element() < 0.05 * want.max_element(),
            "{power:?} vs {want:?}"
        );
    }

    /// A uniform map is the constant environment: radiance and density everywhere.
    #[test]
    fn uniform_map_is_a_constant_environment() {
        let image = Bitmap {
            width: 6,
            height: 1,
            texels: vec![Rgb::splat(0.5); 6],
        };
        let light = EnvmapLight::new(&image, Mat3::IDENTITY, 2.0).unwrap();
        let mut rng = rng_for(7, 0, 0);
        for _ in 0..1000 {
            let d = square_to_uniform_sphere(rng.next_2d());
            assert!((light.eval(d) - Rgb::ONE).abs().max_element() < 1e-5);
        }
        let sphere = SceneSphere {
            center: Vec3::ZERO,
            radius: 1.0,
        };
        let power = light.power(&sphere);
        let want = 4.0 * PI * PI;
        assert!((power.x - want).abs() < 1e-3 * want, "{power:?}");
    }

    #[test]
    fn bad_maps_are_refused_by_name() {
        let mut image = test_map(4, 3);
        image.texels[5] = Rgb::new(f32::NAN, 0.0, 0.0);
        let e = EnvmapLight::new(&image, Mat3::IDENTITY, 1.0).unwrap_err();
        assert!(matches!(e, EnvmapError::BadTexel { x: 1, y: 1, .. }), "{e}");
        let image = test_map(4, 3);
        assert_eq!(
            EnvmapLight::new(&image, Mat3::IDENTITY, -1.0).unwrap_err(),
            EnvmapError::BadScale(-1.0)
        );
        assert_eq!(
            EnvmapLight::new(&image, Mat3::from_diagonal(Vec3::new(1.0, 2.0, 1.0)), 1.0)
                .unwrap_err(),
            EnvmapError::NotARotation
        );
    }
}
