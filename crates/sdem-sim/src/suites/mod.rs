//! Seeded scan pairs for `sdem bench --suite`: scans as they come in the field, not as the
//! paper's gyro and compass promise them.
//!
//! [`suite_pairs`] draws pairs of scans in several scenes ([`SuiteScene`]: the collapsed
//! building's rubble void and ditch, a corridor, an open hall, a street), taken by the paper's
//! tilting laser range finder or by a spinning LiDAR ([`SuiteSensor`]). The query stands up to
//! [`SuiteConfig::step_max_m`] from the reference, tilted up to [`SuiteConfig::query_tilt_max_deg`]
//! in roll and in pitch, at any heading; the scans carry no attitude, or a reading with the
//! errors and the standard deviations of [`Readings::Noisy`]. Recipes: [`SuiteConfig::unlevelled`],
//! [`SuiteConfig::compass_noise`], [`SuiteConfig::spinning_lidar`].
//!
//! A pair is kept only when both sensor origins lie in free space with clearance and the two
//! scans see enough of the same surfaces ([`SuiteConfig::min_overlap`]): with the tilting
//! scanner's front half field of view, two scans at opposite headings may share nothing, and no
//! method could match them. The truth comes with every pair.
//!
//! Pure: scenes and scans are simulated in memory; writing them out is the caller's job.
//!
//! # Example
//! ```
//! use sdem_sim::suites::{suite_pairs, SuiteConfig, SuiteSensor};
//! let mut config = SuiteConfig::unlevelled();
//! // A coarse sweep keeps the example quick.
//! if let SuiteSensor::Tilting(sensor) = &mut config.sensor {
//!     sensor.tilt_step_deg = 3.0;
//!     sensor.pan_step_deg = 3.0;
//! }
//! let pairs = suite_pairs(7, 2, &config)?;
//! assert_eq!(pairs.len(), 2);
//! assert!(pairs[0].query_attitude.is_none()); // no attitude on either scan
//! assert!(pairs[0].step_m() <= config.step_max_m);
//! # Ok::<(), sdem::Error>(())
//! ```

use crate::benchmark::symmetric;
use crate::sim::{self, wrap_angle, LidarConfig, Scene};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use sdem::error::{Error, Result};
use sdem::geometry::{attitude_of, pose_from_parts, Attitude, Pose, Vec3};
use sdem::search::SearchWindow;
use sdem::sensor::{beam_direction, SensorConfig};
use serde::Serialize;

#[cfg(test)]
mod tests;

/// Mixed into the seed of the pairs' random streams, so they do not repeat the scenes'.
const PAIR_SALT: u64 = 0x5017_e500_0000_0001;
/// Mixed into the seed of the attitude readings' errors: a stream of their own, so the same
/// seed gives the same scans with or without readings.
const READING_SALT: u64 = 0x7ead_1265_0000_0001;
/// References drawn per pair before giving up.
const MAX_REFERENCE_DRAWS: usize = 50;
/// Queries drawn per reference before drawing another reference.
const MAX_QUERY_DRAWS: usize = 400;
/// Sample directions of the clearance checks (as [`sim::collapsed_building_stops`] uses).
const CLEARANCE_DIRECTIONS: usize = 200;
/// The overlap check's beams are spaced this far apart, degrees.
const OVERLAP_STEP_DEG: f64 = 5.0;
/// A query beam's hit counts as seen by the reference when the reference's ray along it stops
/// within this of it, metres.
const OVERLAP_TOLERANCE_M: f64 = 0.03;
/// The corridor's length, metres: both ends within the tilting scanner's 8 m from anywhere
/// in its sensor region, so a scan can fix the position along it.
pub const CORRIDOR_LENGTH_M: f64 = 8.0;

/// The scenes the suites draw pairs in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SuiteScene {
    /// The rubble void of [`sim::collapsed_building`]: references at the route's stops past the
    /// ditch.
    RubbleVoid,
    /// The narrow ditch of [`sim::collapsed_building`]: references at the route's stops where
    /// the lift is low.
    Ditch,
    /// [`sim::corridor`] of [`CORRIDOR_LENGTH_M`]: 1.2 m wide, 1 m high, featureless walls.
    Corridor,
    /// [`sim::open_hall`]: 18 × 13 × 4.5 m with pillars and boxes.
    Hall,
    /// [`sim::street`]: facades, side streets, parked cars, poles and trees.
    Street,
}

impl SuiteScene {
    /// A short name, as the reports print it.
    pub fn name(&self) -> &'static str {
        match self {
            SuiteScene::RubbleVoid => "rubble-void",
            SuiteScene::Ditch => "ditch",
            SuiteScene::Corridor => "corridor",
            SuiteScene::Hall => "hall",
            SuiteScene::Street => "street",
        }
    }
}

/// The sensor that takes both scans of a pair.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SuiteSensor {
    /// The paper's tilting laser range finder ([`sim::scan`]): the front half of the sphere.
    Tilting(SensorConfig),
    /// A spinning multi-beam LiDAR ([`sim::spin_scan`]): all around, within its rings.
    Spinning(LidarConfig),
}

impl SuiteSensor {
    fn validate(&self) -> Result<()> {
        match self {
            SuiteSensor::Tilting(s) => s.validate(),
            SuiteSensor::Spinning(l) => l.validate(),
        }
    }

    /// The returns of one scan at `world_from_sensor`, points in the sensor frame, metres.
    fn scan(
        &self,
        scene: &Scene,
        world_from_sensor: &Pose,
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<Vec3>> {
        match self {
            SuiteSensor::Tilting(s) => {
                Ok(sim::scan(scene, s, world_from_sensor, 0.0, rng).points_in_sensor())
            }
            SuiteSensor::Spinning(l) => sim::spin_scan(scene, l, world_from_sensor, rng),
        }
    }

    /// The beams of the overlap check, sensor frame: every [`OVERLAP_STEP_DEG`] over the field
    /// of view.
    fn sample_beams(&self) -> Vec<Vec3> {
        let step = OVERLAP_STEP_DEG;
        let spaced = |lo: f64, hi: f64| {
            let n = ((hi - lo) / step).floor() as usize;
            (0..=n).map(move |i| (lo + i as f64 * step).to_radians())
        };
        match self {
            SuiteSensor::Tilting(s) => spaced(s.tilt_min_deg, s.tilt_max_deg)
                .flat_map(|t| {
                    spaced(s.pan_min_deg, s.pan_max_deg).map(move |p| beam_direction(t, p))
                })
                .collect(),
            SuiteSensor::Spinning(l) => {
                let (lo, hi) = if l.azimuth_fov_deg >= 360.0 {
                    (-180.0, 180.0 - step)
                } else {
                    (-0.5 * l.azimuth_fov_deg, 0.5 * l.azimuth_fov_deg)
                };
                spaced(l.elevation_min_deg, l.elevation_max_deg)
                    .flat_map(|e| spaced(lo, hi).map(move |a| sim::lidar_beam(e, a)))
                    .collect()
            }
        }
    }

    /// True when a return at `point_in_sensor` lies within the field of view and the ranges.
    fn could_see(&self, point_in_sensor: &Vec3) -> bool {
        let range = point_in_sensor.norm();
        let direction = point_in_sensor / range;
        match self {
            SuiteSensor::Tilting(s) => {
                let pan = direction.y.clamp(-1.0, 1.0).asin().to_degrees();
                let tilt = direction.z.atan2(direction.x).to_degrees();
                range >= s.min_range_m
                    && range <= s.usable_range_m()
                    && (s.pan_min_deg..=s.pan_max_deg).contains(&pan)
                    && (s.tilt_min_deg..=s.tilt_max_deg).contains(&tilt)
            }
            SuiteSensor::Spinning(l) => {
                range >= l.min_range_m && range <= l.max_range_m && l.sees(&direction)
            }
        }
    }

    fn max_range_m(&self) -> f64 {
        match self {
            SuiteSensor::Tilting(s) => s.usable_range_m(),
            SuiteSensor::Spinning(l) => l.max_range_m,
        }
    }
}

/// The attitude readings the scans of a pair carry.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Readings {
    /// No attitude on either scan (`None`): no gyro, no compass.
    None,
    /// A reading on each scan: the true roll and pitch plus N(0, `roll_pitch_sigma_deg`) each,
    /// the true heading plus N(0, `yaw_sigma_deg`), with these standard deviations stated
    /// ([`Attitude::with_sigma_deg`]).
    Noisy {
        /// The gyro's standard deviation in roll and in pitch, degrees.
        roll_pitch_sigma_deg: f64,
        /// The compass's standard deviation, degrees.
        yaw_sigma_deg: f64,
    },
}

/// How [`suite_pairs`] draws its pairs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SuiteConfig {
    /// The scenes, in turn: pair `i` is drawn in `scenes[i % scenes.len()]`.
    pub scenes: Vec<SuiteScene>,
    /// The sensor of both scans.
    pub sensor: SuiteSensor,
    /// The largest distance between the two sensor origins, metres (uniform in the ball).
    pub step_max_m: f64,
    /// The largest difference in height between them, metres.
    pub step_z_max_m: f64,
    /// The query's roll and pitch are each uniform within ± this, degrees.
    pub query_tilt_max_deg: f64,
    /// The reference's roll and pitch are each uniform within ± this, degrees.
    pub reference_tilt_max_deg: f64,
    /// Both sensor origins lie at least this far from every surface, metres.
    pub min_clearance_m: f64,
    /// Of the query's beams that return, at least this share hit a surface the reference
    /// sees at the same place (within 3 cm; beams every 5° over the field of view).
    pub min_overlap: f64,
    /// The attitude readings given with the scans.
    pub readings: Readings,
}

impl SuiteConfig {
    /// `sdem bench --suite unlevelled`: the tilting scanner (default sensor, 1° steps, 5 mm
    /// range noise) in the rubble void, the ditch, the corridor and the hall in turn; the query
    /// up to 1 m away (±0.25 m in height), roll and pitch each within ±30°, any heading; the
    /// reference nearly level (roll and pitch within ±5°, as a robot standing on a floor), any
    /// heading; 0.15 m of clearance; 30 % overlap; no attitude on either scan.
    pub fn unlevelled() -> Self {
        Self {
            scenes: vec![
                SuiteScene::RubbleVoid,
                SuiteScene::Ditch,
                SuiteScene::Corridor,
                SuiteScene::Hall,
            ],
            sensor: SuiteSensor::Tilting(SensorConfig::default()),
            step_max_m: 1.0,
            step_z_max_m: 0.25,
            query_tilt_max_deg: 30.0,
            reference_tilt_max_deg: 5.0,
            min_clearance_m: sim::MIN_SENSOR_CLEARANCE_M,
            min_overlap: 0.3,
            readings: Readings::None,
        }
    }

    /// `sdem bench --suite compass-noise`: the pairs of [`Self::unlevelled`] (the same seed
    /// gives the same scans), each scan with a reading off by N(0, 2°) in roll and pitch and
    /// N(0, 20°) in heading, and these σ stated.
    pub fn compass_noise() -> Self {
        Self {
            readings: Readings::Noisy {
                roll_pitch_sigma_deg: 2.0,
                yaw_sigma_deg: 20.0,
            },
            ..Self::unlevelled()
        }
    }

    /// The simulated half of `sdem bench --suite lidar`: a spinning LiDAR ([`LidarConfig`]'s
    /// default: 32 rings, −25°..+15°, 0.2°, 100 m, 2 cm noise) 1.6–1.9 m above the road in the
    /// street and 0.4–1.6 m above the floor in the hall, in turn; the query up to 1 m away
    /// (±0.1 m in height), both scans tilted up to ±3° in roll and pitch, any heading; 0.5 m of
    /// clearance; 50 % overlap; no attitude.
    pub fn spinning_lidar() -> Self {
        Self {
            scenes: vec![SuiteScene::Street, SuiteScene::Hall],
            sensor: SuiteSensor::Spinning(LidarConfig::default()),
            step_max_m: 1.0,
            step_z_max_m: 0.1,
            query_tilt_max_deg: 3.0,
            reference_tilt_max_deg: 3.0,
            min_clearance_m: 0.5,
            min_overlap: 0.5,
            readings: Readings::None,
        }
    }

    /// The solid-state half of `sdem bench --suite lidar`: [`LidarConfig::solid_state`] (70° ×
    /// 70°, forward-looking) in the street and the hall, placed as [`Self::spinning_lidar`]
    /// places its sensor; the query up to 1 m away, any heading as long as 30 % of the query's
    /// returns fall where the reference sees the same surface (so, in practice, within a few
    /// tens of degrees of each other).
    pub fn solid_state_lidar() -> Self {
        Self {
            sensor: SuiteSensor::Spinning(LidarConfig::solid_state()),
            min_overlap: 0.3,
            ..Self::spinning_lidar()
        }
    }

    /// Checks every field; the message names the field.
    ///
    /// # Errors
    /// [`Error::Invalid`] for no scenes, a building scene with the spinning LiDAR, a negative
    /// or non-finite step, clearance or tilt, a tilt of 90° or more, an overlap outside [0, 1],
    /// bad reading σ, or an invalid sensor.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::Invalid(format!("suite pairs: {what}")));
        if self.scenes.is_empty() {
            return bad("no scenes".into());
        }
        let fields = [
            ("step_max_m", self.step_max_m),
            ("step_z_max_m", self.step_z_max_m),
            ("query_tilt_max_deg", self.query_tilt_max_deg),
            ("reference_tilt_max_deg", self.reference_tilt_max_deg),
            ("min_clearance_m", self.min_clearance_m),
            ("min_overlap", self.min_overlap),
        ];
        for (name, value) in fields {
            if !(value.is_finite() && value >= 0.0) {
                return bad(format!(
                    "{name} is {value}; it must be a finite number >= 0"
                ));
            }
        }
        if self.query_tilt_max_deg >= 90.0 || self.reference_tilt_max_deg >= 90.0 {
            return bad("tilts must be below 90°".into());
        }
        if self.min_overlap > 1.0 {
            return bad(format!("min_overlap {} is above 1", self.min_overlap));
        }
        if let Readings::Noisy {
            roll_pitch_sigma_deg,
            yaw_sigma_deg,
        } = self.readings
        {
            let valid = |sigma: f64| sigma.is_finite() && sigma > 0.0;
            if !(valid(roll_pitch_sigma_deg) && valid(yaw_sigma_deg)) {
                return bad("the readings' σ must be finite and positive".into());
            }
        }
        self.sensor.validate()
    }

    /// A translation window that holds every query of these pairs, on the reference's levelled
    /// axes (levelled by its reading, or by its own floor and ceiling without one):
    /// `step_max_m` (+5 cm) across and `step_z_max_m` (+5 cm) in height.
    pub fn search_window(&self) -> SearchWindow {
        let across = self.step_max_m + 0.05;
        SearchWindow::around(&Vec3::zeros(), [across, across, self.step_z_max_m + 0.05])
    }
}

/// Two scans with their readings and the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct SuitePair {
    /// The pair's index in its suite (its random stream).
    pub index: usize,
    /// Where it was drawn.
    pub scene: SuiteScene,
    /// The reference scan, points in its sensor frame, metres.
    pub reference_points: Vec<Vec3>,
    /// The query scan, points in its sensor frame, metres.
    pub query_points: Vec<Vec3>,
    /// The reading given with the reference, or `None` (no attitude).
    pub reference_attitude: Option<Attitude>,
    /// The reading given with the query, or `None` (no attitude).
    pub query_attitude: Option<Attitude>,
    /// True `world_from_sensor` of the reference.
    pub world_from_reference: Pose,
    /// True `world_from_sensor` of the query.
    pub world_from_query: Pose,
    /// True `reference_from_query` (for tools that name transforms `T_target_source`: the
    /// query is the source, the reference the target).
    pub truth: Pose,
    /// The share of the query's sample beams that the reference sees (see
    /// [`SuiteConfig::min_overlap`]).
    pub overlap: f64,
}

impl SuitePair {
    /// The distance between the two sensor origins, metres.
    pub fn step_m(&self) -> f64 {
        self.truth.translation.vector.norm()
    }

    /// The query's heading minus the reference's, degrees in [−180, 180).
    pub fn relative_heading_deg(&self) -> f64 {
        let q = attitude_of(&self.world_from_query).yaw;
        let r = attitude_of(&self.world_from_reference).yaw;
        wrap_angle(q - r).to_degrees()
    }

    /// The angle between the query sensor's z axis and the vertical, degrees.
    pub fn query_tilt_deg(&self) -> f64 {
        let up = self.world_from_query.rotation * Vec3::z();
        up.z.clamp(-1.0, 1.0).acos().to_degrees()
    }
}

/// A scene with where its sensors may stand.
struct Place {
    kind: SuiteScene,
    scene: Scene,
    origins: Origins,
}

/// Where a reference sensor may stand.
enum Origins {
    /// At one of these points (the collapsed building's stops).
    Stops(Vec<Vec3>),
    /// Anywhere in this box `[min, max]` with clearance.
    Region([[f64; 3]; 2]),
}

/// Builds the scenes of `config` for `seed` (the collapsed building once for both its parts).
fn places(seed: u64, config: &SuiteConfig) -> Result<Vec<Place>> {
    let mut building: Option<(Scene, Vec<sim::Stop>)> = None;
    let lift = SensorConfig::default().lift;
    let mut out = Vec::new();
    for &kind in &config.scenes {
        let place = match kind {
            SuiteScene::RubbleVoid | SuiteScene::Ditch => {
                if building.is_none() {
                    let scene = sim::collapsed_building(seed);
                    let stops = sim::collapsed_building_stops(&scene, seed, sim::MAX_STOPS, &lift)?;
                    building = Some((scene, stops));
                }
                let (scene, stops) = building.as_ref().expect("built above");
                Place {
                    kind,
                    scene: scene.clone(),
                    origins: Origins::Stops(building_origins(stops, kind, &lift)?),
                }
            }
            SuiteScene::Corridor => Place {
                kind,
                scene: sim::corridor(CORRIDOR_LENGTH_M)?,
                origins: Origins::Region(corridor_region()),
            },
            SuiteScene::Hall => Place {
                kind,
                scene: sim::open_hall(seed),
                origins: Origins::Region(sim::open_hall_sensor_region()),
            },
            SuiteScene::Street => Place {
                kind,
                scene: sim::street(seed),
                origins: Origins::Region(sim::street_sensor_region()),
            },
        };
        out.push(place);
    }
    Ok(out)
}

/// The corridor's sensor region: 2.5 m or more from its ends, clear of its walls, floor and
/// ceiling.
fn corridor_region() -> [[f64; 3]; 2] {
    let floor = -sim::CORRIDOR_SENSOR_HEIGHT_M;
    let end = 0.5 * CORRIDOR_LENGTH_M - 2.5;
    [[-end, -0.3, floor + 0.25], [end, 0.3, floor + 0.75]]
}

/// The sensor origins of the collapsed building's stops in the ditch (the lift low) or in the
/// void beyond it.
fn building_origins(
    stops: &[sim::Stop],
    kind: SuiteScene,
    lift: &sdem::sensor::LiftConfig,
) -> Result<Vec<Vec3>> {
    // Stop 0 stands in the room with the lift high; the ditch's stops hold it low.
    let high = stops[0].lift_slide_m;
    let in_ditch: Vec<bool> = stops.iter().map(|s| s.lift_slide_m != high).collect();
    let last_ditch = in_ditch.iter().rposition(|&d| d).unwrap_or(0);
    let mut origins = Vec::new();
    for (i, stop) in stops.iter().enumerate() {
        let keep = match kind {
            SuiteScene::Ditch => in_ditch[i],
            _ => i > last_ditch,
        };
        if keep {
            origins.push(stop.world_from_sensor(lift)?.translation.vector);
        }
    }
    if origins.is_empty() {
        return Err(Error::Invalid(format!(
            "suite pairs: the collapsed building has no stop in its {}",
            kind.name()
        )));
    }
    Ok(origins)
}

/// Draws `count` seeded pairs (see the module documentation and [`SuiteConfig`]):
/// [`SuiteGenerator::new`]`(seed, config)` then [`SuiteGenerator::pairs`]`(0..count)`.
///
/// # Arguments
/// * `seed` — seeds the scenes and every pair.
/// * `count` — the number of pairs; pair `i` is drawn in `config.scenes[i % len]`.
/// * `config` — the recipe.
///
/// # Errors
/// [`Error::Invalid`] for an invalid `config`, or when no pair fits after many draws.
pub fn suite_pairs(seed: u64, count: usize, config: &SuiteConfig) -> Result<Vec<SuitePair>> {
    SuiteGenerator::new(seed, config.clone())?.pairs(0..count)
}

/// The scenes of a recipe, built once, from which pairs are drawn by index: a long suite
/// simulates its pairs a few at a time instead of holding them all.
pub struct SuiteGenerator {
    seed: u64,
    config: SuiteConfig,
    places: Vec<Place>,
}

impl SuiteGenerator {
    /// Checks `config` and builds its scenes for `seed`.
    ///
    /// # Errors
    /// [`Error::Invalid`] for an invalid `config`.
    pub fn new(seed: u64, config: SuiteConfig) -> Result<Self> {
        config.validate()?;
        let places = places(seed, &config)?;
        Ok(Self {
            seed,
            config,
            places,
        })
    }

    /// The recipe.
    pub fn config(&self) -> &SuiteConfig {
        &self.config
    }

    /// The pairs with the indices of `range`, drawn in parallel.
    ///
    /// # Returns
    /// For pair `i`, from its own `ChaCha8Rng` stream `i`: a reference sensor origin (one of the
    /// scene's stops, or uniform in its region with `min_clearance_m`), roll and pitch each
    /// uniform within `±reference_tilt_max_deg`, heading uniform over a full turn; a query
    /// origin uniform in the ball of `step_max_m` around it (height within `±step_z_max_m`) with
    /// `min_clearance_m`, roll and pitch each uniform within `±query_tilt_max_deg`, heading
    /// uniform over a full turn, redrawn until it shares `min_overlap` with the reference; both
    /// scans simulated; the readings from a stream of their own. Pair `i` depends on the seed
    /// and `i` only, not on the range or the thread count.
    ///
    /// # Errors
    /// [`Error::Invalid`] when no pair fits after many draws.
    pub fn pairs(&self, range: std::ops::Range<usize>) -> Result<Vec<SuitePair>> {
        range
            .into_par_iter()
            .map(|index| {
                let place = &self.places[index % self.places.len()];
                let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ PAIR_SALT);
                rng.set_stream(index as u64);
                let mut reading_rng = ChaCha8Rng::seed_from_u64(self.seed ^ READING_SALT);
                reading_rng.set_stream(index as u64);
                draw_pair(place, &self.config, index, &mut rng, &mut reading_rng)
            })
            .collect()
    }
}

/// One pair from its own random streams (see [`suite_pairs`]).
fn draw_pair(
    place: &Place,
    config: &SuiteConfig,
    index: usize,
    rng: &mut ChaCha8Rng,
    reading_rng: &mut ChaCha8Rng,
) -> Result<SuitePair> {
    let (world_from_reference, world_from_query, overlap) = draw_poses(place, config, rng)
        .ok_or_else(|| {
            Error::Invalid(format!(
                "suite pair {index} ({}): no query pose with {} m of clearance and {:.0} % overlap \
                 turned up after {MAX_REFERENCE_DRAWS} references",
                place.kind.name(),
                config.min_clearance_m,
                config.min_overlap * 100.0
            ))
        })?;
    let reference_points = config
        .sensor
        .scan(&place.scene, &world_from_reference, rng)?;
    let query_points = config.sensor.scan(&place.scene, &world_from_query, rng)?;
    Ok(SuitePair {
        index,
        scene: place.kind,
        reference_points,
        query_points,
        reference_attitude: reading(&config.readings, &world_from_reference, reading_rng),
        query_attitude: reading(&config.readings, &world_from_query, reading_rng),
        truth: world_from_reference.inverse() * world_from_query,
        world_from_reference,
        world_from_query,
        overlap,
    })
}

/// A reference and a query pose and their overlap, or `None` when none fits.
fn draw_poses(
    place: &Place,
    config: &SuiteConfig,
    rng: &mut ChaCha8Rng,
) -> Option<(Pose, Pose, f64)> {
    for _ in 0..MAX_REFERENCE_DRAWS {
        let Some(origin) = reference_origin(place, config, rng) else {
            continue;
        };
        let reference =
            pose_from_parts(origin, random_attitude(rng, config.reference_tilt_max_deg));
        for _ in 0..MAX_QUERY_DRAWS {
            let step = step_in_ball(rng, config.step_max_m, config.step_z_max_m);
            let query = pose_from_parts(
                origin + step,
                random_attitude(rng, config.query_tilt_max_deg),
            );
            let clear = place
                .scene
                .clearance(&query.translation.vector, CLEARANCE_DIRECTIONS)
                >= config.min_clearance_m;
            if !clear {
                continue;
            }
            let shared = overlap(&place.scene, &config.sensor, &reference, &query);
            if shared >= config.min_overlap {
                return Some((reference, query, shared));
            }
        }
    }
    None
}

/// A reference sensor origin: a stop, or a point of the region with clearance (`None` after
/// a few misses).
fn reference_origin(place: &Place, config: &SuiteConfig, rng: &mut ChaCha8Rng) -> Option<Vec3> {
    match &place.origins {
        Origins::Stops(stops) => Some(stops[rng.random_range(0..stops.len())]),
        Origins::Region([lo, hi]) => (0..100).find_map(|_| {
            let p = Vec3::from_fn(|i, _| rng.random_range(lo[i]..=hi[i]));
            (place.scene.clearance(&p, CLEARANCE_DIRECTIONS) >= config.min_clearance_m).then_some(p)
        }),
    }
}

/// Roll and pitch each uniform within `±tilt_max_deg`, heading uniform over a full turn.
fn random_attitude(rng: &mut ChaCha8Rng, tilt_max_deg: f64) -> Attitude {
    let roll = symmetric(rng, tilt_max_deg).to_radians();
    let pitch = symmetric(rng, tilt_max_deg).to_radians();
    let yaw = symmetric(rng, 180.0).to_radians();
    Attitude::new(roll, pitch, wrap_angle(yaw))
}

/// A step uniform in the ball of radius `max_m` with its height within `±z_max_m`.
fn step_in_ball(rng: &mut ChaCha8Rng, max_m: f64, z_max_m: f64) -> Vec3 {
    loop {
        let step = Vec3::new(
            symmetric(rng, max_m),
            symmetric(rng, max_m),
            symmetric(rng, z_max_m.min(max_m)),
        );
        if step.norm() <= max_m {
            return step;
        }
    }
}

/// The share of the query's sample beams that return from a surface the reference sees at the
/// same place: within its field of view and ranges, and its own ray stopping within
/// [`OVERLAP_TOLERANCE_M`] of it. 0 when no query beam returns.
fn overlap(
    scene: &Scene,
    sensor: &SuiteSensor,
    world_from_reference: &Pose,
    world_from_query: &Pose,
) -> f64 {
    let query_origin = world_from_query.translation.vector;
    let reference_origin = world_from_reference.translation.vector;
    let max_range = sensor.max_range_m();
    let (mut returned, mut seen) = (0usize, 0usize);
    for beam in sensor.sample_beams() {
        let direction = world_from_query.rotation * beam;
        let Some(range) = scene.raycast(&query_origin, &direction, max_range) else {
            continue;
        };
        returned += 1;
        let hit = query_origin + direction * range;
        let in_reference = world_from_reference.inverse_transform_vector(&(hit - reference_origin));
        if !sensor.could_see(&in_reference) {
            continue;
        }
        let distance = in_reference.norm();
        let toward = (hit - reference_origin) / distance;
        let reached = scene.raycast(&reference_origin, &toward, max_range + 1.0);
        if reached.is_some_and(|r| (r - distance).abs() <= OVERLAP_TOLERANCE_M) {
            seen += 1;
        }
    }
    if returned == 0 {
        0.0
    } else {
        seen as f64 / returned as f64
    }
}

/// The reading of `readings` for a sensor at `world_from_sensor`.
fn reading(
    readings: &Readings,
    world_from_sensor: &Pose,
    rng: &mut ChaCha8Rng,
) -> Option<Attitude> {
    match *readings {
        Readings::None => None,
        Readings::Noisy {
            roll_pitch_sigma_deg,
            yaw_sigma_deg,
        } => {
            let truth = attitude_of(world_from_sensor);
            let mut noise = |sigma_deg: f64| {
                let n: f64 = rng.sample(StandardNormal);
                n * sigma_deg.to_radians()
            };
            let roll = truth.roll + noise(roll_pitch_sigma_deg);
            let pitch = truth.pitch + noise(roll_pitch_sigma_deg);
            let yaw = wrap_angle(truth.yaw + noise(yaw_sigma_deg));
            Some(
                Attitude::new(roll, pitch, yaw).with_sigma_deg(roll_pitch_sigma_deg, yaw_sigma_deg),
            )
        }
    }
}
