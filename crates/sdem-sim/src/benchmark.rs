//! Seeded scan pairs for benchmarks: where the robot stood, where it stands now, what it read.
//!
//! [`bench_pairs`] draws pairs of scans in [`sim::collapsed_building`]: a reference at one of the
//! route's stops ([`sim::collapsed_building_stops`]) and a query somewhere within a window around
//! it, each with its gyro/compass reading, the query's compass possibly disturbed (steel in the
//! rubble). The truth comes with every pair, so `sdem bench`, the tests and the peers' scripts
//! score themselves against the same answers. [`summarize`] and [`success_rate`] turn errors into
//! figures; [`localize_pair`] runs sdem on one pair.
//!
//! Pure: scenes and scans are simulated in memory; writing them out is the caller's job (see
//! `sdem-cli/examples/export_bench_pairs.rs`).
//!
//! # Example
//! ```
//! use sdem_sim::benchmark::{bench_pairs, PairConfig};
//! let mut config = PairConfig::default();
//! // A coarse sweep keeps the example quick.
//! config.sensor.tilt_step_deg = 3.0;
//! config.sensor.pan_step_deg = 3.0;
//! let pairs = bench_pairs(7, 2, &config)?;
//! assert_eq!(pairs.len(), 2);
//! // The truth is the query sensor's pose in the reference sensor's frame.
//! let origin = pairs[0].world_from_reference.inverse() * pairs[0].world_from_query;
//! assert!((origin.translation.vector - pairs[0].truth.translation.vector).norm() < 1e-12);
//! # Ok::<(), sdem::Error>(())
//! ```

use crate::sim::{self, wrap_angle};
use nalgebra::{Matrix6, Translation3, Unit, UnitQuaternion, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use sdem::error::{Error, Result};
use sdem::geometry::{attitude_of, pose_error, pose_from_parts, Attitude, Pose, Vec3};
use sdem::localize::{localize, Localization, LocalizeOptions, SearchWindow};
use sdem::sdem::{Sdem, SdemConfig};
use sdem::sensor::SensorConfig;
use std::time::Instant;

/// Mixed into the seed of the pairs' random streams, so they do not repeat the scene's.
const PAIR_STREAM_SALT: u64 = 0xbe7c_4a1a_5eed_0001;
/// Query poses drawn per pair before giving up on finding one with enough clearance.
const MAX_QUERY_DRAWS: usize = 10_000;
/// Sample directions of the clearance check (as [`sim::collapsed_building_stops`] uses).
const CLEARANCE_DIRECTIONS: usize = 200;

/// Where the query of [`paper_pair`] stands: the paper's move of (22, 36, 5) cm.
pub const PAPER_MOVE_M: [f64; 3] = [0.22, 0.36, 0.05];

/// The paper's pair (Sec. V), as S-DEMs (each keeps its attitude reading): a scan at the origin of
/// [`sim::paper_room`] and one after moving [`PAPER_MOVE_M`] with the same attitude, default
/// sensor and grid, seed 1. The problem `sdem bench` and the criterion benchmark time.
///
/// # Errors
/// None in practice (the default grid is valid); [`Sdem::from_points`]'s errors are passed on.
pub fn paper_pair() -> Result<(Sdem, Sdem)> {
    let scene = sim::paper_room();
    let sensor = SensorConfig::default();
    let grid = SdemConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut sdem_at = |pose: &Pose| -> Result<Sdem> {
        let sweep = sim::scan(&scene, &sensor, pose, 0.0, &mut rng);
        Sdem::from_points(&sweep.points_in_sensor(), &sweep.mean_attitude(), &grid)
    };
    let reference = sdem_at(&Pose::identity())?;
    let query = sdem_at(&pose_from_parts(
        Vec3::from(PAPER_MOVE_M),
        Attitude::default(),
    ))?;
    Ok((reference, query))
}

/// How [`bench_pairs`] draws its pairs.
#[derive(Debug, Clone, PartialEq)]
pub struct PairConfig {
    /// Half-size of the window the query's origin is drawn in, around the reference's origin,
    /// world axes `[x, y, z]`, metres (uniform).
    pub displacement_half_m: [f64; 3],
    /// The query's true heading differs from the reference's by up to this, degrees (uniform).
    pub yaw_spread_deg: f64,
    /// The query's true roll and pitch are drawn uniformly within ± this, degrees.
    pub tilt_max_deg: f64,
    /// A compass error drawn uniformly within ± this is added to the query's yaw reading, degrees;
    /// 0 leaves the reading as the sensor gave it (its own noise only).
    pub compass_error_max_deg: f64,
    /// The query's origin must be at least this far from every surface, metres.
    pub min_clearance_m: f64,
    /// The simulated sensor (range noise, angular steps, gyro and compass noise, lift).
    pub sensor: SensorConfig,
}

impl Default for PairConfig {
    /// ±0.5 m in x and y, ±0.1 m in z, ±15° of heading, ±3° of roll and pitch, a compass off by
    /// up to ±10°, 0.15 m of clearance and the default sensor (5 mm range noise).
    fn default() -> Self {
        Self {
            displacement_half_m: [0.5, 0.5, 0.1],
            yaw_spread_deg: 15.0,
            tilt_max_deg: 3.0,
            compass_error_max_deg: 10.0,
            min_clearance_m: sim::MIN_SENSOR_CLEARANCE_M,
            sensor: SensorConfig::default(),
        }
    }
}

impl PairConfig {
    /// Checks every field; the message names the field.
    ///
    /// # Errors
    /// [`Error::Invalid`] for a negative or non-finite spread, window or clearance, or an invalid
    /// sensor.
    pub fn validate(&self) -> Result<()> {
        let fields = [
            ("displacement_half_m[0]", self.displacement_half_m[0]),
            ("displacement_half_m[1]", self.displacement_half_m[1]),
            ("displacement_half_m[2]", self.displacement_half_m[2]),
            ("yaw_spread_deg", self.yaw_spread_deg),
            ("tilt_max_deg", self.tilt_max_deg),
            ("compass_error_max_deg", self.compass_error_max_deg),
            ("min_clearance_m", self.min_clearance_m),
        ];
        check_non_negative("bench pairs", &fields)?;
        if self.yaw_spread_deg >= 180.0 || self.compass_error_max_deg >= 180.0 {
            return Err(Error::Invalid(
                "bench pairs: yaw_spread_deg and compass_error_max_deg must be below 180".into(),
            ));
        }
        if self.tilt_max_deg >= 90.0 {
            return Err(Error::Invalid(
                "bench pairs: tilt_max_deg must be below 90".into(),
            ));
        }
        self.sensor.validate()
    }

    /// The search window that holds every query of these pairs: the displacement window around
    /// a zero offset.
    pub fn search_window(&self) -> SearchWindow {
        SearchWindow::around(&Vec3::zeros(), self.displacement_half_m)
    }
}

/// Two scans with their readings and the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchPair {
    /// The reference scan, points in its sensor frame, metres.
    pub reference_points: Vec<Vec3>,
    /// The gyro/compass reading at the reference (its own sensor noise only).
    pub reference_attitude: Attitude,
    /// The query scan, points in its sensor frame, metres.
    pub query_points: Vec<Vec3>,
    /// The gyro/compass reading at the query, with [`Self::compass_error_deg`] added to its yaw.
    pub query_attitude: Attitude,
    /// True `reference_from_query`: the query sensor's pose in the reference sensor's frame
    /// (maps query points into the reference frame; for tools that name transforms
    /// `T_target_source` the query is the source and the reference the target).
    pub truth: Pose,
    /// The compass error added to the query's yaw reading, degrees.
    pub compass_error_deg: f64,
    /// True `world_from_sensor` of the reference.
    pub world_from_reference: Pose,
    /// True `world_from_sensor` of the query.
    pub world_from_query: Pose,
    /// Which stop of [`sim::collapsed_building_stops`] (with [`sim::MAX_STOPS`] stops) the
    /// reference stands at.
    pub reference_stop: usize,
}

impl BenchPair {
    /// The true offset that [`localize`] estimates: query origin minus reference origin, world
    /// axes, metres.
    pub fn true_offset(&self) -> Vec3 {
        self.world_from_query.translation.vector - self.world_from_reference.translation.vector
    }
}

/// Draws `count` seeded scan pairs in [`sim::collapsed_building`]`(seed)`.
///
/// # Arguments
/// * `seed` — seeds the scene, its route and every pair.
/// * `count` — the number of pairs.
/// * `config` — the windows, spreads and the sensor.
///
/// # Returns
/// For pair `i`, from its own `ChaCha8Rng` stream `i`: a reference stop drawn uniformly among the
/// route's [`sim::MAX_STOPS`] stops; a query sensor pose whose origin is the reference's plus a
/// uniform displacement within `config.displacement_half_m` (world axes), whose heading is the
/// reference's plus a uniform turn within `±yaw_spread_deg` and whose roll and pitch are uniform
/// within `±tilt_max_deg`, redrawn until its origin is free and at least `min_clearance_m` from
/// every surface; both scans simulated by [`sim::scan`]; and a compass error uniform within
/// `±compass_error_max_deg` added to the query's yaw reading. The draws per pair do not depend
/// on `compass_error_max_deg`, so the same seed gives the same scans with or without it. The
/// result depends on the seed only, not on the thread count.
///
/// # Errors
/// [`Error::Invalid`] for an invalid `config`, a lift that does not fit the scene's route, or
/// when no query pose with enough clearance turns up after many draws.
pub fn bench_pairs(seed: u64, count: usize, config: &PairConfig) -> Result<Vec<BenchPair>> {
    config.validate()?;
    let scene = sim::collapsed_building(seed);
    let stops = sim::collapsed_building_stops(&scene, seed, sim::MAX_STOPS, &config.sensor.lift)?;
    (0..count)
        .into_par_iter()
        .map(|index| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ PAIR_STREAM_SALT);
            rng.set_stream(index as u64);
            draw_pair(&scene, &stops, config, index, &mut rng)
        })
        .collect()
}

/// One pair from its own random stream (see [`bench_pairs`] for the recipe).
fn draw_pair(
    scene: &sim::Scene,
    stops: &[sim::Stop],
    config: &PairConfig,
    index: usize,
    rng: &mut ChaCha8Rng,
) -> Result<BenchPair> {
    let reference_stop = rng.random_range(0..stops.len());
    let stop = &stops[reference_stop];
    let world_from_reference = stop.world_from_sensor(&config.sensor.lift)?;
    let compass_error_deg = symmetric(rng, config.compass_error_max_deg);
    let world_from_query =
        draw_query_pose(scene, &world_from_reference, config, rng).ok_or_else(|| {
            Error::Invalid(format!(
                "bench pair {index}: no query origin within {:?} m of stop {reference_stop} has \
                 {} m of clearance after {MAX_QUERY_DRAWS} draws",
                config.displacement_half_m, config.min_clearance_m
            ))
        })?;
    let reference = sim::scan(
        scene,
        &config.sensor,
        &world_from_reference,
        stop.lift_slide_m,
        rng,
    );
    let query = sim::scan(
        scene,
        &config.sensor,
        &world_from_query,
        stop.lift_slide_m,
        rng,
    );
    let reading = query.mean_attitude();
    let query_attitude = Attitude::new(
        reading.roll,
        reading.pitch,
        wrap_angle(reading.yaw + compass_error_deg.to_radians()),
    );
    Ok(BenchPair {
        reference_points: reference.points_in_sensor(),
        reference_attitude: reference.mean_attitude(),
        query_points: query.points_in_sensor(),
        query_attitude,
        truth: world_from_reference.inverse() * world_from_query,
        compass_error_deg,
        world_from_reference,
        world_from_query,
        reference_stop,
    })
}

/// A query sensor pose around `world_from_reference` with enough clearance, or `None` after
/// [`MAX_QUERY_DRAWS`] draws.
pub(crate) fn draw_query_pose(
    scene: &sim::Scene,
    world_from_reference: &Pose,
    config: &PairConfig,
    rng: &mut ChaCha8Rng,
) -> Option<Pose> {
    let origin = world_from_reference.translation.vector;
    let heading = attitude_of(world_from_reference).yaw;
    let half = config.displacement_half_m;
    for _ in 0..MAX_QUERY_DRAWS {
        let displacement = Vec3::new(
            symmetric(rng, half[0]),
            symmetric(rng, half[1]),
            symmetric(rng, half[2]),
        );
        let attitude = Attitude::new(
            symmetric(rng, config.tilt_max_deg).to_radians(),
            symmetric(rng, config.tilt_max_deg).to_radians(),
            wrap_angle(heading + symmetric(rng, config.yaw_spread_deg).to_radians()),
        );
        let query_origin = origin + displacement;
        if scene.clearance(&query_origin, CLEARANCE_DIRECTIONS) >= config.min_clearance_m {
            return Some(pose_from_parts(query_origin, attitude));
        }
    }
    None
}

/// Uniform in `[-half, half]`; always one draw, so the stream does not depend on `half`.
pub(crate) fn symmetric(rng: &mut impl Rng, half: f64) -> f64 {
    half * rng.random_range(-1.0..=1.0)
}

/// `pose` moved by exactly `translation_m` along a random direction and turned by exactly
/// `rotation_deg` about a random axis: an initial guess that is off by a known amount.
///
/// The translation error of the result against `pose` is `translation_m` (its translation is
/// `pose`'s plus the offset) and its rotation error `rotation_deg` (its rotation is
/// `turn · pose.rotation`), whichever frame the errors are measured in.
///
/// # Example
/// ```
/// use rand::SeedableRng;
/// let truth = sdem::geometry::Pose::translation(0.3, -0.1, 0.05);
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
/// let guess = sdem_sim::benchmark::perturbed(&truth, 0.2, 5.0, &mut rng);
/// let dt = (guess.translation.vector - truth.translation.vector).norm();
/// let dr = guess.rotation.angle_to(&truth.rotation).to_degrees();
/// assert!((dt - 0.2).abs() < 1e-12 && (dr - 5.0).abs() < 1e-9);
/// ```
pub fn perturbed(pose: &Pose, translation_m: f64, rotation_deg: f64, rng: &mut impl Rng) -> Pose {
    let offset = random_unit(rng).into_inner() * translation_m;
    let turn = UnitQuaternion::from_axis_angle(&random_unit(rng), rotation_deg.to_radians());
    Pose::from_parts(
        Translation3::from(pose.translation.vector + offset),
        turn * pose.rotation,
    )
}

/// A direction drawn uniformly on the sphere.
pub(crate) fn random_unit(rng: &mut impl Rng) -> Unit<Vec3> {
    loop {
        let v = Vec3::new(
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
        );
        if v.norm() > 1e-9 {
            return Unit::new_normalize(v);
        }
    }
}

/// Order statistics of a set of errors.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stats {
    /// The number of values.
    pub count: usize,
    /// The median (the mean of the two middle values for an even count).
    pub median: f64,
    /// The 95th percentile, interpolated linearly between order statistics (as numpy's default).
    pub p95: f64,
    /// The largest value.
    pub max: f64,
    /// The mean.
    pub mean: f64,
}

/// The median, 95th percentile, maximum and mean of `errors`.
///
/// A NaN counts as infinitely bad (a failed run), so it raises the percentiles instead of
/// hiding. An empty slice gives a count of 0 and NaN everywhere else.
///
/// # Example
/// ```
/// let s = sdem_sim::benchmark::summarize(&[4.0, 1.0, 3.0, 2.0]);
/// assert_eq!((s.median, s.max, s.mean), (2.5, 4.0, 2.5));
/// assert!((s.p95 - 3.85).abs() < 1e-12);
/// ```
pub fn summarize(errors: &[f64]) -> Stats {
    let mut sorted: Vec<f64> = errors
        .iter()
        .map(|&e| if e.is_nan() { f64::INFINITY } else { e })
        .collect();
    sorted.sort_by(f64::total_cmp);
    let count = sorted.len();
    if count == 0 {
        return Stats {
            count,
            median: f64::NAN,
            p95: f64::NAN,
            max: f64::NAN,
            mean: f64::NAN,
        };
    }
    Stats {
        count,
        median: percentile(&sorted, 0.5),
        p95: percentile(&sorted, 0.95),
        max: sorted[count - 1],
        mean: sorted.iter().sum::<f64>() / count as f64,
    }
}

/// The `q` quantile of sorted, non-empty `values`, linear between order statistics.
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let position = q * (sorted.len() - 1) as f64;
    let below = position.floor() as usize;
    let above = position.ceil() as usize;
    let (a, b) = (sorted[below], sorted[above]);
    if below == above || a == b {
        a
    } else {
        a + (b - a) * (position - below as f64)
    }
}

/// The fraction of `errors` below `threshold` (NaN counts as a failure); 0 for no errors.
///
/// # Example
/// ```
/// let rate = sdem_sim::benchmark::success_rate(&[0.001, 0.05, f64::NAN, 0.01], 0.02);
/// assert_eq!(rate, 0.5);
/// ```
pub fn success_rate(errors: &[f64], threshold: f64) -> f64 {
    if errors.is_empty() {
        return 0.0;
    }
    errors.iter().filter(|&&e| e < threshold).count() as f64 / errors.len() as f64
}

/// 95 % of a χ² with 6 degrees of freedom lie below this: the bound for [`nees`] over all six
/// axes.
pub const CHI2_95_6: f64 = 12.592;
/// 95 % of a χ² with 3 degrees of freedom lie below this: the bound for [`nees`] over the
/// translation.
pub const CHI2_95_3: f64 = 7.815;

/// The share of `nees` values below `bound` ([`CHI2_95_6`] or [`CHI2_95_3`]: 0.95 when the
/// covariances are honest); `None` for no values.
pub fn share_below(nees: &[f64], bound: f64) -> Option<f64> {
    (!nees.is_empty())
        .then(|| nees.iter().filter(|&&n| n < bound).count() as f64 / nees.len() as f64)
}

/// The normalized estimation error squared of `estimate` against `truth` under a reported
/// `covariance`: `eᵀ Σ⁻¹ e` over all six axes, and over the translation alone.
///
/// `covariance` is [`Localization::covariance`]'s: `[x, y, z, rx, ry, rz]` on the estimated
/// query sensor's axes (metres, radians), the estimate's error `e` the translation and the
/// rotation vector of `estimate⁻¹ · truth` (the correction the estimate needs, on its own
/// axes). When the covariance says how large the errors are, the first averages 6 over many
/// localizations (a χ² with 6 degrees of freedom: 95 % of them below 12.6) and the second 3
/// (95 % below 7.8); much larger means the covariance is too small (overconfident).
///
/// # Returns
/// `None` when the covariance is not positive definite.
///
/// # Example
/// ```
/// use nalgebra::Matrix6;
/// use sdem::geometry::Pose;
/// let truth = Pose::translation(0.002, 0.0, 0.0);
/// // σ = 1 mm on every axis (and 1 mrad): an error of 2 mm is 2 σ, NEES 4.
/// let covariance = Matrix6::identity() * 1e-6;
/// let (all, translation) = sdem_sim::benchmark::nees(&truth, &Pose::identity(), &covariance).unwrap();
/// assert!((all - 4.0).abs() < 1e-9 && (translation - 4.0).abs() < 1e-9);
/// ```
pub fn nees(truth: &Pose, estimate: &Pose, covariance: &Matrix6<f64>) -> Option<(f64, f64)> {
    let correction = estimate.inverse() * truth;
    let t = correction.translation.vector;
    let r = correction.rotation.scaled_axis();
    let e = Vector6::new(t.x, t.y, t.z, r.x, r.y, r.z);
    let all = covariance.cholesky()?.solve(&e).dot(&e);
    let translation_block = covariance.fixed_view::<3, 3>(0, 0).into_owned();
    let translation = translation_block.cholesky()?.solve(&t).dot(&t);
    Some((all, translation))
}

/// The grid step the pairs are searched with, metres: a 2 cm grid finds the basin and the
/// refinement the bottom (`sdem bench --step`'s default).
pub const PAIRS_STEP_M: f64 = 0.02;

/// The localization settings the benchmark runs sdem with: the default search over the pairs'
/// displacement window on a [`PAIRS_STEP_M`] grid. The one place this module builds a
/// [`LocalizeOptions`]; `sdem bench` and the pairs exported for the peers both use it.
pub fn localize_config(pairs: &PairConfig) -> LocalizeOptions {
    LocalizeOptions {
        window: pairs.search_window(),
        step_m: PAIRS_STEP_M,
        ..Default::default()
    }
}

/// sdem's answer for one pair, scored against the truth.
#[derive(Debug, Clone)]
pub struct PairResult {
    /// Estimated `reference_from_query`.
    pub estimate: Pose,
    /// Translation error against [`BenchPair::truth`], metres.
    pub translation_error_m: f64,
    /// Rotation error against [`BenchPair::truth`], degrees.
    pub rotation_error_deg: f64,
    /// Time to build both S-DEMs and localize, milliseconds.
    pub time_ms: f64,
    /// The search's full result.
    pub localization: Localization,
}

/// Builds both S-DEMs of `pair` (each levelled by its reading; the two at once) and localizes the
/// query against the reference with `config` (see [`localize_config`]).
///
/// # Errors
/// Whatever [`Sdem::from_points`] or [`localize`] reports (an invalid configuration, no candidate
/// with enough overlap).
pub fn localize_pair(
    pair: &BenchPair,
    sdem: &SdemConfig,
    config: &LocalizeOptions,
) -> Result<PairResult> {
    let start = Instant::now();
    let (reference, query) = Sdem::pair_from_points(
        (&pair.reference_points, &pair.reference_attitude),
        (&pair.query_points, &pair.query_attitude),
        sdem,
    )?;
    let localization = localize(&reference, &query, config)?;
    let time_ms = start.elapsed().as_secs_f64() * 1e3;
    let estimate = localization.reference_from_query;
    let (translation_error_m, rotation_error) = pose_error(&pair.truth, &estimate);
    Ok(PairResult {
        estimate,
        translation_error_m,
        rotation_error_deg: rotation_error.to_degrees(),
        time_ms,
        localization,
    })
}

/// Checks that each named field is a finite number ≥ 0; the error names `what` and the field.
pub(crate) fn check_non_negative(what: &str, fields: &[(&str, f64)]) -> Result<()> {
    for &(name, value) in fields {
        if !(value.is_finite() && value >= 0.0) {
            return Err(Error::Invalid(format!(
                "{what}: {name} is {value}; it must be a finite number >= 0"
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A coarse sweep (2° steps) keeps the tests quick; the geometry is the same.
    fn quick_config() -> PairConfig {
        let mut config = PairConfig::default();
        config.sensor.tilt_step_deg = 2.0;
        config.sensor.pan_step_deg = 2.0;
        config
    }

    #[test]
    fn pairs_are_deterministic_for_a_seed_and_any_thread_count() {
        let config = quick_config();
        let a = bench_pairs(5, 3, &config).unwrap();
        let b = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| bench_pairs(5, 3, &config))
            .unwrap();
        assert_eq!(a, b);
        // A prefix of a longer run is the same pairs.
        let c = bench_pairs(5, 2, &config).unwrap();
        assert_eq!(&a[..2], &c[..]);
        // Another seed gives other pairs.
        let d = bench_pairs(6, 3, &config).unwrap();
        assert_ne!(a[0].truth, d[0].truth);
    }

    #[test]
    fn the_compass_error_changes_only_the_yaw_reading() {
        let config = quick_config();
        let none = PairConfig {
            compass_error_max_deg: 0.0,
            ..config.clone()
        };
        let with = bench_pairs(2, 4, &config).unwrap();
        let without = bench_pairs(2, 4, &none).unwrap();
        for (w, o) in with.iter().zip(&without) {
            assert_eq!(w.query_points, o.query_points);
            assert_eq!(w.truth, o.truth);
            assert_eq!(o.compass_error_deg, 0.0);
            assert!(w.compass_error_deg.abs() <= config.compass_error_max_deg);
            let added = wrap_angle(w.query_attitude.yaw - o.query_attitude.yaw);
            assert!((added.to_degrees() - w.compass_error_deg).abs() < 1e-9);
            assert_eq!(w.query_attitude.roll, o.query_attitude.roll);
            // Without the added error the reading is the truth plus the compass's own noise.
            let true_yaw = attitude_of(&o.world_from_query).yaw;
            let noise = wrap_angle(o.query_attitude.yaw - true_yaw).to_degrees();
            assert!(
                noise.abs() < 6.0 * config.sensor.compass_noise_deg,
                "{noise}"
            );
        }
    }

    #[test]
    fn queries_stay_in_their_windows_with_clearance() {
        let config = quick_config();
        let pairs = bench_pairs(1, 8, &config).unwrap();
        let scene = sim::collapsed_building(1);
        for pair in &pairs {
            let offset = pair.true_offset();
            for axis in 0..3 {
                assert!(offset[axis].abs() <= config.displacement_half_m[axis] + 1e-12);
            }
            let origin = pair.world_from_query.translation.vector;
            assert!(scene.is_free(&origin));
            assert!(scene.clearance(&origin, 1000) >= config.min_clearance_m - 0.01);
            let query = attitude_of(&pair.world_from_query);
            let reference = attitude_of(&pair.world_from_reference);
            let turn = wrap_angle(query.yaw - reference.yaw).to_degrees();
            assert!(turn.abs() <= config.yaw_spread_deg + 1e-9, "{turn}");
            assert!(query.roll.to_degrees().abs() <= config.tilt_max_deg + 1e-9);
            assert!(query.pitch.to_degrees().abs() <= config.tilt_max_deg + 1e-9);
            assert!(pair.reference_stop < sim::MAX_STOPS);
            assert!(pair.reference_points.len() > 1000 && pair.query_points.len() > 1000);
        }
    }

    /// Of the query's points mapped into the reference frame by `reference_from_query`, the
    /// fraction that the reference sensor sees at the same range (within 3 cm): a point the
    /// query saw on a surface is either visible from the reference at its range or hidden behind
    /// something nearer, never beyond free space.
    fn agreement(pair: &BenchPair, scene: &sim::Scene, reference_from_query: &Pose) -> f64 {
        let origin = pair.world_from_reference.translation.vector;
        let (mut seen, mut total) = (0, 0);
        for p in pair.query_points.iter().step_by(7) {
            let in_reference = reference_from_query * nalgebra::Point3::from(*p);
            let range = in_reference.coords.norm();
            let direction = pair.world_from_reference.rotation * (in_reference.coords / range);
            let hit = scene.raycast(&origin, &direction, 20.0).unwrap_or(20.0);
            total += 1;
            if (hit - range).abs() < 0.03 {
                seen += 1;
            }
        }
        seen as f64 / total as f64
    }

    #[test]
    fn truth_maps_query_points_onto_the_reference_scene() {
        let pairs = bench_pairs(3, 3, &quick_config()).unwrap();
        let scene = sim::collapsed_building(3);
        for pair in &pairs {
            // The query's origin in the reference frame is the truth's translation.
            let origin = pair.world_from_reference.inverse()
                * nalgebra::Point3::from(pair.world_from_query.translation.vector);
            assert!((origin.coords - pair.truth.translation.vector).norm() < 1e-12);
            let right = agreement(pair, &scene, &pair.truth);
            let inverted = agreement(pair, &scene, &pair.truth.inverse());
            let shifted = agreement(
                pair,
                &scene,
                &(Pose::translation(0.1, 0.0, 0.0) * pair.truth),
            );
            assert!(right > 0.6, "truth agrees on only {right}");
            assert!(
                inverted < right - 0.2,
                "inverse {inverted} vs truth {right}"
            );
            assert!(shifted < right - 0.2, "shifted {shifted} vs truth {right}");
        }
    }

    #[test]
    fn perturbed_guesses_are_off_by_exactly_the_asked_amount() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let truth = pose_from_parts(
            Vec3::new(0.4, -0.2, 0.05),
            Attitude::from_degrees(2.0, -1.0, 12.0),
        );
        for _ in 0..20 {
            let guess = perturbed(&truth, 0.2, 5.0, &mut rng);
            let dt = (guess.translation.vector - truth.translation.vector).norm();
            let dr = guess.rotation.angle_to(&truth.rotation).to_degrees();
            assert!((dt - 0.2).abs() < 1e-12 && (dr - 5.0).abs() < 1e-9);
        }
    }

    #[test]
    fn statistics() {
        let s = summarize(&[5.0, 1.0, 2.0, 4.0, 3.0]);
        assert_eq!(s.count, 5);
        assert_eq!(s.median, 3.0);
        assert_eq!(s.max, 5.0);
        assert_eq!(s.mean, 3.0);
        assert!((s.p95 - 4.8).abs() < 1e-12);
        let values: Vec<f64> = (1..=100).map(f64::from).collect();
        let s = summarize(&values);
        assert!((s.p95 - 95.05).abs() < 1e-12);
        assert_eq!(summarize(&[f64::NAN, 1.0]).max, f64::INFINITY);
        assert!(summarize(&[]).median.is_nan());
        assert_eq!(success_rate(&[], 1.0), 0.0);
        assert_eq!(success_rate(&[0.5, 1.5], 1.0), 0.5);
    }

    #[test]
    fn invalid_configs_are_rejected() {
        let bad = PairConfig {
            yaw_spread_deg: -1.0,
            ..Default::default()
        };
        assert!(bench_pairs(1, 1, &bad).is_err());
        let bad = PairConfig {
            displacement_half_m: [0.5, f64::NAN, 0.1],
            ..Default::default()
        };
        assert!(bad.validate().is_err());
        assert!(bench_pairs(1, 0, &PairConfig::default())
            .unwrap()
            .is_empty());
    }
}
