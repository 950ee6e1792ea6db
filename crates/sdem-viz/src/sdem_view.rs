//! Pictures of one S-DEM: the panorama (azimuth × elevation) and the polar slice at one
//! elevation (Nagatani et al. 2003, Fig. 10–11).

use super::draw::{
    color_bar, legend, quantile, subtitle, tick_label, title, turbo, Anchor, Axes, Canvas, Swatch,
    INK, LABEL_SCALE, WHITE,
};
use image::{Rgb, RgbImage};
use sdem::sdem::{Sdem, SdemConfig};

/// Free space in the polar slice.
const FREE: Rgb<u8> = Rgb([170, 215, 245]);
/// The boundary points in the polar slice.
const BOUNDARY: Rgb<u8> = Rgb([200, 30, 30]);

/// A nice upper end for a colour scale over `values`: the 99th percentile, rounded up.
fn nice_max(values: &mut [f64]) -> f64 {
    let top = quantile(values, 0.99).unwrap_or(1.0).max(0.1);
    let step = super::draw::nice_step(top, 5.0);
    (top / step).ceil() * step
}

/// The S-DEM as a panorama: azimuth across (+180° at the left, turning right to −180°, as seen
/// from the sensor), elevation up, each cell's range colour-mapped (turbo, near = blue, far =
/// red); unknown cells hatched grey. Axes in degrees, a colour bar in metres.
///
/// # Arguments
/// * `sdem` — the S-DEM (levelled: azimuth 0° is the world's +x).
/// * `title` — a line above the picture, e.g. `"scan 3"`.
///
/// # Returns
/// An RGB image about 1300 × 750 pixels.
///
/// # Example
/// ```
/// use sdem::geometry::{Attitude, Vec3};
/// use sdem::sdem::{Sdem, SdemConfig};
/// let points: Vec<Vec3> = (0..360).map(|i| {
///     let a = (i as f64).to_radians();
///     Vec3::new(3.0 * a.cos(), 3.0 * a.sin(), -0.5)
/// }).collect();
/// let sdem = Sdem::from_points(&points, &Attitude::default(), &SdemConfig::default()).unwrap();
/// let picture = sdem_viz::sdem_panorama(&sdem, "a ring of points");
/// assert!(picture.width() > 1000);
/// ```
pub fn sdem_panorama(sdem: &Sdem, title_text: &str) -> RgbImage {
    let config = sdem.config();
    let grid = sdem.grid();
    let az_span = config.azimuth_max_deg - config.azimuth_min_deg;
    let el_span = config.elevation_max_deg - config.elevation_min_deg;
    let data_w: i64 = 1080;
    let data_h = ((data_w as f64 * el_span / az_span).round() as i64).clamp(120, 720);
    let (left, top) = (110, 80);
    let mut canvas = Canvas::new((left + data_w + 170) as u32, (top + data_h + 90) as u32);
    let axes = Axes {
        left,
        top,
        width: data_w,
        height: data_h,
        x_range: (config.azimuth_max_deg, config.azimuth_min_deg),
        y_range: (config.elevation_min_deg, config.elevation_max_deg),
    };
    let mut known: Vec<f64> = sdem
        .ranges()
        .iter()
        .filter(|r| !r.is_nan())
        .map(|&r| r as f64)
        .collect();
    let known_count = known.len();
    let max_range = nice_max(&mut known);
    let res = config.resolution_deg;
    let (az_cells, el_cells) = (grid.azimuth_cells() as i64, grid.elevation_cells() as i64);
    for row in top..top + data_h {
        for column in left..left + data_w {
            let (az, el) = axes.data_at(column, row);
            let ia = ((az - config.azimuth_min_deg) / res).floor() as i64;
            let ie = ((el - config.elevation_min_deg) / res).floor() as i64;
            let color = if (0..az_cells).contains(&ia) && (0..el_cells).contains(&ie) {
                match sdem.range((ie * az_cells + ia) as usize) {
                    Some(r) => turbo(r as f64 / max_range),
                    None => Canvas::unknown_at(column, row),
                }
            } else {
                Canvas::unknown_at(column, row)
            };
            canvas.put(column, row, color);
        }
    }
    axes.draw_frame(
        &mut canvas,
        "azimuth (°), counter-clockwise from +x; left = turning left",
        "elevation (°)",
        Some(if az_span > 180.0 {
            30.0
        } else {
            super::draw::nice_step(az_span, 8.0)
        }),
        Some(if el_span > 90.0 {
            30.0
        } else {
            super::draw::nice_step(el_span, 6.0)
        }),
    );
    title(&mut canvas, &format!("S-DEM panorama: {title_text}"));
    subtitle(
        &mut canvas,
        &format!(
            "{res}° cells, {known_count} of {} known ({:.0} %); grey hatch = unknown",
            grid.len(),
            100.0 * known_count as f64 / grid.len().max(1) as f64
        ),
    );
    color_bar(
        &mut canvas,
        left + data_w + 40,
        top + 30,
        28,
        data_h - 60,
        (0.0, max_range),
        turbo,
        "range (m)",
    );
    canvas.image
}

/// One elevation band of the S-DEM seen from above, like the paper's Fig. 10–11: for each azimuth
/// cell of the band, free space (light blue) fills from the sensor out to the boundary point
/// (red), drawn at its horizontal distance `range · cos(elevation)`; directions with no return
/// are hatched grey out to the plot's edge. Rings are labelled in metres, spokes in degrees of
/// azimuth; +x points right and +y up.
///
/// # Arguments
/// * `sdem` — the S-DEM.
/// * `elevation_deg` — the elevation whose band is drawn (the band holding it; clamped to the
///   grid's extent), degrees.
/// * `title` — a line above the picture.
///
/// # Returns
/// An RGB image about 1000 × 900 pixels.
pub fn sdem_polar_slice(sdem: &Sdem, elevation_deg: f64, title_text: &str) -> RgbImage {
    let config = sdem.config();
    let grid = sdem.grid();
    let res = config.resolution_deg;
    let el_cells = grid.elevation_cells() as i64;
    let az_cells = grid.azimuth_cells() as i64;
    let requested = if elevation_deg.is_finite() {
        elevation_deg
    } else {
        0.0
    };
    let ie = (((requested - config.elevation_min_deg) / res).floor() as i64).clamp(0, el_cells - 1);
    let band_lo = config.elevation_min_deg + ie as f64 * res;
    let band_mid = (band_lo + res / 2.0).to_radians();
    // Horizontal distance of each azimuth cell's boundary point (None: unknown).
    let horizontal: Vec<Option<f64>> = (0..az_cells)
        .map(|ia| {
            sdem.range((ie * az_cells + ia) as usize)
                .map(|r| r as f64 * band_mid.cos().abs().max(1e-3))
        })
        .collect();
    let mut known: Vec<f64> = horizontal.iter().flatten().copied().collect();
    let known_count = known.len();
    let radius = nice_max(&mut known);
    let size: i64 = 760;
    let (left, top) = (120, 90);
    let mut canvas = Canvas::new((left + size + 300) as u32, (top + size + 90) as u32);
    let axes = Axes {
        left,
        top,
        width: size,
        height: size,
        x_range: (-radius, radius),
        y_range: (-radius, radius),
    };
    let polar = Polar {
        cx: axes.px(0.0),
        cy: axes.py(0.0),
        ppm: axes.x_scale(),
        radius,
    };
    paint_free_space(&mut canvas, &axes, config, &horizontal, radius);
    let ring_step = rings_and_spokes(&mut canvas, &polar);
    draw_boundary(&mut canvas, &polar, config, &horizontal);
    // Ring labels on the +x spoke, over the picture.
    let (cx, cy, ppm) = (polar.cx, polar.cy, polar.ppm);
    let mut r = ring_step;
    while r <= radius + 1e-9 {
        canvas.text_boxed(
            (cx + r * ppm * (-75f64).to_radians().cos()).round() as i64,
            (cy - r * ppm * (-75f64).to_radians().sin()).round() as i64,
            &format!("{} m", tick_label(r, ring_step)),
            LABEL_SCALE,
            Anchor::Center,
            INK,
        );
        r += ring_step;
    }
    // The sensor.
    canvas.disc(cx, cy, 6.0, INK);
    canvas.disc(cx, cy, 3.5, WHITE);
    title(
        &mut canvas,
        &format!(
            "S-DEM slice at elevation {:.0}° (band {} to {}°): {title_text}",
            requested,
            tick_label(band_lo, res),
            tick_label(band_lo + res, res)
        ),
    );
    subtitle(
        &mut canvas,
        &format!(
            "seen from above, +x right, +y up; {known_count} of {az_cells} directions known; horizontal distance"
        ),
    );
    legend(
        &mut canvas,
        left + size + 50,
        top + 20,
        &[
            (Swatch::Fill(FREE), "free space"),
            (Swatch::Dot(BOUNDARY), "boundary point"),
            (Swatch::Unknown, "unknown"),
            (Swatch::Dot(WHITE), "sensor"),
        ],
    );
    canvas.image
}

/// The polar slice's plot: the sensor's pixel, pixels per metre, and the outer ring's radius,
/// metres.
struct Polar {
    cx: f64,
    cy: f64,
    ppm: f64,
    radius: f64,
}

/// Fills the disc of `radius` in `axes`: free space out to each azimuth cell's boundary point at
/// its `horizontal` distance, white beyond, hatched where the cell is unknown.
fn paint_free_space(
    canvas: &mut Canvas,
    axes: &Axes,
    config: &SdemConfig,
    horizontal: &[Option<f64>],
    radius: f64,
) {
    let res = config.resolution_deg;
    let az_cells = horizontal.len() as i64;
    let cell_of_azimuth = |az_deg: f64| -> Option<usize> {
        let ia = ((az_deg - config.azimuth_min_deg) / res).floor() as i64;
        (0..az_cells).contains(&ia).then_some(ia as usize)
    };
    for row in axes.top..axes.top + axes.height {
        for column in axes.left..axes.left + axes.width {
            let (x, y) = axes.data_at(column, row);
            let rho = (x * x + y * y).sqrt();
            if rho > radius {
                continue;
            }
            let mut az = y.atan2(x).to_degrees();
            if az >= 180.0 {
                az -= 360.0;
            }
            let color = match cell_of_azimuth(az).map(|i| horizontal[i]) {
                Some(Some(h)) if rho <= h => FREE,
                Some(Some(_)) => WHITE,
                _ => Canvas::unknown_at(column, row),
            };
            canvas.put(column, row, color);
        }
    }
}

/// Draws the rings (unlabelled) and the labelled spokes every 30°; returns the rings' spacing,
/// metres.
fn rings_and_spokes(canvas: &mut Canvas, polar: &Polar) -> f64 {
    let Polar {
        cx,
        cy,
        ppm,
        radius,
    } = *polar;
    let ring_step = super::draw::nice_step(radius, 4.0);
    let mut r = ring_step;
    while r <= radius + 1e-9 {
        canvas.ring(cx, cy, r * ppm, 1.0, Rgb([120, 120, 120]));
        r += ring_step;
    }
    for k in 0..12 {
        let a = (k as f64 * 30.0).to_radians();
        let end = (cx + radius * ppm * a.cos(), cy - radius * ppm * a.sin());
        canvas.line((cx, cy), end, 1.0, Rgb([160, 160, 160]), Some((4.0, 4.0)));
        let label_r = radius * ppm + 22.0;
        let deg = if k <= 6 { k * 30 } else { k * 30 - 360 };
        canvas.text(
            (cx + label_r * a.cos()).round() as i64,
            (cy - label_r * a.sin()).round() as i64,
            &format!("{deg}°"),
            LABEL_SCALE,
            Anchor::Center,
            INK,
        );
    }
    ring_step
}

/// The boundary: a dot per known cell within the plot, joined where neighbours are both known.
fn draw_boundary(
    canvas: &mut Canvas,
    polar: &Polar,
    config: &SdemConfig,
    horizontal: &[Option<f64>],
) {
    let Polar {
        cx,
        cy,
        ppm,
        radius,
    } = *polar;
    let res = config.resolution_deg;
    let point_of = |ia: usize, h: f64| {
        let az = (config.azimuth_min_deg + (ia as f64 + 0.5) * res).to_radians();
        (cx + h * az.cos() * ppm, cy - h * az.sin() * ppm)
    };
    let n = horizontal.len();
    let full = (config.azimuth_max_deg - config.azimuth_min_deg - 360.0).abs() < 1e-9;
    for ia in 0..n {
        let next = if ia + 1 < n {
            Some(ia + 1)
        } else if full {
            Some(0)
        } else {
            None
        };
        if let (Some(h0), Some(Some(h1))) = (horizontal[ia], next.map(|j| horizontal[j])) {
            // Join only where the surface is continuous (no jump past a quarter of the range).
            if (h0 - h1).abs() < 0.25 * h0.max(h1) {
                canvas.line(
                    point_of(ia, h0),
                    point_of(next.unwrap_or(0), h1),
                    1.5,
                    BOUNDARY,
                    None,
                );
            }
        }
    }
    for (ia, h) in horizontal.iter().enumerate() {
        if let Some(h) = h {
            if *h <= radius {
                let (x, y) = point_of(ia, *h);
                canvas.disc(x, y, 2.2, BOUNDARY);
            }
        }
    }
}
