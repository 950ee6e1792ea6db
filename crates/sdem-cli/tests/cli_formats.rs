//! Scans in the formats other tools write, through the real binary: a held-out pair saved by
//! Open3D as compressed PCD (committed in `tests/fixtures/open3d-pair`, see its README), and
//! scans written by laspy (LAZ) and pye57 (E57) at test time with `SDEM_TEST_PYTHON`.

mod common;

use common::{run, run_err, run_json, run_ok, run_python};
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn s(path: &Path) -> &str {
    path.to_str().expect("paths are UTF-8")
}

#[test]
fn a_pair_saved_by_open3d_as_compressed_pcd_localizes_within_a_centimetre() {
    let dir = tempfile::tempdir().unwrap();
    let pair = fixture("open3d-pair");
    let head = std::fs::read(pair.join("scans/000001.pcd")).unwrap();
    assert!(
        String::from_utf8_lossy(&head[..300]).contains("DATA binary_compressed"),
        "the fixture is not compressed PCD"
    );
    let json = run_json(
        dir.path(),
        &[
            "localize",
            s(&pair),
            "--reference",
            "0",
            "--query",
            "1",
            "--json",
        ],
    );
    assert_eq!(json["trusted"], true, "{json}");
    let error_m = json["error_m"].as_f64().unwrap();
    assert!(error_m <= 0.01, "error {error_m} m against poses_truth.txt");
}

/// Rewrites every `scans/NNNNNN.ply` of `dataset` as `scans/NNNNNN.xyz` text (for Python).
fn scans_to_xyz(dataset: &Path) {
    let scans = dataset.join("scans");
    let mut plys: Vec<PathBuf> = std::fs::read_dir(&scans)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "ply"))
        .collect();
    plys.sort();
    for ply in &plys {
        let points = sdem_io::read_points(ply).unwrap();
        let text: String = points
            .iter()
            .map(|p| format!("{} {} {}\n", p.x, p.y, p.z))
            .collect();
        std::fs::write(ply.with_extension("xyz"), text).unwrap();
        std::fs::remove_file(ply).unwrap();
    }
}

/// Rewrites every `scans/NNNNNN.ply` of the dataset `dataset` as `scans/NNNNNN.laz` written by
/// laspy (LAS 1.4, point format 6, 0.1 mm steps, lazrs), through `.xyz` text.
fn scans_to_laz(dataset: &Path) {
    scans_to_xyz(dataset);
    let scans = dataset.join("scans");
    run_python(
        &scans,
        r#"
import glob, os
import laspy
import numpy as np
for xyz in sorted(glob.glob("*.xyz")):
    points = np.loadtxt(xyz)
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([1e-4, 1e-4, 1e-4])
    header.offsets = np.array([0.0, 0.0, 0.0])
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    las.write(xyz[:-4] + ".laz", laz_backend=laspy.LazBackend.Lazrs)
    os.remove(xyz)
"#,
        &[],
    );
}

#[test]
fn a_pair_of_laz_scans_written_by_laspy_localizes_within_a_centimetre() {
    let dir = tempfile::tempdir().unwrap();
    let pair = dir.path().join("pair");
    run_ok(
        dir.path(),
        &[
            "simulate",
            "--out",
            s(&pair),
            "--seed",
            "12",
            "--stops",
            "2",
        ],
    );
    scans_to_laz(&pair);
    assert!(pair.join("scans/000001.laz").is_file());
    let json = run_json(
        dir.path(),
        &[
            "localize",
            s(&pair),
            "--reference",
            "0",
            "--query",
            "1",
            "--json",
        ],
    );
    assert_eq!(json["trusted"], true, "{json}");
    let error_m = json["error_m"].as_f64().unwrap();
    assert!(error_m <= 0.01, "error {error_m} m against poses_truth.txt");
}

/// Writes `survey.e57` in the current folder with pye57 from the dataset in `argv[1]` (see the
/// script's docstring).
const PYE57_SURVEY: &str = include_str!("fixtures/e57_survey.py");

/// Reads the E57 file `argv[1]` with pye57 and prints, per scan, its point count and its pose as
/// 12 numbers (the row-major 3×4 matrix), one scan per line.
const PYE57_READ: &str = r#"
import sys
import numpy as np
import pye57

survey = pye57.E57(sys.argv[1])
for i in range(survey.scan_count):
    header = survey.get_header(i)
    data = survey.read_scan_raw(i)
    rows = np.hstack([header.rotation_matrix, header.translation.reshape(3, 1)])
    print(len(data["cartesianX"]), " ".join(repr(float(v)) for v in rows.ravel()))
"#;

/// Runs the Python `script` with `args` in `dir` and returns what it printed.
fn python_output(dir: &Path, script: &str, args: &[&str]) -> String {
    let out = std::process::Command::new(common::test_python())
        .current_dir(dir)
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn kitti_rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(|t| t.parse().unwrap()).collect())
        .collect()
}

#[test]
fn a_held_out_run_delivered_as_one_e57_survey_maps_within_2_cm_and_exports_back() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    run_ok(
        dir.path(),
        &[
            "simulate",
            "--out",
            s(&run_dir),
            "--seed",
            "7",
            "--stops",
            "12",
        ],
    );
    scans_to_xyz(&run_dir);
    run_python(dir.path(), PYE57_SURVEY, &[s(&run_dir)]);

    // The survey imports: twelve scans in their own frames, the poses as odometry, never truth.
    let imported = dir.path().join("imported");
    let summary = run_json(
        dir.path(),
        &["import", "survey.e57", "--out", s(&imported), "--json"],
    );
    assert_eq!(summary["format"], "e57", "{summary}");
    assert_eq!(summary["scans"], 12, "{summary}");
    assert_eq!(summary["dropped_invalid"], 12 * 25, "{summary}");
    for name in ["odometry.txt", "attitude.csv", "scans/000011.ply"] {
        assert!(imported.join(name).is_file(), "{name} missing");
    }
    assert!(!imported.join("poses_truth.txt").exists());
    // Scoring only: the simulator's truth beside the imported scans.
    std::fs::copy(
        run_dir.join("poses_truth.txt"),
        imported.join("poses_truth.txt"),
    )
    .unwrap();
    let mapped = dir.path().join("mapped");
    let r = run(
        dir.path(),
        &[
            "slam",
            s(&imported),
            "--out",
            s(&mapped),
            "--accept-doubtful",
        ],
    );
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(mapped.join("report.json")).unwrap()).unwrap();
    let ate = report["truth"]["ate_rmse_m"].as_f64().unwrap();
    assert!(ate <= 0.02, "ATE RMSE {ate} m");

    // The map exports as E57 that libE57Format reads: a scan per node with sdem's pose.
    let out = dir.path().join("aligned.e57");
    let exported = run_json(
        dir.path(),
        &["export", s(&mapped), "--e57", s(&out), "--json"],
    );
    assert_eq!(exported["e57"]["points_from"], "dataset", "{exported}");
    let printed = python_output(dir.path(), PYE57_READ, &[s(&out)]);
    let lines: Vec<&str> = printed.lines().collect();
    let poses = kitti_rows(&mapped.join("poses.txt"));
    assert_eq!(lines.len(), poses.len());
    for (i, (line, pose)) in lines.iter().zip(&poses).enumerate() {
        let values: Vec<f64> = line
            .split_whitespace()
            .map(|t| t.parse().unwrap())
            .collect();
        let points = std::fs::read(imported.join(format!("scans/{i:06}.ply"))).unwrap();
        assert!(
            values[0] > 10_000.0 && points.len() > 100_000,
            "scan {i}: {line}"
        );
        for (k, (a, b)) in values[1..].iter().zip(pose).enumerate() {
            assert!((a - b).abs() < 1e-9, "scan {i}, pose entry {k}: {a} vs {b}");
        }
    }
}

#[test]
fn import_and_export_refuse_what_they_cannot_read() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("notes.e57"), "not a survey").unwrap();
    let line = run_err(dir.path(), &["import", "notes.e57", "--out", "ds"]);
    assert!(
        line.contains("notes.e57") && line.contains("ASTM-E57"),
        "{line}"
    );
    assert!(!dir.path().join("ds").exists());
    let line = run_err(dir.path(), &["export", "nowhere", "--e57", "out.e57"]);
    assert!(line.contains("nowhere"), "{line}");
    // No format to write: a usage error (exit status 2) before the map is read.
    common::usage_error(dir.path(), &["export", "nowhere"], &["--e57", "--mcap"]);
}
