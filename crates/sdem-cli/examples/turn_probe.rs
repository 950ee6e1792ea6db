//! Measures the heading bias of matching a turned scan, with exact attitudes, refined from the
//! truth: what `docs/scale.md` reads where the `wings` route's drift comes from.
//!
//! ```sh
//! cargo run --release -p sdem-cli --example turn_probe -- in-place
//! cargo run --release -p sdem-cli --example turn_probe -- steps --reference nearest
//! ```
//!
//! * `in-place`: stops 10, 30, 50 and 70 of the `wings` route scanned twice from the same
//!   place, the second turned about the vertical by 0, ¼, ½, ¾, 1, 2.5, 5, 5.5, 10, 10.5, 18,
//!   18.5, 25, 25.5, −18 and −18.5°; per turn, the mean yaw error over the four stops.
//! * `steps`: every step of the route's first 100 stops, each scan matched against the stop
//!   before it; the mean yaw error and sideways error of the steps that turn less and more than
//!   10°.
//!
//! `--reference` says what the stop before is matched as: `scan` (its whole scan, the default),
//! `means` (one point per cell, the mean of its returns on the nearest surface, as a map node
//! keeps it) or `nearest` (the nearest return of each cell, the paper's boundary points).

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sdem::geometry::{attitude_of, Pose, Vec3};
use sdem::refine::{refine, RefineConfig, SurfaceNormals};
use sdem::sdem::Sdem;
use sdem::sensor::{SensorConfig, Sweep};
use sdem::{Attitude, SdemConfig};
use sdem_sim::sim::{long_run, scan, LongRoute, LongRun};

/// What the reference scan is matched as.
#[derive(Clone, Copy, PartialEq)]
enum Reference {
    Scan,
    Means,
    Nearest,
}

/// The reference S-DEM of `sweep`, levelled by its exact reading, as `kind` says.
fn reference_sdem(sweep: &Sweep, kind: Reference) -> anyhow::Result<Sdem> {
    let grid = SdemConfig::default();
    let sdem = Sdem::from_points(&sweep.points_in_sensor(), &sweep.mean_attitude(), &grid)?;
    let kept = match kind {
        Reference::Scan => return Ok(sdem),
        Reference::Means => sdem.surface_points(),
        Reference::Nearest => sdem.points(),
    };
    let levelled: Vec<Vec3> = (kept.iter())
        .map(|p| Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .collect();
    Ok(Sdem::from_points(&levelled, &Attitude::default(), &grid)?)
}

/// The refined `reference_level_from_query_level` of `query` against `reference`, from the
/// true `offset` (the readings are exact, so the true rotation is the identity).
fn refined(reference: &Sdem, query: &Sweep, offset: &Vec3) -> anyhow::Result<Isometry3<f64>> {
    let grid = SdemConfig::default();
    let query = Sdem::from_points(&query.points_in_sensor(), &query.mean_attitude(), &grid)?;
    let config = RefineConfig::default();
    let normals = SurfaceNormals::of(reference, config.normal_radius_cells);
    let initial = Isometry3::translation(offset.x, offset.y, offset.z);
    let found = refine(reference, &normals, &query, &initial, None, &config)?;
    Ok(found.reference_level_from_query_level)
}

fn in_place(
    run: &LongRun,
    truth: &[Pose],
    sensor: &SensorConfig,
    kind: Reference,
) -> anyhow::Result<()> {
    let turns = [
        0.0, 0.25, 0.5, 0.75, 1.0, 2.5, 5.0, 5.5, 10.0, 10.5, 18.0, 18.5, 25.0, 25.5, -18.0, -18.5,
    ];
    let stops = [10, 30, 50, 70];
    println!("turn deg | mean yaw error mdeg over stops {stops:?} | each");
    for turn in turns {
        let mut errors = Vec::new();
        for s in stops {
            let pose = truth[s];
            let near = run
                .scene
                .cropped(&pose.translation.vector, sensor.max_range_m);
            let sweep = |pose: &Pose, seed| {
                scan(
                    &near,
                    sensor,
                    pose,
                    0.0,
                    &mut ChaCha8Rng::seed_from_u64(seed),
                )
            };
            let turned = Isometry3::from_parts(
                pose.translation,
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), f64::to_radians(turn))
                    * pose.rotation,
            );
            let reference = reference_sdem(&sweep(&pose, 7 + s as u64), kind)?;
            let found = refined(&reference, &sweep(&turned, 1000 + s as u64), &Vec3::zeros())?;
            errors.push(attitude_of(&found).yaw.to_degrees() * 1e3);
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        println!("{turn:6.2} | {mean:6.2} | {errors:.1?}");
    }
    Ok(())
}

fn steps(
    run: &LongRun,
    truth: &[Pose],
    sensor: &SensorConfig,
    kind: Reference,
) -> anyhow::Result<()> {
    let sims = run.simulate(sensor, 1, 0..run.stops.len())?;
    // [steps, yaw (mdeg), across (mm, left positive)] for turns below and above 10°.
    let mut sums = [[0.0; 3]; 2];
    for i in 1..sims.len() {
        let heading = attitude_of(&truth[i - 1]).yaw;
        let turn = (attitude_of(&truth[i]).yaw - heading).to_degrees();
        let turn = (turn + 180.0).rem_euclid(360.0) - 180.0;
        let offset = truth[i].translation.vector - truth[i - 1].translation.vector;
        let reference = reference_sdem(&sims[i - 1].sweep, kind)?;
        let found = refined(&reference, &sims[i].sweep, &offset)?;
        let e = found.translation.vector - offset;
        let across = -e.x * heading.sin() + e.y * heading.cos();
        let yaw = attitude_of(&found).yaw.to_degrees() * 1e3;
        println!(
            "step {i}: turn {turn:6.2}°, yaw error {yaw:6.1} mdeg, across {:6.3} mm",
            across * 1e3
        );
        let s = &mut sums[usize::from(turn.abs() >= 10.0)];
        s[0] += 1.0;
        s[1] += yaw;
        s[2] += across * 1e3;
    }
    for (name, s) in ["below 10°", "10° and more"].iter().zip(sums) {
        println!(
            "turns {name}: {} steps, mean yaw error {:.1} mdeg, across {:.3} mm",
            s[0],
            s[1] / s[0],
            s[2] / s[0]
        );
    }
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let kind = match args
        .iter()
        .position(|a| a == "--reference")
        .map(|i| args.get(i + 1))
    {
        None => Reference::Scan,
        Some(Some(v)) if v == "scan" => Reference::Scan,
        Some(Some(v)) if v == "means" => Reference::Means,
        Some(Some(v)) if v == "nearest" => Reference::Nearest,
        _ => anyhow::bail!("--reference takes scan, means or nearest"),
    };
    let sensor = SensorConfig {
        compass_noise_deg: 0.0,
        tilt_sensor_noise_deg: 0.0,
        ..Default::default()
    };
    let run = long_run(LongRoute::Wings, 1, 100, &sensor.lift)?;
    let truth = run.truth(&sensor.lift)?;
    match args.first().map(String::as_str) {
        Some("in-place") => in_place(&run, &truth, &sensor, kind),
        Some("steps") => steps(&run, &truth, &sensor, kind),
        _ => anyhow::bail!("say in-place or steps; see the example's documentation"),
    }
}
