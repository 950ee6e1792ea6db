//! The experiments `sdem demo` runs: the paper's preparatory experiment (Sec. V) and a short
//! stop-and-go run through a simulated collapsed building. Pure: scenes and scans are simulated
//! in memory, results are returned as values.

use crate::sim;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sdem::error::Result;
use sdem::geometry::{pose_error, pose_from_parts, Attitude, Pose, Vec3};
use sdem::localize::{localize, HeadingWindow, Localization, LocalizeOptions, SearchWindow};
use sdem::sdem::{Sdem, SdemConfig};
use sdem::sensor::{SensorConfig, Sweep};
use std::time::Instant;

/// The settings of both experiments.
#[derive(Debug, Clone)]
pub struct ExperimentConfig {
    /// Seed of scenes, paths and noise.
    pub seed: u64,
    /// The simulated sensor.
    pub sensor: SensorConfig,
    /// The S-DEM grid.
    pub sdem: SdemConfig,
    /// The search (its window is replaced per experiment).
    pub localize: LocalizeOptions,
    /// Stops of the stop-and-go run.
    pub stops: usize,
    /// Standard deviation of the odometry's horizontal error per step, metres.
    pub odometry_noise_m: f64,
    /// Half-size of the window around the odometry prediction in the run, metres.
    pub run_window_half_m: [f64; 3],
}

impl Default for ExperimentConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            sensor: SensorConfig::default(),
            sdem: SdemConfig::default(),
            // The run searches heading ±2° around the compass (its noise is 1°); the paper's
            // experiment trusts the compass, as the paper did.
            localize: LocalizeOptions {
                heading: HeadingWindow {
                    half_range_deg: 2.0,
                    step_deg: None,
                },
                ..Default::default()
            },
            stops: 8,
            odometry_noise_m: 0.02,
            run_window_half_m: [0.15, 0.15, 0.08],
        }
    }
}

/// One localization with its truth.
#[derive(Debug, Clone)]
pub struct Trial {
    /// What was localized.
    pub case: String,
    /// True `reference_from_query`.
    pub truth: Pose,
    /// Estimated `reference_from_query`.
    pub estimate: Pose,
    /// Translation error, metres.
    pub error_m: f64,
    /// Rotation error, radians.
    pub error_rad: f64,
    /// The search's result.
    pub localization: Localization,
    /// Time to build both S-DEMs and search, milliseconds.
    pub time_ms: f64,
}

/// A scan ready to localize: its sweep, points in the sensor frame and the attitude reading.
struct SensedScan {
    points: Vec<Vec3>,
    attitude: Attitude,
}

fn sense(
    scene: &sim::Scene,
    sensor: &SensorConfig,
    world_from_sensor: &Pose,
    rng: &mut ChaCha8Rng,
) -> SensedScan {
    let sweep: Sweep = sim::scan(scene, sensor, world_from_sensor, 0.0, rng);
    SensedScan {
        points: sweep.points_in_sensor(),
        attitude: sweep.mean_attitude(),
    }
}

fn trial(
    case: &str,
    reference: &SensedScan,
    query: &SensedScan,
    truth: Pose,
    sdem: &SdemConfig,
    config: &LocalizeOptions,
) -> Result<Trial> {
    let start = Instant::now();
    let (r, q) = Sdem::pair_from_points(
        (&reference.points, &reference.attitude),
        (&query.points, &query.attitude),
        sdem,
    )?;
    let localization = localize(&r, &q, config)?;
    let time_ms = start.elapsed().as_secs_f64() * 1e3;
    let estimate = localization.reference_from_query;
    let (error_m, error_rad) = pose_error(&truth, &estimate);
    Ok(Trial {
        case: case.to_string(),
        truth,
        estimate,
        error_m,
        error_rad,
        localization,
        time_ms,
    })
}

/// The paper's preparatory experiment (Sec. V): a scan at the origin of an indoor room with a
/// flat floor and obstacles, a scan after moving (22, 36, 5) cm with the same pose, and one at the
/// same place with the body tilted 8° as if it stood on a rock. Each later scan is localized
/// against the first over the paper's window, trusting the compass as the paper did (the 6-DoF
/// refinement still corrects heading, roll and pitch by small amounts).
pub fn paper_experiment(config: &ExperimentConfig) -> Result<Vec<Trial>> {
    let scene = sim::paper_room();
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let origin = Pose::identity();
    let moved = pose_from_parts(Vec3::new(0.22, 0.36, 0.05), Attitude::default());
    let tilted = pose_from_parts(
        Vec3::new(0.22, 0.36, 0.05),
        Attitude::from_degrees(0.0, 8.0, 0.0),
    );
    let reference = sense(&scene, &config.sensor, &origin, &mut rng);
    let localize_config = LocalizeOptions {
        window: SearchWindow::paper(),
        heading: HeadingWindow::none(),
        ..config.localize.clone()
    };
    let mut trials = Vec::new();
    for (case, pose) in [
        ("moved (22, 36, 5) cm", moved),
        ("moved and tilted 8°", tilted),
    ] {
        let query = sense(&scene, &config.sensor, &pose, &mut rng);
        trials.push(trial(
            case,
            &reference,
            &query,
            origin.inverse() * pose,
            &config.sdem,
            &localize_config,
        )?);
    }
    Ok(trials)
}

/// One stop of the stop-and-go run.
#[derive(Debug, Clone)]
pub struct RunStop {
    /// True `world_from_sensor`.
    pub truth: Pose,
    /// Estimated `world_from_sensor` (position chained from the localizations, attitude from the
    /// gyro/compass reading).
    pub estimate: Pose,
    /// The localization against the previous stop (`None` for the first stop).
    pub step: Option<Trial>,
    /// Distance between the estimated and the true sensor origin, metres.
    pub position_error_m: f64,
    /// The scan, sensor frame.
    pub points: Vec<Vec3>,
}

/// A short stop-and-go run through the ditch into the void: each scan is localized against the
/// previous one, in a window around the odometry's prediction, and the poses are chained.
pub fn stop_and_go_run(config: &ExperimentConfig) -> Result<Vec<RunStop>> {
    let scene = sim::collapsed_building(config.seed);
    let path =
        sim::collapsed_building_stops(&scene, config.seed, config.stops, &config.sensor.lift)?;
    let run = sim::simulate_run(&scene, &path, &config.sensor, config.seed)?;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ 0x0d0_3e7e);
    let odometry_noise = Normal::new(0.0, config.odometry_noise_m.max(0.0)).map_err(|e| {
        sdem::Error::Invalid(format!("odometry noise {}: {e}", config.odometry_noise_m))
    })?;
    let mut stops: Vec<RunStop> = Vec::with_capacity(run.len());
    let mut previous: Option<SensedScan> = None;
    for (i, sim_stop) in run.iter().enumerate() {
        let scan = SensedScan {
            points: sim_stop.sweep.points_in_sensor(),
            attitude: sim_stop.sweep.mean_attitude(),
        };
        let truth = sim_stop.world_from_sensor;
        let (estimate, step) = match (&previous, stops.last()) {
            (Some(prev_scan), Some(prev_stop)) => {
                // Odometry: the true motion of the sensor origin plus noise (the crawler's tracks
                // slip on rubble; the lift's encoder is exact).
                let true_step = truth.translation.vector - prev_stop.truth.translation.vector;
                let predicted = true_step
                    + Vec3::new(
                        odometry_noise.sample(&mut rng),
                        odometry_noise.sample(&mut rng),
                        0.25 * odometry_noise.sample(&mut rng),
                    );
                let localize_config = LocalizeOptions {
                    window: SearchWindow::around(&predicted, config.run_window_half_m),
                    ..config.localize.clone()
                };
                let step_truth = prev_stop.truth.inverse() * truth;
                let t = trial(
                    &format!("stop {i} against stop {}", i - 1),
                    prev_scan,
                    &scan,
                    step_truth,
                    &config.sdem,
                    &localize_config,
                )?;
                let position = prev_stop.estimate.translation.vector + t.localization.offset;
                (pose_from_parts(position, scan.attitude), Some(t))
            }
            _ => (
                pose_from_parts(truth.translation.vector, scan.attitude),
                None,
            ),
        };
        let position_error_m = (estimate.translation.vector - truth.translation.vector).norm();
        previous = Some(SensedScan {
            points: scan.points.clone(),
            attitude: scan.attitude,
        });
        stops.push(RunStop {
            truth,
            estimate,
            step,
            position_error_m,
            points: scan.points,
        });
    }
    Ok(stops)
}
