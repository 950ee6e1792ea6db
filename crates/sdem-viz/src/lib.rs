//! # sdem-viz — pictures for people
//!
//! The viewing method Nagatani et al. (2003) leave to future work (Sec. VI: "a viewing method of
//! detected environment information for a human").
//!
//! Every function here is pure: it takes plain values and returns an image or a string; the
//! caller writes them (see [`encode_png`]). Each picture has axes, a scale and a legend; text is
//! set in Noto Sans (embedded, SIL Open Font License 1.1, `fonts/OFL.txt`) and anti-aliased, as
//! are lines and discs.
//!
//! | picture | function |
//! |---|---|
//! | an S-DEM as a panorama (azimuth × elevation, range colour-mapped, unknown hatched) | [`sdem_panorama`] |
//! | an S-DEM slice at one elevation, from above (free space, boundary, unknown; Fig. 10–11) | [`sdem_polar_slice`] |
//! | the map from above, height-shaded, with trajectory, nodes and loop closures | [`map_plan`] |
//! | a vertical cut through the map | [`map_section`] |
//! | a localization's cost over x–y through the optimum | [`sample_cost_slice`], [`cost_surface`] |
//! | a self-contained 3D viewer page (inline WebGL, no network) | [`viewer_html`] |
//! | measurements against a count, with running medians (time per stop by stop number) | [`series_plot`] |
//!
//! # Example
//! ```
//! use sdem::geometry::{Pose, Vec3};
//! use sdem_viz::{encode_png, map_plan, MapView};
//! let points: Vec<Vec3> = (0..400)
//!     .map(|i| Vec3::new((i % 20) as f64 * 0.1, (i / 20) as f64 * 0.1, (i % 7) as f64 * 0.1))
//!     .collect();
//! let poses = vec![Pose::identity(), Pose::translation(1.0, 0.5, 0.0)];
//! let view = MapView { points_in_world: &points, world_from_node: &poses, loop_closures: &[] };
//! let png = encode_png(&map_plan(&view, "a patch")).unwrap();
//! assert_eq!(&png[1..4], b"PNG");
//! ```

mod cost_view;
mod draw;
mod html;
mod map_view;
mod plot;
mod sdem_view;
mod text;

pub use cost_view::{cost_surface, sample_cost_slice, CostSlice};
pub use html::{viewer_html, VIEWER_MAX_POINTS};
pub use image::{Rgb, RgbImage};
pub use map_view::{map_plan, map_section, MapView, Section};
pub use plot::{series_plot, Series};
pub use sdem_view::{sdem_panorama, sdem_polar_slice};

use sdem::error::{Error, Result};

/// Encodes a picture as PNG bytes (in memory; the caller writes the file).
///
/// # Errors
/// When the encoder fails (it does not for a well-formed image).
pub fn encode_png(image: &RgbImage) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(
            image.as_raw(),
            image.width(),
            image.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| Error::Invalid(format!("cannot encode a PNG: {e}")))?;
    Ok(bytes)
}

#[cfg(test)]
mod tests;
