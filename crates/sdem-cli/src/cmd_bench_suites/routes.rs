//! `sdem bench --suite routes`: the stop-and-go loop on routes robots really drive, each without
//! and with odometry ([`sdem_sim::routes`]); relocalization without a prior at every stop of a
//! saved map; and the real KITTI frames through the same loop, beside KISS-ICP's odometry in
//! the same run.

use crate::bench_kitti::{self, Kitti};
use crate::bench_peers::{self, PeerOdometry, Peers};
use crate::output::print_json;
use anyhow::{Context, Result};
use sdem::geometry::Pose;
use sdem::slam::{trajectory_errors, ScanInput, Slam, SlamOptions, StepStatus, TrajectoryErrors};
use sdem_sim::routes::{
    relocalize_every_stop, route, run_route, RelocalizationOutcome, RouteConfig, RouteKind,
    RouteOutcome, RELOCALIZED_WITHIN_M,
};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// A route's stops must all lie within this of the truth, metres.
const ROUTE_TARGET_M: f64 = 0.02;
/// Relocalization: the share that must be right (within [`RELOCALIZED_WITHIN_M`]).
const RELOCALIZATION_TARGET: f64 = 0.95;
/// KITTI frames are read up to this range by KISS-ICP, metres (the HDL-64E's).
const KITTI_MAX_RANGE_M: f64 = 80.0;
/// With `--quick`: relocalize at most this many stops.
const QUICK_RELOCALIZATIONS: usize = 8;

/// The whole report.
#[derive(Serialize)]
struct Report {
    suite: &'static str,
    seed: u64,
    quick: bool,
    threads: usize,
    /// Every route, without and with odometry.
    routes: Vec<RouteOutcome>,
    /// Routes whose every stop lies within 2 cm of the truth, of all.
    routes_within_target: usize,
    /// Accepted loop closures off the truth by more than 5 cm or 2°, over every route.
    false_closures_accepted: usize,
    /// Relocalization without a prior at every stop of the map of a route.
    relocalization: Option<Relocalization>,
    /// The KITTI frames through the loop, beside KISS-ICP.
    kitti: Option<KittiPart>,
}

/// The relocalization part.
#[derive(Serialize)]
struct Relocalization {
    /// The route whose map it is, with odometry.
    route: RouteKind,
    /// Nodes in that map.
    map_nodes: usize,
    #[serde(flatten)]
    outcome: RelocalizationOutcome,
}

/// The KITTI part.
#[derive(Serialize)]
struct KittiPart {
    folder: PathBuf,
    frames: usize,
    /// Frames that were not tracked or recovered without doubt.
    doubtful: usize,
    /// Errors against the truth (KITTI's, doubted for the first frames: see its README).
    errors: TrajectoryErrors,
    /// Median time of a frame in the loop (its whole step), ms.
    time_ms_median: f64,
    /// Time to settle the map after the last frame (fusing every frame into the voxel map,
    /// which the loop's steps leave to a view or a save), ms.
    settle_ms: f64,
    /// KISS-ICP on the same frames in the same run, as its script scores it (evo).
    kiss_icp: Option<PeerOdometry>,
    /// KISS-ICP's poses scored as sdem's are.
    kiss_icp_errors: Option<TrajectoryErrors>,
    /// Why KISS-ICP did not run, when it did not.
    kiss_icp_missing: Option<String>,
}

/// The routes named by `--route` (empty: every route).
///
/// # Errors
/// A name that is not a route's, with the names there are.
pub(super) fn parse_routes(names: &[String]) -> Result<Vec<RouteKind>> {
    (names.iter())
        .map(|name| {
            (name.trim().parse()).map_err(|e| {
                crate::parse::usage_error(
                    "bench",
                    format!("--route {name}: no such route of --suite routes: {e}"),
                )
            })
        })
        .collect()
}

/// Runs the suite on the routes of `only` (every route, and the KITTI frames, when empty) and
/// prints its report.
pub(super) fn run(
    only: &[RouteKind],
    kitti_folder: Option<&Path>,
    peers: &std::result::Result<Peers, String>,
    common: &super::Common,
    say: &dyn Fn(&str),
) -> Result<()> {
    let config = RouteConfig::default();
    let options = SlamOptions::default();
    let mut routes = Vec::new();
    let mut relocalization = None;
    let odometry: &[bool] = if common.quick {
        &[false]
    } else {
        &[false, true]
    };
    for kind in RouteKind::ALL
        .into_iter()
        .filter(|k| only.is_empty() || only.contains(k))
    {
        let drawn =
            route(kind, common.seed, &config).with_context(|| format!("route {}", kind.name()))?;
        for &with_odometry in odometry {
            say(&format!(
                "{} ({} stops), {} odometry ...",
                kind.name(),
                drawn.run.stops.len() + drawn.map_run.as_ref().map_or(0, |r| r.stops.len()),
                if with_odometry { "with" } else { "without" }
            ));
            let (outcome, slam) = run_route(&drawn, with_odometry, &options)?;
            let wanted = if common.quick {
                !with_odometry
            } else {
                with_odometry
            };
            if kind == RouteKind::Revisit && wanted {
                say("relocalization at every stop of its map ...");
                let scans = if common.quick {
                    QUICK_RELOCALIZATIONS
                } else {
                    usize::MAX
                };
                let outcome = relocalize_every_stop(&drawn, &config, &slam, common.seed, scans)?;
                relocalization = Some(Relocalization {
                    route: kind,
                    map_nodes: slam.map.nodes.len(),
                    outcome,
                });
            }
            routes.push(outcome);
        }
    }
    let kitti = if only.is_empty() {
        kitti_part(kitti_folder, peers, say)?
    } else {
        say("kitti: left out (--route names the routes)");
        None
    };
    let report = Report {
        suite: "routes",
        seed: common.seed,
        quick: common.quick,
        threads: rayon::current_num_threads(),
        routes_within_target: (routes.iter())
            .filter(|r| r.max_error_m <= ROUTE_TARGET_M)
            .count(),
        false_closures_accepted: routes.iter().map(|r| r.false_closures_accepted).sum(),
        routes,
        relocalization,
        kitti,
    };
    if common.json {
        let mut value = serde_json::to_value(&report).context("cannot encode the report")?;
        // The per-stop lists stay out of stdout's object (they are long); the totals are there.
        if let Some(routes) = value["routes"].as_array_mut() {
            for r in routes {
                if let Some(o) = r.as_object_mut() {
                    o.remove("stops_detail");
                }
            }
        }
        return print_json(&value);
    }
    print_report(&report);
    Ok(())
}

/// The KITTI frames through the loop with the options their first frame gives
/// ([`SlamOptions::for_scan`]), no attitude and no odometry, and KISS-ICP on the same frames.
/// `None` (saying why) without the folder.
fn kitti_part(
    folder: Option<&Path>,
    peers: &std::result::Result<Peers, String>,
    say: &dyn Fn(&str),
) -> Result<Option<KittiPart>> {
    let folder = folder.map_or_else(bench_kitti::default_folder, Path::to_path_buf);
    if !folder.exists() {
        say(&format!(
            "kitti: no folder at {} (--kitti DIR names one); skipped",
            bench_peers::shown(&folder)
        ));
        return Ok(None);
    }
    say(&format!("kitti: {} ...", bench_peers::shown(&folder)));
    let kitti = Kitti::read(&folder)?;
    let options = SlamOptions::for_scan(&kitti.frames[0]);
    let mut slam = Slam::new(options)?;
    let (mut times, mut doubtful) = (Vec::new(), 0);
    for (i, points) in kitti.frames.iter().enumerate() {
        let report = slam.add_scan(&ScanInput {
            scan_index: i,
            points_in_sensor: points,
            attitude: None,
            odometry: None,
        })?;
        if !matches!(
            report.status,
            StepStatus::First | StepStatus::Tracked | StepStatus::Recovered
        ) {
            doubtful += 1;
        }
        if i > 0 {
            times.push(report.time_ms);
        }
    }
    let settle_start = std::time::Instant::now();
    slam.settle_map()?;
    let settle_ms = settle_start.elapsed().as_secs_f64() * 1e3;
    let poses: Vec<Pose> = slam.poses();
    let truth = &kitti.world_from_velodyne[..poses.len()];
    let errors = trajectory_errors(truth, &poses)?;
    times.sort_by(f64::total_cmp);
    let (kiss_icp, kiss_icp_errors, kiss_icp_missing) = match peers {
        Ok(peers) => {
            say("kitti: KISS-ICP on the same frames ...");
            let (odometry, errors) = kiss_icp(peers, &kitti)?;
            (Some(odometry), errors, None)
        }
        Err(why) => (None, None, Some(why.clone())),
    };
    Ok(Some(KittiPart {
        folder,
        frames: kitti.frames.len(),
        doubtful,
        errors,
        time_ms_median: times.get(times.len() / 2).copied().unwrap_or(0.0),
        settle_ms,
        kiss_icp,
        kiss_icp_errors,
        kiss_icp_missing,
    }))
}

/// KISS-ICP over the KITTI frames, written as PLY clouds with the truth into a temporary
/// folder; its poses scored as sdem's are, when it ran.
fn kiss_icp(peers: &Peers, kitti: &Kitti) -> Result<(PeerOdometry, Option<TrajectoryErrors>)> {
    let dir = std::env::temp_dir().join(format!("sdem-bench-routes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let result = (|| -> Result<(PeerOdometry, Option<TrajectoryErrors>)> {
        // The script reads every cloud-like file of its folder (text ones too): the truth
        // lies beside the clouds' folder, not in it.
        let clouds = dir.join("clouds");
        std::fs::create_dir_all(&clouds)
            .with_context(|| format!("cannot create {}", clouds.display()))?;
        for (number, points) in kitti.numbers.iter().zip(&kitti.frames) {
            bench_peers::write_cloud(&clouds.join(format!("{number:06}.ply")), points)?;
        }
        let truth = dir.join("truth.txt");
        sdem_io::write_kitti_poses(&truth, &kitti.world_from_velodyne)?;
        let odometry = peers.run_odometry(&clouds, &truth, KITTI_MAX_RANGE_M);
        let errors = match &odometry.poses_file {
            Some(file) => {
                let poses = sdem_io::read_kitti_poses(file)?;
                let n = poses.len().min(kitti.world_from_velodyne.len());
                Some(trajectory_errors(
                    &kitti.world_from_velodyne[..n],
                    &poses[..n],
                )?)
            }
            None => None,
        };
        Ok((odometry, errors))
    })();
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Prints the report as text.
fn print_report(report: &Report) {
    println!(
        "routes (seed {}{}): the stop-and-go loop, default options, {} threads",
        report.seed,
        if report.quick { ", --quick" } else { "" },
        report.threads
    );
    println!(
        "{:<13} {:>4} {:>5} {:>7} {:>8} {:>4}  {:<24} {:>13}  {:>16}",
        "route",
        "odo",
        "stops",
        "ATE cm",
        "max cm",
        "segs",
        "tracked/recov/reloc/new/doubt",
        "closures +/-/F",
        "ms median/p95"
    );
    for r in &report.routes {
        let n = |k: &str| r.statuses.get(k).copied().unwrap_or(0);
        println!(
            "{:<13} {:>4} {:>5} {:>7.2} {:>8.2} {:>4}  {:<29} {:>8}  {:>7.0}/{:<7.0}",
            r.route_name(),
            if r.odometry { "yes" } else { "no" },
            r.stops,
            r.ate_rmse_m * 100.0,
            r.max_error_m * 100.0,
            r.segments,
            format!(
                "{}/{}/{}/{}/{}",
                n("tracked") + n("first"),
                n("recovered"),
                n("relocalized"),
                n("new_segment"),
                n("doubtful")
            ),
            format!(
                "{}/{}/{}",
                r.closures_accepted, r.closures_rejected, r.false_closures_accepted
            ),
            r.time_ms_median,
            r.time_ms_p95
        );
    }
    println!(
        "{} of {} routes with every stop within {:.0} cm of the truth (max cm: in the map's frame, \
         aligned as the ATE; a second run: its own stops, in the first run's frame); {} false \
         loop closures accepted",
        report.routes_within_target,
        report.routes.len(),
        ROUTE_TARGET_M * 100.0,
        report.false_closures_accepted
    );
    if let Some(r) = &report.relocalization {
        let o = &r.outcome;
        println!(
            "relocalization without a prior, every stop of the {} map ({} nodes): {} of {} \
             within {:.0} cm ({:.0} %, target {:.0} %), {} not found, {} doubtful, {} wrong and \
             trusted; {:.0} ms median, {:.0} ms at most",
            r.route.name(),
            r.map_nodes,
            o.right,
            o.scans,
            RELOCALIZED_WITHIN_M * 100.0,
            100.0 * o.right as f64 / o.scans.max(1) as f64,
            RELOCALIZATION_TARGET * 100.0,
            o.not_found,
            o.doubtful,
            o.wrong_trusted,
            o.time_ms_median,
            o.time_ms_max
        );
    }
    if let Some(k) = &report.kitti {
        let e = &k.errors;
        println!(
            "kitti ({} frames, no odometry, options from the first frame): {} doubtful; ATE \
             {:.1} cm (aligned {:.1} cm), RPE {:.1} cm / {:.3}°, {:.0} ms a frame (median); \
             the fused map, built when the map is settled after the last frame: {:.0} ms ({:.0} \
             ms a frame)",
            k.frames,
            k.doubtful,
            e.unaligned_rmse_m * 100.0,
            e.ate_rmse_m * 100.0,
            e.rpe_translation_rmse_m * 100.0,
            e.rpe_rotation_rmse_deg,
            k.time_ms_median,
            k.settle_ms,
            k.settle_ms / k.frames.max(1) as f64
        );
        match (&k.kiss_icp, &k.kiss_icp_missing) {
            (Some(p), _) if p.error.is_none() => {
                if let Some(e) = &k.kiss_icp_errors {
                    println!(
                        "  KISS-ICP, same frames, same run: ATE {:.1} cm (aligned {:.1} cm), RPE \
                         {:.1} cm / {:.3}°",
                        e.unaligned_rmse_m * 100.0,
                        e.ate_rmse_m * 100.0,
                        e.rpe_translation_rmse_m * 100.0,
                        e.rpe_rotation_rmse_deg,
                    );
                }
                println!(
                    "  KISS-ICP: {:.0} ms a frame (median); sdem's time is {:.1}× its",
                    p.time_ms_median.unwrap_or(f64::NAN),
                    k.time_ms_median / p.time_ms_median.unwrap_or(f64::NAN)
                );
            }
            (Some(p), _) => println!(
                "  KISS-ICP did not run: {}",
                p.error.as_deref().unwrap_or("")
            ),
            (None, Some(why)) => println!("  KISS-ICP not run: {why}"),
            (None, None) => {}
        }
        println!(
            "  (ATE without alignment, both anchored at the first frame, as evo_ape; KITTI's \
             truth is doubted for the first frames: see the folder's README)"
        );
    }
}

/// A route's name, for [`RouteOutcome`].
trait RouteName {
    fn route_name(&self) -> &'static str;
}

impl RouteName for RouteOutcome {
    fn route_name(&self) -> &'static str {
        self.route.name()
    }
}
