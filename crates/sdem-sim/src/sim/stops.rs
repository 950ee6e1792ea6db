//! Stops of a stop-and-go run along the collapsed building's route: where the robot stands.

use super::route::{COLLAPSED_BUILDING_START_HEIGHT_M, MAX_STOPS};
use super::scene::Scene;
use super::{yaw_rotation, Frame2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sdem::error::{Error, Result};
use sdem::geometry::{pose_from_parts, Attitude, Pose, Vec3};
use sdem::sensor::LiftConfig;

/// Every stop's sensor origin is at least this far from any surface, metres.
pub const MIN_SENSOR_CLEARANCE_M: f64 = 0.15;
/// Longitudinal jitter of each stop along the route, metres (± this, uniform).
const STEP_JITTER_M: f64 = 0.015;

/// One stop of a stop-and-go run: where the robot's body stands and the lift's setting.
///
/// The body frame's origin is on the floor under the robot's centre, x forward, z up; the
/// sensor is at `world_from_body * lift.body_from_sensor(lift_slide_m)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stop {
    /// The body's pose.
    pub world_from_body: Pose,
    /// The lift's slide `u` at this stop, metres.
    pub lift_slide_m: f64,
}

impl Stop {
    /// The sensor's pose at this stop for the lift `lift`.
    ///
    /// # Errors
    /// [`Error::Invalid`] when the slide is outside the lift's range.
    pub fn world_from_sensor(&self, lift: &LiftConfig) -> Result<Pose> {
        Ok(self.world_from_body * lift.body_from_sensor(self.lift_slide_m)?)
    }
}

/// Half the distance between the crawler's front and rear contact points, metres.
const TRACK_HALF_LENGTH_M: f64 = 0.25;
/// Half the distance between its left and right tracks, metres.
const TRACK_HALF_GAUGE_M: f64 = 0.18;
/// Largest roll and pitch of the body, degrees.
const MAX_TILT_DEG: f64 = 4.0;
/// Standard deviation of the random part of roll and pitch, degrees.
const TILT_JITTER_DEG: f64 = 0.5;
/// Sample directions for the clearance check of each stop.
const CLEARANCE_DIRECTIONS: usize = 200;

/// Roll, pitch and height of a crawler standing at `body_xy` heading `yaw`: the plane through the
/// floor under its four contact points.
fn stance(scene: &Scene, body_xy: [f64; 2], yaw: f64) -> Result<(f64, f64, f64)> {
    let body = Frame2 {
        origin: body_xy,
        yaw,
    };
    let floor = |dx: f64, dy: f64| -> Result<f64> {
        let [x, y] = body.point(dx, dy);
        scene.floor_height(x, y).ok_or_else(|| {
            Error::Invalid(format!(
                "collapsed_building_stops: no floor under the robot at ({x:.2}, {y:.2})"
            ))
        })
    };
    let (l, g) = (TRACK_HALF_LENGTH_M, TRACK_HALF_GAUGE_M);
    let front_left = floor(l, g)?;
    let front_right = floor(l, -g)?;
    let rear_left = floor(-l, g)?;
    let rear_right = floor(-l, -g)?;
    let front_rise = 0.5 * (front_left + front_right - rear_left - rear_right);
    let left_rise = 0.5 * (front_left + rear_left - front_right - rear_right);
    // Positive pitch points x down; positive roll raises the left (+y) side.
    let pitch = -front_rise.atan2(2.0 * l);
    let roll = left_rise.atan2(2.0 * g);
    let z = 0.25 * (front_left + front_right + rear_left + rear_right);
    Ok((roll, pitch, z))
}

/// The slides for the high (room, void) and low (ditch) sensor.
pub(super) fn lift_settings(lift: &LiftConfig) -> Result<(f64, f64)> {
    lift.validate()?;
    let height = COLLAPSED_BUILDING_START_HEIGHT_M - lift.mount_in_body_m[2];
    let high = lift.slide_for_height(height).map_err(|e| {
        Error::Invalid(format!(
            "collapsed_building_stops: the lift cannot hold the sensor {COLLAPSED_BUILDING_START_HEIGHT_M} m \
             above the floor at the first stop ({e})"
        ))
    })?;
    let low = (lift.slide_max_m - 0.05 * (lift.slide_max_m - lift.slide_min_m)).max(high);
    Ok((high, low))
}

/// A stop-and-go path through [`collapsed_building`]`(…)`: from the room through the ditch into
/// the void, round a rubble pile and back to where the loop began.
///
/// # Arguments
/// - `scene`: a scene from [`collapsed_building`] (it carries the route).
/// - `seed`: seeds the stops' jitter along the route and the random part of their tilt.
/// - `count`: number of stops, 1 ..= [`MAX_STOPS`].
/// - `lift`: the lift; pass the same one to [`simulate_run`] (through its sensor).
///
/// # Returns
/// The stops, in order. Stop 0's sensor pose is exactly the identity (the world origin), with
/// the lift set so that the sensor stands 0.4 m above the flat room floor. Consecutive sensor
/// origins are 2πR/20 ≈ 0.35 m (± 3 cm) apart along the route, which turns with a radius
/// R = 1.1 m (≤ 19.6° of heading per stop). The lift is low (slide 5 % short of `slide_max_m`)
/// while the sensor is in the ditch and high (sensor 0.4 m up, near `slide_min_m`) in the room
/// and the void: it changes at two stops. The body stands on the floor under its four track
/// contacts (roll and pitch from their plane plus N(0, 0.5°), within ±4°). Stops 0–2 are in the
/// room, about 3–12 in the ditch, the rest in the void. The loop in the void starts at a stop
/// `i` (17 or 18, depending on the scene) and the stop `j = i + 20` is at the same place and
/// heading ([`Scene::loop_closure_stops`] gives both), so runs of `count` > `j` (38 or 39
/// stops) close the loop; a full turn at ≤ 20° per stop takes at least 18 stops, which is why
/// shorter runs cannot. Every sensor origin is checked to be free and at least
/// [`MIN_SENSOR_CLEARANCE_M`] from every surface.
///
/// # Errors
/// [`Error::Invalid`] when `count` is 0 or above [`MAX_STOPS`], when `scene` has no route (it
/// was not built by [`collapsed_building`]), when the lift cannot reach the start height, or
/// when a stop's sensor would come too close to a surface (a lift that does not fit the scene).
///
/// [`collapsed_building`]: super::collapsed_building
/// [`simulate_run`]: super::simulate_run
pub fn collapsed_building_stops(
    scene: &Scene,
    seed: u64,
    count: usize,
    lift: &LiftConfig,
) -> Result<Vec<Stop>> {
    if count == 0 || count > MAX_STOPS {
        return Err(Error::Invalid(format!(
            "collapsed_building_stops: count is {count}; the route holds 1 to {MAX_STOPS} stops"
        )));
    }
    let route = scene.route.as_ref().ok_or_else(|| {
        Error::Invalid(
            "collapsed_building_stops: the scene has no route; build it with sim::collapsed_building"
                .into(),
        )
    })?;
    let (high, low) = lift_settings(lift)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut stops = Vec::with_capacity(count);
    for index in 0..count {
        // Always three draws per stop, so the stream does not depend on the branches below.
        let jitter = rng.random_range(-STEP_JITTER_M..STEP_JITTER_M);
        let roll_noise: f64 = rng.sample(StandardNormal);
        let pitch_noise: f64 = rng.sample(StandardNormal);
        let exact = index == 0 || route.anchors.contains(&index);
        let s = index as f64 * route.spacing_m + if exact { 0.0 } else { jitter };
        let slide = if route.lift_is_low(s) { low } else { high };
        let stop = if index == 0 {
            first_stop(lift, slide)?
        } else {
            let noise = TILT_JITTER_DEG.to_radians();
            place_stop(
                scene,
                lift,
                route.at(s),
                slide,
                (roll_noise * noise, pitch_noise * noise),
            )?
        };
        check_clearance(scene, lift, &stop, index)?;
        stops.push(stop);
    }
    Ok(stops)
}

/// Stop 0: the sensor at the world origin, level, heading +x; the body on the flat floor below.
pub(super) fn first_stop(lift: &LiftConfig, slide: f64) -> Result<Stop> {
    Ok(Stop {
        world_from_body: lift.body_from_sensor(slide)?.inverse(),
        lift_slide_m: slide,
    })
}

/// A stop whose sensor origin is above `sensor_xy` heading `yaw`, the body standing on the floor.
pub(super) fn place_stop(
    scene: &Scene,
    lift: &LiftConfig,
    (sensor_xy, yaw): ([f64; 2], f64),
    slide: f64,
    (roll_noise, pitch_noise): (f64, f64),
) -> Result<Stop> {
    let sensor_in_body = lift.body_from_sensor(slide)?.translation.vector;
    let level_offset = yaw_rotation(yaw) * sensor_in_body;
    let guess = [sensor_xy[0] - level_offset.x, sensor_xy[1] - level_offset.y];
    let (roll, pitch, _) = stance(scene, guess, yaw)?;
    let max_tilt = MAX_TILT_DEG.to_radians();
    let attitude = Attitude::new(
        (roll + roll_noise).clamp(-max_tilt, max_tilt),
        (pitch + pitch_noise).clamp(-max_tilt, max_tilt),
        yaw,
    );
    // Put the body where the tilted sensor lands exactly above `sensor_xy`.
    let offset = attitude.rotation() * sensor_in_body;
    let body_xy = [sensor_xy[0] - offset.x, sensor_xy[1] - offset.y];
    let (_, _, z) = stance(scene, body_xy, yaw)?;
    Ok(Stop {
        world_from_body: pose_from_parts(Vec3::new(body_xy[0], body_xy[1], z), attitude),
        lift_slide_m: slide,
    })
}

pub(super) fn check_clearance(
    scene: &Scene,
    lift: &LiftConfig,
    stop: &Stop,
    index: usize,
) -> Result<()> {
    let sensor = stop.world_from_sensor(lift)?.translation.vector;
    let clearance = scene.clearance(&sensor, CLEARANCE_DIRECTIONS);
    if clearance < MIN_SENSOR_CLEARANCE_M {
        return Err(Error::Invalid(format!(
            "collapsed_building_stops: stop {index}'s sensor at ({:.2}, {:.2}, {:.2}) is only \
             {clearance:.3} m from a surface (need {MIN_SENSOR_CLEARANCE_M} m); this lift does not \
             fit the scene's route",
            sensor.x, sensor.y, sensor.z
        )));
    }
    Ok(())
}
