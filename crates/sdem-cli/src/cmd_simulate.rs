//! `sdem simulate`: a simulated collapsed-building run written as a dataset folder.

use crate::output::print_json;
use anyhow::{bail, Context, Result};
use sdem::sensor::SensorConfig;
use sdem::sim;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Arguments of `sdem simulate`.
#[derive(clap::Args)]
pub struct Args {
    /// The dataset folder to write.
    #[arg(long)]
    out: PathBuf,
    /// Seed of the scene, the path and the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Number of stops.
    #[arg(long, default_value_t = 8)]
    stops: usize,
    /// Standard deviation of the range noise, metres.
    #[arg(long, default_value_t = 0.005)]
    range_noise: f64,
    /// Standard deviation of the compass heading reading, degrees.
    #[arg(long)]
    compass_noise_deg: Option<f64>,
    /// Drop returns beyond this range, metres (the paper trusts 3 m).
    #[arg(long)]
    trusted_range: Option<f64>,
    /// Write into a folder that already holds a dataset: its scans, sweeps, attitudes, truth and
    /// sensor file are removed first, so no old file mixes into the new dataset.
    #[arg(long)]
    force: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct Summary {
    out: PathBuf,
    seed: u64,
    stops: usize,
    points_per_scan: Vec<usize>,
}

/// Runs `sdem simulate`.
pub fn run(args: Args) -> Result<()> {
    if args.out.join("scans").exists() && !args.force {
        bail!(
            "{} already holds a dataset (scans/); choose another --out or pass --force to replace it",
            args.out.display()
        );
    }
    if !(1..=sim::MAX_STOPS).contains(&args.stops) {
        bail!(
            "--stops {} must lie in 1..={} (the simulated route holds {} stops)",
            args.stops,
            sim::MAX_STOPS,
            sim::MAX_STOPS
        );
    }
    let mut sensor = SensorConfig {
        range_noise_m: args.range_noise,
        trusted_range_m: args.trusted_range,
        ..Default::default()
    };
    if let Some(c) = args.compass_noise_deg {
        sensor.compass_noise_deg = c;
    }
    sensor.validate()?;
    let scene = sim::collapsed_building(args.seed);
    let stops = sim::collapsed_building_stops(&scene, args.seed, args.stops, &sensor.lift)?;
    let run = sim::simulate_run(&scene, &stops, &sensor, args.seed)?;
    let scans: Vec<_> = run
        .iter()
        .map(|s| (s.sweep.points_in_sensor(), s.sweep.mean_attitude()))
        .collect();
    let sweeps: Vec<_> = run.iter().map(|s| s.sweep.clone()).collect();
    if args.force {
        remove_old_dataset(&args.out)?;
    }
    let truth: Vec<_> = run.iter().map(|s| s.world_from_sensor).collect();
    sdem::io::write_dataset(&args.out, &sensor, &scans, Some(&sweeps), Some(&truth))?;
    let summary = Summary {
        out: args.out.clone(),
        seed: args.seed,
        stops: run.len(),
        points_per_scan: scans.iter().map(|s| s.0.len()).collect(),
    };
    if args.json {
        return print_json(&summary);
    }
    println!(
        "wrote {} stops of a collapsed building (seed {}) to {}",
        summary.stops,
        summary.seed,
        args.out.display()
    );
    let n = &summary.points_per_scan;
    println!(
        "  {}..{} returns per scan; truth in poses_truth.txt, raw sweeps in sweeps/",
        n.iter().min().unwrap_or(&0),
        n.iter().max().unwrap_or(&0)
    );
    Ok(())
}

/// Removes the files of the dataset in `root` that `simulate` writes (and nothing else).
fn remove_old_dataset(root: &Path) -> Result<()> {
    for dir in ["scans", "sweeps"] {
        let path = root.join(dir);
        if path.is_dir() {
            std::fs::remove_dir_all(&path)
                .with_context(|| format!("cannot remove {} for --force", path.display()))?;
        }
    }
    for file in [
        "attitude.csv",
        "poses_truth.txt",
        "poses_truth.tum",
        "sensor.toml",
    ] {
        let path = root.join(file);
        if path.is_file() {
            std::fs::remove_file(&path)
                .with_context(|| format!("cannot remove {} for --force", path.display()))?;
        }
    }
    Ok(())
}
