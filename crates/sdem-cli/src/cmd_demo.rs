//! `sdem demo`: the paper's preparatory experiment, then a short stop-and-go run, with the errors
//! against truth. Results with doubts are labelled as `localize` and `slam` label them, but the
//! exit status stays 0: the demonstration has the truth to show how far off they are.

use crate::output::{
    check_output_folder, create_folder, doubts_json, estimate_label, pose_line, print_doubts,
    print_json,
};
use anyhow::{bail, Context, Result};
use sdem::geometry::{PoseRecord, Vec3};
use sdem_sim::experiment::{paper_experiment, stop_and_go_run, ExperimentConfig, RunStop, Trial};
use serde::Serialize;
use serde_json::Value;
use std::path::PathBuf;

/// Arguments of `sdem demo`.
#[derive(clap::Args)]
pub struct Args {
    /// Folder for the outputs (report.json, poses, map.ply, pictures, viewer.html); a folder
    /// named here is refused when it already holds any of them (or a map/ folder), unless
    /// --force. [default: sdem-demo, the demo's own, which each run replaces]
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write into an --out folder that already holds outputs of an earlier demo (or files of
    /// the same names): they are replaced; other files are left alone.
    #[arg(long)]
    force: bool,
    /// Seed of the scenes, the path and the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Stops of the stop-and-go run, 2 to 40 (the simulated building's route holds 40).
    #[arg(long, default_value_t = 8, allow_hyphen_values = true, value_parser = parse_stops)]
    stops: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct CaseReport {
    case: String,
    truth: PoseRecord,
    estimate: PoseRecord,
    error_m: f64,
    error_deg: f64,
    cost: f64,
    overlap: usize,
    candidates_evaluated: usize,
    time_ms: f64,
    trusted: bool,
    doubts: Vec<Value>,
}

impl From<&Trial> for CaseReport {
    fn from(t: &Trial) -> Self {
        Self {
            case: t.case.clone(),
            truth: PoseRecord::from(&t.truth),
            estimate: PoseRecord::from(&t.estimate),
            error_m: t.error_m,
            error_deg: t.error_rad.to_degrees(),
            cost: t.localization.cost,
            overlap: t.localization.overlap,
            candidates_evaluated: t.localization.candidates_evaluated,
            time_ms: t.time_ms,
            trusted: t.localization.trusted,
            doubts: doubts_json(&t.localization.doubts),
        }
    }
}

#[derive(Serialize)]
struct StopReport {
    index: usize,
    truth: PoseRecord,
    estimate: PoseRecord,
    position_error_m: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    step: Option<CaseReport>,
}

#[derive(Serialize)]
struct RunReport {
    stops: Vec<StopReport>,
    /// Steps whose localization has doubts.
    doubtful_steps: usize,
    max_step_error_m: f64,
    final_position_error_m: f64,
    path_length_m: f64,
}

#[derive(Serialize)]
struct Report {
    paper_experiment: Vec<CaseReport>,
    run: RunReport,
    out: PathBuf,
}

fn run_report(stops: &[RunStop]) -> RunReport {
    let reports: Vec<StopReport> = stops
        .iter()
        .enumerate()
        .map(|(index, s)| StopReport {
            index,
            truth: PoseRecord::from(&s.truth),
            estimate: PoseRecord::from(&s.estimate),
            position_error_m: s.position_error_m,
            step: s.step.as_ref().map(CaseReport::from),
        })
        .collect();
    let max_step_error_m = stops
        .iter()
        .filter_map(|s| s.step.as_ref().map(|t| t.error_m))
        .fold(0.0, f64::max);
    let path_length_m = stops
        .windows(2)
        .map(|w| (w[1].truth.translation.vector - w[0].truth.translation.vector).norm())
        .sum();
    RunReport {
        doubtful_steps: stops
            .iter()
            .filter(|s| s.step.as_ref().is_some_and(|t| !t.localization.trusted))
            .count(),
        stops: reports,
        max_step_error_m,
        final_position_error_m: stops.last().map_or(0.0, |s| s.position_error_m),
        path_length_m,
    }
}

/// The files `sdem demo` writes into its folder besides the map's pictures
/// ([`crate::cmd_view::MAP_PICTURE_FILES`]).
const OUTPUT_FILES: &[&str] = &[
    "report.json",
    "poses.txt",
    "poses.tum",
    "poses_truth.txt",
    "poses_truth.tum",
    "map.ply",
];

/// The stops the run may have: two make its first step, and the simulated building's route
/// holds [`sdem_sim::sim::MAX_STOPS`].
const STOPS: std::ops::RangeInclusive<usize> = 2..=sdem_sim::sim::MAX_STOPS;

/// Parses `--stops N`: within [`STOPS`].
fn parse_stops(text: &str) -> Result<usize, String> {
    let why = format!(
        "the stop-and-go run needs 2 stops for one step, and the simulated building's route \
         holds {}",
        STOPS.end()
    );
    crate::parse::count_in(text, STOPS, &why)
}

/// Checks, before any work, that an `--out` folder holds none of the files the demo writes,
/// nor the `map/` of a `sdem slam` output (whose poses and pictures the demo's would replace),
/// unless `--force`.
fn check_args(args: &Args) -> Result<()> {
    let names: Vec<&str> = OUTPUT_FILES
        .iter()
        .chain(crate::cmd_view::MAP_PICTURE_FILES)
        .copied()
        .collect();
    let Some(out) = &args.out else {
        // The demo's own folder: each run replaces the last one's outputs.
        return Ok(());
    };
    check_output_folder(out, "--out", &names, args.force)?;
    if !args.force && out.join("map").exists() {
        bail!(
            "--out {} holds map/, the saved map of a `sdem slam` run, whose poses and pictures \
             the demo would replace; choose another --out, or pass --force",
            out.display()
        );
    }
    Ok(())
}

/// Writes the run's outputs: estimated and true poses (KITTI + TUM) and the merged map.
fn write_outputs(out: &std::path::Path, stops: &[RunStop], report: &Report) -> Result<()> {
    create_folder(out)?;
    let estimates: Vec<_> = stops.iter().map(|s| s.estimate).collect();
    let truths: Vec<_> = stops.iter().map(|s| s.truth).collect();
    sdem_io::write_poses(&out.join("poses.txt"), &estimates)?;
    sdem_io::write_poses(&out.join("poses_truth.txt"), &truths)?;
    let map: Vec<Vec3> = stops
        .iter()
        .flat_map(|s| {
            s.points
                .iter()
                .map(move |p| s.estimate * nalgebra::Point3::from(*p))
        })
        .map(|p| p.coords)
        .collect();
    sdem_io::write_points_ply(&out.join("map.ply"), &map)?;
    // Pictures and the 3D viewer page of the run's map.
    let sdem_config = sdem::sdem::SdemConfig::default();
    let nodes = stops
        .iter()
        .enumerate()
        .map(|(i, s)| sdem::map::Node::from_scan(i, i, s.estimate, None, &s.points, &sdem_config))
        .collect::<sdem::Result<Vec<_>>>()?;
    crate::cmd_view::write_map_pictures(
        out,
        &crate::cmd_view::map_name(None, out),
        &sdem::map::Map { nodes },
        &[],
        &sdem::slam::SlamOptions::default(),
        &map,
        &[],
    )?;
    let text = serde_json::to_string_pretty(report)?;
    sdem_io::write_atomic(&out.join("report.json"), |w| w.write_all(text.as_bytes()))?;
    Ok(())
}

/// The outputs' folder: `--out`, else the demo's own.
fn out_folder(args: &Args) -> PathBuf {
    args.out
        .clone()
        .unwrap_or_else(|| PathBuf::from(DEFAULT_OUT))
}

/// The demo's own folder, which each run without `--out` replaces.
const DEFAULT_OUT: &str = "sdem-demo";

/// Runs `sdem demo`.
pub fn run(args: Args) -> Result<()> {
    check_args(&args)?;
    let config = ExperimentConfig {
        seed: args.seed,
        stops: args.stops,
        ..Default::default()
    };
    if !args.json {
        print_paper_heading();
    }
    let paper = paper_experiment(&config).context("the paper's experiment")?;
    if !args.json {
        print_paper(&paper);
        print_run_heading(&config);
    }
    let stops = stop_and_go_run(&config).context("the stop-and-go run")?;
    if !args.json {
        print_stops(&stops);
    }
    let report = Report {
        paper_experiment: paper.iter().map(CaseReport::from).collect(),
        run: run_report(&stops),
        out: out_folder(&args),
    };
    write_outputs(&out_folder(&args), &stops, &report)?;
    if args.json {
        return print_json(&report);
    }
    print_summary(&args, &report);
    Ok(())
}

/// Prints what the paper's experiment is, before it runs.
fn print_paper_heading() {
    println!("sdem demo — Nagatani et al. (IROS 2003), Sec. V, on a simulated sensor\n");
    println!("1. The paper's preparatory experiment: an indoor room, scans 1° x 1°, 5 mm noise,");
    println!("   window x -50..50, y -30..60, z -10..10 cm at 1 cm.");
}

/// Prints each case of the paper's experiment: truth, estimate, error.
fn print_paper(paper: &[Trial]) {
    for t in paper {
        println!("   {}", t.case);
        println!("     truth     {}", pose_line(&t.truth));
        println!(
            "     {}  {}",
            estimate_label(t.localization.trusted),
            pose_line(&t.estimate)
        );
        print_doubts("     ", &t.localization.doubts);
        println!(
            "     error     {:.2} cm  ({} candidates, {:.0} ms)",
            t.error_m * 100.0,
            t.localization.candidates_evaluated,
            t.time_ms
        );
    }
}

/// Prints what the stop-and-go run is and its table's header, before it runs.
fn print_run_heading(config: &ExperimentConfig) {
    println!(
        "\n2. Stop-and-go through the ditch into the void ({} stops, seed {})",
        config.stops, config.seed
    );
    println!("   stop   step error   position error   overlap   time");
}

/// Prints one row per stop of the run; a step with doubts is marked DOUBTFUL, with its doubts
/// on the lines below.
fn print_stops(stops: &[RunStop]) {
    for (i, s) in stops.iter().enumerate() {
        match &s.step {
            Some(t) => {
                println!(
                    "   {i:4}   {:7.2} cm   {:11.2} cm   {:7}   {:4.0} ms{}",
                    t.error_m * 100.0,
                    s.position_error_m * 100.0,
                    t.localization.overlap,
                    t.time_ms,
                    if t.localization.trusted {
                        ""
                    } else {
                        "   DOUBTFUL"
                    }
                );
                print_doubts("          ", &t.localization.doubts);
            }
            None => println!("   {i:4}   (origin)"),
        }
    }
}

/// Prints the run's totals and the files written.
fn print_summary(args: &Args, report: &Report) {
    println!(
        "\n   path {:.2} m, largest step error {:.2} cm, final position error {:.2} cm; {} of {} \
         steps doubtful",
        report.run.path_length_m,
        report.run.max_step_error_m * 100.0,
        report.run.final_position_error_m * 100.0,
        report.run.doubtful_steps,
        report.run.stops.len().saturating_sub(1)
    );
    println!(
        "   wrote {}/report.json, poses.txt (+ .tum), poses_truth.txt, map.ply, plan.png, \
         section.png, panorama.png, slice.png, cost.png, viewer.html",
        out_folder(args).display()
    );
}
