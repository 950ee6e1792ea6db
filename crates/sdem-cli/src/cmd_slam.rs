//! `sdem slam`: the stop-and-go loop over a dataset folder, saving the map after every scan.

use crate::output::{degrees, elapsed_ms, pose_line, print_json, with_doubt_messages, Outcome};
use anyhow::{bail, Context, Result};
use sdem::geometry::{Attitude, AttitudeSigma, Pose, Vec3};
use sdem::slam::{
    trajectory_errors, Odometry, PredictionSource, ScanInput, Segment, Slam, SlamOptions,
    StepReport, StepStatus, TrajectoryErrors,
};
use sdem_io::{
    read_kitti_poses, write_atomic, write_points_ply, write_poses, write_voxel_map, Dataset,
    MapFolder,
};
use serde::Serialize;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

mod out_folder;
mod start;

use out_folder::{check_beside_outputs, prepare_out};
use start::{check_extended_map, extend, resume, start_fresh};

/// Arguments of `sdem slam`.
#[derive(clap::Args)]
pub struct Args {
    /// The dataset folder (scans/, optional attitude.csv, odometry.txt, poses_truth.txt,
    /// sensor.toml). Each attitude reading goes to the loop with its σ (attitude.csv's σ
    /// columns, else sensor.toml's attitude_sigma_*_deg, else 0.5° roll/pitch and 3.5° heading).
    /// Without attitude.csv the attitude is unknown: each scan's prior is the last estimate.
    dataset: PathBuf,
    /// How far the attitude readings can be off, standard deviations in degrees:
    /// ROLL_PITCH,YAW (e.g. 0.5,20 for a compass near steel). Overrides attitude.csv's and
    /// sensor.toml's σ for every reading; needs attitude.csv.
    #[arg(
        long,
        allow_hyphen_values = true,
        value_name = "RP,YAW",
        value_parser = crate::attitude_args::attitude_sigma
    )]
    attitude_sigma_deg: Option<AttitudeSigma>,
    /// The output folder: poses.txt, poses.tum, report.json, map.ply, map.sdemvox, config.toml,
    /// the saved map in map/, pictures and viewer.html.
    #[arg(long)]
    out: PathBuf,
    /// A TOML file with the loop's settings (the fields of config.toml, which every run writes;
    /// missing keys take the defaults). Without it, the defaults, with the S-DEM's resolution
    /// matched to the scanner's angular step when the dataset has a sensor.toml; without one,
    /// derived from the first scan when it is a LiDAR's (a spinning one: every azimuth within a
    /// band of elevation; a solid-state one: at most 120° of azimuth; `SlamOptions::for_scan`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Grid step of the search, metres [default: 0.02, a LiDAR's derived from its first scan,
    /// or the config file's]. A LiDAR's recovery windows stay those its scan's scale gave.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::parse::positive_metres)]
    step: Option<f64>,
    /// Do not look for loop closures.
    #[arg(long)]
    no_loop_closure: bool,
    /// Continue the run saved in OUT/map (after a crash or a kill), with its configuration.
    #[arg(long)]
    resume: bool,
    /// A saved map (the folder `sdem slam` wrote, OUT or OUT/map) to extend with this dataset
    /// as a second run: its first scan is relocalized in the map with no known pose (or starts
    /// a new map segment until a later scan is found), and OUT/map holds both runs, in the
    /// saved map's frame and with its configuration. The saved map is left as it was.
    #[arg(long, value_name = "EXISTING", conflicts_with_all = ["resume", "config", "step", "no_loop_closure"])]
    map: Option<PathBuf>,
    /// Replace a map already in OUT.
    #[arg(long)]
    force: bool,
    /// Process at most this many scans (of the dataset, counted from the first).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_max_scans)]
    max_scans: Option<usize>,
    /// Compare the result with these poses too (KITTI format, one per scan; e.g. another
    /// tool's result), besides poses_truth.txt.
    #[arg(long)]
    compare: Option<PathBuf>,
    /// Do not write the pictures (plan.png, section.png, panorama.png, slice.png, cost.png) and
    /// the 3D viewer page (viewer.html).
    #[arg(long)]
    no_pictures: bool,
    /// Take steps with doubts as the best guess: exit status 0 instead of 3. They are still
    /// counted and labelled DOUBTFUL (`"trusted": false` with their doubts in report.json).
    #[arg(long)]
    accept_doubtful: bool,
    /// Also write the map as MCAP for Foxglove and RViz (see `sdem export --mcap`); an
    /// existing file is replaced only with --force.
    #[arg(long, value_name = "OUT.mcap")]
    mcap: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct Report {
    dataset: PathBuf,
    scans: usize,
    nodes: usize,
    resumed_at: Option<usize>,
    /// With --map: the saved map this run extends, and how many nodes it held.
    #[serde(skip_serializing_if = "Option::is_none")]
    extends: Option<ExtendedMap>,
    /// This run's index in the map (0: the run that started it).
    run: usize,
    /// The steps of this run by status: first, tracked, recovered, relocalized,
    /// new_segment, doubtful.
    statuses: std::collections::BTreeMap<&'static str, usize>,
    /// The map's segments at the end; more than one: pieces of the map whose place in the
    /// world is not known (their poses are in their own frames).
    segments: Vec<Segment>,
    time_ms: f64,
    step_time_ms_median: f64,
    localize_time_ms_median: f64,
    bytes_per_node: f64,
    loop_closures_accepted: usize,
    loop_closures_rejected: usize,
    occupied_voxels: usize,
    free_voxels: usize,
    map_points: usize,
    pictures: Vec<PathBuf>,
    /// The MCAP file written with --mcap.
    #[serde(skip_serializing_if = "Option::is_none")]
    mcap: Option<sdem_io::McapSummary>,
    /// Where the attitudes came from: `readings` (attitude.csv) or `unknown`, the readings' σ
    /// and where it came from, in figures and words.
    attitude: SlamAttitude,
    /// No step of the map has doubts.
    trusted: bool,
    /// Steps whose match has doubts (their poses are best guesses).
    doubtful_steps: usize,
    /// The scan indices of those steps.
    doubtful_scans: Vec<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    truth: Option<TrajectoryErrors>,
    #[serde(skip_serializing_if = "Option::is_none")]
    compare: Option<TrajectoryErrors>,
    steps: Vec<Value>,
}

/// The saved map a second run extends (the `extends` of report.json).
#[derive(Serialize)]
struct ExtendedMap {
    /// Its folder.
    map: PathBuf,
    /// Its nodes, before this run.
    nodes: usize,
}

/// What the loop was told about the attitudes (the `attitude` of report.json).
#[derive(Serialize)]
struct SlamAttitude {
    /// `readings` (attitude.csv) or `unknown` (none: each scan's prior is the last estimate).
    source: &'static str,
    /// The σ of the readings, degrees, when it is one for all (sensor.toml's, the default's,
    /// or --attitude-sigma-deg's); null when attitude.csv gives each row its own, or unknown.
    sigma_roll_pitch_deg: Option<f64>,
    /// The heading's σ, degrees, as `sigma_roll_pitch_deg`.
    sigma_yaw_deg: Option<f64>,
    /// Where the σ comes from: `attitude.csv`, `sensor.toml`, `the default`,
    /// `--attitude-sigma-deg`; null when unknown.
    sigma_from: Option<&'static str>,
    /// All of it in words.
    summary: String,
}

/// What the loop is told about the attitudes, with `sigma` (from --attitude-sigma-deg) over
/// the dataset's.
fn slam_attitude(dataset: &Dataset, sigma: Option<AttitudeSigma>) -> SlamAttitude {
    if dataset.attitudes.is_none() {
        return SlamAttitude {
            source: "unknown",
            sigma_roll_pitch_deg: None,
            sigma_yaw_deg: None,
            sigma_from: None,
            summary: "unknown (no attitude.csv): each scan's prior is the last estimate, the \
                      heading searched wider"
                .to_string(),
        };
    }
    let (one_sigma, from) = match (sigma, dataset.attitude_sigma_from) {
        (Some(s), _) => (Some(s), "--attitude-sigma-deg"),
        (None, sdem_io::SigmaSource::AttitudeCsv) => (None, "attitude.csv"),
        (None, from) => (Some(dataset.attitude_sigma), from.describe()),
    };
    let summary = match one_sigma {
        Some(s) => format!(
            "from attitude.csv, compass σ {}°, roll/pitch σ {}° ({from})",
            degrees(s.yaw.to_degrees()),
            degrees(s.roll_pitch.to_degrees())
        ),
        None => "from attitude.csv, each reading with its own σ (attitude.csv)".to_string(),
    };
    SlamAttitude {
        source: "readings",
        sigma_roll_pitch_deg: one_sigma.map(|s| s.roll_pitch.to_degrees()),
        sigma_yaw_deg: one_sigma.map(|s| s.yaw.to_degrees()),
        sigma_from: Some(from),
        summary,
    }
}

/// Parses `--max-scans N`: at least 1.
fn parse_max_scans(text: &str) -> std::result::Result<usize, String> {
    crate::parse::count_in(
        text,
        1..=usize::MAX,
        "0 maps nothing (leave the flag out for every scan)",
    )
}

/// `--attitude-sigma-deg` (parsed and checked as sensor.toml's σ is), which needs attitude.csv.
fn attitude_sigma(args: &Args, dataset: &Dataset) -> Result<Option<AttitudeSigma>> {
    let Some(sigma) = args.attitude_sigma_deg else {
        return Ok(None);
    };
    if dataset.attitudes.is_none() {
        bail!(
            "--attitude-sigma-deg: {} has no attitude.csv, so there is no reading for a σ to \
             describe; add attitude.csv, or drop the flag",
            args.dataset.display()
        );
    }
    Ok(Some(sigma))
}

const MAP_DIR: &str = "map";
const REPORT_FILE: &str = "report.json";
const STEPS_FILE: &str = "steps.json";

/// A run of the loop: the mapper and its step log, fresh or restored from OUT/map.
struct Run {
    slam: Slam,
    /// The log of every step so far, as written to steps.json.
    steps: Vec<Value>,
    /// With `--resume`: the number of nodes the saved map held.
    resumed_at: Option<usize>,
    /// With `--map`: the map extended.
    extends: Option<ExtendedMap>,
    /// OUT/map: the saved map, and the store of the nodes parked far from the robot.
    folder: Arc<MapFolder>,
    /// The datasets of the map's runs before this one, by run (`sdem export` reads each
    /// node's scan from its run's dataset).
    earlier_datasets: Vec<Option<PathBuf>>,
}

/// What the run wrote after its last scan, for the report.
struct Outputs {
    poses: Vec<Pose>,
    cloud: Vec<Vec3>,
    /// The fused map's occupied and free voxels.
    voxel_counts: (usize, usize),
    pictures: Vec<PathBuf>,
    mcap: Option<sdem_io::McapSummary>,
}

/// Runs `sdem slam`: done, or done with doubts (exit status 3) when a step of the map has
/// doubts and `--accept-doubtful` was not given.
pub fn run(args: Args) -> Result<Outcome> {
    check_resume_flags(&args)?;
    let start = Instant::now();
    let dataset = Dataset::open(&args.dataset)?;
    let sigma = attitude_sigma(&args, &dataset)?;
    let map_dir = args.out.join(MAP_DIR);
    if let Some(mcap) = &args.mcap {
        crate::export_mcap::check_target(mcap, args.force)?;
        check_beside_outputs(&args.out, mcap, "--mcap")?;
    }
    // Read before the run: a bad file is refused before the work, and a file among the outputs
    // (OUT/poses.txt of an earlier run) is read as it was, not as this run rewrites it.
    let compare = match &args.compare {
        Some(path) => {
            let poses = read_kitti_poses(path).context("--compare")?;
            let scans = args.max_scans.unwrap_or(dataset.len()).min(dataset.len());
            if poses.len() < scans {
                bail!(
                    "--compare {} holds {} poses, fewer than the {scans} scans to be mapped",
                    path.display(),
                    poses.len()
                );
            }
            Some(poses)
        }
        None => None,
    };
    if let Some(existing) = &args.map {
        check_extended_map(existing, &args.out)?;
    }
    // Held to the end of the run: no other sdem slam writes this folder meanwhile.
    let _lock = prepare_out(&args, &map_dir)?;
    let mut run = match (&args.map, args.resume) {
        (Some(existing), _) => extend(existing, &map_dir)?,
        (None, true) => resume(&args, &map_dir)?,
        (None, false) => start_fresh(&args, &dataset)?,
    };
    if args.resume {
        out_folder::remove_final_outputs(&args.out)?;
    }
    write_config(&args.out, run.slam.config())?;
    let total = map_scans(&args, &dataset, sigma, &map_dir, &mut run)?;
    let outputs = write_outputs(&args, &mut run.slam, &run.steps)?;
    let attitude = slam_attitude(&dataset, sigma);
    let compare = compare_errors(&args, compare.as_deref(), &outputs.poses)?;
    let report = make_report(
        &args,
        &dataset,
        run,
        total,
        (outputs, compare),
        attitude,
        start,
    )?;
    let report_text = serde_json::to_vec_pretty(&report).context("cannot encode the report")?;
    write_atomic(&args.out.join(REPORT_FILE), |w| w.write_all(&report_text))?;
    if args.json {
        print_json(&summary(&report))?;
    } else {
        print_text(&args, &report);
    }
    Ok(Outcome::of(report.trusted, args.accept_doubtful))
}

/// Refuses (a usage error, before anything is read) `--resume` with the flags that would
/// change the saved map's configuration.
fn check_resume_flags(args: &Args) -> Result<()> {
    if args.resume && (args.config.is_some() || args.step.is_some() || args.no_loop_closure) {
        return Err(crate::parse::usage_error(
            "slam",
            "--resume continues with the saved map's configuration; drop --config, --step and \
             --no-loop-closure",
        ));
    }
    Ok(())
}

/// The nodes of the loop's current run.
fn run_nodes(slam: &Slam) -> usize {
    let run = slam.run();
    slam.map.nodes.iter().filter(|n| n.run == run).count()
}

/// Writes `config.toml`: the configuration the run uses, for `--config` and for the record.
fn write_config(out: &Path, config: &SlamOptions) -> Result<()> {
    let config_text = toml::to_string_pretty(config).context("cannot encode the configuration")?;
    write_atomic(&out.join("config.toml"), |w| {
        w.write_all(config_text.as_bytes())
    })?;
    Ok(())
}

/// The loop: maps every scan not mapped yet (up to `--max-scans`), saving the map and the step
/// log after each. Returns the number of scans to be mapped in all.
fn map_scans(
    args: &Args,
    dataset: &Dataset,
    sigma: Option<AttitudeSigma>,
    map_dir: &Path,
    run: &mut Run,
) -> Result<usize> {
    let total = args.max_scans.unwrap_or(dataset.len()).min(dataset.len());
    let first = run_nodes(&run.slam);
    if first > total {
        bail!(
            "the saved map has {first} nodes but only {total} scans are to be processed; give \
             --max-scans {first} or more (or leave it out), with the dataset the map was made from"
        );
    }
    let bar = crate::progress::bar((total - first) as u64, args.json, "scans");
    for index in first..total {
        let step = map_scan(dataset, sigma, &mut run.slam, map_dir, index)?;
        if !args.json {
            bar.suspend(|| eprintln!("{}", step_line(index, total, &step)));
        }
        bar.inc(1);
        let value = serde_json::to_value(&step).context("cannot encode the step")?;
        run.steps.push(with_doubt_messages(value, &step.doubts));
        save_progress(args, map_dir, run)?;
    }
    bar.finish_and_clear();
    Ok(total)
}

/// What an error while mapping scan `index` adds: what is saved and how to go on.
fn saved_note(index: usize, map_dir: &Path) -> String {
    if index == 0 {
        "nothing was mapped yet".to_string()
    } else {
        format!(
            "the map up to scan {} is saved in {}; mend the input and continue with --resume",
            index - 1,
            map_dir.display()
        )
    }
}

/// Reads scan `index` of the dataset and adds it to the map, with its attitude reading and the
/// reading's σ (`sigma` over the dataset's), or none.
fn map_scan(
    dataset: &Dataset,
    sigma: Option<AttitudeSigma>,
    slam: &mut Slam,
    map_dir: &Path,
    index: usize,
) -> Result<StepReport> {
    let points = dataset.load_scan(index).with_context(|| {
        format!(
            "scan {index} cannot be read; {}",
            saved_note(index, map_dir)
        )
    })?;
    let attitude = dataset.attitude(index).map(|a| Attitude {
        sigma: sigma.unwrap_or(a.sigma),
        ..a
    });
    let odometry = match (&dataset.odometry, index) {
        (Some(odometry), i) if i > 0 => Some(Odometry {
            odom_from_sensor: odometry[i],
            odom_from_previous_sensor: odometry[i - 1],
        }),
        _ => None,
    };
    slam.add_scan(&ScanInput {
        scan_index: index,
        points_in_sensor: &points,
        attitude,
        odometry,
    })
    .with_context(|| {
        format!(
            "scan {index} ({}) could not be mapped; {}",
            dataset.scan_paths[index].display(),
            saved_note(index, map_dir)
        )
    })
}

/// The progress line of one step, for stderr.
fn step_line(index: usize, total: usize, step: &StepReport) -> String {
    let closures: Vec<String> = step
        .loop_closures
        .iter()
        .map(|c| {
            if c.accepted {
                format!("loop {}→{} accepted", c.from, c.to)
            } else {
                format!("loop {}→{} rejected ({})", c.from, c.to, c.reason)
            }
        })
        .collect();
    let joins: Vec<String> = (step.joined.iter())
        .map(|j| format!("segment {} joined to {}", j.absorbed, j.into))
        .collect();
    format!(
        "scan {index:4}/{total}: {}  {:6.0} ms  {}  refs {:?}{}{}{}",
        pose_line(&Pose::from(&step.world_from_sensor)),
        step.time_ms,
        status_words(step),
        step.reference_nodes.iter().map(|r| r.0).collect::<Vec<_>>(),
        if closures.is_empty() {
            String::new()
        } else {
            format!("  {}", closures.join(", "))
        },
        if joins.is_empty() {
            String::new()
        } else {
            format!("  {}", joins.join(", "))
        },
        if step.trusted || step.doubts.is_empty() {
            String::new()
        } else {
            let kinds: Vec<&str> = step.doubts.iter().map(|d| d.kind()).collect();
            format!("  DOUBTFUL ({})", kinds.join(", "))
        }
    )
}

/// A step's status in words: `tracked`, `recovered (wider window)`, `NEW SEGMENT 12`, ….
fn status_words(step: &StepReport) -> String {
    match (step.status, step.recovery) {
        (StepStatus::Recovered, Some(how)) => format!("recovered ({})", recovery_words(how)),
        (StepStatus::NewSegment, _) => format!("NEW SEGMENT {}", step.segment),
        (StepStatus::Doubtful, _) => "DOUBTFUL".to_string(),
        (status, _) => status.name().replace('_', " "),
    }
}

/// How a stop was recovered, in words.
fn recovery_words(how: PredictionSource) -> &'static str {
    match how {
        PredictionSource::Odometry => "odometry",
        PredictionSource::ConstantVelocity => "last motion repeated",
        PredictionSource::NoMotion => "no motion",
        PredictionSource::Neighbour => "a linked node's place",
        PredictionSource::OtherNodes => "older nodes",
        PredictionSource::WiderWindow => "wider window",
        PredictionSource::EveryHeading => "every heading",
        PredictionSource::Relocalization => "the whole map",
    }
}

/// Saves the step log, then the map: a kill between the two leaves the log one step ahead of
/// the map, and `--resume` drops that step and maps its scan again, so no step's log is lost.
fn save_progress(args: &Args, map_dir: &Path, run: &mut Run) -> Result<()> {
    let steps_text = serde_json::to_vec(&run.steps).context("cannot encode the step log")?;
    write_atomic(&args.out.join(STEPS_FILE), |w| w.write_all(&steps_text))?;
    let slam = &run.slam;
    debug_assert_eq!(run.folder.path(), map_dir);
    // The dataset's whole path: `sdem export` and `--resume` find it from any folder.
    let dataset = std::fs::canonicalize(&args.dataset).unwrap_or_else(|_| args.dataset.clone());
    let mut datasets = run.earlier_datasets.clone();
    datasets.push(Some(dataset));
    run.folder.save(
        slam.config(),
        &slam.map,
        &slam.edges,
        &slam.loop_closures,
        &datasets,
    )?;
    Ok(())
}

/// Writes the final outputs: poses.txt (+ .tum), map.ply, map.sdemvox and, unless
/// `--no-pictures`, the pictures and viewer.html.
fn write_outputs(args: &Args, slam: &mut Slam, steps: &[Value]) -> Result<Outputs> {
    // The nodes the last loop closures moved are fused again on their final poses first.
    slam.settle_map()?;
    let slam = &*slam;
    // This run's poses, one per scan of the dataset, in the map's frame.
    let run = slam.run();
    let poses: Vec<Pose> = (slam.map.nodes.iter())
        .filter(|n| n.run == run)
        .map(|n| n.world_from_sensor)
        .collect();
    write_poses(&args.out.join("poses.txt"), &poses)?;
    let cloud = slam.merged_cloud()?;
    write_points_ply(&args.out.join("map.ply"), &cloud)?;
    let voxels = slam.voxels()?;
    let voxel_counts = voxels.counts();
    write_voxel_map(&args.out.join("map.sdemvox"), &voxels)?;
    drop(voxels);
    let pictures = if args.no_pictures {
        Vec::new()
    } else {
        crate::cmd_view::write_map_pictures(
            &args.out,
            &crate::cmd_view::map_name(Some(&args.dataset), &args.out),
            &slam.map,
            &slam.loop_closures,
            slam.config(),
            &cloud,
            &node_statuses(slam, steps),
        )?
    };
    let mcap = match &args.mcap {
        Some(path) => Some(crate::export_mcap::write(path, slam)?),
        None => None,
    };
    Ok(Outputs {
        poses,
        cloud,
        voxel_counts,
        pictures,
        mcap,
    })
}

/// Each node's status word from this run's step log (empty for the nodes of earlier runs).
fn node_statuses(slam: &Slam, steps: &[Value]) -> Vec<String> {
    let mut status = vec![String::new(); slam.map.nodes.len()];
    for step in steps {
        if let (Some(node), Some(word)) = (step["node_id"].as_u64(), step["status"].as_str()) {
            if let Some(s) = status.get_mut(node as usize) {
                *s = word.to_string();
            }
        }
    }
    status
}

/// The errors of `poses` against the `--compare` file's poses (`reference`), when given.
fn compare_errors(
    args: &Args,
    reference: Option<&[Pose]>,
    poses: &[Pose],
) -> Result<Option<TrajectoryErrors>> {
    let (Some(path), Some(reference)) = (&args.compare, reference) else {
        return Ok(None);
    };
    if reference.len() < poses.len() {
        bail!(
            "{} holds {} poses, fewer than the {} scans mapped",
            path.display(),
            reference.len(),
            poses.len()
        );
    }
    Ok(Some(trajectory_errors(&reference[..poses.len()], poses)?))
}

/// The median of `v` (the upper one of an even count), 0 when empty.
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The report of the whole run: counts, times, errors against the truth and `--compare`, and
/// every step.
fn make_report(
    args: &Args,
    dataset: &Dataset,
    run: Run,
    total: usize,
    (outputs, compare): (Outputs, Option<TrajectoryErrors>),
    attitude: SlamAttitude,
    start: Instant,
) -> Result<Report> {
    let Outputs {
        poses,
        cloud,
        voxel_counts,
        pictures,
        mcap,
    } = outputs;
    let truth = match &dataset.truth {
        Some(t) => Some(trajectory_errors(&t[..poses.len()], &poses)?),
        None => None,
    };
    let Run {
        slam,
        steps,
        resumed_at,
        extends,
        ..
    } = run;
    let mut statuses = std::collections::BTreeMap::new();
    for step in &steps {
        if let Some(word) = step["status"].as_str().and_then(status_name) {
            *statuses.entry(word).or_insert(0) += 1;
        }
    }
    let doubtful_scans: Vec<u64> = steps
        .iter()
        .filter(|s| s["trusted"] == Value::Bool(false))
        .map(|s| s["scan_index"].as_u64().unwrap_or_default())
        .collect();
    let (occupied_voxels, free_voxels) = voxel_counts;
    let points_total: usize = (0..slam.map.nodes.len())
        .map(|id| slam.node_point_count(id))
        .sum();
    Ok(Report {
        dataset: args.dataset.clone(),
        scans: total,
        nodes: slam.map.nodes.len(),
        resumed_at,
        extends,
        run: slam.run(),
        statuses,
        segments: slam.segments(),
        time_ms: elapsed_ms(start),
        step_time_ms_median: median(field(&steps, "time_ms")),
        localize_time_ms_median: median(field(&steps, "localize_ms")),
        bytes_per_node: (points_total * 12) as f64 / slam.map.nodes.len().max(1) as f64,
        loop_closures_accepted: slam.loop_closures.len(),
        loop_closures_rejected: steps
            .iter()
            .filter_map(|s| s["loop_closures"].as_array())
            .flatten()
            .filter(|c| c["accepted"] == Value::Bool(false))
            .count(),
        occupied_voxels,
        free_voxels,
        map_points: cloud.len(),
        pictures,
        mcap,
        attitude,
        trusted: doubtful_scans.is_empty(),
        doubtful_steps: doubtful_scans.len(),
        doubtful_scans,
        truth,
        compare,
        steps,
    })
}

/// The static name of a status word of the step log.
fn status_name(word: &str) -> Option<&'static str> {
    [
        StepStatus::First,
        StepStatus::Tracked,
        StepStatus::Recovered,
        StepStatus::Relocalized,
        StepStatus::NewSegment,
        StepStatus::Doubtful,
    ]
    .into_iter()
    .map(StepStatus::name)
    .find(|name| *name == word)
}

/// Prints the report as text.
fn print_text(args: &Args, report: &Report) {
    println!(
        "mapped {} scans in {:.1} s (median {:.0} ms per scan); {} loop closures accepted, {} rejected",
        report.nodes - report.extends.as_ref().map_or(0, |e| e.nodes),
        report.time_ms / 1e3,
        report.step_time_ms_median,
        report.loop_closures_accepted,
        report.loop_closures_rejected
    );
    if let Some(n) = report.resumed_at {
        println!(
            "resumed at scan {n}: scans 0 to {} were in the saved map",
            n.max(1) - 1
        );
    }
    if let Some(e) = &report.extends {
        println!(
            "run {} into the map {} ({} nodes before it); the map in {} holds both",
            report.run,
            e.map.display(),
            e.nodes,
            args.out.join(MAP_DIR).display()
        );
    }
    let tally: Vec<String> = (report.statuses.iter())
        .map(|(word, n)| format!("{n} {}", word.replace('_', " ")))
        .collect();
    println!("steps: {}", tally.join(", "));
    if report.segments.len() > 1 {
        let floating: Vec<String> = (report.segments.iter())
            .filter(|s| !s.in_world)
            .map(|s| match s.nodes {
                1 => format!("{} (1 node)", s.id),
                n => format!("{} ({n} nodes)", s.id),
            })
            .collect();
        println!(
            "{} map segments: the world's and {}, whose place in the world is not known (their \
             poses are in their own frames)",
            report.segments.len(),
            floating.join(", ")
        );
    }
    println!("attitude: {}", report.attitude.summary);
    print_doubtful_steps(args, report);
    if let Some(t) = &report.truth {
        println!(
            "against poses_truth.txt: ATE RMSE {:.2} cm (max {:.2} cm), RPE {:.2} cm / {:.3}°",
            t.ate_rmse_m * 100.0,
            t.ate_max_m * 100.0,
            t.rpe_translation_rmse_m * 100.0,
            t.rpe_rotation_rmse_deg
        );
    }
    if let Some(t) = &report.compare {
        println!(
            "against {}: ATE RMSE {:.2} cm (max {:.2} cm), RPE {:.2} cm / {:.3}°",
            args.compare
                .as_deref()
                .map(Path::display)
                .map(|d| d.to_string())
                .unwrap_or_default(),
            t.ate_rmse_m * 100.0,
            t.ate_max_m * 100.0,
            t.rpe_translation_rmse_m * 100.0,
            t.rpe_rotation_rmse_deg
        );
    }
    println!(
        "wrote {}: poses.txt, poses.tum, report.json, steps.json (the step log --resume reads), map.ply ({} points), map.sdemvox ({} occupied voxels), config.toml, map/{}",
        args.out.display(),
        report.map_points,
        report.occupied_voxels,
        if report.pictures.is_empty() {
            ""
        } else {
            ", plan.png, section.png, panorama.png, slice.png, cost.png, viewer.html"
        }
    );
    if let (Some(path), Some(m)) = (&args.mcap, &report.mcap) {
        println!(
            "wrote {} ({:.1} MiB, {} messages) for Foxglove and RViz",
            path.display(),
            m.bytes as f64 / (1024.0 * 1024.0),
            m.messages
        );
    }
}

/// Prints how many steps are doubtful, then each doubtful step's doubts, one `DOUBT:` line each.
fn print_doubtful_steps(args: &Args, report: &Report) {
    println!(
        "{} of {} steps doubtful{}",
        report.doubtful_steps,
        report.steps.len(),
        if report.trusted {
            ""
        } else if args.accept_doubtful {
            " (their poses are best guesses, taken with --accept-doubtful)"
        } else {
            " (their poses are best guesses)"
        }
    );
    for step in &report.steps {
        let status = step["status"].as_str().unwrap_or("");
        match status {
            "recovered" | "relocalized" => println!(
                "  scan {} {}{}",
                step["scan_index"],
                status,
                match serde_json::from_value::<PredictionSource>(step["recovery"].clone()) {
                    Ok(how) => format!(" ({})", recovery_words(how)),
                    Err(_) => step["recovery"]
                        .as_str()
                        .map(|how| format!(" ({})", how.replace('_', " ")))
                        .unwrap_or_default(),
                }
            ),
            "new_segment" => {
                println!(
                    "  scan {} NEW SEGMENT {}: found nowhere with confidence; its pose is a guess",
                    step["scan_index"], step["segment"]
                );
                let attempts = step["attempts"]
                    .as_array()
                    .map(Vec::as_slice)
                    .unwrap_or(&[]);
                if let Some(reason) = attempts.last().and_then(|a| a["reason"].as_str()) {
                    println!("    last search: {reason}");
                }
            }
            _ if step["trusted"] == Value::Bool(false) => {
                println!("  scan {} DOUBTFUL:", step["scan_index"]);
            }
            _ => continue,
        }
        let doubts = step["doubts"].as_array().map(Vec::as_slice).unwrap_or(&[]);
        for doubt in doubts {
            // A step log written by this command has messages; name the kind otherwise.
            let message = doubt["message"].as_str().or(doubt["kind"].as_str());
            println!("    DOUBT: {}", message.unwrap_or("(no reason recorded)"));
        }
    }
}

/// The report without its per-step list, for `--json` on stdout (report.json has it all).
fn summary(report: &Report) -> serde_json::Value {
    let mut value = serde_json::to_value(report).unwrap_or_default();
    if let Some(object) = value.as_object_mut() {
        object.remove("steps");
    }
    value
}

/// A numeric field of every step but the first (which only defines the world).
fn field(steps: &[Value], name: &str) -> Vec<f64> {
    steps
        .iter()
        .filter(|s| s["node_id"].as_u64() != Some(0))
        .filter_map(|s| s[name].as_f64())
        .collect()
}
