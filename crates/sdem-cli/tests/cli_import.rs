//! Optional `attitude.csv`, `odometry.txt` in datasets and from `sdem simulate`, and
//! `sdem import` of 3DTK folders and KITTI sequences. Every test runs the real binary in its own
//! temporary folder on small synthetic inputs (no shared data needed).

mod common;

use common::{run_err, run_json, run_ok, usage_error};
use std::path::{Path, PathBuf};
use tempfile::TempDir;

// ---------------------------------------------------------------------------------------------
// Helpers: running the binary
// ---------------------------------------------------------------------------------------------

fn s(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}

fn write(path: &Path, content: &str) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, content).unwrap();
}

/// KITTI-format poses as `[[f64; 4]; 3]`.
fn parse_kitti(path: &Path) -> Vec<[[f64; 4]; 3]> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            assert_eq!(v.len(), 12, "{l}");
            [
                [v[0], v[1], v[2], v[3]],
                [v[4], v[5], v[6], v[7]],
                [v[8], v[9], v[10], v[11]],
            ]
        })
        .collect()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

// ---------------------------------------------------------------------------------------------
// Synthetic inputs
// ---------------------------------------------------------------------------------------------

/// A 3DTK folder with `n` scans. Scan `i` stands 150·i cm forward (3DTK z) and 10·i cm to the
/// right (3DTK x), turned 5·i° about 3DTK's up axis (y). Each scan has a far sentinel point and
/// a point on the robot, which import drops.
fn uos_folder(dir: &Path, n: usize, frames: bool) -> PathBuf {
    let source = dir.join("uos");
    for i in 0..n {
        write(
            &source.join(format!("scan{i:03}.3d")),
            "100 0 200\n-50 20 300 0.5\n0 -30 150\n0 0 3276\n1 1 5\n",
        );
        write(
            &source.join(format!("scan{i:03}.pose")),
            &format!("{} 0 {}\n0 {} 0\n", 10 * i, 150 * i, 5 * i),
        );
        if frames {
            // Identity, then the final registration: 1 cm further forward than the pose.
            write(
                &source.join(format!("slam6d_frames_2009/scan{i:03}.frames")),
                &format!(
                    "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2\n1 0 0 0 0 1 0 0 0 0 1 0 {} 0 {} 1 1\n",
                    10 * i,
                    150 * i + 1
                ),
            );
        }
    }
    source
}

/// A KITTI sequence folder with `n` scans of two points; camera 0 moves 0.8 m forward (its z)
/// per frame; `Tr` maps Velodyne axes to camera axes with an offset.
fn kitti_folder(dir: &Path, n: usize) -> PathBuf {
    let source = dir.join("kitti");
    std::fs::create_dir_all(source.join("velodyne")).unwrap();
    for i in 0..n {
        let bytes: Vec<u8> = [[1.0f32 + i as f32, 2.0, 3.0, 0.5], [4.0, 5.0, 6.0, 0.25]]
            .iter()
            .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
            .collect();
        std::fs::write(source.join(format!("velodyne/{i:06}.bin")), bytes).unwrap();
    }
    let poses: String = (0..n)
        .map(|i| format!("1 0 0 0 0 1 0 0 0 0 1 {}\n", 0.8 * i as f64))
        .collect();
    write(&source.join("poses.txt"), &poses);
    write(
        &source.join("calib.txt"),
        "P0: 718 0 607 0 0 718 185 0 0 0 1 0\nTr: 0 -1 0 -0.01 0 0 -1 -0.05 1 0 0 -0.29\n",
    );
    source
}

// ---------------------------------------------------------------------------------------------
// sdem import: 3DTK
// ---------------------------------------------------------------------------------------------

/// A 3DTK folder becomes scans (filtered), odometry.txt, attitude.csv and poses_slam6d.txt in
/// sdem's right-handed frame; never poses_truth.txt.
#[test]
fn import_3dtk_converts_frames_and_filters_points() {
    let dir = TempDir::new().unwrap();
    let source = uos_folder(dir.path(), 3, true);
    let out = dir.path().join("ds");
    let summary = run_json(
        dir.path(),
        &["import", s(&source), "--out", s(&out), "--json"],
    );
    assert_eq!(summary["format"], "3dtk", "{summary}");
    assert_eq!(summary["scans"], 3, "{summary}");
    assert_eq!(summary["points_per_scan"], serde_json::json!([3, 3, 3]));
    assert_eq!(summary["dropped_far"], 3, "{summary}");
    assert_eq!(summary["dropped_near"], 3, "{summary}");
    let written: Vec<&str> = summary["written"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    for file in ["odometry.txt", "attitude.csv", "poses_slam6d.txt"] {
        assert!(written.contains(&file), "{summary}");
        assert!(out.join(file).is_file(), "{file}");
    }
    // Five points a scan show no scanner's lines: no sensor model is made up, and the note
    // says so (the steps measured from real scans: `sdem-io`'s import tests).
    assert!(!out.join("sensor.toml").exists());
    assert!(
        summary["notes"][0]
            .as_str()
            .is_some_and(|n| n.starts_with("no sensor.toml written")),
        "{summary}"
    );
    assert!(!out.join("poses_truth.txt").exists());
    for i in 0..3 {
        assert!(out.join(format!("scans/{i:06}.ply")).is_file());
    }

    // Odometry: 3DTK (x right, z forward, cm) → sdem (x forward, y left, m): scan 2 stands
    // 3 m forward and 0.2 m to the RIGHT, i.e. y = −0.2.
    let odometry = parse_kitti(&out.join("odometry.txt"));
    assert_eq!(odometry.len(), 3);
    assert!(close(odometry[2][0][3], 3.0, 1e-9), "{:?}", odometry[2]);
    assert!(close(odometry[2][1][3], -0.2, 1e-9), "{:?}", odometry[2]);
    assert!(close(odometry[2][2][3], 0.0, 1e-9), "{:?}", odometry[2]);
    // Turned +10° about 3DTK's up axis (towards its right): the sensor's forward axis points to
    // −y in sdem, a yaw of −10°.
    assert!(odometry[2][1][0] < 0.0, "{:?}", odometry[2]);
    let yaw = odometry[2][1][0].atan2(odometry[2][0][0]).to_degrees();
    assert!(close(yaw, -10.0, 1e-6), "{yaw}");

    let attitude = std::fs::read_to_string(out.join("attitude.csv")).unwrap();
    let rows: Vec<Vec<f64>> = attitude
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|c| c.trim().parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 3, "{attitude}");
    assert!(close(rows[1][3], -5.0, 1e-9), "{attitude}");
    assert!(close(rows[2][3], -10.0, 1e-9), "{attitude}");

    let slam6d = parse_kitti(&out.join("poses_slam6d.txt"));
    assert!(close(slam6d[2][0][3], 3.01, 1e-9), "{:?}", slam6d[2]);
    assert!(close(slam6d[2][1][3], -0.2, 1e-9), "{:?}", slam6d[2]);

    // The first point of every scan: 3DTK (100, 0, 200) cm → (2, −1, 0) m.
    let ply = std::fs::read(out.join("scans/000000.ply")).unwrap();
    let header_end = ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = String::from_utf8_lossy(&ply[..header_end]);
    assert!(header.contains("element vertex 3"), "{header}");
    let xyz: Vec<f32> = ply[header_end..header_end + 12]
        .chunks(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert_eq!(xyz, vec![2.0, -1.0, 0.0]);

    // --first/--count and text output.
    let out2 = dir.path().join("ds2");
    let text = run_ok(
        dir.path(),
        &[
            "import",
            s(&source),
            "--out",
            s(&out2),
            "--format",
            "3dtk",
            "--first",
            "1",
            "--count",
            "1",
        ],
    );
    assert!(text.contains("imported 1 3DTK scans"), "{text}");
    assert!(
        text.contains("\"no return\" range (32.76 m and beyond)"),
        "{text}"
    );
    assert!(text.contains("no sensor.toml written"), "{text}");
    assert_eq!(parse_kitti(&out2.join("odometry.txt")).len(), 1);
}

/// Without a frames folder no poses_slam6d.txt; an explicit --frames folder is used.
#[test]
fn import_3dtk_frames_are_optional() {
    let dir = TempDir::new().unwrap();
    let source = uos_folder(dir.path(), 2, false);
    let out = dir.path().join("ds");
    run_ok(dir.path(), &["import", s(&source), "--out", s(&out)]);
    assert!(out.join("odometry.txt").is_file());
    assert!(!out.join("poses_slam6d.txt").exists());

    let frames = dir.path().join("myframes");
    for i in 0..2 {
        write(
            &frames.join(format!("scan{i:03}.frames")),
            "1 0 0 0 0 1 0 0 0 0 1 0 0 0 50 1 2\n",
        );
    }
    let out2 = dir.path().join("ds2");
    run_ok(
        dir.path(),
        &[
            "import",
            s(&source),
            "--out",
            s(&out2),
            "--frames",
            s(&frames),
        ],
    );
    let slam6d = parse_kitti(&out2.join("poses_slam6d.txt"));
    assert!(close(slam6d[1][0][3], 0.5, 1e-12), "{:?}", slam6d[1]);
}

// ---------------------------------------------------------------------------------------------
// sdem import: KITTI
// ---------------------------------------------------------------------------------------------

/// A KITTI sequence: .bin copied unchanged, Velodyne truth re-based on the first imported scan,
/// no attitude.csv.
#[test]
fn import_kitti_copies_scans_and_rebases_truth() {
    let dir = TempDir::new().unwrap();
    let source = kitti_folder(dir.path(), 6);
    let out = dir.path().join("ds");
    let summary = run_json(
        dir.path(),
        &[
            "import",
            s(&source),
            "--out",
            s(&out),
            "--first",
            "2",
            "--count",
            "3",
            "--json",
        ],
    );
    assert_eq!(summary["format"], "kitti", "{summary}");
    assert_eq!(summary["scans"], 3, "{summary}");
    assert_eq!(summary["points_per_scan"], serde_json::json!([2, 2, 2]));
    for i in 0..3 {
        assert_eq!(
            std::fs::read(out.join(format!("scans/{i:06}.bin"))).unwrap(),
            std::fs::read(source.join(format!("velodyne/{:06}.bin", i + 2))).unwrap()
        );
    }
    assert!(!out.join("attitude.csv").exists());
    assert!(!out.join("odometry.txt").exists());
    let truth = parse_kitti(&out.join("poses_truth.txt"));
    assert_eq!(truth.len(), 3);
    let identity = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    assert_eq!(truth[0], identity);
    // The camera's forward (z) is the Velodyne's x.
    assert!(close(truth[2][0][3], 1.6, 1e-9), "{:?}", truth[2]);
    assert!(close(truth[2][1][3], 0.0, 1e-9) && close(truth[2][2][3], 0.0, 1e-9));
    assert!(out.join("poses_truth.tum").is_file());
}

// ---------------------------------------------------------------------------------------------
// sdem import: errors
// ---------------------------------------------------------------------------------------------

/// Each bad input gives one line naming the file (and line), exit 1, and writes nothing.
#[test]
fn import_errors_name_the_problem() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("ds");
    let import = |source: &Path, extra: &[&str]| -> String {
        let mut args = vec!["import", s(source), "--out", s(&out)];
        args.extend_from_slice(extra);
        let m = run_err(dir.path(), &args);
        assert!(!out.join("scans").exists(), "a failed import wrote scans");
        m
    };

    // Source missing.
    let m = import(&dir.path().join("nowhere"), &[]);
    assert!(m.contains("nowhere") && m.contains("does not exist"), "{m}");

    // No scans.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let m = import(&empty, &[]);
    assert!(m.contains("empty") && m.contains("neither"), "{m}");
    let m = import(&empty, &["--format", "3dtk"]);
    assert!(m.contains("no scans"), "{m}");
    let m = import(&empty, &["--format", "kitti"]);
    assert!(m.contains("velodyne"), "{m}");

    // A .pose missing for a .3d; a malformed pose line.
    let source = uos_folder(dir.path(), 2, true);
    std::fs::remove_file(source.join("scan001.pose")).unwrap();
    let m = import(&source, &[]);
    assert!(m.contains("scan001.pose is missing"), "{m}");
    write(&source.join("scan001.pose"), "0 0 150\n0 five 0\n");
    let m = import(&source, &[]);
    assert!(m.contains("scan001.pose:2"), "{m}");
    write(&source.join("scan001.pose"), "0 0 150\n0 5 0\n");

    // A malformed frames line.
    write(
        &source.join("slam6d_frames_2009/scan001.frames"),
        "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2\n1 0 0 0\n",
    );
    let m = import(&source, &[]);
    assert!(m.contains("scan001.frames:2"), "{m}");
    std::fs::remove_dir_all(source.join("slam6d_frames_2009")).unwrap();

    // A malformed .3d line (found while writing: nothing is left).
    write(&source.join("scan001.3d"), "100 0 200\n1 2\n");
    let m = import(&source, &[]);
    assert!(m.contains("scan001.3d:2"), "{m}");

    // KITTI: malformed calib and poses lines.
    let kitti = kitti_folder(dir.path(), 2);
    write(&kitti.join("calib.txt"), "P0: 1 0 0\nTr: 1 0 0 0 0 1\n");
    let m = import(&kitti, &[]);
    assert!(m.contains("calib.txt:2"), "{m}");
    write(&kitti.join("calib.txt"), "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n");
    write(
        &kitti.join("poses.txt"),
        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 x 0\n",
    );
    let m = import(&kitti, &[]);
    assert!(m.contains("poses.txt:2"), "{m}");

    // --count 0 (a usage error), and more scans asked than there are.
    usage_error(
        dir.path(),
        &["import", s(&kitti), "--out", s(&out), "--count", "0"],
        &["'0' for '--count", "≥ 1", "0 imports nothing"],
    );
    assert!(!out.join("scans").exists());
    write(
        &kitti.join("poses.txt"),
        &"1 0 0 0 0 1 0 0 0 0 1 0\n".repeat(2),
    );
    let m = import(&kitti, &["--count", "3"]);
    assert!(m.contains("3 scans asked"), "{m}");
}

/// --out not empty: refused without --force (nothing changed); --force replaces the dataset and
/// keeps unrelated files.
#[test]
fn import_refuses_a_non_empty_out_without_force() {
    let dir = TempDir::new().unwrap();
    let source = uos_folder(dir.path(), 2, false);
    let out = dir.path().join("ds");
    write(&out.join("notes.md"), "mine");
    let m = run_err(dir.path(), &["import", s(&source), "--out", s(&out)]);
    assert!(m.contains("not empty") && m.contains("--force"), "{m}");
    assert!(!out.join("scans").exists());

    run_ok(
        dir.path(),
        &["import", s(&source), "--out", s(&out), "--force"],
    );
    assert!(out.join("scans/000001.ply").is_file());
    // Again with one scan and --force: no stale scan is left, notes.md is kept.
    run_ok(
        dir.path(),
        &[
            "import",
            s(&source),
            "--out",
            s(&out),
            "--count",
            "1",
            "--force",
        ],
    );
    assert!(out.join("scans/000000.ply").is_file());
    assert!(!out.join("scans/000001.ply").exists());
    assert!(out.join("notes.md").is_file());

    // A KITTI import over the 3DTK dataset: the old odometry and attitude are removed.
    let kitti = kitti_folder(dir.path(), 2);
    run_ok(
        dir.path(),
        &["import", s(&kitti), "--out", s(&out), "--force"],
    );
    assert!(!out.join("odometry.txt").exists() && !out.join("attitude.csv").exists());
    assert!(!out.join("scans/000000.ply").exists());
    assert!(out.join("scans/000001.bin").is_file());
}

// ---------------------------------------------------------------------------------------------
// sdem simulate: odometry.txt
// ---------------------------------------------------------------------------------------------

/// simulate writes odometry.txt by default (seeded, noisy, starting at the truth) and not with
/// --no-odometry; --force removes an old one.
#[test]
fn simulate_writes_seeded_odometry() {
    let dir = TempDir::new().unwrap();
    let a = dir.path().join("a");
    let b = dir.path().join("b");
    for out in [&a, &b] {
        run_ok(
            dir.path(),
            &["simulate", "--out", s(out), "--stops", "4", "--seed", "3"],
        );
    }
    let odometry = std::fs::read(a.join("odometry.txt")).unwrap();
    assert_eq!(odometry, std::fs::read(b.join("odometry.txt")).unwrap());
    assert!(a.join("odometry.tum").is_file());
    let odometry = parse_kitti(&a.join("odometry.txt"));
    let truth = parse_kitti(&a.join("poses_truth.txt"));
    assert_eq!(odometry.len(), 4);
    assert_eq!(odometry[0], truth[0]);
    for i in 1..4 {
        let d: f64 = (0..3)
            .map(|r| (odometry[i][r][3] - truth[i][r][3]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(d > 0.0 && d < 0.3, "stop {i}: odometry off by {d} m");
    }
    // Another seed, other noise.
    let c = dir.path().join("c");
    run_ok(
        dir.path(),
        &["simulate", "--out", s(&c), "--stops", "4", "--seed", "4"],
    );
    assert_ne!(parse_kitti(&c.join("odometry.txt")), odometry);

    run_ok(
        dir.path(),
        &[
            "simulate",
            "--out",
            s(&a),
            "--stops",
            "4",
            "--no-odometry",
            "--force",
        ],
    );
    assert!(!a.join("odometry.txt").exists() && !a.join("odometry.tum").exists());
    usage_error(
        dir.path(),
        &[
            "simulate",
            "--out",
            s(&b),
            "--odometry-noise",
            "-1",
            "--force",
        ],
        &["'-1' for '--odometry-noise", "≥ 0"],
    );
}

// ---------------------------------------------------------------------------------------------
// Datasets without attitude.csv
// ---------------------------------------------------------------------------------------------

/// A dataset without attitude.csv opens; localize takes its attitude as unknown and says so
/// (text and JSON), refuses the flags that need a compass reading, and with --assume-level
/// takes both scans as level: the same pose as with an attitude.csv of level readings.
#[test]
fn localize_without_attitude_is_unknown_or_assumed_level() {
    let dir = TempDir::new().unwrap();
    let help = run_ok(dir.path(), &["localize", "--help"]);
    assert!(
        help.contains("the attitude is unknown") && help.contains("--assume-level"),
        "{help}"
    );

    let ds = dir.path().join("ds");
    run_ok(
        dir.path(),
        &["simulate", "--out", s(&ds), "--stops", "2", "--seed", "1"],
    );
    let base = [
        "localize",
        s(&ds),
        "--reference",
        "0",
        "--query",
        "1",
        "--window",
        "0.2:0.5,-0.1:0.1,-0.1:0.1",
        "--step",
        "0.05",
        "--no-runner-up",
        "--accept-doubtful",
        "--json",
    ];
    let localize = |extra: &[&str]| run_json(dir.path(), &[&base[..], extra].concat());
    write(
        &ds.join("attitude.csv"),
        "index,roll_deg,pitch_deg,yaw_deg\n0,0,0,0\n1,0,0,0\n",
    );
    let with_level_readings = localize(&["--heading-window", "0"]);
    assert_eq!(with_level_readings["attitude"]["source"], "readings");
    assert_eq!(with_level_readings["attitude"]["sigma_from"], "the default");
    std::fs::remove_file(ds.join("attitude.csv")).unwrap();
    let assumed_level = localize(&["--heading-window", "0", "--assume-level"]);
    let attitude = &assumed_level["attitude"];
    assert_eq!(attitude["source"], "assumed_level", "{attitude}");
    assert_eq!(attitude["heading_searched_deg"], 0.0, "{attitude}");
    assert_eq!(attitude["roll_pitch_searched"], false, "{attitude}");
    let (a, b) = (
        &assumed_level["reference_from_query"],
        &with_level_readings["reference_from_query"],
    );
    // The same search and refinement; only the parallel sums' order may move the last digit.
    for key in ["x", "y", "z", "roll_deg", "pitch_deg", "yaw_deg"] {
        let (a, b) = (a[key].as_f64().unwrap(), b[key].as_f64().unwrap());
        assert!(
            (a - b).abs() < 1e-9,
            "{key}: {assumed_level} against {with_level_readings}"
        );
    }

    // Unknown: the whole rotation is searched, and the output says so.
    let unknown = localize(&[]);
    let attitude = &unknown["attitude"];
    assert_eq!(attitude["source"], "unknown", "{attitude}");
    assert_eq!(attitude["roll_pitch_searched"], true, "{attitude}");
    assert_eq!(attitude["heading_searched_deg"], 180.0, "{attitude}");
    assert!(
        attitude["reference"].is_null() && attitude["sigma_from"].is_null(),
        "{attitude}"
    );
    let text = common::run(dir.path(), &base[..base.len() - 1]).stdout;
    assert!(
        text.contains("attitude: unknown (no attitude.csv): roll/pitch and heading searched"),
        "{text}"
    );
    assert!(!text.contains("to the compass"), "{text}");

    // Flags that describe a compass reading need one.
    for flag in [["--heading-window", "5"], ["--attitude-sigma-deg", "0.5,3"]] {
        let m = run_err(dir.path(), &[&base[..base.len() - 1], &flag[..]].concat());
        assert!(m.contains(flag[0]) && m.contains("no attitude.csv"), "{m}");
    }

    // A present attitude.csv with the wrong row count is still an error naming it.
    write(
        &ds.join("attitude.csv"),
        "index,roll_deg,pitch_deg,yaw_deg\n0,0,0,0\n",
    );
    let m = run_err(
        dir.path(),
        &["localize", s(&ds), "--reference", "0", "--query", "1"],
    );
    assert!(
        m.contains("attitude.csv") && m.contains("1 row ") && m.contains("2 scans"),
        "{m}"
    );
}
