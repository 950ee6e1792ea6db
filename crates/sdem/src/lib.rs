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
//! The modules hold pure algorithms over plain values, except [`io`], which reads and writes files.
#![deny(missing_docs)]

pub mod benchmark;
pub mod bnb;
pub mod cost;
pub mod error;
pub mod experiment;
pub mod faults;
pub mod geometry;
pub mod io;
pub mod localize;
pub mod map;
pub mod odometry;
pub mod posegraph;
pub mod refine;
pub mod sdem;
pub mod search;
pub mod sensor;
pub mod sim;
pub mod slam;
pub mod viz;
pub mod voxel;

pub use error::{Error, Result};
