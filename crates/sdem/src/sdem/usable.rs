//! An S-DEM that holds a return ([`Sdem::from_usable_points`]), and why a scan fills no cell
//! when it does not: one explanation for every caller (a localization's scans, a
//! relocalization's, `sdem localize` and the Python binding), so that they name it alike.

use super::{Sdem, SdemConfig};
use crate::error::{Error, Result};
use crate::geometry::{Attitude, Vec3};

impl Sdem {
    /// [`Self::from_points`], refusing a scan of which the grid can use no point.
    ///
    /// # Errors
    /// [`Error::NoUsablePoints`] when no cell holds a return, saying why with the counts: the
    /// scan is empty, none of its points is finite (NaN: no return), they lie within the grid's
    /// minimum range of the sensor's origin (where a return is the scanner itself), or outside
    /// the grid's extent; [`Error::Invalid`] for an invalid `config`.
    ///
    /// # Example
    /// ```
    /// use sdem::geometry::{Attitude, Vec3};
    /// use sdem::sdem::{Sdem, SdemConfig};
    /// let (at_origin, level) = (vec![Vec3::zeros(); 500], Attitude::default());
    /// match Sdem::from_usable_points(&at_origin, &level, &SdemConfig::default()) {
    ///     Err(sdem::Error::NoUsablePoints { reason }) => {
    ///         assert!(reason.contains("all 500 of its points lie within 0.05 m"), "{reason}")
    ///     }
    ///     other => panic!("{other:?}"),
    /// }
    /// ```
    pub fn from_usable_points(
        points_in_sensor: &[Vec3],
        attitude: &Attitude,
        config: &SdemConfig,
    ) -> Result<Self> {
        let sdem = Self::from_points(points_in_sensor, attitude, config)?;
        if sdem.known_cells() == 0 {
            return Err(no_usable_points(points_in_sensor, attitude, config));
        }
        Ok(sdem)
    }
}

/// [`Error::NoUsablePoints`] for `points` (sensor frame, levelled by `attitude`), which fill no
/// cell of the grid `config`, saying why (for a caller that built the S-DEM from some of them,
/// as [`crate::Scan`] does from the finite ones, to explain it over all of them).
pub(crate) fn no_usable_points(points: &[Vec3], attitude: &Attitude, config: &SdemConfig) -> Error {
    Error::NoUsablePoints {
        reason: why_no_cell(points, attitude, config),
    }
}

/// Why `points` (sensor frame, levelled by `attitude`) fill no cell of the grid `config`: each
/// point is counted as [`Sdem::from_points`] bins it (ranges in `f32`, as the grid computes
/// them), by the first reason it is left out.
fn why_no_cell(points: &[Vec3], attitude: &Attitude, config: &SdemConfig) -> String {
    let total = points.len();
    if total == 0 {
        return "it holds no point".to_string();
    }
    // Beyond this range a point's squared range overflows `f32`, and the grid cannot bin it.
    let farthest_m = f64::from(f32::MAX).sqrt();
    let finite: Vec<f64> = (points.iter())
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .map(|p| p.norm())
        .collect();
    let close = (finite.iter())
        .filter(|&&r| (r as f32) < config.min_range_m as f32)
        .count();
    let far = finite.iter().filter(|&&r| r >= farthest_m).count();
    let not_finite = total - finite.len();
    let outside = finite.len() - close - far;
    let near_words = format!(
        "within {} m of the sensor's origin (the S-DEM's minimum range), where a return is the \
         scanner itself",
        config.min_range_m
    );
    let far_words = format!("farther than {farthest_m:.1e} m, beyond what the grid can bin");
    let grid_words = grid_words(attitude, config);
    if not_finite == total {
        return format!("none of its {total} points is finite (NaN: no return)");
    }
    let all = |what: &str| match total {
        1 => format!("its one point lies {what}"),
        _ => format!("all {total} of its points lie {what}"),
    };
    if close == total {
        return all(&near_words);
    }
    if far == total {
        return all(&far_words);
    }
    if outside == total {
        return all(&format!("outside the S-DEM grid ({grid_words})"));
    }
    let parts: Vec<String> = [
        (
            not_finite,
            ["is", "are"],
            "not finite (NaN: no return)".to_string(),
        ),
        (close, ["lies", "lie"], near_words),
        (far, ["lies", "lie"], far_words),
        (
            outside,
            ["lies", "lie"],
            format!("outside the S-DEM grid ({grid_words})"),
        ),
    ]
    .into_iter()
    .filter(|(count, _, _)| *count > 0)
    .map(|(count, verb, what)| format!("{count} {} {what}", verb[usize::from(count > 1)]))
    .collect();
    format!("of its {total} points, {}", parts.join("; "))
}

/// The grid's extent in words, with the levelling when the reading tilts the scan.
fn grid_words(attitude: &Attitude, config: &SdemConfig) -> String {
    let extent = format!(
        "elevation {}..{}°, azimuth {}..{}°",
        config.elevation_min_deg,
        config.elevation_max_deg,
        config.azimuth_min_deg,
        config.azimuth_max_deg
    );
    let [roll, pitch, _] = attitude.to_degrees();
    if roll == 0.0 && pitch == 0.0 {
        return extent;
    }
    format!("{extent}, levelled by the reading's roll {roll:.1}° and pitch {pitch:.1}°")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(points: &[Vec3], attitude: &Attitude, config: &SdemConfig) -> String {
        match Sdem::from_usable_points(points, attitude, config) {
            Err(Error::NoUsablePoints { reason }) => reason,
            other => panic!("{points:?}: expected NoUsablePoints, got {other:?}"),
        }
    }

    #[test]
    fn a_scan_that_fills_no_cell_is_refused_saying_why_with_the_counts() {
        let (level, grid) = (Attitude::default(), SdemConfig::default());
        let nan = Vec3::new(f64::NAN, 0.0, 0.0);
        let close = Vec3::new(0.01, 0.02, 0.0);
        let far = Vec3::new(1e30, 0.0, 0.0);
        let cases: [(Vec<Vec3>, &str); 7] = [
            (vec![], "it holds no point"),
            (
                vec![nan; 3],
                "none of its 3 points is finite (NaN: no return)",
            ),
            (
                vec![Vec3::zeros(); 500],
                "all 500 of its points lie within 0.05 m",
            ),
            (
                vec![close],
                "its one point lies within 0.05 m of the sensor's origin",
            ),
            (vec![far; 2], "all 2 of its points lie farther than"),
            (
                vec![nan, close, close, far],
                "of its 4 points, 1 is not finite (NaN: no return); 2 lie within 0.05 m of the \
                 sensor's origin (the S-DEM's minimum range), where a return is the scanner \
                 itself; 1 lies farther than",
            ),
            (vec![Vec3::new(1.0, 0.0, 1.0)], ""),
        ];
        for (points, wanted) in &cases[..6] {
            let why = refused(points, &level, &grid);
            assert!(why.contains(wanted), "{why:?} lacks {wanted:?}");
        }
        // A point above the grid's band of elevations, levelled or tilted by the reading.
        let band = SdemConfig {
            elevation_min_deg: -10.0,
            elevation_max_deg: 10.0,
            ..SdemConfig::default()
        };
        let above = &cases[6].0;
        let why = refused(above, &level, &band);
        assert_eq!(
            why,
            "its one point lies outside the S-DEM grid (elevation -10..10°, azimuth -180..180°)"
        );
        let pitched = Attitude::from_degrees(0.0, 30.0, 0.0);
        let why = refused(&[Vec3::new(1.0, 0.0, 0.0)], &pitched, &band);
        assert!(
            why.ends_with("levelled by the reading's roll 0.0° and pitch 30.0°)"),
            "{why}"
        );
        // One usable point is enough here (the fewest a localization needs is the Scan's).
        let one = Sdem::from_usable_points(&[Vec3::new(1.0, 0.0, 0.0)], &level, &grid).unwrap();
        assert_eq!(one.known_cells(), 1);
    }
}
