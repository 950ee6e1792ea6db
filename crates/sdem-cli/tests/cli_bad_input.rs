//! Bad input at the command line: a dataset, saved map or import source with a malformed
//! file makes `sdem` exit with status 1 and one line on stderr that names the file and the place
//! (line, element or byte offset) — never a panic, never a result computed from garbage. The
//! readers' own table of malformed inputs is `crates/sdem-io/tests/bad_input.rs`. A number out
//! of its flag's range, or flags that do not fit together, are a usage error instead (status 2),
//! refused before any file is touched.

mod common;

use common::{run_err, usage_error};
use sdem::geometry::{pose_from_parts, Attitude, Vec3};
use sdem::map::{Map, Node};
use std::path::Path;

fn s(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}

/// A small dataset of `.xyz` scans with attitude.csv and sensor.toml, in `DIR/ds`. The scans
/// are valid; each test damages one file.
fn dataset(dir: &Path) -> std::path::PathBuf {
    let ds = dir.join("ds");
    std::fs::create_dir_all(ds.join("scans")).unwrap();
    let scan = common::wavy_ellipse_xyz();
    for i in 0..3 {
        std::fs::write(ds.join(format!("scans/{i:06}.xyz")), &scan).unwrap();
    }
    std::fs::write(
        ds.join("attitude.csv"),
        "index,roll_deg,pitch_deg,yaw_deg\n0,0.5,-1,10\n1,0.5,-1,12\n2,0.5,-1,14\n",
    )
    .unwrap();
    std::fs::write(ds.join("sensor.toml"), "max_range_m = 8.0\n").unwrap();
    ds
}

/// The one-line error of `sdem ARGS` (exit status 1, nothing on stdout, no panic), which must
/// contain every one of `wanted`.
fn error_naming(dir: &Path, args: &[&str], wanted: &[&str]) -> String {
    let line = run_err(dir, args);
    for w in wanted {
        assert!(line.contains(w), "sdem {args:?}: {line:?} lacks {w:?}");
    }
    line
}

#[test]
fn localize_names_an_infinite_coordinate_in_a_scan() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    std::fs::write(ds.join("scans/000001.xyz"), "1 2 0.5\n1 inf 0.5\n").unwrap();
    let args = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    error_naming(dir.path(), &args, &["000001.xyz:2:", "inf"]);
}

#[test]
fn localize_names_a_bad_sensor_toml() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    std::fs::write(
        ds.join("sensor.toml"),
        "max_range_m = 8.0\nmin_range_m = nan\n",
    )
    .unwrap();
    let args = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    error_naming(dir.path(), &args, &["sensor.toml:2:", "min_range_m"]);
    std::fs::write(ds.join("sensor.toml"), "").unwrap();
    error_naming(dir.path(), &args, &["sensor.toml", "empty"]);
    // A step too coarse for an S-DEM cell is named by its key, not as the grid's resolution.
    std::fs::write(ds.join("sensor.toml"), "pan_step_deg = 90.0\n").unwrap();
    error_naming(
        dir.path(),
        &args,
        &["sensor.toml:1:", "pan_step_deg is 90°"],
    );
}

/// Relocalizing in a saved map searches with the map's own settings: the search's options of
/// a pair are refused there, not ignored.
#[test]
fn localize_in_a_map_refuses_the_options_it_would_ignore() {
    let dir = tempfile::tempdir().unwrap();
    let flags: [&[&str]; 9] = [
        &["--step", "0.05"],
        &["--window", "-1:1,-1:1,-0.1:0.1"],
        &["--resolution", "0.5"],
        &["--cost", "virtual"],
        &["--search", "exhaustive"],
        &["--search", "coarse-to-fine"],
        &["--search", "branch-and-bound"],
        &["--exhaustive"],
        &["--max-candidates", "1000"],
    ];
    for flag in flags {
        let r = common::run(
            dir.path(),
            &[&["localize", "--map", "map", "scan.ply"][..], flag].concat(),
        );
        assert_eq!(r.code, Some(2), "{flag:?}: {}", r.stderr);
        assert!(
            r.stderr.contains("cannot be used with"),
            "{flag:?}: {}",
            r.stderr
        );
    }
}

#[test]
fn localize_refuses_a_scan_in_millimetres() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    let text = std::fs::read_to_string(ds.join("scans/000000.xyz")).unwrap();
    let mm: String = text
        .lines()
        .map(|l| {
            let v: Vec<String> = l
                .split(' ')
                .map(|x| (x.parse::<f64>().unwrap() * 1000.0).to_string())
                .collect();
            v.join(" ") + "\n"
        })
        .collect();
    std::fs::write(ds.join("scans/000000.xyz"), mm).unwrap();
    let args = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    error_naming(dir.path(), &args, &["000000.xyz", "millimetres"]);
}

#[test]
fn slam_names_a_bad_attitude_csv() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    let out = dir.path().join("out");
    // Hundredths of a degree where degrees are expected (a robot on a 12° slope; a nearly
    // level one would read within ±360 and could not be told apart).
    std::fs::write(
        ds.join("attitude.csv"),
        "index,roll_deg,pitch_deg,yaw_deg\n0,50,-100,1000\n1,500,-1200,1200\n2,50,-100,1400\n",
    )
    .unwrap();
    let args = ["slam", s(&ds), "--out", s(&out)];
    error_naming(dir.path(), &args, &["attitude.csv:3:", "roll"]);
    // A row cut short.
    std::fs::write(
        ds.join("attitude.csv"),
        "index,roll_deg,pitch_deg,yaw_deg\n0,0.5,-1,10\n1,0.5,",
    )
    .unwrap();
    error_naming(dir.path(), &args, &["attitude.csv:3:"]);
    assert!(
        !out.join("map").exists(),
        "nothing may be mapped from a bad dataset"
    );
}

#[test]
fn slam_names_a_bad_config_file() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    let out = dir.path().join("out");
    let config = dir.path().join("slam.toml");
    let args = ["slam", s(&ds), "--out", s(&out), "--config", s(&config)];
    std::fs::write(&config, "heading_half_deg = 3.0\nheading_hlaf_deg = 4.0\n").unwrap();
    error_naming(dir.path(), &args, &["slam.toml:2:", "heading_hlaf_deg"]);
    std::fs::write(&config, "[voxel]\nvoxel_m = nan\n").unwrap();
    error_naming(dir.path(), &args, &["slam.toml:2:", "voxel_m"]);
}

#[test]
fn slam_names_a_truncated_binary_scan() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset(dir.path());
    let out = dir.path().join("out");
    for i in 0..3 {
        std::fs::remove_file(ds.join(format!("scans/{i:06}.xyz"))).unwrap();
        let points: Vec<Vec3> = (0..200)
            .map(|k| {
                let a = f64::from(k) * 0.0314;
                Vec3::new(3.0 * a.cos(), 2.0 * a.sin(), 0.5)
            })
            .collect();
        sdem_io::write_points_ply(&ds.join(format!("scans/{i:06}.ply")), &points).unwrap();
    }
    let first = ds.join("scans/000000.ply");
    let bytes = std::fs::read(&first).unwrap();
    std::fs::write(&first, &bytes[..bytes.len() - 7]).unwrap();
    let args = ["slam", s(&ds), "--out", s(&out)];
    error_naming(
        dir.path(),
        &args,
        &["000000.ply:4:", "'vertex' element 199", "byte offset"],
    );
}

#[test]
fn localize_map_names_a_damaged_node_file() {
    let dir = tempfile::tempdir().unwrap();
    let map_dir = dir.path().join("map");
    let nodes: Vec<Node> = (0..2)
        .map(|i| Node {
            node_id: i,
            scan_index: i,
            world_from_sensor: pose_from_parts(
                Vec3::new(0.5 * i as f64, 0.0, 0.0),
                Attitude::default(),
            ),
            attitude_reading: None,
            points_in_sensor: (0..50).map(|k| [k as f32 * 0.1, 1.0, 0.3]).collect(),
            segment: 0,
            run: 0,
        })
        .collect();
    sdem_io::save_map(
        &map_dir,
        &mut sdem_io::NodeFiles::default(),
        &sdem::slam::SlamOptions::default(),
        &Map { nodes },
        &[],
        &[],
        &[],
    )
    .unwrap();
    let node = map_dir.join("nodes/000001.pts");
    let bytes = std::fs::read(&node).unwrap();
    std::fs::write(&node, &bytes[..bytes.len() - 7]).unwrap();
    let scan = dir.path().join("scan.xyz");
    std::fs::write(&scan, "1 2 0.5\n-3 0.25 1.5\n2 -1 -0.5\n").unwrap();
    let args = ["localize", "--map", s(&map_dir), "--scan", s(&scan)];
    error_naming(dir.path(), &args, &["000001.pts", "truncated"]);
}

#[test]
fn import_names_a_bad_3dtk_pose() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("uos");
    std::fs::create_dir_all(&source).unwrap();
    for i in 0..2 {
        std::fs::write(
            source.join(format!("scan{i:03}.3d")),
            "100 50 200\n-150 20 300\n80 -10 -250\n",
        )
        .unwrap();
        std::fs::write(source.join(format!("scan{i:03}.pose")), "0 0 0\n0 0 0\n").unwrap();
    }
    std::fs::write(source.join("scan001.pose"), "0 0 inf\n0 0 0\n").unwrap();
    let out = dir.path().join("out");
    let args = ["import", s(&source), "--out", s(&out)];
    error_naming(dir.path(), &args, &["scan001.pose:1:"]);
    assert!(!out.join("scans").exists(), "nothing may be imported");
}

/// Every subcommand with numeric flags refuses a number out of its range, or malformed, as a
/// usage error (exit status 2, clap's message naming the flag and what it allows), before any
/// file is read or written: the inputs named do not exist, and the folder stays empty.
#[test]
fn every_subcommand_refuses_a_bad_number_as_a_usage_error_before_any_file() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("out");
    let out = s(&out_path);
    let pair = ["nowhere", "--reference", "0", "--query", "1"];
    let cases: Vec<(Vec<&str>, [&str; 2])> = vec![
        (
            vec!["demo", "--out", out, "--stops", "1"],
            ["--stops", "2..=40"],
        ),
        (
            vec!["simulate", "--out", out, "--stops", "41"],
            ["--stops 41", "1..=40"],
        ),
        (
            vec!["simulate", "--out", out, "--range-noise", "-0.1"],
            ["--range-noise", "[0, 8)"],
        ),
        (
            vec!["simulate", "--out", out, "--trusted-range", "0"],
            ["--trusted-range", "above 0.05"],
        ),
        (
            [&["localize"][..], &pair, &["--heading-step", "0"]].concat(),
            ["--heading-step", "positive number of degrees"],
        ),
        (
            vec!["slam", "nowhere", "--out", out, "--step", "0"],
            ["--step", "positive number of metres"],
        ),
        (
            vec!["slam", "nowhere", "--out", out, "--attitude-sigma-deg", "1"],
            ["--attitude-sigma-deg", "ROLL_PITCH,YAW"],
        ),
        (vec!["bench", "--pairs", "0"], ["--pairs", "≥ 1"]),
        (
            vec!["bench", "--faults", "--step", "nan"],
            ["--step", "positive"],
        ),
        (
            vec!["bench", "--suite", "scale", "--sizes", "100,100"],
            ["--sizes", "must increase"],
        ),
        (
            vec!["import", "nowhere", "--out", out, "--stop-angle", "0"],
            ["--stop-angle", "positive number of degrees"],
        ),
        (
            vec!["import", "nowhere", "--out", out, "--count", "x"],
            ["--count", "≥ 1"],
        ),
        (
            [
                &["view", "cost"][..],
                &pair,
                &["--out", "c.png", "--heading-window", "181"],
            ]
            .concat(),
            ["--heading-window", "[0, 180]"],
        ),
        (
            vec![
                "view",
                "panorama",
                "nowhere",
                "--out",
                "p.png",
                "--resolution",
                "0",
            ],
            ["--resolution", "(0, 45]"],
        ),
        (
            vec![
                "view",
                "slice",
                "nowhere",
                "--out",
                "s.png",
                "--elevation",
                "-91",
            ],
            ["--elevation", "[-90, 90]"],
        ),
    ];
    for (args, wanted) in cases {
        let e = usage_error(dir.path(), &args, &wanted);
        assert!(!e.contains("nowhere"), "{args:?}: {e}");
        let written: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(written.is_empty(), "{args:?} wrote {written:?}");
    }
}

/// Options that are each well formed but do not fit the subcommand, or a name that is none of
/// the flag's choices: a usage error (status 2) saying what and how to fix it, before any file
/// is read or written.
#[test]
fn every_subcommand_refuses_options_that_do_not_fit_as_a_usage_error_before_any_file() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("out");
    let out = s(&out_path);
    let pair = ["localize", "nowhere", "--reference", "0", "--query", "1"];
    let cases: Vec<(Vec<&str>, &[&str])> = vec![
        (
            vec!["bench", "--suite", "scale", "--pairs", "3"],
            &["--pairs applies to", "--sizes and --route choose them"],
        ),
        (
            vec!["bench", "--suite", "routes", "--pairs", "3"],
            &["--pairs applies to"],
        ),
        (
            vec!["bench", "--suite", "scale", "--step", "0.1"],
            &["--step applies to", "the loop's own step"],
        ),
        (
            vec!["bench", "--suite", "routes", "--step", "0.1"],
            &["--step applies to"],
        ),
        (
            vec!["bench", "--suite", "lidar", "--step", "0.1"],
            &[
                "--step applies to",
                "lidar searches each scan's grid at 5 cm",
            ],
        ),
        (
            vec!["bench", "--suite", "unlevelled", "--sizes", "10"],
            &["--sizes applies to --suite scale only"],
        ),
        (
            vec!["bench", "--suite", "lidar", "--route", "revisit"],
            &["--route applies to --suite scale and --suite routes only"],
        ),
        (
            vec!["bench", "--suite", "unlevelled", "--kitti", "nowhere"],
            &["--kitti applies to --suite lidar and --suite routes only"],
        ),
        (
            vec!["bench", "--suite", "lidar", "--scan", "nowhere"],
            &["--scan applies to --suite real-geometry only"],
        ),
        (
            vec!["bench", "--suite", "scale", "--route", "stairs"],
            &["--route stairs", "room-laps, floor and wings"],
        ),
        (
            vec!["bench", "--suite", "routes", "--route", "stairs"],
            &["--route stairs", "long-steps", "second-run"],
        ),
        (
            vec!["bench", "--suite", "unlevelled", "--force"],
            &[
                "--force applies to --suite scale only",
                "the other suites write no file",
            ],
        ),
        (
            vec!["bench", "--suite", "lidar", "--plot", "p.png"],
            &["--plot applies to --suite scale only"],
        ),
        (
            vec!["bench", "--suite", "scale", "--peers", "nowhere"],
            &[
                "--peers applies to --suite unlevelled, compass-noise, lidar, routes and \
                 real-geometry only",
                "scale runs no peer",
            ],
        ),
        (
            [
                &["bench", "--suite", "routes", "--quick"][..],
                &["--route", "long-steps", "--kitti", "nowhere"],
            ]
            .concat(),
            &[
                "--kitti cannot be given with --route",
                "--route runs only the named routes, without the KITTI part",
            ],
        ),
        (
            [
                &["bench", "--suite", "routes", "--quick"][..],
                &["--route", "revisit", "--peers", "nowhere"],
            ]
            .concat(),
            &[
                "--peers cannot be given with --route",
                "--route runs only the named routes, without the KITTI part",
            ],
        ),
        (
            vec!["bench", "--suite", "routes", "--peer-pairs", "3"],
            &[
                "--peer-pairs applies to --suite unlevelled, compass-noise, lidar and \
                 real-geometry only",
                "routes gives KISS-ICP every KITTI frame",
            ],
        ),
        (
            vec!["bench", "--suite", "scale", "--peer-pairs", "3"],
            &["--peer-pairs applies to"],
        ),
        (
            vec!["bench", "--faults", "--case", "hail"],
            &["'hail'", "--case", "none, compass", "person, all"],
        ),
        (
            vec!["simulate", "--out", out, "--fault", "tilt"],
            &["'tilt'", "`sdem bench --faults --case tilt` measures"],
        ),
        (
            [&pair[..], &["--exhaustive", "--max-candidates", "1000"]].concat(),
            &[
                "at least 193011 candidates (101 × 91 × 21 positions, each at every heading",
                "more than its limit of 1000",
                "--max-candidates (to 193011 or more;",
            ],
        ),
        (
            [
                &pair[..],
                &["--search", "exhaustive", "--window", "-2:2,-2:2,-0.1:0.1"],
                &["--heading-window", "2", "--heading-step", "1"],
            ]
            .concat(),
            &[
                "would score 16884105 candidates (401 × 401 × 21 positions × 5 headings)",
                "limit of 4000000",
                "--max-candidates 16884105",
            ],
        ),
        (
            [&pair[..], &["--exhaustive", "--search", "coarse-to-fine"]].concat(),
            &[
                "--exhaustive and --search coarse-to-fine",
                "--exhaustive is --search exhaustive",
            ],
        ),
        (
            [&pair[..], &["--search", "branch-and-bound", "--exhaustive"]].concat(),
            &["--exhaustive and --search branch-and-bound"],
        ),
        (
            [&pair[..], &["--window", "-2000:2000,-2:2,-0.1:0.1"]].concat(),
            &[
                "--window -2000:2000,-2:2,-0.1:0.1 at --step 0.01 m",
                "spans 400001 steps",
            ],
        ),
        (
            [&pair[..], &["--window", "-200:200,-200:200,-1:1"]].concat(),
            &[
                "at least 321616080201 candidates",
                "more than the 2000000000 any search takes",
            ],
        ),
        (
            vec!["simulate", "--out", out, "--route", "stairs"],
            &["'stairs'", "--route", "room-laps, floor, wings"],
        ),
        (
            vec!["simulate", "--out", out, "--fault", "smoke"],
            &["'smoke'", "--fault", "compass, gyro-drift"],
        ),
        (
            vec![
                "localize",
                "--map",
                "map",
                "scan.ply",
                "--attitude-sigma-deg",
                "1,5",
            ],
            &["--attitude-sigma-deg describes the --attitude reading"],
        ),
        (
            vec![
                "localize",
                "--map",
                "map",
                "scan.ply",
                "--attitude",
                "400,0,0",
            ],
            &["--attitude", "roll is 400 degrees", "within ±360°"],
        ),
        (
            vec![
                "localize",
                "--map",
                "map",
                "scan.ply",
                "--attitude",
                "0,-1e4,0",
            ],
            &["--attitude", "pitch is -10000 degrees"],
        ),
        (
            vec![
                "localize",
                "--map",
                "map",
                "scan.ply",
                "--attitude",
                "0,0,2e6",
            ],
            &["--attitude", "yaw is 2.000e6 degrees", "±1.000e6°"],
        ),
        (
            [&pair[..], &["--cost", "virtual"]].concat(),
            &["--cost virtual needs --search exhaustive or --search coarse-to-fine"],
        ),
        (
            vec![
                "import",
                "nowhere",
                "--out",
                out,
                "--no-imu",
                "--imu-topic",
                "/imu",
            ],
            &["--no-imu and --imu-topic contradict each other; give one"],
        ),
        (
            vec![
                "import",
                "nowhere",
                "--out",
                out,
                "--no-odom",
                "--odom-topic",
                "/odom",
            ],
            &["--no-odom and --odom-topic contradict each other; give one"],
        ),
        (
            vec!["slam", "nowhere", "--out", out, "--resume", "--step", "0.1"],
            &[
                "--resume continues",
                "drop --config, --step and --no-loop-closure",
            ],
        ),
        (
            vec![
                "slam",
                "nowhere",
                "--out",
                out,
                "--resume",
                "--no-loop-closure",
            ],
            &["--resume continues"],
        ),
        (
            vec![
                "slam",
                "nowhere",
                "--out",
                out,
                "--resume",
                "--config",
                "nowhere.toml",
            ],
            &["--resume continues"],
        ),
    ];
    for (args, wanted) in cases {
        usage_error(dir.path(), &args, wanted);
        let written: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(written.is_empty(), "{args:?} wrote {written:?}");
    }
}

/// Beside the refusals above, the flags that do fit stay accepted: `--exhaustive --search
/// exhaustive` is one search, and `--kitti`/`--peers` serve `--suite routes` when no `--route`
/// leaves its KITTI part out. Each gets as far as its files (exit status 1, not 2).
#[test]
fn flags_that_fit_together_are_not_refused() {
    let dir = tempfile::tempdir().unwrap();
    let pair = ["localize", "nowhere", "--reference", "0", "--query", "1"];
    let line = common::fails(
        dir.path(),
        &[&pair[..], &["--exhaustive", "--search", "exhaustive"]].concat(),
    );
    assert!(line.contains("nowhere"), "{line}");
    // --peers is looked for first, before any route runs.
    let line = common::fails(
        dir.path(),
        &[
            "bench", "--suite", "routes", "--quick", "--kitti", "nowhere", "--peers", "nowhere",
        ],
    );
    assert!(
        line.contains("--peers nowhere: no register_pair.py there"),
        "{line}"
    );
}
