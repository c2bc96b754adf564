//! Loss curves as SVG, drawn by plotters: one panel per curve name, one line per run in it.
//!
//! A curve whose values all lie above zero and span more than [`LOG_SPAN`] is drawn on a log
//! axis (losses fall by orders of magnitude; on a linear axis everything after the first steps
//! is a flat line at the bottom). The axis labels then show the values themselves, not their logs.

use plotters::prelude::*;

use crate::ReportError;
use crate::log::thin;

/// Panel size in SVG pixels.
pub const PANEL: (u32, u32) = (380, 230);
/// A curve is drawn on a log axis when its largest value exceeds its smallest this many times.
pub const LOG_SPAN: f64 = 20.0;
/// Curves are thinned to about twice this many points before drawing ([`thin`]).
const BUCKETS: usize = 400;

/// Run colours, in the order the runs are given (Tableau 10: distinguishable, also in grey).
pub const COLOURS: [(u8, u8, u8); 10] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
];

/// The CSS colour of run `k`.
pub fn colour_css(k: usize) -> String {
    let (r, g, b) = COLOURS[k % COLOURS.len()];
    format!("#{r:02x}{g:02x}{b:02x}")
}

/// One run's points of a curve; `run` picks its colour.
pub struct Line<'a> {
    pub run: usize,
    pub points: &'a [(f64, f64)],
}

/// An SVG panel titled `title` with `x_label` under its x axis, one polyline per line. `None` when
/// no line has a point.
pub fn panel(title: &str, x_label: &str, lines: &[Line]) -> Result<Option<String>, ReportError> {
    let points = || lines.iter().flat_map(|l| l.points.iter());
    let Some(first) = points().next() else { return Ok(None) };
    let (mut x0, mut x1, mut y0, mut y1) = (first.0, first.0, first.1, first.1);
    for &(x, y) in points() {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    let log = y0 > 0.0 && y1 > LOG_SPAN * y0;
    let map = |y: f64| if log { y.log10() } else { y };
    let (y0, y1) = padded(map(y0), map(y1));
    let (x0, x1) = if x1 > x0 { (x0, x1) } else { (x0 - 0.5, x0 + 0.5) };

    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, PANEL).into_drawing_area();
        area.fill(&WHITE).map_err(plot_error)?;
        let caption = if log { format!("{title} (log scale)") } else { title.to_owned() };
        let mut chart = ChartBuilder::on(&area)
            .caption(caption, ("sans-serif", 15))
            .margin(6)
            .x_label_area_size(34)
            .y_label_area_size(58)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(plot_error)?;
        let y_label = |v: &f64| if log { format_value(10f64.powf(*v)) } else { format_value(*v) };
        chart
            .configure_mesh()
            .x_desc(x_label)
            .x_labels(6)
            .y_labels(6)
            .x_label_formatter(&|v| format_value(*v))
            .y_label_formatter(&y_label)
            .label_style(("sans-serif", 11))
            .light_line_style(RGBColor(238, 238, 238))
            .draw()
            .map_err(plot_error)?;
        for line in lines {
            let (r, g, b) = COLOURS[line.run % COLOURS.len()];
            let style = ShapeStyle::from(&RGBColor(r, g, b)).stroke_width(2);
            let thinned = thin(line.points, BUCKETS);
            chart
                .draw_series(LineSeries::new(thinned.into_iter().map(|(x, y)| (x, map(y))), style))
                .map_err(plot_error)?;
        }
        area.present().map_err(plot_error)?;
    }
    Ok(Some(svg))
}

/// A range with 4% room on either side (a flat curve gets a unit-wide band round it).
fn padded(lo: f64, hi: f64) -> (f64, f64) {
    if hi > lo {
        let pad = 0.04 * (hi - lo);
        (lo - pad, hi + pad)
    } else {
        (lo - 0.5 * lo.abs().max(1e-3), hi + 0.5 * hi.abs().max(1e-3))
    }
}

/// A short label for an axis value: no trailing zeros, exponents for the very small and large.
pub fn format_value(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    }
}

fn plot_error(e: impl std::fmt::Display) -> ReportError {
    ReportError::Plot(e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The points of every data line (the axes and ticks are thinner polylines), in SVG pixels.
    fn polylines(svg: &str) -> Vec<Vec<(f64, f64)>> {
        svg.split("<polyline")
            .skip(1)
            .filter(|p| p.contains("stroke-width=\"2\""))
            .map(|p| {
                let points = p.split("points=\"").nth(1).unwrap().split('"').next().unwrap();
                points
                    .split_whitespace()
                    .map(|xy| {
                        let (x, y) = xy.split_once(',').unwrap();
                        (x.parse().unwrap(), y.parse().unwrap())
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn a_panel_draws_one_line_per_run_in_its_colour_through_every_point() {
        let a = [(0.0, 4.0), (1.0, 3.0), (2.0, 2.0)];
        let b = [(0.0, 2.0), (2.0, 3.0)];
        let svg = panel("chamfer", "step", &[Line { run: 0, points: &a }, Line { run: 1, points: &b }])
            .unwrap()
            .unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("\nchamfer\n") && svg.contains("\nstep\n"), "{svg}");
        let data = polylines(&svg);
        assert_eq!(data.len(), 2, "{svg}");
        assert_eq!(data[0].len(), 3);
        assert_eq!(data[1].len(), 2);
        let upper = svg.to_ascii_uppercase();
        assert!(
            upper.contains(&colour_css(0).to_ascii_uppercase())
                && upper.contains(&colour_css(1).to_ascii_uppercase())
        );
        // A falling curve falls on screen: y in pixels grows downwards, evenly (linear axis).
        let ys: Vec<f64> = data[0].iter().map(|p| p.1).collect();
        assert!(ys[0] < ys[1] && ys[1] < ys[2], "{ys:?}");
        assert!(((ys[1] - ys[0]) - (ys[2] - ys[1])).abs() < 1.0, "{ys:?}");
        // The shared x range: b's last point is as far right as a's.
        assert!((data[0][2].0 - data[1][1].0).abs() < 0.5);
    }

    #[test]
    fn a_curve_spanning_orders_of_magnitude_is_drawn_on_a_log_axis() {
        let points = [(0.0, 100.0), (1.0, 10.0), (2.0, 1.0)];
        let svg = panel("total", "step", &[Line { run: 0, points: &points }]).unwrap().unwrap();
        assert!(svg.contains("total (log scale)"));
        let line = polylines(&svg).remove(0);
        // Equal ratios are equal steps on a log axis.
        assert!(((line[1].1 - line[0].1) - (line[2].1 - line[1].1)).abs() < 1.0, "{line:?}");
        let flat =
            panel("x", "step", &[Line { run: 0, points: &[(0.0, 2.0), (1.0, 2.0)] }]).unwrap().unwrap();
        assert!(!flat.contains("log scale"));
    }

    #[test]
    fn no_points_no_panel() {
        assert!(panel("x", "step", &[]).unwrap().is_none());
        assert!(panel("x", "step", &[Line { run: 0, points: &[] }]).unwrap().is_none());
    }

    #[test]
    fn axis_values_are_short() {
        assert_eq!(format_value(0.0), "0");
        assert_eq!(format_value(2.5), "2.5");
        assert_eq!(format_value(1200.0), "1200");
        assert_eq!(format_value(0.0001234), "1.2e-4");
        assert_eq!(format_value(-3.0), "-3");
    }
}
