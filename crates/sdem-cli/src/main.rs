//! `sdem`: Sphere-DEM localization and mapping for rescue robots, from the command line.
//!
//! This binary parses arguments, reports progress and prints results; the work is done by the
//! `sdem` library. Errors go to stderr as one line. The exit status says how it ended (see
//! [`EXIT_STATUS`]).

mod attitude_args;
mod bench_kitti;
mod bench_peers;
mod bench_tally;
mod cmd_bench;
mod cmd_bench_faults;
mod cmd_bench_scale;
mod cmd_bench_suites;
mod cmd_demo;
mod cmd_export;
mod cmd_import;
mod cmd_import_bag;
mod cmd_info;
mod cmd_localize;
mod cmd_simulate;
mod cmd_slam;
mod cmd_view;
mod cpu;
mod export_e57;
mod export_mcap;
mod memory;
mod output;
mod parse;
mod progress;

use clap::{Parser, Subcommand};
use output::Outcome;
use std::process::ExitCode;

/// The exit statuses, as `sdem --help` prints them.
const EXIT_STATUS: &str = "\
Exit status:
  0  done, and every result trusted
  1  an error: stderr says what was wrong, where, and how to fix it
  2  a malformed command line: a value out of its range, or options that do not fit together
  3  done, but a result has doubts (localize, slam): the pose is printed as a best guess,
     labelled \"best guess (doubtful)\" or DOUBTFUL with a \"DOUBT:\" line per reason, and with
     --json \"trusted\": false and its \"doubts\". --accept-doubtful takes the best guess: status
     0, still labelled";

/// A result done but with doubts (see [`EXIT_STATUS`]).
const EXIT_DOUBTS: u8 = 3;

/// Three-dimensional localization and mapping for a rescue robot with a tilting laser range
/// finder (Nagatani et al., IROS 2003).
#[derive(Parser)]
#[command(name = "sdem", version, about, long_about = None, after_help = EXIT_STATUS)]
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
    /// Localize one scan of a dataset against another, or in a saved map, and print the pose.
    #[command(after_help = EXIT_STATUS)]
    Localize(cmd_localize::Args),
    /// Map a dataset: the stop-and-go loop with merging, loop closure and a fused map.
    #[command(after_help = EXIT_STATUS)]
    Slam(cmd_slam::Args),
    /// Measure the exact search against the exhaustive oracle, and accuracy over seeded pairs;
    /// --faults and --suite measure other cases.
    Bench(cmd_bench::Args),
    /// Turn a 3DTK folder, a KITTI odometry sequence, a ROS 2 bag or an E57 survey into a
    /// dataset folder.
    Import(cmd_import::Args),
    /// Say what a ROS 2 bag holds: files, storage, time span, topics with types, counts, rates.
    Info(cmd_info::Args),
    /// Write a map made by `sdem slam` for other tools: --mcap for Foxglove and RViz, --e57 the
    /// aligned scans as an E57 survey.
    Export(cmd_export::Args),
    /// Pictures for people: S-DEM panorama and slice, map plan and section, cost surface, and
    /// the 3D viewer page.
    View(cmd_view::Args),
}

fn main() -> ExitCode {
    output::end_quietly_when_stdout_fails();
    if let Some(usage) = non_utf8_argument() {
        usage.exit();
    }
    let cli = Cli::parse();
    let done = |result: anyhow::Result<()>| result.map(|()| Outcome::Done);
    let result = match cli.command {
        Command::Demo(args) => done(cmd_demo::run(args)),
        Command::Simulate(args) => done(cmd_simulate::run(args)),
        Command::Localize(args) => cmd_localize::run(args),
        Command::Bench(args) => done(cmd_bench::run(args)),
        Command::Import(args) => done(cmd_import::run(args)),
        Command::Info(args) => done(cmd_info::run(args)),
        Command::Export(args) => done(cmd_export::run(args)),
        Command::Slam(args) => cmd_slam::run(args),
        Command::View(args) => done(cmd_view::run(args)),
    };
    match result {
        Ok(Outcome::Done) => ExitCode::SUCCESS,
        Ok(Outcome::DoneWithDoubts) => {
            eprintln!(
                "sdem: done with doubts (exit status {EXIT_DOUBTS}): a pose is a best guess (see \
                 its DOUBT lines, or \"doubts\" in the JSON); --accept-doubtful takes it with \
                 status 0"
            );
            ExitCode::from(EXIT_DOUBTS)
        }
        Err(error) => match error.downcast::<clap::Error>() {
            // Options that do not fit together, found after parsing (`parse::usage_error`): a
            // usage error as clap's own, status 2.
            Ok(usage) => usage.exit(),
            Err(error) => {
                eprintln!("sdem: error: {}", output::error_line(&error));
                ExitCode::from(1)
            }
        },
    }
}

/// A usage error for the first command-line argument that is not valid UTF-8. sdem writes the
/// paths it reads and writes into its JSON (`--json`, `report.json`, the saved map's manifest),
/// which holds only UTF-8: such a path failed after the work, with the outputs written and
/// status 1 (or a panic for `export --mcap`).
fn non_utf8_argument() -> Option<clap::Error> {
    use clap::CommandFactory;
    let (k, arg) = std::env::args_os()
        .enumerate()
        .skip(1)
        .find(|(_, arg)| arg.to_str().is_none())?;
    Some(Cli::command().error(
        clap::error::ErrorKind::InvalidUtf8,
        format!(
            "argument {k} ({}) is not valid UTF-8: sdem names its files in its JSON outputs \
             and saved maps, which hold only UTF-8; rename the file or folder",
            arg.to_string_lossy()
        ),
    ))
}
