//! The tilting laser range finder: one sweep at a pose, and whole runs of stops.

use super::scene::Scene;
use super::stops::Stop;
use super::wrap_angle;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use sdem::error::Result;
use sdem::geometry::{attitude_of, Attitude, Pose};
use sdem::sensor::{beam_direction, SensorConfig, Sweep, SweepLine};
use std::borrow::Cow;

/// One simulated stop: the true sensor pose, the lift's slide and the raw sweep taken there.
#[derive(Debug, Clone, PartialEq)]
pub struct SimStop {
    /// True `world_from_sensor`.
    pub world_from_sensor: Pose,
    /// The lift's slide `u`, metres.
    pub lift_slide_m: f64,
    /// The sweep as the hardware reports it.
    pub sweep: Sweep,
}

/// The gyro/compass reading: the true attitude plus one error drawn for the whole sweep
/// (roll and pitch ~ N(0, `tilt_sensor_noise_deg`), yaw ~ N(0, `compass_noise_deg`)).
fn attitude_reading(
    world_from_sensor: &Pose,
    sensor: &SensorConfig,
    rng: &mut impl Rng,
) -> Attitude {
    let truth = attitude_of(world_from_sensor);
    let tilt = sensor.tilt_sensor_noise_deg.to_radians();
    let compass = sensor.compass_noise_deg.to_radians();
    let e_roll: f64 = rng.sample(StandardNormal);
    let e_pitch: f64 = rng.sample(StandardNormal);
    let e_yaw: f64 = rng.sample(StandardNormal);
    Attitude::new(
        truth.roll + tilt * e_roll,
        truth.pitch + tilt * e_pitch,
        wrap_angle(truth.yaw + compass * e_yaw),
    )
}

/// A measured range from a true hit: noise added, then dropped (NaN) when below
/// `min_range_m` or beyond the usable range.
fn measured(hit: Option<f64>, noise: f64, sensor: &SensorConfig) -> f32 {
    match hit {
        Some(r) => {
            let noisy = r + noise;
            if noisy < sensor.min_range_m || noisy > sensor.usable_range_m() {
                f32::NAN
            } else {
                noisy as f32
            }
        }
        None => f32::NAN,
    }
}

/// Simulates one raw sweep of the tilting LRF at `world_from_sensor` (paper Sec. IV).
///
/// For each tilt line of `sensor.tilt_angles_deg()` and each pan beam
/// `pan_min_deg + k · pan_step_deg` (k < `pan_count()`), the beam
/// `world_from_sensor.rotation · beam_direction(tilt, pan)` is cast from the sensor origin; its
/// range gets N(0, `range_noise_m`) noise and is NaN when nothing is hit within `max_range_m`,
/// or the noisy range is below `min_range_m` or beyond `trusted_range_m` (when set). Every line
/// carries the same gyro/compass reading (the robot stands still): the true attitude plus one
/// error per sweep. `lift_slide_m` is only recorded in the sweep: `world_from_sensor` already
/// includes the lift.
///
/// Draws from `rng`: the three attitude errors, then one seed per line; each line's range noise
/// comes from its own `ChaCha8Rng`, so the lines run in parallel and the result does not depend
/// on the number of threads.
///
/// An invalid `sensor` (see [`SensorConfig::validate`]) gives a sweep with no lines;
/// [`simulate_run`] reports it as an error instead.
pub fn scan(
    scene: &Scene,
    sensor: &SensorConfig,
    world_from_sensor: &Pose,
    lift_slide_m: f64,
    rng: &mut impl Rng,
) -> Sweep {
    let mut sweep = Sweep {
        pan_min_deg: sensor.pan_min_deg,
        pan_step_deg: sensor.pan_step_deg,
        lift_slide_m,
        lines: Vec::new(),
    };
    if sensor.validate().is_err() {
        return sweep;
    }
    let reading = attitude_reading(world_from_sensor, sensor, rng);
    let tilts = sensor.tilt_angles_deg();
    let seeds: Vec<u64> = tilts.iter().map(|_| rng.random()).collect();
    let pans: Vec<f64> = (0..sensor.pan_count())
        .map(|k| (sensor.pan_min_deg + k as f64 * sensor.pan_step_deg).to_radians())
        .collect();
    let origin = world_from_sensor.translation.vector;
    sweep.lines = tilts
        .par_iter()
        .zip(seeds.par_iter())
        .map(|(&tilt_deg, &seed)| {
            let mut line_rng = ChaCha8Rng::seed_from_u64(seed);
            let tilt = tilt_deg.to_radians();
            let ranges = pans
                .iter()
                .map(|&pan| {
                    let direction = world_from_sensor.rotation * beam_direction(tilt, pan);
                    let noise: f64 = line_rng.sample(StandardNormal);
                    let hit = scene.raycast(&origin, &direction, sensor.max_range_m);
                    measured(hit, noise * sensor.range_noise_m, sensor)
                })
                .collect();
            SweepLine {
                tilt_deg,
                attitude: reading,
                ranges,
            }
        })
        .collect();
    sweep
}

/// Simulates a whole run: at each stop the sensor pose
/// `world_from_body · sensor.lift.body_from_sensor(slide)` and its sweep ([`scan`]).
///
/// Stop `i` draws its noise from `ChaCha8Rng::seed_from_u64(seed)` on stream `i`, so the result
/// depends only on the seed, not on the thread count or on the other stops.
///
/// # Errors
/// [`Error::Invalid`] when `sensor` is invalid or a stop's slide is outside the lift's range.
///
/// [`Error::Invalid`]: sdem::error::Error::Invalid
pub fn simulate_run(
    scene: &Scene,
    stops: &[Stop],
    sensor: &SensorConfig,
    seed: u64,
) -> Result<Vec<SimStop>> {
    simulate_changing_run(stops, sensor, seed, |_| Cow::Borrowed(scene))
}

/// [`simulate_run`] in a scene that changes between stops (rubble moved, say): stop `i` is
/// scanned in `scene_at(i)`, with the same noise streams as [`simulate_run`], so where the
/// scenes do not differ the sweeps are the same.
///
/// # Errors
/// As [`simulate_run`].
pub fn simulate_changing_run<'a>(
    stops: &[Stop],
    sensor: &SensorConfig,
    seed: u64,
    scene_at: impl Fn(usize) -> Cow<'a, Scene> + Sync,
) -> Result<Vec<SimStop>> {
    sensor.validate()?;
    stops
        .par_iter()
        .enumerate()
        .map(|(index, stop)| {
            let world_from_sensor = stop.world_from_sensor(&sensor.lift)?;
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(index as u64);
            let sweep = scan(
                &scene_at(index),
                sensor,
                &world_from_sensor,
                stop.lift_slide_m,
                &mut rng,
            );
            Ok(SimStop {
                world_from_sensor,
                lift_slide_m: stop.lift_slide_m,
                sweep,
            })
        })
        .collect()
}
