//! Uses sdem through its crate root only, as the README shows: two scans localized (with a gyro
//! reading, and without one), then an incremental map over a run with odometry, saved with
//! `sdem_io` and a scan relocalized in it. Exits non-zero when a result is off the truth.

use nalgebra::Isometry3;
use sdem::{Attitude, LocalizeOptions, Scan, SensorConfig, Slam, SlamOptions, StepStatus};
use sdem_sim::odometry::{simulate_odometry, OdometryNoise};
use sdem_sim::sim;
use std::process::ExitCode;

/// Stops of the simulated run, and its seed.
const STOPS: usize = 12;
const SEED: u64 = 5;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("library-user: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    // A simulated run through a collapsed building, with the true pose of every stop.
    let scene = sim::collapsed_building(SEED);
    let sensor = SensorConfig::default();
    let stops = sim::collapsed_building_stops(&scene, SEED, STOPS, &sensor.lift)?;
    let run = sim::simulate_run(&scene, &stops, &sensor, SEED)?;
    // The returns as nalgebra vectors; `Point3`s or `[f32; 3]` arrays would do as well.
    let points = |k: usize| run[k].sweep.points_in_sensor();
    let reading = |k: usize| -> Attitude { run[k].sweep.mean_attitude() };

    // 1. One scan against another: with both gyro readings, then with none for the query.
    let (points0, points1) = (points(0), points(1));
    let truth = run[0].world_from_sensor.inverse() * run[1].world_from_sensor;
    let reference = Scan::from_points(&points0, Some(reading(0)))?;
    for query_attitude in [Some(reading(1)), None] {
        let query = Scan::from_points(&points1, query_attitude)?;
        let found = sdem::localize(&reference, &query, &LocalizeOptions::default())?;
        let reference_from_query: Isometry3<f64> = found.reference_from_query;
        let error_m = (reference_from_query.translation.vector - truth.translation.vector).norm();
        let error_deg = reference_from_query
            .rotation
            .angle_to(&truth.rotation)
            .to_degrees();
        println!(
            "localize, query attitude {}: error {:.2} mm, {:.3}°, trusted {}, {} doubts, {:.0} ms",
            if query_attitude.is_some() {
                "read"
            } else {
                "unknown"
            },
            error_m * 1e3,
            error_deg,
            found.trusted,
            found.doubts.len(),
            found.time.as_secs_f64() * 1e3
        );
        if !found.trusted {
            eprintln!("doubts: {:?}", found.doubts);
        }
        if error_m > 0.01 || error_deg > 0.5 {
            return Err(format!("localization off the truth: {error_m} m, {error_deg}°").into());
        }
    }

    // 2. The incremental loop, one stop at a time, with odometry 5 % long and 0.5° a step off.
    let truth: Vec<_> = run.iter().map(|s| s.world_from_sensor).collect();
    let odometry = simulate_odometry(&truth, &OdometryNoise::default(), SEED)?;
    let mut slam = Slam::new(SlamOptions::default())?;
    for (k, odom_from_sensor) in odometry.iter().enumerate() {
        let step = slam.add(&points(k), Some(reading(k)), Some(*odom_from_sensor))?;
        if step.status == StepStatus::Doubtful {
            println!("stop {k}: doubtful: {:?}", step.report.doubts);
        }
    }
    let world_from_sensor = slam.poses();
    let squared: f64 = (world_from_sensor.iter().zip(&truth))
        .map(|(estimate, truth)| {
            (estimate.translation.vector - truth.translation.vector).norm_squared()
        })
        .sum();
    let ate_m = (squared / truth.len() as f64).sqrt();
    println!(
        "slam: {} stops with odometry, ATE {:.2} cm",
        truth.len(),
        ate_m * 100.0
    );
    if ate_m > 0.02 {
        return Err(format!("the map is {ate_m} m off the truth (ATE)").into());
    }

    // 3. The map saved as `sdem slam` saves it, loaded back, and a stop's scan found in it with
    //    no position given.
    let folder = std::env::temp_dir().join(format!("sdem-library-user-{}", std::process::id()));
    sdem_io::MapFolder::create(&folder)?.save_slam(&slam)?;
    let saved = sdem_io::load_map(&folder);
    std::fs::remove_dir_all(&folder)?;
    let k = STOPS / 2;
    let found = saved?.relocalize(&points(k), Some(reading(k)), None, None)?;
    let off_m = (found.world_from_sensor.translation.vector
        - world_from_sensor[k].translation.vector)
        .norm();
    println!(
        "relocalized stop {k} in the saved map: node {}, {:.2} cm from its mapped pose, \
         trusted {}, {:.0} ms",
        found.node_id,
        off_m * 100.0,
        found.trusted,
        found.time.as_secs_f64() * 1e3
    );
    if off_m > 0.05 {
        return Err(format!("relocalized {off_m} m from the mapped pose").into());
    }
    Ok(())
}
