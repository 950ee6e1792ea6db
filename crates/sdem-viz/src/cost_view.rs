//! The cost surface of one localization: eq. (1) sampled over an x–y grid through the optimum.

use super::draw::{
    color_bar, quantile, subtitle, title, viridis, Anchor, Axes, Canvas, INK, LABEL_SCALE, WHITE,
};
use image::{Rgb, RgbImage};
use rayon::prelude::*;
use sdem::cost::{Correlator, CostConfig};
use sdem::error::{Error, Result};
use sdem::geometry::Vec3;
use sdem::sdem::Sdem;

/// Eq. (1) sampled on an x–y grid of candidate offsets at one height and heading.
#[derive(Debug, Clone, PartialEq)]
pub struct CostSlice {
    /// Candidate x offsets, metres (columns), ascending.
    pub x_m: Vec<f64>,
    /// Candidate y offsets, metres (rows), ascending.
    pub y_m: Vec<f64>,
    /// The cost of each candidate, m², row-major (`costs[row * x_m.len() + column]`); `None`
    /// where the candidate overlaps the reference too little to be scored.
    pub costs: Vec<Option<f64>>,
    /// The optimum the slice passes through (offset, metres).
    pub optimum: [f64; 3],
    /// The heading correction of the slice, radians.
    pub heading_rad: f64,
}

impl CostSlice {
    /// The smallest sampled cost and its `(x, y)`, when any candidate was scored.
    pub fn minimum(&self) -> Option<(f64, [f64; 2])> {
        let n = self.x_m.len();
        self.costs
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.map(|c| (c, [self.x_m[i % n], self.y_m[i / n]])))
            .min_by(|a, b| a.0.total_cmp(&b.0))
    }
}

/// Samples eq. (1) of `query` against `reference` over the square `optimum ± half_extent_m` in
/// x and y at `step_m`, at the optimum's z and the given heading correction.
///
/// The candidate `(t, ψ)` places query point `q` at `Rz(ψ) q + t` in the reference's levelled
/// frame, as [`sdem::cost::Correlator::evaluate`]; pass a localization's `offset` and
/// `heading_correction`.
///
/// # Errors
/// When the grids differ, the cost configuration is invalid, or the extent or step is not a
/// positive number (or asks for more than 401 × 401 samples).
pub fn sample_cost_slice(
    reference: &Sdem,
    query: &Sdem,
    cost: &CostConfig,
    optimum: &Vec3,
    heading_rad: f64,
    half_extent_m: f64,
    step_m: f64,
) -> Result<CostSlice> {
    if !(half_extent_m.is_finite() && half_extent_m > 0.0 && step_m.is_finite() && step_m > 0.0) {
        return Err(Error::Invalid(format!(
            "cost slice: extent ±{half_extent_m} m and step {step_m} m must be positive numbers"
        )));
    }
    let half_count = (half_extent_m / step_m).round() as i64;
    if half_count > 200 {
        return Err(Error::Invalid(format!(
            "cost slice: ±{half_extent_m} m at {step_m} m asks for {} samples a side; at most 401",
            2 * half_count + 1
        )));
    }
    // Made once (it chooses the compared points, several passes over a LiDAR scan's) and
    // cloned for each worker.
    let correlator = Correlator::new(reference, query, cost)?;
    let axis = |c: f64| -> Vec<f64> {
        (-half_count..=half_count)
            .map(|k| c + k as f64 * step_m)
            .collect()
    };
    let x_m = axis(optimum.x);
    let y_m = axis(optimum.y);
    let rows: Vec<Vec<Option<f64>>> = y_m
        .par_iter()
        .map_init(
            || correlator.clone(),
            |correlator, &y| {
                x_m.iter()
                    .map(|&x| {
                        correlator
                            .evaluate(&Vec3::new(x, y, optimum.z), heading_rad)
                            .map(|c| c.cost)
                    })
                    .collect()
            },
        )
        .collect();
    Ok(CostSlice {
        x_m,
        y_m,
        costs: rows.into_iter().flatten().collect(),
        optimum: [optimum.x, optimum.y, optimum.z],
        heading_rad,
    })
}

/// `value`, with a value that prints as zero at `decimals` made exactly zero (no "-0.000").
fn no_negative_zero(value: f64, decimals: i32) -> f64 {
    if value.abs() < 0.5 * 10f64.powi(-decimals) {
        0.0
    } else {
        value
    }
}

/// The cost slice as a heat map: `sqrt(cost)` (the RMS range difference, cm) colour-mapped with
/// viridis, dark = low cost (a good match); candidates that could not be scored hatched grey;
/// the optimum marked with a white cross in a ring and the sampled minimum with a small square;
/// axes are the candidate offset in metres, with a colour bar.
///
/// A single small dark spot is a sharp, trustworthy optimum; a dark valley stretched along one
/// direction is a corridor's ridge (the position is uncertain along it).
///
/// # Arguments
/// * `slice` — from [`sample_cost_slice`].
/// * `title` — a line above the picture.
pub fn cost_surface(slice: &CostSlice, title_text: &str) -> RgbImage {
    let cells = SliceCells::of(slice);
    let (left, top) = (130, 90);
    let axes = Axes::equal(left, top, 720, 720, cells.x_range, cells.y_range);
    let mut canvas = Canvas::new(
        (left + axes.width + 220) as u32,
        (top + axes.height + 100) as u32,
    );
    let (lo, hi) = paint_costs(&mut canvas, &axes, slice, &cells);
    let minimum = mark_optimum_and_minimum(&mut canvas, &axes, slice);
    axes.draw_frame(
        &mut canvas,
        "candidate x offset (m)",
        "candidate y offset (m)",
        None,
        None,
    );
    title(&mut canvas, &format!("Cost surface: {title_text}"));
    subtitle(
        &mut canvas,
        &format!(
            "eq. (1) at z = {:.3} m, heading {:+.2}°; optimum ({:.3}, {:.3}) m; dark = good match",
            no_negative_zero(slice.optimum[2], 3),
            no_negative_zero(slice.heading_rad.to_degrees(), 2),
            no_negative_zero(slice.optimum[0], 3),
            no_negative_zero(slice.optimum[1], 3)
        ),
    );
    color_bar(
        &mut canvas,
        left + axes.width + 50,
        top + 40,
        28,
        axes.height - 160,
        (lo, hi),
        viridis,
        "rms diff (cm)",
    );
    marker_notes(&mut canvas, left + axes.width + 20, top + axes.height - 90);
    if minimum.is_none() {
        canvas.text_boxed(
            left + axes.width / 2,
            top + axes.height / 2,
            "no candidate overlaps enough to be scored",
            LABEL_SCALE,
            Anchor::Center,
            Rgb([200, 0, 0]),
        );
    }
    canvas.image
}

/// The slice's samples as cells: their counts and spacing along x and y, and the data ranges
/// they cover (half a step beyond the outer samples).
struct SliceCells {
    nx: usize,
    ny: usize,
    step_x: f64,
    step_y: f64,
    x_range: (f64, f64),
    y_range: (f64, f64),
}

impl SliceCells {
    fn of(slice: &CostSlice) -> Self {
        let (nx, ny) = (slice.x_m.len().max(1), slice.y_m.len().max(1));
        let first = |v: &[f64]| v.first().copied().unwrap_or(0.0);
        let last = |v: &[f64]| v.last().copied().unwrap_or(1.0);
        let step_x = if nx > 1 {
            (last(&slice.x_m) - first(&slice.x_m)) / (nx - 1) as f64
        } else {
            0.01
        };
        let step_y = if ny > 1 {
            (last(&slice.y_m) - first(&slice.y_m)) / (ny - 1) as f64
        } else {
            0.01
        };
        let x_range = (
            first(&slice.x_m) - step_x / 2.0,
            last(&slice.x_m) + step_x / 2.0,
        );
        let y_range = (
            first(&slice.y_m) - step_y / 2.0,
            last(&slice.y_m) + step_y / 2.0,
        );
        Self {
            nx,
            ny,
            step_x,
            step_y,
            x_range,
            y_range,
        }
    }
}

/// Paints each pixel of `axes` with its cell's RMS range difference (cm) on viridis, hatched
/// where the candidate was not scored; returns the colour scale's ends.
fn paint_costs(
    canvas: &mut Canvas,
    axes: &Axes,
    slice: &CostSlice,
    cells: &SliceCells,
) -> (f64, f64) {
    let SliceCells {
        nx,
        ny,
        step_x,
        step_y,
        x_range,
        y_range,
    } = *cells;
    let rms_cm: Vec<Option<f64>> = slice
        .costs
        .iter()
        .map(|c| c.map(|c| c.max(0.0).sqrt() * 100.0))
        .collect();
    let mut known: Vec<f64> = rms_cm.iter().flatten().copied().collect();
    let lo = quantile(&mut known, 0.0).unwrap_or(0.0);
    let hi = quantile(&mut known, 1.0).unwrap_or(1.0).max(lo + 1e-3);
    for row in axes.top..axes.top + axes.height {
        for column in axes.left..axes.left + axes.width {
            let (x, y) = axes.data_at(column, row);
            let ix = (((x - x_range.0) / step_x.max(1e-12)).floor() as i64).clamp(0, nx as i64 - 1)
                as usize;
            let iy = (((y - y_range.0) / step_y.max(1e-12)).floor() as i64).clamp(0, ny as i64 - 1)
                as usize;
            let color = match rms_cm.get(iy * nx + ix).copied().flatten() {
                Some(v) => viridis((v - lo) / (hi - lo)),
                None => Canvas::unknown_at(column, row),
            };
            canvas.put(column, row, color);
        }
    }
    (lo, hi)
}

/// Marks the optimum (a white cross in a ring, outlined dark so it shows on any colour) and the
/// lowest sample (a small square); returns that sample, `None` when none was scored.
fn mark_optimum_and_minimum(
    canvas: &mut Canvas,
    axes: &Axes,
    slice: &CostSlice,
) -> Option<(f64, [f64; 2])> {
    let (ox, oy) = (axes.px(slice.optimum[0]), axes.py(slice.optimum[1]));
    for (color, width) in [(INK, 5.0), (WHITE, 2.5)] {
        canvas.ring(ox, oy, 12.0, width, color);
        canvas.line((ox - 20.0, oy), (ox - 7.0, oy), width, color, None);
        canvas.line((ox + 7.0, oy), (ox + 20.0, oy), width, color, None);
        canvas.line((ox, oy - 20.0), (ox, oy - 7.0), width, color, None);
        canvas.line((ox, oy + 7.0), (ox, oy + 20.0), width, color, None);
    }
    let minimum = slice.minimum();
    if let Some((_, [mx, my])) = minimum {
        let (px, py) = (axes.px(mx).round() as i64, axes.py(my).round() as i64);
        canvas.rect_outline(px - 4, py - 4, px + 5, py + 5, WHITE);
        canvas.rect_outline(px - 5, py - 5, px + 6, py + 6, INK);
    }
    minimum
}

/// What the two markers mean, in four lines from `(note_x, note_y)`.
fn marker_notes(canvas: &mut Canvas, note_x: i64, note_y: i64) {
    for (dy, text) in [
        (0, "circle+cross:"),
        (20, " the optimum"),
        (44, "square: lowest"),
        (64, " sample"),
    ] {
        canvas.text(note_x, note_y + dy, text, LABEL_SCALE, Anchor::Left, INK);
    }
}
