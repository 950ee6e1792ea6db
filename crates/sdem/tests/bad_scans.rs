//! Scans that cannot be localized, or only doubtfully, through the crate's root API: each gives
//! a clear error or a result with its doubt, never a panic, never a confident wrong pose. And the
//! attitude readings' uncertainty: what the search covers, and a doubt where a match goes beyond.

use nalgebra::{Isometry3, Point3, Vector3};
use sdem::{Attitude, Doubt, Error, LocalizeOptions, Scan};

/// Points on the walls, floor and ceiling of a 3.5 × 3 × 1.5 m room with a pillar, sensor frame.
fn room() -> Vec<Point3<f64>> {
    let mut points = Vec::new();
    for i in -40..=40 {
        for j in -40..=40 {
            let (u, v) = (i as f64 * 0.05, j as f64 * 0.05);
            for p in [
                [2.0, u, v],
                [-1.5, u, v],
                [u, 1.7, v],
                [u, -1.3, v],
                [u, v, 1.1],
                [u, v, -0.4],
            ] {
                points.push(Point3::new(p[0], p[1], p[2]));
            }
            let (s, h) = (i as f64 * 0.15 / 40.0, j as f64 * 0.75 / 40.0 + 0.35);
            for p in [
                [0.85, 0.8 + s],
                [1.15, 0.8 + s],
                [1.0 + s, 0.65],
                [1.0 + s, 0.95],
            ] {
                points.push(Point3::new(p[0], p[1], h));
            }
        }
    }
    points
}

fn level() -> Option<Attitude> {
    Some(Attitude::default())
}

/// The same returns as nalgebra points, vectors, `f64` arrays or `f32` arrays (`AsPoint`) make
/// the same scan; an infinite coordinate is refused, naming the point, in every form.
#[test]
fn every_point_type_makes_the_same_scan() {
    let points = room();
    let vectors: Vec<Vector3<f64>> = points.iter().map(|p| p.coords).collect();
    let arrays: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let floats: Vec<[f32; 3]> = points
        .iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let reading = Some(Attitude::from_degrees(1.0, -2.0, 30.0));
    // Each cell's range, unknown cells (NaN) as 0.
    let cells = |scan: Scan| -> Vec<f32> {
        (scan.sdem().ranges().iter())
            .map(|r| if r.is_nan() { 0.0 } else { *r })
            .collect()
    };
    let expected = cells(Scan::from_points(&points, reading).unwrap());
    assert_eq!(
        cells(Scan::from_points(&vectors, reading).unwrap()),
        expected
    );
    assert_eq!(
        cells(Scan::from_points(&arrays, reading).unwrap()),
        expected
    );
    // f32 coordinates round at 0.1 µm: the nearest return per cell stays in its cell.
    let vectors32: Vec<Vector3<f32>> = floats.iter().map(|p| Vector3::from(*p)).collect();
    let points32: Vec<Point3<f32>> = floats.iter().map(|p| Point3::from(*p)).collect();
    for from_floats in [
        cells(Scan::from_points(&floats, reading).unwrap()),
        cells(Scan::from_points(&vectors32, reading).unwrap()),
        cells(Scan::from_points(&points32, reading).unwrap()),
    ] {
        assert_eq!(from_floats.len(), expected.len());
        for (a, b) in from_floats.iter().zip(&expected) {
            assert!(a == b || (a - b).abs() < 1e-6, "{a} {b}");
        }
    }
    // An infinite coordinate is refused, naming the point, in every form.
    let refused = |e: sdem::Error| assert!(e.to_string().contains("point 7"), "{e}");
    let mut bad = (
        points.clone(),
        vectors.clone(),
        arrays.clone(),
        floats.clone(),
    );
    bad.0[7].y = f64::INFINITY;
    bad.1[7].y = f64::INFINITY;
    bad.2[7][1] = f64::INFINITY;
    bad.3[7][1] = f32::INFINITY;
    refused(Scan::from_points(&bad.0, reading).unwrap_err());
    refused(Scan::from_points(&bad.1, reading).unwrap_err());
    refused(Scan::from_points(&bad.2, reading).unwrap_err());
    refused(Scan::from_points(&bad.3, reading).unwrap_err());
}

/// Degrees given where radians are meant (`Attitude::new(30.0, …)`, roll beyond a full turn)
/// are refused, naming the two constructors; a full turn itself passes.
#[test]
fn an_attitude_in_degrees_given_as_radians_is_refused() {
    let room = room();
    let e = Scan::from_points(&room, Some(Attitude::new(30.0, 0.0, 0.0))).unwrap_err();
    assert!(e.to_string().contains("Attitude::from_degrees"), "{e}");
    Scan::from_points(&room, Some(Attitude::from_degrees(0.0, 360.0, 0.0))).unwrap();
}

#[test]
fn too_few_points_is_an_error_saying_how_many() {
    let few: Vec<Point3<f64>> = room().into_iter().step_by(2000).collect();
    match Scan::from_points(&few, level()) {
        Err(Error::TooFewPoints { usable, needed }) => {
            assert!(
                usable < needed && needed == sdem::scan::MIN_KNOWN_CELLS,
                "{usable} {needed}"
            )
        }
        other => panic!("expected TooFewPoints, got {other:?}"),
    }
}

/// A scan that fills no cell at all is refused saying why, in the words `relocalize` and
/// `sdem localize` use: not as "0 cells, fewer than 100".
#[test]
fn a_scan_that_fills_no_cell_says_why() {
    let at_origin = vec![Point3::origin(); 500];
    let nan = [Point3::new(f64::NAN, 0.0, 0.0); 3];
    for (points, wanted) in [
        (&[][..], "it holds no point"),
        (
            &at_origin[..],
            "all 500 of its points lie within 0.05 m of the sensor's origin",
        ),
        (&nan[..], "none of its 3 points is finite"),
    ] {
        match Scan::from_points(points, None) {
            Err(e @ Error::NoUsablePoints { .. }) => {
                let message = e.to_string();
                for w in ["the scan has no usable point", wanted] {
                    assert!(message.contains(w), "{message:?} lacks {w:?}");
                }
            }
            other => panic!("expected NoUsablePoints, got {other:?}"),
        }
    }
}

/// The loop's first scan becomes a node at once, with no search: one that fills no cell is
/// refused there too, with the same typed error naming the scan, and the map stays empty.
#[test]
fn a_first_scan_that_fills_no_cell_is_refused_saying_why() {
    let at_origin = vec![Vector3::zeros(); 500];
    let mut slam = sdem::Slam::new(sdem::SlamOptions::default()).unwrap();
    let scan = sdem::slam::ScanInput {
        scan_index: 7,
        points_in_sensor: &at_origin,
        attitude: None,
        odometry: None,
    };
    match slam.add_scan(&scan) {
        Err(e @ Error::NoUsablePoints { .. }) => {
            let message = e.to_string();
            for w in ["the scan has no usable point", "within 0.05 m", "(scan 7)"] {
                assert!(message.contains(w), "{message:?} lacks {w:?}");
            }
        }
        other => panic!("expected NoUsablePoints, got {other:?}"),
    }
    assert!(slam.map.nodes.is_empty());
}

#[test]
fn non_finite_input_is_named_nan_points_are_no_return() {
    let mut points = room();
    points[17] = Point3::new(1.0, f64::INFINITY, 0.0);
    match Scan::from_points(&points, level()) {
        Err(Error::InvalidInput { what, .. }) => assert_eq!(what, "point 17"),
        other => panic!("expected InvalidInput, got {other:?}"),
    }
    points[17] = Point3::new(f64::NAN, 0.0, 0.0);
    let scan = Scan::from_points(&points, level()).unwrap();
    assert_eq!(scan.points_in_sensor().len(), points.len() - 1);
    let bad = Attitude::from_degrees(f64::NAN, 0.0, 0.0);
    match Scan::from_points(&room(), Some(bad)) {
        Err(Error::InvalidInput { what, .. }) => assert_eq!(what, "attitude"),
        other => panic!("expected InvalidInput, got {other:?}"),
    }
    // The incremental loop checks its input the same way, and stays empty.
    let mut slam = sdem::Slam::new(sdem::SlamOptions::default()).unwrap();
    points[17] = Point3::new(1.0, f64::INFINITY, 0.0);
    match slam.add(&points, level(), None) {
        Err(Error::InvalidInput { what, .. }) => assert_eq!(what, "point 17"),
        other => panic!("expected InvalidInput, got {other:?}"),
    }
    assert!(matches!(
        slam.add(&room(), Some(bad), None),
        Err(Error::InvalidInput { .. })
    ));
    assert!(slam.poses().is_empty());
}

#[test]
fn the_reference_again_is_where_it_was() {
    let scan = Scan::from_points(&room(), level()).unwrap();
    let found = sdem::localize(&scan, &scan, &LocalizeOptions::default()).unwrap();
    assert!(found.trusted, "{:?}", found.doubts);
    let moved = found.reference_from_query.translation.vector.norm();
    let turned = found.reference_from_query.rotation.angle().to_degrees();
    assert!(moved < 1e-3 && turned < 0.01, "{moved} m, {turned}°");
}

#[test]
fn a_floor_alone_is_never_a_confident_wrong_pose() {
    // Only the floor, a 4 m patch of it: its edges are all that fixes x, y and the heading.
    // Whatever comes back is either right, or says why it may not be.
    let floor: Vec<Point3<f64>> = room().into_iter().filter(|p| p.z < -0.39).collect();
    let reference = Scan::from_points(&floor, level()).unwrap();
    for (x, y, yaw_deg) in [(0.2, 0.1, 6.0f64), (0.45, -0.45, 9.0), (-0.3, 0.25, -8.0)] {
        let truth = Isometry3::new(Vector3::new(x, y, 0.0), Vector3::z() * yaw_deg.to_radians());
        let seen: Vec<Point3<f64>> = floor.iter().map(|p| truth.inverse() * p).collect();
        let query = Scan::from_points(&seen, level()).unwrap();
        match sdem::localize(&reference, &query, &LocalizeOptions::default()) {
            Ok(found) if found.trusted => {
                let off = found.reference_from_query.translation.vector - truth.translation.vector;
                let turned = found
                    .reference_from_query
                    .rotation
                    .angle_to(&truth.rotation);
                assert!(
                    off.norm() < 0.01 && turned.to_degrees() < 0.5,
                    "trusted but {:.1} mm and {:.2}° off",
                    off.norm() * 1e3,
                    turned.to_degrees()
                );
            }
            Ok(found) => assert!(!found.doubts.is_empty()),
            Err(e) => assert!(e.is_no_match(), "{e}"),
        }
    }
}

#[test]
fn scans_on_different_grids_are_refused() {
    let fine = Scan::from_points(&room(), level()).unwrap();
    let coarse = sdem::SdemConfig {
        resolution_deg: 2.0,
        ..Default::default()
    };
    let coarse = Scan::with_grid(&room(), level(), &coarse).unwrap();
    assert!(matches!(
        sdem::localize(&fine, &coarse, &LocalizeOptions::default()),
        Err(Error::Invalid(_))
    ));
}

/// The room seen from `truth` (the query's pose in the reference's frame).
fn seen_from(truth: &Isometry3<f64>) -> Vec<Point3<f64>> {
    room().iter().map(|p| truth.inverse() * p).collect()
}

#[test]
fn a_roll_reading_off_beyond_its_sigma_is_a_doubt_within_it_is_not() {
    // The query stands level, 10 cm on; its gyro says 2.5° of roll (the default σ of 0.5° for
    // roll and pitch allows 2.1° between two readings at 3σ).
    let truth = Isometry3::translation(0.1, 0.0, 0.0);
    let reference = Scan::from_points(&room(), level()).unwrap();
    let wrong_roll = Attitude::from_degrees(2.5, 0.0, 0.0);
    let query = Scan::from_points(&seen_from(&truth), Some(wrong_roll)).unwrap();
    let found = sdem::localize(&reference, &query, &LocalizeOptions::default()).unwrap();
    assert!(!found.trusted);
    let tilt = found.doubts.iter().find_map(|d| match d {
        Doubt::AttitudeCorrected { tilt_deg, .. } => Some(*tilt_deg),
        _ => None,
    });
    assert!(
        tilt.is_some_and(|t| (t - 2.5).abs() < 0.25),
        "{:?}",
        found.doubts
    );
    // The match itself is right: the refinement took the roll out.
    let off = (found.reference_from_query.translation.vector - truth.translation.vector).norm();
    assert!(off < 0.005, "{off} m");
    // A gyro said to be good to 2° allows it: no doubt about the attitude (this box-shaped room
    // may still leave a runner-up close).
    let query = Scan::from_points(
        &seen_from(&truth),
        Some(wrong_roll.with_sigma_deg(2.0, 3.5)),
    )
    .unwrap();
    let found = sdem::localize(&reference, &query, &LocalizeOptions::default()).unwrap();
    let attitude_doubt = |d: &Doubt| matches!(d, Doubt::AttitudeCorrected { .. });
    assert!(
        !found.doubts.iter().any(attitude_doubt),
        "{:?}",
        found.doubts
    );
}

#[test]
fn the_heading_search_covers_what_the_compass_sigma_allows() {
    // The query turned 20° while its compass reads 0°; a 4 cm grid keeps the search short.
    let truth = Isometry3::new(
        Vector3::new(0.12, 0.04, 0.0),
        Vector3::z() * 20f64.to_radians(),
    );
    let seen = seen_from(&truth);
    let options = LocalizeOptions {
        step_m: 0.04,
        ..Default::default()
    };
    let found_with = |sigma_yaw_deg: f64| {
        let reading = Some(Attitude::default().with_sigma_deg(0.5, sigma_yaw_deg));
        let reference = Scan::from_points(&room(), reading).unwrap();
        let query = Scan::from_points(&seen, reading).unwrap();
        sdem::localize(&reference, &query, &options)
    };
    // σ 1° each: ±4.2° searched; σ 3.5° each: ±14.8°; the truth outside both. Neither may come
    // back as a trusted wrong pose.
    let mut candidates = Vec::new();
    for sigma_yaw_deg in [1.0, 3.5] {
        match found_with(sigma_yaw_deg) {
            Ok(found) => {
                let turned = found
                    .reference_from_query
                    .rotation
                    .angle_to(&truth.rotation);
                assert!(
                    !found.trusted || turned.to_degrees() < 0.5,
                    "σ {sigma_yaw_deg}°: trusted {:.1}° off",
                    turned.to_degrees()
                );
                candidates.push(found.candidates_total);
            }
            Err(e) => assert!(e.is_no_match(), "{e}"),
        }
    }
    // The window follows the standard deviation: 3.5 times as wide, about as many more headings.
    if let [narrow, wide] = candidates[..] {
        let ratio = wide as f64 / narrow as f64;
        assert!((2.5..4.5).contains(&ratio), "{narrow} → {wide} candidates");
    }
    // A standard deviation that is no number is refused.
    let bad = Attitude::default().with_sigma_deg(f64::NAN, 3.5);
    assert!(matches!(
        Scan::from_points(&seen, Some(bad)),
        Err(Error::InvalidInput { .. })
    ));
}
