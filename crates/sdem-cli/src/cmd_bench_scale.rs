//! `sdem bench --suite scale`: the stop-and-go loop on long simulated routes (laps of a room,
//! a floor of rooms, two wings joined by a ditch), with odometry and a compass off by σ 2°,
//! measured as the map grows: time per stop, time of loop closure and of the graph solve, peak
//! memory, the map's size on disk and the trajectory error, at each map size asked for; and a
//! plot of time per stop against stop number.
//!
//! The figures at a size `N` are taken over the stops that brought the map from
//! `N − min(100, N/2)` to `N` nodes (time per stop), or over the whole run up to `N` (loop
//! closure, graph solve, the trajectory error of all `N` poses against the truth); the peak
//! memory is the process's since the route began (the simulator's scans of the moment
//! included), and the map is saved at each size as `sdem slam` saves it.

use crate::output::{elapsed_ms, print_json};
use anyhow::{Context, Result};
use sdem::geometry::Pose;
use sdem::sensor::SensorConfig;
use sdem::slam::{trajectory_errors, Odometry, ScanInput, Slam, SlamOptions, StepReport};
use sdem_io::MapFolder;
use sdem_sim::benchmark::{summarize, Stats};
use sdem_sim::odometry::{simulate_odometry, OdometryNoise};
use sdem_sim::sim::{long_run, LongRoute, LongRun};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

mod print;

/// Map sizes measured by default, and with `--quick`.
pub const DEFAULT_SIZES: (&[usize], &[usize]) = (&[100, 300, 1000], &[100]);
/// The compass's σ on the routes, degrees.
const COMPASS_SIGMA_DEG: f64 = 2.0;
/// Stops simulated at a time (their sweeps are held until mapped).
const CHUNK: usize = 16;
/// The window of stops whose times a size's figures take: at most this many.
const WINDOW_STOPS: usize = 100;
/// The plot's file when `--plot` is not given.
pub const DEFAULT_PLOT: &str = "scale.png";

/// What the scale suite is asked.
pub struct ScaleArgs {
    /// Map sizes, increasing.
    pub sizes: Vec<usize>,
    /// Routes, in order.
    pub routes: Vec<LongRoute>,
    /// Where the plot goes.
    pub plot: PathBuf,
    pub seed: u64,
    pub json: bool,
}

/// One route's run.
#[derive(Debug, Clone, Serialize)]
pub struct RouteReport {
    route: &'static str,
    stops: usize,
    laps: usize,
    /// Stops the loop could not map (an error: no match), by stop index.
    failed_stops: Vec<usize>,
    /// Stops mapped with doubts.
    doubtful_stops: usize,
    loop_closures_accepted: usize,
    loop_closures_rejected: usize,
    /// The figures at each size.
    sizes: Vec<SizeReport>,
    /// Median time per stop of each lap, ms.
    lap_median_ms: Vec<f64>,
    /// Median CPU time per stop of each lap, every thread together, ms (empty off Linux).
    lap_cpu_median_ms: Vec<f64>,
    /// Every stop's time, ms (NaN for a failed stop), in stop order.
    time_per_stop_ms: Vec<f64>,
    /// After the last stop, the map settled as `sdem slam` settles it before it writes its
    /// outputs (every node fused into the voxel map, which the steps leave to a view or a
    /// save): how long it took, ms …
    settle_ms: f64,
    /// … the voxels it fused …
    fused_voxels: usize,
    /// … and the process's peak resident memory since the route began, settling included,
    /// MiB (`None` off Linux).
    peak_memory_settled_mib: Option<f64>,
}

/// The figures when the map reached a size.
#[derive(Debug, Clone, Serialize)]
pub struct SizeReport {
    nodes: usize,
    /// The stops the time per stop is taken over, `[from, to)`.
    window: [usize; 2],
    time_per_stop_ms: Stats,
    /// CPU time per stop over the same stops, every thread together, ms: unlike the wall
    /// time, what other jobs take from the machine does not count (`None` off Linux).
    cpu_per_stop_ms: Option<Stats>,
    localize_ms: Stats,
    /// Loop closure (the candidates' verification and the graph solve) at the stops that
    /// checked any, up to this size, ms.
    loop_closure_ms: Stats,
    /// The map's upkeep per stop (moved nodes fused again, far nodes parked), over the window,
    /// ms.
    map_update_ms: Stats,
    /// Nodes the solves were free to move, up to this size: median and largest.
    solve_free_nodes: Stats,
    /// Nodes holding their points in memory (the others are in the saved map's files).
    resident_nodes: usize,
    /// Graph solves up to this size, ms.
    solve_ms: Stats,
    /// The process's peak resident memory since the route began, MiB (`None` off Linux).
    peak_memory_mib: Option<f64>,
    /// The memory resident when the map reached this size, MiB.
    resident_memory_mib: Option<f64>,
    /// The saved map's files, MiB, and how long saving took, ms.
    map_on_disk_mib: f64,
    save_ms: f64,
    /// The trajectory's error against the truth over every pose so far, metres.
    ate_rmse_m: f64,
    ate_max_m: f64,
}

/// Laps of a room: the first lap's time per stop against the later ones'.
#[derive(Debug, Clone, Serialize)]
pub struct FlatReport {
    first_lap_median_ms: f64,
    fourth_lap_median_ms: Option<f64>,
    last_lap_median_ms: f64,
    laps: usize,
    /// The fourth lap's median over the first's (the target: ≤ 1.5).
    fourth_over_first: Option<f64>,
    last_over_first: f64,
    /// The same two ratios of the CPU time per stop, which other jobs on the machine do not
    /// move (`None` off Linux).
    fourth_over_first_cpu: Option<f64>,
    last_over_first_cpu: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
struct Report {
    suite: &'static str,
    threads: usize,
    seed: u64,
    compass_sigma_deg: f64,
    sizes: Vec<usize>,
    flat: Option<FlatReport>,
    routes: Vec<RouteReport>,
    plot: Option<PathBuf>,
}

/// Refuses (a usage error) `--sizes` that do not increase; each size is at least 1 node
/// (`parse::positive_count`).
pub fn check_sizes(sizes: &[usize]) -> Result<()> {
    match sizes.windows(2).find(|w| w[0] >= w[1]) {
        Some(w) => Err(crate::parse::usage_error(
            "bench",
            format!(
                "--sizes must increase, each map size larger than the last (e.g. \
                 100,300,1000): {} is followed by {}",
                w[0], w[1]
            ),
        )),
        None => Ok(()),
    }
}

/// Runs the suite.
pub fn run(args: &ScaleArgs, say: &dyn Fn(&str)) -> Result<()> {
    let mut routes = Vec::new();
    for &route in &args.routes {
        routes.push(run_route(route, args, say)?);
    }
    let flat = routes
        .iter()
        .find(|r| r.route == LongRoute::RoomLaps.name())
        .and_then(flat_report);
    let plot = write_plot(&args.plot, &routes)?;
    let report = Report {
        suite: "scale",
        threads: rayon::current_num_threads(),
        seed: args.seed,
        compass_sigma_deg: COMPASS_SIGMA_DEG,
        sizes: args.sizes.clone(),
        flat,
        routes,
        plot,
    };
    if args.json {
        return print_json(&report);
    }
    print::print_report(&report);
    Ok(())
}

/// The sensor of the routes: the default tilting scanner, its compass off by σ 2°.
fn sensor() -> SensorConfig {
    SensorConfig {
        compass_noise_deg: COMPASS_SIGMA_DEG,
        ..Default::default()
    }
}

/// Maps one route up to the largest size, taking the figures at each size.
fn run_route(route: LongRoute, args: &ScaleArgs, say: &dyn Fn(&str)) -> Result<RouteReport> {
    let sensor = sensor();
    let stops = *args.sizes.last().expect("checked non-empty");
    say(&format!("{}: placing {stops} stops ...", route.name()));
    let run = long_run(route, args.seed, stops, &sensor.lift)?;
    let truth = run.truth(&sensor.lift)?;
    let odometry = simulate_odometry(&truth, &OdometryNoise::default(), args.seed)?;
    let map_dir = scratch_dir(route)?;
    let result = map_route(&run, &truth, &odometry, &sensor, args, &map_dir, say);
    let _ = std::fs::remove_dir_all(&map_dir);
    result
}

/// A fresh folder for the route's saved map, removed when the route is done.
fn scratch_dir(route: LongRoute) -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!(
        "sdem-bench-scale-{}-{}",
        std::process::id(),
        route.name()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    Ok(dir)
}

/// What the loop did at each stop, as the figures need it.
struct StopRecord {
    time_ms: f64,
    /// CPU time of every thread, ms (`None` off Linux).
    cpu_ms: Option<f64>,
    report: Option<StepReport>,
}

/// The loop over the route's stops, simulated a chunk at a time.
fn map_route(
    run: &LongRun,
    truth: &[Pose],
    odometry: &[Pose],
    sensor: &SensorConfig,
    args: &ScaleArgs,
    map_dir: &Path,
    say: &dyn Fn(&str),
) -> Result<RouteReport> {
    let stops = run.stops.len();
    crate::memory::reset_peak();
    let mut slam = Slam::new(SlamOptions::default())?;
    let folder = Arc::new(MapFolder::create(map_dir)?);
    slam.set_node_store(folder.clone());
    let mut records: Vec<StopRecord> = Vec::with_capacity(stops);
    // The stop each node was mapped from, and the last stop mapped.
    let mut mapped: Vec<usize> = Vec::new();
    let mut sizes = Vec::new();
    let bar = crate::progress::bar(stops as u64, args.json, run.route.name());
    for chunk in (0..stops).step_by(CHUNK) {
        let sims = run.simulate(sensor, args.seed, chunk..(chunk + CHUNK).min(stops))?;
        for (k, sim) in sims.iter().enumerate() {
            let index = chunk + k;
            let points = sim.sweep.points_in_sensor();
            let odometry = mapped.last().map(|&previous| Odometry {
                odom_from_sensor: odometry[index],
                odom_from_previous_sensor: odometry[previous],
            });
            let (start, cpu_start) = (Instant::now(), crate::cpu::used_ms());
            let step = slam.add_scan(&ScanInput {
                scan_index: index,
                points_in_sensor: &points,
                attitude: Some(sim.sweep.mean_attitude()),
                odometry,
            });
            let (time_ms, cpu_ms) = (elapsed_ms(start), crate::cpu::since_ms(cpu_start));
            let report = match step {
                Ok(report) => {
                    mapped.push(index);
                    Some(report)
                }
                Err(e) if e.is_no_match() => None,
                Err(e) => {
                    return Err(e).with_context(|| format!("{}: stop {index}", run.route.name()))
                }
            };
            records.push(StopRecord {
                time_ms,
                cpu_ms,
                report,
            });
            bar.inc(1);
            if args.sizes.contains(&(index + 1)) {
                let size = SizeInput {
                    slam: &slam,
                    records: &records,
                    truth,
                    mapped: &mapped,
                };
                let figures = size.report(&folder)?;
                bar.suspend(|| say(&size_line(run.route, &figures)));
                sizes.push(figures);
            }
        }
    }
    bar.finish_and_clear();
    say(&format!(
        "{}: settling the map (the fused voxel map) ...",
        run.route.name()
    ));
    let start = Instant::now();
    slam.settle_map()?;
    let settle_ms = elapsed_ms(start);
    let (occupied, free) = slam.voxels()?.counts();
    let mut report = route_report(run, &records, sizes);
    report.settle_ms = settle_ms;
    report.fused_voxels = occupied + free;
    report.peak_memory_settled_mib = crate::memory::peak_mib();
    Ok(report)
}

/// What the figures at a size are taken from.
struct SizeInput<'a> {
    slam: &'a Slam,
    records: &'a [StopRecord],
    truth: &'a [Pose],
    mapped: &'a [usize],
}

impl SizeInput<'_> {
    fn report(&self, folder: &MapFolder) -> Result<SizeReport> {
        let n = self.records.len();
        let from = n - WINDOW_STOPS.min(n / 2).max(1).min(n);
        let window = &self.records[from..];
        let times: Vec<f64> = window
            .iter()
            .filter(|r| r.report.is_some())
            .map(|r| r.time_ms)
            .collect();
        let cpu: Option<Vec<f64>> = window
            .iter()
            .filter(|r| r.report.is_some())
            .map(|r| r.cpu_ms)
            .collect();
        let reports = || self.records.iter().filter_map(|r| r.report.as_ref());
        let localize: Vec<f64> = window
            .iter()
            .filter_map(|r| r.report.as_ref())
            .map(|r| r.localize_ms)
            .collect();
        let closures: Vec<f64> = reports()
            .filter(|r| !r.loop_closures.is_empty())
            .map(|r| r.loop_closure_ms)
            .collect();
        let solves: Vec<f64> = reports()
            .filter_map(|r| r.optimization.as_ref())
            .map(|o| o.time_ms)
            .collect();
        let free: Vec<f64> = reports()
            .filter_map(|r| r.optimization.as_ref())
            .map(|o| o.free_nodes as f64)
            .collect();
        let upkeep: Vec<f64> = window
            .iter()
            .filter_map(|r| r.report.as_ref())
            .map(|r| r.map_update_ms)
            .collect();
        let truth: Vec<Pose> = self.mapped.iter().map(|&i| self.truth[i]).collect();
        let errors = trajectory_errors(&truth, &self.slam.poses())?;
        let save_start = Instant::now();
        let slam = self.slam;
        folder.save_slam(slam)?;
        let save_ms = elapsed_ms(save_start);
        Ok(SizeReport {
            nodes: slam.map.nodes.len(),
            window: [from, n],
            time_per_stop_ms: summarize(&times),
            cpu_per_stop_ms: cpu.map(|c| summarize(&c)),
            localize_ms: summarize(&localize),
            loop_closure_ms: summarize(&closures),
            map_update_ms: summarize(&upkeep),
            solve_free_nodes: summarize(&free),
            resident_nodes: slam.resident_nodes(),
            solve_ms: summarize(&solves),
            peak_memory_mib: crate::memory::peak_mib(),
            resident_memory_mib: crate::memory::resident_mib(),
            map_on_disk_mib: folder_bytes(folder.path()) as f64 / (1024.0 * 1024.0),
            save_ms,
            ate_rmse_m: errors.ate_rmse_m,
            ate_max_m: errors.ate_max_m,
        })
    }
}

/// The bytes of every file under `dir`.
fn folder_bytes(dir: &Path) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .map(|e| match e.file_type() {
            Ok(t) if t.is_dir() => folder_bytes(&e.path()),
            Ok(_) => e.metadata().map_or(0, |m| m.len()),
            Err(_) => 0,
        })
        .sum()
}

fn size_line(route: LongRoute, s: &SizeReport) -> String {
    format!(
        "{}: {} nodes, time per stop median {:.0} ms, p95 {:.0} ms (CPU {} ms); ATE {:.2} cm; \
         peak {} MiB",
        route.name(),
        s.nodes,
        s.time_per_stop_ms.median,
        s.time_per_stop_ms.p95,
        s.cpu_per_stop_ms
            .as_ref()
            .map_or("?".to_string(), |c| format!("{:.0}", c.median)),
        s.ate_rmse_m * 100.0,
        s.peak_memory_mib
            .map_or("?".to_string(), |m| format!("{m:.0}"))
    )
}

fn route_report(run: &LongRun, records: &[StopRecord], sizes: Vec<SizeReport>) -> RouteReport {
    let reports = || records.iter().filter_map(|r| r.report.as_ref());
    let accepted = reports()
        .flat_map(|r| &r.loop_closures)
        .filter(|c| c.accepted)
        .count();
    let checked = reports().map(|r| r.loop_closures.len()).sum::<usize>();
    let mut bounds = run.lap_starts.clone();
    bounds.push(records.len());
    let lap_medians = |time: fn(&StopRecord) -> Option<f64>| -> Option<Vec<f64>> {
        (bounds.windows(2))
            .filter(|w| w[1] > w[0])
            .map(|w| {
                let times: Option<Vec<f64>> = (records[w[0]..w[1]].iter())
                    .filter(|r| r.report.is_some())
                    .map(time)
                    .collect();
                times.map(|t| summarize(&t).median)
            })
            .collect()
    };
    let lap_median_ms = lap_medians(|r| Some(r.time_ms)).unwrap_or_default();
    let lap_cpu_median_ms = lap_medians(|r| r.cpu_ms).unwrap_or_default();
    RouteReport {
        route: run.route.name(),
        stops: records.len(),
        laps: run.lap_starts.len(),
        failed_stops: (records.iter().enumerate())
            .filter(|(_, r)| r.report.is_none())
            .map(|(i, _)| i)
            .collect(),
        doubtful_stops: reports().filter(|r| !r.trusted).count(),
        loop_closures_accepted: accepted,
        loop_closures_rejected: checked - accepted,
        sizes,
        lap_median_ms,
        lap_cpu_median_ms,
        time_per_stop_ms: records
            .iter()
            .map(|r| {
                if r.report.is_some() {
                    r.time_ms
                } else {
                    f64::NAN
                }
            })
            .collect(),
        settle_ms: 0.0,
        fused_voxels: 0,
        peak_memory_settled_mib: None,
    }
}

/// The first lap against the fourth and the last, when the room was lapped at least twice.
fn flat_report(route: &RouteReport) -> Option<FlatReport> {
    let laps = &route.lap_median_ms;
    let (&first, &last) = (laps.first()?, laps.last()?);
    if laps.len() < 2 {
        return None;
    }
    let fourth = laps.get(3).copied();
    let cpu = &route.lap_cpu_median_ms;
    let cpu_ratio = |lap: Option<&f64>| Some(lap? / cpu.first()?);
    Some(FlatReport {
        fourth_over_first_cpu: cpu_ratio(cpu.get(3)),
        last_over_first_cpu: cpu_ratio(cpu.last()),
        first_lap_median_ms: first,
        fourth_lap_median_ms: fourth,
        last_lap_median_ms: last,
        laps: laps.len(),
        fourth_over_first: fourth.map(|f| f / first),
        last_over_first: last / first,
    })
}

/// Writes the plot of time per stop against stop number, one series per route.
fn write_plot(path: &Path, routes: &[RouteReport]) -> Result<Option<PathBuf>> {
    if routes.is_empty() {
        return Ok(None);
    }
    let series: Vec<sdem_viz::Series> = routes
        .iter()
        .map(|r| sdem_viz::Series {
            label: r.route.to_string(),
            points: (r.time_per_stop_ms.iter().enumerate())
                .map(|(i, &t)| (i as f64, t))
                .collect(),
        })
        .collect();
    let note = format!(
        "sdem slam's loop on simulated routes, odometry, compass σ {COMPASS_SIGMA_DEG}°, {} threads",
        rayon::current_num_threads()
    );
    let picture = sdem_viz::series_plot(
        &series,
        "Time per stop as the map grows",
        &note,
        "stop (= nodes in the map)",
        "time per stop, ms",
    );
    let png = sdem_viz::encode_png(&picture)?;
    sdem_io::write_atomic(path, |w| w.write_all(&png))?;
    Ok(Some(path.to_path_buf()))
}
