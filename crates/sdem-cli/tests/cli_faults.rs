//! Faults of a disaster site injected by `sdem simulate --fault` and measured by `sdem
//! bench --faults`.

mod common;

use common::{fails, run_json};

#[test]
fn simulate_injects_faults_at_every_stop() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("faulty");
    let out = out.to_str().unwrap();
    let summary = run_json(
        dir.path(),
        &[
            "simulate", "--out", out, "--stops", "3", "--fault", "dust", "--fault", "missing",
            "--fault", "compass", "--json",
        ],
    );
    let faults = summary["faults"].as_array().unwrap();
    assert_eq!(faults.len(), 3);
    let injected = summary["injected"].as_array().unwrap();
    assert_eq!(injected.len(), 3);
    let points = summary["points_per_scan"].as_array().unwrap();
    for (stop, (i, n)) in injected.iter().zip(points).enumerate() {
        let dust = i["dust_returns"].as_u64().unwrap() as f64;
        let lost = i["lost_returns"].as_u64().unwrap() as f64;
        let n = n.as_u64().unwrap() as f64;
        // 30 % of the returns lost, then 5 % of all beams turned to dust.
        assert!(dust > 0.02 * n && lost > 0.2 * n, "stop {stop}: {i}");
        assert!(i["compass_error_deg"].as_f64().unwrap().abs() <= 20.0);
    }
    // The dataset is readable and holds the damaged scans.
    assert!(std::path::Path::new(out).join("scans").is_dir());

    let e = fails(dir.path(), &["simulate", "--out", "x", "--fault", "tilt"]);
    assert!(e.contains("bench --faults"), "{e}");
    let e = fails(dir.path(), &["simulate", "--out", "x", "--fault", "smoke"]);
    assert!(e.contains("smoke") && e.contains("gyro-drift"), "{e}");
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
    let e = fails(dir.path(), &["bench", "--faults", "--case", "hail"]);
    assert!(e.contains("hail") && e.contains("person"), "{e}");
}
