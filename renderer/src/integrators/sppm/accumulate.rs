//! Per-pixel accumulation over passes: Welford running mean and variance of each level's
//! per-pass estimate, and pass-averaged G-buffer features.
//!
//! Every pass contributes exactly one sample per pixel and level (zero when nothing was seen),
//! so the pixel value is the mean over passes and the variance of that mean is the Welford
//! sample variance divided by the pass count.

use crate::spectrum::Rgb;
use glam::{DVec3, Vec3};

/// Welford's running mean and sum of squared deviations of an RGB sample stream (f64, so
/// thousands of passes lose no precision).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Welford {
    /// Number of samples.
    pub count: u32,
    /// Running mean.
    pub mean: DVec3,
    /// Sum of squared deviations from the mean.
    pub m2: DVec3,
}

impl Welford {
    /// Adds one sample.
    #[inline]
    pub fn push(&mut self, x: Rgb) {
        let x = x.as_dvec3();
        self.count += 1;
        let delta = x - self.mean;
        self.mean += delta / self.count as f64;
        self.m2 += delta * (x - self.mean);
    }

    /// Unbiased sample variance per channel (0 with fewer than two samples).
    #[inline]
    pub fn sample_variance(&self) -> DVec3 {
        if self.count < 2 {
            DVec3::ZERO
        } else {
            self.m2 / (self.count - 1) as f64
        }
    }

    /// Variance of the mean, averaged over R, G, B: the bundle's `variance.<level>` value.
    #[inline]
    pub fn variance_of_mean(&self) -> f32 {
        if self.count < 2 {
            return 0.0;
        }
        let v = self.sample_variance() / self.count as f64;
        ((v.x + v.y + v.z) / 3.0) as f32
    }

    /// The mean as f32 RGB.
    #[inline]
    pub fn mean_rgb(&self) -> Rgb {
        self.mean.as_vec3()
    }
}

/// G-buffer features of one pass at path A's visible point (zeros when the path escaped).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GBufferSample {
    /// BSDF albedo.
    pub albedo: Rgb,
    /// World-space shading normal.
    pub normal: Vec3,
    /// Distance along the camera path to the visible point.
    pub depth: f32,
}

/// Running sums of G-buffer features over passes (f64).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GBufferSum {
    /// Sum of albedos.
    pub albedo: DVec3,
    /// Sum of normals.
    pub normal: DVec3,
    /// Sum of depths.
    pub depth: f64,
}

impl GBufferSum {
    /// Adds one pass's features.
    #[inline]
    pub fn push(&mut self, s: &GBufferSample) {
        self.albedo += s.albedo.as_dvec3();
        self.normal += s.normal.as_dvec3();
        self.depth += s.depth as f64;
    }

    /// Average over `passes` passes.
    #[inline]
    pub fn average(&self, passes: u32) -> GBufferSample {
        let n = passes.max(1) as f64;
        GBufferSample {
            albedo: (self.albedo / n).as_vec3(),
            normal: (self.normal / n).as_vec3(),
            depth: (self.depth / n) as f32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welford_matches_two_pass_formula() {
        let xs = [1.0f32, 4.0, 2.5, -3.0, 10.0, 0.0, 7.25];
        let mut w = Welford::default();
        for (i, &x) in xs.iter().enumerate() {
            w.push(Rgb::new(x, 2.0 * x, i as f32));
        }
        let n = xs.len() as f64;
        let mean = xs.iter().map(|&x| x as f64).sum::<f64>() / n;
        let var = xs.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let idx_mean = (n - 1.0) / 2.0;
        let idx_var = (0..xs.len())
            .map(|i| (i as f64 - idx_mean).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        assert!((w.mean.x - mean).abs() < 1e-12);
        assert!((w.mean.y - 2.0 * mean).abs() < 1e-12);
        let v = w.sample_variance();
        assert!((v.x - var).abs() < 1e-9 && (v.y - 4.0 * var).abs() < 1e-9);
        assert!((v.z - idx_var).abs() < 1e-9);
        let expect = ((var + 4.0 * var + idx_var) / 3.0 / n) as f32;
        assert!((w.variance_of_mean() - expect).abs() < 1e-5 * expect);
    }

    #[test]
    fn single_sample_has_zero_variance() {
        let mut w = Welford::default();
        assert_eq!(w.variance_of_mean(), 0.0);
        w.push(Rgb::splat(3.0));
        assert_eq!(w.variance_of_mean(), 0.0);
        assert_eq!(w.mean_rgb(), Rgb::splat(3.0));
    }

    #[test]
    fn gbuffer_average() {
        let mut s = GBufferSum::default();
        s.push(&GBufferSample {
            albedo: Rgb::ONE,
            normal: Vec3::Z,
            depth: 2.0,
        });
        s.push(&GBufferSample::default());
        let a = s.average(2);
        assert_eq!(a.albedo, Rgb::splat(0.5));
        assert_eq!(a.normal, Vec3::new(0.0, 0.0, 0.5));
        assert_eq!(a.depth, 1.0);
    }
}
