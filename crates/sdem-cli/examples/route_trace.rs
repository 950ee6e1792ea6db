//! Maps a long simulated route with the loop as `sdem bench --suite scale` does (odometry,
//! compass σ 2°, the map's node store in a scratch folder) and prints, stop by stop, the work
//! the step did and its error against the truth: what `docs/scale.md` reads where a
//! trajectory's error comes from and whether a stop's work grows with the map.
//!
//! ```sh
//! cargo run --release -p sdem-cli --example route_trace -- wings 100
//! cargo run --release -p sdem-cli --example route_trace -- room-laps 1000 --store /tmp/trace-store
//! ```
//!
//! Options: `--seed N` (1); `--store DIR`, the node store's folder (emptied first; without it
//! every node stays in memory); `--compass-deg S`, the compass's σ (2); `--odometry-scale F`,
//! the odometry's noise as a multiple of the default (1: 5 % of a step, 0.5° a step).
//!
//! Per stop, a line `S`: the CPU time of the step (every thread of the process, read from
//! `/proc/self/task/*/schedstat`, so that other jobs on the machine do not count), its wall
//! time, the localization's and loop closure's wall time, the loop closures checked, the nodes
//! the store gave back; the step's error against the true step (along, across and up in the
//! previous sensor's frame, cm, and yaw, degrees), the true turn, and the pose's error at the
//! step (cm). Every 100 stops a line `W`: the medians of the window. At 100, 300, 1,000 and
//! 3,000 nodes, and at the end, the ATE as the bench takes it.

use sdem::geometry::{attitude_of, Pose};
use sdem::map::Node;
use sdem::sensor::SensorConfig;
use sdem::slam::{trajectory_errors, Odometry, ScanInput, Slam, SlamOptions};
use sdem::store::NodeStore;
use sdem_io::MapFolder;
use sdem_sim::odometry::{simulate_odometry, OdometryNoise};
use sdem_sim::sim::{long_run, LongRoute};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// The process's CPU time, as `sdem bench --suite scale` reads it.
#[path = "../src/cpu.rs"]
mod cpu;

/// The map folder as the node store, counting the nodes it gives back.
#[derive(Debug)]
struct CountingStore {
    folder: MapFolder,
    fetched: AtomicUsize,
}

impl NodeStore for CountingStore {
    fn keep(&self, node: &Node) -> sdem::Result<()> {
        self.folder.keep(node)
    }

    fn fetch(&self, node_id: usize) -> sdem::Result<Vec<[f32; 3]>> {
        self.fetched.fetch_add(1, Ordering::Relaxed);
        self.folder.fetch(node_id)
    }
}

struct Args {
    route: LongRoute,
    stops: usize,
    seed: u64,
    store: Option<std::path::PathBuf>,
    compass_deg: f64,
    odometry_scale: f64,
}

fn parse_args() -> anyhow::Result<Args> {
    let mut args = Args {
        route: LongRoute::Wings,
        stops: 100,
        seed: 1,
        store: None,
        compass_deg: 2.0,
        odometry_scale: 1.0,
    };
    let mut it = std::env::args().skip(1);
    let mut positional = 0;
    while let Some(a) = it.next() {
        let mut value = || {
            it.next()
                .ok_or_else(|| anyhow::anyhow!("{a} needs a value"))
        };
        match a.as_str() {
            "--seed" => args.seed = value()?.parse()?,
            "--store" => args.store = Some(value()?.into()),
            "--compass-deg" => args.compass_deg = value()?.parse()?,
            "--odometry-scale" => args.odometry_scale = value()?.parse()?,
            _ if positional == 0 => {
                args.route = a.parse()?;
                positional += 1;
            }
            _ if positional == 1 => {
                args.stops = a.parse()?;
                positional += 1;
            }
            _ => anyhow::bail!("unexpected argument {a}; see the example's documentation"),
        }
    }
    Ok(args)
}

fn wrap_deg(a: f64) -> f64 {
    (a + 180.0).rem_euclid(360.0) - 180.0
}

/// The error of the estimated step `a → b` against the true one: along, across, up (cm, in
/// `a`'s frame), yaw (degrees); and the true turn (degrees).
fn step_error(estimate: (&Pose, &Pose), truth: (&Pose, &Pose)) -> [f64; 5] {
    let de = estimate.0.inverse() * estimate.1;
    let dt = truth.0.inverse() * truth.1;
    let e = (de.translation.vector - dt.translation.vector) * 100.0;
    let turn = attitude_of(&dt).yaw.to_degrees();
    let yaw = wrap_deg(attitude_of(&de).yaw.to_degrees() - turn);
    [e.x, e.y, e.z, yaw, wrap_deg(turn)]
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() -> anyhow::Result<()> {
    let args = parse_args()?;
    let sensor = SensorConfig {
        compass_noise_deg: args.compass_deg,
        ..Default::default()
    };
    let run = long_run(args.route, args.seed, args.stops, &sensor.lift)?;
    let truth = run.truth(&sensor.lift)?;
    let noise = OdometryNoise {
        translation_frac: 0.05 * args.odometry_scale,
        yaw_deg_per_step: 0.5 * args.odometry_scale,
    };
    let odometry = simulate_odometry(&truth, &noise, args.seed)?;
    let mut slam = Slam::new(SlamOptions::default())?;
    let store = match &args.store {
        Some(dir) => {
            let _ = std::fs::remove_dir_all(dir);
            std::fs::create_dir_all(dir)?;
            let store = Arc::new(CountingStore {
                folder: MapFolder::create(dir)?,
                fetched: AtomicUsize::new(0),
            });
            slam.set_node_store(store.clone());
            Some(store)
        }
        None => None,
    };
    let fetched = || {
        store
            .as_ref()
            .map_or(0, |s| s.fetched.load(Ordering::Relaxed))
    };
    println!("S stop cpu_ms wall_ms localize_ms closure_ms closures fetched | step error: along across up cm yaw deg | turn deg | pose error x y z cm");
    let mut mapped: Vec<usize> = Vec::new();
    let mut window: Vec<[f64; 3]> = Vec::new();
    let mut previous: Option<Pose> = None;
    for chunk in (0..args.stops).step_by(16) {
        let sims = run.simulate(&sensor, args.seed, chunk..(chunk + 16).min(args.stops))?;
        for (k, sim) in sims.iter().enumerate() {
            let i = chunk + k;
            let points = sim.sweep.points_in_sensor();
            let odometry = mapped.last().map(|&p| Odometry {
                odom_from_sensor: odometry[i],
                odom_from_previous_sensor: odometry[p],
            });
            let (fetched_before, cpu_before, start) = (fetched(), cpu::used_ms(), Instant::now());
            let step = slam.add_scan(&ScanInput {
                scan_index: i,
                points_in_sensor: &points,
                attitude: Some(sim.sweep.mean_attitude()),
                odometry,
            });
            let wall = start.elapsed().as_secs_f64() * 1e3;
            let cpu = cpu::since_ms(cpu_before).unwrap_or(f64::NAN);
            let report = match step {
                Ok(report) => report,
                Err(e) => {
                    println!("S {i} failed: {e}");
                    continue;
                }
            };
            let pose = slam.map.nodes[report.node_id].world_from_sensor;
            // The step as the loop took it: from the last pose as its own step left it.
            let e = match (mapped.last(), &previous) {
                (Some(&p), Some(previous)) => step_error((previous, &pose), (&truth[p], &truth[i])),
                _ => [0.0; 5],
            };
            previous = Some(pose);
            let at = (pose.translation.vector - truth[i].translation.vector) * 100.0;
            let brought = fetched() - fetched_before;
            println!(
                "S {i} {cpu:.1} {wall:.1} {:.1} {:.1} {} {brought} | {:.3} {:.3} {:.3} {:.4} | {:.2} | {:.2} {:.2} {:.2}",
                report.localize_ms,
                report.loop_closure_ms,
                report.loop_closures.len(),
                e[0], e[1], e[2], e[3], e[4], at.x, at.y, at.z,
            );
            mapped.push(i);
            window.push([cpu, wall, brought as f64]);
            if window.len() == 100 {
                let column = |c: usize| window.iter().map(|w| w[c]).collect::<Vec<f64>>();
                let most = column(2).into_iter().fold(0.0, f64::max);
                println!(
                    "W stops {}-{i}: median cpu {:.1} ms, wall {:.1} ms; nodes brought back: most {most} in a stop",
                    i + 1 - window.len(),
                    median(column(0)),
                    median(column(1)),
                );
                window.clear();
            }
            if [100, 300, 1000, 3000].contains(&mapped.len()) || i + 1 == args.stops {
                let truth: Vec<Pose> = mapped.iter().map(|&m| truth[m]).collect();
                let errors = trajectory_errors(&truth, &slam.poses())?;
                println!(
                    "ATE at {} nodes: rms {:.2} cm, max {:.2} cm",
                    mapped.len(),
                    errors.ate_rmse_m * 100.0,
                    errors.ate_max_m * 100.0
                );
            }
        }
    }
    Ok(())
}
