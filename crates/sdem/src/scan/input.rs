//! A scan as it comes from the sensor: its checked points, its attitude and its S-DEM.

use crate::error::{Error, Result};
use crate::geometry::{AsPoint, Attitude, Vec3};
use crate::sdem::{no_usable_points, Sdem, SdemConfig};

/// The fewest S-DEM cells a scan must fill to be localized: the search compares at least this
/// many points (the minimum overlap of [`crate::cost::CostConfig`]).
pub const MIN_KNOWN_CELLS: usize = 100;

/// A scan as the sensor gave it: points in the sensor frame, metres, and the gyro/compass
/// attitude read when it was taken, if the robot has one.
///
/// The attitude belongs to the scan: the S-DEM is levelled by it, and a localization reads it
/// from here, so it is given once and cannot disagree with itself. With no attitude
/// (`None`) the scan's tilt (up to [`crate::global::MAX_UNKNOWN_TILT`], 30°) and heading are
/// unknown, and a localization searches them ([`crate::global`]).
///
/// # Example
/// ```
/// use nalgebra::Point3;
/// use sdem::{Attitude, Scan};
/// let points: Vec<Point3<f64>> = (0..2000)
///     .map(|i| {
///         let (a, e) = (i as f64 * 0.0314, (i % 40) as f64 * 0.03 - 0.6);
///         Point3::new(3.0 * a.cos() * e.cos(), 3.0 * a.sin() * e.cos(), 3.0 * e.sin())
///     })
///     .collect();
/// let scan = Scan::from_points(&points, Some(Attitude::from_degrees(1.0, -2.0, 90.0)))?;
/// assert_eq!(scan.attitude().unwrap().to_degrees()[2].round(), 90.0);
/// assert!(Scan::from_points(&points[..10], None).is_err()); // too few points to localize
/// # Ok::<(), sdem::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Scan {
    pub(crate) points_in_sensor: Vec<Vec3>,
    pub(crate) attitude: Option<Attitude>,
    pub(crate) sdem: Sdem,
}

impl Scan {
    /// A scan on the default S-DEM grid (1° × 1°, [`SdemConfig::default`]).
    ///
    /// # Arguments
    /// * `points_in_sensor` — the returns, sensor frame, metres, as nalgebra points or vectors
    ///   or arrays, `f64` or `f32` ([`AsPoint`]). Points with a NaN coordinate are "no return",
    ///   as sensors write them, and are skipped.
    /// * `attitude` — the gyro/compass reading at the scan, or `None` when there is none.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for an infinite coordinate or a non-finite attitude (naming
    /// which), [`Error::NoUsablePoints`] when no cell of the S-DEM holds a return (saying why:
    /// no point, every point at the sensor's origin, …), [`Error::TooFewPoints`] when fewer
    /// than [`MIN_KNOWN_CELLS`] do.
    pub fn from_points<P: AsPoint>(
        points_in_sensor: &[P],
        attitude: Option<Attitude>,
    ) -> Result<Self> {
        Self::with_grid(points_in_sensor, attitude, &SdemConfig::default())
    }

    /// A scan on the given S-DEM grid; see [`Self::from_points`].
    ///
    /// # Errors
    /// As [`Self::from_points`], and [`Error::Invalid`] for an invalid grid.
    pub fn with_grid<P: AsPoint>(
        points_in_sensor: &[P],
        attitude: Option<Attitude>,
        grid: &SdemConfig,
    ) -> Result<Self> {
        let points = checked_input(points_in_sensor, attitude.as_ref())?;
        let reading = attitude.unwrap_or_default();
        let sdem = Sdem::from_points(&points, &reading, grid)?;
        if sdem.known_cells() == 0 {
            // Said over every point given, the NaN ones ("no return") among them.
            let given = P::as_vec3s(points_in_sensor);
            return Err(no_usable_points(&given, &reading, grid));
        }
        if sdem.known_cells() < MIN_KNOWN_CELLS {
            return Err(Error::TooFewPoints {
                usable: sdem.known_cells(),
                needed: MIN_KNOWN_CELLS,
            });
        }
        Ok(Self {
            points_in_sensor: points,
            attitude,
            sdem,
        })
    }

    /// The attitude read at the scan, or `None` when it is unknown.
    pub fn attitude(&self) -> Option<&Attitude> {
        self.attitude.as_ref()
    }

    /// The finite points, sensor frame, metres.
    pub fn points_in_sensor(&self) -> &[Vec3] {
        &self.points_in_sensor
    }

    /// The S-DEM, levelled by the attitude (as level when it is unknown).
    pub fn sdem(&self) -> &Sdem {
        &self.sdem
    }
}

/// Checks a scan as it comes (see [`Scan::from_points`]) and returns its finite points: an
/// infinite coordinate or a non-finite attitude (or standard deviation) is [`Error::InvalidInput`]
/// naming which; NaN points are no return and are dropped. [`crate::Slam::add`] checks its
/// input with this too.
pub(crate) fn checked_input<P: AsPoint>(
    points_in_sensor: &[P],
    attitude: Option<&Attitude>,
) -> Result<Vec<Vec3>> {
    if let Some(a) = attitude.filter(|a| !a.is_finite()) {
        return Err(Error::InvalidInput {
            what: "attitude".into(),
            problem: format!("{:?} is not finite", a.to_degrees()),
        });
    }
    // Roll and pitch beyond a full turn are degrees given where radians are meant
    // (`Attitude::new(30.0, …)`); attitude.csv holds them to ±360° too.
    if let Some(a) = attitude.filter(|a| a.roll.abs().max(a.pitch.abs()) > std::f64::consts::TAU) {
        return Err(Error::InvalidInput {
            what: "attitude".into(),
            problem: format!(
                "roll {} rad and pitch {} rad: beyond a full turn; `Attitude::new` takes \
                 radians, `Attitude::from_degrees` degrees",
                a.roll, a.pitch
            ),
        });
    }
    if let Some(a) = attitude.filter(|a| !a.sigma_is_valid()) {
        return Err(Error::InvalidInput {
            what: "attitude's standard deviations".into(),
            problem: format!(
                "{:?} (radians) must be positive numbers",
                [a.sigma.roll_pitch, a.sigma.yaw]
            ),
        });
    }
    if let Some(i) = points_in_sensor
        .iter()
        .position(|p| p.to_vec3().iter().any(|v| v.is_infinite()))
    {
        return Err(Error::InvalidInput {
            what: format!("point {i}"),
            problem: format!(
                "{:?} has an infinite coordinate (NaN means no return; infinity means \
                 nothing)",
                points_in_sensor[i].to_vec3().as_slice()
            ),
        });
    }
    Ok((points_in_sensor.iter())
        .map(AsPoint::to_vec3)
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect())
}
