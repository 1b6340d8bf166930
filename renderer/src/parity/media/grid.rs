//! Volume data for heterogeneous media: Mitsuba's `gridvolume` (a voxel grid read from a `.vol`
//! file, the binary format of Mitsuba 0.6 and 3) and `constvolume`, looked up in world space.
//!
//! A grid spans the unit cube of its local space (or, with `use_grid_bbox`, the bounding box
//! stored in the file), mapped into the world by `to_world`. Voxel values sit at cell centres,
//! as in Mitsuba's 3D textures: a lookup at local `p` reads `p·res − ½` trilinearly (or the
//! nearest cell), indices outside the grid mapped back by the wrap mode (default clamp).

use crate::spectrum::Rgb;
use crate::texture::BitmapWrap;
use glam::{Mat4, UVec3, Vec3};
use std::path::Path;
use std::sync::Arc;

/// Largest accepted number of voxel values (channels included): guards absurd headers.
const MAX_VALUES: u64 = 1 << 31;

/// How voxel values are interpolated (`filter_type`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GridFilter {
    /// `trilinear` (Mitsuba's default).
    Trilinear,
    /// `nearest`.
    Nearest,
}

/// The contents of a `.vol` file.
#[derive(Debug, Clone, PartialEq)]
pub struct VolFile {
    /// Cells along x, y, z.
    pub res: UVec3,
    /// Values per cell: 1 or 3.
    pub channels: u32,
    /// The bounding box stored in the file (min, max).
    pub bbox: (Vec3, Vec3),
    /// Values, x fastest, then y, then z, channels innermost.
    pub data: Vec<f32>,
}

/// Reads a `.vol` grid: "VOL", version 3, encoding 1 (float32), the resolution, the channel
/// count (1 or 3; Mitsuba's 6-channel grids hold spectral data this renderer does not use),
/// the bounding box, then the values, all little-endian. Errors say what is wrong.
pub fn read_vol(path: &Path) -> Result<VolFile, String> {
    let size = std::fs::metadata(path)
        .map_err(|e| format!("cannot read: {e}"))?
        .len();
    // The file's bytes and the decoded values are held at once.
    crate::memory::check_fits("the volume grid", 2 * size).map_err(|e| e.to_string())?;
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
    parse_vol(&bytes)
}

/// [`read_vol`] on the file's bytes.
pub fn parse_vol(bytes: &[u8]) -> Result<VolFile, String> {
    if bytes.len() < 48 || &bytes[..3] != b"VOL" {
        return Err("not a .vol grid (it must start with \"VOL\" and a 48-byte header)".into());
    }
    if bytes[3] != 3 {
        return Err(format!(
            "unsupported .vol version {} (expected 3)",
            bytes[3]
        ));
    }
    let int = |at: usize| i32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
    let float = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
    let encoding = int(4);
    if encoding != 1 {
        return Err(format!(
            "unsupported .vol encoding {encoding} (only 1, float32, is defined)"
        ));
    }
    let (x, y, z, channels) = (int(8), int(12), int(16), int(20));
    if x <= 0 || y <= 0 || z <= 0 {
        return Err(format!("invalid .vol resolution {x} x {y} x {z}"));
    }
    if channels != 1 && channels != 3 {
        return Err(format!(
            "unsupported .vol channel count {channels} (1 or 3 are supported)"
        ));
    }
    let count = x as u64 * y as u64 * z as u64 * channels as u64;
    if count > MAX_VALUES {
        return Err(format!("the .vol grid is too large ({count} values)"));
    }
    let expected = 48 + 4 * count;
    if (bytes.len() as u64) < expected {
        return Err(format!(
            "the .vol file is truncated: {} bytes, its header announces {expected}",
            bytes.len()
        ));
    }
    let bbox = (
        Vec3::new(float(24), float(28), float(32)),
        Vec3::new(float(36), float(40), float(44)),
    );
    let data: Vec<f32> = bytes[48..expected as usize]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect();
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(format!("value #{i} of the .vol grid is not finite"));
    }
    Ok(VolFile {
        res: UVec3::new(x as u32, y as u32, z as u32),
        channels: channels as u32,
        bbox,
        data,
    })
}

/// A voxel grid placed in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct VolumeGrid {
    /// The grid's values.
    pub file: VolFile,
    /// World → the grid's unit cube.
    pub to_local: Mat4,
    /// Interpolation.
    pub filter: GridFilter,
    /// Lookups outside the grid.
    pub wrap: BitmapWrap,
    /// World-space bounding box of the grid's unit cube.
    pub bounds: (Vec3, Vec3),
    /// Largest value over every cell and channel (no lookup exceeds it).
    pub max: f32,
    /// The file name (for messages).
    pub name: String,
}

impl VolumeGrid {
    /// Places `file` in the world: `to_world` maps the unit cube (or, with `use_grid_bbox`, the
    /// file's bounding box) into the scene.
    pub fn new(
        file: VolFile,
        to_world: Mat4,
        use_grid_bbox: bool,
        filter: GridFilter,
        wrap: BitmapWrap,
        name: String,
    ) -> Result<Self, String> {
        let box_to_unit = if use_grid_bbox {
            let (lo, hi) = file.bbox;
            let size = hi - lo;
            if !(size.min_element() > 0.0 && size.is_finite() && lo.is_finite()) {
                return Err(format!(
                    "use_grid_bbox: the file's bounding box {lo:?} .. {hi:?} is empty"
                ));
            }
            Mat4::from_scale(1.0 / size) * Mat4::from_translation(-lo)
        } else {
            Mat4::IDENTITY
        };
        if to_world.determinant().abs() < 1e-20 || !to_world.is_finite() {
            return Err("to_world is singular".into());
        }
        let to_local = box_to_unit * to_world.inverse();
        let (lo, hi) = unit_cube_bounds(to_local.inverse());
        let max = file.data.iter().fold(0.0f32, |m, &v| m.max(v));
        Ok(VolumeGrid {
            file,
            to_local,
            filter,
            wrap,
            bounds: (lo, hi),
            max,
            name,
        })
    }

    /// The value of cell (x, y, z) after the wrap mode, as a colour (one channel: grey).
    #[inline]
    fn cell(&self, x: i64, y: i64, z: i64) -> Rgb {
        let r = self.file.res;
        let x = self.wrap.apply(x, r.x as i64) as usize;
        let y = self.wrap.apply(y, r.y as i64) as usize;
        let z = self.wrap.apply(z, r.z as i64) as usize;
        let c = self.file.channels as usize;
        let i = ((z * r.y as usize + y) * r.x as usize + x) * c;
        let d = &self.file.data;
        if c == 1 {
            Rgb::splat(d[i])
        } else {
            Rgb::new(d[i], d[i + 1], d[i + 2])
        }
    }

    /// The grid's value at world point `p`.
    #[inline]
    pub fn eval(&self, p: Vec3) -> Rgb {
        let local = self.to_local.transform_point3(p);
        let res = self.file.res.as_vec3();
        let q = local * res - Vec3::splat(0.5);
        match self.filter {
            GridFilter::Nearest => {
                let i = (q + Vec3::splat(0.5)).floor();
                self.cell(i.x as i64, i.y as i64, i.z as i64)
            }
            GridFilter::Trilinear => {
                let f = q.floor();
                let w = q - f;
                let (x, y, z) = (f.x as i64, f.y as i64, f.z as i64);
                let lerp = |a: Rgb, b: Rgb, t: f32| a + (b - a) * t;
                let c00 = lerp(self.cell(x, y, z), self.cell(x + 1, y, z), w.x);
                let c10 = lerp(self.cell(x, y + 1, z), self.cell(x + 1, y + 1, z), w.x);
                let c01 = lerp(self.cell(x, y, z + 1), self.cell(x + 1, y, z + 1), w.x);
                let c11 = lerp(
                    self.cell(x, y + 1, z + 1),
                    self.cell(x + 1, y + 1, z + 1),
                    w.x,
                );
                lerp(lerp(c00, c10, w.y), lerp(c01, c11, w.y), w.z)
            }
        }
    }
}

/// The world-space bounding box of the unit cube mapped by `to_world` (Mitsuba's volume box).
pub fn unit_cube_bounds(to_world: Mat4) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for i in 0..8 {
        let c = Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32);
        let w = to_world.transform_point3(c);
        lo = lo.min(w);
        hi = hi.max(w);
    }
    (lo, hi)
}

/// Blocks per axis of a [`MajorantGrid`] (at most: never more than the grid has cells).
pub const MAJORANT_BLOCKS: u32 = 16;

/// Upper bounds of a grid's values (× a scale) over the blocks of a regular subdivision of a
/// world-space box: the local majorants that let delta and ratio tracking take long steps
/// through the thin parts of a medium instead of the densest voxel's short ones.
#[derive(Debug, Clone, PartialEq)]
pub struct MajorantGrid {
    /// The box's minimum corner.
    lo: Vec3,
    /// One block's size.
    block: Vec3,
    /// Blocks per axis.
    res: UVec3,
    /// Each block's bound, x fastest.
    max: Vec<f32>,
    /// The largest bound (for a last stretch that rounding leaves past the last block).
    global: f32,
}

impl MajorantGrid {
    /// Bounds of `grid` × `scale` over `bounds` (the grid's world box) cut into at most
    /// [`MAJORANT_BLOCKS`] blocks per axis. A block's bound is the largest value of every cell
    /// a lookup inside it can read: the cells under the block's box in grid space, one more on
    /// each side (trilinear neighbours), mapped by the wrap mode — so it holds for rotated
    /// grids and for the parts of the box outside the grid's own cube as well.
    pub fn new(grid: &VolumeGrid, bounds: (Vec3, Vec3), scale: f32) -> MajorantGrid {
        let cells = grid.file.res;
        let res = cells.min(UVec3::splat(MAJORANT_BLOCKS)).max(UVec3::ONE);
        let (lo, hi) = bounds;
        let block = (hi - lo) / res.as_vec3();
        let cell_res = cells.as_vec3();
        let mut max = Vec::with_capacity((res.x * res.y * res.z) as usize);
        for bz in 0..res.z {
            for by in 0..res.y {
                for bx in 0..res.x {
                    let b_lo = lo + block * Vec3::new(bx as f32, by as f32, bz as f32);
                    // The block's corners in cell coordinates (cell centres at integers).
                    let (mut q_lo, mut q_hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
                    for i in 0..8 {
                        let c = Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, (i >> 2) as f32);
                        let q = grid.to_local.transform_point3(b_lo + block * c) * cell_res
                            - Vec3::splat(0.5);
                        q_lo = q_lo.min(q);
                        q_hi = q_hi.max(q);
                    }
                    let range = |a: f32, b: f32, n: u32| -> Vec<i64> {
                        let (a, b) = (a.floor() as i64 - 1, b.floor() as i64 + 2);
                        let n = n as i64;
                        let mut idx: Vec<i64> = if b - a >= 2 * n {
                            (0..n).collect()
                        } else {
                            (a..=b).map(|i| grid.wrap.apply(i, n)).collect()
                        };
                        idx.sort_unstable();
                        idx.dedup();
                        idx
                    };
                    let (xs, ys, zs) = (
                        range(q_lo.x, q_hi.x, cells.x),
                        range(q_lo.y, q_hi.y, cells.y),
                        range(q_lo.z, q_hi.z, cells.z),
                    );
                    let c = grid.file.channels as usize;
                    let mut m = 0.0f32;
                    for &z in &zs {
                        for &y in &ys {
                            let row =
                                ((z as usize * cells.y as usize) + y as usize) * cells.x as usize;
                            for &x in &xs {
                                let i = (row + x as usize) * c;
                                for v in &grid.file.data[i..i + c] {
                                    m = m.max(*v);
                                }
                            }
                        }
                    }
                    max.push(m * scale);
                }
            }
        }
        let global = max.iter().fold(0.0f32, |m, &v| m.max(v));
        MajorantGrid {
            lo,
            block,
            res,
            max,
            global,
        }
    }

    /// Calls `f(t_start, t_end, bound)` for the consecutive stretches of `ray` between `t0` and
    /// `t1` (inside the box) that cross one block each, in order, until `f` returns false.
    pub fn segments(
        &self,
        o: Vec3,
        d: Vec3,
        t0: f32,
        t1: f32,
        mut f: impl FnMut(f32, f32, f32) -> bool,
    ) {
        let res = self.res.as_ivec3();
        let p = o + d * t0;
        let mut cell = ((p - self.lo) / self.block)
            .floor()
            .as_ivec3()
            .clamp(glam::IVec3::ZERO, res - 1);
        let mut next = Vec3::INFINITY;
        let mut delta = Vec3::INFINITY;
        let mut step = glam::IVec3::ZERO;
        for a in 0..3 {
            if d[a] > 0.0 {
                let edge = self.lo[a] + (cell[a] + 1) as f32 * self.block[a];
                next[a] = t0 + (edge - p[a]) / d[a];
                delta[a] = self.block[a] / d[a];
                step[a] = 1;
            } else if d[a] < 0.0 {
                let edge = self.lo[a] + cell[a] as f32 * self.block[a];
                next[a] = t0 + (edge - p[a]) / d[a];
                delta[a] = -self.block[a] / d[a];
                step[a] = -1;
            }
        }
        let mut t = t0;
        loop {
            let axis = if next.x <= next.y && next.x <= next.z {
                0
            } else if next.y <= next.z {
                1
            } else {
                2
            };
            let end = next[axis].min(t1);
            let i = ((cell.z * res.y + cell.y) * res.x + cell.x) as usize;
            if end > t && !f(t, end, self.max[i]) {
                return;
            }
            if end >= t1 {
                return;
            }
            t = end;
            cell[axis] += step[axis];
            if cell[axis] < 0 || cell[axis] >= res[axis] {
                // Only rounding leaves a stretch here: bound it by every block.
                f(t, t1, self.global);
                return;
            }
            next[axis] += delta[axis];
        }
    }
}

/// A spatially varying medium parameter: Mitsuba's `constvolume` (or a plain value) or
/// `gridvolume`.
#[derive(Debug, Clone, PartialEq)]
pub enum VolumeTexture {
    /// The same value everywhere.
    Constant(Rgb),
    /// Values from a voxel grid.
    Grid(Arc<VolumeGrid>),
}

impl VolumeTexture {
    /// The value at world point `p`.
    #[inline]
    pub fn eval(&self, p: Vec3) -> Rgb {
        match self {
            VolumeTexture::Constant(c) => *c,
            VolumeTexture::Grid(g) => g.eval(p),
        }
    }

    /// The value at world point `p` read as one number, as Mitsuba's `eval_1`: a constant's
    /// mean over its channels, a grid's one channel or the luminance of its three.
    #[inline]
    pub fn eval_1(&self, p: Vec3) -> f32 {
        match self {
            VolumeTexture::Constant(c) => (c.x + c.y + c.z) / 3.0,
            VolumeTexture::Grid(g) if g.file.channels == 1 => g.eval(p).x,
            VolumeTexture::Grid(g) => crate::spectrum::luminance(g.eval(p)),
        }
    }

    /// The largest value anywhere, over every channel.
    pub fn max(&self) -> f32 {
        match self {
            VolumeTexture::Constant(c) => c.max_element(),
            VolumeTexture::Grid(g) => g.max,
        }
    }

    /// The smallest value anywhere, over every channel.
    pub fn min(&self) -> f32 {
        match self {
            VolumeTexture::Constant(c) => c.min_element(),
            VolumeTexture::Grid(g) => g.file.data.iter().fold(f32::INFINITY, |m, &v| m.min(v)),
        }
    }
}

/// Writes a `.vol` file (tests and scene generators).
pub fn encode_vol(file: &VolFile) -> Vec<u8> {
    let mut out = Vec::with_capacity(48 + 4 * file.data.len());
    out.extend_from_slice(b"VOL");
    out.push(3);
    for v in [
        1,
        file.res.x as i32,
        file.res.y as i32,
        file.res.z as i32,
        file.channels as i32,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in file
        .bbox
        .0
        .to_array()
        .into_iter()
        .chain(file.bbox.1.to_array())
    {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in &file.data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(res: UVec3, channels: u32, data: Vec<f32>) -> VolFile {
        VolFile {
            res,
            channels,
            bbox: (Vec3::ZERO, Vec3::ONE),
            data,
        }
    }

    #[test]
    fn vol_files_round_trip_and_errors_say_what_is_wrong() {
        let f = file(UVec3::new(2, 3, 1), 3, (0..18).map(|i| i as f32).collect());
        let bytes = encode_vol(&f);
        assert_eq!(bytes.len(), 48 + 18 * 4);
        assert_eq!(parse_vol(&bytes).unwrap(), f);
        let err = |b: &[u8]| parse_vol(b).unwrap_err();
        assert!(err(b"PLY").contains("not a .vol grid"));
        assert!(
            err(&bytes[..100]).contains("truncated"),
            "{}",
            err(&bytes[..100])
        );
        let mut v = bytes.clone();
        v[3] = 2;
        assert!(err(&v).contains("version 2"));
        let mut v = bytes.clone();
        v[20] = 6;
        assert!(err(&v).contains("channel count 6"));
        let mut v = bytes.clone();
        v[4] = 2;
        assert!(err(&v).contains("encoding 2"));
        let mut v = bytes.clone();
        v[48..52].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(err(&v).contains("not finite"));
    }

    /// Values sit at cell centres: a 2×1×1 grid of 1 and 3 reads 1 up to the first centre
    /// (x = ¼, clamped beyond), 2 halfway, 3 from the second centre; nearest switches at ½.
    #[test]
    fn lookups_interpolate_between_cell_centres() {
        let grid = |filter| {
            VolumeGrid::new(
                file(UVec3::new(2, 1, 1), 1, vec![1.0, 3.0]),
                Mat4::IDENTITY,
                false,
                filter,
                BitmapWrap::Clamp,
                "test.vol".into(),
            )
            .unwrap()
        };
        let tri = grid(GridFilter::Trilinear);
        let at = |g: &VolumeGrid, x: f32| g.eval(Vec3::new(x, 0.5, 0.5)).x;
        assert_eq!(at(&tri, 0.1), 1.0);
        assert_eq!(at(&tri, 0.25), 1.0);
        assert_eq!(at(&tri, 0.5), 2.0);
        assert_eq!(at(&tri, 0.75), 3.0);
        assert_eq!(at(&tri, 0.95), 3.0);
        let near = grid(GridFilter::Nearest);
        assert_eq!(at(&near, 0.49), 1.0);
        assert_eq!(at(&near, 0.51), 3.0);
        assert_eq!(tri.max, 3.0);
        assert_eq!(tri.bounds, (Vec3::ZERO, Vec3::ONE));
    }

    /// Local majorants bound every lookup inside their block — for a rotated, repeating grid
    /// too, also in the corners of its world box that lie outside its own cube — and a single
    /// dense voxel leaves most blocks' bounds low; the blocks a ray crosses tile its stretch
    /// inside the box without gaps, in order.
    #[test]
    fn majorant_blocks_bound_every_lookup_and_tile_a_ray() {
        use crate::sampling::{Pcg32, UniformSource};
        let n = 32u32;
        let mut data = vec![0.1f32; (n * n * 4) as usize];
        data[5] = 9.0; // cell (5, 0, 0)
        let file = VolFile {
            res: UVec3::new(n, n, 4),
            channels: 1,
            bbox: (Vec3::ZERO, Vec3::ONE),
            data,
        };
        let cases = [
            (GridFilter::Trilinear, BitmapWrap::Clamp, Mat4::IDENTITY),
            (
                GridFilter::Trilinear,
                BitmapWrap::Repeat,
                Mat4::from_rotation_y(0.6) * Mat4::from_scale(Vec3::new(3.0, 1.0, 2.0)),
            ),
            (
                GridFilter::Nearest,
                BitmapWrap::Mirror,
                Mat4::from_rotation_z(-0.3),
            ),
        ];
        for (filter, wrap, to_world) in cases {
            let grid =
                VolumeGrid::new(file.clone(), to_world, false, filter, wrap, "m".into()).unwrap();
            let majorants = MajorantGrid::new(&grid, grid.bounds, 2.0);
            assert_eq!(majorants.res, UVec3::new(16, 16, 4));
            let (lo, hi) = grid.bounds;
            let bound_at = |p: Vec3| {
                let b = ((p - lo) / majorants.block)
                    .floor()
                    .as_uvec3()
                    .min(majorants.res - 1);
                majorants.max[((b.z * majorants.res.y + b.y) * majorants.res.x + b.x) as usize]
            };
            let mut rng = Pcg32::new(5, 9);
            for _ in 0..20_000 {
                let u = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                let p = lo + (hi - lo) * u;
                let v = grid.eval(p).x * 2.0;
                assert!(
                    v <= bound_at(p) * (1.0 + 1e-6),
                    "{v} > {} at {p:?}",
                    bound_at(p)
                );
            }
            let low = majorants.max.iter().filter(|&&m| m < 1.0).count();
            assert!(
                low > majorants.max.len() / 2,
                "{low} of {}",
                majorants.max.len()
            );
            // A ray from inside the box to its exit: contiguous stretches that cover it.
            let o = lo + (hi - lo) * 0.1;
            let d = Vec3::new(1.0, 0.7, 0.4).normalize();
            let t1 = ((hi - o) / d).min_element();
            let mut pieces = Vec::new();
            majorants.segments(o, d, 0.0, t1, |a, b, bound| {
                pieces.push((a, b, bound));
                true
            });
            assert!(pieces.len() > 10, "{}", pieces.len());
            assert_eq!(pieces[0].0, 0.0);
            assert!((pieces.last().unwrap().1 - t1).abs() < 1e-4 * t1);
            for w in pieces.windows(2) {
                assert_eq!(w[0].1, w[1].0);
            }
            for &(a, b, bound) in &pieces {
                let mid = o + d * (0.5 * (a + b));
                assert!(grid.eval(mid).x * 2.0 <= bound * (1.0 + 1e-6));
            }
        }
    }

    /// `to_world` places the unit cube; `use_grid_bbox` maps the file's box onto it first.
    #[test]
    fn grids_are_placed_by_to_world_and_the_file_box() {
        let mut f = file(UVec3::new(2, 1, 1), 1, vec![1.0, 3.0]);
        f.bbox = (Vec3::new(-1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 1.0));
        let to_world = Mat4::from_translation(Vec3::new(10.0, 0.0, 0.0));
        let g = VolumeGrid::new(
            f.clone(),
            to_world,
            true,
            GridFilter::Nearest,
            BitmapWrap::Clamp,
            "t".into(),
        )
        .unwrap();
        assert_eq!(
            g.bounds,
            (Vec3::new(9.0, 0.0, 0.0), Vec3::new(11.0, 1.0, 1.0))
        );
        assert_eq!(g.eval(Vec3::new(9.5, 0.5, 0.5)).x, 1.0);
        assert_eq!(g.eval(Vec3::new(10.5, 0.5, 0.5)).x, 3.0);
        let err = VolumeGrid::new(
            f,
            Mat4::ZERO,
            false,
            GridFilter::Nearest,
            BitmapWrap::Clamp,
            "t".into(),
        )
        .unwrap_err();
        assert!(err.contains("singular"));
    }
}
