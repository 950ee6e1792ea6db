//! `sdem bench --suite real-geometry`: a user's scan re-viewed and localized, the report's
//! shape, sdem's error on re-views of a real 3DTK scan within the bound measured for it, and bad
//! flags.

mod common;

use common::{fails, run_json, sdem, usage_error};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The paper's room scanned from its origin at 0.5° steps, written as a PLY in `dir`.
fn room_scan(dir: &Path) -> PathBuf {
    use rand::SeedableRng;
    let sensor = sdem::sensor::SensorConfig {
        tilt_step_deg: 0.5,
        pan_step_deg: 0.5,
        ..Default::default()
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let sweep = sdem_sim::sim::scan(
        &sdem_sim::sim::paper_room(),
        &sensor,
        &sdem::geometry::Pose::identity(),
        0.0,
        &mut rng,
    );
    let path = dir.join("room.ply");
    sdem_io::write_points_ply(&path, &sweep.points_in_sensor()).unwrap();
    path
}

/// The records of a report, checked for their shape.
fn records(report: &Value, expected: usize) -> Vec<Value> {
    let records = report["records"].as_array().expect("records").clone();
    assert_eq!(records.len(), expected, "{report}");
    for r in &records {
        assert!(r["error"].is_null(), "{r}");
        for key in [
            "translation_error_mm",
            "rotation_error_deg",
            "nees",
            "time_ms",
        ] {
            assert!(r[key].as_f64().is_some_and(f64::is_finite), "{key}: {r}");
        }
        assert!(r["query_points"].as_u64().unwrap() > 1000, "{r}");
    }
    records
}

/// A user's scan (any point file) is modelled, re-viewed by a scanner like its own (a front-half
/// scan: the tilting one) and localized; without the peers the report says so and compares
/// nothing.
/// The real-geometry suite's report on `pairs` re-views of `scan`, without the peers, run in
/// `dir`.
fn re_views(dir: &Path, scan: &Path, pairs: usize) -> Value {
    let pairs = pairs.to_string();
    run_json(
        dir,
        &[
            "bench",
            "--suite",
            "real-geometry",
            "--scan",
            scan.to_str().unwrap(),
            "--pairs",
            &pairs,
            "--peer-pairs",
            "0",
            "--json",
        ],
    )
}

#[test]
fn a_users_scan_is_re_viewed_and_localized() {
    let dir = tempfile::tempdir().unwrap();
    let scan = room_scan(dir.path());
    let report = re_views(dir.path(), &scan, 2);
    assert_eq!(report["suite"], "real-geometry");
    assert_eq!(report["peers"], "--peer-pairs 0");
    let scans = report["scans"].as_array().unwrap();
    assert_eq!(scans.len(), 1);
    assert!(
        scans[0]["scanner"].as_str().unwrap().contains("tilting"),
        "{}",
        scans[0]
    );
    for r in records(&report, 2) {
        assert!(r["translation_error_mm"].as_f64().unwrap() < 5.0, "{r}");
        assert!(r["gicp_translation_error_mm"].is_null(), "{r}");
    }
    assert_eq!(report["all"]["compared"], 0);
}

/// Where the 3DTK scans lie beside the repository.
fn threedtk_scan() -> Option<PathBuf> {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/3dtk-dat/scan000.3d");
    path.is_file().then_some(path)
}

/// On re-views of a real scan (3DTK's scan000, a nodding SICK in a corridor) sdem stays within
/// the bound measured for it with margin: 3 re-views, each within 2 mm and 0.05°
/// (measured: 0.36–0.79 mm and 0.007–0.016°).
#[test]
fn re_views_of_a_real_scan_localize_within_the_measured_bound() {
    let Some(scan) = threedtk_scan() else {
        eprintln!("skipped: no ../shared/data/3dtk-dat/scan000.3d beside the repository");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let report = re_views(dir.path(), &scan, 3);
    for r in records(&report, 3) {
        let t = r["translation_error_mm"].as_f64().unwrap();
        let d = r["rotation_error_deg"].as_f64().unwrap();
        assert!(t <= 2.0 && d <= 0.05, "{t} mm, {d}°: {r}");
    }
}

/// Where the first KITTI frame lies beside the repository.
fn kitti_frame() -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/kitti-00-first16/velodyne/000000.bin");
    path.is_file().then_some(path)
}

/// The covariance reported on re-views of a real LiDAR frame covers the error: the median
/// NEES (six axes) of 3 re-views of KITTI's frame 0 lies below χ²₆'s 95 % bound, 12.59 (when
/// honest its median is 5.3). The residuals' spread alone gave 14.9–18.3 on all three; with the
/// sampling bias measured by refining both ways, 3.5–7.0.
#[test]
fn the_covariance_covers_the_error_on_re_views_of_a_real_lidar_frame() {
    let Some(scan) = kitti_frame() else {
        eprintln!(
            "skipped: no ../shared/data/kitti-00-first16/velodyne/000000.bin beside the repository"
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let report = re_views(dir.path(), &scan, 3);
    let mut nees: Vec<f64> = records(&report, 3)
        .iter()
        .map(|r| r["nees"].as_f64().unwrap())
        .collect();
    nees.sort_by(f64::total_cmp);
    assert!(nees[1] < 12.59, "NEES {nees:?}");
}

/// A real scan re-viewed (`ReviewConfig::unlevelled`: both views rolled and pitched up to
/// ±30° at any heading, seed 1) as pair `index`, localized with no attitude reading: the error
/// (metres, radians) and what sdem found. A KITTI `.bin` frame is seen by its HDL-64E and
/// matched on the grid derived from it at 5 cm steps; a 3DTK `.3d` scan by a scanner like its
/// own at 2 cm, as `examples/real_unlevelled` does.
fn tilted_real_pair(path: &Path, index: usize) -> (f64, f64, sdem::Localization) {
    use sdem_sim::reviews::{
        localize_review, review_pairs, ModelConfig, ReviewConfig, ReviewScanner,
    };
    let spinning = path.extension().is_some_and(|e| e == "bin");
    let mut model_config = ModelConfig::default();
    if !spinning {
        model_config.min_range_m = sdem_io::UOS_MIN_RANGE_M;
        model_config.max_range_m = sdem_io::UOS_MAX_RANGE_M;
    }
    let ranges = model_config.min_range_m..=model_config.max_range_m;
    let points: Vec<_> = (sdem_io::read_points(path).unwrap().into_iter())
        .filter(|p| ranges.contains(&p.norm()))
        .collect();
    let model = sdem_sim::reviews::SurfaceModel::new(&points, &model_config).unwrap();
    let scanner = if spinning {
        ReviewScanner::hdl64e()
    } else {
        ReviewScanner::like(&points)
    };
    let config = ReviewConfig::unlevelled(scanner);
    let review = review_pairs(&model, &config, 1, index..index + 1)
        .unwrap()
        .remove(0);
    let across = 0.7 * 2f64.sqrt() + 0.05;
    let window = sdem::SearchWindow::around(&nalgebra::Vector3::zeros(), [across, across, 0.15]);
    let step = if spinning { 0.05 } else { 0.02 };
    let found = localize_review(&review, &config.scanner, false, window, step).unwrap();
    let (t, d) = sdem::geometry::pose_error(&review.truth, &found.reference_from_query);
    (t, d, found)
}

/// Asserts that a tilted pair's localization (`tilted_real_pair`'s translation and rotation
/// errors and result) is trusted, within `max_m` and 0.1°.
fn assert_trusted_within((t, d, found): &(f64, f64, sdem::Localization), max_m: f64) {
    assert!(
        *t < max_m && d.to_degrees() < 0.1 && found.trusted,
        "{:.1} mm, {:.2}°, doubts {:?}",
        t * 1e3,
        d.to_degrees(),
        found.doubts
    );
}

/// [`tilted_real_pair`] of KITTI's frame 0; `None` without the frame beside the repository.
fn tilted_kitti_pair(index: usize) -> Option<(f64, f64, sdem::Localization)> {
    let Some(path) = kitti_frame() else {
        eprintln!(
            "skipped: no ../shared/data/kitti-00-first16/velodyne/000000.bin beside the repository"
        );
        return None;
    };
    Some(tilted_real_pair(&path, index))
}

/// Pair 10 (0.30 m and 35° apart): each view is levelled by its own surfaces, a degree or so
/// apart; at 30 m that moved the grid's optimum 14.5 cm, the refinement, too far from its start
/// to pair its points, failed, and the pose came back flagged 14.5 cm and 1.3° off. Levelled
/// again by the points (the refinement allowed to pair and move further, the search run again
/// at its attitude) it is millimetres off and trusted.
#[test]
fn a_tilted_real_lidar_frame_without_attitude_is_levelled_by_its_points() {
    let Some(pair) = tilted_kitti_pair(10) else {
        return;
    };
    assert_trusted_within(&pair, 0.01);
}

/// Pair 5 (0.54 m and 149° apart): at the two views' levels no heading matched ("no candidate
/// in the window matches", exit 1 for `sdem localize`); the search over tilt and heading within
/// 8° of the levels finds it, 2 mm off (flagged `runner_up`: another place compares within
/// 1.1× of its cost).
#[test]
fn a_tilted_real_lidar_frame_no_heading_matches_is_found_over_tilt() {
    let Some((t, d, found)) = tilted_kitti_pair(5) else {
        return;
    };
    assert!(
        t < 0.01 && d.to_degrees() < 0.1,
        "{:.1} mm, {:.2}°, doubts {:?}",
        t * 1e3,
        d.to_degrees(),
        found.doubts
    );
}

/// 3DTK's scan000, pair 5 (0.46 m and 32° apart), each view levelled by its own surfaces: the
/// match is 1.5 mm off, but it tilts the two levels against each other by more than three
/// standard deviations of the spread the surfaces' normals claimed (0.2° each) and was flagged
/// `attitude_corrected`, its only doubt. Real floors slope: two views of one real scene level
/// 0.6–1° apart (median), and a levelling now claims at least 0.5°. Trusted.
#[test]
fn a_tilted_real_scan_levelled_by_its_surfaces_is_trusted_within_their_real_spread() {
    let Some(path) = threedtk_scan() else {
        eprintln!("skipped: no ../shared/data/3dtk-dat/scan000.3d beside the repository");
        return;
    };
    assert_trusted_within(&tilted_real_pair(&path, 5), 0.005);
}

/// Bad flags and files: a clear error, exit 1 (2 for usage).
#[test]
fn bad_scans_and_flags_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let missing = fails(
        dir.path(),
        &[
            "bench",
            "--suite",
            "real-geometry",
            "--scan",
            "nowhere.ply",
            "--peer-pairs",
            "0",
        ],
    );
    assert!(missing.contains("nowhere.ply"), "{missing}");
    std::fs::write(dir.path().join("few.xyz"), "1 0 0\n0 1 0\n0 0 1\n").unwrap();
    let few = fails(
        dir.path(),
        &[
            "bench",
            "--suite",
            "real-geometry",
            "--scan",
            "few.xyz",
            "--peer-pairs",
            "0",
        ],
    );
    let few = few.lines().last().unwrap_or_default();
    assert!(
        few.contains("few.xyz") && few.contains("3 of its points"),
        "{few}"
    );
    usage_error(
        dir.path(),
        &["bench", "--suite", "lidar", "--scan", "few.xyz"],
        &["--scan applies to --suite real-geometry only"],
    );
    let usage = sdem(dir.path())
        .args(["bench", "--scan", "few.xyz"])
        .output()
        .unwrap();
    assert_eq!(usage.status.code(), Some(2));
}
