//! Faults of a disaster site injected by `sdem simulate --fault` and measured by `sdem
//! bench --faults`.

mod common;

use common::{run_json, usage_error};
use nalgebra::Vector3;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The scans of stop `k` of the dataset `out` (sensor frame, metres), as `sdem` reads them.
fn scan(out: &Path, k: usize) -> Vec<Vector3<f64>> {
    sdem_io::read_points(&out.join(format!("scans/{k:06}.ply")))
        .unwrap_or_else(|e| panic!("{}: scan {k}: {e}", out.display()))
}

/// The rows of `attitude.csv`: roll, pitch, yaw in degrees.
fn attitudes(out: &Path) -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(out.join("attitude.csv")).unwrap();
    text.lines()
        .skip(1)
        .map(|row| {
            let v: Vec<f64> = row.split(',').map(|c| c.trim().parse().unwrap()).collect();
            [v[1], v[2], v[3]]
        })
        .collect()
}

/// Simulates 3 stops of seed 1 into `dir/name` with `faults`; returns the folder and the JSON
/// summary.
fn simulate(dir: &Path, name: &str, faults: &[&str]) -> (PathBuf, Value) {
    let out = dir.join(name);
    let mut args = vec!["simulate", "--out", out.to_str().unwrap(), "--stops", "3"];
    for fault in faults {
        args.extend(["--fault", fault]);
    }
    args.push("--json");
    let summary = run_json(dir, &args);
    (out, summary)
}

/// Each fault is really in the scans: compared stop by stop with a fault-free run of the same
/// seed (the same sweeps before the faults), dust turns about 5 % of the beams into returns
/// between the sensor and the surface, `missing` removes 30 % of the returns and keeps the rest
/// as they were, and `compass` turns the heading reading alone.
#[test]
fn simulate_injects_faults_at_every_stop() {
    let dir = tempfile::tempdir().unwrap();
    let (clean, _) = simulate(dir.path(), "clean", &[]);
    let (dust, dust_summary) = simulate(dir.path(), "dust", &["dust"]);
    let (missing, missing_summary) = simulate(dir.path(), "missing", &["missing"]);
    let (compass, compass_summary) = simulate(dir.path(), "compass", &["compass"]);
    let (clean_attitude, compass_attitude) = (attitudes(&clean), attitudes(&compass));
    for k in 0..3 {
        let before = scan(&clean, k);
        let n = before.len();
        assert!(n > 10_000, "stop {k}: {n} points");
        // Nothing in the fault-free scan lies within 30 cm of the sensor (the robot's own
        // surroundings are clear).
        let near = |points: &[Vector3<f64>]| points.iter().filter(|p| p.norm() < 0.3).count();
        assert_eq!(near(&before), 0, "stop {k}");

        // Dust: every beam of this enclosed scene returns, so dust replaces returns one for one:
        // the same count, and the changed points (as many as reported) all lie closer to the
        // sensor than the surface they hid.
        let dusty = scan(&dust, k);
        assert_eq!(dusty.len(), n, "stop {k}: dust changed the count");
        let changed: Vec<(f64, f64)> = before
            .iter()
            .zip(&dusty)
            .filter(|(a, b)| a != b)
            .map(|(a, b)| (a.norm(), b.norm()))
            .collect();
        let reported = dust_summary["injected"][k]["dust_returns"]
            .as_u64()
            .unwrap() as usize;
        assert_eq!(changed.len(), reported, "stop {k}");
        let share = changed.len() as f64 / n as f64;
        assert!(
            (0.04..0.06).contains(&share),
            "stop {k}: {share} of the beams dusty"
        );
        assert!(
            changed.iter().all(|(surface, d)| d < surface),
            "stop {k}: a dust return lies beyond its surface"
        );
        assert!(
            near(&dusty) > n / 200,
            "stop {k}: {} dust returns within 30 cm",
            near(&dusty)
        );

        // Missing: 30 % of the returns gone (rounded up), the others kept, in order.
        let kept = scan(&missing, k);
        let lost = missing_summary["injected"][k]["lost_returns"]
            .as_u64()
            .unwrap() as usize;
        assert_eq!(lost, (0.3 * n as f64).ceil() as usize, "stop {k}");
        assert_eq!(kept.len(), n - lost, "stop {k}");
        let mut rest = before.iter();
        assert!(
            kept.iter().all(|p| rest.any(|q| q == p)),
            "stop {k}: a point of the scan with missing returns is not one of the fault-free scan's"
        );

        // Compass: only the heading reading differs, by the error reported.
        let error = compass_summary["injected"][k]["compass_error_deg"]
            .as_f64()
            .unwrap();
        assert!(error != 0.0 && error.abs() <= 20.0, "stop {k}: {error}°");
        let (a, b) = (clean_attitude[k], compass_attitude[k]);
        assert_eq!(a[..2], b[..2], "stop {k}: roll and pitch changed");
        let turned = (b[2] - a[2] + 540.0).rem_euclid(360.0) - 180.0;
        assert!(
            (turned - error).abs() < 1e-6,
            "stop {k}: yaw turned {turned}° for {error}°"
        );
        assert_eq!(
            scan(&compass, k),
            before,
            "stop {k}: a compass fault changed the points"
        );
    }

    // All three at once: the summary counts them at every stop.
    let (_, summary) = simulate(dir.path(), "faulty", &["dust", "missing", "compass"]);
    assert_eq!(summary["faults"].as_array().unwrap().len(), 3);
    let injected = summary["injected"].as_array().unwrap();
    assert_eq!(injected.len(), 3);
    let points = summary["points_per_scan"].as_array().unwrap();
    for (stop, (i, n)) in injected.iter().zip(points).enumerate() {
        let dust = i["dust_returns"].as_u64().unwrap() as f64;
        let lost = i["lost_returns"].as_u64().unwrap() as f64;
        let n = n.as_u64().unwrap() as f64;
        // 5 % of all beams turned to dust, then 30 % of the returns lost.
        assert!(dust > 0.02 * n && lost > 0.2 * n, "stop {stop}: {i}");
        assert!(i["compass_error_deg"].as_f64().unwrap().abs() <= 20.0);
    }

    // Tilt is not injected into a run: a usage error that says what measures it, before the
    // folder is made.
    usage_error(
        dir.path(),
        &["simulate", "--out", "x", "--fault", "tilt"],
        &[
            "'tilt'",
            "--fault",
            "`sdem bench --faults --case tilt` measures",
        ],
    );
    assert!(!dir.path().join("x").exists());
    usage_error(
        dir.path(),
        &["simulate", "--out", "x", "--fault", "smoke"],
        &["'smoke'", "--fault", "gyro-drift"],
    );
}

#[test]
fn bench_faults_scores_each_case() {
    let dir = tempfile::tempdir().unwrap();
    let report = run_json(
        dir.path(),
        &[
            "bench",
            "--faults",
            "--pairs",
            "2",
            "--case",
            "person",
            "--case",
            "gyro-drift",
            "--json",
        ],
    );
    let cases = report["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2);
    assert_eq!(cases[0]["case"], "person");
    for case in cases {
        assert_eq!(case["pairs"], 2);
        // Both pairs localized within 2 cm: a person walking through the scan and a drifted
        // gyro do not throw sdem off.
        assert_eq!(case["success_rate_2cm"], 1.0, "{case}");
        assert!(case["translation_error_mm"]["max"].as_f64().unwrap() < 20.0);
        assert_eq!(case["failures_flagged"], 0);
        // Every flagged success has at least one reason counted.
        let reasons: u64 = case["false_alarm_reasons"]
            .as_object()
            .unwrap()
            .values()
            .map(|v| v.as_u64().unwrap())
            .sum();
        assert!(reasons >= case["successes_flagged"].as_u64().unwrap());
    }
    usage_error(
        dir.path(),
        &["bench", "--faults", "--case", "hail"],
        &["'hail'", "--case", "none, compass", "person, all"],
    );
}
