//! A plot of measurements against a count: one dot per measurement and a running median per
//! series (time per stop against stop number, for the scale bench).

use crate::draw::{legend, subtitle, title, Axes, Canvas, Swatch};
use image::{Rgb, RgbImage};

/// One series of a [`series_plot`]: a label and `(x, y)` values.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// The legend's label.
    pub label: String,
    /// The values, in the order of x; non-finite ones are skipped.
    pub points: Vec<(f64, f64)>,
}

/// The series' colours, in turn (Tableau's ten, dark enough to read on white).
const PALETTE: [Rgb<u8>; 6] = [
    Rgb([31, 119, 180]),
    Rgb([255, 127, 14]),
    Rgb([44, 160, 44]),
    Rgb([214, 39, 40]),
    Rgb([148, 103, 189]),
    Rgb([140, 86, 75]),
];

/// A running median over this many values draws each series' line.
const MEDIAN_WINDOW: usize = 25;

/// Plots `series` on shared axes: every value a faint dot, and a line through the running
/// median of 25 values, so a slow trend shows through the noise of single values. The y axis
/// starts at 0 and ends at the largest 99th percentile of the series (rarer outliers are drawn
/// on the top edge).
///
/// # Arguments
/// * `series` — the series; each gets its own colour and a legend entry.
/// * `title_text`, `note` — the title, and a line under it.
/// * `x_title`, `y_title` — the axes' titles.
///
/// # Returns
/// A 1,200 × 700 pixel image.
///
/// # Example
/// ```
/// use sdem_viz::{encode_png, series_plot, Series};
/// let times = Series {
///     label: "room laps".into(),
///     points: (0..300).map(|i| (i as f64, 40.0 + (i % 7) as f64)).collect(),
/// };
/// let picture = series_plot(&[times], "Time per stop", "2 threads", "stop", "time, ms");
/// assert_eq!(picture.width(), 1200);
/// assert_eq!(&encode_png(&picture).unwrap()[1..4], b"PNG");
/// ```
pub fn series_plot(
    series: &[Series],
    title_text: &str,
    note: &str,
    x_title: &str,
    y_title: &str,
) -> RgbImage {
    let finite = |&&(x, y): &&(f64, f64)| x.is_finite() && y.is_finite();
    let x_max = (series.iter())
        .flat_map(|s| s.points.iter().filter(finite).map(|p| p.0))
        .fold(1.0_f64, f64::max);
    let x_min = (series.iter())
        .flat_map(|s| s.points.iter().filter(finite).map(|p| p.0))
        .fold(x_max, f64::min)
        .min(0.0);
    let y_max = (series.iter())
        .filter_map(|s| {
            let mut ys: Vec<f64> = s.points.iter().filter(finite).map(|p| p.1).collect();
            crate::draw::quantile(&mut ys, 0.99)
        })
        .fold(1e-9_f64, f64::max)
        * 1.05;
    let (left, top, width, height) = (110, 90, 1040, 500);
    let axes = Axes {
        left,
        top,
        width,
        height,
        x_range: (x_min, x_max),
        y_range: (0.0, y_max),
    };
    let mut canvas = Canvas::new(1200, 700);
    axes.draw_grid(&mut canvas, None, None);
    let colours: Vec<Rgb<u8>> = (0..series.len())
        .map(|i| PALETTE[i % PALETTE.len()])
        .collect();
    for (s, &colour) in series.iter().zip(&colours) {
        for &(x, y) in s.points.iter().filter(finite) {
            let (px, py) = (axes.px(x), axes.py(y.min(y_max)));
            canvas.disc(px, py, 1.8, blend(colour, 0.5));
        }
    }
    for (s, &colour) in series.iter().zip(&colours) {
        let medians = running_median(&s.points);
        for pair in medians.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            canvas.line(
                (axes.px(a.0), axes.py(a.1.min(y_max))),
                (axes.px(b.0), axes.py(b.1.min(y_max))),
                2.5,
                colour,
                None,
            );
        }
    }
    axes.draw_frame(&mut canvas, x_title, y_title, None, None);
    title(&mut canvas, title_text);
    subtitle(&mut canvas, note);
    let labels: Vec<String> = series
        .iter()
        .map(|s| format!("{} (running median of {MEDIAN_WINDOW})", s.label))
        .collect();
    let entries: Vec<(Swatch, &str)> = colours
        .iter()
        .zip(&labels)
        .map(|(&c, l)| (Swatch::Line(c, false), l.as_str()))
        .collect();
    if !entries.is_empty() {
        legend(&mut canvas, left + 12, top + 12, &entries);
    }
    canvas.image
}

/// `colour` washed towards white, `strength` of it kept.
fn blend(colour: Rgb<u8>, strength: f64) -> Rgb<u8> {
    Rgb(colour
        .0
        .map(|c| (c as f64 * strength + 255.0 * (1.0 - strength)).round() as u8))
}

/// The median of each window of [`MEDIAN_WINDOW`] finite values, at the window's middle x.
fn running_median(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let values: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let window = MEDIAN_WINDOW.min(values.len()).max(1);
    values
        .windows(window)
        .step_by((window / 5).max(1))
        .map(|w| {
            let mut ys: Vec<f64> = w.iter().map(|p| p.1).collect();
            let y = crate::draw::quantile(&mut ys, 0.5).unwrap_or(f64::NAN);
            (w[w.len() / 2].0, y)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_running_median_ignores_single_outliers() {
        let mut points: Vec<(f64, f64)> = (0..100).map(|i| (i as f64, 10.0)).collect();
        points[50].1 = 1000.0;
        points[51].1 = f64::NAN;
        let medians = running_median(&points);
        assert!(!medians.is_empty());
        assert!(medians.iter().all(|m| m.1 == 10.0), "{medians:?}");
    }

    #[test]
    fn every_series_is_drawn_in_its_own_colour() {
        let series = |label: &str, y: f64| Series {
            label: label.into(),
            points: (0..200).map(|i| (i as f64, y)).collect(),
        };
        let picture = series_plot(&[series("a", 10.0), series("b", 20.0)], "t", "n", "x", "y");
        let colours: std::collections::HashSet<[u8; 3]> = picture.pixels().map(|p| p.0).collect();
        assert!(colours.contains(&PALETTE[0].0));
        assert!(colours.contains(&PALETTE[1].0));
    }
}
