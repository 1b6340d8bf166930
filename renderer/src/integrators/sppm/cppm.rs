//! The CPPM radius rule (chi-squared progressive photon mapping; Lin et al., SIGGRAPH Asia
//! 2020): the per-level state of one pixel ([`CppmLevel`]: radius, stage, photon counts in 12
//! equal-area cells of the kernel disk) and the Pearson χ² test that decides whether the radius
//! is kept or shrunk (docs/sppm.md, "CPPM radius schedule").
//!
//! Why a test: where the photon density is uniform inside the kernel the estimate has no
//! kernel bias, so shrinking the radius only adds variance. The counts are tested against
//! "equal expected count in every cell" on the full disk and on its inner half; an accepted
//! full disk keeps its radius (and keeps accumulating counts, so the test grows stronger), a
//! rejected one shrinks — to the inner disk when that one looks uniform, else by
//! [`AREA_FACTOR`] — and starts counting again against a threshold grown by
//! [`THRESHOLD_GROWTH`]. The estimator itself (the mean of per-pass kernel estimates) is the
//! SPPM one; only the radii differ.

use glam::Vec3;

use crate::frame::Frame;

/// Rings of the disk partition: split at |d|² = r²/2, so both rings have the same area.
pub const RINGS: usize = 2;
/// Equal angular sectors per ring, measured in the tangent plane from the shading tangent.
pub const SECTORS: usize = 6;
/// Cells of the partition ([`RINGS`] × [`SECTORS`], all of equal area); cells
/// `0..SECTORS` are the inner ring.
pub const CELLS: usize = RINGS * SECTORS;

/// n₀: photons a level must count before its first test (the authors' k-NN count of 10).
pub const MIN_PHOTONS: f64 = 10.0;
/// β: the count threshold is multiplied by this after every shrink (the authors' 1.5625 =
/// [`AREA_FACTOR`]⁻²; with it the all-reject schedule is SPPM's α = 2/3 rate, R² ∝ P^(−1/3)).
pub const THRESHOLD_GROWTH: f64 = 1.5625;
/// k: r² is multiplied by this when neither disk looks uniform (the authors' 0.8).
pub const AREA_FACTOR: f32 = 0.8;
/// r² is multiplied by this when only the inner disk looks uniform: the radius becomes the
/// inner disk's, r/√2.
pub const INNER_AREA_FACTOR: f32 = 0.5;
/// Significance level of both tests.
pub const SIGNIFICANCE: f64 = 0.05;
/// χ²₀.₉₅ with 11 degrees of freedom: the full disk's critical value (12 cells).
pub const CRITICAL_FULL: f64 = 19.67514;
/// χ²₀.₉₅ with 5 degrees of freedom: the inner disk's critical value (6 cells).
pub const CRITICAL_INNER: f64 = 11.07050;

/// One level's CPPM state at one pixel (56 bytes).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CppmLevel {
    /// Current squared radius; 0 until the pixel's first visible point.
    pub r2: f32,
    /// Shrinks so far; the count threshold is n₀·β^stage.
    pub stage: u32,
    /// Photons counted per cell since the last shrink ([`cell_index`] order). Saturating: an
    /// accepted disk never resets.
    pub cells: [u32; CELLS],
}

/// What the test at the start of a pass decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Fewer photons counted than the threshold: no test, nothing changes.
    Untested,
    /// The full disk looks uniform: radius and counts kept.
    Kept,
    /// Only the inner disk looks uniform: r² halved, counts reset, stage + 1.
    ShrunkToInner,
    /// Neither disk looks uniform: r² × [`AREA_FACTOR`], counts reset, stage + 1.
    Shrunk,
}

/// Pearson's X² of `counts` against equal expected counts: Σ(O − E)²/E with E = n/c, written
/// (c/n)·ΣO² − n. 0 when nothing was counted (nothing contradicts uniformity).
pub fn pearson_x2(counts: &[u32]) -> f64 {
    let n: f64 = counts.iter().map(|&o| o as f64).sum();
    if n == 0.0 {
        return 0.0;
    }
    let sum_sq: f64 = counts.iter().map(|&o| (o as f64) * (o as f64)).sum();
    counts.len() as f64 * sum_sq / n - n
}

/// Whether `counts` pass the uniformity test at [`SIGNIFICANCE`] against `critical`.
fn looks_uniform(counts: &[u32], critical: f64) -> bool {
    pearson_x2(counts) < critical
}

/// The cell of a photon at offset `d` (photon − visible point, world space) with squared
/// distance `d2` (the grid's, the kernel's own membership test) from a point with shading
/// frame `frame` and squared radius `r2`: ring 0 when 2·d2 < r2, sector from the angle of `d`
/// in the tangent plane measured from `frame.s` towards `frame.t` (the normal component is
/// ignored). Any frame works as long as one pass uses one; equal-area cells are what the test
/// needs.
#[inline]
pub fn cell_index(d: Vec3, d2: f32, frame: &Frame, r2: f32) -> usize {
    let ring = usize::from(2.0 * d2 >= r2);
    let mut phi = d.dot(frame.t).atan2(d.dot(frame.s));
    // atan2 gives (−π, π] (and −π for −0.0): map to [0, 2π); rounding can land on 2π, hence
    // the clamp to the last sector.
    if phi < 0.0 {
        phi += std::f32::consts::TAU;
    }
    let sector = ((phi * (SECTORS as f32 / std::f32::consts::TAU)) as usize).min(SECTORS - 1);
    ring * SECTORS + sector
}

/// The decision for `cells` once their total reached the threshold: the full disk first, and
/// on its rejection the inner disk.
pub fn decide(cells: &[u32; CELLS]) -> Decision {
    if looks_uniform(cells, CRITICAL_FULL) {
        Decision::Kept
    } else if looks_uniform(&cells[..SECTORS], CRITICAL_INNER) {
        Decision::ShrunkToInner
    } else {
        Decision::Shrunk
    }
}

impl CppmLevel {
    /// A level starting at squared radius `r2`.
    pub fn new(r2: f32) -> Self {
        CppmLevel {
            r2,
            ..CppmLevel::default()
        }
    }

    /// Photons counted since the last shrink.
    pub fn total(&self) -> u64 {
        self.cells.iter().map(|&c| c as u64).sum()
    }

    /// n₀·β^stage, by repeated multiplication (exact for the first stages, and the same bits
    /// on every platform, unlike `powf`). Stops growing once past any possible total.
    pub fn threshold(&self) -> f64 {
        let unreachable = (CELLS as f64) * (u32::MAX as f64) + 1.0;
        let mut t = MIN_PHOTONS;
        for _ in 0..self.stage {
            t *= THRESHOLD_GROWTH;
            if t > unreachable {
                break;
            }
        }
        t
    }

    /// Counts one photon into `cell`.
    #[inline]
    pub fn count(&mut self, cell: usize) {
        self.cells[cell] = self.cells[cell].saturating_add(1);
    }

    /// Runs the test when the counts reached the threshold and applies its decision: the
    /// radius the next gather uses. Run at the start of a pass, before gathering (an
    /// acceptance changes nothing and a rejection empties the counts, so testing again
    /// without new photons decides the same).
    pub fn test_and_update(&mut self) -> Decision {
        if self.r2 <= 0.0 || (self.total() as f64) < self.threshold() {
            return Decision::Untested;
        }
        let decision = decide(&self.cells);
        match decision {
            Decision::Untested | Decision::Kept => {}
            Decision::ShrunkToInner | Decision::Shrunk => {
                let factor = if decision == Decision::ShrunkToInner {
                    INNER_AREA_FACTOR
                } else {
                    AREA_FACTOR
                };
                self.r2 *= factor;
                self.cells = [0; CELLS];
                self.stage = self.stage.saturating_add(1);
            }
        }
        decision
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{rng_for, UniformSource};

    /// Cells from the design's listing: inner ring (sectors 0–5), then outer ring.
    fn cells(inner: [u32; 6], outer: [u32; 6]) -> [u32; CELLS] {
        let mut c = [0; CELLS];
        c[..6].copy_from_slice(&inner);
        c[6..].copy_from_slice(&outer);
        c
    }

    fn level_with(cells: [u32; CELLS]) -> CppmLevel {
        CppmLevel {
            r2: 1.0,
            stage: 0,
            cells,
        }
    }

    /// Hand-computed case A: near-uniform counts, X²_full = 2, X²_inner = 4/3: kept, counts
    /// and stage untouched.
    #[test]
    fn case_a_uniform_counts_keep_radius_and_counts() {
        let c = cells([3, 2, 4, 3, 2, 4], [3, 3, 2, 4, 3, 3]);
        assert!((pearson_x2(&c) - 2.0).abs() < 1e-12);
        assert!((pearson_x2(&c[..6]) - 4.0 / 3.0).abs() < 1e-12);
        let mut level = level_with(c);
        assert_eq!(level.test_and_update(), Decision::Kept);
        assert_eq!(level, level_with(c), "an acceptance changes nothing");
    }

    /// Case B: a uniform inner disk in a sparse outer ring: X²_full = 23.142857 > 19.67514,
    /// X²_inner = 2/3: r² halves, counts reset, threshold 10 → 15.625.
    #[test]
    fn case_b_uniform_inner_disk_halves_the_area() {
        let c = cells([6, 5, 7, 6, 5, 7], [1, 2, 1, 0, 1, 1]);
        assert!((pearson_x2(&c) - (12.0 * 228.0 / 42.0 - 42.0)).abs() < 1e-12);
        assert!((pearson_x2(&c) - 23.142857).abs() < 1e-6);
        assert!((pearson_x2(&c[..6]) - 2.0 / 3.0).abs() < 1e-12);
        let mut level = level_with(c);
        assert_eq!(level.test_and_update(), Decision::ShrunkToInner);
        assert_eq!(level.r2, 0.5);
        assert_eq!(level.cells, [0; CELLS]);
        assert_eq!(level.stage, 1);
        assert_eq!(level.threshold(), 15.625);
    }

    /// Case C: a shadow edge through the point (half the sectors empty in both rings):
    /// X²_full = 36, X²_inner = 18, both rejected: r² × 0.8.
    #[test]
    fn case_c_shadow_edge_shrinks_by_the_area_factor() {
        let c = cells([6, 6, 6, 0, 0, 0], [6, 6, 6, 0, 0, 0]);
        assert!((pearson_x2(&c) - 36.0).abs() < 1e-12);
        assert!((pearson_x2(&c[..6]) - 18.0).abs() < 1e-12);
        let mut level = level_with(c);
        assert_eq!(level.test_and_update(), Decision::Shrunk);
        assert_eq!(level.r2, 0.8);
        assert_eq!(level.cells, [0; CELLS]);
        assert_eq!(level.stage, 1);
    }

    /// Case D: nothing counted is uniform; below the threshold no test runs at all, however
    /// lopsided the counts; at it, the same counts shrink.
    #[test]
    fn case_d_empty_counts_pass_and_no_test_below_the_threshold() {
        assert_eq!(pearson_x2(&[0; CELLS]), 0.0);
        assert_eq!(decide(&[0; CELLS]), Decision::Kept);
        let mut lopsided = [0; CELLS];
        lopsided[0] = 9;
        let mut level = level_with(lopsided);
        assert_eq!(level.test_and_update(), Decision::Untested);
        assert_eq!(level, level_with(lopsided));
        level.count(0);
        assert_eq!(level.test_and_update(), Decision::Shrunk);
        // A level not yet initialised is never tested.
        let mut unset = CppmLevel {
            r2: 0.0,
            ..level_with(lopsided)
        };
        unset.cells[0] = 100;
        assert_eq!(unset.test_and_update(), Decision::Untested);
    }

    /// The design's cell-index checks (r = 1, s = +x, t = +y), the ring boundary, and the
    /// −0.0 wrap of atan2.
    #[test]
    fn cell_index_follows_rings_and_sectors() {
        let frame = Frame {
            s: Vec3::X,
            t: Vec3::Y,
            n: Vec3::Z,
        };
        let at = |d: Vec3| cell_index(d, d.length_squared(), &frame, 1.0);
        assert_eq!(at(Vec3::new(0.5, 0.1, 0.0)), 0);
        assert_eq!(at(Vec3::new(-0.8, -0.1, 0.0)), 9);
        assert_eq!(
            at(Vec3::new(-1.0, -0.0, 0.0)),
            9,
            "φ = −π wraps to π: sector 3"
        );
        assert_eq!(
            at(Vec3::new(0.3, -1e-9, 0.0)),
            5,
            "just below +s: last sector"
        );
        // The normal component moves a photon between rings (3-D distance) but not sectors.
        assert_eq!(at(Vec3::new(0.1, 0.3, 0.0)), 1);
        assert_eq!(at(Vec3::new(0.1, 0.3, 0.7)), 7);
        // Ring boundary 2·d² = r²: outer.
        assert_eq!(cell_index(Vec3::X, 0.5, &frame, 1.0), 6);
        assert_eq!(cell_index(Vec3::X, 0.4999, &frame, 1.0), 0);
        // Every sector's centre, both rings; a rotated frame rotates the sectors.
        for ring in 0..RINGS {
            let r = if ring == 0 { 0.5 } else { 0.9 };
            for sector in 0..SECTORS {
                let phi = (sector as f32 + 0.5) * std::f32::consts::TAU / SECTORS as f32;
                let d = Vec3::new(r * phi.cos(), r * phi.sin(), 0.0);
                assert_eq!(at(d), ring * SECTORS + sector);
                let rotated = Frame {
                    s: Vec3::Y,
                    t: -Vec3::X,
                    n: Vec3::Z,
                };
                let d_rot = rotated.s * d.x + rotated.t * d.y;
                assert_eq!(
                    cell_index(d_rot, d_rot.length_squared(), &rotated, 1.0),
                    ring * SECTORS + sector
                );
            }
        }
    }

    /// Counts `photons` photons drawn by `place` (a point in the unit disk, or `None` when
    /// the field puts nothing there) into `level`'s cells, radius `sqrt(level.r2)`.
    fn deposit(
        level: &mut CppmLevel,
        photons: u32,
        rng: &mut impl UniformSource,
        field: impl Fn(Vec3) -> bool,
    ) {
        let frame = Frame {
            s: Vec3::X,
            t: Vec3::Y,
            n: Vec3::Z,
        };
        let r = level.r2.sqrt();
        for _ in 0..photons {
            // Uniform in the disk of radius r, kept where the field has light.
            let u = rng.next_2d();
            let (rho, phi) = (r * u.x.sqrt(), std::f32::consts::TAU * u.y);
            let d = Vec3::new(rho * phi.cos(), rho * phi.sin(), 0.0);
            if field(d) {
                level.count(cell_index(d, d.length_squared(), &frame, level.r2));
            }
        }
    }

    /// A uniform photon field mostly keeps the radius, a step edge through the point always
    /// shrinks it: 400 pixels, 60 passes of Poisson-ish photon counts proportional to the disk
    /// area (24 per pass at the initial radius).
    #[test]
    fn uniform_field_keeps_the_radius_and_a_step_edge_shrinks_it() {
        let passes = 60;
        let pixels = 400;
        let run = |field: &dyn Fn(Vec3) -> bool, pixel: u64| -> CppmLevel {
            let mut rng = rng_for(7, pixel, 0);
            let mut level = CppmLevel::new(1.0);
            for _ in 0..passes {
                level.test_and_update();
                // Photon density fixed in space: the count scales with the disk's area.
                let photons = (24.0 * level.r2).round() as u32;
                deposit(&mut level, photons, &mut rng, field);
            }
            level.test_and_update();
            level
        };
        let uniform: Vec<CppmLevel> = (0..pixels).map(|p| run(&|_| true, p)).collect();
        let kept = uniform.iter().filter(|l| l.r2 == 1.0).count();
        // Each test keeps a uniform disk with probability ≈ 0.95, but the counts grow with
        // every pass and are tested again; most pixels never shrink.
        assert!(
            kept as f64 > 0.6 * pixels as f64,
            "uniform field: only {kept} of {pixels} pixels kept their radius"
        );
        let mean_uniform: f64 = uniform.iter().map(|l| l.r2 as f64).sum::<f64>() / pixels as f64;
        eprintln!("uniform field: {kept} of {pixels} pixels kept r², mean r² {mean_uniform}");
        // A step edge through the point: light only where d.s > 0 (half of every ring).
        let edge: Vec<CppmLevel> = (0..pixels).map(|p| run(&|d| d.x > 0.0, p)).collect();
        assert!(
            edge.iter().all(|l| l.r2 < 0.5 && l.stage >= 3),
            "step edge: every pixel must shrink repeatedly: {:?}",
            edge.iter()
                .map(|l| (l.r2, l.stage))
                .max_by(|a, b| a.0.total_cmp(&b.0))
        );
        let mean_edge: f64 = edge.iter().map(|l| l.r2 as f64).sum::<f64>() / pixels as f64;
        assert!(
            mean_edge < 0.3 * mean_uniform,
            "mean r²: edge {mean_edge}, uniform {mean_uniform}"
        );
    }

    /// The all-reject schedule (every test rejects both disks: all photons in one cell) with a
    /// photon density fixed in space shrinks r² as P^(−1/3), SPPM's α = 2/3 rate: stage j has
    /// r² = 0.8^j and needs 10·1.5625^j photons at a rate ∝ r², i.e. ∝ (1.5625/0.8)^j passes.
    #[test]
    fn all_reject_schedule_follows_p_to_the_minus_one_third() {
        // Expected photons per pass at r² = 1; fractional counts carried over, so the field is
        // exactly density × area × passes.
        let rate = 4.0f64;
        let mut level = CppmLevel::new(1.0);
        let mut carried = 0.0f64;
        let mut log_points = Vec::new();
        for pass in 1..=2_000_000u64 {
            if level.test_and_update() == Decision::Shrunk {
                log_points.push(((pass as f64).ln(), (level.r2 as f64).ln()));
            }
            carried += rate * level.r2 as f64;
            let whole = carried.floor();
            carried -= whole;
            level.cells[0] = level.cells[0].saturating_add(whole as u32);
        }
        assert!(log_points.len() >= 15, "{} shrinks", log_points.len());
        // Least-squares slope of ln r² against ln P over the later stages.
        let tail = &log_points[log_points.len() / 2..];
        let n = tail.len() as f64;
        let (mx, my) = (
            tail.iter().map(|p| p.0).sum::<f64>() / n,
            tail.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let slope = tail.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>()
            / tail.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
        assert!(
            (slope + 1.0 / 3.0).abs() < 0.01,
            "log-log slope {slope}, expected −1/3"
        );
    }

    /// The threshold grows by β per stage, exactly for the first stages, and stops growing
    /// past any possible count.
    #[test]
    fn threshold_grows_by_beta_and_saturates() {
        let at = |stage| {
            CppmLevel {
                stage,
                ..CppmLevel::default()
            }
            .threshold()
        };
        assert_eq!(at(0), 10.0);
        assert_eq!(at(1), 15.625);
        assert_eq!(at(2), 24.4140625);
        assert_eq!(at(5), 10.0 * 1.5625f64.powi(5));
        assert!(at(u32::MAX).is_finite() && at(u32::MAX) > 12.0 * u32::MAX as f64);
    }
}
