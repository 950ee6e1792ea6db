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
#![deny(missing_docs)]

pub mod bnb;
pub mod cost;
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
