//! Textures: values varying over a surface, looked up at a [`TexPoint`] (the surface's (u, v)
//! coordinates, plus the hit triangle and its barycentrics for Mitsuba's `mesh_attribute`).

use crate::spectrum::Rgb;
use glam::{Mat3, Vec2};
use std::sync::Arc;

/// Where a texture is looked up: the texture coordinates and, on a triangle mesh, the hit
/// triangle and its barycentrics. `mesh_attribute` reads the latter; every other texture reads
/// `uv` only. Kept `Copy` and small (20 bytes) because every BSDF evaluation passes it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TexPoint {
    /// Texture coordinates.
    pub uv: Vec2,
    /// Index of the hit triangle within its mesh (0 on analytic shapes).
    pub prim: u32,
    /// Barycentric coordinates (b1, b2) of the hit in that triangle (weights of its second and
    /// third corners; zero on analytic shapes).
    pub bary: Vec2,
}

impl TexPoint {
    /// A point known by its uv only (analytic shapes, tests): triangle 0, barycentrics zero.
    #[inline]
    pub const fn at_uv(uv: Vec2) -> Self {
        TexPoint::new(uv, 0, Vec2::ZERO)
    }

    /// The point at `uv`, barycentrics `bary` in triangle `prim`.
    #[inline]
    pub const fn new(uv: Vec2, prim: u32, bary: Vec2) -> Self {
        TexPoint { uv, prim, bary }
    }
}

impl From<Vec2> for TexPoint {
    /// [`TexPoint::at_uv`].
    #[inline]
    fn from(uv: Vec2) -> Self {
        TexPoint::at_uv(uv)
    }
}

/// One mesh attribute (Mitsuba's `vertex_*` / `face_*`) bound to the mesh of one shape, laid
/// out per triangle so that a lookup needs only the hit's triangle index: a vertex attribute is
/// stored as the values at each triangle's three corners (in winding order), a face attribute as
/// one value per triangle (polygons fan-triangulated on load repeat their value).
#[derive(Debug, Clone, PartialEq)]
pub struct AttributeValues {
    /// The attribute's name (`vertex_color`, `face_weight`, …), for messages.
    pub name: String,
    /// Values per element: 1 (a grey value) or 3 (a colour).
    pub channels: usize,
    /// Constant over each triangle (`face_*`) rather than interpolated (`vertex_*`).
    pub per_face: bool,
    /// `channels` numbers per triangle (per face) or 3·`channels` per triangle (per vertex).
    pub values: Vec<f32>,
}

impl AttributeValues {
    /// The colour at `tp` (unscaled): the triangle's value, or the barycentric blend of its
    /// corners' values; a 1-channel attribute reads as a grey colour (Mitsuba's `eval`).
    #[inline]
    fn eval(&self, tp: TexPoint) -> Rgb {
        let ch = self.channels;
        let at = |i: usize| {
            if ch == 1 {
                Rgb::splat(self.values[i])
            } else {
                Rgb::new(self.values[i], self.values[i + 1], self.values[i + 2])
            }
        };
        let prim = tp.prim as usize;
        if self.per_face {
            at(prim * ch)
        } else {
            let i = prim * 3 * ch;
            let b0 = 1.0 - tp.bary.x - tp.bary.y;
            // Mitsuba: fmadd(v0, b0, fmadd(v1, b1, v2·b2)).
            at(i) * b0 + (at(i + ch) * tp.bary.x + at(i + 2 * ch) * tp.bary.y)
        }
    }

    /// Every stored value as a colour (a vertex attribute's corners, a face attribute's faces):
    /// interpolation stays within them, so their range bounds every lookup.
    fn elements(&self) -> impl Iterator<Item = Rgb> + '_ {
        self.values.chunks_exact(self.channels).map(|c| {
            if c.len() == 1 {
                Rgb::splat(c[0])
            } else {
                Rgb::new(c[0], c[1], c[2])
            }
        })
    }
}

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
    pub(crate) fn apply(self, i: i64, n: i64) -> i64 {
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
    /// Mitsuba's `mesh_attribute`: a per-vertex (interpolated) or per-face attribute of the
    /// mesh the texture is bound to, times `scale`. The importer binds one copy per shape.
    MeshAttribute {
        /// The attribute, laid out per triangle of the shape's mesh.
        values: Arc<AttributeValues>,
        /// Factor applied to every value (Mitsuba's `scale`).
        scale: f32,
    },
}

impl Texture {
    /// Width over height of the texture's image (Mitsuba's `resolution()` ratio): a bitmap's
    /// own, 1 for any other texture.
    pub fn aspect_ratio(&self) -> f32 {
        match self {
            Texture::Bitmap { image, .. } => image.width as f32 / image.height as f32,
            _ => 1.0,
        }
    }

    /// Whether every value the texture can take is finite and non-negative (a valid emitted
    /// radiance).
    pub fn is_finite_non_negative(&self) -> bool {
        let ok = |c: &Rgb| c.is_finite() && c.min_element() >= 0.0;
        match self {
            Texture::Constant(c) => ok(c),
            Texture::Checkerboard { color0, color1, .. } => ok(color0) && ok(color1),
            Texture::Bitmap { image, .. } => image.texels.iter().all(ok),
            Texture::MeshAttribute { values, scale } => {
                values.elements().all(|c| ok(&(c * *scale)))
            }
        }
    }

    /// The texture as one number at `at`, as Mitsuba's `eval_1`: a grey value as it is, a
    /// colour by its luminance; NaN reads as 0.
    #[inline]
    pub fn eval_1(&self, at: impl Into<TexPoint>) -> f32 {
        scalar_of(self.eval(at))
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
            Texture::MeshAttribute { values, scale } => values
                .elements()
                .map(|c| c * *scale)
                .fold(init, |acc, c| fold(acc, &c)),
        }
    }

    /// Whether the texture is the same everywhere.
    pub fn is_constant(&self) -> bool {
        matches!(self, Texture::Constant(_))
    }

    /// The colour at `at` (texture coordinates, or a point of a mesh: a bare `Vec2` uv
    /// converts).
    #[inline]
    pub fn eval(&self, at: impl Into<TexPoint>) -> Rgb {
        let tp = at.into();
        let uv = tp.uv;
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
            Texture::MeshAttribute { values, scale } => values.eval(tp) * *scale,
        }
    }

    /// The gradient (∂/∂u, ∂/∂v) of [`Texture::eval_1`] at `uv`, as Mitsuba's `eval_1_grad`
    /// (which `bumpmap` reads): for a bilinear bitmap the derivative of the interpolated
    /// luminance, through `to_uv`; zero where the texture is piecewise constant (constants,
    /// checkerboards, nearest-neighbour bitmaps — Mitsuba implements it for bitmaps only).
    pub fn eval_1_grad(&self, uv: Vec2) -> Vec2 {
        // `mesh_attribute` has no gradient (Mitsuba: not implemented); the importer refuses
        // it as a bump map's height, so it reads as flat here like the other non-bitmaps.
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

    /// The mean colour (used for albedo estimates and light power; for a mesh attribute the
    /// unweighted mean of its stored values — triangle corners or faces — times `scale`).
    pub fn mean(&self) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checkerboard { color0, color1, .. } => 0.5 * (*color0 + *color1),
            Texture::Bitmap { image, .. } => {
                let n = image.texels.len().max(1) as f32;
                image.texels.iter().copied().sum::<Rgb>() / n
            }
            Texture::MeshAttribute { values, scale } => {
                let n = (values.values.len() / values.channels).max(1) as f32;
                values.elements().sum::<Rgb>() / n * *scale
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
