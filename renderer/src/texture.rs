//! Textures: values varying over a surface's (u, v) coordinates.

use crate::spectrum::Rgb;
use glam::{Mat3, Vec2};
use std::sync::Arc;

/// A linear-RGB image sampled by [`Texture::Bitmap`] (row 0 is the top row, as in files).
#[derive(Debug, Clone)]
pub struct Bitmap {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major linear-RGB texels (sRGB-encoded files are linearised on load unless `raw`).
    pub texels: Vec<Rgb>,
}

/// How a bitmap is filtered (Mitsuba's `filter_type`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BitmapFilter {
    /// Nearest texel.
    Nearest,
    /// Bilinear interpolation of the four nearest texels.
    Bilinear,
}

/// How texel indices outside the image are mapped back into it (Mitsuba's `wrap_mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BitmapWrap {
    /// Tile the image.
    Repeat,
    /// Tile the image, every other copy mirrored.
    Mirror,
    /// Extend the border texels.
    Clamp,
}

impl BitmapWrap {
    /// The texel index in `0..n` that index `i` reads.
    #[inline]
    fn apply(self, i: i64, n: i64) -> i64 {
        match self {
            BitmapWrap::Repeat => i.rem_euclid(n),
            BitmapWrap::Mirror => {
                let j = i.rem_euclid(2 * n);
                if j < n {
                    j
                } else {
                    2 * n - 1 - j
                }
            }
            BitmapWrap::Clamp => i.clamp(0, n - 1),
        }
    }
}

/// A colour as one number (Mitsuba's `eval_1`): a grey value as it is, a colour by its
/// luminance; NaN reads as 0.
fn scalar_of(c: Rgb) -> f32 {
    let v = if c.x == c.y && c.y == c.z {
        c.x
    } else {
        crate::spectrum::luminance(c)
    };
    if v.is_nan() {
        0.0
    } else {
        v
    }
}

/// A spatially varying colour, Mitsuba's texture plugins plus constants.
#[derive(Debug, Clone)]
pub enum Texture {
    /// The same colour everywhere (`<rgb>`, `<spectrum>` or `<float>` values).
    Constant(Rgb),
    /// Mitsuba's `checkerboard`: with (u', v') = to_uv·(u, v, 1), `color0` where the fractional
    /// parts of u' and v' are both ≤ ½ or both > ½, `color1` elsewhere (2×2 cells per unit square).
    Checkerboard {
        /// Colour of the first cell type.
        color0: Rgb,
        /// Colour of the second cell type.
        color1: Rgb,
        /// Affine uv transform (Mitsuba's `to_uv`).
        to_uv: Mat3,
    },
    /// Mitsuba's `bitmap`: an image looked up by uv exactly as Mitsuba 3 does: texel row
    /// ⌊v·height⌋ counted from the **top** row of the file (no flip here), wrapping by
    /// `wrap_mode`, bilinear filtering between texel centres. Mitsuba's OBJ/PLY loaders store `1 − v`, so the
    /// importers must do the same for textured meshes to come out upright.
    Bitmap {
        /// The decoded image.
        image: Arc<Bitmap>,
        /// Filtering mode.
        filter: BitmapFilter,
        /// Wrapping of texel indices outside the image.
        wrap: BitmapWrap,
        /// Affine uv transform (Mitsuba's `to_uv`).
        to_uv: Mat3,
    },
}

impl Texture {
    /// Whether every value the texture can take is finite and non-negative (a valid emitted
    /// radiance).
    pub fn is_finite_non_negative(&self) -> bool {
        let ok = |c: &Rgb| c.is_finite() && c.min_element() >= 0.0;
        match self {
            Texture::Constant(c) => ok(c),
            Texture::Checkerboard { color0, color1, .. } => ok(color0) && ok(color1),
            Texture::Bitmap { image, .. } => image.texels.iter().all(ok),
        }
    }

    /// The texture as one number at `uv`, as Mitsuba's `eval_1`: a grey value as it is, a
    /// colour by its luminance; NaN reads as 0.
    pub fn eval_1(&self, uv: Vec2) -> f32 {
        scalar_of(self.eval(uv))
    }

    /// The mean colour ([`Texture::mean`]) as one number, read as [`Texture::eval_1`] reads.
    pub fn mean_1(&self) -> f32 {
        scalar_of(self.mean())
    }

    /// The smallest and largest values [`Texture::eval_1`] can return (over the constant, the
    /// two checkerboard colours, or every texel: interpolation stays within them).
    pub fn scalar_range(&self) -> (f32, f32) {
        let fold = |(lo, hi): (f32, f32), c: &Rgb| {
            let v = scalar_of(*c);
            (lo.min(v), hi.max(v))
        };
        let init = (f32::INFINITY, f32::NEG_INFINITY);
        match self {
            Texture::Constant(c) => fold(init, c),
            Texture::Checkerboard { color0, color1, .. } => fold(fold(init, color0), color1),
            Texture::Bitmap { image, .. } => image.texels.iter().fold(init, fold),
        }
    }

    /// Whether the texture is the same everywhere.
    pub fn is_constant(&self) -> bool {
        matches!(self, Texture::Constant(_))
    }

    /// The colour at texture coordinates `uv`.
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checkerboard {
                color0,
                color1,
                to_uv,
            } => {
                let p = *to_uv * uv.extend(1.0);
                // Mitsuba: cells of size 0.5 in the transformed uv square.
                let x = p.x - p.x.floor();
                let y = p.y - p.y.floor();
                if (x > 0.5) == (y > 0.5) {
                    *color0
                } else {
                    *color1
                }
            }
            Texture::Bitmap {
                image,
                filter,
                wrap,
                to_uv,
            } => {
                let p = *to_uv * uv.extend(1.0);
                let (w, h) = (image.width as i64, image.height as i64);
                let fetch = |x: i64, y: i64| {
                    // Row 0 is the file's top row, reached at v ∈ [0, 1/h).
                    let x = wrap.apply(x, w);
                    let y = wrap.apply(y, h);
                    image.texels[(y * w + x) as usize]
                };
                let u = p.x * w as f32;
                let v = p.y * h as f32;
                match filter {
                    BitmapFilter::Nearest => fetch(u.floor() as i64, v.floor() as i64),
                    BitmapFilter::Bilinear => {
                        let (u, v) = (u - 0.5, v - 0.5);
                        let (x0, y0) = (u.floor(), v.floor());
                        let (fx, fy) = (u - x0, v - y0);
                        // Saturating: a huge uv (a degenerate `to_uv`) must not overflow.
                        let (x0, y0) = (x0 as i64, y0 as i64);
                        let a = fetch(x0, y0) * (1.0 - fx) + fetch(x0.saturating_add(1), y0) * fx;
                        let b = fetch(x0, y0.saturating_add(1)) * (1.0 - fx)
                            + fetch(x0.saturating_add(1), y0.saturating_add(1)) * fx;
                        a * (1.0 - fy) + b * fy
                    }
                }
            }
        }
    }

    /// The gradient (∂/∂u, ∂/∂v) of [`Texture::eval_1`] at `uv`, as Mitsuba's `eval_1_grad`
    /// (which `bumpmap` reads): for a bilinear bitmap the derivative of the interpolated
    /// luminance, through `to_uv`; zero where the texture is piecewise constant (constants,
    /// checkerboards, nearest-neighbour bitmaps — Mitsuba implements it for bitmaps only).
    pub fn eval_1_grad(&self, uv: Vec2) -> Vec2 {
        let Texture::Bitmap {
            image,
            filter: BitmapFilter::Bilinear,
            wrap,
            to_uv,
        } = self
        else {
            return Vec2::ZERO;
        };
        let p = *to_uv * uv.extend(1.0);
        let (w, h) = (image.width as i64, image.height as i64);
        let fetch = |x: i64, y: i64| {
            let (x, y) = (wrap.apply(x, w), wrap.apply(y, h));
            scalar_of(image.texels[(y * w + x) as usize])
        };
        let (u, v) = (p.x * w as f32 - 0.5, p.y * h as f32 - 0.5);
        let (x0, y0) = (u.floor(), v.floor());
        let (fx, fy) = (u - x0, v - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let (f00, f10) = (fetch(x0, y0), fetch(x0.saturating_add(1), y0));
        let (f01, f11) = (
            fetch(x0, y0.saturating_add(1)),
            fetch(x0.saturating_add(1), y0.saturating_add(1)),
        );
        // Per texel along x and y, then per unit of the transformed uv, then back through
        // the affine map's linear part (its transpose). Mitsuba 3.9.1 scales by the resolution
        // after the transpose instead, which differs only for a non-square image under a
        // `to_uv` that mixes u and v.
        let dx = (1.0 - fy) * (f10 - f00) + fy * (f11 - f01);
        let dy = (1.0 - fx) * (f01 - f00) + fx * (f11 - f10);
        let (dx, dy) = (dx * w as f32, dy * h as f32);
        let m = to_uv;
        Vec2::new(
            m.x_axis.x * dx + m.x_axis.y * dy,
            m.y_axis.x * dx + m.y_axis.y * dy,
        )
    }

    /// A cheap estimate of [`Texture::mean`] for per-sample use (lobe-selection weights): exact
    /// for constants and checkerboards, a fixed stride subsample of ≤ 64 texels for bitmaps.
    pub fn mean_estimate(&self) -> Rgb {
        match self {
            Texture::Bitmap { image, .. } if image.texels.len() > 64 => {
                let stride = image.texels.len().div_ceil(64);
                let (sum, count) = image
                    .texels
                    .iter()
                    .step_by(stride)
                    .fold((Rgb::ZERO, 0u32), |(s, c), t| (s + *t, c + 1));
                sum / count as f32
            }
            _ => self.mean(),
        }
    }

    /// The mean colour (used for albedo estimates and light power).
    pub fn mean(&self) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checkerboard { color0, color1, .. } => 0.5 * (*color0 + *color1),
            Texture::Bitmap { image, .. } => {
                let n = image.texels.len().max(1) as f32;
                image.texels.iter().copied().sum::<Rgb>() / n
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Texel indices past the edges, for a 3-texel row: repeat tiles, mirror reflects at each
    /// edge (the edge texel repeated once), clamp extends the border texel.
    #[test]
    fn wrap_modes_map_indices_into_the_image() {
        let at = |wrap: BitmapWrap| (-4..7).map(|i| wrap.apply(i, 3)).collect::<Vec<_>>();
        assert_eq!(at(BitmapWrap::Repeat), [2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0]);
        assert_eq!(at(BitmapWrap::Mirror), [2, 2, 1, 0, 0, 1, 2, 2, 1, 0, 0]);
        assert_eq!(at(BitmapWrap::Clamp), [0, 0, 0, 0, 0, 1, 2, 2, 2, 2, 2]);
    }

    /// Bilinear lookups across the edge blend with the texel the wrap mode names.
    #[test]
    fn bilinear_lookup_at_the_edge_follows_the_wrap_mode() {
        let image = Arc::new(Bitmap {
            width: 2,
            height: 1,
            texels: vec![Rgb::splat(1.0), Rgb::splat(3.0)],
        });
        let tex = |wrap| Texture::Bitmap {
            image: image.clone(),
            filter: BitmapFilter::Bilinear,
            wrap,
            to_uv: Mat3::IDENTITY,
        };
        // u = 0: half-way between texel −1 and texel 0.
        let u0 = Vec2::new(0.0, 0.5);
        assert_eq!(tex(BitmapWrap::Repeat).eval(u0), Rgb::splat(2.0));
        assert_eq!(tex(BitmapWrap::Mirror).eval(u0), Rgb::splat(1.0));
        assert_eq!(tex(BitmapWrap::Clamp).eval(u0), Rgb::splat(1.0));
        // u = 1: between texel 1 and texel 2.
        let u1 = Vec2::new(1.0, 0.5);
        assert_eq!(tex(BitmapWrap::Repeat).eval(u1), Rgb::splat(2.0));
        assert_eq!(tex(BitmapWrap::Mirror).eval(u1), Rgb::splat(3.0));
        assert_eq!(tex(BitmapWrap::Clamp).eval(u1), Rgb::splat(3.0));
    }
}
