//! Scenes that leave the pose free along some direction: the result must say so, never come
//! back as a trusted pose along the free direction; and the same scene with something to fix
//! that direction must be found and trusted.

use nalgebra::{Isometry3, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sdem::{Attitude, LocalizeOptions, Scan};

/// A scan over the whole sphere at 1° of a tube (walls at y = ±1 m, floor at −0.5 m, ceiling at
/// +1 m) from `origin`, within 8 m, with uniform range noise of 3 mm standard deviation. With
/// `closed` the tube has end walls at x = ±`half_length`; without, it is open and nothing is
/// seen beyond them.
fn tube_scan(origin: Vector3<f64>, half_length: f64, closed: bool, seed: u64) -> Vec<Point3<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut points = Vec::new();
    let mut bounds = vec![(1, 1.0), (1, -1.0), (2, -0.5), (2, 1.0)];
    if closed {
        bounds.extend([(0, half_length), (0, -half_length)]);
    }
    for i in 0..360 {
        for j in 0..180 {
            let (az, el) = (
                (i as f64 - 180.0).to_radians(),
                (j as f64 - 89.5).to_radians(),
            );
            let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let t = (bounds.iter())
                .filter(|(axis, _)| d[*axis].abs() > 1e-12)
                .map(|&(axis, bound)| (bound - origin[axis]) / d[axis])
                .filter(|&s| s > 0.0)
                .fold(f64::INFINITY, f64::min);
            let p = origin + d * t;
            if t < 8.0 && p.x.abs() <= half_length + 1e-9 {
                let r = t + (rng.random::<f64>() - 0.5) * 0.0104;
                points.push(Point3::from(d * r));
            }
        }
    }
    points
}

fn localize_in_tube(half_length: f64, closed: bool, shift: f64) -> (f64, sdem::Localization) {
    let level = Some(Attitude::default());
    let origin = Vector3::zeros();
    let reference = Scan::from_points(&tube_scan(origin, half_length, closed, 1), level).unwrap();
    let truth = Isometry3::translation(shift, 0.05, 0.0);
    let moved = truth.translation.vector;
    let query = Scan::from_points(&tube_scan(moved, half_length, closed, 2), level).unwrap();
    let found = sdem::localize(&reference, &query, &LocalizeOptions::default()).unwrap();
    let error = (found.reference_from_query.translation.vector - moved).norm();
    (error, found)
}

#[test]
fn an_open_featureless_tube_leaves_the_position_along_it_in_doubt() {
    // Only the edge of what each scan sees (its 8 m range, the tube's open ends) moves with
    // the sensor: a search over eq. (1) then prefers no motion along the tube, and the
    // refinement's normals, a few degrees off each near the sensor, add up to as much
    // information along the axis as a real surface would give. The surfaces facing along the
    // axis must be counted, and found missing.
    for (half_length, shift) in [(6.0, 0.1), (15.0, 0.1), (6.0, 0.2)] {
        let (error, found) = localize_in_tube(half_length, false, shift);
        let kinds: Vec<&str> = found.doubts.iter().map(|d| d.kind()).collect();
        assert!(
            !found.trusted && kinds.contains(&"unconstrained"),
            "open tube ±{half_length} m, {shift} m along: {:.1} mm off, doubts {kinds:?}",
            error * 1e3
        );
        let support = found.diagnostics.weakest_support.unwrap();
        assert!(support < 0.01, "{support}");
        let axis = found.diagnostics.weakest_direction.unwrap();
        assert!(
            axis[0].abs() > 0.99,
            "the free direction is the tube's axis: {axis:?}"
        );
    }
}

#[test]
fn the_same_tube_closed_at_its_ends_is_found_and_trusted() {
    let (error, found) = localize_in_tube(6.0, true, 0.1);
    assert!(found.trusted, "{:?}", found.doubts);
    assert!(error < 0.005, "{:.1} mm", error * 1e3);
    assert!(found.diagnostics.weakest_support.unwrap() > 0.02);
}
