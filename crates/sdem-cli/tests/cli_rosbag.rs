//! ROS 2 bags in and MCAP out, checked against other people's code: the bags are written by
//! the Python `rosbags` library (rosbag2 folders, MCAP and SQLite3 storage) and by `mcap` with
//! `mcap-ros2-support` (one .mcap file) from a `sdem simulate` run
//! (`tests/fixtures/make_bag.py`), and sdem's MCAP output is read back by `mcap-ros2-support`,
//! which decodes it from the schemas the file embeds (`tests/fixtures/read_mcap.py`).
//!
//! The Python comes from `SDEM_TEST_PYTHON`, which `scripts/test` sets up; without it these
//! tests fail saying how to get it.

mod common;

use common::{run, run_err, run_json, run_ok};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The Python with `rosbags`, `mcap` and `mcap-ros2-support` (scripts/test-requirements.txt).
fn python() -> PathBuf {
    match std::env::var_os("SDEM_TEST_PYTHON") {
        Some(p) if Path::new(&p).is_file() => PathBuf::from(p),
        _ => panic!(
            "SDEM_TEST_PYTHON is not set to a Python with the packages of \
             scripts/test-requirements.txt; run scripts/test (it makes target/test-venv), or: \
             python3 -m venv target/test-venv && target/test-venv/bin/pip install -r \
             scripts/test-requirements.txt && export SDEM_TEST_PYTHON=$PWD/target/test-venv/bin/python"
        ),
    }
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn python_run(args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = std::process::Command::new(python())
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .expect("cannot run Python");
    assert!(
        out.status.success(),
        "python {:?} failed:\n{}",
        args.iter()
            .map(|a| a.as_ref().to_owned())
            .collect::<Vec<_>>(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Writes a bag of the simulated run `dataset` with `make_bag.py` and its extra flags.
fn make_bag(dataset: &Path, out: &Path, storage: &str, extra: &[&str]) {
    let script = fixture("make_bag.py");
    let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> =
        vec![&"-B", &script, &dataset, &out, &"--storage", &storage];
    for e in extra {
        args.push(e);
    }
    python_run(&args);
}

/// A simulated 12-stop run (seed 3, compass noise 2°), made once for all tests.
fn simulated() -> &'static Path {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let sim = dir.path().join("sim");
        run_ok(
            dir.path(),
            &[
                "simulate",
                "--out",
                sim.to_str().unwrap(),
                "--stops",
                "12",
                "--seed",
                "3",
                "--compass-noise-deg",
                "2",
            ],
        );
        (dir, sim)
    })
    .1
}

fn read_rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with("index") && !l.trim().is_empty())
        .map(|l| {
            l.split([',', ' '])
                .filter(|t| !t.is_empty())
                .map(|t| t.parse().unwrap())
                .collect()
        })
        .collect()
}

fn assert_rows_close(a: &Path, b: &Path, tolerance: f64) {
    let (ra, rb) = (read_rows(a), read_rows(b));
    assert_eq!(ra.len(), rb.len(), "{} vs {}", a.display(), b.display());
    for (x, y) in ra.iter().zip(&rb) {
        for (u, v) in x.iter().zip(y) {
            assert!(
                (u - v).abs() <= tolerance,
                "{} vs {}: {x:?} / {y:?}",
                a.display(),
                b.display()
            );
        }
    }
}

/// Imports a bag with no flags, checks the readings against the simulation, maps it with
/// `--mcap`, and returns the slam report and the MCAP file's content as the reader saw it.
fn import_and_map(dir: &Path, bag: &Path) -> (Value, Value) {
    let sim = simulated();
    let ds = dir.join("ds");
    let summary = run_json(
        dir,
        &[
            "import",
            bag.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
            "--json",
        ],
    );
    assert_eq!(summary["stops"], 12, "{summary}");
    assert_eq!(summary["scan_topic"]["topic"], "/robot/lidar/points");
    assert_eq!(summary["imu_topic"]["topic"], "/robot/imu/data");
    assert_eq!(summary["odom_topic"]["topic"], "/robot/wheel_odom");
    assert!(
        summary["mounting"].as_str().unwrap().contains("yaw 90.00°"),
        "{summary}"
    );
    // Through the turned sensor and the upside-down IMU, back to the readings simulated.
    assert_rows_close(&ds.join("attitude.csv"), &sim.join("attitude.csv"), 1e-6);
    assert_rows_close(&ds.join("odometry.txt"), &sim.join("odometry.txt"), 1e-9);
    let mcap = dir.join("run.mcap");
    let truth = sim.join("poses_truth.txt");
    let out = dir.join("map");
    let report = run_json(
        dir,
        &[
            "slam",
            ds.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--compare",
            truth.to_str().unwrap(),
            "--no-pictures",
            "--mcap",
            mcap.to_str().unwrap(),
            "--json",
        ],
    );
    let read = python_run(&[&"-B", &fixture("read_mcap.py"), &mcap]);
    (report, serde_json::from_str(&read).unwrap())
}

fn check_mcap(report: &Value, read: &Value, poses: &Path) {
    assert_eq!(read["profile"], "ros2");
    let topics = &read["topics"];
    let expect = [
        ("/sdem/map", "sensor_msgs/msg/PointCloud2", 1),
        ("/sdem/scans", "sensor_msgs/msg/PointCloud2", 12),
        ("/sdem/trajectory", "nav_msgs/msg/Path", 1),
        ("/tf", "tf2_msgs/msg/TFMessage", 12),
        (
            "/sdem/loop_closures",
            "visualization_msgs/msg/MarkerArray",
            1,
        ),
    ];
    for (topic, schema, count) in expect {
        assert_eq!(topics[topic]["schema"], schema, "{read}");
        assert_eq!(topics[topic]["count"], count, "{read}");
    }
    assert_eq!(read["map_points"], report["map_points"]);
    assert_eq!(read["map_frame"], "map");
    // The path and /tf hold the poses of poses.txt.
    let rows = read_rows(poses);
    let path = read["path"].as_array().unwrap();
    for (row, (p, tf)) in rows
        .iter()
        .zip(path.iter().zip(read["tf"].as_array().unwrap()))
    {
        for (k, col) in [3, 7, 11].iter().enumerate() {
            assert!((p[k].as_f64().unwrap() - row[*col]).abs() < 1e-9);
            assert!((tf[2 + k].as_f64().unwrap() - row[*col]).abs() < 1e-9);
        }
        assert_eq!(
            (tf[0].as_str(), tf[1].as_str()),
            (Some("map"), Some("base_link"))
        );
    }
    let closures = report["loop_closures_accepted"].as_u64().unwrap();
    assert_eq!(read["markers"][0], serde_json::json!([5, 2 * closures]));
    assert_eq!(read["markers"][1], serde_json::json!([7, 12]));
}

#[test]
fn a_stop_and_go_bag_in_mcap_imports_with_no_flags_and_maps_within_2_cm() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    make_bag(simulated(), &bag, "mcap", &[]);
    let (report, read) = import_and_map(dir.path(), &bag);
    let ate = report["compare"]["ate_rmse_m"].as_f64().unwrap();
    assert!(ate <= 0.02, "ATE {ate} m");
    check_mcap(&report, &read, &dir.path().join("map/poses.txt"));
    // `sdem export` writes the same from the saved map.
    let again = dir.path().join("again.mcap");
    let map = dir.path().join("map");
    run_ok(
        dir.path(),
        &[
            "export",
            map.to_str().unwrap(),
            "--mcap",
            again.to_str().unwrap(),
        ],
    );
    let read_again = python_run(&[&"-B", &fixture("read_mcap.py"), &again]);
    let read_again: Value = serde_json::from_str(&read_again).unwrap();
    assert_eq!(read_again["path"], read["path"]);
    assert_eq!(read_again["topics"], read["topics"]);
    let e = run_err(
        dir.path(),
        &[
            "export",
            map.to_str().unwrap(),
            "--mcap",
            again.to_str().unwrap(),
        ],
    );
    assert!(e.contains("already exists") && e.contains("--force"), "{e}");
}

#[test]
fn a_stop_and_go_bag_in_sqlite3_imports_with_no_flags_and_maps_within_2_cm() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    make_bag(simulated(), &bag, "sqlite3", &[]);
    let (report, read) = import_and_map(dir.path(), &bag);
    let ate = report["compare"]["ate_rmse_m"].as_f64().unwrap();
    assert!(ate <= 0.02, "ATE {ate} m");
    check_mcap(&report, &read, &dir.path().join("map/poses.txt"));
}

#[test]
fn one_mcap_file_from_the_mcap_library_imports_like_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("run.mcap");
    make_bag(simulated(), &bag, "mcap-file", &[]);
    let ds = dir.path().join("ds");
    run_ok(
        dir.path(),
        &[
            "import",
            bag.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
        ],
    );
    assert_rows_close(
        &ds.join("attitude.csv"),
        &simulated().join("attitude.csv"),
        1e-6,
    );
    for i in [0, 11] {
        let name = format!("scans/{i:06}.ply");
        assert_eq!(
            sdem_points(&ds.join(&name)),
            sdem_points(&simulated().join(&name)),
            "{name}: the cloud's points, NaN points dropped"
        );
    }
}

/// The points of a binary PLY sdem wrote (the body after the header).
fn sdem_points(path: &Path) -> Vec<u8> {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    bytes[end..].to_vec()
}

#[test]
fn a_tilting_laser_bag_becomes_one_scan_per_sweep_in_the_sensor_model() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    make_bag(simulated(), &bag, "mcap", &["--laser"]);
    let ds = dir.path().join("ds");
    let summary = run_json(
        dir.path(),
        &[
            "import",
            bag.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
            "--json",
        ],
    );
    assert_eq!(summary["stops"], 12, "{summary}");
    assert!(
        summary["tilt"]
            .as_str()
            .unwrap()
            .contains("laser_tilt_joint"),
        "{summary}"
    );
    assert_rows_close(
        &ds.join("attitude.csv"),
        &simulated().join("attitude.csv"),
        1e-6,
    );
    // Each sweep's points are the simulated sweep's, to the precision of float32 angles.
    for i in [0, 7] {
        let name = format!("scans/{i:06}.ply");
        let (a, b) = (
            sdem_points(&ds.join(&name)),
            sdem_points(&simulated().join(&name)),
        );
        assert_eq!(a.len(), b.len(), "{name}");
        let floats = |v: &[u8]| -> Vec<f32> {
            v.chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect()
        };
        let worst = floats(&a)
            .iter()
            .zip(floats(&b))
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{name}: {worst} m");
    }
    assert!(ds.join("sensor.toml").is_file());
}

#[test]
fn a_laser_tilted_on_tf_gives_the_same_sweeps_in_its_parent_frame() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    make_bag(simulated(), &bag, "sqlite3", &["--laser", "--laser-tf"]);
    let ds = dir.path().join("ds");
    let summary = run_json(
        dir.path(),
        &[
            "import",
            bag.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
            "--json",
        ],
    );
    assert_eq!(summary["stops"], 12, "{summary}");
    assert_eq!(summary["sensor_frame"], "tilt_base", "{summary}");
    assert_rows_close(
        &ds.join("attitude.csv"),
        &simulated().join("attitude.csv"),
        1e-6,
    );
    let name = "scans/000005.ply";
    let floats = |p: &Path| -> Vec<f32> {
        sdem_points(p)
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    };
    let (a, b) = (floats(&ds.join(name)), floats(&simulated().join(name)));
    assert_eq!(a.len(), b.len());
    assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-4));
}

#[test]
fn a_lidar_scanning_at_10_hz_gives_a_stop_per_distance_travelled() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    make_bag(simulated(), &bag, "mcap", &["--cloud-rate", "10"]);
    let ds = dir.path().join("ds");
    let summary = run_json(
        dir.path(),
        &[
            "import",
            bag.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
            "--stop-distance",
            "0.2",
            "--stop-angle",
            "5",
            "--json",
        ],
    );
    // 40 clouds at each of the 12 places; one stop where the robot arrives at each.
    assert_eq!(summary["scans_in_bag"], 480, "{summary}");
    assert_eq!(summary["stops"], 12, "{summary}");
    assert!(
        summary["stop_rule"].as_str().unwrap().contains("travelled"),
        "{summary}"
    );
    assert_rows_close(
        &ds.join("attitude.csv"),
        &simulated().join("attitude.csv"),
        1e-6,
    );
    assert_rows_close(
        &ds.join("odometry.txt"),
        &simulated().join("odometry.txt"),
        1e-9,
    );
}

#[test]
fn sdem_info_lists_topics_types_counts_and_rates() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    make_bag(simulated(), &bag, "sqlite3", &[]);
    let text = run_ok(dir.path(), &["info", bag.to_str().unwrap()]);
    assert!(text.contains("Storage id:        sqlite3"), "{text}");
    assert!(
        text.contains("Topic: /robot/imu/data") && text.contains("Rate: 50.00 Hz"),
        "{text}"
    );
    let info = run_json(dir.path(), &["info", bag.to_str().unwrap(), "--json"]);
    let topics = info["topics"].as_array().unwrap();
    let imu = topics
        .iter()
        .find(|t| t["name"] == "/robot/imu/data")
        .unwrap();
    assert_eq!(imu["type"], "sensor_msgs/msg/Imu");
    assert_eq!(imu["sdem_use"], "attitude");
    let odom = topics
        .iter()
        .find(|t| t["name"] == "/robot/wheel_odom")
        .unwrap();
    assert!(
        (odom["rate_hz"].as_f64().unwrap() - 10.0).abs() < 0.01,
        "{odom}"
    );
    let clouds = topics
        .iter()
        .find(|t| t["name"] == "/robot/lidar/points")
        .unwrap();
    assert_eq!(clouds["count"], 12);
    assert_eq!(info["messages"], info["metadata_messages"]);
}

#[test]
fn a_bag_cut_short_is_refused_naming_the_damage_and_salvaged_on_request() {
    for (storage, name) in [("mcap", "bag.mcap"), ("sqlite3", "bag.db3")] {
        cut_short(storage, name);
    }
}

fn cut_short(storage: &str, name: &str) {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    make_bag(simulated(), &bag, storage, &[]);
    let file = bag.join(name);
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..bytes.len() * 7 / 10]).unwrap();
    let ds = dir.path().join("ds");
    let e = run_err(
        dir.path(),
        &[
            "import",
            bag.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
        ],
    );
    assert!(e.contains(name) && e.contains("damaged"), "{e}");
    assert!(
        e.contains("the last whole message is") && e.contains("--salvage"),
        "{e}"
    );
    assert!(!ds.join("scans").exists(), "nothing is written");
    let summary = run_json(
        dir.path(),
        &[
            "import",
            bag.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
            "--salvage",
            "--json",
        ],
    );
    let stops = summary["stops"].as_u64().unwrap();
    assert!((4..12).contains(&stops), "{summary}");
    assert!(summary["damage"]["messages_read"].as_u64().unwrap() > 0);
    // The stops salvaged are the first ones, with their readings.
    let (got, simulated) = (
        read_rows(&ds.join("attitude.csv")),
        read_rows(&simulated().join("attitude.csv")),
    );
    assert_eq!(got.len() as u64, stops);
    for (a, b) in got.iter().zip(&simulated) {
        assert!(
            a.iter().zip(b).all(|(u, v)| (u - v).abs() < 1e-6),
            "{a:?} / {b:?}"
        );
    }
    let r = run(dir.path(), &["info", bag.to_str().unwrap()]);
    assert_eq!(r.code, Some(1));
    assert!(
        r.stdout.contains("DAMAGED") && r.stderr.contains("--salvage"),
        "{}",
        r.stderr
    );
}

#[test]
fn topics_of_the_wrong_type_or_none_are_refused_with_the_choices() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    make_bag(simulated(), &bag, "mcap", &[]);
    let ds = dir.path().join("ds");
    let import = |extra: &[&str]| {
        let mut args = vec![
            "import",
            bag.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        run_err(dir.path(), &args)
    };
    let e = import(&["--scan-topic", "/robot/imu/data"]);
    assert!(
        e.contains("sensor_msgs/msg/Imu") && e.contains("PointCloud2"),
        "{e}"
    );
    let e = import(&["--scan-topic", "/points"]);
    assert!(
        e.contains("no such topic")
            && e.contains("/robot/lidar/points (sensor_msgs/msg/PointCloud2, 12 messages)"),
        "{e}"
    );
    let e = import(&["--imu-topic", "/robot/wheel_odom"]);
    assert!(e.contains("nav_msgs/msg/Odometry"), "{e}");
    // A channel without a schema: its message type is missing.
    let untyped = dir.path().join("untyped.mcap");
    let script = "import sys\nfrom mcap.writer import Writer\nw = Writer(open(sys.argv[1], 'wb'))\n\
                  w.start(profile='ros2')\nc = w.register_channel('/points', 'cdr', 0)\n\
                  w.add_message(c, log_time=1, data=b'\\x00\\x01\\x00\\x00', publish_time=1)\nw.finish()\n";
    python_run(&[&"-c", &script, &untyped]);
    let e = run_err(
        dir.path(),
        &[
            "import",
            untyped.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
            "--scan-topic",
            "/points",
        ],
    );
    assert!(e.contains("does not say its message type"), "{e}");
    let e = run_err(
        dir.path(),
        &[
            "import",
            untyped.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
        ],
    );
    assert!(
        e.contains("no sensor_msgs/msg/PointCloud2") && e.contains("/points (no type, 1 messages)"),
        "{e}"
    );
}

#[test]
fn clouds_without_z_and_an_imu_that_stops_early_are_refused_naming_the_message() {
    let dir = tempfile::tempdir().unwrap();
    let (flat, short) = (dir.path().join("flat"), dir.path().join("short"));
    make_bag(simulated(), &flat, "sqlite3", &["--cloud-fields", "xy"]);
    make_bag(simulated(), &short, "mcap", &["--imu-until", "40"]);
    let ds = dir.path().join("ds");
    let e = run_err(
        dir.path(),
        &[
            "import",
            flat.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
        ],
    );
    assert!(
        e.contains("flat.db3") && e.contains("/robot/lidar/points message #0"),
        "{e}"
    );
    assert!(
        e.contains("no 'z' field") && e.contains("x, y, intensity"),
        "{e}"
    );
    let e = run_err(
        dir.path(),
        &[
            "import",
            short.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
        ],
    );
    assert!(
        e.contains("short.mcap") && e.contains("/robot/lidar/points #6"),
        "{e}"
    );
    assert!(
        e.contains("no reading on /robot/imu/data") && e.contains("--no-imu"),
        "{e}"
    );
    let summary = run_json(
        dir.path(),
        &[
            "import",
            short.to_str().unwrap(),
            "--out",
            ds.to_str().unwrap(),
            "--salvage",
            "--json",
        ],
    );
    assert_eq!(summary["stops"], 6, "scans at 5, 11, …, 35 s: {summary}");
    let left_out = summary["left_out"].as_array().unwrap();
    assert_eq!(left_out.len(), 6, "{summary}");
}
