//! `sdem simulate --route` (long simulated routes written stop by stop) and `sdem bench --suite
//! scale` (the loop measured as the map grows): what they write and report, and bad flags. The
//! figures themselves are the bench's to measure; here only what must hold on any run.

mod common;

use common::{run_json, usage_error};
use serde_json::Value;
use std::path::Path;
use tempfile::TempDir;

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// The translations of a KITTI pose file (12 numbers a line).
fn kitti_positions(path: &Path) -> Vec<[f64; 3]> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            assert_eq!(v.len(), 12, "{l}");
            [v[3], v[7], v[11]]
        })
        .collect()
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[test]
fn a_long_route_is_written_lap_after_lap_with_truth_and_odometry() {
    let dir = TempDir::new().unwrap();
    let ds = dir.path().join("laps");
    let summary = run_json(
        dir.path(),
        &[
            "simulate",
            "--route",
            "room-laps",
            "--stops",
            "34",
            "--out",
            s(&ds),
            "--json",
        ],
    );
    assert_eq!(summary["route"], "room_laps", "{summary}");
    assert_eq!(summary["stops"], 34, "{summary}");
    assert_eq!(
        summary["lap_starts"],
        serde_json::json!([0, 30]),
        "{summary}"
    );
    let scans = std::fs::read_dir(ds.join("scans")).unwrap().count();
    assert_eq!(scans, 34);
    let truth = kitti_positions(&ds.join("poses_truth.txt"));
    assert_eq!(truth.len(), 34);
    assert_eq!(kitti_positions(&ds.join("odometry.txt")).len(), 34);
    // Stops every ~35 cm along the lap, and the second lap comes back where the first began
    // (± the stops' jitter): that is the loop to close.
    for w in truth.windows(2) {
        let step = distance(w[0], w[1]);
        assert!((0.1..0.6).contains(&step), "a step of {step} m");
    }
    for i in 0..4 {
        let d = distance(truth[i], truth[30 + i]);
        assert!(d < 0.1, "stop {i} and {}: {d} m apart", 30 + i);
    }
}

#[test]
fn bad_long_route_flags_are_refused_with_the_choices() {
    let dir = TempDir::new().unwrap();
    let ds = dir.path().join("ds");
    usage_error(
        dir.path(),
        &["simulate", "--route", "stairs", "--out", s(&ds)],
        &["'stairs'", "--route", "room-laps, floor, wings"],
    );
    let route = ["simulate", "--route", "floor", "--out", s(&ds)];
    for stops in ["0", "100001"] {
        usage_error(
            dir.path(),
            &[&route[..], &["--stops", stops]].concat(),
            &[&format!("'{stops}' for '--stops"), "1..=100000"],
        );
    }
    assert!(!ds.exists());
    usage_error(
        dir.path(),
        &[
            "bench", "--suite", "scale", "--sizes", "30,20", "--route", "floor",
        ],
        &["--sizes must increase", "30 is followed by 20"],
    );
}

fn number(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("no number {key} in {v}"))
}

#[test]
fn the_scale_bench_reports_each_size_and_plots_time_per_stop() {
    let dir = TempDir::new().unwrap();
    let plot = dir.path().join("scale.png");
    let report = run_json(
        dir.path(),
        &[
            "bench",
            "--suite",
            "scale",
            "--route",
            "room-laps",
            "--sizes",
            "12,36",
            "--plot",
            s(&plot),
            "--json",
        ],
    );
    assert_eq!(report["suite"], "scale");
    let routes = report["routes"].as_array().unwrap();
    assert_eq!(routes.len(), 1);
    let route = &routes[0];
    assert_eq!(route["stops"], 36, "{route}");
    assert_eq!(route["time_per_stop_ms"].as_array().unwrap().len(), 36);
    let sizes = route["sizes"].as_array().unwrap();
    assert_eq!(sizes.len(), 2);
    for (size, stops) in sizes.iter().zip([12, 36]) {
        assert_eq!(size["window"][1], stops, "{size}");
        let nodes = number(size, "nodes");
        assert!(nodes >= 1.0 && nodes <= stops as f64, "{size}");
        let time = &size["time_per_stop_ms"];
        assert!(number(time, "median") > 0.0 && number(time, "p95") >= number(time, "median"));
        assert!(number(size, "map_on_disk_mib") > 0.0, "{size}");
        assert!(number(size, "ate_rmse_m").is_finite(), "{size}");
        if cfg!(target_os = "linux") {
            assert!(number(size, "peak_memory_mib") > 0.0, "{size}");
            // Each stop localizes, so it takes CPU time; the p95 bounds the median.
            let cpu = &size["cpu_per_stop_ms"];
            assert!(number(cpu, "median") > 0.0 && number(cpu, "p95") >= number(cpu, "median"));
        }
    }
    if cfg!(target_os = "linux") {
        // Two laps of the room (30 stops each): the second's CPU time per stop against the first's.
        assert!(
            number(&report["flat"], "last_over_first_cpu") > 0.0,
            "{}",
            report["flat"]
        );
    }
    // The second lap begins at stop 30: by stop 36 a loop was closed and solved.
    assert!(
        route["loop_closures_accepted"].as_u64().unwrap() >= 1,
        "{route}"
    );
    assert!(
        number(&sizes[1]["solve_ms"], "median") >= 0.0,
        "{}",
        sizes[1]
    );
    // The steps leave the fused map to a save or a view: settling after the last stop fused it.
    assert!(number(route, "settle_ms") > 0.0, "{route}");
    assert!(number(route, "fused_voxels") > 1000.0, "{route}");
    if cfg!(target_os = "linux") {
        assert!(
            number(route, "peak_memory_settled_mib") >= number(&sizes[1], "peak_memory_mib"),
            "{route}"
        );
    }
    let png = std::fs::read(&plot).unwrap();
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
}
