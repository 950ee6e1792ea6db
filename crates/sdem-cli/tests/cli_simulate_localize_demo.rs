//! The `sdem` command line end to end — `simulate`, `localize`, `demo` and their error
//! messages. Every test runs the real binary in its own temporary folder.
//!
//! `sdem simulate` takes a fraction of a second, so each test writes the dataset it needs into
//! its own folder (cleaned up on drop) instead of sharing one; the costly part is `localize`,
//! which runs once per checked pair.

mod common;

use common::{doubt_kinds, run, run_err, run_json, run_ok, usage_error};
use serde_json::Value;
use std::path::{Path, PathBuf};
use tempfile::TempDir;

// ---------------------------------------------------------------------------------------------
// Helpers: running the binary
// ---------------------------------------------------------------------------------------------

fn s(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}

/// A fresh temporary folder with a simulated dataset `DIR/ds` of `stops` stops (seed 1).
fn simulated(stops: usize) -> (TempDir, PathBuf) {
    let dir = TempDir::new().unwrap();
    let ds = dir.path().join("ds");
    run_ok(
        dir.path(),
        &[
            "simulate",
            "--out",
            s(&ds),
            "--seed",
            "1",
            "--stops",
            &stops.to_string(),
        ],
    );
    (dir, ds)
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

fn files_with_ext(folder: &Path, ext: &str) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(folder)
        .unwrap_or_else(|e| panic!("{}: {e}", folder.display()))
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(&format!(".{ext}")))
        .collect();
    names.sort();
    names
}

fn num(v: &Value, key: &str) -> f64 {
    v.get(key)
        .and_then(Value::as_f64)
        .unwrap_or_else(|| panic!("'{key}' is not a number in {v}"))
}

// ---------------------------------------------------------------------------------------------
// Helpers: 3x4 rigid transforms (row-major [R | t], as in a KITTI line)
// ---------------------------------------------------------------------------------------------

type Pose34 = [[f64; 4]; 3];

fn parse_kitti(path: &Path) -> Vec<Pose34> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .enumerate()
        .map(|(i, line)| {
            let v: Vec<f64> = line
                .split_whitespace()
                .map(|t| {
                    t.parse()
                        .unwrap_or_else(|_| panic!("{}:{}: '{t}'", path.display(), i + 1))
                })
                .collect();
            assert_eq!(v.len(), 12, "{}:{}: {line}", path.display(), i + 1);
            let mut p = [[0.0; 4]; 3];
            for r in 0..3 {
                for c in 0..4 {
                    p[r][c] = v[4 * r + c];
                }
            }
            p
        })
        .collect()
}

fn translation(p: &Pose34) -> [f64; 3] {
    [p[0][3], p[1][3], p[2][3]]
}

fn inverse(p: &Pose34) -> Pose34 {
    let mut q = [[0.0; 4]; 3];
    for r in 0..3 {
        for c in 0..3 {
            q[r][c] = p[c][r];
        }
        q[r][3] = -(0..3).map(|k| p[k][r] * p[k][3]).sum::<f64>();
    }
    q
}

fn compose(a: &Pose34, b: &Pose34) -> Pose34 {
    let mut q = [[0.0; 4]; 3];
    for r in 0..3 {
        for c in 0..4 {
            q[r][c] = (0..3).map(|k| a[r][k] * b[k][c]).sum::<f64>();
        }
        q[r][3] += a[r][3];
    }
    q
}

/// Roll, pitch, yaw (degrees) of `R = Rz(yaw) · Ry(pitch) · Rx(roll)`.
fn rpy_deg(p: &Pose34) -> [f64; 3] {
    let roll = p[2][1].atan2(p[2][2]);
    let pitch = (-p[2][0]).clamp(-1.0, 1.0).asin();
    let yaw = p[1][0].atan2(p[0][0]);
    [roll.to_degrees(), pitch.to_degrees(), yaw.to_degrees()]
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The `{"x","y","z","roll_deg","pitch_deg","yaw_deg"}` object of DESIGN.md: translation.
fn pose_xyz(record: &Value) -> [f64; 3] {
    for key in ["x", "y", "z", "roll_deg", "pitch_deg", "yaw_deg"] {
        assert!(
            record.get(key).is_some_and(Value::is_f64),
            "pose record lacks a number '{key}': {record}"
        );
    }
    [num(record, "x"), num(record, "y"), num(record, "z")]
}

/// The paper's default window: x -0.5..0.5, y -0.3..0.6, z -0.1..0.1 m.
const DEFAULT_WINDOW: [[f64; 2]; 3] = [[-0.5, 0.5], [-0.3, 0.6], [-0.1, 0.1]];

fn inside(offset: [f64; 3], window: &[[f64; 2]; 3]) -> bool {
    (0..3).all(|a| offset[a] >= window[a][0] && offset[a] <= window[a][1])
}

/// Checks the fields of a `localize --json` report, and its truth fields against `truth`
/// (reference_from_query computed here from poses_truth.txt). Returns the translation error
/// computed here.
fn check_localize_report(report: &Value, reference: usize, query: usize, truth: &Pose34) -> f64 {
    assert_eq!(report["reference"], reference, "{report}");
    assert_eq!(report["query"], query, "{report}");
    let estimate = pose_xyz(&report["reference_from_query"]);
    let cost = num(report, "cost");
    assert!(cost.is_finite() && cost >= 0.0, "cost {cost}");
    assert!(
        report["overlap"].as_u64().is_some_and(|o| o > 0),
        "{report}"
    );
    assert!(
        report["candidates_evaluated"]
            .as_u64()
            .is_some_and(|c| c > 0),
        "{report}"
    );
    let time_ms = num(report, "time_ms");
    assert!(time_ms.is_finite() && time_ms >= 0.0, "time_ms {time_ms}");

    // The CLI's own truth must be the one computed here.
    let cli_truth = &report["truth"];
    assert!(cli_truth.is_object(), "no truth in {report}");
    let t = translation(truth);
    let cli_t = pose_xyz(cli_truth);
    assert!(dist(t, cli_t) < 1e-9, "truth {cli_t:?} != {t:?}");
    let rpy = rpy_deg(truth);
    for (i, key) in ["roll_deg", "pitch_deg", "yaw_deg"].iter().enumerate() {
        let got = num(cli_truth, key);
        assert!(
            (got - rpy[i]).abs() < 1e-6,
            "truth {key} {got} != {} computed from poses_truth.txt",
            rpy[i]
        );
    }
    let error = dist(estimate, t);
    let cli_error = num(report, "error_m");
    assert!(
        (cli_error - error).abs() < 1e-6,
        "{reference}->{query}: the CLI's error_m {cli_error} disagrees with {error} from \
         poses_truth.txt"
    );
    assert!(num(report, "error_deg").is_finite(), "{report}");
    error
}

fn localize(dir: &Path, ds: &Path, reference: usize, query: usize, extra: &[&str]) -> Value {
    let (r, q) = (reference.to_string(), query.to_string());
    let mut args = vec![
        "localize",
        s(ds),
        "--reference",
        &r,
        "--query",
        &q,
        "--json",
    ];
    args.extend_from_slice(extra);
    run_json(dir, &args)
}

// ---------------------------------------------------------------------------------------------
// sdem simulate
// ---------------------------------------------------------------------------------------------

/// `simulate --stops N` writes N scans, N attitude rows, N KITTI and TUM poses (the first the
/// identity), sensor.toml and N sweeps; the same seed writes the same files.
#[test]
fn simulate_writes_a_consistent_dataset() {
    let stops = 5;
    let (dir, ds) = simulated(stops);

    let scans = files_with_ext(&ds.join("scans"), "ply");
    let expected: Vec<String> = (0..stops).map(|i| format!("{i:06}.ply")).collect();
    assert_eq!(scans, expected);
    for name in &scans {
        let bytes = std::fs::read(ds.join("scans").join(name)).unwrap();
        assert!(bytes.starts_with(b"ply\n"), "{name} is not a PLY file");
        let header = String::from_utf8_lossy(&bytes[..bytes.len().min(400)]).into_owned();
        let vertices: usize = header
            .lines()
            .find_map(|l| l.strip_prefix("element vertex "))
            .unwrap_or_else(|| panic!("{name}: no vertex count in {header}"))
            .trim()
            .parse()
            .unwrap();
        assert!(vertices > 1000, "{name} holds only {vertices} points");
    }

    let attitude = std::fs::read_to_string(ds.join("attitude.csv")).unwrap();
    let mut lines = attitude.lines();
    assert_eq!(lines.next(), Some("index,roll_deg,pitch_deg,yaw_deg"));
    let rows: Vec<&str> = lines.filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(rows.len(), stops, "{attitude}");
    for (i, row) in rows.iter().enumerate() {
        let cells: Vec<&str> = row.split(',').collect();
        assert_eq!(cells.len(), 4, "attitude.csv row {row}");
        assert_eq!(cells[0].trim().parse::<usize>().unwrap(), i, "{row}");
        for cell in &cells[1..] {
            let v: f64 = cell.trim().parse().unwrap();
            assert!(v.is_finite() && v.abs() <= 180.0, "{row}");
        }
    }

    let truth = parse_kitti(&ds.join("poses_truth.txt"));
    assert_eq!(truth.len(), stops);
    let identity = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    for r in 0..3 {
        for c in 0..4 {
            assert!(
                (truth[0][r][c] - identity[r][c]).abs() < 1e-12,
                "first truth pose is not the identity: {:?}",
                truth[0]
            );
        }
    }
    for (i, p) in truth.iter().enumerate() {
        // Rows of R orthonormal.
        for a in 0..3 {
            for b in 0..3 {
                let dot: f64 = (0..3).map(|k| p[a][k] * p[b][k]).sum();
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-9, "pose {i} R is not a rotation");
            }
        }
    }

    let tum = std::fs::read_to_string(ds.join("poses_truth.tum")).unwrap();
    let tum_rows: Vec<Vec<f64>> = tum
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| l.split_whitespace().map(|t| t.parse().unwrap()).collect())
        .collect();
    assert_eq!(tum_rows.len(), stops, "{tum}");
    for (i, row) in tum_rows.iter().enumerate() {
        assert_eq!(row.len(), 8, "TUM row {i}: {row:?}");
        let t = translation(&truth[i]);
        assert!(
            dist([row[1], row[2], row[3]], t) < 1e-9,
            "TUM row {i} {row:?} and KITTI {t:?} disagree"
        );
        let qn = (row[4..8].iter().map(|q| q * q).sum::<f64>()).sqrt();
        assert!((qn - 1.0).abs() < 1e-6, "TUM row {i}: quaternion norm {qn}");
    }

    let sensor = std::fs::read_to_string(ds.join("sensor.toml")).unwrap();
    assert!(!sensor.trim().is_empty(), "sensor.toml is empty");

    let sweeps = files_with_ext(&ds.join("sweeps"), "sweep");
    let expected: Vec<String> = (0..stops).map(|i| format!("{i:06}.sweep")).collect();
    assert_eq!(sweeps, expected);

    // Same seed, same dataset.
    let again = dir.path().join("again");
    run_ok(
        dir.path(),
        &[
            "simulate",
            "--out",
            s(&again),
            "--seed",
            "1",
            "--stops",
            &stops.to_string(),
        ],
    );
    for file in ["attitude.csv", "poses_truth.txt", "scans/000003.ply"] {
        assert_eq!(
            std::fs::read(ds.join(file)).unwrap(),
            std::fs::read(again.join(file)).unwrap(),
            "{file} differs between two runs with the same seed"
        );
    }
}

/// `simulate --json` prints one JSON object whose stop count matches --stops.
#[test]
fn simulate_json_summary() {
    let dir = TempDir::new().unwrap();
    let ds = dir.path().join("ds");
    let summary = run_json(
        dir.path(),
        &["simulate", "--out", s(&ds), "--stops", "3", "--json"],
    );
    assert_eq!(summary["stops"], 3, "{summary}");
    assert_eq!(
        summary["points_per_scan"].as_array().map(Vec::len),
        Some(3),
        "{summary}"
    );
}

/// Writing into a folder that already holds a dataset is refused (one line, non-zero exit)
/// unless --force is given; --force with fewer stops never leaves old scans mixed in.
#[test]
fn simulate_refuses_an_existing_dataset_without_force() {
    let (dir, ds) = simulated(3);
    let before = std::fs::read(ds.join("scans/000001.ply")).unwrap();

    let message = run_err(dir.path(), &["simulate", "--out", s(&ds), "--stops", "3"]);
    assert!(message.contains("--force"), "{message}");
    assert!(message.contains(s(&ds)), "{message}");
    assert_eq!(
        std::fs::read(ds.join("scans/000001.ply")).unwrap(),
        before,
        "a refused simulate changed the dataset"
    );

    run_ok(
        dir.path(),
        &[
            "simulate",
            "--out",
            s(&ds),
            "--stops",
            "3",
            "--seed",
            "2",
            "--force",
        ],
    );
    assert_eq!(files_with_ext(&ds.join("scans"), "ply").len(), 3);
    assert_ne!(
        std::fs::read(ds.join("scans/000001.ply")).unwrap(),
        before,
        "--force --seed 2 did not replace the scans"
    );
    let attitude = std::fs::read_to_string(ds.join("attitude.csv")).unwrap();
    assert_eq!(attitude.lines().count(), 1 + 3);

    // Fewer stops with --force: a clean 2-stop dataset, never 3 scans with 2 attitude rows.
    let r = run(
        dir.path(),
        &["simulate", "--out", s(&ds), "--stops", "2", "--force"],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let scans = files_with_ext(&ds.join("scans"), "ply").len();
    let sweeps = files_with_ext(&ds.join("sweeps"), "sweep").len();
    let rows = std::fs::read_to_string(ds.join("attitude.csv"))
        .unwrap()
        .lines()
        .count()
        - 1;
    assert_eq!(
        (scans, sweeps, rows),
        (2, 2, 2),
        "--force --stops 2 mixed datasets"
    );
}

/// `simulate --stops` out of its range is a usage error (exit 2), and nothing is written.
#[test]
fn simulate_stops_out_of_range_are_usage_errors() {
    let dir = TempDir::new().unwrap();
    let ds = dir.path().join("ds");
    usage_error(
        dir.path(),
        &["simulate", "--out", s(&ds), "--stops", "0"],
        &[
            "'0' for '--stops",
            "1..=100000",
            "up to 40 in the collapsed building",
        ],
    );
    // More than the collapsed building holds: a usage error too, saying a --route takes more.
    usage_error(
        dir.path(),
        &["simulate", "--out", s(&ds), "--stops", "41"],
        &["--stops 41", "1..=40", "--route", "Usage: sdem simulate"],
    );
    assert!(!ds.exists());
}

/// A finer scanner (`simulate --step-deg 0.5`): the dataset's sensor file says its step, a scan
/// holds about four times the returns of the 1° sweep, and `sdem slam` maps it on an S-DEM grid
/// of the same 0.5° within a centimetre of the truth. Steps outside 0.25..=5° are refused.
#[test]
fn a_finer_scanner_is_simulated_and_mapped_on_its_own_grid() {
    let dir = TempDir::new().unwrap();
    let (coarse, fine) = (dir.path().join("coarse"), dir.path().join("fine"));
    let points = |ds: &Path, step: &str| -> f64 {
        let summary = run_json(
            dir.path(),
            &[
                "simulate",
                "--out",
                s(ds),
                "--stops",
                "3",
                "--step-deg",
                step,
                "--json",
            ],
        );
        let per_scan = summary["points_per_scan"].as_array().unwrap();
        per_scan.iter().map(|n| n.as_f64().unwrap()).sum::<f64>() / per_scan.len() as f64
    };
    let ratio = points(&fine, "0.5") / points(&coarse, "1");
    assert!(
        (3.5..=4.5).contains(&ratio),
        "0.5° against 1°: {ratio}× the returns"
    );
    let sensor = std::fs::read_to_string(fine.join("sensor.toml")).unwrap();
    assert!(sensor.contains("pan_step_deg = 0.5"), "{sensor}");
    assert!(sensor.contains("tilt_step_deg = 0.5"), "{sensor}");

    let out = dir.path().join("map");
    run_ok(dir.path(), &["slam", s(&fine), "--out", s(&out)]);
    let config = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(config.contains("resolution_deg = 0.5"), "{config}");
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let ate = num(&report["truth"], "ate_rmse_m");
    assert!(ate < 0.01, "ATE {ate} m on the 0.5° scans");

    let bad = dir.path().join("bad");
    for step in ["0.1", "6", "nan", "-1"] {
        usage_error(
            dir.path(),
            &["simulate", "--out", s(&bad), "--step-deg", step],
            &[&format!("'{step}' for '--step-deg"), "[0.25, 5]"],
        );
    }
    assert!(!bad.exists());
}

// ---------------------------------------------------------------------------------------------
// sdem localize
// ---------------------------------------------------------------------------------------------

/// On consecutive stops of `simulate --seed 1 --stops 8` whose true motion lies in the default
/// window, the default search finds the translation within 1 cm of the truth, and the CLI's
/// truth and error fields agree with poses_truth.txt.
#[test]
fn localize_consecutive_stops_within_1cm() {
    let (dir, ds) = simulated(8);
    let truth = parse_kitti(&ds.join("poses_truth.txt"));
    assert_eq!(truth.len(), 8);
    let mut checked = 0;
    let mut failures = Vec::new();
    for i in 0..truth.len() - 1 {
        let (r, q) = (&truth[i], &truth[i + 1]);
        let (tr, tq) = (translation(r), translation(q));
        let world_offset = [tq[0] - tr[0], tq[1] - tr[1], tq[2] - tr[2]];
        if !inside(world_offset, &DEFAULT_WINDOW) {
            println!(
                "{i}->{}: true offset {world_offset:?} is outside the window",
                i + 1
            );
            continue;
        }
        let reference_from_query = compose(&inverse(r), q);
        // The compass is trusted here (the simulated compass errs by 0.1°), which keeps the test
        // quick; the heading search has tests of its own.
        let report = localize(dir.path(), &ds, i, i + 1, &["--heading-window", "0"]);
        let error = check_localize_report(&report, i, i + 1, &reference_from_query);
        assert_eq!(report["search"], "branch_and_bound", "{report}");
        println!(
            "{i}->{}: error {:.3} mm ({} candidates, {:.0} ms, on edge {})",
            i + 1,
            error * 1e3,
            report["candidates_evaluated"],
            num(&report, "time_ms"),
            report["on_window_edge"]
        );
        if error >= 0.01 {
            failures.push(format!(
                "{i}->{}: error {error:.4} m, estimate {}, truth {:?}",
                i + 1,
                report["reference_from_query"],
                translation(&reference_from_query)
            ));
        }
        checked += 1;
    }
    assert!(
        checked >= 4,
        "only {checked} steps inside the default window"
    );
    assert!(
        failures.is_empty(),
        "translation errors of 1 cm or more:\n{}",
        failures.join("\n")
    );
}

/// An explicit --window around the truth (±0.1 m) is used, with a ±2° heading search: it
/// localizes the lift step, whose height change lies outside the default window, within 1 cm.
#[test]
fn localize_with_an_explicit_window() {
    let (dir, ds) = simulated(4);
    let truth = parse_kitti(&ds.join("poses_truth.txt"));
    for (i, j) in [(0, 1), (2, 3)] {
        let (tr, tq) = (translation(&truth[i]), translation(&truth[j]));
        let c = [tq[0] - tr[0], tq[1] - tr[1], tq[2] - tr[2]];
        let window = format!(
            "{:.6}:{:.6},{:.6}:{:.6},{:.6}:{:.6}",
            c[0] - 0.1,
            c[0] + 0.1,
            c[1] - 0.1,
            c[1] + 0.1,
            c[2] - 0.1,
            c[2] + 0.1
        );
        // The second pair also gets a prediction 3 cm off the truth (σ 5 cm): the scans decide.
        let prior = format!("{:.6},{:.6},{:.6},0.05", c[0] + 0.03, c[1], c[2]);
        let mut extra = vec!["--window", window.as_str(), "--heading-window", "2"];
        if i == 2 {
            extra.extend(["--prior", prior.as_str()]);
        }
        let report = localize(dir.path(), &ds, i, j, &extra);
        let reference_from_query = compose(&inverse(&truth[i]), &truth[j]);
        let error = check_localize_report(&report, i, j, &reference_from_query);
        println!("{i}->{j} in {window}: error {:.3} mm", error * 1e3);
        assert!(
            error < 0.01,
            "{i}->{j} with --window {window}: error {error} m\n{report}"
        );
        assert_eq!(report["on_window_edge"], false, "{report}");
        // Diagnostics come with every result.
        let d = &report["diagnostics"];
        assert!(num(d, "overlap_fraction") > 0.5, "{d}");
        assert!(num(d, "inlier_fraction") > 0.5, "{d}");
        assert_eq!(d["ambiguous"], false, "{d}");
        assert_eq!(d["covariance"].as_array().map(Vec::len), Some(6), "{d}");
        let r = &report["refinement"];
        assert_eq!(r["outcome"], "six_dof", "{r}");
        assert_eq!(r["converged"], true, "{r}");
        assert!(num(r, "rms_m") < 0.02, "{r}");
    }
}

/// `--exhaustive` scores every candidate of a 7x7x7 window (±0.03 m at 1 cm) and lands within
/// one step of the default (branch-and-bound) search's answer over the paper's window, which
/// scores less than a tenth of its candidates.
#[test]
fn localize_exhaustive_tiny_window_matches_default_search() {
    let (dir, ds) = simulated(2);
    let truth = parse_kitti(&ds.join("poses_truth.txt"));
    let reference_from_query = compose(&inverse(&truth[0]), &truth[1]);
    let default = localize(dir.path(), &ds, 0, 1, &["--heading-window", "0"]);
    check_localize_report(&default, 0, 1, &reference_from_query);
    let full_grid = 101 * 91 * 21;
    assert_eq!(default["candidates_total"], full_grid, "{default}");
    let evaluated = default["candidates_evaluated"].as_u64().unwrap();
    assert!(
        evaluated < full_grid / 10,
        "{evaluated} candidates of {full_grid}"
    );

    // A window of 7 grid points per axis, centred on the true offset rounded to the 1 cm grid.
    let (tr, tq) = (translation(&truth[0]), translation(&truth[1]));
    let centre: Vec<i64> = (0..3)
        .map(|a| ((tq[a] - tr[a]) / 0.01).round() as i64)
        .collect();
    let window = centre
        .iter()
        .map(|&c| format!("{:.2}:{:.2}", (c - 3) as f64 * 0.01, (c + 3) as f64 * 0.01))
        .collect::<Vec<_>>()
        .join(",");
    let exhaustive = localize(
        dir.path(),
        &ds,
        0,
        1,
        &[
            "--window",
            &window,
            "--step",
            "0.01",
            "--exhaustive",
            "--heading-window",
            "0",
            "--no-runner-up",
        ],
    );
    let error = check_localize_report(&exhaustive, 0, 1, &reference_from_query);
    assert_eq!(exhaustive["candidates_evaluated"], 343, "{exhaustive}");
    assert_eq!(exhaustive["search"], "exhaustive", "{exhaustive}");
    assert_eq!(exhaustive["on_window_edge"], false, "{exhaustive}");
    assert!(error < 0.01, "exhaustive in {window}: error {error} m");
    let a = pose_xyz(&default["reference_from_query"]);
    let b = pose_xyz(&exhaustive["reference_from_query"]);
    for axis in 0..3 {
        assert!(
            (a[axis] - b[axis]).abs() <= 0.01 + 1e-9,
            "default {a:?} and exhaustive {b:?} differ by more than one step on axis {axis}"
        );
    }
}

/// Without poses_truth.txt, `localize --json` still prints the pose, and no truth fields.
#[test]
fn localize_without_truth_omits_truth_fields() {
    let (dir, ds) = simulated(2);
    std::fs::remove_file(ds.join("poses_truth.txt")).unwrap();
    let _ = std::fs::remove_file(ds.join("poses_truth.tum"));
    let report = localize(
        dir.path(),
        &ds,
        0,
        1,
        &[
            "--window",
            "0.30:0.37,-0.03:0.03,-0.03:0.03",
            "--heading-window",
            "1",
        ],
    );
    pose_xyz(&report["reference_from_query"]);
    for key in ["cost", "time_ms", "heading_correction_deg"] {
        num(&report, key);
    }
    for key in ["overlap", "candidates_evaluated", "candidates_total"] {
        assert!(report[key].is_u64(), "{key} in {report}");
    }
    for key in ["truth", "error_m", "error_deg"] {
        assert!(
            report.get(key).is_none(),
            "{key} present without truth: {report}"
        );
    }
}

/// Bad datasets and options that do not fit together: one line on stderr naming the problem,
/// exit 1, no panic; malformed values are usage errors (exit 2).
#[test]
fn localize_bad_input_gives_one_line_errors() {
    let (dir, ds) = simulated(3);
    // Numbers out of range: usage errors (cli_localize_options.rs has them all).
    for (flag, value) in [
        ("--step", "0"),
        ("--heading-window", "200"),
        ("--prior", "0.1,0.2,0,0"),
    ] {
        let mut args = vec!["localize", s(&ds), "--reference", "0", "--query", "1"];
        args.extend_from_slice(&[flag, value]);
        let m = usage_error(dir.path(), &args, &[]);
        assert!(m.contains(flag) && m.contains(value), "{m}");
    }
    let args = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    usage_error(
        dir.path(),
        &[&args[..], &["--cost", "virtual"]].concat(),
        &["--cost virtual needs --search exhaustive"],
    );
    let m = run_err(
        dir.path(),
        &["localize", s(&ds), "--reference", "0", "--query", "99"],
    );
    assert!(m.contains("--query 99 is out of range"), "{m}");
    let m = run_err(
        dir.path(),
        &[
            "localize",
            s(&dir.path().join("nowhere")),
            "--reference",
            "0",
            "--query",
            "1",
        ],
    );
    assert!(m.contains("nowhere"), "{m}");

    // Inverted and malformed windows are usage errors naming the window (clap, exit 2).
    for window in ["0.1:-0.1,0:0,0:0", "0:1,0:1", "a:b,0:0,0:0"] {
        let mut args = vec!["localize", s(&ds), "--reference", "0", "--query", "1"];
        args.extend_from_slice(&["--window", window]);
        let m = usage_error(dir.path(), &args, &[]);
        assert!(m.contains("--window"), "{m}");
    }

    // A malformed scan file: the error names it.
    let broken = dir.path().join("broken");
    copy_dir(&ds, &broken);
    std::fs::write(
        broken.join("scans/000001.ply"),
        "ply\nformat ascii 1.0\nelement vertex 9\n",
    )
    .unwrap();
    let m = run_err(
        dir.path(),
        &["localize", s(&broken), "--reference", "0", "--query", "1"],
    );
    assert!(m.contains("000001.ply"), "{m}");

    // An attitude.csv with fewer rows than scans: the error names it.
    let short = dir.path().join("short");
    copy_dir(&ds, &short);
    let text = std::fs::read_to_string(short.join("attitude.csv")).unwrap();
    let kept: Vec<&str> = text.lines().take(2).collect();
    std::fs::write(short.join("attitude.csv"), kept.join("\n") + "\n").unwrap();
    let m = run_err(
        dir.path(),
        &["localize", s(&short), "--reference", "0", "--query", "1"],
    );
    assert!(m.contains("attitude.csv"), "{m}");
}

/// Runs `localize DS --reference 0 --query 1 --heading-window 0` with `extra`; returns the exit
/// status, stdout and stderr.
fn localize_0_1(dir: &Path, ds: &Path, extra: &[&str]) -> common::Run {
    let mut args = vec![
        "localize",
        s(ds),
        "--reference",
        "0",
        "--query",
        "1",
        "--heading-window",
        "0",
    ];
    args.extend_from_slice(extra);
    run(dir, &args)
}

/// A result with doubts is never presented as a plain success. Scan 1 lies 34 cm ahead of
/// scan 0; a window that ends at 20 cm puts the optimum on its edge: exit status 3, `trusted:
/// false` with typed doubts (`on_window_edge` among them), the text labels the pose and prints
/// a DOUBT line per doubt. `--accept-doubtful` exits 0 and still says it. The default window
/// gives a trusted result, exit 0.
#[test]
fn localize_with_doubts_exits_3_and_says_why() {
    let (dir, ds) = simulated(2);
    let narrow = ["--window", "0.0:0.2,-0.1:0.1,-0.1:0.1"];

    let r = localize_0_1(dir.path(), &ds, &[&narrow[..], &["--json"]].concat());
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    let doubtful = r.json();
    assert_eq!(doubtful["trusted"], false, "{doubtful}");
    let kinds = doubt_kinds(&doubtful);
    assert!(kinds.contains(&"on_window_edge".to_string()), "{kinds:?}");
    assert_eq!(doubtful["on_window_edge"], true, "{doubtful}");
    // The figures travel with the kind: a flat cost names its direction.
    for d in doubtful["doubts"].as_array().unwrap() {
        if d["kind"] == "flat_cost" {
            assert_eq!(d["direction"].as_array().map(Vec::len), Some(3), "{d}");
        }
    }
    // The pose is still printed, and it is off: the truth lies outside the window.
    assert!(num(&doubtful, "error_m") > 0.1, "{doubtful}");
    assert!(r.stderr.contains("--accept-doubtful"), "{}", r.stderr);

    let r = localize_0_1(dir.path(), &ds, &narrow);
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(r.stdout.contains("best guess (doubtful)"), "{}", r.stdout);
    assert_eq!(
        r.stdout.matches("  DOUBT: ").count(),
        kinds.len(),
        "{}",
        r.stdout
    );
    assert!(!r.stdout.contains("AMBIGUOUS"), "{}", r.stdout);

    let r = localize_0_1(
        dir.path(),
        &ds,
        &[&narrow[..], &["--json", "--accept-doubtful"]].concat(),
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let accepted = r.json();
    assert_eq!(accepted["trusted"], false, "{accepted}");
    // The same doubts (their figures' last digits move with the parallel sums' order).
    assert_eq!(doubt_kinds(&accepted), doubt_kinds(&doubtful));
    let r = localize_0_1(
        dir.path(),
        &ds,
        &[&narrow[..], &["--accept-doubtful"]].concat(),
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(r.stdout.contains("best guess (doubtful)"), "{}", r.stdout);
    assert!(r.stdout.contains("DOUBT: "), "{}", r.stdout);

    // The default window holds the truth: trusted, no doubt, status 0.
    let r = localize_0_1(dir.path(), &ds, &["--json"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let trusted = r.json();
    assert_eq!(trusted["trusted"], true, "{trusted}");
    assert!(doubt_kinds(&trusted).is_empty(), "{trusted}");
    assert!(num(&trusted, "error_m") < 0.01, "{trusted}");
    let r = localize_0_1(dir.path(), &ds, &[]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(r.stdout.contains("  estimate  "), "{}", r.stdout);
    assert!(!r.stdout.contains("DOUBT"), "{}", r.stdout);
}

// ---------------------------------------------------------------------------------------------
// sdem demo
// ---------------------------------------------------------------------------------------------

/// `demo --json`: both paper cases within 1 cm, a run of at least 5 stops, and the files it
/// writes.
#[test]
fn demo_json_meets_the_paper_and_writes_its_files() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("demo");
    let report = run_json(dir.path(), &["demo", "--out", s(&out), "--json"]);
    let cases = report["paper_experiment"]
        .as_array()
        .expect("paper_experiment array");
    assert_eq!(cases.len(), 2, "{report}");
    for case in cases {
        assert!(case["case"].is_string(), "{case}");
        pose_xyz(&case["truth"]);
        pose_xyz(&case["estimate"]);
        let e = num(case, "error_m");
        assert!(e < 0.01, "paper case {} off by {e} m", case["case"]);
        // The paper's room fixes every direction: no doubt.
        assert_eq!(case["trusted"], true, "{case}");
        assert_eq!(case["doubts"], Value::Array(vec![]), "{case}");
    }
    let run = &report["run"];
    assert!(run.is_object(), "{report}");
    // Every step says whether it is trusted, and the run counts those that are not.
    let steps: Vec<&Value> = run["stops"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s.get("step"))
        .collect();
    let doubtful = steps.iter().filter(|t| t["trusted"] == false).count();
    assert!(steps.iter().all(|t| t["trusted"].is_boolean()), "{run}");
    assert_eq!(run["doubtful_steps"], doubtful, "{run}");
    for name in [
        "report.json",
        "poses.txt",
        "poses.tum",
        "poses_truth.txt",
        "map.ply",
    ] {
        assert!(out.join(name).is_file(), "demo did not write {name}");
    }
    let poses = parse_kitti(&out.join("poses.txt"));
    assert!(poses.len() >= 5, "{} stops", poses.len());
}

// ---------------------------------------------------------------------------------------------
// sdem bench
// ---------------------------------------------------------------------------------------------

/// `bench --quick --json` on one coarse pair (keeps the test short; the README quotes a full
/// run): the exact search and the oracle return the same minimum, with and without a heading
/// search, the exact one scoring a small share of the candidates in less time; the pair is
/// localized well within 2 cm, with and without the compass; the pose graph shrinks the loop's
/// error. The bounds are the README's figures over 50 pairs, with margin for one pair.
#[test]
fn bench_quick_json_reports_identical_minima_and_figures() {
    let dir = TempDir::new().unwrap();
    let report = run_json(
        dir.path(),
        &[
            "bench", "--quick", "--pairs", "1", "--step", "0.04", "--json",
        ],
    );
    for name in ["exact", "exact_heading"] {
        let exact = &report[name];
        assert_eq!(exact["identical"], true, "{name}: {exact}");
        assert_eq!(
            num(exact, "exhaustive_cost"),
            num(exact, "branch_and_bound_cost"),
            "{name}"
        );
        let candidates = exact["candidates"].as_u64().unwrap();
        let scored = exact["candidates_scored"].as_u64().unwrap();
        // 64 of 10,571 measured with the compass trusted.
        assert!(scored * 10 < candidates, "{name}: {scored} of {candidates}");
        let exhaustive_ms = num(exact, "exhaustive_ms");
        let exact_ms = num(&exact["branch_and_bound_ms"], "median");
        assert!(exhaustive_ms > 0.0 && exact_ms > 0.0, "{name}: {exact}");
        // 16x measured with the compass trusted on an idle 2-core machine; 2x leaves room for
        // a busy one.
        assert!(num(exact, "ratio") > 2.0, "{name}: {exact}");
    }
    for (name, heading) in [("pairs", 10.0), ("pairs_no_compass", 180.0)] {
        let pairs = &report[name];
        assert_eq!(pairs["count"], 1, "{name}: {pairs}");
        assert_eq!(num(pairs, "heading_window_deg"), heading, "{name}: {pairs}");
        assert_eq!(num(pairs, "success_rate_2cm"), 1.0, "{name}: {pairs}");
        assert_eq!(pairs["failures"], Value::Array(vec![]), "{name}: {pairs}");
        // 0.77 mm and 0.025° measured; the README's 50 pairs: max 3.64 mm, p95 0.077°.
        let max = |key: &str| num(&pairs[key], "max");
        assert!(max("translation_error_mm") < 5.0, "{name}: {pairs}");
        assert!(max("rotation_error_deg") < 0.1, "{name}: {pairs}");
        assert!(num(&pairs["time_ms"], "median") > 0.0, "{name}: {pairs}");
    }
    // The 1,000-node loop: 11.2 m of ATE before, 1.0 m after measured.
    let graph = &report["pose_graph"];
    assert_eq!(graph["nodes"], 1000, "{graph}");
    assert!(
        num(graph, "ate_after_m") < 0.2 * num(graph, "ate_before_m"),
        "{graph}"
    );
    assert!(num(graph, "time_ms") > 0.0, "{graph}");
}
