//! # sdem — Sphere-DEM localization and mapping for rescue robots
//!
//! An implementation and extension of Nagatani, Ishida, Yamanaka and Tanaka, "Three-dimensional
//! localization and mapping for mobile robot in disaster environments" (IROS 2003).
//!
//! A tilting 2D laser range finder sweeps a 3D scan at each stop. The scan, levelled by the
//! gyro/compass attitude, is stored as a [`sdem::Sdem`] (a grid of nearest ranges over azimuth and
//! elevation). A new scan is localized against a reference by re-projecting the reference's points
//! around candidate origins into *virtual S-DEMs* and picking the candidate whose virtual S-DEM
//! differs least from the new one ([`localize`]).
//!
//! Every module here holds algorithms over plain values: nothing reads or writes a file or prints.
//! File formats live in `sdem-io`, the simulator in `sdem-sim`, pictures in `sdem-viz` and the
//! `sdem` command in `sdem-cli`.
//!
//! # Example
//! Two scans of a box-shaped room, levelled by their gyro/compass readings, the second taken
//! 12 cm further along x and 5 cm to the left; the exact search finds the move. Scans of
//! simulated collapsed buildings, with truth, come from `sdem-sim`.
//! ```
//! use sdem::geometry::{Attitude, Vec3};
//! use sdem::localize::{localize, HeadingWindow, LocalizeOptions};
//! use sdem::sdem::{Sdem, SdemConfig};
//! // Points on the walls, floor and ceiling, in the sensor frame, metres.
//! let mut room = Vec::new();
//! for i in -40..=40 {
//!     for j in -40..=40 {
//!         let (u, v) = (i as f64 * 0.05, j as f64 * 0.05);
//!         for p in [[2.0, u, v], [-1.5, u, v], [u, 1.7, v], [u, -1.3, v], [u, v, 1.1], [u, v, -0.4]] {
//!             room.push(Vec3::new(p[0], p[1], p[2]));
//!         }
//!     }
//! }
//! let moved = Vec3::new(0.12, 0.05, 0.0);
//! let seen_after_moving: Vec<Vec3> = room.iter().map(|p| p - moved).collect();
//! let level = Attitude::default();
//! let grid = SdemConfig::default();
//! let reference = Sdem::from_points(&room, &level, &grid)?;
//! let query = Sdem::from_points(&seen_after_moving, &level, &grid)?;
//! let config = LocalizeOptions { heading: HeadingWindow::none(), ..Default::default() };
//! let found = localize(&reference, &query, &config)?;
//! assert!((found.reference_from_query.translation.vector - moved).norm() < 0.005);
//! # Ok::<(), sdem::Error>(())
//! ```
#![deny(missing_docs)]

pub mod bnb;
pub mod cost;
pub mod doubt;
pub mod error;
pub mod geometry;
pub mod localize;
pub mod map;
pub mod posegraph;
pub mod refine;
pub mod sdem;
pub mod search;
pub mod sensor;
pub mod slam;
pub mod voxel;

pub use error::{Error, Result};
