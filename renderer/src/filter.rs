//! Pixel reconstruction filters (Mitsuba 3's `rfilter` plugins: `box`, `gaussian`, `tent`,
//! `mitchell`, `catmullrom`, `lanczos`), applied by *filter importance sampling*.
//!
//! Mitsuba splats every sample into the pixels around it with the filter's weights and divides
//! by the summed weights. Here each pixel instead draws its own sample positions from the
//! filter centred on it (restricted to the image, as Mitsuba only takes samples inside it
//! unless `sample_border` is set), so pixels stay independent — each with its own random
//! stream, which is what keeps renders deterministic for any thread count and lets SPPM keep
//! per-pixel state — and the converged value is the same: the filter-weighted mean of the
//! radiance around the pixel centre over the image. A filter with negative lobes is sampled in
//! proportion to its absolute value and each sample carries the sign of the filter there,
//! times the ratio of the filter's absolute and signed integrals over the sampled interval.
//!
//! The filters are separable (f(x, y) = f(x)·f(y)); each axis is a table of the filter over
//! [−radius, radius] in [`TABLE_BINS`] equal bins (the filter at each bin's centre), sampled
//! exactly as that piecewise-constant function — the same kind of table Mitsuba's own CPU
//! variants splat with, here 66 times finer.

use glam::{UVec2, Vec2};

/// Bins of the tabulated filter over its whole support [−radius, radius].
pub const TABLE_BINS: usize = 2048;

/// A reconstruction filter as a scene names it (the parameters in Mitsuba's words).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FilterDesc {
    /// `box`: every sample lands in one pixel (radius ½).
    Box,
    /// `gaussian`: exp(−x²/2σ²) minus its value at the cut-off 4σ (`stddev` σ, default 0.5).
    Gaussian {
        /// `stddev` in pixels.
        stddev: f32,
    },
    /// `tent`: max(0, 1 − |x|/radius) (`radius`, default 1).
    Tent {
        /// `radius` in pixels.
        radius: f32,
    },
    /// `mitchell` (`B`, `C`, default ⅓ each; radius 2) and `catmullrom` (B = 0, C = ½).
    Mitchell {
        /// `B` of Mitchell and Netravali.
        b: f32,
        /// `C` of Mitchell and Netravali.
        c: f32,
    },
    /// `lanczos`: sinc(x)·sinc(x/lobes) over |x| ≤ `lobes` (default 3).
    Lanczos {
        /// `lobes`.
        lobes: u32,
    },
}

impl FilterDesc {
    /// Mitsuba's default filter (a film without `<rfilter>`).
    pub const MITSUBA_DEFAULT: FilterDesc = FilterDesc::Gaussian { stddev: 0.5 };

    /// The filter as Mitsuba's XML would name it, with its parameters.
    pub fn describe(&self) -> String {
        match *self {
            FilterDesc::Box => "box".into(),
            FilterDesc::Gaussian { stddev } => format!("gaussian (stddev {stddev})"),
            FilterDesc::Tent { radius } => format!("tent (radius {radius})"),
            FilterDesc::Mitchell { b, c } if b == 0.0 && c == 0.5 => "catmullrom".into(),
            FilterDesc::Mitchell { b, c } => format!("mitchell (B {b}, C {c})"),
            FilterDesc::Lanczos { lobes } => format!("lanczos ({lobes} lobes)"),
        }
    }

    /// Half width of the support in pixels.
    pub fn radius(&self) -> f64 {
        match *self {
            FilterDesc::Box => 0.5,
            FilterDesc::Gaussian { stddev } => 4.0 * stddev as f64,
            FilterDesc::Tent { radius } => radius as f64,
            FilterDesc::Mitchell { .. } => 2.0,
            FilterDesc::Lanczos { lobes } => lobes as f64,
        }
    }

    /// The filter's value at offset `x` (pixels) from the pixel centre, as Mitsuba's `eval`.
    pub fn eval(&self, x: f64) -> f64 {
        let x = x.abs();
        match *self {
            FilterDesc::Box => {
                if x <= 0.5 {
                    1.0
                } else {
                    0.0
                }
            }
            FilterDesc::Gaussian { stddev } => {
                let alpha = -1.0 / (2.0 * (stddev as f64).powi(2));
                let bias = (alpha * self.radius().powi(2)).exp();
                ((alpha * x * x).exp() - bias).max(0.0)
            }
            FilterDesc::Tent { radius } => (1.0 - x / radius as f64).max(0.0),
            FilterDesc::Mitchell { b, c } => {
                let (b, c) = (b as f64, c as f64);
                let (x2, x3) = (x * x, x * x * x);
                let v = if x < 1.0 {
                    (12.0 - 9.0 * b - 6.0 * c) * x3
                        + (-18.0 + 12.0 * b + 6.0 * c) * x2
                        + (6.0 - 2.0 * b)
                } else if x < 2.0 {
                    (-b - 6.0 * c) * x3
                        + (6.0 * b + 30.0 * c) * x2
                        + (-12.0 * b - 48.0 * c) * x
                        + (8.0 * b + 24.0 * c)
                } else {
                    0.0
                };
                v / 6.0
            }
            FilterDesc::Lanczos { lobes } => {
                let r = lobes as f64;
                if x < 1e-7 {
                    1.0
                } else if x > r {
                    0.0
                } else {
                    let x1 = std::f64::consts::PI * x;
                    let x2 = x1 / r;
                    x1.sin() * x2.sin() / (x1 * x2)
                }
            }
        }
    }
}

/// One axis of a tabulated filter: cumulative absolute and signed integrals over its bins.
#[derive(Debug, Clone)]
struct FilterTable {
    /// Half width of the support.
    radius: f64,
    /// Bin width.
    step: f64,
    /// `abs_cdf[i]` = ∫|f| from −radius to the start of bin i (length bins + 1).
    abs_cdf: Vec<f64>,
    /// `signed_cdf[i]` = ∫f over the same range.
    signed_cdf: Vec<f64>,
    /// Some bin is negative: samples carry signed weights.
    signed: bool,
}

impl FilterTable {
    fn new(desc: &FilterDesc) -> Self {
        let radius = desc.radius();
        let step = 2.0 * radius / TABLE_BINS as f64;
        let mut abs_cdf = Vec::with_capacity(TABLE_BINS + 1);
        let mut signed_cdf = Vec::with_capacity(TABLE_BINS + 1);
        let (mut a, mut s) = (0.0f64, 0.0f64);
        abs_cdf.push(0.0);
        signed_cdf.push(0.0);
        let mut signed = false;
        for i in 0..TABLE_BINS {
            let v = desc.eval(-radius + (i as f64 + 0.5) * step);
            signed |= v < 0.0;
            a += v.abs() * step;
            s += v * step;
            abs_cdf.push(a);
            signed_cdf.push(s);
        }
        FilterTable {
            radius,
            step,
            abs_cdf,
            signed_cdf,
            signed,
        }
    }

    /// Position of offset `x` in bins (clamped to the support).
    fn bin_position(&self, x: f64) -> (usize, f64) {
        let t = ((x + self.radius) / self.step).clamp(0.0, TABLE_BINS as f64);
        let i = (t as usize).min(TABLE_BINS - 1);
        (i, t - i as f64)
    }

    /// A cumulative table evaluated at offset `x` (linear within a bin: the table is
    /// piecewise constant).
    fn cumulative(&self, cdf: &[f64], x: f64) -> f64 {
        let (i, frac) = self.bin_position(x);
        cdf[i] + frac * (cdf[i + 1] - cdf[i])
    }

    /// Draws an offset in [lo, hi] ∩ [−radius, radius] with density ∝ |f|; returns it with the
    /// sample's weight: 1 for a non-negative filter, else sign(f) · ∫|f| / ∫f over the range.
    fn sample(&self, lo: f64, hi: f64, u: f32) -> (f64, f64) {
        let (lo, hi) = (lo.max(-self.radius), hi.min(self.radius));
        let (a_lo, a_hi) = (
            self.cumulative(&self.abs_cdf, lo),
            self.cumulative(&self.abs_cdf, hi),
        );
        let target = a_lo + u as f64 * (a_hi - a_lo);
        // The last bin starting at or below the target; zero-width bins are skipped because
        // partition_point passes over equal entries.
        let i = (self.abs_cdf.partition_point(|&c| c <= target).max(1) - 1).min(TABLE_BINS - 1);
        let mass = self.abs_cdf[i + 1] - self.abs_cdf[i];
        let frac = if mass > 0.0 {
            ((target - self.abs_cdf[i]) / mass).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let x = (-self.radius + (i as f64 + frac) * self.step).clamp(lo, hi);
        if !self.signed {
            return (x, 1.0);
        }
        let signed_mass =
            self.cumulative(&self.signed_cdf, hi) - self.cumulative(&self.signed_cdf, lo);
        let sign = if self.signed_cdf[i + 1] - self.signed_cdf[i] < 0.0 {
            -1.0
        } else {
            1.0
        };
        (x, sign * (a_hi - a_lo) / signed_mass)
    }
}

/// A filter ready to place samples: where in the film a pixel's sample lies, with its weight.
#[derive(Debug, Clone)]
pub struct PixelFilter {
    /// The filter as described.
    desc: FilterDesc,
    /// Its table (`None` for the box, which samples the pixel uniformly).
    table: Option<FilterTable>,
    /// Samples may fall outside the image (Mitsuba's `sample_border`).
    sample_border: bool,
}

impl PixelFilter {
    /// Tabulates `desc`; `sample_border` lets samples of edge pixels leave the image.
    pub fn new(desc: FilterDesc, sample_border: bool) -> Self {
        let table = match desc {
            FilterDesc::Box => None,
            _ => Some(FilterTable::new(&desc)),
        };
        PixelFilter {
            desc,
            table,
            sample_border,
        }
    }

    /// The filter as described.
    pub fn desc(&self) -> FilterDesc {
        self.desc
    }

    /// A sample position for `pixel` of a `resolution` film, in film pixels ((0, 0) the
    /// top-left corner of the image), drawn with `u` ∈ [0,1)², and the sample's weight (1
    /// unless the filter has negative lobes). The box filter returns `pixel + u`.
    #[inline]
    pub fn sample(&self, pixel: UVec2, resolution: UVec2, u: Vec2) -> (Vec2, f32) {
        let Some(table) = &self.table else {
            return (pixel.as_vec2() + u, 1.0);
        };
        let mut position = Vec2::ZERO;
        let mut weight = 1.0f64;
        for axis in 0..2 {
            let centre = pixel[axis] as f64 + 0.5;
            let (lo, hi) = if self.sample_border {
                (f64::NEG_INFINITY, f64::INFINITY)
            } else {
                (-centre, resolution[axis] as f64 - centre)
            };
            let (offset, w) = table.sample(lo, hi, u[axis]);
            position[axis] = (centre + offset) as f32;
            weight *= w;
        }
        (position, weight as f32)
    }
}

/// Every kind of filter with Mitsuba's default parameters (catmull-rom as Mitchell B = 0,
/// C = ½), for tests.
#[cfg(test)]
pub(crate) const TEST_FILTERS: [FilterDesc; 6] = [
    FilterDesc::Box,
    FilterDesc::Gaussian { stddev: 0.5 },
    FilterDesc::Tent { radius: 1.0 },
    FilterDesc::Mitchell {
        b: 1.0 / 3.0,
        c: 1.0 / 3.0,
    },
    FilterDesc::Mitchell { b: 0.0, c: 0.5 },
    FilterDesc::Lanczos { lobes: 3 },
];

/// What pixel column `x` of a `width`-pixel image shows of a step from 0 to 1 at film
/// position `edge`: ∫ f(X − c) over [edge, width] / ∫ f(X − c) over [0, width] (the filter
/// truncated to the image), by quadrature. For tests.
#[cfg(test)]
pub(crate) fn edge_response(filter: &FilterDesc, width: u32, edge: f64, x: u32) -> f64 {
    let c = x as f64 + 0.5;
    let n = 20_000;
    let (mut lit, mut all) = (0.0, 0.0);
    for i in 0..n {
        let pos = (i as f64 + 0.5) * width as f64 / n as f64;
        let f = filter.eval(pos - c);
        all += f;
        if pos > edge {
            lit += f;
        }
    }
    lit / all
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{rng_for, UniformSource};

    const ALL: [FilterDesc; 6] = TEST_FILTERS;

    /// Values Mitsuba 3.9.1 (`scalar_rgb`) gives for `rfilter.eval(x)` with default parameters
    /// (its Gaussian goes through Dr.Jit's fast `exp`: within 5·10⁻⁴ of the exact formula).
    #[test]
    fn filter_values_match_mitsuba() {
        let cases: [(FilterDesc, [f64; 4]); 5] = [
            // x = 0, 0.3, 1.1, 1.9
            (ALL[1], [0.99924713, 0.83504784, 0.08858962, 0.00038788]),
            (ALL[2], [1.0, 0.7, 0.0, 0.0]),
            (ALL[3], [0.88888896, 0.74038899, 0.01349995, -0.00294425]),
            (ALL[4], [1.0, 0.81550002, -0.04049985, -0.00450023]),
            (ALL[5], [1.0, 0.84434313, -0.07091677, -0.02376987]),
        ];
        for (desc, expected) in cases {
            for (x, e) in [0.0, 0.3, 1.1, 1.9].iter().zip(expected) {
                let v = desc.eval(*x);
                assert!((v - e).abs() < 5e-4, "{desc:?} at {x}: {v} vs Mitsuba {e}");
            }
        }
        // Non-default parameters: gaussian stddev 0.3, tent radius 1.5, mitchell B 0.2 C 0.4,
        // lanczos 2 lobes, at x = 0.3 and 1.1.
        let cases: [(FilterDesc, [f64; 2]); 4] = [
            (
                FilterDesc::Gaussian { stddev: 0.3 },
                [0.60644001, 0.00088248],
            ),
            (FilterDesc::Tent { radius: 1.5 }, [0.79999995, 0.26666665]),
            (
                FilterDesc::Mitchell { b: 0.2, c: 0.4 },
                [0.77043331, -0.00810024],
            ),
            (FilterDesc::Lanczos { lobes: 2 }, [0.82697457, -0.05111489]),
        ];
        for (desc, expected) in cases {
            for (x, e) in [0.3, 1.1].iter().zip(expected) {
                let v = desc.eval(*x);
                assert!((v - e).abs() < 5e-4, "{desc:?} at {x}: {v} vs Mitsuba {e}");
            }
        }
        assert_eq!(FilterDesc::Gaussian { stddev: 0.3 }.radius() as f32, 1.2);
    }

    /// Samples placed inside the image follow f(x)·f(y) restricted to the image: the weighted
    /// mean of test functions of the offset equals their filter-weighted integral, for a pixel
    /// in the middle and for a corner pixel (truncated support).
    #[test]
    fn weighted_samples_average_to_the_filter_integral() {
        let res = UVec2::new(16, 12);
        for desc in ALL {
            let filter = PixelFilter::new(desc, false);
            for pixel in [UVec2::new(8, 6), UVec2::new(0, 11)] {
                let centre = pixel.as_dvec2() + 0.5;
                // Test functions of the film position: 1, x, x², a step.
                let g = |p: glam::DVec2| {
                    [
                        1.0,
                        p.x - centre.x,
                        (p.y - centre.y).powi(2),
                        if p.x > centre.x + 0.2 { 1.0 } else { 0.0 },
                    ]
                };
                // Quadrature of f(x)f(y)·g over the image part of the support.
                let r = desc.radius();
                let n = 800;
                let mut num = [0.0f64; 4];
                let mut den = 0.0f64;
                for i in 0..n {
                    for j in 0..n {
                        let ox = -r + (i as f64 + 0.5) * 2.0 * r / n as f64;
                        let oy = -r + (j as f64 + 0.5) * 2.0 * r / n as f64;
                        let p = centre + glam::DVec2::new(ox, oy);
                        if p.x < 0.0 || p.y < 0.0 || p.x > res.x as f64 || p.y > res.y as f64 {
                            continue;
                        }
                        let f = desc.eval(ox) * desc.eval(oy);
                        den += f;
                        for (k, v) in g(p).iter().enumerate() {
                            num[k] += f * v;
                        }
                    }
                }
                let mut rng = rng_for(7, 0, (pixel.x * 100 + pixel.y) as u64);
                let samples = 400_000;
                let mut sum = [0.0f64; 4];
                for _ in 0..samples {
                    let (p, w) = filter.sample(pixel, res, rng.next_2d());
                    assert!(p.x >= 0.0 && p.y >= 0.0 && p.x <= 16.0 && p.y <= 12.0);
                    for (k, v) in g(p.as_dvec2()).iter().enumerate() {
                        sum[k] += w as f64 * v;
                    }
                }
                for k in 0..4 {
                    let expected = num[k] / den;
                    let got = sum[k] / samples as f64;
                    let tolerance = if desc == FilterDesc::Box || k == 0 {
                        0.01
                    } else {
                        0.02
                    };
                    assert!(
                        (got - expected).abs() < tolerance,
                        "{desc:?} pixel {pixel} moment {k}: {got} vs {expected}"
                    );
                }
            }
        }
    }

    /// The box keeps the renderer's historical sample positions (pixel + u), and a
    /// non-negative filter gives every sample weight 1.
    #[test]
    fn box_is_the_pixel_and_positive_filters_have_unit_weights() {
        let res = UVec2::new(4, 4);
        let u = Vec2::new(0.25, 0.75);
        assert_eq!(
            PixelFilter::new(FilterDesc::Box, false).sample(UVec2::new(2, 1), res, u),
            (Vec2::new(2.25, 1.75), 1.0)
        );
        for desc in [ALL[1], ALL[2]] {
            let f = PixelFilter::new(desc, false);
            let mut rng = rng_for(3, 0, 0);
            for _ in 0..1000 {
                assert_eq!(f.sample(UVec2::new(0, 3), res, rng.next_2d()).1, 1.0);
            }
        }
    }

    /// With `sample_border`, an edge pixel's samples spread outside the image like an
    /// interior pixel's; without it they stay inside.
    #[test]
    fn sample_border_lets_samples_leave_the_image() {
        let res = UVec2::new(8, 8);
        let inside = PixelFilter::new(ALL[1], false);
        let border = PixelFilter::new(ALL[1], true);
        let mut rng = rng_for(5, 0, 0);
        let mut outside = 0;
        for _ in 0..10_000 {
            let u = rng.next_2d();
            let p = inside.sample(UVec2::ZERO, res, u).0;
            assert!(p.x >= 0.0 && p.y >= 0.0);
            let q = border.sample(UVec2::ZERO, res, u).0;
            outside += (q.x < 0.0) as u32;
        }
        // P(offset < −½): the filter's mass left of the image edge.
        let t = FilterTable::new(&ALL[1]);
        let expected = 10_000.0 * t.cumulative(&t.abs_cdf, -0.5) / t.abs_cdf[TABLE_BINS];
        assert!(
            (outside as f64 - expected).abs() < 5.0 * expected.sqrt(),
            "{outside} vs {expected}"
        );
        assert!(outside > 100, "{outside}");
    }
}
