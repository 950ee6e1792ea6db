//! `sdem slam` end to end — its outputs, a run killed and resumed, and bad datasets.
//! Every test runs the real binary in its own temporary folder.

mod common;

use common::{fails, run_ok};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use tempfile::TempDir;

fn simulate(dir: &Path, stops: usize) {
    run_ok(
        dir,
        &[
            "simulate",
            "--out",
            "data",
            "--stops",
            &stops.to_string(),
            "--compass-noise-deg",
            "2",
        ],
    );
}

fn lines(path: &Path) -> usize {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .count()
}

#[test]
fn slam_maps_a_simulated_run_and_writes_every_output() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), 4);
    let summary: Value = serde_json::from_str(&run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--json"],
    ))
    .unwrap();
    assert_eq!(summary["nodes"], 4);
    let ate = summary["truth"]["ate_rmse_m"].as_f64().unwrap();
    assert!(ate < 0.01, "ATE {ate} m");
    let out = dir.path().join("out");
    assert_eq!(lines(&out.join("poses.txt")), 4);
    assert_eq!(lines(&out.join("poses.tum")), 4);
    for file in [
        "map.ply",
        "map.sdemvox",
        "config.toml",
        "map/map.json",
        "map/nodes/000003.pts",
    ] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    let report: Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let steps = report["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 4);
    for step in &steps[1..] {
        assert!(step["time_ms"].as_f64().unwrap() > 0.0);
        assert!(step["cost"].as_f64().is_some());
        assert!(step["overlap_fraction"].as_f64().unwrap() > 0.3);
        assert!(step["covariance"].as_array().is_some());
        assert!(!step["reference_nodes"].as_array().unwrap().is_empty());
        // How the refinement went: the 6-DoF one, converged within its iterations.
        let refinement = &step["refinement"];
        assert_eq!(refinement["outcome"], "six_dof", "{refinement}");
        assert_eq!(refinement["converged"], true, "{refinement}");
        assert!(
            refinement["iterations"].as_u64().unwrap() >= 1,
            "{refinement}"
        );
    }
    assert!(steps[0]["refinement"].is_null());
    // A scan relocalized in the saved map lands where the map put it.
    let attitude = std::fs::read_to_string(dir.path().join("data/attitude.csv")).unwrap();
    let row: Vec<&str> = attitude.lines().nth(3).unwrap().split(',').collect();
    let mapped = &steps[2]["world_from_sensor"];
    let near = format!(
        "{},{},{}",
        mapped["x"].as_f64().unwrap() + 0.1,
        mapped["y"].as_f64().unwrap() - 0.1,
        mapped["z"].as_f64().unwrap()
    );
    let attitude_row = row[1..].join(",");
    // `sdem localize --map out --scan <scan 2>` followed by `more`.
    let localize_scan_2 = |more: &[&str]| -> Vec<String> {
        [
            "localize",
            "--map",
            "out",
            "--scan",
            "data/scans/000002.ply",
        ]
        .iter()
        .chain(more)
        .map(|a| a.to_string())
        .collect()
    };
    // Relocalizes scan 2 with `place` (--near or --prior and its value); returns how far it
    // landed from where the map put it.
    let relocalized = |place: [&str; 2]| -> (f64, Value) {
        let args = localize_scan_2(&["--attitude", &attitude_row, place[0], place[1], "--json"]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let found: Value = serde_json::from_str(&run_ok(dir.path(), &args)).unwrap();
        let pose = &found["world_from_sensor"];
        let moved = ["x", "y", "z"]
            .iter()
            .map(|k| (pose[k].as_f64().unwrap() - mapped[k].as_f64().unwrap()).powi(2))
            .sum::<f64>()
            .sqrt();
        (moved, found)
    };
    let (moved, found) = relocalized(["--near", &near]);
    assert!(
        moved < 0.01,
        "relocalized {moved} m from the mapped pose: {found}"
    );
    // With a prediction (x,y,z,σ) instead: the same place, where the scan fixes every direction.
    let prior = format!("{near},0.05");
    let (moved, found) = relocalized(["--prior", &prior]);
    assert!(moved < 0.01, "relocalized {moved} m with --prior: {found}");
    // Both is a usage error (clap's exit code 2), naming the two.
    let args = localize_scan_2(&["--near", &near, "--prior", &prior]);
    let both = common::run(
        dir.path(),
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
    );
    assert_eq!(both.code, Some(2), "{}", both.stderr);
    assert!(
        both.stderr.contains("--prior") && both.stderr.contains("--near"),
        "{}",
        both.stderr
    );
    let err = fails(
        dir.path(),
        &[
            "localize",
            "--map",
            "nowhere",
            "--scan",
            "data/scans/000002.ply",
        ],
    );
    assert!(err.contains("nowhere"), "{err}");

    // The effective configuration reads back as a configuration.
    let config = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(config.contains("step_m"), "{config}");
    std::fs::write(dir.path().join("mine.toml"), &config).unwrap();
    run_ok(
        dir.path(),
        &[
            "slam",
            "data",
            "--out",
            "again",
            "--config",
            "mine.toml",
            "--max-scans",
            "2",
        ],
    );
    // A map is never overwritten by accident.
    let err = fails(dir.path(), &["slam", "data", "--out", "out"]);
    assert!(err.contains("--resume") && err.contains("--force"), "{err}");
}

#[test]
fn a_killed_run_resumes_from_its_saved_map() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), 6);
    let mut child = Command::new(env!("CARGO_BIN_EXE_sdem"))
        .current_dir(dir.path())
        .args(["slam", "data", "--out", "out"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kill it once the map holds three nodes (the manifest is written after every scan).
    let manifest = dir.path().join("out/map/map.json");
    let start = Instant::now();
    loop {
        let nodes = std::fs::read(&manifest)
            .ok()
            .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
            .and_then(|v| v["body"]["nodes"].as_array().map(Vec::len))
            .unwrap_or(0);
        if nodes >= 3 {
            break;
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before it could be killed"
        );
        assert!(start.elapsed() < Duration::from_secs(600), "no progress");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(
        !dir.path().join("out/poses.txt").exists(),
        "killed before the end"
    );

    let summary: Value = serde_json::from_str(&run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--resume", "--json"],
    ))
    .unwrap();
    let resumed_at = summary["resumed_at"].as_u64().unwrap();
    assert!((3..6).contains(&resumed_at), "resumed at {resumed_at}");
    assert_eq!(summary["nodes"], 6);
    assert_eq!(lines(&dir.path().join("out/poses.txt")), 6);
    let ate = summary["truth"]["ate_rmse_m"].as_f64().unwrap();
    assert!(ate < 0.01, "ATE {ate} m after resuming");
    // Resuming a finished run has nothing left to do, and says the same.
    let again: Value = serde_json::from_str(&run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--resume", "--json"],
    ))
    .unwrap();
    assert_eq!(again["nodes"], 6);
}

#[test]
fn bad_datasets_are_refused_with_the_file_named() {
    let dir = TempDir::new().unwrap();
    // No scans/ folder.
    std::fs::create_dir(dir.path().join("empty")).unwrap();
    let err = fails(dir.path(), &["slam", "empty", "--out", "o1"]);
    assert!(err.contains("scans"), "{err}");

    // attitude.csv with a row missing.
    simulate(dir.path(), 3);
    let attitude = dir.path().join("data/attitude.csv");
    let text = std::fs::read_to_string(&attitude).unwrap();
    let short: Vec<&str> = text.lines().take(3).collect();
    std::fs::write(&attitude, short.join("\n") + "\n").unwrap();
    let err = fails(dir.path(), &["slam", "data", "--out", "o2"]);
    assert!(
        err.contains("attitude.csv") && err.contains('2') && err.contains('3'),
        "{err}"
    );
    std::fs::write(&attitude, &text).unwrap();

    // An unreadable scan: the error names the file, and the map so far is kept for --resume.
    let scan = dir.path().join("data/scans/000002.ply");
    let bytes = std::fs::read(&scan).unwrap();
    std::fs::write(&scan, &bytes[..bytes.len() / 3]).unwrap();
    let err = fails(dir.path(), &["slam", "data", "--out", "o3"]);
    assert!(
        err.contains("000002.ply") && err.contains("--resume"),
        "{err}"
    );
    assert!(dir.path().join("o3/map/map.json").is_file());
    // Mend the file and resume.
    std::fs::write(&scan, &bytes).unwrap();
    let summary: Value = serde_json::from_str(&run_ok(
        dir.path(),
        &["slam", "data", "--out", "o3", "--resume", "--json"],
    ))
    .unwrap();
    assert_eq!(summary["nodes"], 3);

    // --resume with nothing to resume, and a bad --step.
    let err = fails(dir.path(), &["slam", "data", "--out", "o4", "--resume"]);
    assert!(err.contains("no saved map"), "{err}");
    let err = fails(dir.path(), &["slam", "data", "--out", "o5", "--step", "-1"]);
    assert!(err.contains("--step"), "{err}");
}

/// Without `--config`, the S-DEM's cells match the scanner's step from `sensor.toml`; a config
/// file's resolution wins over it.
#[test]
fn slam_matches_the_sdem_to_the_sensor_step() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), 2);
    let sensor_path = dir.path().join("data/sensor.toml");
    let sensor = std::fs::read_to_string(&sensor_path).unwrap();
    assert!(sensor.contains("tilt_step_deg = 1.0"), "{sensor}");
    let coarse = sensor
        .replace("tilt_step_deg = 1.0", "tilt_step_deg = 1.5")
        .replace("pan_step_deg = 1.0", "pan_step_deg = 1.2");
    std::fs::write(&sensor_path, coarse).unwrap();
    let resolution = |out: &str| -> f64 {
        let config = std::fs::read_to_string(dir.path().join(out).join("config.toml")).unwrap();
        let line = config
            .lines()
            .find(|l| l.starts_with("resolution_deg"))
            .unwrap_or_else(|| panic!("{config}"));
        line.split('=').nth(1).unwrap().trim().parse().unwrap()
    };
    run_ok(
        dir.path(),
        &[
            "slam",
            "data",
            "--out",
            "matched",
            "--max-scans",
            "2",
            "--no-pictures",
        ],
    );
    assert_eq!(resolution("matched"), 1.5);
    std::fs::write(
        dir.path().join("mine.toml"),
        "[sdem]\nresolution_deg = 2.0\n",
    )
    .unwrap();
    run_ok(
        dir.path(),
        &[
            "slam",
            "data",
            "--out",
            "mine",
            "--config",
            "mine.toml",
            "--max-scans",
            "2",
            "--no-pictures",
        ],
    );
    assert_eq!(resolution("mine"), 2.0);
}
