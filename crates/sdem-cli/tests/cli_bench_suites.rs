//! `sdem bench --suite` (issue 21, item 5): the report's shape and its counts, the peers run
//! beside it (a stand-in Python here, so the test needs none), and bad flags. Accuracy is not
//! asserted: the suites measure it.

mod common;

use common::{run_err, sdem, usage_error};
use serde_json::Value;
use std::path::Path;

/// Runs `sdem args` in `dir` with `SDEM_PEERS_PYTHON=python`; expects success and one JSON
/// object on stdout.
fn run_suite(dir: &Path, python: &Path, args: &[&str]) -> Value {
    let out = sdem(dir)
        .env("SDEM_PEERS_PYTHON", python)
        .args(args)
        .output()
        .expect("cannot run sdem");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert_eq!(out.status.code(), Some(0), "sdem {args:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    serde_json::from_str(&stdout).unwrap_or_else(|e| panic!("not one JSON value ({e}):\n{stdout}"))
}

/// A stand-in for the peers' Python: whatever it is asked, it prints what register_pair.py
/// would for three methods: FPFH within 1 mm, KISS-Matcher not installed, GICP 0.5 m off.
fn fake_python(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("python");
    let script = r#"#!/bin/sh
echo '{"method": "o3d_fpfh_ransac_icp", "time_ms": 100.0, "T": [[1, 0, 0, 0.25], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "trans_err_m": 0.001, "rot_err_deg": 0.01}'
echo '{"method": "kiss_matcher_icp", "error": "ModuleNotFoundError: No module named kiss_matcher"}'
echo '{"method": "small_gicp_gicp", "time_ms": 20.0, "trans_err_m": 0.5, "rot_err_deg": 10.0}'
"#;
    std::fs::write(&path, script).unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    path
}

/// The counts of a tally agree with each other and with `pairs`.
fn check_tally(t: &Value, pairs: u64) {
    let n = |k: &str| t[k].as_u64().unwrap_or_else(|| panic!("no {k} in {t}"));
    assert_eq!(n("pairs"), pairs, "{t}");
    assert_eq!(n("trusted") + n("flagged"), pairs, "{t}");
    assert!(
        n("succeeded") <= pairs && n("errors") <= n("flagged"),
        "{t}"
    );
    assert!(n("wrong_trusted") <= n("trusted"), "{t}");
    assert_eq!(
        n("wrong_trusted") + n("wrong_flagged") + n("succeeded"),
        pairs,
        "{t}"
    );
    assert!(n("correct_flagged") <= n("succeeded"), "{t}");
    let rate = t["success_rate"].as_f64().unwrap();
    assert!((rate - n("succeeded") as f64 / pairs as f64).abs() < 1e-12);
    for stats in ["translation_error_mm", "rotation_error_deg", "time_ms"] {
        assert_eq!(t[stats]["count"].as_u64(), Some(pairs), "{stats}: {t}");
    }
    assert!(t["doubt_kinds"].is_object());
}

#[test]
fn unlevelled_suite_reports_counts_that_add_up_with_the_peers_beside_it() {
    let dir = tempfile::tempdir().unwrap();
    let python = fake_python(dir.path());
    let peers = dir.path().join("peers");
    std::fs::create_dir(&peers).unwrap();
    std::fs::write(peers.join("register_pair.py"), "# stand-in\n").unwrap();
    // A coarse grid keeps the run short; the pairs are the suite's.
    let report = run_suite(
        dir.path(),
        &python,
        &[
            "bench",
            "--suite",
            "unlevelled",
            "--quick",
            "--pairs",
            "3",
            "--step",
            "0.1",
            "--peers",
            peers.to_str().unwrap(),
            "--json",
        ],
    );
    assert_eq!(report["suite"], "unlevelled");
    assert_eq!(report["quick"], true);
    let parts = report["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 1);
    let part = &parts[0];
    assert_eq!(part["part"], "unlevelled");
    assert_eq!(part["available"], true);
    assert!(part["what"].as_str().unwrap().contains("no attitude"));
    assert_eq!(part["success_translation_m"], 0.02);
    assert_eq!(part["success_rotation_deg"], 0.5);
    assert_eq!(part["step_m"], 0.1);
    assert_eq!(part["config"]["query_tilt_max_deg"], 30.0);
    check_tally(&part["all"], 3);
    // Pairs 0, 1, 2: the rubble void, the ditch, the corridor.
    let groups = part["by_group"].as_array().unwrap();
    let names: Vec<&str> = groups
        .iter()
        .map(|g| g["group"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["corridor", "ditch", "rubble-void"]);
    for g in groups {
        check_tally(g, 1);
    }
    let records = part["records"].as_array().unwrap();
    assert_eq!(records.len(), 3);
    let mut wrong_trusted = 0;
    for (i, r) in records.iter().enumerate() {
        assert_eq!(r["index"].as_u64(), Some(i as u64));
        assert!(r["time_ms"].as_f64().unwrap() > 0.0);
        assert!(r["truth_translation_m"].as_f64().unwrap() <= 1.0 + 1e-9);
        assert!(r["query_tilt_deg"].as_f64().unwrap() <= 45.0);
        assert!(r["overlap"].as_f64().unwrap() >= 0.3);
        let (trusted, correct) = (r["trusted"] == true, r["correct"] == true);
        // An error is never trusted; a pose comes with both errors.
        if r["error"].is_string() {
            assert!(!trusted && !correct, "{r}");
        } else {
            assert!(r["translation_error_m"].is_number() && r["rotation_error_deg"].is_number());
        }
        wrong_trusted += usize::from(trusted && !correct);
    }
    assert_eq!(
        part["all"]["wrong_trusted"].as_u64(),
        Some(wrong_trusted as u64)
    );
    assert_eq!(report["wrong_trusted"].as_u64(), Some(wrong_trusted as u64));

    // The peers ran on all three pairs (fewer than --quick's 4) through the stand-in.
    let p = &part["peers"];
    assert_eq!(p["available"], true, "{p}");
    assert_eq!(p["pairs"], 3);
    assert_eq!(p["per_pair"].as_array().unwrap().len(), 3);
    let methods = p["methods"].as_array().unwrap();
    let method = |name: &str| {
        methods
            .iter()
            .find(|m| m["method"] == name)
            .unwrap_or_else(|| panic!("no {name} in {p}"))
    };
    assert_eq!(method("o3d_fpfh_ransac_icp")["succeeded"], 3);
    assert_eq!(method("o3d_fpfh_ransac_icp")["time_ms"]["median"], 100.0);
    assert_eq!(method("kiss_matcher_icp")["ran"], 0);
    assert!(method("kiss_matcher_icp")["first_error"]
        .as_str()
        .unwrap()
        .contains("kiss_matcher"));
    assert_eq!(method("small_gicp_gicp")["succeeded"], 0);
    // The peers' poses are read, and compared with sdem's.
    let first = &p["per_pair"][0][0];
    assert_eq!(first["estimate"]["x"], 0.25, "{first}");
    for m in methods {
        assert!(m["agrees_with_sdem"].as_u64().unwrap() <= 3);
    }
    assert!(records
        .iter()
        .all(|r| r["estimate"].is_object() == r["error"].is_null()));
    assert_eq!(method("small_gicp_gicp")["global"], false);
    // The fastest global peer that ran on every pair: FPFH (KISS-Matcher did not run).
    assert_eq!(p["fastest_global"], "Open3D FPFH + RANSAC + ICP");
    let sdem_median = p["sdem_time_ms"]["median"].as_f64().unwrap();
    let ratio = p["sdem_time_ratio_to_fastest_global"].as_f64().unwrap();
    assert!((ratio - sdem_median / 100.0).abs() < 1e-9);
}

#[test]
fn suites_run_without_the_peers_and_say_why() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-python");
    let report = run_suite(
        dir.path(),
        &missing,
        &[
            "bench",
            "--suite",
            "compass-noise",
            "--pairs",
            "1",
            "--step",
            "0.2",
            "--json",
        ],
    );
    let part = &report["parts"][0];
    assert_eq!(part["part"], "compass-noise");
    assert!(part["what"].as_str().unwrap().contains("20°"));
    check_tally(&part["all"], 1);
    let peers = &part["peers"];
    assert_eq!(peers["available"], false);
    let reason = peers["reason"].as_str().unwrap();
    assert!(
        reason.contains("SDEM_PEERS_PYTHON") || reason.contains("register_pair.py"),
        "{reason}"
    );
}

#[test]
fn bad_suite_flags_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // An unknown suite: clap's usage error, naming the suites.
    let r = common::run(d, &["bench", "--suite", "rubble"]);
    assert_eq!(r.code, Some(2), "{}", r.stderr);
    assert!(
        r.stderr.contains("unlevelled") && r.stderr.contains("lidar"),
        "{}",
        r.stderr
    );
    // --suite and --faults are two different benches.
    let r = common::run(d, &["bench", "--suite", "lidar", "--faults"]);
    assert_eq!(r.code, Some(2), "{}", r.stderr);
    // --kitti without a suite, or with another suite.
    let r = common::run(d, &["bench", "--kitti", "x"]);
    assert_eq!(r.code, Some(2), "{}", r.stderr);
    usage_error(
        d,
        &["bench", "--suite", "unlevelled", "--kitti", "x"],
        &["--kitti applies to --suite lidar"],
    );
    // A KITTI folder that is not there, or lacks its files.
    let e = run_err(
        d,
        &["bench", "--suite", "lidar", "--kitti", "no-such-folder"],
    );
    assert!(e.contains("no-such-folder") && e.contains("missing"), "{e}");
    let kitti = d.join("kitti");
    std::fs::create_dir_all(kitti.join("velodyne")).unwrap();
    std::fs::write(kitti.join("calib.txt"), "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n").unwrap();
    let e = run_err(d, &["bench", "--suite", "lidar", "--kitti", "kitti"]);
    assert!(e.contains("poses.txt"), "{e}");
    std::fs::write(kitti.join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n").unwrap();
    let e = run_err(d, &["bench", "--suite", "lidar", "--kitti", "kitti"]);
    assert!(e.contains("0 NNNNNN.bin"), "{e}");
    // A peers' folder without the script.
    let e = run_err(d, &["bench", "--suite", "unlevelled", "--peers", "kitti"]);
    assert!(e.contains("register_pair.py"), "{e}");
    usage_error(
        d,
        &["bench", "--suite", "unlevelled", "--pairs", "0"],
        &["--pairs", "≥ 1"],
    );
    // A route the suite does not have, or a route for a suite without routes: usage errors.
    usage_error(
        d,
        &["bench", "--suite", "routes", "--route", "stairs"],
        &["--route stairs", "second-run"],
    );
    usage_error(
        d,
        &["bench", "--suite", "lidar", "--route", "revisit"],
        &["--route applies to"],
    );
}

#[test]
fn the_routes_suite_runs_only_the_routes_named() {
    let dir = tempfile::tempdir().unwrap();
    let report = common::run_json(
        dir.path(),
        &[
            "bench",
            "--suite",
            "routes",
            "--route",
            "half-blocked",
            "--quick",
            "--seed",
            "3",
            "--json",
        ],
    );
    assert_eq!(report["suite"], "routes", "{report}");
    assert_eq!(report["seed"], 3, "{report}");
    let routes = report["routes"].as_array().unwrap();
    assert_eq!(routes.len(), 1, "{report}");
    assert_eq!(routes[0]["route"], "half-blocked", "{report}");
    assert_eq!(routes[0]["odometry"], false, "{report}");
    assert!(routes[0]["stops"].as_u64().unwrap() > 1, "{report}");
    // Neither the relocalization (it maps `revisit`) nor the KITTI frames were asked for.
    assert!(report["relocalization"].is_null(), "{report}");
    assert!(report["kitti"].is_null(), "{report}");
}
