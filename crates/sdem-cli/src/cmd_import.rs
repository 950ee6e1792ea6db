//! `sdem import`: a 3DTK folder, a KITTI odometry sequence, a ROS 2 bag or an E57 survey turned
//! into a dataset folder.

use crate::output::print_json;
use anyhow::{bail, Context, Result};
use sdem_io::{import_dataset, ImportFormat, ImportOptions, ImportSummary};
use std::path::PathBuf;

/// Arguments of `sdem import`.
#[derive(clap::Args)]
pub struct Args {
    /// What to import: a 3DTK folder (scanNNN.3d + scanNNN.pose, optionally
    /// slam6d_frames_2009/ or scanNNN.frames), a KITTI odometry sequence (velodyne/NNNNNN.bin,
    /// poses.txt, calib.txt), a ROS 2 bag (a rosbag2 folder, or one .mcap or .db3 file) or an
    /// E57 survey (SURVEY.e57: every scan in its own frame).
    source: PathBuf,
    /// The dataset folder to write (scans/ and, for 3DTK, odometry.txt, attitude.csv,
    /// poses_slam6d.txt and sensor.toml with the scanner's steps measured from the scans; for
    /// KITTI, poses_truth.txt; for a ROS 2 bag, attitude.csv, odometry.txt and, for a tilting
    /// laser, sensor.toml; for E57, odometry.txt and attitude.csv from the
    /// registered poses when every scan has one).
    #[arg(long)]
    out: PathBuf,
    /// The source's format [default: guessed: a bag means ros2, a .e57 file e57, velodyne/
    /// kitti, scanNNN.3d 3dtk].
    #[arg(long, value_enum)]
    format: Option<Format>,
    /// The first scan number to import (the NNN in the file names; for E57 the scan's position
    /// in the survey, from 0).
    #[arg(long, default_value_t = 0)]
    first: usize,
    /// How many scans to import from --first on [default: all].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_count)]
    count: Option<usize>,
    /// Import every Nth scan from --first on (--count of them): a 10 Hz LiDAR recording
    /// thinned as a vehicle that stops to scan, or drops frames, would take it [default: 1].
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = parse_every)]
    every: Option<usize>,
    /// 3DTK only: the folder of slam6D's scanNNN.frames, written as poses_slam6d.txt (a
    /// reference, not ground truth) [default: SOURCE/slam6d_frames_2009/, else SOURCE when it
    /// holds .frames files].
    #[arg(long)]
    frames: Option<PathBuf>,
    /// Write into a folder that is not empty: the dataset files there (scans/, sweeps/,
    /// attitude.csv, pose files, sensor.toml) are removed first; other files are kept.
    #[arg(long)]
    force: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    bag: crate::cmd_import_bag::BagArgs,
}

/// The `--format` values.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Format {
    /// 3DTK: scanNNN.3d + scanNNN.pose.
    #[value(name = "3dtk")]
    Uos3dtk,
    /// KITTI odometry: velodyne/NNNNNN.bin, poses.txt, calib.txt.
    Kitti,
    /// A ROS 2 bag: a rosbag2 folder (metadata.yaml + .mcap or .db3), or one .mcap file.
    Ros2,
    /// An E57 survey: one .e57 file of scans with their registered poses.
    E57,
}

/// Runs `sdem import`.
pub fn run(args: Args) -> Result<()> {
    args.bag.check()?;
    check_args(&args)?;
    let is_bag = match args.format {
        Some(Format::Ros2) => true,
        Some(_) => false,
        None => sdem_io::rosbag::is_rosbag(&args.source),
    };
    if is_bag {
        if args.first != 0 || args.count.is_some() || args.every.is_some() || args.frames.is_some()
        {
            bail!("--first, --count, --every and --frames are for 3DTK and KITTI folders and E57 surveys; a bag's stops are chosen with --stops");
        }
        clear_for_force(&args)?;
        return crate::cmd_import_bag::run(&args.source, &args.out, &args.bag, args.json);
    }
    if let Some(flag) = args.bag.given().first() {
        bail!(
            "{flag} is for ROS 2 bags; {} is not one (a rosbag2 folder with metadata.yaml, or \
             an .mcap or .db3 file)",
            args.source.display()
        );
    }
    let format = args.format.map(|f| match f {
        Format::Uos3dtk => ImportFormat::Uos3dtk,
        Format::Kitti | Format::Ros2 => ImportFormat::Kitti,
        Format::E57 => ImportFormat::E57,
    });
    let options = ImportOptions {
        first: args.first,
        count: args.count,
        every: args.every,
        frames_dir: args.frames.clone(),
    };
    let format = match format {
        Some(f) => f,
        None => ImportFormat::detect(&args.source)?,
    };
    clear_for_force(&args)?;
    let summary = import_dataset(&args.source, &args.out, Some(format), &options)?;
    if args.json {
        return print_json(&summary);
    }
    print_text(&args, &summary);
    Ok(())
}

/// With `--force`, removes the old dataset in `--out`.
fn clear_for_force(args: &Args) -> Result<()> {
    if args.force {
        sdem_io::clear_dataset(&args.out).with_context(|| {
            format!(
                "cannot remove the old dataset in {} for --force",
                args.out.display()
            )
        })?;
    }
    Ok(())
}

/// Parses `--count N`: at least 1.
fn parse_count(text: &str) -> std::result::Result<usize, String> {
    crate::parse::count_in(
        text,
        1..=usize::MAX,
        "0 imports nothing (leave the flag out for all scans)",
    )
}

/// Parses `--every N`: at least 1.
fn parse_every(text: &str) -> std::result::Result<usize, String> {
    crate::parse::count_in(
        text,
        1..=usize::MAX,
        "give 1 for every scan, 5 for every fifth",
    )
}

/// Checks the source, and that `--out` is a folder that is empty or may be replaced.
fn check_args(args: &Args) -> Result<()> {
    if !args.source.exists() {
        bail!(
            "{} does not exist; import reads a 3DTK folder, a KITTI sequence folder, a ROS 2 \
             bag or an .e57 file",
            args.source.display()
        );
    }
    if args.out.exists() {
        if !args.out.is_dir() {
            bail!(
                "--out {} is a file, not a folder; choose another --out",
                args.out.display()
            );
        }
        let not_empty = std::fs::read_dir(&args.out)
            .with_context(|| format!("cannot list {}", args.out.display()))?
            .next()
            .is_some();
        if not_empty && !args.force {
            bail!(
                "{} is not empty; choose another --out or pass --force to replace the dataset there",
                args.out.display()
            );
        }
    }
    Ok(())
}

/// Prints the summary as text.
fn print_text(args: &Args, summary: &ImportSummary) {
    let name = match summary.format {
        ImportFormat::Uos3dtk => "3DTK",
        ImportFormat::Kitti => "KITTI",
        ImportFormat::E57 => "E57",
    };
    println!(
        "imported {} {name} scans from {} to {}",
        summary.scans,
        args.source.display(),
        args.out.display()
    );
    let n = &summary.points_per_scan;
    println!(
        "  {}..{} points per scan",
        n.iter().min().unwrap_or(&0),
        n.iter().max().unwrap_or(&0)
    );
    if summary.format == ImportFormat::Uos3dtk {
        let far = match summary.no_return_from_m {
            Some(from) => format!(
                "{} points at the scanner's \"no return\" range ({from:.2} m and beyond)",
                summary.dropped_far
            ),
            None => "no \"no return\" points (the scans have no such range)".into(),
        };
        println!(
            "  dropped {far} and {} points nearer than {} m (the robot)",
            summary.dropped_near,
            sdem_io::UOS_MIN_RANGE_M
        );
    }
    if summary.dropped_invalid > 0 {
        println!(
            "  dropped {} invalid points (no return, or a direction without a range)",
            summary.dropped_invalid
        );
    }
    for note in &summary.notes {
        println!("  note: {note}");
    }
    println!("  wrote {}", summary.written.join(", "));
}
