//! A scan as it comes from the sensor, and the one call that localizes one scan against another.

use crate::error::{Error, Result};
use crate::geometry::{Attitude, Vec3};
use crate::localize::{HeadingWindow, Localization, LocalizeOptions};
use crate::sdem::{Sdem, SdemConfig};
use nalgebra::Point3;

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
    points_in_sensor: Vec<Vec3>,
    attitude: Option<Attitude>,
    sdem: Sdem,
}

impl Scan {
    /// A scan on the default S-DEM grid (1° × 1°, [`SdemConfig::default`]).
    ///
    /// # Arguments
    /// * `points_in_sensor` — the returns, sensor frame, metres. Points with a NaN coordinate
    ///   are "no return", as sensors write them, and are skipped.
    /// * `attitude` — the gyro/compass reading at the scan, or `None` when there is none.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for an infinite coordinate or a non-finite attitude (naming
    /// which), [`Error::TooFewPoints`] when fewer than [`MIN_KNOWN_CELLS`] cells of the S-DEM
    /// hold a return.
    pub fn from_points(
        points_in_sensor: &[Point3<f64>],
        attitude: Option<Attitude>,
    ) -> Result<Self> {
        Self::with_grid(points_in_sensor, attitude, &SdemConfig::default())
    }

    /// A scan on the given S-DEM grid; see [`Self::from_points`].
    ///
    /// # Errors
    /// As [`Self::from_points`], and [`Error::Invalid`] for an invalid grid.
    pub fn with_grid(
        points_in_sensor: &[Point3<f64>],
        attitude: Option<Attitude>,
        grid: &SdemConfig,
    ) -> Result<Self> {
        let points = checked_input(points_in_sensor, attitude.as_ref())?;
        let sdem = Sdem::from_points(&points, &attitude.unwrap_or_default(), grid)?;
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
pub(crate) fn checked_input(
    points_in_sensor: &[Point3<f64>],
    attitude: Option<&Attitude>,
) -> Result<Vec<Vec3>> {
    if let Some(a) = attitude.filter(|a| !a.is_finite()) {
        return Err(Error::InvalidInput {
            what: "attitude".into(),
            problem: format!("{:?} is not finite", a.to_degrees()),
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
        .position(|p| p.iter().any(|v| v.is_infinite()))
    {
        return Err(Error::InvalidInput {
            what: format!("point {i}"),
            problem: format!(
                "{:?} has an infinite coordinate (NaN means no return; infinity means \
                 nothing)",
                points_in_sensor[i]
            ),
        });
    }
    Ok((points_in_sensor.iter())
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .map(|p| p.coords)
        .collect())
}

/// Localizes `query` against `reference`: where the query's sensor stood, in the reference
/// sensor's frame (Nagatani et al. 2003, Sec. III-C, searched exactly and refined in 6-DoF).
///
/// The attitudes come from the scans, with their uncertainty ([`Attitude::sigma`]). When both
/// have one whose roll and pitch agree within [`LEVEL_TOLERANCE`] at three σ, the search covers
/// the options' translation window and, around the compass readings, three standard deviations
/// of the two headings' difference (the options' heading window gives only the step); a match
/// that tilts one scan against the other beyond what the readings allow carries the doubt
/// [`crate::Doubt::AttitudeCorrected`]. Otherwise (a scan without a reading, or readings too
/// uncertain) the rotation is searched too: hypotheses from the scans' surface orientations,
/// each verified by the exact search ([`crate::global::localize_unlevelled`]); a rotation that
/// compares almost as well as the one returned is the doubt [`crate::Doubt::AnotherRotation`].
///
/// # Returns
/// The pose [`Localization::reference_from_query`] with its cost, runner-up, covariance and
/// [`Localization::doubts`]; a result with doubts is the best candidate found, not a pose to
/// trust ([`Localization::trusted`] is false).
///
/// # Errors
/// [`Error::Invalid`] for invalid options or scans on different grids; [`Error::NoOverlap`]
/// or [`Error::NoMatch`] when nothing in the window matches.
///
/// # Example
/// ```
/// use nalgebra::{Point3, Vector3};
/// use sdem::{Attitude, LocalizeOptions, Scan};
/// // A box-shaped room seen from two places 12 cm apart, both levelled by their gyro/compass.
/// let mut room = Vec::new();
/// for i in -40..=40 {
///     for j in -40..=40 {
///         let (u, v) = (i as f64 * 0.05, j as f64 * 0.05);
///         for p in [[2.0, u, v], [-1.5, u, v], [u, 1.7, v], [u, -1.3, v], [u, v, 1.1], [u, v, -0.4]] {
///             room.push(Point3::new(p[0], p[1], p[2]));
///         }
///     }
/// }
/// let moved = Vector3::new(0.12, 0.0, 0.0);
/// let seen_after_moving: Vec<Point3<f64>> = room.iter().map(|p| p - moved).collect();
/// let reference = Scan::from_points(&room, Some(Attitude::default()))?;
/// let query = Scan::from_points(&seen_after_moving, Some(Attitude::default()))?;
/// let found = sdem::localize(&reference, &query, &LocalizeOptions::default())?;
/// assert!((found.reference_from_query.translation.vector - moved).norm() < 0.005);
/// # Ok::<(), sdem::Error>(())
/// ```
pub fn localize(reference: &Scan, query: &Scan, options: &LocalizeOptions) -> Result<Localization> {
    if reference.sdem.config() != query.sdem.config() {
        return Err(Error::Invalid(
            "the reference and the query are on different S-DEM grids; build both scans with \
             the same grid"
                .into(),
        ));
    }
    if let Some(prior) = crate::global::rotation_prior(
        reference.attitude.as_ref(),
        query.attitude.as_ref(),
        LEVEL_TOLERANCE,
    ) {
        return crate::global::localize_unlevelled(reference, query, options, &prior);
    }
    let half_range_deg = match (reference.attitude, query.attitude) {
        // Three standard deviations of the two headings' difference.
        (Some(r), Some(q)) => (3.0 * r.sigma.yaw.hypot(q.sigma.yaw).to_degrees()).min(180.0),
        // Unreachable: without a reading the rotation is searched above.
        _ => 180.0,
    };
    let options = LocalizeOptions {
        heading: HeadingWindow {
            half_range_deg,
            ..options.heading
        },
        ..options.clone()
    };
    crate::localize::localize(&reference.sdem, &query.sdem, &options)
}

/// Eq. (1) between two scans at a given pose: how well `query`, placed at `reference_from_query`,
/// compares with `reference` (the cost every search minimizes, with the search's compared
/// points and overlap rule). The attitudes are not used: the pose says it all.
///
/// Useful to score a pose from elsewhere (odometry, another method, the truth of a simulation)
/// on the same scale as [`Localization::cost`].
///
/// # Returns
/// `None` when the scans share fewer cells at that pose than a candidate must
/// ([`crate::cost::CostConfig::min_overlap`]).
///
/// # Errors
/// [`Error::Invalid`] for an invalid cost configuration or scans on different grids.
pub fn cost_at(
    reference: &Scan,
    query: &Scan,
    reference_from_query: &crate::geometry::Pose,
    cost: &crate::cost::CostConfig,
) -> Result<Option<crate::cost::Correlation>> {
    cost.validate()?;
    let grid = reference.sdem.config();
    if grid != query.sdem.config() {
        return Err(Error::Invalid(
            "the reference and the query are on different S-DEM grids".into(),
        ));
    }
    // The reference's frame is the levelled frame of both: the query turned into it.
    let turned = Attitude::from_rotation(&reference_from_query.rotation.to_rotation_matrix());
    let (reference_sdem, query_sdem) = rayon::join(
        || Sdem::from_points(&reference.points_in_sensor, &Attitude::default(), grid),
        || Sdem::from_points(&query.points_in_sensor, &turned, grid),
    );
    let (reference_sdem, query_sdem) = (reference_sdem?, query_sdem?);
    let mut correlator = crate::cost::Correlator::new(&reference_sdem, &query_sdem, cost)?;
    Ok(correlator.evaluate(&reference_from_query.translation.vector, 0.0))
}

/// Roll and pitch readings whose difference is within this at three standard deviations are
/// taken as they are: the levelled search and the 6-DoF refinement absorb such a tilt. Beyond
/// it, the rotation is searched ([`crate::global`]). Radians (3°: the default readings, 0.5°
/// each, stay levelled).
pub const LEVEL_TOLERANCE: f64 = 3.0 * std::f64::consts::PI / 180.0;
