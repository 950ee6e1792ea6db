//! Localizes pairs of real LiDAR scans of a dataset folder (`sdem import` of
//! `../shared/data/kitti-00-first16`) with the grid and options derived from the scans
//! ([`SdemConfig::for_scan`], [`LocalizeOptions::for_scan`]), no guess, and prints the median
//! time (both S-DEMs built, and the localization) and the error against `poses_truth.txt`.
//! `scripts/lidar-pairs.sh` runs it beside small_gicp's GICP on the same pairs.
//!
//! ```sh
//! sdem import ../shared/data/kitti-00-first16 --out /tmp/kitti
//! cargo run --release -p sdem-cli --example lidar_pairs -- /tmp/kitti 0:1 5:6 10:11
//! ```
//!
//! The scans are taken as level (KITTI has no attitude readings); the window is ±`--window` m
//! (1) in x and y, ±`--z-window` m (0.3) in height, ±`--heading` degrees (5) of heading. The grid
//! is derived once, from the first pair's reference scan, as a robot would for its sensor.
//! Options: `--repeat N` (5), `--default` (the default grid and options, as `sdem localize`
//! runs), `--step M` and `--tau M` (override the derived step and truncation), `--json` (one
//! line per pair).

use sdem::geometry::{pose_error, Attitude};
use sdem::localize::{localize, HeadingWindow, LocalizeOptions, SearchWindow};
use sdem::sdem::{Sdem, SdemConfig};
use std::path::PathBuf;
use std::time::Instant;

struct Args {
    dataset: PathBuf,
    pairs: Vec<(usize, usize)>,
    repeat: usize,
    window_m: f64,
    z_window_m: f64,
    heading_deg: f64,
    default: bool,
    step_m: Option<f64>,
    tau_m: Option<f64>,
    json: bool,
}

const USAGE: &str = "usage: lidar_pairs DATASET I:J... [--repeat N] [--window M] [--z-window M] \
[--heading DEG] [--default] [--step M] [--tau M] [--json]";

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        dataset: PathBuf::new(),
        pairs: Vec::new(),
        repeat: 5,
        window_m: 1.0,
        z_window_m: 0.3,
        heading_deg: 5.0,
        default: false,
        step_m: None,
        tau_m: None,
        json: false,
    };
    let mut it = std::env::args().skip(1);
    let number = |v: Option<String>, flag: &str| -> Result<f64, String> {
        v.and_then(|v| v.parse().ok())
            .filter(|v: &f64| v.is_finite() && *v >= 0.0)
            .ok_or(format!("{flag} needs a number >= 0\n{USAGE}"))
    };
    while let Some(a) = it.next() {
        match a.as_str() {
            "--repeat" => args.repeat = number(it.next(), &a)?.max(1.0) as usize,
            "--window" => args.window_m = number(it.next(), &a)?,
            "--z-window" => args.z_window_m = number(it.next(), &a)?,
            "--heading" => args.heading_deg = number(it.next(), &a)?.min(180.0),
            "--step" => args.step_m = Some(number(it.next(), &a)?),
            "--tau" => args.tau_m = Some(number(it.next(), &a)?),
            "--default" => args.default = true,
            "--json" => args.json = true,
            _ if a.contains(':') => {
                let (i, j) = a.split_once(':').expect("has ':'");
                let parse = |s: &str| s.parse().map_err(|_| format!("bad pair {a}\n{USAGE}"));
                args.pairs.push((parse(i)?, parse(j)?));
            }
            _ if args.dataset.as_os_str().is_empty() && !a.starts_with('-') => {
                args.dataset = PathBuf::from(a)
            }
            _ => return Err(format!("unexpected {a}\n{USAGE}")),
        }
    }
    if args.dataset.as_os_str().is_empty() || args.pairs.is_empty() {
        return Err(USAGE.into());
    }
    Ok(args)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The grid and options: derived from `points` (the sensor's typical scan), or the defaults.
fn settings(
    args: &Args,
    points: &[sdem::geometry::Vec3],
) -> Result<(SdemConfig, LocalizeOptions), sdem::Error> {
    let (grid, mut options) = if args.default {
        (SdemConfig::default(), LocalizeOptions::default())
    } else {
        let grid = SdemConfig::for_scan(points);
        let typical = Sdem::from_points(points, &Attitude::default(), &grid)?;
        let options = LocalizeOptions::for_scan(&typical);
        (grid, options)
    };
    let (w, z) = (args.window_m, args.z_window_m);
    options.window = SearchWindow {
        min: [-w, -w, -z],
        max: [w, w, z],
    };
    options.heading = HeadingWindow {
        half_range_deg: args.heading_deg,
        ..options.heading
    };
    if let Some(step) = args.step_m {
        options.step_m = step;
    }
    if let Some(tau) = args.tau_m {
        options.cost.truncation_m = tau;
    }
    Ok((grid, options))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = parse_args()?;
    let dataset = sdem_io::Dataset::open(&args.dataset)?;
    let first = dataset.load_scan(args.pairs[0].0)?;
    let start = Instant::now();
    let (grid, options) = settings(&args, &first)?;
    let derive_ms = start.elapsed().as_secs_f64() * 1e3;
    if !args.json {
        println!(
            "grid {}° cells, elevation {}..{}°, plane reach from neighbours {}; step {} m, τ {} \
             m, refining {} points (derived in {derive_ms:.1} ms, once per sensor)",
            grid.resolution_deg,
            grid.elevation_min_deg,
            grid.elevation_max_deg,
            grid.plane_reach_from_neighbours,
            options.step_m,
            options.cost.truncation_m,
            options.refinement.max_points,
        );
    }
    let level = Attitude::default();
    for &(r, q) in &args.pairs {
        let reference_points = dataset.load_scan(r)?;
        let query_points = dataset.load_scan(q)?;
        let mut times = Vec::new();
        let mut found = None;
        for _ in 0..args.repeat {
            let start = Instant::now();
            let (reference, query) = Sdem::pair_from_points(
                (&reference_points, &level),
                (&query_points, &level),
                &grid,
            )?;
            let result = localize(&reference, &query, &options)?;
            times.push(start.elapsed().as_secs_f64() * 1e3);
            found = Some(result);
        }
        let found = found.expect("repeat >= 1");
        let estimate = found.reference_from_query;
        let error = (dataset.truth.as_ref())
            .map(|t| pose_error(&(t[r].inverse() * t[q]), &estimate))
            .map_or((f64::NAN, f64::NAN), |(m, rad)| (m, rad.to_degrees()));
        let t = estimate.translation.vector;
        let yaw_deg = estimate.rotation.euler_angles().2.to_degrees();
        let time_ms = median(&mut times);
        let doubts: Vec<String> = found.doubts.iter().map(|d| d.to_string()).collect();
        if args.json {
            let m = estimate.to_homogeneous();
            let rows: Vec<String> = (0..4)
                .map(|i| {
                    format!(
                        "[{}]",
                        (0..4)
                            .map(|j| m[(i, j)].to_string())
                            .collect::<Vec<_>>()
                            .join(",")
                    )
                })
                .collect();
            println!(
                "{{\"pair\":[{r},{q}],\"time_ms\":{time_ms:.2},\"error_m\":{:.4},\
                 \"error_deg\":{:.4},\"T\":[{}],\"trusted\":{},\"boxes\":{}}}",
                error.0,
                error.1,
                rows.join(","),
                found.trusted,
                found.nodes_bounded
            );
        } else {
            println!(
                "{r}->{q}: {time_ms:.1} ms (median of {}), error {:.2} cm {:.3}°, at ({:.3}, {:.3}, \
                 {:.3}) m, yaw {:.3}°; {} boxes, {} candidates scored, trusted {} {doubts:?}",
                args.repeat,
                error.0 * 100.0,
                error.1,
                t.x,
                t.y,
                t.z,
                yaw_deg,
                found.nodes_bounded,
                found.candidates_evaluated,
                found.trusted,
            );
        }
    }
    Ok(())
}
