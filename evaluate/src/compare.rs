//! Equal-time arithmetic: standard SPPM's error at an arbitrary wall time, interpolated
//! log-log between its checkpoints, and the summary statistics of a comparison.

use serde::{Deserialize, Serialize};

/// One point of a convergence curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Passes rendered.
    pub passes: u32,
    /// Wall-clock seconds to get this estimate.
    pub seconds: f64,
    /// relMSE against the reference.
    pub relmse: f64,
}

/// The error of a curve at `seconds`, and whether it had to be extrapolated.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Interpolated {
    /// Estimated relMSE at that time.
    pub relmse: f64,
    /// True if `seconds` lies outside the curve's time range (the nearest end point is used).
    pub extrapolated: bool,
}

/// relMSE of `curve` at `seconds`, linear in (log t, log relMSE) between the two checkpoints
/// around it. SPPM's error falls roughly as a power of time, a straight line on log-log axes,
/// so this is exact for a power law and close for the real curve when checkpoints are dense.
/// Outside the curve's range the nearest end point's error is returned, flagged.
/// `curve` must be sorted by time; returns `None` if it is empty.
pub fn relmse_at_time(curve: &[CurvePoint], seconds: f64) -> Option<Interpolated> {
    let first = curve.first()?;
    let last = curve.last()?;
    if seconds <= first.seconds {
        return Some(Interpolated {
            relmse: first.relmse,
            extrapolated: seconds < first.seconds,
        });
    }
    if seconds >= last.seconds {
        return Some(Interpolated {
            relmse: last.relmse,
            extrapolated: seconds > last.seconds,
        });
    }
    let i = curve.partition_point(|p| p.seconds <= seconds);
    let (a, b) = (curve[i - 1], curve[i]);
    let relmse = if a.relmse > 0.0 && b.relmse > 0.0 && b.seconds > a.seconds {
        let f = (seconds.ln() - a.seconds.ln()) / (b.seconds.ln() - a.seconds.ln());
        (a.relmse.ln() + f * (b.relmse.ln() - a.relmse.ln())).exp()
    } else {
        // A zero error cannot be put on a log axis: fall back to linear interpolation.
        let f = (seconds - a.seconds) / (b.seconds - a.seconds).max(f64::MIN_POSITIVE);
        a.relmse + f * (b.relmse - a.relmse)
    };
    Some(Interpolated {
        relmse,
        extrapolated: false,
    })
}

/// Median of finite values (mean of the two middle ones for an even count); `None` if none.
pub fn median(values: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// Geometric mean of positive finite values; `None` if none.
pub fn geometric_mean(values: &[f64]) -> Option<f64> {
    let logs: Vec<f64> = values
        .iter()
        .filter(|x| x.is_finite() && **x > 0.0)
        .map(|x| x.ln())
        .collect();
    if logs.is_empty() {
        return None;
    }
    Some((logs.iter().sum::<f64>() / logs.len() as f64).exp())
}

/// Checkpoints per doubling of the pass count in the standard run. The SPPM + OIDN peer is
/// denoised at the first checkpoint at or past ours' time, so the spacing is the most extra time
/// it can get: 2^(1/16) − 1 ≈ 4.4 %, up to 5.1 % with the counts' rounding above 64 passes.
/// Four per doubling gave it up to 19 % (9 % on average), which moved its win count on 30
/// scenes by ±3 with the machine's timing alone.
const CHECKPOINTS_PER_DOUBLING: f64 = 16.0;

/// Pass counts for the standard run's convergence curve: every configured count plus a
/// geometric series with [`CHECKPOINTS_PER_DOUBLING`] points per doubling, from 1 up to `cap`.
/// Dense checkpoints keep the log-log interpolation error small and the OIDN peer's time close
/// to ours.
pub fn dense_checkpoints(configured: &[u32], cap: u32) -> Vec<u32> {
    let mut out: Vec<u32> = configured.to_vec();
    let mut k = 0i32;
    loop {
        let p = 2f64.powf(k as f64 / CHECKPOINTS_PER_DOUBLING).round() as u32;
        if p > cap {
            break;
        }
        out.push(p);
        k += 1;
    }
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(seconds: f64, relmse: f64) -> CurvePoint {
        CurvePoint {
            passes: 0,
            seconds,
            relmse,
        }
    }

    #[test]
    fn power_law_is_interpolated_exactly() {
        // relMSE = 0.5 · t^(−2/3): a straight line on log-log axes.
        let f = |t: f64| 0.5 * t.powf(-2.0 / 3.0);
        let curve: Vec<CurvePoint> = [1.0, 2.0, 8.0, 32.0]
            .iter()
            .map(|&t| point(t, f(t)))
            .collect();
        for t in [1.0, 1.3, 2.0, 5.0, 31.9, 32.0] {
            let r = relmse_at_time(&curve, t).unwrap();
            assert!(!r.extrapolated);
            assert!(
                (r.relmse / f(t) - 1.0).abs() < 1e-12,
                "t = {t}: {} vs {}",
                r.relmse,
                f(t)
            );
        }
        let late = relmse_at_time(&curve, 40.0).unwrap();
        assert!(late.extrapolated);
        assert_eq!(late.relmse, f(32.0));
        let early = relmse_at_time(&curve, 0.5).unwrap();
        assert!(early.extrapolated);
        assert_eq!(early.relmse, f(1.0));
        assert!(relmse_at_time(&[], 1.0).is_none());
    }

    #[test]
    fn zero_error_falls_back_to_linear() {
        let curve = [point(1.0, 1.0), point(3.0, 0.0)];
        let r = relmse_at_time(&curve, 2.0).unwrap();
        assert!((r.relmse - 0.5).abs() < 1e-12);
    }

    #[test]
    fn statistics() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0, f64::NAN]), Some(2.5));
        assert_eq!(median(&[]), None);
        let g = geometric_mean(&[1.0, 4.0, 16.0]).unwrap();
        assert!((g - 4.0).abs() < 1e-12);
    }

    #[test]
    fn dense_checkpoints_include_the_configured_ones() {
        let c = dense_checkpoints(&[12, 100], 64);
        assert_eq!(c[..8], [1, 2, 3, 4, 5, 6, 7, 8]);
        assert!(c.contains(&12) && c.contains(&100) && c.contains(&64));
        assert!(c.windows(2).all(|w| w[0] < w[1]));
        // Sixteen points per doubling: consecutive ratios ≈ 2^(1/16) = 1.044 (plus rounding)
        // once the counts are large enough for rounding not to matter.
        assert!(c
            .windows(2)
            .filter(|w| w[0] >= 16 && w[1] <= 64)
            .all(|w| w[1] as f64 / w[0] as f64 <= 1.25));
        let wide = dense_checkpoints(&[64, 256], 1024);
        assert!(wide
            .windows(2)
            .filter(|w| w[0] >= 64)
            .all(|w| w[1] as f64 / w[0] as f64 <= 1.06));
    }
}
