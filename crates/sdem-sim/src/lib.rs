//! # sdem-sim — a seeded simulator for sdem
//!
//! Everything sdem is measured against: collapsed-building, hall and street scenes cast exactly,
//! the tilting laser range finder of Nagatani et al. (2003) and a spinning LiDAR with their
//! noise, drivable stop-and-go routes with true poses, simulated odometry, field faults (dust,
//! dropped returns, people walking by, moved rubble), the seeded benchmark pairs and the bench
//! suites' pairs (unlevelled, compass noise, spinning LiDAR), the paper's preparatory experiment
//! and synthetic pose graphs. Every random draw comes from a seeded `ChaCha8Rng`, so a seed gives
//! the same scene and sweeps on every machine and for any number of threads.
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
#![deny(missing_docs)]

pub mod benchmark;
pub mod experiment;
pub mod faults;
pub mod odometry;
pub mod pose_graphs;
pub mod reviews;
pub mod routes;
pub mod sim;
pub mod suites;
