//! Stops anywhere along the collapsed building's route, facing either way: what the routes of
//! [`crate::routes`] are made of (long steps, turn-arounds, revisits, a second run).

use super::route::MAX_STOPS;
use super::scene::Scene;
use super::stops::{check_clearance, first_stop, lift_settings, place_stop, TILT_JITTER_DEG};
use super::{wrap_angle, Stop};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use sdem::error::{Error, Result};
use sdem::sensor::LiftConfig;

/// Where a robot stops on the route: how far along it, and which way it faces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    /// Arc length along the route's centre line from the first stop, metres.
    pub along_m: f64,
    /// The robot's heading minus the route's heading there, radians: 0 faces along the route,
    /// π back the way it came.
    pub heading_offset: f64,
}

impl Waypoint {
    /// A stop facing along the route.
    pub fn forward(along_m: f64) -> Self {
        Self {
            along_m,
            heading_offset: 0.0,
        }
    }

    /// A stop facing back along the route.
    pub fn backward(along_m: f64) -> Self {
        Self {
            along_m,
            heading_offset: std::f64::consts::PI,
        }
    }
}

/// The drivable length of a [`super::collapsed_building`]'s route, metres (the route that
/// [`super::collapsed_building_stops`] places its [`MAX_STOPS`] stops on); `None` for a scene
/// without a route.
pub fn route_length_m(scene: &Scene) -> Option<f64> {
    let route = scene.route.as_ref()?;
    Some((MAX_STOPS - 1) as f64 * route.spacing_m)
}

/// The route's centre line at `along_m`: the sensor's plan position (x, y) and the route's
/// heading there, radians; `None` for a scene without a route.
pub fn route_at(scene: &Scene, along_m: f64) -> Option<([f64; 2], f64)> {
    Some(scene.route.as_ref()?.at(along_m))
}

/// Stops at `waypoints` along the route of a [`super::collapsed_building`]: the sensor above
/// the route's centre line, the body standing on the floor under its tracks (roll and pitch
/// from the floor plus N(0, 0.5°), as [`super::collapsed_building_stops`]), the lift low in the
/// ditch and high elsewhere. A first waypoint at the route's start facing along it is stop 0
/// of [`super::collapsed_building_stops`] (the sensor exactly at the world origin).
///
/// # Errors
/// [`Error::Invalid`] for a scene without a route, a waypoint off the route (before its start
/// or past [`route_length_m`]) or not finite, or a stop where the robot does not fit (no floor
/// under a track, or the sensor closer than [`super::MIN_SENSOR_CLEARANCE_M`] to a surface).
pub fn waypoint_stops(
    scene: &Scene,
    seed: u64,
    waypoints: &[Waypoint],
    lift: &LiftConfig,
) -> Result<Vec<Stop>> {
    let route = scene.route.as_ref().ok_or_else(|| {
        Error::Invalid(
            "waypoint_stops: the scene has no route; build it with sim::collapsed_building".into(),
        )
    })?;
    let length = (MAX_STOPS - 1) as f64 * route.spacing_m;
    let (high, low) = lift_settings(lift)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = TILT_JITTER_DEG.to_radians();
    let mut stops = Vec::with_capacity(waypoints.len());
    for (index, w) in waypoints.iter().enumerate() {
        // Two draws per stop, whatever the branch below.
        let roll_noise: f64 = StandardNormal.sample(&mut rng);
        let pitch_noise: f64 = StandardNormal.sample(&mut rng);
        let inside = w.along_m.is_finite()
            && w.heading_offset.is_finite()
            && (0.0..=length).contains(&w.along_m);
        if !inside {
            return Err(Error::Invalid(format!(
                "waypoint_stops: waypoint {index} lies {} m along a route of {length:.2} m",
                w.along_m
            )));
        }
        let slide = if route.lift_is_low(w.along_m) {
            low
        } else {
            high
        };
        let stop = if w.along_m == 0.0 && wrap_angle(w.heading_offset) == 0.0 {
            first_stop(lift, slide)?
        } else {
            let (xy, yaw) = route.at(w.along_m);
            place_stop(
                scene,
                lift,
                (xy, wrap_angle(yaw + w.heading_offset)),
                slide,
                (roll_noise * noise, pitch_noise * noise),
            )?
        };
        check_clearance(scene, lift, &stop, index)?;
        stops.push(stop);
    }
    Ok(stops)
}
