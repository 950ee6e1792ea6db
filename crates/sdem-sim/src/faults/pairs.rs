//! Seeded pairs of scans with faults, and how sdem localizes them.

use super::inject::{
    add_dust, add_walking_person, drop_returns, place_moved_rubble, place_person, returns_on,
};
use super::{Fault, FaultConfig, Injected, FAULT_STREAM_SALT};
use crate::benchmark::{
    draw_query_pose, localize_pair, random_unit, symmetric, BenchPair, PairResult,
};
use crate::sim::{self, wrap_angle, OrientedBox, Scene, Solid};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use sdem::error::{Error, Result};
use sdem::geometry::{Attitude, Pose, Vec3};
use sdem::localize::{CostConfig, HeadingWindow, LocalizeOptions, OffsetPrior, SearchWindow};
use sdem::sdem::SdemConfig;
use sdem::sensor::Sweep;

/// A pair with faults, the robot's prior, and what was injected.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultPair {
    /// The scans, readings and truth (the readings carry the faults).
    pub pair: BenchPair,
    /// The faults in this pair.
    pub faults: Vec<Fault>,
    /// The prior for the offset that [`sdem::localize::localize`] estimates (query origin minus
    /// reference origin, world axes, metres): the truth with the odometry error.
    pub predicted_offset: Vec3,
    /// What was injected.
    pub injected: Injected,
}

/// Draws `count` seeded pairs in [`sim::collapsed_building`]`(seed)` with `faults` injected.
///
/// Pair `i` comes from its own random stream, so the result depends on the seed only, not on
/// the thread count; with no faults the pairs are clean ones drawn the same way.
///
/// # Errors
/// [`Error::Invalid`] for an invalid `config`, or when no pose, person or rubble place with enough
/// clearance turns up after many draws.
pub fn fault_pairs(
    seed: u64,
    count: usize,
    faults: &[Fault],
    config: &FaultConfig,
) -> Result<Vec<FaultPair>> {
    config.validate()?;
    let scene = sim::collapsed_building(seed);
    let stops =
        sim::collapsed_building_stops(&scene, seed, sim::MAX_STOPS, &config.pairs.sensor.lift)?;
    (0..count)
        .into_par_iter()
        .map(|index| draw_indexed_pair(&scene, &stops, seed, faults, config, index))
        .collect()
}

/// Pair `index` of [`fault_pairs`]`(seed, …)` alone (the same pair, without drawing the others).
///
/// # Errors
/// As [`fault_pairs`].
pub fn fault_pair(
    seed: u64,
    index: usize,
    faults: &[Fault],
    config: &FaultConfig,
) -> Result<FaultPair> {
    config.validate()?;
    let scene = sim::collapsed_building(seed);
    let stops =
        sim::collapsed_building_stops(&scene, seed, sim::MAX_STOPS, &config.pairs.sensor.lift)?;
    draw_indexed_pair(&scene, &stops, seed, faults, config, index)
}

fn draw_indexed_pair(
    scene: &Scene,
    stops: &[sim::Stop],
    seed: u64,
    faults: &[Fault],
    config: &FaultConfig,
    index: usize,
) -> Result<FaultPair> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ FAULT_STREAM_SALT);
    rng.set_stream(index as u64);
    draw_fault_pair(scene, stops, faults, config, index, &mut rng)
}

fn draw_fault_pair(
    scene: &Scene,
    stops: &[sim::Stop],
    faults: &[Fault],
    config: &FaultConfig,
    index: usize,
    rng: &mut ChaCha8Rng,
) -> Result<FaultPair> {
    let draw = PairDraw {
        scene,
        faults,
        config,
        index,
    };
    let sensor = &config.pairs.sensor;
    let reference_stop = rng.random_range(0..stops.len());
    let stop = &stops[reference_stop];
    let world_from_reference = stop.world_from_sensor(&sensor.lift)?;
    let world_from_query = draw.query_pose(&world_from_reference, reference_stop, rng)?;
    let mut injected = Injected::default();
    let (reference_scene, query_scene, moved) =
        draw.scenes_with_rubble(&world_from_reference, &world_from_query, rng)?;
    let mut reference = sim::scan(
        &reference_scene,
        sensor,
        &world_from_reference,
        stop.lift_slide_m,
        rng,
    );
    let mut query = sim::scan(
        &query_scene,
        sensor,
        &world_from_query,
        stop.lift_slide_m,
        rng,
    );
    if draw.has(Fault::Rubble) {
        injected.rubble_returns =
            returns_on(
                &reference,
                &world_from_reference,
                moved.iter().map(|m| &m.0),
            ) + returns_on(&query, &world_from_query, moved.iter().map(|m| &m.1));
    }
    draw.corrupt_returns(
        &mut reference,
        &mut query,
        &world_from_query,
        &mut injected,
        rng,
    )?;
    let reading = query.mean_attitude();
    let query_attitude = draw.misread_attitude(reading, &mut injected, rng);
    let pair = BenchPair {
        reference_points: reference.points_in_sensor(),
        reference_attitude: reference.mean_attitude(),
        query_points: query.points_in_sensor(),
        query_attitude,
        truth: world_from_reference.inverse() * world_from_query,
        compass_error_deg: injected.compass_error_deg,
        world_from_reference,
        world_from_query,
        reference_stop,
    };
    let offset = pair.true_offset();
    let predicted_offset =
        offset + random_unit(rng).into_inner() * (config.odometry_error_fraction * offset.norm());
    Ok(FaultPair {
        pair,
        faults: faults.to_vec(),
        predicted_offset,
        injected,
    })
}

/// The pieces of rubble moved between the scans: each where the reference saw it, then where
/// the query sees it.
type MovedRubble = Vec<(OrientedBox, OrientedBox)>;

/// What drawing fault pair `index` reads: the scene, the faults to inject and their settings.
struct PairDraw<'a> {
    scene: &'a Scene,
    faults: &'a [Fault],
    config: &'a FaultConfig,
    index: usize,
}

impl PairDraw<'_> {
    fn has(&self, f: Fault) -> bool {
        self.faults.contains(&f)
    }

    /// The query's pose near the reference stop (tilted further with [`Fault::Tilt`]).
    fn query_pose(
        &self,
        world_from_reference: &Pose,
        reference_stop: usize,
        rng: &mut ChaCha8Rng,
    ) -> Result<Pose> {
        let mut pose_config = self.config.pairs.clone();
        if self.has(Fault::Tilt) {
            pose_config.tilt_max_deg = self.config.tilt_max_deg;
        }
        draw_query_pose(self.scene, world_from_reference, &pose_config, rng).ok_or_else(|| {
            Error::Invalid(format!(
                "fault pair {}: no query origin near stop {reference_stop} has enough clearance",
                self.index
            ))
        })
    }

    /// The scenes the two scans see: with [`Fault::Rubble`], pieces of rubble placed near the
    /// query where the reference saw them and moved before the query; with each moved piece's
    /// place before and after.
    fn scenes_with_rubble(
        &self,
        world_from_reference: &Pose,
        world_from_query: &Pose,
        rng: &mut ChaCha8Rng,
    ) -> Result<(Scene, Scene, MovedRubble)> {
        let (mut reference_scene, mut query_scene) = (self.scene.clone(), self.scene.clone());
        let mut moved = Vec::new();
        if self.has(Fault::Rubble) {
            moved = place_moved_rubble(
                self.scene,
                &world_from_reference.translation.vector,
                world_from_query,
                self.config,
                rng,
            )
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "fault pair {}: no room for {} pieces of rubble near the query",
                    self.index, self.config.rubble_pieces
                ))
            })?;
            for (before, after) in &moved {
                reference_scene.add_solid(Solid::Box(before.clone()));
                query_scene.add_solid(Solid::Box(after.clone()));
            }
        }
        Ok((reference_scene, query_scene, moved))
    }

    /// Injects the faults that change returns: a walking person in the query, dust and lost
    /// returns in both scans; counts them in `injected`.
    fn corrupt_returns(
        &self,
        reference: &mut Sweep,
        query: &mut Sweep,
        world_from_query: &Pose,
        injected: &mut Injected,
        rng: &mut ChaCha8Rng,
    ) -> Result<()> {
        let (config, sensor) = (self.config, &self.config.pairs.sensor);
        if self.has(Fault::Person) {
            let person = place_person(self.scene, world_from_query, config.person_walk_m, rng)
                .ok_or_else(|| {
                    Error::Invalid(format!(
                        "fault pair {}: no room for a walking person near the query",
                        self.index
                    ))
                })?;
            injected.person_returns =
                add_walking_person(query, world_from_query, &person, sensor, rng);
        }
        if self.has(Fault::Dust) {
            injected.dust_returns = add_dust(reference, config.dust_fraction, sensor, rng)
                + add_dust(query, config.dust_fraction, sensor, rng);
        }
        if self.has(Fault::Missing) {
            injected.lost_returns =
                drop_returns(
                    reference,
                    config.missing_fraction,
                    config.missing_run_max,
                    rng,
                ) + drop_returns(query, config.missing_fraction, config.missing_run_max, rng);
        }
        Ok(())
    }

    /// The query's attitude reading: its true mean `reading` with the compass and gyro errors
    /// of [`Fault::Compass`] and [`Fault::GyroDrift`], recorded in `injected`.
    fn misread_attitude(
        &self,
        reading: Attitude,
        injected: &mut Injected,
        rng: &mut ChaCha8Rng,
    ) -> Attitude {
        let config = self.config;
        if self.has(Fault::Compass) {
            injected.compass_error_deg = symmetric(rng, config.compass_error_max_deg);
        }
        if self.has(Fault::GyroDrift) {
            injected.gyro_error_deg = [
                symmetric(rng, config.gyro_error_max_deg),
                symmetric(rng, config.gyro_error_max_deg),
            ];
        }
        Attitude::new(
            reading.roll + injected.gyro_error_deg[0].to_radians(),
            reading.pitch + injected.gyro_error_deg[1].to_radians(),
            wrap_angle(reading.yaw + injected.compass_error_deg.to_radians()),
        )
    }
}

/// The prediction's standard deviation is the odometry's error fraction of the predicted motion,
/// but never below this, metres.
pub const MIN_PRIOR_SIGMA_M: f64 = 0.01;

/// How sdem localizes a fault pair: a window of [`FaultConfig::window_half_m`] around the
/// prior, weighed in the cost with a standard deviation of
/// [`FaultConfig::odometry_error_fraction`] of the predicted motion ([`OffsetPrior`]), headings
/// within [`FaultConfig::heading_half_range_deg`] of the compass, the grid step
/// [`FaultConfig::step_m`], refinement on, no runner-up search (as `sdem slam` runs).
pub fn localize_config(config: &FaultConfig, pair: &FaultPair) -> LocalizeOptions {
    LocalizeOptions {
        window: SearchWindow::around(&pair.predicted_offset, config.window_half_m),
        step_m: config.step_m,
        heading: HeadingWindow {
            half_range_deg: config.heading_half_range_deg,
            step_deg: None,
        },
        runner_up: false,
        cost: CostConfig {
            prior: Some(OffsetPrior {
                offset: pair.predicted_offset.into(),
                sigma_m: (config.odometry_error_fraction * pair.predicted_offset.norm())
                    .max(MIN_PRIOR_SIGMA_M),
            }),
            ..Default::default()
        },
        ..Default::default()
    }
}

/// Localizes `pair` with [`localize_config`] and scores it against the truth.
///
/// # Errors
/// Whatever [`localize_pair`] reports.
pub fn localize_fault_pair(
    pair: &FaultPair,
    sdem: &SdemConfig,
    config: &FaultConfig,
) -> Result<PairResult> {
    localize_pair(&pair.pair, sdem, &localize_config(config, pair))
}
