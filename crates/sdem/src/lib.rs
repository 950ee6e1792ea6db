//! # sdem — Sphere-DEM localization and mapping for rescue robots
//!
//! An implementation and extension of Nagatani, Ishida, Yamanaka and Tanaka, "Three-dimensional
//! localization and mapping for mobile robot in disaster environments" (IROS 2003).
//!
//! A stop-and-go robot sweeps a 3D scan at each stop and reads its attitude from a gyro with a
//! compass, when it has one. A [`Scan`] holds the points (sensor frame, metres) with that
//! reading, levelled into an S-DEM (a grid of nearest ranges over azimuth and elevation,
//! [`sdem::Sdem`]). [`localize()`] finds where one scan was taken relative to another: an exact
//! search of the paper's correlation (eq. 1) over a window of positions and headings, refined in
//! 6-DoF, with a [`Localization`] that says how far to trust it. [`Slam`] adds scans one stop at a
//! time into a map of S-DEMs with loop closure, a pose graph and a fused voxel map.
//!
//! Every module here holds algorithms over plain values: nothing reads or writes a file or prints.
//! File formats live in `sdem-io`, the simulator in `sdem-sim`, pictures in `sdem-viz` and the
//! `sdem` command in `sdem-cli`. Poses are `nalgebra::Isometry3<f64>` named for their frames
//! (`reference_from_query`, `world_from_sensor`); angles are radians, except in names that say
//! `_deg` and in [`Attitude::from_degrees`].
//!
//! # Example
//! A room with a pillar, scanned twice: the second scan 12 cm further along x and 5 cm to the
//! left, turned 20°, by a robot with no gyro (its attitude is unknown, so the heading is searched
//! over a full turn).
//! ```
//! use nalgebra::{Isometry3, Point3, Vector3};
//! use sdem::{Attitude, LocalizeOptions, Scan};
//! # let (r0, p0, y0) = (0.0, 0.0, 0.0);
//! let points0 = room_with_pillar(); // sensor frame, metres
//! let truth = Isometry3::new(Vector3::new(0.12, 0.05, 0.0), Vector3::z() * 20f64.to_radians());
//! let points1: Vec<Point3<f64>> = points0.iter().map(|p| truth.inverse() * p).collect();
//!
//! let reference = Scan::from_points(&points0, Some(Attitude::from_degrees(r0, p0, y0)))?;
//! let query = Scan::from_points(&points1, None)?; // no gyro: attitude unknown
//! let found = sdem::localize(&reference, &query, &LocalizeOptions::default())?;
//! let reference_from_query: Isometry3<f64> = found.reference_from_query;
//! if !found.trusted {
//!     eprintln!("doubts: {:?}", found.doubts);
//! }
//! assert!(found.trusted);
//! assert!((reference_from_query.translation.vector - truth.translation.vector).norm() < 0.005);
//! assert!(reference_from_query.rotation.angle_to(&truth.rotation).to_degrees() < 0.1);
//!
//! /// Points on the walls, floor and ceiling of a 3.5 × 3 × 1.5 m room with a 0.3 m pillar.
//! fn room_with_pillar() -> Vec<Point3<f64>> {
//!     let mut points = Vec::new();
//!     for i in -40..=40 {
//!         for j in -40..=40 {
//!             let (u, v) = (i as f64 * 0.05, j as f64 * 0.05);
//!             for p in [[2.0, u, v], [-1.5, u, v], [u, 1.7, v], [u, -1.3, v], [u, v, 1.1], [u, v, -0.4]] {
//!                 points.push(Point3::new(p[0], p[1], p[2]));
//!             }
//!             let (s, h) = (i as f64 * 0.15 / 40.0, j as f64 * 0.75 / 40.0 + 0.35);
//!             for p in [[0.85, 0.8 + s], [1.15, 0.8 + s], [1.0 + s, 0.65], [1.0 + s, 0.95]] {
//!                 points.push(Point3::new(p[0], p[1], h));
//!             }
//!         }
//!     }
//!     points
//! }
//! # Ok::<(), sdem::Error>(())
//! ```
#![deny(missing_docs)]

pub mod bnb;
pub mod cost;
pub mod doubt;
pub mod error;
pub mod free_space;
pub mod geometry;
pub mod global;
pub mod index;
pub mod level;
pub mod localize;
pub mod map;
pub mod posegraph;
pub mod refine;
pub mod scan;
pub mod sdem;
pub mod search;
pub mod sensor;
pub mod slam;
pub mod store;
#[cfg(test)]
mod test_scenes;
pub mod voxel;

pub use doubt::Doubt;
pub use error::{Error, Result};
pub use geometry::{Attitude, AttitudeSigma, Pose};
pub use localize::{HeadingWindow, Localization, LocalizeOptions, SearchMode, SearchWindow};
pub use scan::{cost_at, localize, Scan};
pub use sdem::SdemConfig;
pub use sensor::SensorConfig;
pub use slam::{Odometry, Slam, SlamOptions, Step, StepStatus};
