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
//! The paper's preparatory experiment (Sec. V): a scan at the origin of a room and one after
//! moving (22, 36, 5) cm, both levelled by their gyro/compass readings (here simulated by
//! `sdem-sim`), localized by the exact search with the compass trusted.
//! ```
//! use sdem::localize::{localize, LocalizeConfig};
//! use sdem::search::HeadingWindow;
//! use sdem_sim::benchmark::{paper_pair, PAPER_MOVE_M};
//! let (reference, reference_attitude, query, query_attitude) = paper_pair()?;
//! let config = LocalizeConfig { heading: HeadingWindow::none(), ..Default::default() };
//! let found = localize(&reference, &reference_attitude, &query, &query_attitude, &config)?;
//! let moved = nalgebra::Vector3::from(PAPER_MOVE_M);
//! assert!((found.reference_from_query.translation.vector - moved).norm() < 0.005);
//! assert!(!found.diagnostics.ambiguous);
//! # Ok::<(), sdem::Error>(())
//! ```
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
