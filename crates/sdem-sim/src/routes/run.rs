//! A route mapped by [`sdem::Slam`] and scored against its truth; relocalization in the map it
//! made.

use super::{RouteKind, RouteRun, SimRoute, StopEvent};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sdem::error::{Error, Result};
use sdem::geometry::{pose_error, Pose};
use sdem::slam::{
    alignment, relocalize, trajectory_errors, Odometry, ScanInput, Slam, SlamOptions, StepReport,
    StepStatus,
};
use serde::Serialize;
use std::collections::BTreeMap;

/// A loop closure is false when its measured relative pose is farther than this from the
/// truth's, metres…
const FALSE_CLOSURE_M: f64 = 0.05;
/// … or turned more than this, degrees.
const FALSE_CLOSURE_DEG: f64 = 2.0;
/// A relocalization is right within this of the truth, metres.
pub const RELOCALIZED_WITHIN_M: f64 = 0.05;

/// One stop of a mapped route.
#[derive(Debug, Clone, Serialize)]
pub struct RouteStopOutcome {
    /// The run (0: the first, or the only one) and the stop's index in it.
    pub run: usize,
    /// The stop's index in its run.
    pub index: usize,
    /// What happened on the way to it.
    pub event: StopEvent,
    /// How the loop took it.
    pub status: StepStatus,
    /// The segment it ended in.
    pub segment: usize,
    /// Its position's error at the end in the map's frame, metres: the estimate aligned to the
    /// truth by every stop, as the ATE is (the world frame is where the first stop's compass
    /// put it, and a reading 2° off there turns the whole map, 35 cm at 10 m); a second run's
    /// stop's in the first run's frame (aligned by the first run's stops alone).
    pub error_m: f64,
    /// Wall time of its step, ms.
    pub time_ms: f64,
}

/// A route mapped and scored.
#[derive(Debug, Clone, Serialize)]
pub struct RouteOutcome {
    /// The route's kind.
    pub route: RouteKind,
    /// Its seed.
    pub seed: u64,
    /// Mapped with the odometry's motion between stops.
    pub odometry: bool,
    /// Stops mapped (both runs of a second run).
    pub stops: usize,
    /// Absolute trajectory error after the best rigid alignment, RMSE over every stop, metres.
    pub ate_rmse_m: f64,
    /// The largest position error of a stop in the map's frame ([`RouteStopOutcome::error_m`]),
    /// metres: over every stop; for a second run over its own stops, in the first run's frame.
    pub max_error_m: f64,
    /// Segments at the end (1: everything in the world's frame).
    pub segments: usize,
    /// Steps by status.
    pub statuses: BTreeMap<String, usize>,
    /// Loop closures (and segment joins) accepted, at any step.
    pub closures_accepted: usize,
    /// Loop closures verified or proposed and rejected.
    pub closures_rejected: usize,
    /// Accepted closures whose relative pose is off the truth's by more than 5 cm or 2°.
    pub false_closures_accepted: usize,
    /// Time per stop: median, 95th percentile and largest, ms.
    pub time_ms_median: f64,
    /// See `time_ms_median`.
    pub time_ms_p95: f64,
    /// See `time_ms_median`.
    pub time_ms_max: f64,
    /// Every stop.
    pub stops_detail: Vec<RouteStopOutcome>,
}

/// Maps `route` with `options` (the odometry's motion given to the loop when `with_odometry`)
/// and scores it against the truth. A second run maps the first run, then starts a new run
/// into the same map ([`Slam::begin_run`]); its own stops are the ones scored by
/// `max_error_m`.
///
/// # Errors
/// The loop's errors (invalid input or options).
pub fn run_route(
    route: &SimRoute,
    with_odometry: bool,
    options: &SlamOptions,
) -> Result<(RouteOutcome, Slam)> {
    let mut slam = Slam::new(options.clone())?;
    let mut reports: Vec<(usize, usize, StopEvent, StepReport)> = Vec::new();
    let mut truth: Vec<Pose> = Vec::new();
    let runs: Vec<&RouteRun> = route.map_run.iter().chain([&route.run]).collect();
    for (r, run) in runs.iter().enumerate() {
        if r > 0 {
            slam.begin_run();
        }
        for (i, stop) in run.stops.iter().enumerate() {
            let points = stop.sweep.points_in_sensor();
            let odometry = (with_odometry && i > 0).then(|| Odometry {
                odom_from_sensor: run.odometry[i],
                odom_from_previous_sensor: run.odometry[i - 1],
            });
            let report = slam.add_scan(&ScanInput {
                scan_index: i,
                points_in_sensor: &points,
                attitude: Some(stop.sweep.mean_attitude()),
                odometry,
            })?;
            reports.push((r, i, run.events[i], report));
            truth.push(stop.world_from_sensor);
        }
    }
    let poses = slam.poses();
    let errors = trajectory_errors(&truth, &poses)?;
    let scored_run = runs.len() - 1;
    let mut stops_detail: Vec<RouteStopOutcome> = (reports.iter())
        .zip(&errors.position_errors_m)
        .map(|((run, index, event, report), &error_m)| RouteStopOutcome {
            run: *run,
            index: *index,
            event: *event,
            status: report.status,
            segment: slam.map.nodes[report.node_id].segment,
            error_m,
            time_ms: report.time_ms,
        })
        .collect();
    if route.kind == RouteKind::SecondRun {
        measure_in_first_runs_frame(&truth, &poses, &mut stops_detail, scored_run)?;
    }
    let max_error_m = (stops_detail.iter())
        .filter(|s| route.kind != RouteKind::SecondRun || s.run == scored_run)
        .map(|s| s.error_m)
        .fold(0.0, f64::max);
    let mut statuses = BTreeMap::new();
    for (_, _, _, report) in &reports {
        *statuses
            .entry(report.status.name().to_string())
            .or_insert(0) += 1;
    }
    let (accepted, rejected, false_accepted) = closure_counts(&reports, &truth);
    let mut times: Vec<f64> = reports.iter().map(|r| r.3.time_ms).collect();
    times.sort_by(f64::total_cmp);
    let at = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
    let outcome = RouteOutcome {
        route: route.kind,
        seed: route.seed,
        odometry: with_odometry,
        stops: reports.len(),
        ate_rmse_m: errors.ate_rmse_m,
        max_error_m,
        segments: slam.segments().len(),
        statuses,
        closures_accepted: accepted,
        closures_rejected: rejected,
        false_closures_accepted: false_accepted,
        time_ms_median: at(0.5),
        time_ms_p95: at(0.95),
        time_ms_max: at(1.0),
        stops_detail,
    };
    Ok((outcome, slam))
}

/// Measures the errors of a second run's stops (run `scored_run`) in the first run's frame:
/// the estimate carried onto the truth by the alignment of the earlier runs' stops alone, so
/// that where the first run's frame lies (its first stop's compass reading) does not count,
/// only where the second run lies in it.
fn measure_in_first_runs_frame(
    truth: &[Pose],
    poses: &[Pose],
    stops: &mut [RouteStopOutcome],
    scored_run: usize,
) -> Result<()> {
    let frame = alignment_of(truth, poses, |i| stops[i].run < scored_run)?;
    for (i, stop) in stops.iter_mut().enumerate() {
        if stop.run == scored_run {
            let placed = frame * poses[i];
            stop.error_m = (placed.translation.vector - truth[i].translation.vector).norm();
        }
    }
    Ok(())
}

/// Loop closures accepted, rejected, and accepted but false (against the truth), over every
/// step.
fn closure_counts(
    reports: &[(usize, usize, StopEvent, StepReport)],
    truth: &[Pose],
) -> (usize, usize, usize) {
    let (mut accepted, mut rejected, mut false_accepted) = (0, 0, 0);
    for (_, _, _, report) in reports {
        for c in &report.loop_closures {
            if !c.accepted {
                rejected += 1;
                continue;
            }
            accepted += 1;
            if let Some(measured) = c.from_from_to {
                let true_relative = truth[c.from].inverse() * truth[c.to];
                let (dt, dr) = pose_error(&true_relative, &measured);
                if dt > FALSE_CLOSURE_M || dr.to_degrees() > FALSE_CLOSURE_DEG {
                    false_accepted += 1;
                }
            }
        }
    }
    (accepted, rejected, false_accepted)
}

/// Relocalization without a prior at every stop of a mapped route.
#[derive(Debug, Clone, Serialize)]
pub struct RelocalizationOutcome {
    /// Scans relocalized: one at each stop of the map.
    pub scans: usize,
    /// Found and trusted within [`RELOCALIZED_WITHIN_M`] of the truth, in the map's frame
    /// ([`truth_from_map`]).
    pub right: usize,
    /// Reported as not found.
    pub not_found: usize,
    /// Found with doubts (not trusted).
    pub doubtful: usize,
    /// Trusted but farther than [`RELOCALIZED_WITHIN_M`] from the truth in the map's frame: the
    /// target is none.
    pub wrong_trusted: usize,
    /// Time per scan: median and largest, ms.
    pub time_ms_median: f64,
    /// See `time_ms_median`.
    pub time_ms_max: f64,
    /// The error of each trusted result in the map's frame, metres (`None`: not found or
    /// doubtful).
    pub errors_m: Vec<Option<f64>>,
}

/// Where the truth sees the frame of a map whose nodes are `poses`, in `segments`, made at the
/// stops whose truth is `truth` (in order): the alignment of the world segment's nodes (the
/// first node's) to their truth, as the ATE's. A map's world frame is where its first stop put
/// it: a compass reading 2° off there turns the whole map by 2°, 35 cm at 10 m, and a scan
/// relocalized right in that map lies as far from the truth.
///
/// # Errors
/// `poses`, `segments` and `truth` of different lengths, or no node.
pub fn truth_from_map(poses: &[Pose], segments: &[usize], truth: &[Pose]) -> Result<Pose> {
    if poses.len() != truth.len() || segments.len() != poses.len() || poses.is_empty() {
        return Err(Error::Invalid(format!(
            "a map of {} nodes ({} segments given) cannot be aligned to {} stops",
            poses.len(),
            segments.len(),
            truth.len()
        )));
    }
    alignment_of(truth, poses, |i| segments[i] == segments[0])
}

/// The alignment ([`alignment`]) of the estimate's `poses` to their `truth` over the indices
/// `keep` keeps alone.
fn alignment_of(truth: &[Pose], poses: &[Pose], keep: impl Fn(usize) -> bool) -> Result<Pose> {
    let kept: Vec<usize> = (0..poses.len()).filter(|&i| keep(i)).collect();
    let pick = |v: &[Pose]| kept.iter().map(|&i| v[i]).collect::<Vec<Pose>>();
    alignment(&pick(truth), &pick(poses))
}

/// Relocalizes, without a prior, a fresh scan at each of the first `scans` stops of the run
/// that made `slam`'s map (`run`, whose stops are the map's nodes in order): the same pose, the
/// sensor's noise drawn anew from `seed`, the gyro/compass reading given with the heading
/// searched in full. A pose found in the world's segment is scored in the map's frame
/// ([`truth_from_map`]); one found in another segment, in its own frame as it is.
///
/// # Errors
/// The relocalization's errors other than "not found"; a map whose nodes are not the run's
/// stops.
pub fn relocalize_every_stop(
    route: &SimRoute,
    route_config: &super::RouteConfig,
    slam: &Slam,
    seed: u64,
    scans: usize,
) -> Result<RelocalizationOutcome> {
    let run = route.map_run.as_ref().unwrap_or(&route.run);
    let segments: Vec<usize> = slam.map.nodes.iter().map(|n| n.segment).collect();
    let truth: Vec<Pose> = run.stops.iter().map(|s| s.world_from_sensor).collect();
    let map_frame = truth_from_map(&slam.poses(), &segments, &truth)?;
    let config = slam.config();
    let sensor = &route_config.sensor;
    let mut outcome = RelocalizationOutcome {
        scans: 0,
        right: 0,
        not_found: 0,
        doubtful: 0,
        wrong_trusted: 0,
        time_ms_median: 0.0,
        time_ms_max: 0.0,
        errors_m: Vec::new(),
    };
    let mut times = Vec::new();
    for (i, stop) in run.stops.iter().enumerate().take(scans) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(1_000 + i as u64);
        let scene = &route.scene;
        let sweep = crate::sim::scan(
            scene,
            sensor,
            &stop.world_from_sensor,
            stop.lift_slide_m,
            &mut rng,
        );
        let points = sweep.points_in_sensor();
        let start = std::time::Instant::now();
        let found = relocalize(
            &slam.map,
            config,
            &points,
            Some(sweep.mean_attitude()),
            None,
            config.recovery.relocalize_candidates,
        );
        times.push(start.elapsed().as_secs_f64() * 1e3);
        outcome.scans += 1;
        match found {
            Ok(found) if found.trusted => {
                let pose = found.world_from_sensor;
                let pose = if segments[found.node_id] == segments[0] {
                    map_frame * pose
                } else {
                    pose
                };
                let error =
                    (pose.translation.vector - stop.world_from_sensor.translation.vector).norm();
                outcome.errors_m.push(Some(error));
                if error <= RELOCALIZED_WITHIN_M {
                    outcome.right += 1;
                } else {
                    outcome.wrong_trusted += 1;
                }
            }
            Ok(_) => {
                outcome.doubtful += 1;
                outcome.errors_m.push(None);
            }
            Err(e) if e.is_no_match() => {
                outcome.not_found += 1;
                outcome.errors_m.push(None);
            }
            Err(e) => return Err(e),
        }
    }
    if times.is_empty() {
        return Err(Error::Invalid("the route has no stop".into()));
    }
    times.sort_by(f64::total_cmp);
    outcome.time_ms_median = times[times.len() / 2];
    outcome.time_ms_max = times[times.len() - 1];
    Ok(outcome)
}
