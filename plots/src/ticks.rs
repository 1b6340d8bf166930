//! Log axes that read: labelled ticks inside every decade where the range is short (1-2-5
//! steps and finer), powers of two on an axis of counts (passes), light grid lines at the
//! 2..9 multiples of each decade, and numbers written as a person writes them (`0.005`, `1`,
//! `64`, `2e-4`; never `1e0` or `1.00`).
//!
//! plotters' own log axis labels whole decades only, so a range inside one decade (relMSE
//! 0.3..5.6, seconds 0.003..0.05) got a single label. Every log plot of the toolkit builds its
//! log axes with [`LogAxis`] instead.

use std::ops::Range;

use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, Ranged, ValueFormatter};

/// Mantissas of the labelled ticks inside one decade, finest first: the first set that fits
/// (see [`decimal_log_ticks`]) is used.
const MANTISSAS: [&[f64]; 5] = [
    &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0],
    &[1.0, 2.0, 5.0],
    &[1.0, 3.0],
    &[1.0],
];

/// The multiples `m · 10^k` (m in `mantissas`, every `decade_step`-th decade) inside
/// `lo..=hi`, ascending.
fn decade_multiples(lo: f64, hi: f64, mantissas: &[f64], decade_step: i32) -> Vec<f64> {
    let first = lo.log10().floor() as i32 - 1;
    let last = hi.log10().ceil() as i32 + 1;
    let mut out = Vec::new();
    for k in first..=last {
        if k.rem_euclid(decade_step) != 0 {
            continue;
        }
        for &m in mantissas {
            let v = round_sig(m * 10f64.powi(k));
            if v >= lo * (1.0 - 1e-12) && v <= hi * (1.0 + 1e-12) {
                out.push(v);
            }
        }
    }
    out
}

/// `v` rounded to 12 significant digits (so that 3 · 10⁻¹ prints as 0.3).
fn round_sig(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let scale = 10f64.powi(11 - v.abs().log10().floor() as i32);
    (v * scale).round() / scale
}

/// Smallest distance between neighbours, in decades (infinite for fewer than two ticks).
fn min_log_gap(ticks: &[f64]) -> f64 {
    ticks
        .windows(2)
        .map(|w| (w[1] / w[0]).log10())
        .fold(f64::INFINITY, f64::min)
}

/// Ticks of a linear axis over `lo..=hi` at the widest 1-2-5 step that gives at least three
/// (for log ranges too narrow to hold three 1..9 multiples of a decade, where the axis is
/// nearly linear).
fn linear_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let top = (hi - lo).log10().floor() as i32;
    for k in (top - 3..=top).rev() {
        for m in [5.0, 2.0, 1.0] {
            let step = m * 10f64.powi(k);
            let (first, last) = ((lo / step).ceil() as i64, (hi / step).floor() as i64);
            if last - first >= 2 {
                return (first..=last).map(|i| round_sig(i as f64 * step)).collect();
            }
        }
    }
    Vec::new()
}

/// Labelled ticks for a log axis over `lo..hi` (0 < lo < hi), at most about `max_labels`:
/// the finest of 1..9, 1-2-3-4-5-6-8, 1-2-5, 1-3, 1 multiples of each decade (then
/// every 2nd, 3rd, 5th… decade) whose neighbours are no closer than `span / (1.5 · max_labels)`
/// decades — so a short range gets labels inside its decade and a long one labels at the
/// decades only. Ranges too narrow for three of those get linear 1-2-5 steps. At least 3
/// ticks whenever `hi / lo` exceeds 1.5.
pub fn decimal_log_ticks(lo: f64, hi: f64, max_labels: usize) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo && lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    let max_labels = max_labels.max(3);
    let span = (hi / lo).log10();
    let min_gap = span / (1.5 * max_labels as f64);
    let mut chosen = None;
    for mantissas in MANTISSAS {
        let ticks = decade_multiples(lo, hi, mantissas, 1);
        if ticks.len() <= max_labels && min_log_gap(&ticks) >= min_gap {
            chosen = Some(ticks);
            break;
        }
    }
    let ticks = chosen.unwrap_or_else(|| {
        // More decades than labels: every n-th decade.
        (2..)
            .map(|step| decade_multiples(lo, hi, &[1.0], step))
            .find(|t| t.len() <= max_labels)
            .unwrap_or_default()
    });
    if ticks.len() >= 3 {
        return ticks;
    }
    let fine = decade_multiples(lo, hi, MANTISSAS[0], 1);
    if fine.len() >= 3 {
        fine
    } else {
        linear_ticks(lo, hi)
    }
}

/// Labelled ticks for a log axis of counts (passes) over `lo..hi`: the powers of two inside
/// it (every 2nd, 3rd… power when more than `max_labels` fit); where fewer than three powers
/// of two fit, [`decimal_log_ticks`] (whole numbers from 1 up).
pub fn binary_log_ticks(lo: f64, hi: f64, max_labels: usize) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo && lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    let first = lo.log2().ceil() as i32;
    let last = hi.log2().floor() as i32;
    let max_labels = max_labels.max(3) as i32;
    let mut step = 1;
    while (last - first) / step + 1 > max_labels {
        step += 1;
    }
    let ticks: Vec<f64> = (first..=last)
        .filter(|k| (k - first) % step == 0)
        .map(|k| 2f64.powi(k))
        .collect();
    if ticks.len() >= 3 {
        ticks
    } else {
        decimal_log_ticks(lo, hi, max_labels as usize)
    }
}

/// A tick label as a person writes it: up to four significant digits without trailing zeros
/// between 0.001 and 100 000 (`0.005`, `0.1285`, `1`, `64`, `25000`), else scientific with
/// a short mantissa (`2e-4`, `2.5e-5`, `1e6`).
pub fn tick_label(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if !v.is_finite() {
        return format!("{v}");
    }
    let magnitude = v.abs().log10().floor();
    if (-3.0..5.0).contains(&magnitude) {
        let decimals = (3.0 - magnitude).max(0.0) as usize;
        let text = format!("{v:.decimals$}");
        if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            text
        }
    } else {
        let text = format!("{v:.2e}");
        let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
        let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
        format!("{mantissa}e{exponent}")
    }
}

/// How the labelled ticks of a [`LogAxis`] are spaced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogTicks {
    /// Decades and their 1-2-5 (or finer) multiples: [`decimal_log_ticks`].
    Decimal,
    /// Powers of two, for counts such as passes: [`binary_log_ticks`].
    Binary,
}

/// A logarithmic axis for plotters (`build_cartesian_2d(LogAxis::new(..), ..)`) with readable
/// labelled ticks ([`LogTicks`]), light grid lines at the 1..9 multiples of each decade, and
/// labels written by [`tick_label`] (a `x_label_formatter` still overrides them).
#[derive(Clone, Debug)]
pub struct LogAxis {
    range: Range<f64>,
    labels: Vec<f64>,
    minor: Vec<f64>,
}

impl LogAxis {
    /// The axis over `range` (positive, increasing), with about `max_labels` labels at most.
    pub fn new(range: Range<f64>, ticks: LogTicks, max_labels: usize) -> Self {
        let (lo, hi) = (range.start, range.end);
        let labels = match ticks {
            LogTicks::Decimal => decimal_log_ticks(lo, hi, max_labels),
            LogTicks::Binary => binary_log_ticks(lo, hi, max_labels),
        };
        let minor = if lo > 0.0 && hi > lo {
            decade_multiples(lo, hi, MANTISSAS[0], 1)
        } else {
            Vec::new()
        };
        LogAxis {
            range,
            labels,
            minor,
        }
    }

    /// The labelled ticks, ascending.
    pub fn labels(&self) -> &[f64] {
        &self.labels
    }
}

impl Ranged for LogAxis {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let (lo, hi) = (self.range.start.ln(), self.range.end.ln());
        // Values a log axis cannot show map far outside the picture rather than to NaN.
        let f = ((value.max(f64::MIN_POSITIVE).ln() - lo) / (hi - lo)).clamp(-1e3, 1e3);
        limit.0 + (f * (limit.1 - limit.0) as f64).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        // Light grid lines (plotters asks with a light hint) at every multiple of a decade
        // when they are not too dense; bold lines and labels at the labelled ticks.
        if hint.weight().allow_light_points() && self.minor.len() <= hint.max_num_points() {
            self.minor.clone()
        } else {
            self.labels.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.range.clone()
    }
}

impl ValueFormatter<f64> for LogAxis {
    fn format_ext(&self, value: &f64) -> String {
        tick_label(*value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mantissa of `v` (1 ≤ m < 10), rounded.
    fn mantissa(v: f64) -> f64 {
        let m = v / 10f64.powf(v.log10().floor());
        (m * 1e6).round() / 1e6
    }

    fn labels(ticks: &[f64]) -> Vec<String> {
        ticks.iter().map(|&v| tick_label(v)).collect()
    }

    /// The ranges of the review: relMSE 0.3..5.6 and seconds 0.003..0.05 (as the plots pad
    /// them) get labels inside their decades, at 1-2-5 steps.
    #[test]
    fn short_ranges_get_labels_inside_the_decade() {
        let relmse = decimal_log_ticks(0.3 / 1.5, 5.6 * 1.5, 10);
        assert_eq!(labels(&relmse), ["0.2", "0.5", "1", "2", "5"]);
        let seconds = decimal_log_ticks(0.003 / 1.2, 0.05 * 1.2, 8);
        assert_eq!(labels(&seconds), ["0.005", "0.01", "0.02", "0.05"]);
        // A range inside one decade gets its 1..9 multiples.
        let narrow = decimal_log_ticks(0.31, 0.75, 8);
        assert_eq!(labels(&narrow), ["0.4", "0.5", "0.6", "0.7"]);
        // Many decades: the decades only, then every other one.
        let wide = decimal_log_ticks(1e-5, 2.0, 8);
        assert_eq!(labels(&wide), ["1e-5", "1e-4", "0.001", "0.01", "0.1", "1"]);
        let wider = decimal_log_ticks(1e-12, 1e3, 8);
        assert_eq!(
            labels(&wider),
            ["1e-12", "1e-10", "1e-8", "1e-6", "1e-4", "0.01", "1", "100"]
        );
    }

    /// Over many ranges: ticks lie inside the range, ascend, sit at 1..9 multiples of a decade
    /// (or a linear 1-2-5 step for narrow ranges), stay within the label budget, and a
    /// range wider than a factor 3 gets at least three.
    #[test]
    fn ticks_are_inside_sorted_round_and_enough() {
        let mut lo = 1e-6;
        while lo < 1e4 {
            for factor in [
                1.2, 1.6, 2.0, 3.01, 4.5, 7.0, 12.0, 30.0, 150.0, 1e3, 1e5, 1e9,
            ] {
                let hi = lo * factor;
                for max_labels in [5, 8, 10] {
                    let t = decimal_log_ticks(lo, hi, max_labels);
                    let what = format!("{lo:e}..{hi:e} max {max_labels}: {t:?}");
                    assert!(t.windows(2).all(|w| w[0] < w[1]), "{what}");
                    assert!(
                        t.iter()
                            .all(|&v| v >= lo * 0.999_999 && v <= hi * 1.000_001),
                        "{what}"
                    );
                    if factor > 3.0 {
                        assert!(t.len() >= 3, "{what}");
                        // 1..9 multiples of a decade, or a linear step of 0.5 of one where
                        // the range holds only two of those (e.g. 0.9..2.7).
                        assert!(
                            t.iter().all(|&v| (2.0 * mantissa(v)).fract() == 0.0),
                            "{what}"
                        );
                        // 1-2-5 (or the decades) once a range is longer than a decade.
                        if factor >= 30.0 {
                            assert!(
                                t.iter()
                                    .all(|&v| [1.0, 2.0, 3.0, 5.0].contains(&mantissa(v))),
                                "{what}"
                            );
                        }
                    } else {
                        assert!(t.len() >= 2, "{what}");
                    }
                    assert!(t.len() <= max_labels.max(9), "{what}");
                }
            }
            lo *= 1.37;
        }
    }

    /// Passes: powers of two (8, 16, 32, 64), thinned when there are many, whole numbers
    /// when fewer than three powers of two fit.
    #[test]
    fn pass_axes_get_powers_of_two() {
        assert_eq!(
            labels(&binary_log_ticks(8.0 / 1.2, 64.0 * 1.2, 8)),
            ["8", "16", "32", "64"]
        );
        assert_eq!(
            labels(&binary_log_ticks(1.0 / 1.2, 107.0 * 1.2, 8)),
            ["1", "2", "4", "8", "16", "32", "64", "128"]
        );
        assert_eq!(
            labels(&binary_log_ticks(1.0, 4096.0, 6)),
            ["1", "8", "64", "512", "4096"]
        );
        // A single checkpoint (8 passes, padded): 7, 8, 9.
        assert_eq!(
            labels(&binary_log_ticks(8.0 / 1.2, 8.0 * 1.2, 8)),
            ["7", "8", "9"]
        );
    }

    /// Numbers read as a person writes them.
    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(tick_label(1.0), "1");
        assert_eq!(tick_label(64.0), "64");
        assert_eq!(tick_label(0.8), "0.8");
        assert_eq!(tick_label(0.30000000000000004), "0.3");
        assert_eq!(tick_label(0.1285), "0.1285");
        assert_eq!(tick_label(0.005), "0.005");
        assert_eq!(tick_label(0.0015), "0.0015");
        assert_eq!(tick_label(120.0), "120");
        assert_eq!(tick_label(25000.0), "25000");
        assert_eq!(tick_label(2e-4), "2e-4");
        assert_eq!(tick_label(2.5e-5), "2.5e-5");
        assert_eq!(tick_label(1e6), "1e6");
    }

    /// The axis maps its ends to the pixel limits and the geometric middle to the middle;
    /// light grid lines come at the decade multiples, labels at the labelled ticks.
    #[test]
    fn axis_maps_logarithmically() {
        let axis = LogAxis::new(0.01..1.0, LogTicks::Decimal, 8);
        assert_eq!(axis.map(&0.01, (0, 200)), 0);
        assert_eq!(axis.map(&1.0, (0, 200)), 200);
        assert_eq!(axis.map(&0.1, (0, 200)), 100);
        assert_eq!(axis.map(&0.1, (300, 100)), 200);
        assert_eq!(
            labels(axis.labels()),
            ["0.01", "0.02", "0.05", "0.1", "0.2", "0.5", "1"]
        );
        assert_eq!(axis.key_points(100usize).len(), 19);
        assert_eq!(
            axis.key_points(plotters::coord::ranged1d::BoldPoints(8)),
            axis.labels()
        );
        assert_eq!(axis.format_ext(&0.05), "0.05");
    }
}
