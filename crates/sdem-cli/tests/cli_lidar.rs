//! `sdem localize --match-scan` on a spinning LiDAR's scans (a simulated street): the grid and
//! the search's settings derived from the reference scan, a pair 0.7 m apart found without a
//! guess.

mod common;

use common::{run, run_json};
use nalgebra::{Isometry3, Vector3};
use sdem::geometry::{Attitude, Pose};
use sdem::sensor::SensorConfig;
use sdem_sim::sim::lidar_street::street;
use sdem_sim::sim::{spinning_scan, SpinningLidar};

#[test]
fn localize_matches_the_grid_to_a_lidar_scan() {
    let dir = tempfile::tempdir().unwrap();
    let truth: Pose = Isometry3::new(
        Vector3::new(0.7, 0.05, 0.02),
        Vector3::z() * 1.5f64.to_radians(),
    );
    let (scene, lidar) = (street(7), SpinningLidar::hdl32());
    let scans = vec![
        (
            spinning_scan(&scene, &lidar, &Pose::identity(), 1),
            Attitude::default(),
        ),
        (
            spinning_scan(&scene, &lidar, &truth, 2),
            Attitude::default(),
        ),
    ];
    let dataset = dir.path().join("street");
    let poses = [Pose::identity(), truth];
    sdem_io::write_dataset(
        &dataset,
        &SensorConfig::default(),
        &scans,
        None,
        Some(&poses),
        None,
    )
    .unwrap();
    let ds = dataset.to_str().unwrap();
    let search = ["--window", "-1:1,-1:1,-0.3:0.3", "--heading-window", "5"];
    let mut args = vec!["localize", ds, "--reference", "0", "--query", "1", "--json"];
    args.extend(search);
    args.push("--match-scan");
    let report = run_json(dir.path(), &args);
    assert_eq!(report["trusted"], true, "{report}");
    let error_m = report["error_m"].as_f64().unwrap();
    let error_deg = report["error_deg"].as_f64().unwrap();
    assert!(
        error_m < 0.03 && error_deg < 0.3,
        "{error_m} m, {error_deg}°"
    );
    // The derived settings replace --step and --resolution: giving both is a usage error.
    args.extend(["--step", "0.05"]);
    assert_eq!(run(dir.path(), &args).code, Some(2));
}
