//! Re-views of real scans: real geometry with exact truth.
//!
//! The simulator's scenes are planes and boxes; real surfaces are not (clutter, thin
//! structures, grazing angles, edges). A real scan has no truth of its own, but it can be seen
//! again: [`SurfaceModel`] turns one scan into surfaces (a disc on each planar patch, a ball
//! on clutter, and the space the scan saw to be empty), and [`view`] sees them from another
//! pose as a scanner there would: one return per beam of the scanner's angular grid (the
//! nearest surface, so nearer surfaces hide farther ones), range noise, dropped returns, the
//! scanner's own field of view. Where a beam would cross space the scan never saw, it gets no
//! return: what a real scanner would have seen there is unknown.
//!
//! [`review_pairs`] draws seeded pairs of such views: a reference from the scan's own origin
//! and a query from a known origin, heading and tilt near it, each with its attitude reading.
//! Both views come from one fixed model, so the pose between them is exact.
//!
//! # Example
//! ```
//! use sdem::geometry::Vec3;
//! use sdem_sim::reviews::{review_pairs, ModelConfig, ReviewConfig, ReviewScanner, SurfaceModel};
//! use sdem_sim::sim;
//! // A "real" scan: the simulated paper room seen by the tilting scanner (2° steps).
//! let mut sensor = sdem::sensor::SensorConfig::default();
//! (sensor.tilt_step_deg, sensor.pan_step_deg) = (2.0, 2.0);
//! let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
//! let sweep = sim::scan(&sim::paper_room(), &sensor, &sdem::geometry::Pose::identity(), 0.0, &mut rng);
//! let model = SurfaceModel::new(&sweep.points_in_sensor(), &ModelConfig::default())?;
//! let config = ReviewConfig::tilting(ReviewScanner::Tilting(sensor));
//! let pairs = review_pairs(&model, &config, 7, 0..1)?;
//! assert!(pairs[0].query_points.len() > 1000);
//! assert_eq!(pairs[0].truth, pairs[0].world_from_query); // the reference stands at the origin
//! # Ok::<(), sdem::Error>(())
//! ```

mod model;
#[cfg(test)]
mod tests;

pub use model::{ModelConfig, SurfaceModel};

use crate::benchmark::symmetric;
use crate::sim::{lidar_beam, wrap_angle, LidarConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sdem::error::{Error, Result};
use sdem::geometry::{pose_from_parts, Attitude, Pose, Vec3};
use sdem::sensor::{beam_direction, SensorConfig};
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// The scanner a re-view is taken with: its beams, ranges and range noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReviewScanner {
    /// A tilting 2D range finder (the paper's): the front half, lines tilted from
    /// `tilt_min_deg` to `tilt_max_deg`, beams from `pan_min_deg` to `pan_max_deg` in each
    /// (the lift is not used: every beam leaves the origin).
    Tilting(SensorConfig),
    /// A spinning multi-beam LiDAR: rings at fixed elevations all around.
    Spinning(LidarConfig),
}

impl ReviewScanner {
    /// The tilting SICK at 1° × 1° (the paper's sensor, 5 mm of range noise), its lines tilted
    /// from `tilt_min_deg` to `tilt_max_deg`, to 30 m.
    pub fn tilting_sick(tilt_min_deg: f64, tilt_max_deg: f64) -> Self {
        Self::Tilting(SensorConfig {
            tilt_min_deg,
            tilt_max_deg,
            max_range_m: 30.0,
            ..SensorConfig::default()
        })
    }

    /// A Velodyne HDL-64E as KITTI's: 64 rings from −24.8° to +2° (evenly spread here; the
    /// sensor's two blocks are 1/3° and 1/2° apart), a return every 0.18° of azimuth, 1.5–80 m,
    /// 2 cm of range noise.
    pub fn hdl64e() -> Self {
        Self::Spinning(LidarConfig {
            rings: 64,
            elevation_min_deg: -24.8,
            elevation_max_deg: 2.0,
            azimuth_step_deg: 0.18,
            azimuth_fov_deg: 360.0,
            max_range_m: 80.0,
            min_range_m: 1.5,
            range_noise_m: 0.02,
        })
    }

    /// A scanner like the one that took `points_in_sensor`: a spinning LiDAR when the scan
    /// covers (almost) every azimuth (its rings spread over the scan's band of elevations at
    /// the scan's step), else the tilting SICK at 1° × 1° over the scan's band of tilts.
    pub fn like(points_in_sensor: &[Vec3]) -> Self {
        let grid = sdem::sdem::SdemConfig::for_scan(points_in_sensor);
        let all_round = azimuth_sectors(points_in_sensor) >= ALL_ROUND_SECTORS;
        let (low, high) = tilt_band(points_in_sensor, all_round);
        if all_round {
            let step = grid.resolution_deg;
            let rings = (((high - low) / step).round() as usize + 1).max(2);
            let far = percentile_range(points_in_sensor, 0.99);
            Self::Spinning(LidarConfig {
                rings,
                elevation_min_deg: low,
                elevation_max_deg: high.max(low + step),
                azimuth_step_deg: (0.5 * step).max(0.1),
                azimuth_fov_deg: 360.0,
                max_range_m: far.max(10.0),
                min_range_m: 1.0,
                range_noise_m: 0.02,
            })
        } else {
            Self::tilting_sick(low.max(-89.0), high.min(89.0).max(low.max(-89.0) + 1.0))
        }
    }

    /// The beams, unit vectors in the sensor frame, line by line (ring by ring).
    pub fn lines(&self) -> Vec<Vec<Vec3>> {
        match self {
            Self::Tilting(s) => {
                let pans: Vec<f64> = (0..s.pan_count())
                    .map(|k| (s.pan_min_deg + k as f64 * s.pan_step_deg).to_radians())
                    .collect();
                (s.tilt_angles_deg().iter())
                    .map(|t| {
                        let tilt = t.to_radians();
                        pans.iter().map(|&p| beam_direction(tilt, p)).collect()
                    })
                    .collect()
            }
            Self::Spinning(l) => {
                let azimuths = l.azimuths_deg();
                (l.ring_elevations_deg().iter())
                    .map(|e| {
                        let e = e.to_radians();
                        (azimuths.iter())
                            .map(|a| lidar_beam(e, a.to_radians()))
                            .collect()
                    })
                    .collect()
            }
        }
    }

    /// Returns are kept within these ranges, metres.
    pub fn ranges_m(&self) -> (f64, f64) {
        match self {
            Self::Tilting(s) => (s.min_range_m, s.usable_range_m()),
            Self::Spinning(l) => (l.min_range_m, l.max_range_m),
        }
    }

    /// The range noise's standard deviation, metres.
    pub fn range_noise_m(&self) -> f64 {
        match self {
            Self::Tilting(s) => s.range_noise_m,
            Self::Spinning(l) => l.range_noise_m,
        }
    }

    /// Checks the scanner's settings.
    ///
    /// # Errors
    /// [`Error::Invalid`] as [`SensorConfig::validate`] and [`LidarConfig::validate`] say.
    pub fn validate(&self) -> Result<()> {
        match self {
            Self::Tilting(s) => s.validate(),
            Self::Spinning(l) => l.validate(),
        }
    }

    /// The scanner in words.
    pub fn describe(&self) -> String {
        match self {
            Self::Tilting(s) => format!(
                "a tilting 2D scanner: the front half, {}° × {}° steps, tilts {}°..{}°, \
                 {}–{} m, {} mm range noise",
                s.tilt_step_deg,
                s.pan_step_deg,
                s.tilt_min_deg,
                s.tilt_max_deg,
                s.min_range_m,
                s.usable_range_m(),
                s.range_noise_m * 1e3
            ),
            Self::Spinning(l) => format!(
                "a spinning LiDAR: {} rings {}°..{}°, {}° azimuth steps, {}–{} m, {} mm range \
                 noise",
                l.rings,
                l.elevation_min_deg,
                l.elevation_max_deg,
                l.azimuth_step_deg,
                l.min_range_m,
                l.max_range_m,
                l.range_noise_m * 1e3
            ),
        }
    }
}

/// A scan that holds returns in at least this many of the 36 sectors of 10° of azimuth sees all
/// round (a front-half scanner fills 18–20).
const ALL_ROUND_SECTORS: usize = 30;

/// The number of the 36 sectors of 10° of azimuth that hold at least 0.1 % of the returns.
fn azimuth_sectors(points: &[Vec3]) -> usize {
    let mut counts = [0usize; 36];
    let mut total = 0;
    for p in points.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
        let azimuth = p.y.atan2(p.x).to_degrees() + 180.0;
        counts[((azimuth / 10.0) as usize).min(35)] += 1;
        total += 1;
    }
    counts.iter().filter(|&&c| c * 1000 >= total.max(1)).count()
}

/// The band of tilts (a tilting scanner's, about its y axis, over the front half) or
/// elevations (all round) that 99 % of the scan's returns lie in, degrees, rounded outwards.
fn tilt_band(points: &[Vec3], all_round: bool) -> (f64, f64) {
    let mut angles: Vec<f64> = points
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()) && p.norm() > 0.0)
        .filter(|p| all_round || p.x > 0.0)
        .map(|p| {
            if all_round {
                (p.z / p.norm()).asin().to_degrees()
            } else {
                p.z.atan2(p.x).to_degrees()
            }
        })
        .collect();
    if angles.len() < 2 {
        return (-45.0, 40.0);
    }
    angles.sort_by(f64::total_cmp);
    let at = |q: f64| angles[((angles.len() - 1) as f64 * q) as usize];
    (at(0.005).floor(), at(0.995).ceil())
}

/// The `q`-quantile of the returns' ranges, metres.
fn percentile_range(points: &[Vec3], q: f64) -> f64 {
    let mut ranges: Vec<f64> = (points.iter())
        .map(|p| p.norm())
        .filter(|r| r.is_finite())
        .collect();
    if ranges.is_empty() {
        return 0.0;
    }
    ranges.sort_by(f64::total_cmp);
    ranges[((ranges.len() - 1) as f64 * q) as usize]
}

/// One view of `model` from `world_from_view` by `scanner`: the returns, points in the view's
/// sensor frame, metres, line by line.
///
/// Each beam returns the range to the surface it meets first ([`SurfaceModel::ranges`]) plus
/// N(0, range noise), and is dropped (no return) with probability `drop_fraction`, or when
/// the noisy range lies outside the scanner's limits. Draws a normal and a uniform number per
/// beam from `rng`, hit or not, so the draws do not depend on the geometry.
pub fn view(
    model: &SurfaceModel,
    scanner: &ReviewScanner,
    world_from_view: &Pose,
    drop_fraction: f64,
    rng: &mut impl Rng,
) -> Vec<Vec3> {
    let rays: Vec<Vec3> = scanner.lines().concat();
    let ranges = model.ranges(world_from_view, &rays);
    let noise = scanner.range_noise_m();
    let (near, far) = scanner.ranges_m();
    rays.iter()
        .zip(ranges)
        .filter_map(|(ray, range)| {
            let e: f64 = rng.sample(StandardNormal);
            let dropped = rng.random::<f64>() < drop_fraction;
            let r = range? + noise * e;
            (!dropped && (near..=far).contains(&r)).then_some(ray * r)
        })
        .collect()
}

/// How [`review_pairs`] draws its pairs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReviewConfig {
    /// The scanner both views are taken with.
    pub scanner: ReviewScanner,
    /// Half-size of the window the query's origin is drawn in around the scan's origin, `[x,
    /// y, z]`, metres (uniform).
    pub displacement_half_m: [f64; 3],
    /// The query's heading differs from the reference's by up to this, degrees (uniform).
    pub yaw_spread_deg: f64,
    /// The query's roll and pitch are each within ± this, degrees (uniform).
    pub tilt_max_deg: f64,
    /// The query's compass reading is off by up to ± this, degrees (uniform), besides its noise.
    pub compass_error_max_deg: f64,
    /// Roll and pitch readings' noise, degrees (standard deviation).
    pub tilt_sensor_noise_deg: f64,
    /// Heading readings' noise, degrees (standard deviation).
    pub compass_noise_deg: f64,
    /// The share of returns dropped at random.
    pub drop_fraction: f64,
    /// The query's origin must lie at least this far from every surface, metres, and in space
    /// the scan saw to be empty.
    pub min_clearance_m: f64,
    /// The reference's roll and pitch are each within ± this, degrees (uniform; 0: the scan's
    /// own axes, as it was taken).
    #[serde(default)]
    pub reference_tilt_max_deg: f64,
    /// The reference's heading is within ± this of the scan's, degrees (uniform).
    #[serde(default)]
    pub reference_yaw_spread_deg: f64,
    /// At least this share of the query's returns must lie beside one of the reference's: in
    /// or next to a 10 cm cube that holds one (0: not checked).
    #[serde(default)]
    pub min_overlap: f64,
}

impl ReviewConfig {
    /// For a tilting scanner indoors: the query within ±0.5 m (±0.1 m in height), turned up to
    /// 15°, tilted up to 3°, its compass off by up to 10°; 20 % of returns dropped; 0.3 m of
    /// clearance (as `sdem bench`'s simulated pairs).
    pub fn tilting(scanner: ReviewScanner) -> Self {
        Self {
            scanner,
            displacement_half_m: [0.5, 0.5, 0.1],
            yaw_spread_deg: 15.0,
            tilt_max_deg: 3.0,
            compass_error_max_deg: 10.0,
            tilt_sensor_noise_deg: 0.05,
            compass_noise_deg: 0.1,
            drop_fraction: 0.2,
            min_clearance_m: 0.3,
            reference_tilt_max_deg: 0.0,
            reference_yaw_spread_deg: 0.0,
            min_overlap: 0.0,
        }
    }

    /// For a spinning LiDAR on a vehicle: the query within ±1 m (±0.1 m in height), turned up
    /// to 10°, tilted up to 1°, its compass off by up to 10°; 20 % of returns dropped; 1 m of
    /// clearance.
    pub fn spinning(scanner: ReviewScanner) -> Self {
        Self {
            displacement_half_m: [1.0, 1.0, 0.1],
            yaw_spread_deg: 10.0,
            tilt_max_deg: 1.0,
            min_clearance_m: 1.0,
            ..Self::tilting(scanner)
        }
    }

    /// For scans without attitude readings ([`Self::for_scanner`]'s otherwise): both views
    /// rolled and pitched each up to ±30°, at any heading, the query's origin within ±0.7 m
    /// (±0.1 m in height, so within 1 m across) of the reference's, half the query's returns
    /// or more beside the reference's ([`Self::min_overlap`]). The readings drawn are for
    /// callers that want them (the example `real_unlevelled` gives sdem none).
    pub fn unlevelled(scanner: ReviewScanner) -> Self {
        Self {
            displacement_half_m: [0.7, 0.7, 0.1],
            yaw_spread_deg: 180.0,
            tilt_max_deg: 30.0,
            reference_tilt_max_deg: 30.0,
            reference_yaw_spread_deg: 180.0,
            min_overlap: 0.5,
            ..Self::for_scanner(scanner)
        }
    }

    /// [`Self::tilting`] or [`Self::spinning`], as `scanner` is.
    pub fn for_scanner(scanner: ReviewScanner) -> Self {
        match scanner {
            ReviewScanner::Tilting(_) => Self::tilting(scanner),
            ReviewScanner::Spinning(_) => Self::spinning(scanner),
        }
    }

    /// Checks every field; the message names the field.
    ///
    /// # Errors
    /// [`Error::Invalid`] for a negative or non-finite spread, window, noise or clearance, a
    /// drop fraction outside [0, 1), or an invalid scanner.
    pub fn validate(&self) -> Result<()> {
        let fields = [
            ("displacement_half_m[0]", self.displacement_half_m[0]),
            ("displacement_half_m[1]", self.displacement_half_m[1]),
            ("displacement_half_m[2]", self.displacement_half_m[2]),
            ("yaw_spread_deg", self.yaw_spread_deg),
            ("tilt_max_deg", self.tilt_max_deg),
            ("compass_error_max_deg", self.compass_error_max_deg),
            ("tilt_sensor_noise_deg", self.tilt_sensor_noise_deg),
            ("compass_noise_deg", self.compass_noise_deg),
            ("min_clearance_m", self.min_clearance_m),
            ("reference_tilt_max_deg", self.reference_tilt_max_deg),
            ("reference_yaw_spread_deg", self.reference_yaw_spread_deg),
            ("min_overlap", self.min_overlap),
        ];
        crate::benchmark::check_non_negative("re-views", &fields)?;
        if !(0.0..1.0).contains(&self.drop_fraction) {
            return Err(Error::Invalid(format!(
                "re-views: drop_fraction is {}; it must lie in [0, 1)",
                self.drop_fraction
            )));
        }
        self.scanner.validate()
    }
}

/// A pair of views of one real scan, with the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct Review {
    /// Which pair of the seed's stream.
    pub index: usize,
    /// The reference view, from the scan's own origin (and axes, unless the config turns it):
    /// points in its sensor frame.
    pub reference_points: Vec<Vec3>,
    /// The reference's attitude reading: the truth (level and heading 0 in the scan's frame,
    /// unless turned) plus noise.
    pub reference_attitude: Attitude,
    /// The query view: points in its sensor frame.
    pub query_points: Vec<Vec3>,
    /// The query's attitude reading: the truth plus noise and a compass error.
    pub query_attitude: Attitude,
    /// True `reference_from_query`.
    pub truth: Pose,
    /// The query sensor's pose in the scan's frame.
    pub world_from_query: Pose,
    /// The reference sensor's pose in the scan's frame (the identity unless the config turns
    /// it).
    pub world_from_reference: Pose,
}

/// sdem on a re-view through its root API ([`sdem::localize()`]), the query against the
/// reference over `window` at `step_m`, each view with its reading (`with_readings`) or none.
/// A spinning scanner's views go on the grid and scale derived from the reference
/// ([`sdem::SdemConfig::for_scan`], [`sdem::LocalizeOptions::for_scan`], the window and step
/// kept), a tilting scanner's on the default grid and options.
///
/// # Errors
/// As [`sdem::localize()`].
pub fn localize_review(
    review: &Review,
    scanner: &ReviewScanner,
    with_readings: bool,
    window: sdem::SearchWindow,
    step_m: f64,
) -> Result<sdem::Localization> {
    let spinning = matches!(scanner, ReviewScanner::Spinning(_));
    let grid = if spinning {
        sdem::SdemConfig::for_scan(&review.reference_points)
    } else {
        sdem::SdemConfig::default()
    };
    let reading = |a: &Attitude| with_readings.then_some(*a);
    let (reference, query) = rayon::join(
        || {
            let attitude = reading(&review.reference_attitude);
            sdem::Scan::with_grid(&review.reference_points, attitude, &grid)
        },
        || sdem::Scan::with_grid(&review.query_points, reading(&review.query_attitude), &grid),
    );
    let (reference, query) = (reference?, query?);
    let defaults = if spinning {
        sdem::LocalizeOptions::for_scan(reference.sdem())
    } else {
        sdem::LocalizeOptions::default()
    };
    let options = sdem::LocalizeOptions {
        window,
        step_m,
        ..defaults
    };
    sdem::localize(&reference, &query, &options)
}

/// Query poses drawn per pair before giving up on one with enough clearance.
const MAX_QUERY_DRAWS: usize = 1000;

/// Mixed into the seed of the pairs' random streams.
const REVIEW_STREAM_SALT: u64 = 0x7e71_e3a5_5eed_0027;

/// The pairs `indices` of the seeded stream of re-views of `model`.
///
/// Pair `i` comes from its own `ChaCha8Rng` stream `i` of `seed`: the reference's reading and
/// view, then a query pose drawn within the config's window, spreads and tilt (redrawn until
/// its origin lies in space the scan saw empty with the clearance asked), its reading and view
/// (all redrawn while the view holds less than half the reference's returns). The result
/// depends on the seed and index only, not on the range asked for or the thread count.
///
/// # Errors
/// [`Error::Invalid`] for an invalid `config`, or when no query origin with the clearance asked
/// turns up after many draws.
pub fn review_pairs(
    model: &SurfaceModel,
    config: &ReviewConfig,
    seed: u64,
    indices: Range<usize>,
) -> Result<Vec<Review>> {
    config.validate()?;
    indices
        .map(|index| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ REVIEW_STREAM_SALT);
            rng.set_stream(index as u64);
            draw_review(model, config, index, &mut rng)
        })
        .collect()
}

/// One pair from its own random stream (see [`review_pairs`]).
fn draw_review(
    model: &SurfaceModel,
    config: &ReviewConfig,
    index: usize,
    rng: &mut ChaCha8Rng,
) -> Result<Review> {
    let drop = config.drop_fraction;
    let turned = config.reference_tilt_max_deg > 0.0 || config.reference_yaw_spread_deg > 0.0;
    let reference_view = |world_from_reference: &Pose, rng: &mut ChaCha8Rng| {
        let truth = sdem::geometry::attitude_of(world_from_reference);
        let attitude = reading(config, truth, rng);
        let mut rng = ChaCha8Rng::seed_from_u64(rng.random());
        let points = view(model, &config.scanner, world_from_reference, drop, &mut rng);
        (attitude, points)
    };
    // The reference from the scan's own origin and axes. A turned one is drawn in the loop
    // below instead; the draws of this one are taken all the same (its view is not cast), so
    // that the pairs of every config stay the ones their seeds gave.
    let (mut world_from_reference, mut reference_attitude, mut reference_points) = {
        let attitude = reading(config, Attitude::default(), rng);
        let seed: u64 = rng.random();
        let points = if turned {
            Vec::new()
        } else {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            view(model, &config.scanner, &Pose::identity(), drop, &mut rng)
        };
        (Pose::identity(), attitude, points)
    };
    let tries = if turned {
        MAX_TURNED_VIEWS
    } else {
        MAX_QUERY_VIEWS
    };
    for _ in 0..tries {
        if turned {
            world_from_reference = pose_from_parts(
                Vec3::zeros(),
                Attitude::new(
                    symmetric(rng, config.reference_tilt_max_deg).to_radians(),
                    symmetric(rng, config.reference_tilt_max_deg).to_radians(),
                    symmetric(rng, config.reference_yaw_spread_deg).to_radians(),
                ),
            );
            (reference_attitude, reference_points) = reference_view(&world_from_reference, rng);
        }
        let world_from_query = draw_query_pose(model, config, rng).ok_or_else(|| {
            Error::Invalid(format!(
                "re-view {index}: no query origin within {:?} m of the scan's origin lies {} m \
                 from every surface in space the scan saw empty, after {MAX_QUERY_DRAWS} draws",
                config.displacement_half_m, config.min_clearance_m
            ))
        })?;
        let compass_error = symmetric(rng, config.compass_error_max_deg).to_radians();
        let truth_attitude = sdem::geometry::attitude_of(&world_from_query);
        let mut query_attitude = reading(config, truth_attitude, rng);
        query_attitude.yaw = wrap_angle(query_attitude.yaw + compass_error);
        let mut view_rng = ChaCha8Rng::seed_from_u64(rng.random());
        let query_points = view(
            model,
            &config.scanner,
            &world_from_query,
            drop,
            &mut view_rng,
        );
        let (q, r) = (query_points.len() as f64, reference_points.len() as f64);
        if q < MIN_QUERY_SHARE * r
            || (turned && r < MIN_QUERY_SHARE * q)
            || (config.min_overlap > 0.0
                && overlap(
                    &reference_points,
                    &world_from_reference,
                    &query_points,
                    &world_from_query,
                ) < config.min_overlap)
        {
            continue;
        }
        return Ok(Review {
            index,
            reference_points,
            reference_attitude,
            query_points,
            query_attitude,
            truth: world_from_reference.inverse() * world_from_query,
            world_from_query,
            world_from_reference,
        });
    }
    Err(Error::Invalid(format!(
        "re-view {index}: {tries} pairs of views in a row saw less than {:.0} % as many returns \
         as each other, or overlapped less than {:.0} % (the scan saw too little around them)",
        MIN_QUERY_SHARE * 100.0,
        config.min_overlap * 100.0
    )))
}

/// Views drawn per pair, when the reference is turned too, before giving up.
const MAX_TURNED_VIEWS: usize = 200;

/// The cubes [`overlap`] bins returns into, metres.
const OVERLAP_M: f64 = 0.1;

/// The share of `query`'s returns (in its sensor's frame, at `world_from_query`) beside one of
/// `reference`'s (at `world_from_reference`): in or next to a cube of [`OVERLAP_M`] that holds
/// one (up to about 35 cm away).
fn overlap(
    reference: &[Vec3],
    world_from_reference: &Pose,
    query: &[Vec3],
    world_from_query: &Pose,
) -> f64 {
    let cube = |p: Vec3| (p / OVERLAP_M).map(|c| c.floor() as i64);
    let seen: std::collections::HashSet<_> = (reference.iter())
        .map(|p| cube(world_from_reference.transform_point(&(*p).into()).coords))
        .collect();
    let near = |c: nalgebra::Vector3<i64>| {
        (-1..=1).any(|x| {
            (-1..=1)
                .any(|y| (-1..=1).any(|z| seen.contains(&(c + nalgebra::Vector3::new(x, y, z)))))
        })
    };
    let shared = (query.iter())
        .filter(|p| near(cube(world_from_query.transform_point(&(**p).into()).coords)))
        .count();
    shared as f64 / query.len().max(1) as f64
}

/// A query view must hold at least this share of the reference view's returns: the scan
/// cannot say what lies beyond what it saw, so a query that looks there (a front-half
/// scanner stepped back, turned to where the scan did not look) gets few returns, fewer than a
/// real scanner would.
const MIN_QUERY_SHARE: f64 = 0.5;

/// Query poses viewed per pair before giving up on one that sees enough.
const MAX_QUERY_VIEWS: usize = 20;

/// An attitude reading of `truth`: roll and pitch with the config's tilt noise, the heading
/// with its compass noise.
fn reading(config: &ReviewConfig, truth: Attitude, rng: &mut ChaCha8Rng) -> Attitude {
    let tilt = config.tilt_sensor_noise_deg.to_radians();
    let compass = config.compass_noise_deg.to_radians();
    let (a, b, c): (f64, f64, f64) = (
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
    );
    Attitude::new(
        truth.roll + tilt * a,
        truth.pitch + tilt * b,
        wrap_angle(truth.yaw + compass * c),
    )
}

/// A query pose in the config's window whose origin has the clearance asked and lies in space
/// the scan saw empty, or `None` after [`MAX_QUERY_DRAWS`] draws.
fn draw_query_pose(
    model: &SurfaceModel,
    config: &ReviewConfig,
    rng: &mut ChaCha8Rng,
) -> Option<Pose> {
    let half = config.displacement_half_m;
    for _ in 0..MAX_QUERY_DRAWS {
        let origin = Vec3::new(
            symmetric(rng, half[0]),
            symmetric(rng, half[1]),
            symmetric(rng, half[2]),
        );
        let attitude = Attitude::new(
            symmetric(rng, config.tilt_max_deg).to_radians(),
            symmetric(rng, config.tilt_max_deg).to_radians(),
            symmetric(rng, config.yaw_spread_deg).to_radians(),
        );
        let clear = model.clearance(&origin) >= config.min_clearance_m
            && model.seen_empty(&origin, config.min_clearance_m);
        if clear {
            return Some(pose_from_parts(origin, attitude));
        }
    }
    None
}
