//! Issue 21, item 6: scans that cannot give a pose, at the command line. A scan with too few
//! points, a floor and nothing else, every point outside the range gates, NaN or infinity in
//! the points or in attitude.csv, the reference given again as the query, and a query tilted
//! and turned with no attitude at all: each ends in a clear one-line error (status 1) or a
//! result with its doubts (status 3), never a panic and never a wrong pose with status 0. The
//! scan given twice has one right answer, identity, and gets it.

mod common;

use common::{doubt_kinds, run, run_err};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sdem::geometry::{pose_error, pose_from_parts, Attitude, Pose, Vec3};
use sdem::sensor::SensorConfig;
use serde_json::Value;
use std::path::{Path, PathBuf};

fn s(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}

/// Writes a dataset of `scans` (points in the sensor frame) as binary PLY in `dir/name`, with
/// an attitude.csv when `attitudes` are given.
fn write_dataset(
    dir: &Path,
    name: &str,
    scans: &[Vec<Vec3>],
    attitudes: Option<&[Attitude]>,
) -> PathBuf {
    let ds = dir.join(name);
    std::fs::create_dir_all(ds.join("scans")).unwrap();
    for (i, points) in scans.iter().enumerate() {
        sdem_io::write_points_ply(&ds.join(format!("scans/{i:06}.ply")), points).unwrap();
    }
    if let Some(attitudes) = attitudes {
        sdem_io::write_attitude_csv(&ds.join("attitude.csv"), attitudes).unwrap();
    }
    ds
}

/// A scan of the paper's room (`sdem_sim::sim::paper_room`) from `world_from_sensor`, a
/// tilting LRF with 2° steps and 5 mm noise; points in the sensor frame.
fn room_scan(world_from_sensor: &Pose, seed: u64) -> Vec<Vec3> {
    let sensor = SensorConfig {
        tilt_step_deg: 2.0,
        pan_step_deg: 2.0,
        ..Default::default()
    };
    let scene = sdem_sim::sim::paper_room();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    sdem_sim::sim::scan(&scene, &sensor, world_from_sensor, 0.0, &mut rng).points_in_sensor()
}

/// `localize DS --reference R --query Q --json` with `extra`.
fn localize(dir: &Path, ds: &Path, (r, q): (usize, usize), extra: &[&str]) -> common::Run {
    let (r, q) = (r.to_string(), q.to_string());
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
    run(dir, &args)
}

/// The printed `reference_from_query` of a JSON result.
fn pose_of(result: &Value) -> Pose {
    let p = &result["reference_from_query"];
    let n = |k: &str| p[k].as_f64().unwrap_or_else(|| panic!("{k} in {p}"));
    pose_from_parts(
        Vec3::new(n("x"), n("y"), n("z")),
        Attitude::from_degrees(n("roll_deg"), n("pitch_deg"), n("yaw_deg")),
    )
}

/// A run that printed a result: status 0 (trusted) or 3 (doubts, each with its reason), no
/// panic, one JSON object; returns it.
fn result_of(r: &common::Run, what: &str) -> Value {
    assert!(
        matches!(r.code, Some(0) | Some(3)),
        "{what}: status {:?}\n{}\n{}",
        r.code,
        r.stdout,
        r.stderr
    );
    assert!(!r.stderr.contains("panicked"), "{what}: {}", r.stderr);
    let result: Value = serde_json::from_str(&r.stdout)
        .unwrap_or_else(|e| panic!("{what}: not one JSON object ({e}):\n{}", r.stdout));
    let kinds = doubt_kinds(&result);
    assert_eq!(result["trusted"], kinds.is_empty(), "{what}: {result}");
    assert_eq!(r.code == Some(0), kinds.is_empty(), "{what}: {result}");
    result
}

/// The query given again as the reference: the right answer is identity, and the search finds
/// it (here trusted: the paper's room fixes every direction) — with the attitude read, with the
/// attitude unknown, and for a copy of the scan under another index.
#[test]
fn the_reference_again_is_identity() {
    let dir = tempfile::tempdir().unwrap();
    let scan = room_scan(&Pose::identity(), 1);
    let reading = Attitude::from_degrees(0.02, -0.03, 0.05);
    let scans = [scan.clone(), scan];
    let with = write_dataset(dir.path(), "with", &scans, Some(&[reading, reading]));
    let without = write_dataset(dir.path(), "without", &scans, None);
    for (ds, pair) in [
        (&with, (0, 0)),
        (&with, (1, 0)),
        (&without, (0, 0)),
        (&without, (0, 1)),
    ] {
        let what = format!("{} {pair:?}", ds.display());
        let result = result_of(&localize(dir.path(), ds, pair, &[]), &what);
        let (metres, radians) = pose_error(&Pose::identity(), &pose_of(&result));
        println!(
            "{what}: {:.3} mm, {:.4}°",
            metres * 1e3,
            radians.to_degrees()
        );
        assert!(
            metres < 1e-3 && radians.to_degrees() < 0.05,
            "{what}: not identity: {:.2} mm, {:.3}°\n{result}",
            metres * 1e3,
            radians.to_degrees()
        );
        assert_eq!(result["trusted"], true, "{what}: {result}");
    }
}

/// A scan with too few points to fill the S-DEM's 100 cells: an error naming the scan and
/// saying how many cells it fills; with and without attitude.csv.
#[test]
fn too_few_points_is_an_error_naming_the_scan() {
    let dir = tempfile::tempdir().unwrap();
    let good = room_scan(&Pose::identity(), 1);
    let few: Vec<Vec3> = good.iter().step_by(good.len() / 40).copied().collect();
    let level = Attitude::default();
    for attitudes in [Some(&[level, level][..]), None] {
        let name = if attitudes.is_some() {
            "with"
        } else {
            "without"
        };
        let ds = write_dataset(dir.path(), name, &[good.clone(), few.clone()], attitudes);
        for pair in [(0, 1), (1, 0)] {
            let m = run_err(
                dir.path(),
                &[
                    "localize",
                    s(&ds),
                    "--reference",
                    &pair.0.to_string(),
                    "--query",
                    &pair.1.to_string(),
                ],
            );
            assert!(m.contains("000001.ply") && m.contains("cells"), "{m}");
        }
    }
}

/// Nothing but a floor, seen to 6 m around each stop, from two places 30 cm apart: nothing
/// fixes x, y or the heading. A result must say so (status 3, with doubts) or be an error;
/// with the compass read and with the attitude unknown.
#[test]
fn a_floor_alone_is_never_a_trusted_pose() {
    let dir = tempfile::tempdir().unwrap();
    // A return every 1° of azimuth and elevation below the horizon, up to 6 m away.
    let floor: Vec<Vec3> = (-180..180)
        .flat_map(|a| {
            (-89..=-5).map(move |e| (f64::from(a).to_radians(), f64::from(e).to_radians()))
        })
        .filter_map(|(a, e)| {
            let range = 0.5 / (-e).sin();
            let along = range * e.cos();
            (along <= 6.0).then(|| Vec3::new(along * a.cos(), along * a.sin(), -0.5))
        })
        .collect();
    let level = Attitude::default();
    for attitudes in [Some(&[level, level][..]), None] {
        let name = if attitudes.is_some() {
            "with"
        } else {
            "without"
        };
        let ds = write_dataset(dir.path(), name, &[floor.clone(), floor.clone()], attitudes);
        let r = localize(
            dir.path(),
            &ds,
            (0, 1),
            &["--window", "0.0:0.5,-0.2:0.3,-0.1:0.1"],
        );
        assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
        println!("{name}: status {:?}\n{}{}", r.code, r.stdout, r.stderr);
        match r.code {
            Some(1) => assert!(r.stdout.trim().is_empty(), "{}", r.stdout),
            Some(3) => {
                let result = result_of(&r, name);
                assert!(!doubt_kinds(&result).is_empty(), "{result}");
            }
            other => panic!("{name}: a floor alone gave status {other:?}:\n{}", r.stdout),
        }
    }
}

/// Every point outside the range gates: all beyond 1 km (not metres) is refused on reading;
/// all within the S-DEM's 5 cm minimum range is refused saying so.
#[test]
fn every_point_outside_the_range_gates_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let good = room_scan(&Pose::identity(), 1);
    let far: Vec<Vec3> = good.iter().map(|p| p * 2000.0).collect();
    let near: Vec<Vec3> = good.iter().map(|p| p.normalize() * 0.03).collect();
    let close = "lie within 0.05 m of the sensor's origin";
    for (name, bad, wanted) in [("far", far, "millimetres"), ("near", near, close)] {
        let ds = write_dataset(dir.path(), name, &[good.clone(), bad], None);
        let m = run_err(
            dir.path(),
            &["localize", s(&ds), "--reference", "0", "--query", "1"],
        );
        assert!(
            m.contains("000001.ply") && m.contains(wanted),
            "{name}: {m}"
        );
    }
}

/// NaN and infinity: in a binary PLY a NaN point is "no return" (a scan of nothing but NaN
/// is an error), an infinite coordinate is an error naming the file; in attitude.csv either is
/// an error naming the file and the line, in the angles and in the σ columns.
#[test]
fn nan_and_infinity_in_points_and_attitude_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let good = room_scan(&Pose::identity(), 1);
    let mut infinite = good.clone();
    infinite[7].y = f64::INFINITY;
    let all_nan = vec![Vec3::new(f64::NAN, 1.0, 0.0); 500];
    for (name, bad) in [("inf", infinite), ("nan", all_nan)] {
        let ds = dir.path().join(name);
        write_dataset(dir.path(), name, std::slice::from_ref(&good), None);
        // The writer refuses these points: write the PLY by hand.
        let mut ply = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
            bad.len()
        )
        .into_bytes();
        for p in &bad {
            for v in [p.x, p.y, p.z] {
                ply.extend_from_slice(&(v as f32).to_le_bytes());
            }
        }
        std::fs::write(ds.join("scans/000001.ply"), ply).unwrap();
        let m = run_err(
            dir.path(),
            &["localize", s(&ds), "--reference", "0", "--query", "1"],
        );
        assert!(m.contains("000001.ply"), "{name}: {m}");
    }

    let ds = write_dataset(dir.path(), "att", &[good.clone(), good], None);
    let h = sdem_io::ATTITUDE_HEADER;
    let hs = sdem_io::ATTITUDE_HEADER_WITH_SIGMA;
    for (text, line) in [
        (format!("{h}\n0,0,0,0\n1,nan,0,0\n"), 3),
        (format!("{h}\n0,0,inf,0\n1,0,0,0\n"), 2),
        (format!("{h}\n0,0,0,0\n1,0,0,-inf\n"), 3),
        (format!("{hs}\n0,0,0,0,0.5,3.5\n1,0,0,0,nan,3.5\n"), 3),
        (format!("{hs}\n0,0,0,0,0.5,inf\n1,0,0,0,0.5,3.5\n"), 2),
    ] {
        std::fs::write(ds.join("attitude.csv"), &text).unwrap();
        for command in [
            vec!["localize", s(&ds), "--reference", "0", "--query", "1"],
            vec!["slam", s(&ds), "--out", "out", "--no-pictures"],
        ] {
            let m = run_err(dir.path(), &command);
            assert!(
                m.contains(&format!("attitude.csv:{line}:")),
                "{text:?}: {m}"
            );
        }
    }
}

/// The query tilted 6° and 4° and turned 20°, 30 cm away, with no attitude.csv: sdem searches
/// the rotation (roll/pitch and heading) and finds the pose within 2 cm and 0.5°, or says it
/// doubts it; never a wrong pose with status 0.
#[test]
fn a_tilted_turned_query_without_attitude_is_found_or_doubted() {
    let dir = tempfile::tempdir().unwrap();
    let world_from_query = pose_from_parts(
        Vec3::new(0.3, 0.15, 0.05),
        Attitude::from_degrees(6.0, -4.0, 20.0),
    );
    let scans = [
        room_scan(&Pose::identity(), 1),
        room_scan(&world_from_query, 2),
    ];
    let ds = write_dataset(dir.path(), "ds", &scans, None);
    let r = localize(dir.path(), &ds, (0, 1), &[]);
    let result = result_of(&r, "no attitude");
    assert_eq!(result["attitude"]["source"], "unknown", "{result}");
    let (metres, radians) = pose_error(&world_from_query, &pose_of(&result));
    println!(
        "status {:?}: {:.2} cm, {:.3}°, doubts {:?}",
        r.code,
        metres * 100.0,
        radians.to_degrees(),
        doubt_kinds(&result)
    );
    if r.code == Some(0) {
        assert!(
            metres < 0.02 && radians.to_degrees() < 0.5,
            "a trusted pose {:.2} cm and {:.3}° off the truth:\n{result}",
            metres * 100.0,
            radians.to_degrees()
        );
    }
}

/// A pair whose query or reference has every point at the sensor's origin: refused (status 1)
/// naming the scan and saying why, in the words `localize --map` uses (the library's
/// `Error::NoUsablePoints`).
#[test]
fn a_scan_at_the_origin_is_refused_in_a_pair_saying_why() {
    let dir = tempfile::tempdir().unwrap();
    let zeros = vec![Vec3::zeros(); 500];
    let ds = write_dataset(
        dir.path(),
        "ds",
        &[room_scan(&Pose::identity(), 1), zeros],
        None,
    );
    for (reference, query) in [("0", "1"), ("1", "0")] {
        let args = [
            "localize",
            s(&ds),
            "--reference",
            reference,
            "--query",
            query,
        ];
        let m = run_err(dir.path(), &args);
        for w in [
            "000001.ply",
            "the scan has no usable point",
            "all 500 of its points lie within 0.05 m of the sensor's origin",
        ] {
            assert!(m.contains(w), "{args:?}: {m:?} lacks {w:?}");
        }
        assert!(!m.contains("fills 0"), "{m}");
    }
}

/// A scan whose every point lies at the sensor's origin (a PLY of zeros) or within the S-DEM's
/// 5 cm minimum range, relocalized in a saved map: refused before the map is searched, saying
/// that the scan has no usable point and why, with and without `--near`, and naming the map.
#[test]
fn a_scan_at_the_origin_is_refused_in_a_map_before_the_search() {
    let dir = tempfile::tempdir().unwrap();
    let ds = write_dataset(
        dir.path(),
        "ds",
        &[
            room_scan(&Pose::identity(), 1),
            room_scan(&Pose::identity(), 2),
        ],
        Some(&[Attitude::default(), Attitude::default()]),
    );
    let out = dir.path().join("out");
    let slam = ["slam", s(&ds), "--out", s(&out), "--no-pictures"];
    assert_eq!(run(dir.path(), &slam).code, Some(0));
    let zeros = vec![Vec3::zeros(); 500];
    let near: Vec<Vec3> = room_scan(&Pose::identity(), 3)
        .iter()
        .map(|p| p.normalize() * 0.03)
        .collect();
    for (name, points, wanted) in [
        (
            "zeros.ply",
            zeros,
            "all 500 of its points lie within 0.05 m",
        ),
        ("near.ply", near, "lie within 0.05 m"),
    ] {
        let scan = dir.path().join(name);
        sdem_io::write_points_ply(&scan, &points).unwrap();
        for extra in [&[][..], &["--near", "0,0,0"]] {
            let args = [&["localize", "--map", s(&out), s(&scan)][..], extra].concat();
            let m = run_err(dir.path(), &args);
            for w in [
                name,
                "in the map",
                "no usable point",
                wanted,
                "sensor's origin",
            ] {
                assert!(m.contains(w), "{args:?}: {m:?} lacks {w:?}");
            }
            assert!(!m.contains("not found"), "{m}");
        }
    }
    // Three points: too few cells to compare, said as pair mode says it, not "tried no node".
    let scan = dir.path().join("three.ply");
    let three = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.5),
    ];
    sdem_io::write_points_ply(&scan, &three).unwrap();
    for extra in [&[][..], &["--near", "0,0,0"]] {
        let args = [&["localize", "--map", s(&out), s(&scan)][..], extra].concat();
        let m = run_err(dir.path(), &args);
        assert!(
            m.contains("fills 3 cells") && m.contains("fewer than the 100"),
            "{m}"
        );
    }
}

/// `sdem view panorama` of a scan with every point at the sensor's origin: refused (status 1)
/// saying why, in the words `localize` uses (the library's one explanation).
#[test]
fn a_scan_at_the_origin_is_refused_by_view_saying_why() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("zeros.ply");
    sdem_io::write_points_ply(&scan, &vec![Vec3::zeros(); 500]).unwrap();
    let args = ["view", "panorama", s(&scan), "--out", "p.png"];
    let m = run_err(dir.path(), &args);
    for w in [
        "zeros.ply",
        "the scan has no usable point",
        "all 500 of its points lie within 0.05 m of the sensor's origin",
    ] {
        assert!(m.contains(w), "{args:?}: {m:?} lacks {w:?}");
    }
    assert!(!dir.path().join("p.png").exists());
}
