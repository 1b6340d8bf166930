//! Lines with markers and their legend: one style for a series wherever it is drawn (a dashed
//! input level is dashed in the legend too), and a legend placed in the corner of the plot
//! where it covers the fewest data.

use std::error::Error;

use plotters::coord::ranged1d::Ranged;

/// A pixel of the backend (plotters_backend::BackendCoord).
type BackendCoord = (i32, i32);
use plotters::element::{DashedPathElement, DynElement, MultiLineText};
use plotters::prelude::*;

/// Dash length and gap of dashed lines, in pixels.
pub const DASH: (u32, u32) = (5, 4);
/// Font size of the legend's labels.
pub const LEGEND_FONT: u32 = 12;
/// Length of a legend's line swatch, in pixels.
const SWATCH: i32 = 22;
/// Room plotters leaves for the swatch before a label.
const LEGEND_AREA: u32 = 32;
/// plotters' padding inside the legend box.
const LEGEND_MARGIN: i32 = 10;
/// plotters' distance of a corner legend from the plotting area's edges.
pub const LEGEND_INSET: u32 = 5;

/// One line of a plot: its legend label, colour and points. A dashed series (an input level:
/// the bar to beat, not a result) is drawn thinner, dashed, with smaller markers; a solid one
/// 2 pixels wide.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Stroke and marker colour.
    pub colour: RGBColor,
    /// The points, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// Dashed (inputs) or solid (results).
    pub dashed: bool,
}

impl Series {
    /// The stroke of the line (and of its legend swatch).
    pub fn stroke(&self) -> ShapeStyle {
        self.colour.stroke_width(if self.dashed { 1 } else { 2 })
    }

    /// Radius of the point markers.
    pub fn marker_radius(&self) -> i32 {
        if self.dashed {
            2
        } else {
            3
        }
    }
}

/// The legend swatch of a series drawn with `stroke`: a short line, dashed like the series
/// when `dashed`.
pub fn swatch<DB: DrawingBackend>(
    stroke: ShapeStyle,
    dashed: bool,
) -> impl Fn(BackendCoord) -> DynElement<'static, DB, BackendCoord> {
    move |(x, y)| {
        let ends = [(x, y), (x + SWATCH, y)];
        if dashed {
            DashedPathElement::new(ends, DASH.0, DASH.1, stroke).into_dyn()
        } else {
            PathElement::new(ends, stroke).into_dyn()
        }
    }
}

/// Draws every series (line, markers) and registers its legend entry with a matching swatch;
/// [`draw_legend`] draws the legend afterwards.
pub fn draw_series<'a, DB, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    series: &[Series],
) -> Result<(), Box<dyn Error>>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    for s in series {
        let stroke = s.stroke();
        let annotation = if s.dashed {
            chart.draw_series(DashedLineSeries::new(
                s.points.clone(),
                DASH.0,
                DASH.1,
                stroke,
            ))?
        } else {
            chart.draw_series(LineSeries::new(s.points.clone(), stroke))?
        };
        annotation
            .label(s.label.as_str())
            .legend(swatch(stroke, s.dashed));
        let (colour, radius) = (s.colour, s.marker_radius());
        chart.draw_series(
            s.points
                .iter()
                .map(|&p| Circle::new(p, radius, colour.filled())),
        )?;
    }
    Ok(())
}

/// Size in pixels of the legend box holding `labels` (the embedded font must be registered:
/// [`crate::register_font`]).
pub fn legend_size<'l>(labels: impl IntoIterator<Item = &'l str>) -> Result<(u32, u32), String> {
    let font: TextStyle = ("sans-serif", LEGEND_FONT).into_font().into();
    let mut text = MultiLineText::<BackendCoord, &str>::new((0, 0), font);
    for l in labels {
        text.push_line(l);
    }
    let (w, h) = text
        .estimate_dimension()
        .map_err(|e| format!("legend text: {e}"))?;
    Ok((
        (w + LEGEND_AREA as i32 + 2 * LEGEND_MARGIN).max(0) as u32,
        (h + 2 * LEGEND_MARGIN).max(0) as u32,
    ))
}

/// The corners a legend may take, in the default order of preference.
const CORNERS: [SeriesLabelPosition; 4] = [
    SeriesLabelPosition::UpperRight,
    SeriesLabelPosition::UpperLeft,
    SeriesLabelPosition::LowerLeft,
    SeriesLabelPosition::LowerRight,
];

/// Top-left pixel of a `size` legend at `corner` of a plotting area of `area` pixels (as
/// plotters lays it out).
fn corner_origin(corner: &SeriesLabelPosition, area: (u32, u32), size: (u32, u32)) -> (i32, i32) {
    let inset = LEGEND_INSET as i32;
    let right = area.0 as i32 - size.0 as i32 - inset;
    let bottom = area.1 as i32 - size.1 as i32 - inset;
    match corner {
        SeriesLabelPosition::UpperLeft => (inset, inset),
        SeriesLabelPosition::LowerLeft => (inset, bottom),
        SeriesLabelPosition::LowerRight => (right, bottom),
        _ => (right, inset),
    }
}

/// How much of `lines` (pixel polylines, relative to the plotting area) a `size` legend at
/// `corner` would cover: markers under it, plus samples every 2 pixels along the segments.
fn covered(
    lines: &[Vec<(i32, i32)>],
    corner: &SeriesLabelPosition,
    area: (u32, u32),
    size: (u32, u32),
) -> usize {
    // A few pixels of slack: a line grazing the border is covered too.
    const PAD: f64 = 4.0;
    let (x0, y0) = corner_origin(corner, area, size);
    let (x0, y0) = (x0 as f64 - PAD, y0 as f64 - PAD);
    let (x1, y1) = (
        x0 + size.0 as f64 + 2.0 * PAD,
        y0 + size.1 as f64 + 2.0 * PAD,
    );
    let inside = |x: f64, y: f64| x >= x0 && x <= x1 && y >= y0 && y <= y1;
    let mut count = 0;
    for line in lines {
        // A marker weighs as much as a stretch of line: it is the measured point.
        count += 8 * line
            .iter()
            .filter(|&&(x, y)| inside(x as f64, y as f64))
            .count();
        for w in line.windows(2) {
            let (a, b) = (
                (w[0].0 as f64, w[0].1 as f64),
                (w[1].0 as f64, w[1].1 as f64),
            );
            let length = (b.0 - a.0).hypot(b.1 - a.1);
            let steps = (length / 2.0).ceil().clamp(1.0, 10_000.0) as usize;
            count += (1..=steps)
                .map(|i| i as f64 / steps as f64)
                .filter(|t| inside(a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)))
                .count();
        }
    }
    count
}

/// The corner where a `size` legend covers the least of `lines` (pixel polylines relative to
/// a plotting area of `area` pixels); ties go to the earliest of `preferred`, then of upper
/// right, upper left, lower left, lower right.
pub fn pick_corner(
    lines: &[Vec<(i32, i32)>],
    area: (u32, u32),
    size: (u32, u32),
    preferred: &[SeriesLabelPosition],
) -> SeriesLabelPosition {
    let mut order: Vec<SeriesLabelPosition> = preferred
        .iter()
        .filter(|p| CORNERS.contains(p))
        .cloned()
        .collect();
    for c in CORNERS {
        if !order.contains(&c) {
            order.push(c);
        }
    }
    let mut best = (usize::MAX, SeriesLabelPosition::UpperRight);
    for corner in order {
        let n = covered(lines, &corner, area, size);
        if n < best.0 {
            best = (n, corner);
        }
    }
    best.1
}

/// Draws the legend of `series` (already drawn with [`draw_series`]) in the corner of the
/// plotting area where it covers the fewest data ([`pick_corner`]; ties go to `preferred`),
/// and returns that corner.
pub fn draw_legend<'a, DB, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    series: &[Series],
    preferred: &[SeriesLabelPosition],
) -> Result<SeriesLabelPosition, Box<dyn Error>>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let size = legend_size(series.iter().map(|s| s.label.as_str()))?;
    let area = chart.plotting_area().dim_in_pixel();
    let base = chart.plotting_area().get_base_pixel();
    let lines: Vec<Vec<(i32, i32)>> = series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .map(|p| {
                    let (x, y) = chart.backend_coord(p);
                    (x - base.0, y - base.1)
                })
                .collect()
        })
        .collect();
    let corner = pick_corner(&lines, area, size, preferred);
    chart
        .configure_series_labels()
        .position(corner.clone())
        .legend_area_size(LEGEND_AREA)
        .margin(LEGEND_MARGIN as u32)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", LEGEND_FONT))
        .draw()?;
    Ok(corner)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The legend goes where the data are not: a line along the top of the plot sends it
    /// down; a line falling from the upper left to the lower right leaves the preferred
    /// lower left free; with nothing anywhere the first preference wins.
    #[test]
    fn legend_avoids_the_data() {
        let area = (400, 300);
        let size = (120, 100);
        let top = vec![vec![(0, 20), (200, 20), (400, 20)]];
        let corner = pick_corner(&top, area, size, &[SeriesLabelPosition::UpperRight]);
        assert!(
            matches!(
                corner,
                SeriesLabelPosition::LowerLeft | SeriesLabelPosition::LowerRight
            ),
            "{corner:?}"
        );
        // The last point alone in the upper right (a curve ending at the top).
        let rising = vec![vec![(0, 290), (200, 200), (390, 10)]];
        let corner = pick_corner(&rising, area, size, &[SeriesLabelPosition::UpperRight]);
        assert_eq!(corner, SeriesLabelPosition::UpperLeft);
        let falling = vec![vec![(0, 0), (400, 300)]];
        assert_eq!(
            pick_corner(&falling, area, size, &[SeriesLabelPosition::LowerLeft]),
            SeriesLabelPosition::LowerLeft
        );
        assert_eq!(
            pick_corner(&[], area, size, &[SeriesLabelPosition::LowerRight]),
            SeriesLabelPosition::LowerRight
        );
    }

    /// Series and legend draw into a picture; a dashed series gets a dashed swatch (gaps in
    /// the legend's line), a solid one a solid swatch.
    #[test]
    fn legend_swatch_matches_the_series() {
        crate::register_font().unwrap();
        let (w, h) = (300u32, 200u32);
        let mut buf = vec![255u8; (w * h * 3) as usize];
        let series = [
            Series {
                label: "solid".into(),
                colour: RGBColor(255, 0, 0),
                points: vec![(1.0, 1.0), (2.0, 1.0)],
                dashed: false,
            },
            Series {
                label: "dashed".into(),
                colour: RGBColor(0, 0, 255),
                points: vec![(1.0, 1.1), (2.0, 1.1)],
                dashed: true,
            },
        ];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            let mut chart = ChartBuilder::on(&root)
                .build_cartesian_2d(0.0..10.0, 0.0..10.0)
                .unwrap();
            draw_series(&mut chart, &series).unwrap();
            // Data near the lower left: the legend goes elsewhere (upper right preferred).
            let corner = draw_legend(&mut chart, &series, &[]).unwrap();
            assert_eq!(corner, SeriesLabelPosition::UpperRight);
            root.present().unwrap();
        }
        // Each swatch row: count pixels of the series' colour along the swatch, and the
        // colour changes (dash edges) along it.
        let pixel = |x: u32, y: u32| {
            let i = ((y * w + x) * 3) as usize;
            (buf[i], buf[i + 1], buf[i + 2])
        };
        let row_runs = |colour: (u8, u8, u8)| {
            (0..h)
                .map(|y| {
                    let on: Vec<bool> = (w / 2..w).map(|x| pixel(x, y) == colour).collect();
                    let count = on.iter().filter(|&&b| b).count();
                    let edges = on.windows(2).filter(|p| p[0] != p[1]).count();
                    (count, edges)
                })
                .max()
                .unwrap()
        };
        let (solid_pixels, solid_edges) = row_runs((255, 0, 0));
        let (dashed_pixels, dashed_edges) = row_runs((0, 0, 255));
        assert!(solid_pixels >= SWATCH as usize, "{solid_pixels}");
        assert_eq!(solid_edges, 2, "one solid run");
        assert!(dashed_pixels >= 8, "{dashed_pixels}");
        assert!(dashed_edges >= 6, "three dashes: {dashed_edges} edges");
    }
}
