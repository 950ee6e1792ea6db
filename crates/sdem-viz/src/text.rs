//! Text on the pictures: the one module that draws it.
//!
//! Glyphs come from Noto Sans (SIL Open Font License 1.1; `fonts/OFL.txt`), subset to Latin,
//! Greek, arrows and the signs labels use (`fonts/make_subset.sh` says how it was made, 21 kB),
//! embedded in the crate, and rasterized by `ab_glyph` with anti-aliased coverage. A `scale` of
//! 1 sets an em of [`EM_PX_PER_SCALE`] pixels; [`text_height`] is the height of a capital, which
//! the layout code spaces lines by; descenders hang below it. A character the font lacks is
//! drawn as `?`.

use super::draw::{Anchor, Canvas, WHITE};
use ab_glyph::{point, Font, FontRef, Glyph, GlyphId, PxScale, ScaleFont};
use image::Rgb;
use std::sync::OnceLock;

/// Pixels per em at `scale` 1 (labels use scale 2: an 18-pixel em, capitals 13 pixels high).
pub(crate) const EM_PX_PER_SCALE: f32 = 9.0;

/// The embedded font's bytes.
const FONT_BYTES: &[u8] = include_bytes!("../fonts/NotoSans-Regular-subset.ttf");

/// The embedded font, parsed once.
fn font() -> &'static FontRef<'static> {
    static FONT: OnceLock<FontRef<'static>> = OnceLock::new();
    FONT.get_or_init(|| {
        FontRef::try_from_slice(FONT_BYTES).expect("the embedded font parses (a unit test says so)")
    })
}

/// The `ab_glyph` scale whose em is `EM_PX_PER_SCALE × scale` pixels (`PxScale` counts the
/// font's whole height, ascent to descent).
fn px_scale(scale: i64) -> PxScale {
    let f = font();
    let em = EM_PX_PER_SCALE * scale.max(1) as f32;
    PxScale::from(em * f.height_unscaled() / f.units_per_em().unwrap_or(1000.0))
}

/// The glyph of `c`, or of `?` when the font lacks it.
fn glyph_id(c: char) -> GlyphId {
    match font().glyph_id(c) {
        GlyphId(0) => font().glyph_id('?'),
        id => id,
    }
}

/// The glyphs of `text` laid out on a baseline at y = 0 from x = 0, with kerning.
fn layout(text: &str, scale: i64) -> (Vec<Glyph>, f32) {
    let scaled = font().as_scaled(px_scale(scale));
    let mut glyphs = Vec::with_capacity(text.len());
    let mut caret = 0.0f32;
    let mut previous: Option<GlyphId> = None;
    for c in text.chars() {
        let id = glyph_id(c);
        if let Some(previous) = previous {
            caret += scaled.kern(previous, id);
        }
        glyphs.push(id.with_scale_and_position(px_scale(scale), point(caret, 0.0)));
        caret += scaled.h_advance(id);
        previous = Some(id);
    }
    (glyphs, caret)
}

/// Width in pixels of `text` at `scale`.
pub(crate) fn text_width(text: &str, scale: i64) -> i64 {
    layout(text, scale).1.ceil() as i64
}

/// Height in pixels of a capital letter at `scale`: the box text is placed by.
pub(crate) fn text_height(scale: i64) -> i64 {
    cap_height(scale).round() as i64
}

fn cap_height(scale: i64) -> f32 {
    let f = font();
    let em = EM_PX_PER_SCALE * scale.max(1) as f32;
    let cap = f
        .outline_glyph(f.glyph_id('H').with_scale(PxScale::from(100.0)))
        .map_or(70.0, |g| -g.px_bounds().min.y);
    // Measured at a 100-pixel PxScale, which is an em of 100 × em / height.
    cap / (100.0 * f.units_per_em().unwrap_or(1000.0) / f.height_unscaled()) * em
}

/// How far descenders reach below the baseline at `scale`, pixels.
fn descent(scale: i64) -> i64 {
    (-font().as_scaled(px_scale(scale)).descent() * 0.8).ceil() as i64
}

/// The top-left corner of `text`'s capital box at `scale` so that `anchor` falls on `(x, y)`.
fn text_origin(x: i64, y: i64, text: &str, scale: i64, anchor: Anchor) -> (i64, i64) {
    let w = text_width(text, scale);
    let h = text_height(scale);
    match anchor {
        Anchor::Left => (x, y - h / 2),
        Anchor::Right => (x - w, y - h / 2),
        Anchor::Top => (x - w / 2, y),
        Anchor::Bottom => (x - w / 2, y - h),
        Anchor::Center => (x - w / 2, y - h / 2),
    }
}

/// Calls `put(u, v, coverage)` for every pixel of `text` whose capitals' top-left corner is at
/// `(0, 0)` (u right, v down), coverage in (0, 1].
fn rasterize(text: &str, scale: i64, mut put: impl FnMut(i64, i64, f32)) {
    let baseline = text_height(scale) as f32;
    let (glyphs, _) = layout(text, scale);
    for mut glyph in glyphs {
        glyph.position.y += baseline;
        if let Some(outlined) = font().outline_glyph(glyph) {
            let bounds = outlined.px_bounds();
            let (left, top) = (bounds.min.x as i64, bounds.min.y as i64);
            outlined.draw(|u, v, coverage| {
                if coverage > 0.0 {
                    put(left + i64::from(u), top + i64::from(v), coverage);
                }
            });
        }
    }
}

impl Canvas {
    /// Text, `scale` 2 for labels, placed by `anchor` at `(x, y)` (the anchor refers to the
    /// capitals' box; descenders hang below it).
    pub(crate) fn text(
        &mut self,
        x: i64,
        y: i64,
        text: &str,
        scale: i64,
        anchor: Anchor,
        color: Rgb<u8>,
    ) {
        let (left, top) = text_origin(x, y, text, scale, anchor);
        rasterize(text, scale, |u, v, coverage| {
            self.blend(left + u, top + v, color, f64::from(coverage));
        });
    }

    /// Text with a white box behind it, so it stays legible over data.
    pub(crate) fn text_boxed(
        &mut self,
        x: i64,
        y: i64,
        text: &str,
        scale: i64,
        anchor: Anchor,
        color: Rgb<u8>,
    ) {
        let (w, h) = (text_width(text, scale), text_height(scale));
        let (left, top) = text_origin(x, y, text, scale, anchor);
        let pad = scale;
        for yy in top - pad..top + h + descent(scale).max(pad) {
            for xx in left - pad..left + w + pad {
                self.blend(xx, yy, WHITE, 0.8);
            }
        }
        self.text(x, y, text, scale, anchor, color);
    }

    /// Text turned a quarter counter-clockwise (read bottom to top), centred on `(x, y)`.
    pub(crate) fn text_vertical(&mut self, x: i64, y: i64, text: &str, scale: i64, color: Rgb<u8>) {
        let w = text_width(text, scale);
        let h = text_height(scale);
        // The text's own (u, v) frame: u along the text, v down. Turned: screen x = v, y = -u.
        let left = x - h / 2;
        let bottom = y + w / 2;
        rasterize(text, scale, |u, v, coverage| {
            self.blend(left + v, bottom - u - 1, color, f64::from(coverage));
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_font_has_every_character_labels_use() {
        FontRef::try_from_slice(FONT_BYTES).unwrap();
        let used = "0123456789 abcdefghijklmnopqrstuvwxyz ABCDEFGHIJKLMNOPQRSTUVWXYZ \
                    .,;:()[]/=%_'#<>?!+-–—°²×±σθφΔµ·…";
        for c in used.chars() {
            assert_ne!(font().glyph_id(c), GlyphId(0), "{c:?} is missing");
        }
        assert_eq!(glyph_id('\u{1F600}'), glyph_id('?'));
    }

    #[test]
    fn sizes_follow_the_scale() {
        // Labels (scale 2): capitals about 13 pixels high.
        assert!((12..=14).contains(&text_height(2)), "{}", text_height(2));
        assert_eq!(text_width("", 2), 0);
        let (narrow, wide) = (text_width("iii", 2), text_width("WWW", 2));
        assert!(narrow < wide, "proportional: {narrow} vs {wide}");
        assert!(text_width("x (m)", 4) > text_width("x (m)", 2));
        // Ink lands where the box says: a capital's pixels fill its height.
        let mut rows = Vec::new();
        rasterize("H", 2, |_, v, c| {
            if c > 0.5 {
                rows.push(v);
            }
        });
        let (top, bottom) = (*rows.iter().min().unwrap(), *rows.iter().max().unwrap());
        assert!(
            top <= 1 && (bottom - text_height(2)).abs() <= 1,
            "{top}..{bottom}"
        );
    }
}
