//! `sdem slam`'s loop on simulated LiDAR runs down a street: four scanners (a 32-beam spinning
//! LiDAR, a 16-beam one with lasers 2° apart, a 128-beam one over ±45° like an Ouster OS0, and a
//! 70° × 70° solid-state unit), each driven 12 frames along `sdem_sim`'s LiDAR street (0.8 m a
//! frame by default, weaving ±0.3 m and turning ±3°), with no odometry and no attitude
//! readings, mapped with the options `sdem slam` chooses for a dataset without a `sensor.toml`
//! ([`SlamOptions::for_scan`] of the first frame). Prints, per scanner and street seed, the ATE
//! against the truth, the frames not trusted, the map segments and the median time a frame.
//!
//! ```sh
//! cargo run --release -p sdem-cli --example lidar_runs -- [--seeds 1,5,7] [--step 0.8] [--default]
//! ```
//!
//! `--default` maps with the tilting laser's defaults ([`SlamOptions::default`]) instead.

use nalgebra::{Isometry3, Vector3};
use rand::SeedableRng;
use sdem::geometry::Pose;
use sdem::slam::{trajectory_errors, Slam, SlamOptions};
use sdem_sim::sim::lidar_street::street;
use sdem_sim::sim::{spin_scan, LidarConfig};
use std::time::Instant;

const USAGE: &str = "usage: lidar_runs [--seeds 1,5,7] [--step M] [--default]";

fn main() {
    if let Err(e) = run() {
        eprintln!("lidar_runs: {e}\n{USAGE}");
        std::process::exit(2);
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let mut seeds = vec![1u64, 5, 7];
    let mut step_m = 0.8;
    let mut default = false;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let mut value = || args.next().ok_or(format!("{arg} needs a value"));
        match arg.as_str() {
            "--seeds" => {
                seeds = value()?
                    .split(',')
                    .map(str::parse)
                    .collect::<Result<_, _>>()?
            }
            "--step" => step_m = value()?.parse()?,
            "--default" => default = true,
            _ => return Err(format!("unknown argument {arg}").into()),
        }
    }
    let scanners = [
        ("32 beams", LidarConfig::default()),
        (
            "16 beams, 2° apart",
            LidarConfig {
                rings: 16,
                elevation_min_deg: -15.0,
                elevation_max_deg: 15.0,
                ..LidarConfig::default()
            },
        ),
        (
            "128 beams over ±45°",
            LidarConfig {
                rings: 128,
                elevation_min_deg: -45.0,
                elevation_max_deg: 45.0,
                azimuth_step_deg: 0.35,
                ..LidarConfig::default()
            },
        ),
        ("solid-state 70° × 70°", LidarConfig::solid_state()),
    ];
    println!("| scanner | seed | ATE cm | frames not trusted | segments | ms a frame (median) |");
    println!("|---|---|---|---|---|---|");
    for (name, lidar) in &scanners {
        for &seed in &seeds {
            let scene = street(seed);
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let truth: Vec<Pose> = (0..12)
                .map(|i| {
                    let t = i as f64;
                    Isometry3::new(
                        Vector3::new(-20.0 + step_m * t, 0.3 * (0.3 * t).sin(), 0.0),
                        Vector3::z() * (3.0 * (0.2 * t).cos()).to_radians(),
                    )
                })
                .collect();
            let scans = truth
                .iter()
                .map(|pose| spin_scan(&scene, lidar, pose, &mut rng))
                .collect::<Result<Vec<_>, _>>()?;
            let options = if default {
                SlamOptions::default()
            } else {
                SlamOptions::for_scan(&scans[0])
            };
            let mut slam = Slam::new(options)?;
            let (mut times, mut doubtful) = (Vec::new(), 0);
            for scan in &scans {
                let start = Instant::now();
                let step = slam.add(scan, None, None)?;
                times.push(start.elapsed().as_secs_f64() * 1e3);
                doubtful += usize::from(!step.report.trusted);
            }
            times.sort_by(f64::total_cmp);
            let errors = trajectory_errors(&truth, &slam.poses())?;
            println!(
                "| {name} | {seed} | {:.2} | {doubtful} | {} | {:.0} |",
                errors.ate_rmse_m * 100.0,
                slam.segments().len(),
                times[times.len() / 2],
            );
        }
    }
    Ok(())
}
