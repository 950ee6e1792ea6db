//! A whole simulated run with faults injected at every stop.

use super::inject::{
    add_dust, add_walking_person, drop_returns, place_moved_rubble, place_person, returns_on,
    KEEP_CLEAR_M,
};
use super::{Fault, FaultConfig, Injected, FAULT_STREAM_SALT};
use crate::benchmark::symmetric;
use crate::sim::{self, wrap_angle, OrientedBox, Scene, Solid};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sdem::error::{Error, Result};
use sdem::geometry::{Attitude, Pose, Vec3};
use sdem::sensor::{SensorConfig, Sweep};
use std::borrow::Cow;

/// Why [`Fault::Tilt`] is not injected into a run, and what measures it instead (the words
/// [`simulate_run_with_faults`] and `sdem simulate --fault tilt` refuse it with).
pub const TILT_NOT_INJECTED: &str = "fault 'tilt' cannot be injected into a run: the route \
     decides how the robot stands; `sdem bench --faults --case tilt` measures stops tilted up to \
     30°";

/// Simulates a run like [`sim::simulate_run`] (same scene, stops, noise and seed) with `faults`
/// injected at every stop, for a dataset to map (`sdem simulate --fault ...`):
///
/// - [`Fault::Compass`]: each stop's heading reading is off by its own error within
///   ±[`FaultConfig::compass_error_max_deg`];
/// - [`Fault::GyroDrift`]: the roll and pitch readings carry a bias that drifts from stop to stop
///   (a random walk of 0.5° a stop, held within ±[`FaultConfig::gyro_error_max_deg`]);
/// - [`Fault::Dust`], [`Fault::Missing`], [`Fault::Person`]: in every sweep, as in
///   [`fault_pairs`];
/// - [`Fault::Rubble`]: for each stop after the first, one block in its view lies elsewhere in
///   the earlier sweeps (it was moved just before the stop); blocks keep clear of every stop.
///
/// Returns the stops and, per stop, what was injected.
///
/// # Errors
/// [`Error::Invalid`] for [`Fault::Tilt`] (the route decides how the robot stands; `sdem bench
/// --faults` measures steep tilt), an invalid `config` or `sensor`, or a person with no room.
///
/// [`fault_pairs`]: super::fault_pairs
pub fn simulate_run_with_faults(
    scene: &Scene,
    stops: &[sim::Stop],
    sensor: &SensorConfig,
    seed: u64,
    faults: &[Fault],
    config: &FaultConfig,
) -> Result<(Vec<sim::SimStop>, Vec<Injected>)> {
    config.validate()?;
    if faults.contains(&Fault::Tilt) {
        return Err(Error::Invalid(TILT_NOT_INJECTED.into()));
    }
    let draw = RunDraw {
        scene,
        sensor,
        seed,
        faults,
        config,
    };
    let poses = stops
        .iter()
        .map(|s| s.world_from_sensor(&sensor.lift))
        .collect::<Result<Vec<Pose>>>()?;
    // Block j (placed for stop j) lies at `before` in sweeps 0..j and at `after` from j on.
    let blocks = draw.route_rubble(&poses);
    let placed_at = |k: usize| {
        blocks
            .iter()
            .map(move |(j, before, after)| if *j <= k { after } else { before })
    };
    let mut run = if blocks.is_empty() {
        sim::simulate_run(scene, stops, sensor, seed)?
    } else {
        sim::simulate_changing_run(stops, sensor, seed, |k| {
            let mut here = scene.clone();
            for block in placed_at(k) {
                here.add_solid(Solid::Box(block.clone()));
            }
            Cow::Owned(here)
        })?
    };
    let mut injected = vec![Injected::default(); run.len()];
    if !blocks.is_empty() {
        for (k, stop) in run.iter().enumerate() {
            injected[k].rubble_returns = returns_on(&stop.sweep, &poses[k], placed_at(k));
        }
    }
    let mut bias = [0.0f64; 2];
    for (k, stop) in run.iter_mut().enumerate() {
        draw.inject_at_stop(k, &mut stop.sweep, &poses[k], &mut bias, &mut injected[k]);
    }
    Ok((run, injected))
}

/// What injecting faults into a run reads: the scene, the sensor, the seed, the faults and their
/// settings.
struct RunDraw<'a> {
    scene: &'a Scene,
    sensor: &'a SensorConfig,
    seed: u64,
    faults: &'a [Fault],
    config: &'a FaultConfig,
}

impl RunDraw<'_> {
    fn has(&self, f: Fault) -> bool {
        self.faults.contains(&f)
    }

    /// Stop `k`'s own random stream.
    fn stop_rng(&self, k: usize) -> ChaCha8Rng {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ FAULT_STREAM_SALT);
        rng.set_stream(k as u64);
        rng
    }

    /// With [`Fault::Rubble`], for each stop `j` after the first, a block in its view that lay
    /// elsewhere before it (`(j, before, after)`), kept clear of every stop's sensor and body;
    /// none for a stop where no such block turns up in 20 draws.
    fn route_rubble(&self, poses: &[Pose]) -> Vec<(usize, OrientedBox, OrientedBox)> {
        let mut blocks = Vec::new();
        if !self.has(Fault::Rubble) {
            return blocks;
        }
        let one = FaultConfig {
            rubble_pieces: 1,
            ..self.config.clone()
        };
        for j in 1..poses.len() {
            let mut rng = self.stop_rng(j);
            let previous = poses[j - 1].translation.vector;
            for _ in 0..20 {
                let Some(mut piece) =
                    place_moved_rubble(self.scene, &previous, &poses[j], &one, &mut rng)
                else {
                    break;
                };
                let (before, after) = piece.remove(0);
                let clear_of_route = poses.iter().all(|p| {
                    let o = p.translation.vector;
                    // The sensor and the robot's body below it.
                    [o, o - Vec3::new(0.0, 0.0, 0.3)].iter().all(|q| {
                        before.distance_to(q) > KEEP_CLEAR_M && after.distance_to(q) > KEEP_CLEAR_M
                    })
                });
                if clear_of_route {
                    blocks.push((j, before, after));
                    break;
                }
            }
        }
        blocks
    }

    /// Injects the faults into stop `k`'s `sweep` (taken at `pose`): a walking person, dust and
    /// lost returns, and the compass error and the gyro's drifting `bias` in its attitude
    /// readings; records them in `injected`.
    fn inject_at_stop(
        &self,
        k: usize,
        sweep: &mut Sweep,
        pose: &Pose,
        bias: &mut [f64; 2],
        injected: &mut Injected,
    ) {
        let (config, sensor) = (self.config, self.sensor);
        let mut rng = self.stop_rng(k);
        // A stream apart from the rubble's placement, which used stream k's start.
        rng.set_word_pos(1 << 40);
        if self.has(Fault::Person) {
            // Where nobody fits (a stop deep in the ditch), the sweep goes without.
            if let Some(person) = place_person(self.scene, pose, config.person_walk_m, &mut rng) {
                injected.person_returns =
                    add_walking_person(sweep, pose, &person, sensor, &mut rng);
            }
        }
        if self.has(Fault::Dust) {
            injected.dust_returns = add_dust(sweep, config.dust_fraction, sensor, &mut rng);
        }
        if self.has(Fault::Missing) {
            injected.lost_returns = drop_returns(
                sweep,
                config.missing_fraction,
                config.missing_run_max,
                &mut rng,
            );
        }
        if self.has(Fault::Compass) {
            injected.compass_error_deg = symmetric(&mut rng, config.compass_error_max_deg);
        }
        if self.has(Fault::GyroDrift) {
            let limit = config.gyro_error_max_deg;
            for b in bias.iter_mut() {
                let step: f64 = rng.sample(StandardNormal);
                *b = (*b + 0.5 * step).clamp(-limit, limit);
            }
            injected.gyro_error_deg = *bias;
        }
        for line in &mut sweep.lines {
            line.attitude = Attitude::new(
                line.attitude.roll + injected.gyro_error_deg[0].to_radians(),
                line.attitude.pitch + injected.gyro_error_deg[1].to_radians(),
                wrap_angle(line.attitude.yaw + injected.compass_error_deg.to_radians()),
            );
        }
    }
}
