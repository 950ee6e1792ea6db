//! `sdem simulate`: a simulated collapsed-building run written as a dataset folder.

use crate::output::print_json;
use crate::parse::{count_in, non_negative_degrees, number_in, usage_error};
use anyhow::{Context, Result};
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use sdem::sensor::SensorConfig;
use sdem_sim::faults::{simulate_run_with_faults, Fault, FaultConfig, Injected, TILT_NOT_INJECTED};
use sdem_sim::odometry::{simulate_odometry, OdometryNoise};
use sdem_sim::sim::{self, LongRoute};
use serde::Serialize;
use std::ops::Bound;
use std::path::{Path, PathBuf};

/// Arguments of `sdem simulate`.
#[derive(clap::Args)]
pub struct Args {
    /// The dataset folder to write; refused when it already holds a file a dataset has
    /// (scans/, attitude.csv, poses_truth.txt, sensor.toml, …), unless --force.
    #[arg(long)]
    out: PathBuf,
    /// Seed of the scene, the path and the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Number of stops: up to 40 in the collapsed building, up to 100,000 on a --route.
    #[arg(long, default_value_t = 8, allow_hyphen_values = true, value_parser = parse_stops)]
    stops: usize,
    /// A long route instead of the collapsed building: room-laps (laps of a furnished room,
    /// 30 stops a lap), floor (3 x 3 rooms toured in three different laps), wings (two wings
    /// joined by a low ditch and a corridor). Lap after lap, as many stops as --stops asks,
    /// with loops to close. Faults cannot be injected on them.
    #[arg(long, value_name = "ROUTE", conflicts_with = "faults", value_parser = named::<LongRoute>(LongRoute::ALL.map(LongRoute::name)))]
    route: Option<LongRoute>,
    /// Standard deviation of the range noise, metres.
    #[arg(
        long,
        default_value_t = 0.005,
        allow_hyphen_values = true,
        value_parser = parse_range_noise
    )]
    range_noise: f64,
    /// Standard deviation of the compass heading reading, degrees.
    #[arg(long, allow_hyphen_values = true, value_parser = non_negative_degrees)]
    compass_noise_deg: Option<f64>,
    /// Drop returns beyond this range, metres (the paper trusts 3 m).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_trusted_range)]
    trusted_range: Option<f64>,
    /// The scanner's angular step, tilt and pan alike, degrees (the paper's 1°; 0.5° gives four
    /// times the points). The dataset's `sensor.toml` says it, so the S-DEM grid matches it.
    #[arg(
        long,
        default_value_t = SensorConfig::default().pan_step_deg,
        allow_hyphen_values = true,
        value_parser = parse_step_deg
    )]
    step_deg: f64,
    /// Do not write odometry.txt (the dead-reckoned poses, written by default).
    #[arg(long)]
    no_odometry: bool,
    /// Odometry translation noise per step and axis, as a fraction of the step's length
    /// (0.05: a 35 cm step is off by about 2 cm).
    #[arg(
        long,
        default_value_t = OdometryNoise::default().translation_frac,
        allow_hyphen_values = true,
        value_parser = parse_odometry_noise
    )]
    odometry_noise: f64,
    /// Odometry heading (yaw) noise per step, degrees; it accumulates (dead reckoning drifts).
    #[arg(
        long,
        default_value_t = OdometryNoise::default().yaw_deg_per_step,
        allow_hyphen_values = true,
        value_parser = non_negative_degrees
    )]
    odometry_yaw_noise_deg: f64,
    /// Write into a folder that already holds a dataset: its scans, sweeps, attitudes, odometry,
    /// truth and sensor file are removed first, so no old file mixes into the new dataset.
    #[arg(long)]
    force: bool,
    /// Inject a fault of a disaster site at every stop (repeat the flag): compass (heading off
    /// by up to ±20°), gyro-drift (roll and pitch readings drift, up to ±2°), dust (5 % of beams
    /// return from dust), missing (30 % of returns lost), rubble (a block moved in view before
    /// each stop), person (someone walks through each sweep). `tilt` is measured by `sdem bench
    /// --faults`, not injected into a route.
    #[arg(long = "fault", value_name = "FAULT", value_parser = fault_parser())]
    faults: Vec<Fault>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct Summary {
    out: PathBuf,
    seed: u64,
    /// The long route, when one was asked for (`null`: the collapsed building).
    route: Option<LongRoute>,
    /// Where each lap begins, on a long route.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    lap_starts: Vec<usize>,
    stops: usize,
    points_per_scan: Vec<usize>,
    odometry: bool,
    faults: Vec<Fault>,
    /// Per stop, what the faults did (empty without faults).
    injected: Vec<Injected>,
}

/// Runs `sdem simulate`.
pub fn run(args: Args) -> Result<()> {
    let route = args.route;
    check_stops(args.stops, route)?;
    crate::output::check_output_folder(&args.out, "--out", sdem_io::DATASET_ENTRIES, args.force)?;
    let sensor = sensor_config(&args)?;
    let odometry_noise = OdometryNoise {
        translation_frac: args.odometry_noise,
        yaw_deg_per_step: args.odometry_yaw_noise_deg,
    };
    if let Some(route) = route {
        let summary = write_long_run(&args, route, &sensor, &odometry_noise)?;
        if args.json {
            return print_json(&summary);
        }
        print_text(&args, &summary);
        return Ok(());
    }
    let faults = args.faults.clone();
    let (run, injected) = simulate(&args, &sensor, &faults)?;
    let summary = write(&args, &sensor, &odometry_noise, &run, faults, injected)?;
    if args.json {
        return print_json(&summary);
    }
    print_text(&args, &summary);
    Ok(())
}

/// Parses `--stops N`: at least 1, and at most a long route's [`sim::MAX_LONG_STOPS`]
/// ([`check_stops`] holds the collapsed building to its own).
fn parse_stops(text: &str) -> std::result::Result<usize, String> {
    let why = format!(
        "up to {} in the collapsed building, {} on a --route",
        sim::MAX_STOPS,
        sim::MAX_LONG_STOPS
    );
    count_in(text, 1..=sim::MAX_LONG_STOPS, &why)
}

/// Refuses (a usage error) more `--stops` than the collapsed building's route holds when no
/// `--route` is given.
fn check_stops(stops: usize, route: Option<LongRoute>) -> Result<()> {
    if route.is_none() && stops > sim::MAX_STOPS {
        return Err(usage_error(
            "simulate",
            format!(
                "--stops {stops} must lie in 1..={} in the collapsed building (its route holds \
                 {} stops); a --route takes up to {}",
                sim::MAX_STOPS,
                sim::MAX_STOPS,
                sim::MAX_LONG_STOPS
            ),
        ));
    }
    Ok(())
}

/// Parses `--range-noise M`: a standard deviation below the scanner's largest range.
fn parse_range_noise(text: &str) -> std::result::Result<f64, String> {
    let max_range_m = SensorConfig::default().max_range_m;
    let what = format!(
        "a number of metres in [0, {max_range_m}), a standard deviation below the scanner's \
         {max_range_m} m range (the SICK's is 0.005)"
    );
    number_in(text, 0.0..max_range_m, &what)
}

/// Parses `--trusted-range M`: beyond the closest return kept.
fn parse_trusted_range(text: &str) -> std::result::Result<f64, String> {
    let min_range_m = SensorConfig::default().min_range_m;
    let what = format!(
        "a number of metres above {min_range_m}, the closest return kept (the paper trusts 3)"
    );
    number_in(
        text,
        (Bound::Excluded(min_range_m), Bound::Unbounded),
        &what,
    )
}

/// The finest `--step-deg`: 0.25° sweeps a scan of some 250,000 beams.
const MIN_STEP_DEG: f64 = 0.25;
/// The coarsest `--step-deg`: coarser sweeps hold too few points a scan to localize.
const MAX_STEP_DEG: f64 = 5.0;

/// Parses `--step-deg DEG`: within [`MIN_STEP_DEG`] and [`MAX_STEP_DEG`].
fn parse_step_deg(text: &str) -> std::result::Result<f64, String> {
    let what = format!(
        "a number of degrees in [{MIN_STEP_DEG}, {MAX_STEP_DEG}] ({MIN_STEP_DEG}° sweeps a scan \
         of some 250,000 beams; coarser than {MAX_STEP_DEG}° leaves too few points to localize)"
    );
    number_in(text, MIN_STEP_DEG..=MAX_STEP_DEG, &what)
}

/// Parses `--odometry-noise FRACTION`.
fn parse_odometry_noise(text: &str) -> std::result::Result<f64, String> {
    number_in(
        text,
        0.0..,
        "a finite fraction ≥ 0 of each step's length (0.05: a 35 cm step off by about 2 cm)",
    )
}

/// The sensor model from the arguments (each in its range, by its parser), validated.
fn sensor_config(args: &Args) -> Result<SensorConfig> {
    let mut sensor = SensorConfig {
        range_noise_m: args.range_noise,
        trusted_range_m: args.trusted_range,
        tilt_step_deg: args.step_deg,
        pan_step_deg: args.step_deg,
        ..Default::default()
    };
    if let Some(c) = args.compass_noise_deg {
        sensor.compass_noise_deg = c;
    }
    sensor.validate()?;
    Ok(sensor)
}

/// A parser of the names `names` (a usage error listing them, and `--help`), each read as a `T`.
/// The names are `T`'s own, so each reads; were one not to, clap would refuse it as a usage
/// error too.
fn named<T>(
    names: impl IntoIterator<Item = impl Into<PossibleValue>>,
) -> impl TypedValueParser<Value = T>
where
    T: std::str::FromStr + Clone + Send + Sync + 'static,
    T::Err: std::fmt::Debug,
{
    PossibleValuesParser::new(names).try_map(|name| name.parse().map_err(|e| format!("{e:?}")))
}

/// The parser of `--fault`: a fault's name (a usage error listing them, and `--help`), and
/// `tilt`, which no run can inject, a usage error saying what measures it instead
/// ([`TILT_NOT_INJECTED`]). `tilt` is left out of the names listed.
fn fault_parser() -> impl TypedValueParser<Value = Fault> {
    let names = Fault::ALL.map(|f| PossibleValue::new(f.name()).hide(f == Fault::Tilt));
    named::<Fault>(names).try_map(|fault| match fault {
        Fault::Tilt => Err(TILT_NOT_INJECTED),
        fault => Ok(fault),
    })
}

/// Simulates the route's sweeps, with `faults` injected at every stop; returns the stops and,
/// per stop, what the faults did (empty without faults).
fn simulate(
    args: &Args,
    sensor: &SensorConfig,
    faults: &[Fault],
) -> Result<(Vec<sim::SimStop>, Vec<Injected>)> {
    let scene = sim::collapsed_building(args.seed);
    let stops = sim::collapsed_building_stops(&scene, args.seed, args.stops, &sensor.lift)?;
    let bar = crate::progress::bar(1, args.json, "simulating the sweeps");
    let (run, injected) = if faults.is_empty() {
        (
            sim::simulate_run(&scene, &stops, sensor, args.seed)?,
            Vec::new(),
        )
    } else {
        simulate_run_with_faults(
            &scene,
            &stops,
            sensor,
            args.seed,
            faults,
            &FaultConfig::default(),
        )?
    };
    bar.finish_and_clear();
    Ok((run, injected))
}

/// Writes the dataset folder (after clearing the old one with `--force`): scans, sweeps, truth,
/// odometry unless `--no-odometry`, the sensor model. Returns what was written.
fn write(
    args: &Args,
    sensor: &SensorConfig,
    odometry_noise: &OdometryNoise,
    run: &[sim::SimStop],
    faults: Vec<Fault>,
    injected: Vec<Injected>,
) -> Result<Summary> {
    let scans: Vec<_> = run
        .iter()
        .map(|s| (s.sweep.points_in_sensor(), s.sweep.mean_attitude()))
        .collect();
    let sweeps: Vec<_> = run.iter().map(|s| s.sweep.clone()).collect();
    if args.force {
        remove_old_dataset(&args.out)?;
    }
    let truth: Vec<_> = run.iter().map(|s| s.world_from_sensor).collect();
    let odometry = if args.no_odometry {
        None
    } else {
        Some(simulate_odometry(&truth, odometry_noise, args.seed)?)
    };
    sdem_io::write_dataset(
        &args.out,
        sensor,
        &scans,
        Some(&sweeps),
        Some(&truth),
        odometry.as_deref(),
    )?;
    Ok(Summary {
        out: args.out.clone(),
        seed: args.seed,
        route: None,
        lap_starts: Vec::new(),
        stops: run.len(),
        points_per_scan: scans.iter().map(|s| s.0.len()).collect(),
        odometry: odometry.is_some(),
        faults,
        injected,
    })
}

/// Stops simulated at a time on a long route (their sweeps are held until written).
const LONG_CHUNK: usize = 32;

/// Simulates a long route a chunk of stops at a time and writes each stop as it comes, so
/// that thousands of stops never sit in memory together.
fn write_long_run(
    args: &Args,
    route: LongRoute,
    sensor: &SensorConfig,
    odometry_noise: &OdometryNoise,
) -> Result<Summary> {
    let run = sim::long_run(route, args.seed, args.stops, &sensor.lift)?;
    let truth = run.truth(&sensor.lift)?;
    let odometry = if args.no_odometry {
        None
    } else {
        Some(simulate_odometry(&truth, odometry_noise, args.seed)?)
    };
    if args.force {
        remove_old_dataset(&args.out)?;
    }
    let plan = sdem_io::DatasetPlan {
        scans: run.stops.len(),
        with_sweeps: true,
        truth: Some(&truth),
        odometry: odometry.as_deref(),
    };
    let bar = crate::progress::bar(run.stops.len() as u64, args.json, "stops simulated");
    let mut chunk: Vec<sim::SimStop> = Vec::new();
    let mut points_per_scan = Vec::with_capacity(run.stops.len());
    sdem_io::write_dataset_streamed(&args.out, sensor, &plan, |i| {
        if i % LONG_CHUNK == 0 {
            let end = (i + LONG_CHUNK).min(run.stops.len());
            chunk = run.simulate(sensor, args.seed, i..end)?;
        }
        bar.inc(1);
        let stop = &chunk[i % LONG_CHUNK];
        let points = stop.sweep.points_in_sensor();
        points_per_scan.push(points.len());
        Ok(sdem_io::StreamedScan {
            points: points.into(),
            attitude: stop.sweep.mean_attitude(),
            sweep: Some(std::borrow::Cow::Owned(stop.sweep.clone())),
        })
    })?;
    bar.finish_and_clear();
    Ok(Summary {
        out: args.out.clone(),
        seed: args.seed,
        route: Some(route),
        lap_starts: run.lap_starts.clone(),
        stops: run.stops.len(),
        points_per_scan,
        odometry: odometry.is_some(),
        faults: Vec::new(),
        injected: Vec::new(),
    })
}

/// Prints the summary as text.
fn print_text(args: &Args, summary: &Summary) {
    let what = match summary.route {
        Some(route) => format!(
            "the {} route ({} laps)",
            route.name(),
            summary.lap_starts.len()
        ),
        None => "a collapsed building".to_string(),
    };
    println!(
        "wrote {} stops of {what} (seed {}) to {}",
        summary.stops,
        summary.seed,
        args.out.display()
    );
    let n = &summary.points_per_scan;
    println!(
        "  {}..{} returns per scan; truth in poses_truth.txt, {}raw sweeps in sweeps/",
        n.iter().min().unwrap_or(&0),
        n.iter().max().unwrap_or(&0),
        if summary.odometry {
            "dead-reckoned poses in odometry.txt, "
        } else {
            ""
        }
    );
    if !summary.faults.is_empty() {
        let names: Vec<&str> = summary.faults.iter().map(|f| f.name()).collect();
        let total = |f: fn(&Injected) -> usize| summary.injected.iter().map(f).sum::<usize>();
        println!(
            "  faults {}: {} dust returns, {} returns lost, {} on a person, {} on moved rubble; \
             the readings carry the compass and gyro errors (see --json)",
            names.join(", "),
            total(|i| i.dust_returns),
            total(|i| i.lost_returns),
            total(|i| i.person_returns),
            total(|i| i.rubble_returns)
        );
    }
}

/// Removes the files of the dataset in `root` that sdem writes (and nothing else).
fn remove_old_dataset(root: &Path) -> Result<()> {
    sdem_io::clear_dataset(root).with_context(|| {
        format!(
            "cannot remove the old dataset in {} for --force",
            root.display()
        )
    })
}
