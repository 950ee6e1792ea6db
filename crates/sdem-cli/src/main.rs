//! `sdem`: Sphere-DEM localization and mapping for rescue robots, from the command line.
//!
//! This binary parses arguments, reports progress and prints results; the work is done by the
//! `sdem` library. Errors go to stderr as one line, with a non-zero exit code.

mod bench_tally;
mod cmd_bench;
mod cmd_bench_faults;
mod cmd_demo;
mod cmd_import;
mod cmd_localize;
mod cmd_simulate;
mod cmd_slam;
mod cmd_view;
mod output;
mod progress;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Three-dimensional localization and mapping for a rescue robot with a tilting laser range
/// finder (Nagatani et al., IROS 2003).
#[derive(Parser)]
#[command(name = "sdem", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a collapsed-building run, localize it, print the errors against truth.
    Demo(cmd_demo::Args),
    /// Write a simulated dataset folder (scans, attitude.csv, odometry.txt, poses_truth.txt,
    /// sensor.toml).
    Simulate(cmd_simulate::Args),
    /// Localize one scan of a dataset against another and print the pose.
    Localize(cmd_localize::Args),
    /// Map a dataset: the stop-and-go loop with merging, loop closure and a fused map.
    Slam(cmd_slam::Args),
    /// Measure the exact search against the exhaustive oracle, and accuracy over seeded pairs.
    Bench(cmd_bench::Args),
    /// Turn a 3DTK folder or a KITTI odometry sequence into a dataset folder.
    Import(cmd_import::Args),
    /// Pictures for people: S-DEM panorama and slice, map plan and section, cost surface, and
    /// the 3D viewer page.
    View(cmd_view::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => cmd_demo::run(args),
        Command::Simulate(args) => cmd_simulate::run(args),
        Command::Localize(args) => cmd_localize::run(args),
        Command::Bench(args) => cmd_bench::run(args),
        Command::Import(args) => cmd_import::run(args),
        Command::Slam(args) => cmd_slam::run(args),
        Command::View(args) => cmd_view::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("sdem: error: {error:#}");
            ExitCode::from(1)
        }
    }
}
