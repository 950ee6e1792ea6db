//! Probe: maps one route and prints each stop (development aid).
use sdem::slam::SlamOptions;
use sdem_sim::routes::{route, run_route, RouteConfig, RouteKind};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let kind = match args.get(1).map(String::as_str).unwrap_or("turn-around") {
        "long-steps" => RouteKind::LongSteps,
        "turn-around" => RouteKind::TurnAround,
        "kidnapped" => RouteKind::Kidnapped,
        "half-blocked" => RouteKind::HalfBlocked,
        "revisit" => RouteKind::Revisit,
        _ => RouteKind::SecondRun,
    };
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let odometry = args.get(3).is_some_and(|s| s == "odo");
    let config = RouteConfig::default();
    let r = route(kind, seed, &config).unwrap();
    for (i, (w, e)) in r.run.waypoints.iter().zip(&r.run.events).enumerate() {
        println!("stop {i}: {:.2} m {:+.0}° {:?}", w.along_m, w.heading_offset.to_degrees(), e);
    }
    if let Some(k) = args.get(5).and_then(|s| s.parse::<usize>().ok()) {
        for ids in [(0..k).rev().take(3).collect::<Vec<_>>(), (0..k).rev().collect::<Vec<_>>(), vec![k - 1]] {
            truth_check(&r, k, &ids);
        }
        return;
    }
    let max_stops: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(usize::MAX);
    let mut r = r;
    r.run.stops.truncate(max_stops);
    r.run.events.truncate(max_stops);
    r.run.waypoints.truncate(max_stops);
    r.run.odometry.truncate(max_stops);
    let (outcome, slam) = run_route(&r, odometry, &SlamOptions::default()).unwrap();
    for s in &outcome.stops_detail {
        println!(
            "run {} stop {:3} {:?} -> {:?} seg {} err {:.1} cm {:.0} ms",
            s.run, s.index, s.event, s.status, s.segment, s.error_m * 100.0, s.time_ms
        );
    }
    let mut o = outcome.clone();
    o.stops_detail.clear();
    println!("{}", serde_json::to_string_pretty(&o).unwrap());
    println!("segments {:?}", slam.segments());
}

/// Cost and inliers at the truth of stop `k` against merged references of nodes `ids`
/// (poses of the nodes taken from the truth too).
#[allow(dead_code)]
pub fn truth_check(r: &sdem_sim::routes::SimRoute, k: usize, ids: &[usize]) {
    use nalgebra::Point3;
    let truth: Vec<_> = r.run.truth();
    let origin = truth[ids[0]].translation.vector;
    let mut pts = Vec::new();
    for &i in ids {
        for p in r.run.stops[i].sweep.points_in_sensor() {
            pts.push(Point3::from(truth[i] * Point3::from(p) - origin));
        }
    }
    let reference = sdem::Scan::from_points(&pts, Some(sdem::Attitude::default())).unwrap();
    let q: Vec<Point3<f64>> = r.run.stops[k].sweep.points_in_sensor().into_iter().map(Point3::from).collect();
    let query = sdem::Scan::from_points(&q, Some(sdem::Attitude::default())).unwrap();
    let pose = nalgebra::Translation3::from(-origin) * truth[k];
    let c = sdem::cost_at(&reference, &query, &pose, &sdem::localize::CostConfig::default()).unwrap();
    if let Some(c) = c {
        println!("truth of stop {k} vs {ids:?}: cost {:.3e} overlap {} inliers {} ({:.0} %)", c.cost, c.overlap, c.inliers, 100.0 * c.inliers as f64 / c.overlap as f64);
    } else {
        println!("truth of stop {k} vs {ids:?}: too little overlap");
    }
}
