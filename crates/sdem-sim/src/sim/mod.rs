//! Scenes and a seeded simulator of the tilting-LRF sensor (Nagatani 2003, Sec. IV–V).
//!
//! A [`Scene`] is the union of *free-space* boxes (the air the robot moves in: rooms, a ditch, a
//! void) minus *solid* obstacles inside that air (rubble blocks, slabs, columns, rocks). Rays are
//! cast against it exactly ([`Scene::raycast`]).
//!
//! Scenes: [`paper_room`] (the preparatory experiment of Sec. V), [`corridor`] (long and
//! featureless, for ambiguity tests), [`collapsed_building`] (a room, a narrow ditch and a wider
//! void, with a drivable stop-and-go route: [`collapsed_building_stops`]), and the open scenes
//! [`open_hall`] and [`street`]. [`scan`] simulates one raw sweep of the tilting LRF and
//! [`simulate_run`] a whole run; [`spin_scan`] one turn of a spinning multi-beam LiDAR.
//!
//! World frame (DESIGN.md): the paper's room, the corridor and the collapsed building are built
//! so that the world origin is the first scan's sensor origin. The first sensor pose of
//! [`collapsed_building_stops`] is exactly the identity, with the floor flat at
//! `z = -COLLAPSED_BUILDING_START_HEIGHT_M` beneath it. The open scenes have their floor at
//! `z = 0` and say where a sensor may stand ([`open_hall_sensor_region`],
//! [`street_sensor_region`]).
//!
//! Everything random comes from `ChaCha8Rng` (a fixed algorithm), so a seed gives the same scene,
//! path and sweeps on every machine and for any number of threads.
//!
//! # Example
//! ```
//! use sdem::sensor::SensorConfig;
//! use sdem_sim::sim;
//! let scene = sim::collapsed_building(7);
//! let sensor = SensorConfig::default();
//! let stops = sim::collapsed_building_stops(&scene, 7, 2, &sensor.lift)?;
//! let run = sim::simulate_run(&scene, &stops, &sensor, 7)?;
//! assert_eq!(run.len(), 2);
//! assert_eq!(run[0].world_from_sensor, sdem::geometry::Pose::identity());
//! # Ok::<(), sdem::Error>(())
//! ```

mod building;
mod fixed_scenes;
mod lidar;
pub mod lidar_street;
mod long_routes;
mod open_scenes;
mod plan;
mod route;
mod scanner;
mod scene;
mod solids;
mod stops;
#[cfg(test)]
mod tests;

pub use building::collapsed_building;
pub use fixed_scenes::{
    corridor, paper_room, CORRIDOR_SENSOR_HEIGHT_M, PAPER_ROOM_SENSOR_HEIGHT_M,
};
pub use lidar::{lidar_beam, spin_scan, LidarConfig};
pub use lidar_street::{spinning_scan, SpinningLidar, STREET_SENSOR_HEIGHT_M};
pub use long_routes::{long_run, LongRoute, LongRun, MAX_LONG_STOPS};
pub use open_scenes::{open_hall, open_hall_sensor_region, street, street_sensor_region};
pub use route::{COLLAPSED_BUILDING_START_HEIGHT_M, MAX_STOPS};
pub use scanner::{scan, simulate_changing_run, simulate_run, SimStop};
pub use scene::{Scene, MIN_STANDING_GAP_M};
pub use solids::{Ellipsoid, OrientedBox, Solid};
pub use stops::{collapsed_building_stops, Stop, MIN_SENSOR_CLEARANCE_M};

use nalgebra::{Rotation3, Vector3};
use sdem::geometry::Vec3;
use std::f64::consts::{PI, TAU};

/// Tolerance (metres) for points on a shared face and for ray intervals that touch.
const EPS: f64 = 1e-9;

/// The angle in [-π, π).
pub(crate) fn wrap_angle(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

fn yaw_rotation(yaw: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
}

/// A box from literal corners (internal scenes only).
fn aabb(min: [f64; 3], max: [f64; 3]) -> OrientedBox {
    let (min, max) = (Vec3::from(min), Vec3::from(max));
    OrientedBox::build((min + max) * 0.5, (max - min) * 0.5, Rotation3::identity())
}

/// A box turned about z (internal scenes only).
fn yawed_box(center: [f64; 3], half: [f64; 3], yaw_deg: f64) -> OrientedBox {
    OrientedBox::build(
        Vec3::from(center),
        Vec3::from(half),
        yaw_rotation(yaw_deg.to_radians()),
    )
}

/// A 2D frame on the floor plan: origin and heading.
#[derive(Debug, Clone, Copy)]
struct Frame2 {
    origin: [f64; 2],
    yaw: f64,
}

impl Frame2 {
    /// The plan position of the point at `x` ahead and `y` left of the frame's origin.
    fn point(&self, x: f64, y: f64) -> [f64; 2] {
        let (s, c) = self.yaw.sin_cos();
        [
            self.origin[0] + c * x - s * y,
            self.origin[1] + s * x + c * y,
        ]
    }
}
