//! A scan as it comes ([`Scan`]), and localizing one scan against another: the call that picks
//! the levelled search or the search of the rotation ([`crate::global`]), and the cost of any pose.

pub(crate) mod input;

pub(crate) use input::checked_input;
pub use input::{Scan, MIN_KNOWN_CELLS};

use crate::error::{Error, Result};
use crate::geometry::Attitude;
pub use crate::level::LEVEL_TOLERANCE;
use crate::localize::{HeadingWindow, Localization, LocalizeOptions};
use crate::sdem::Sdem;

/// Localizes `query` against `reference`: where the query's sensor stood, in the reference
/// sensor's frame (Nagatani et al. 2003, Sec. III-C, searched exactly and refined in 6-DoF).
///
/// The attitudes come from the scans, with their uncertainty ([`Attitude::sigma`]). When both
/// have one whose roll and pitch agree within [`LEVEL_TOLERANCE`] at three σ, the search covers
/// the options' translation window and, around the compass readings, three standard deviations
/// of the two headings' difference (the options' heading window gives only the step); a match
/// that tilts one scan against the other beyond what the readings allow carries the doubt
/// [`crate::Doubt::AttitudeCorrected`]. Otherwise (a scan without a reading, readings too
/// uncertain, or compass readings that leave every heading open: three σ of a half turn) the
/// rotation is searched too: hypotheses from the scans' surface orientations, each verified by
/// the exact search ([`crate::global::localize_unlevelled`]); a rotation that compares almost
/// as well as the one returned is the doubt [`crate::Doubt::AnotherRotation`]. A full turn
/// searched exactly is [`crate::localize::localize`] on the two S-DEMs with a heading window of
/// 180° (`sdem localize --heading-window 180`).
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
    // Checked as given, though the heading's range is replaced below: a bad option is refused
    // whichever search reads it.
    options.validate()?;
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
    if half_range_deg >= 180.0 {
        // The compass leaves the heading free: the heading hypotheses of the surfaces, each
        // verified by the exact search, as for scans without a reading. On the first 40 pairs
        // of the `unlevelled` suite given a gyro (±1 m), a full turn searched exactly took
        // 0.45 s median and 12.7 s at most, the hypotheses 0.13 s and 2.8 s; both found the
        // same 25 poses, and the hypotheses flag 2 of them more (corridors turned round).
        let tilt = |a: Option<&Attitude>| a.map_or(0.0, |a| a.sigma.roll_pitch);
        let prior = crate::global::RotationPrior {
            max_tilt: 3.0 * tilt(reference.attitude.as_ref()).hypot(tilt(query.attitude.as_ref())),
            heading_half_range: std::f64::consts::PI,
        };
        return crate::global::localize_unlevelled(reference, query, options, &prior);
    }
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
