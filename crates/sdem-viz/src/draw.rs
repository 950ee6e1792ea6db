//! Drawing primitives over an [`RgbImage`]: lines, discs, colour maps, axes with ticks, colour
//! bars, legends and scale bars (text is `text.rs`'s).

pub(crate) use super::text::{text_height, text_width};
use image::{Rgb, RgbImage};

/// White.
pub(crate) const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
/// Text and axes.
pub(crate) const INK: Rgb<u8> = Rgb([25, 25, 25]);
/// Grid lines.
pub(crate) const GRID: Rgb<u8> = Rgb([215, 215, 215]);
/// Unknown cells: a mid grey, hatched with [`UNKNOWN_HATCH`].
pub(crate) const UNKNOWN: Rgb<u8> = Rgb([150, 150, 150]);
/// The hatch over unknown cells.
pub(crate) const UNKNOWN_HATCH: Rgb<u8> = Rgb([185, 185, 185]);
/// The trajectory and loop closures.
pub(crate) const TRAJECTORY: Rgb<u8> = Rgb([220, 20, 60]);
/// Loop-closure lines.
pub(crate) const LOOP: Rgb<u8> = Rgb([230, 0, 230]);

/// Text size of labels and titles (see `text.rs`: an 18-pixel em).
pub(crate) const LABEL_SCALE: i64 = 2;

/// Where a text's reference point lies on it.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Anchor {
    /// Left end, vertically centred.
    Left,
    /// Right end, vertically centred.
    Right,
    /// Horizontally centred, top edge.
    Top,
    /// Horizontally centred, bottom edge.
    Bottom,
    /// Centre.
    Center,
}

/// An image with drawing operations; coordinates outside it are clipped.
pub(crate) struct Canvas {
    pub(crate) image: RgbImage,
}

impl Canvas {
    /// A canvas filled with white.
    pub(crate) fn new(width: u32, height: u32) -> Self {
        Self {
            image: RgbImage::from_pixel(width.max(1), height.max(1), WHITE),
        }
    }

    pub(crate) fn width(&self) -> i64 {
        self.image.width() as i64
    }

    pub(crate) fn height(&self) -> i64 {
        self.image.height() as i64
    }

    /// Sets one pixel.
    pub(crate) fn put(&mut self, x: i64, y: i64, color: Rgb<u8>) {
        if x >= 0 && y >= 0 && x < self.width() && y < self.height() {
            self.image.put_pixel(x as u32, y as u32, color);
        }
    }

    /// Mixes `color` into one pixel with weight `alpha` in [0, 1].
    pub(crate) fn blend(&mut self, x: i64, y: i64, color: Rgb<u8>, alpha: f64) {
        if x >= 0 && y >= 0 && x < self.width() && y < self.height() {
            let a = alpha.clamp(0.0, 1.0);
            let p = self.image.get_pixel_mut(x as u32, y as u32);
            for k in 0..3 {
                p.0[k] = (p.0[k] as f64 * (1.0 - a) + color.0[k] as f64 * a).round() as u8;
            }
        }
    }

    /// Fills `[x0, x1) × [y0, y1)`.
    pub(crate) fn fill_rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, color: Rgb<u8>) {
        for y in y0.max(0)..y1.min(self.height()) {
            for x in x0.max(0)..x1.min(self.width()) {
                self.image.put_pixel(x as u32, y as u32, color);
            }
        }
    }

    /// The outline of `[x0, x1) × [y0, y1)`, one pixel wide.
    pub(crate) fn rect_outline(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, color: Rgb<u8>) {
        self.fill_rect(x0, y0, x1, y0 + 1, color);
        self.fill_rect(x0, y1 - 1, x1, y1, color);
        self.fill_rect(x0, y0, x0 + 1, y1, color);
        self.fill_rect(x1 - 1, y0, x1, y1, color);
    }

    /// A filled disc of radius `r` pixels, its edge anti-aliased.
    pub(crate) fn disc(&mut self, cx: f64, cy: f64, r: f64, color: Rgb<u8>) {
        let (x0, x1) = ((cx - r - 1.0).floor() as i64, (cx + r + 1.0).ceil() as i64);
        let (y0, y1) = ((cy - r - 1.0).floor() as i64, (cy + r + 1.0).ceil() as i64);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let d = ((x as f64 + 0.5 - cx).powi(2) + (y as f64 + 0.5 - cy).powi(2)).sqrt();
                let coverage = (r + 0.5 - d).clamp(0.0, 1.0);
                if coverage > 0.0 {
                    self.blend(x, y, color, coverage);
                }
            }
        }
    }

    /// A ring of radius `r` and the given width, anti-aliased.
    pub(crate) fn ring(&mut self, cx: f64, cy: f64, r: f64, width: f64, color: Rgb<u8>) {
        let outer = r + width / 2.0;
        let inner = r - width / 2.0;
        let (x0, x1) = (
            (cx - outer - 1.0).floor() as i64,
            (cx + outer + 1.0).ceil() as i64,
        );
        let (y0, y1) = (
            (cy - outer - 1.0).floor() as i64,
            (cy + outer + 1.0).ceil() as i64,
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let d = ((x as f64 + 0.5 - cx).powi(2) + (y as f64 + 0.5 - cy).powi(2)).sqrt();
                let coverage = (outer + 0.5 - d).min(d - inner + 0.5).clamp(0.0, 1.0);
                if coverage > 0.0 {
                    self.blend(x, y, color, coverage);
                }
            }
        }
    }

    /// A line of the given width, anti-aliased; `dash` (on, off) in pixels makes it dashed.
    pub(crate) fn line(
        &mut self,
        from: (f64, f64),
        to: (f64, f64),
        width: f64,
        color: Rgb<u8>,
        dash: Option<(f64, f64)>,
    ) {
        let (dx, dy) = (to.0 - from.0, to.1 - from.1);
        let length = (dx * dx + dy * dy).sqrt();
        if !length.is_finite() {
            return;
        }
        let half = width / 2.0;
        let (x0, x1) = (
            (from.0.min(to.0) - half - 1.0).floor() as i64,
            (from.0.max(to.0) + half + 1.0).ceil() as i64,
        );
        let (y0, y1) = (
            (from.1.min(to.1) - half - 1.0).floor() as i64,
            (from.1.max(to.1) + half + 1.0).ceil() as i64,
        );
        // Far outside the canvas: nothing to draw (and no huge loops).
        if x1 < 0 || y1 < 0 || x0 > self.width() || y0 > self.height() {
            return;
        }
        let (x0, x1) = (x0.max(-1), x1.min(self.width() + 1));
        let (y0, y1) = (y0.max(-1), y1.min(self.height() + 1));
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (px, py) = (x as f64 + 0.5 - from.0, y as f64 + 0.5 - from.1);
                let t = if length > 0.0 {
                    ((px * dx + py * dy) / (length * length)).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                if let Some((on, off)) = dash {
                    if (t * length).rem_euclid(on + off) > on {
                        continue;
                    }
                }
                let d = ((px - t * dx).powi(2) + (py - t * dy).powi(2)).sqrt();
                let coverage = (half + 0.5 - d).clamp(0.0, 1.0);
                if coverage > 0.0 {
                    self.blend(x, y, color, coverage);
                }
            }
        }
    }

    /// Unknown cells' look at pixel `(x, y)`: grey with a diagonal hatch.
    pub(crate) fn unknown_at(x: i64, y: i64) -> Rgb<u8> {
        if (x + y).rem_euclid(8) < 2 {
            UNKNOWN_HATCH
        } else {
            UNKNOWN
        }
    }
}

/// A colour map from [0, 1] to a colour.
pub(crate) type ColorMap = fn(f64) -> Rgb<u8>;

/// Turbo (Mikhailov 2019), the polynomial approximation: a perceptual rainbow, dark blue → red.
pub(crate) fn turbo(t: f64) -> Rgb<u8> {
    let x = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let r = 0.13572138
        + x * (4.61539260
            + x * (-42.66032258 + x * (132.13108234 + x * (-152.94239396 + x * 59.28637943))));
    let g = 0.09140261
        + x * (2.19418839
            + x * (4.84296658 + x * (-14.18503333 + x * (4.27729857 + x * 2.82956604))));
    let b = 0.10667330
        + x * (12.64194608
            + x * (-60.58204836 + x * (110.36276771 + x * (-89.90310912 + x * 27.34824973))));
    let to_u8 = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    Rgb([to_u8(r), to_u8(g), to_u8(b)])
}

/// Viridis (van der Walt & Smith 2015), interpolated between nine stops: dark purple → yellow.
pub(crate) fn viridis(t: f64) -> Rgb<u8> {
    const STOPS: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [71.0, 44.0, 123.0],
        [59.0, 82.0, 139.0],
        [44.0, 114.0, 142.0],
        [33.0, 145.0, 140.0],
        [40.0, 174.0, 128.0],
        [94.0, 201.0, 98.0],
        [173.0, 220.0, 48.0],
        [253.0, 231.0, 37.0],
    ];
    let x = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    } * (STOPS.len() - 1) as f64;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f64;
    let c = |k: usize| (STOPS[i][k] * (1.0 - f) + STOPS[i + 1][k] * f).round() as u8;
    Rgb([c(0), c(1), c(2)])
}

/// A "nice" tick step (1, 2 or 5 × 10^k) giving about `target` ticks over `span`.
pub(crate) fn nice_step(span: f64, target: f64) -> f64 {
    if !(span.is_finite() && span > 0.0) {
        return 1.0;
    }
    let raw = span / target.max(1.0);
    let magnitude = 10f64.powf(raw.log10().floor());
    let r = raw / magnitude;
    let nice = if r < 1.5 {
        1.0
    } else if r < 3.5 {
        2.0
    } else if r < 7.5 {
        5.0
    } else {
        10.0
    };
    nice * magnitude
}

/// A tick label: as many decimals as the step needs.
pub(crate) fn tick_label(value: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil().max(0.0) as usize
    };
    let text = format!("{:.*}", decimals, value);
    // No "-0".
    if text
        .trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        text.trim_start_matches('-').to_string()
    } else {
        text
    }
}

/// The values of the ticks over `[lo, hi]` at `step`.
pub(crate) fn ticks(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last.max(first - 1))
        .map(|k| k as f64 * step)
        .take(200)
        .collect()
}

/// A plotting area: a pixel rectangle and the data range it shows.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Axes {
    /// Left edge of the data area, pixels.
    pub(crate) left: i64,
    /// Top edge, pixels.
    pub(crate) top: i64,
    /// Width, pixels.
    pub(crate) width: i64,
    /// Height, pixels.
    pub(crate) height: i64,
    /// Data value at the left and right edges.
    pub(crate) x_range: (f64, f64),
    /// Data value at the bottom and top edges.
    pub(crate) y_range: (f64, f64),
}

impl Axes {
    /// Pixel column of data `x` (may lie outside the area).
    pub(crate) fn px(&self, x: f64) -> f64 {
        self.left as f64
            + (x - self.x_range.0) / (self.x_range.1 - self.x_range.0) * self.width as f64
    }

    /// Pixel row of data `y`, up on the page.
    pub(crate) fn py(&self, y: f64) -> f64 {
        self.top as f64
            + (self.y_range.1 - y) / (self.y_range.1 - self.y_range.0) * self.height as f64
    }

    /// Data `(x, y)` at the centre of pixel `(column, row)`.
    pub(crate) fn data_at(&self, column: i64, row: i64) -> (f64, f64) {
        let fx = (column - self.left) as f64 + 0.5;
        let fy = (row - self.top) as f64 + 0.5;
        (
            self.x_range.0 + fx / self.width as f64 * (self.x_range.1 - self.x_range.0),
            self.y_range.1 - fy / self.height as f64 * (self.y_range.1 - self.y_range.0),
        )
    }

    /// Pixels per data unit along x.
    pub(crate) fn x_scale(&self) -> f64 {
        self.width as f64 / (self.x_range.1 - self.x_range.0).abs()
    }

    /// True when pixel `(x, y)` is inside the data area.
    pub(crate) fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.left as f64
            && y >= self.top as f64
            && x < (self.left + self.width) as f64
            && y < (self.top + self.height) as f64
    }

    /// Axes of equal scale on x and y that fit `[x0, x1] × [y0, y1]` into at most
    /// `max_width` × `max_height` pixels at `(left, top)`.
    pub(crate) fn equal(
        left: i64,
        top: i64,
        max_width: i64,
        max_height: i64,
        x: (f64, f64),
        y: (f64, f64),
    ) -> Axes {
        let span_x = (x.1 - x.0).max(1e-6);
        let span_y = (y.1 - y.0).max(1e-6);
        let scale = (max_width as f64 / span_x).min(max_height as f64 / span_y);
        Axes {
            left,
            top,
            width: (span_x * scale).round().max(1.0) as i64,
            height: (span_y * scale).round().max(1.0) as i64,
            x_range: x,
            y_range: y,
        }
    }

    /// The frame, grid lines under the data (call before drawing data), tick marks and labels.
    /// `x_step`/`y_step` force the tick spacing.
    pub(crate) fn draw_grid(&self, canvas: &mut Canvas, x_step: Option<f64>, y_step: Option<f64>) {
        let xs = x_step.unwrap_or_else(|| nice_step((self.x_range.1 - self.x_range.0).abs(), 8.0));
        let ys = y_step.unwrap_or_else(|| nice_step((self.y_range.1 - self.y_range.0).abs(), 6.0));
        for v in ticks(self.x_range.0, self.x_range.1, xs) {
            let x = self.px(v).round() as i64;
            canvas.fill_rect(x, self.top, x + 1, self.top + self.height, GRID);
        }
        for v in ticks(self.y_range.0, self.y_range.1, ys) {
            let y = self.py(v).round() as i64;
            canvas.fill_rect(self.left, y, self.left + self.width, y + 1, GRID);
        }
    }

    /// The frame, ticks, tick labels and axis titles (call after drawing data).
    pub(crate) fn draw_frame(
        &self,
        canvas: &mut Canvas,
        x_title: &str,
        y_title: &str,
        x_step: Option<f64>,
        y_step: Option<f64>,
    ) {
        let s = LABEL_SCALE;
        let (l, t, r, b) = (
            self.left,
            self.top,
            self.left + self.width,
            self.top + self.height,
        );
        canvas.rect_outline(l - 1, t - 1, r + 1, b + 1, INK);
        let xs = x_step.unwrap_or_else(|| nice_step((self.x_range.1 - self.x_range.0).abs(), 8.0));
        let ys = y_step.unwrap_or_else(|| nice_step((self.y_range.1 - self.y_range.0).abs(), 6.0));
        for v in ticks(self.x_range.0, self.x_range.1, xs) {
            let x = self.px(v).round() as i64;
            canvas.fill_rect(x, b, x + 1, b + 6, INK);
            canvas.text(x, b + 9, &tick_label(v, xs), s, Anchor::Top, INK);
        }
        let mut widest = 0;
        for v in ticks(self.y_range.0, self.y_range.1, ys) {
            let y = self.py(v).round() as i64;
            canvas.fill_rect(l - 6, y, l, y + 1, INK);
            let label = tick_label(v, ys);
            widest = widest.max(text_width(&label, s));
            canvas.text(l - 9, y, &label, s, Anchor::Right, INK);
        }
        canvas.text(
            (l + r) / 2,
            b + 9 + text_height(s) + 10,
            x_title,
            s,
            Anchor::Top,
            INK,
        );
        canvas.text_vertical(
            l - 9 - widest - 8 - text_height(s) / 2,
            (t + b) / 2,
            y_title,
            s,
            INK,
        );
    }
}

/// A vertical colour bar at `(left, top)`, `width` × `height` pixels, for values `lo..hi`
/// (bottom to top), with ticks and a title above.
#[allow(clippy::too_many_arguments)]
pub(crate) fn color_bar(
    canvas: &mut Canvas,
    left: i64,
    top: i64,
    width: i64,
    height: i64,
    range: (f64, f64),
    map: ColorMap,
    title: &str,
) {
    let (lo, hi) = range;
    for y in 0..height {
        let t = 1.0 - (y as f64 + 0.5) / height as f64;
        canvas.fill_rect(left, top + y, left + width, top + y + 1, map(t));
    }
    canvas.rect_outline(left - 1, top - 1, left + width + 1, top + height + 1, INK);
    let step = nice_step(hi - lo, 6.0);
    for v in ticks(lo, hi, step) {
        let y = top as f64 + (hi - v) / (hi - lo) * height as f64;
        let y = y.round() as i64;
        canvas.fill_rect(left + width, y, left + width + 6, y + 1, INK);
        canvas.text(
            left + width + 9,
            y,
            &tick_label(v, step),
            LABEL_SCALE,
            Anchor::Left,
            INK,
        );
    }
    // Left-aligned over the bar, so a long title runs into the margin, not over the data.
    canvas.text(left - 4, top - 22, title, LABEL_SCALE, Anchor::Left, INK);
}

/// One entry of a legend: a swatch drawer and a label.
pub(crate) enum Swatch {
    /// A filled square.
    Fill(Rgb<u8>),
    /// The hatched grey of unknown cells.
    Unknown,
    /// A line, dashed or not.
    Line(Rgb<u8>, bool),
    /// A disc with a dark outline.
    Dot(Rgb<u8>),
}

/// A legend box at `(left, top)`, one entry per line; returns its bottom edge.
pub(crate) fn legend(canvas: &mut Canvas, left: i64, top: i64, entries: &[(Swatch, &str)]) -> i64 {
    let s = LABEL_SCALE;
    let line_h = text_height(s) + 10;
    let width = 34
        + entries
            .iter()
            .map(|(_, t)| text_width(t, s))
            .max()
            .unwrap_or(0)
        + 12;
    let height = entries.len() as i64 * line_h + 8;
    canvas.fill_rect(left, top, left + width, top + height, WHITE);
    canvas.rect_outline(left, top, left + width, top + height, INK);
    for (i, (swatch, label)) in entries.iter().enumerate() {
        let cy = top + 4 + i as i64 * line_h + line_h / 2;
        let (x0, x1) = (left + 8, left + 28);
        match swatch {
            Swatch::Fill(c) => {
                canvas.fill_rect(x0, cy - 7, x1, cy + 7, *c);
                canvas.rect_outline(x0, cy - 7, x1, cy + 7, INK);
            }
            Swatch::Unknown => {
                for y in cy - 7..cy + 7 {
                    for x in x0..x1 {
                        canvas.put(x, y, Canvas::unknown_at(x, y));
                    }
                }
                canvas.rect_outline(x0, cy - 7, x1, cy + 7, INK);
            }
            Swatch::Line(c, dashed) => canvas.line(
                (x0 as f64, cy as f64),
                (x1 as f64, cy as f64),
                3.0,
                *c,
                dashed.then_some((5.0, 3.0)),
            ),
            Swatch::Dot(c) => {
                canvas.disc((x0 + x1) as f64 / 2.0, cy as f64, 6.0, INK);
                canvas.disc((x0 + x1) as f64 / 2.0, cy as f64, 4.5, *c);
            }
        }
        canvas.text(x1 + 8, cy, label, s, Anchor::Left, INK);
    }
    top + height
}

/// A scale bar of a nice length near `target_px` pixels at `(left, bottom)`, labelled in metres.
pub(crate) fn scale_bar(
    canvas: &mut Canvas,
    left: i64,
    bottom: i64,
    pixels_per_m: f64,
    target_px: f64,
) {
    let length_m = nice_step(target_px / pixels_per_m, 1.0);
    let length_px = (length_m * pixels_per_m).round() as i64;
    let label = format!("{} m", tick_label(length_m, length_m));
    let h = text_height(LABEL_SCALE);
    let box_w = length_px.max(text_width(&label, LABEL_SCALE)) + 16;
    for y in bottom - h - 26..bottom {
        for x in left..left + box_w {
            canvas.blend(x, y, WHITE, 0.85);
        }
    }
    let x0 = left + 8;
    let y = bottom - 8;
    canvas.fill_rect(x0, y - 4, x0 + length_px, y, INK);
    canvas.fill_rect(x0, y - 10, x0 + 2, y, INK);
    canvas.fill_rect(x0 + length_px - 2, y - 10, x0 + length_px, y, INK);
    canvas.text(
        x0 + length_px / 2,
        y - 14,
        &label,
        LABEL_SCALE,
        Anchor::Bottom,
        INK,
    );
}

/// A title centred at the top of the canvas.
pub(crate) fn title(canvas: &mut Canvas, text: &str) {
    let w = canvas.width();
    canvas.text(w / 2, 12, text, LABEL_SCALE, Anchor::Top, INK);
}

/// A smaller note under the title.
pub(crate) fn subtitle(canvas: &mut Canvas, text: &str) {
    let w = canvas.width();
    canvas.text(
        w / 2,
        12 + text_height(LABEL_SCALE) + 8,
        text,
        LABEL_SCALE,
        Anchor::Top,
        Rgb([90, 90, 90]),
    );
}

/// The `q`-quantile (0..=1) of finite `values` (sorted in place), or `None` when there are none.
pub(crate) fn quantile(values: &mut [f64], q: f64) -> Option<f64> {
    let n = values.len();
    if n == 0 {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let i = ((n - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    Some(values[i])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_steps_and_labels() {
        assert_eq!(nice_step(10.0, 5.0), 2.0);
        assert_eq!(nice_step(360.0, 8.0), 50.0);
        assert_eq!(nice_step(0.3, 6.0), 0.05);
        assert_eq!(tick_label(-0.0, 0.5), "0.0");
        assert_eq!(tick_label(1.25, 0.05), "1.25");
        assert_eq!(ticks(-1.0, 1.0, 0.5).len(), 5);
    }

    #[test]
    fn color_maps_run_from_dark_to_light() {
        let luma = |c: Rgb<u8>| c.0[0] as u32 * 3 + c.0[1] as u32 * 6 + c.0[2] as u32;
        assert!(luma(viridis(0.0)) < luma(viridis(1.0)));
        assert_ne!(turbo(0.0), turbo(0.5));
        assert_ne!(turbo(0.5), turbo(1.0));
        assert_eq!(turbo(f64::NAN), turbo(0.0));
    }
}
