use super::*;
use crate::sim;
use sdem::geometry::pose_from_parts;

/// A noise-free tilting scanner at 1° × 1°, every return kept.
fn exact_scanner() -> ReviewScanner {
    ReviewScanner::Tilting(SensorConfig {
        range_noise_m: 0.0,
        ..SensorConfig::default()
    })
}

/// The paper's room scanned from its origin at 0.5° × 0.5° with 5 mm of range noise: a "real"
/// scan whose truth is known.
fn room_model() -> (sim::Scene, SurfaceModel) {
    let scene = sim::paper_room();
    let sensor = SensorConfig {
        tilt_step_deg: 0.5,
        pan_step_deg: 0.5,
        ..SensorConfig::default()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let sweep = sim::scan(&scene, &sensor, &Pose::identity(), 0.0, &mut rng);
    let model = SurfaceModel::new(&sweep.points_in_sensor(), &ModelConfig::default()).unwrap();
    (scene, model)
}

/// The `q` quantile of `values`.
fn quantile(values: &mut [f64], q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * q).round() as usize]
}

/// Seen from elsewhere in the room (moved 41 cm, turned 12°, tilted), each return lies where the
/// room's true surface is along its beam: the view's geometry, and so the pose between views,
/// is the scene's.
#[test]
fn a_view_returns_the_true_surface_along_each_beam() {
    let (scene, model) = room_model();
    let world_from_view = pose_from_parts(
        Vec3::new(0.35, 0.2, 0.05),
        Attitude::from_degrees(2.0, -1.5, 12.0),
    );
    let rays = exact_scanner().lines().concat();
    let ranges = model.ranges(&world_from_view, &rays);
    let origin = world_from_view.translation.vector;
    let mut errors = Vec::new();
    let mut behind = 0;
    for (ray, range) in rays.iter().zip(&ranges) {
        let Some(range) = range else { continue };
        let direction = world_from_view.rotation * ray;
        let truth = scene.raycast(&origin, &direction, 30.0).unwrap();
        errors.push((range - truth).abs());
        if *range > truth + 0.05 {
            behind += 1;
        }
    }
    let returned = errors.len() as f64 / rays.len() as f64;
    let median = quantile(&mut errors, 0.5);
    let p90 = quantile(&mut errors, 0.9);
    assert!(
        returned > 0.6,
        "only {:.0} % of the beams returned",
        returned * 100.0
    );
    assert!(median < 0.002, "median error {:.2} mm", median * 1e3);
    assert!(p90 < 0.006, "90th percentile {:.2} mm", p90 * 1e3);
    assert!(
        behind as f64 <= 0.005 * errors.len() as f64,
        "{behind} of {} returns lie more than 5 cm behind the true surface",
        errors.len()
    );
}

/// Plates facing the origin: a pole 2 m away, a second one 3 m away that the first hides
/// from the origin, and a wall 8 m away; `[x, y_min, y_max, half height]`.
const PLATES: [[f64; 4]; 3] = [
    [2.0, -0.1, 0.1, 1.0],
    [3.0, -0.12, 0.12, 1.0],
    [8.0, -20.0, 20.0, 20.0],
];

/// Where a ray meets `plate` (inside it by `inset`), if it does.
fn plate_hit(plate: &[f64; 4], origin: &Vec3, direction: &Vec3, inset: f64) -> Option<f64> {
    let t = (plate[0] - origin.x) / direction.x;
    let p = origin + direction * t;
    let inside =
        p.y >= plate[1] + inset && p.y <= plate[2] - inset && p.z.abs() <= plate[3] - inset;
    (t > 0.0 && inside).then_some(t)
}

/// The first plate a ray meets: its index and range.
fn first_plate(origin: &Vec3, direction: &Vec3) -> Option<(usize, f64)> {
    (PLATES.iter().enumerate())
        .filter_map(|(i, p)| plate_hit(p, origin, direction, 0.0).map(|t| (i, t)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// The plates scanned from the origin at 0.5° steps, noise-free.
fn plates_scan() -> Vec<Vec3> {
    let mut points = Vec::new();
    for i in -80..=80 {
        for j in -70..=70 {
            let (a, e) = ((i as f64 * 0.5).to_radians(), (j as f64 * 0.5).to_radians());
            let d = sdem::geometry::direction(a, e);
            if let Some((_, t)) = first_plate(&Vec3::zeros(), &d) {
                points.push(d * t);
            }
        }
    }
    points
}

/// The view's z-buffer keeps the nearest surface: no beam that meets a pole returns the wall
/// behind it. From 40 cm to the side the view looks at the hidden pole, which the scan never
/// saw: those beams get no return rather than the wall behind showing through.
#[test]
fn nearer_surfaces_hide_farther_ones_and_the_unseen_stays_unseen() {
    let model = SurfaceModel::new(&plates_scan(), &ModelConfig::default()).unwrap();
    let rays = exact_scanner().lines().concat();
    for origin in [
        Vec3::zeros(),
        Vec3::new(0.0, 0.4, 0.0),
        Vec3::new(0.3, -0.35, 0.1),
    ] {
        let world_from_view = pose_from_parts(origin, Attitude::default());
        let ranges = model.ranges(&world_from_view, &rays);
        let (mut on_pole, mut on_hidden, mut through) = (0, 0, 0);
        for (d, range) in rays.iter().zip(&ranges) {
            if d.x <= 0.05 {
                continue;
            }
            let Some((plate, t)) = first_plate(&origin, d) else {
                continue;
            };
            // Well inside a pole (3 cm from its edges, where the splats overhang).
            if plate == 2 || plate_hit(&PLATES[plate], &origin, d, 0.03).is_none() {
                continue;
            }
            if plate == 1 {
                on_hidden += 1;
            }
            match range {
                Some(r) if (r - t).abs() < 0.01 => on_pole += 1,
                Some(r) if *r > t + 0.05 => through += 1,
                _ => {}
            }
        }
        assert!(
            on_pole > 100,
            "{origin:?}: {on_pole} returns on the first pole"
        );
        assert_eq!(
            through, 0,
            "{origin:?}: beams that meet a pole returned what lies behind it"
        );
        if origin.y.abs() > 0.3 {
            assert!(
                on_hidden > 20,
                "{origin:?}: the view should see the hidden pole"
            );
        }
    }
}

/// A pair depends on its seed and index only; its truth is the query's pose (the reference
/// stands at the scan's origin); both views hold returns.
#[test]
fn review_pairs_are_seeded_per_index() {
    let (_, model) = room_model();
    let config = ReviewConfig::tilting(ReviewScanner::tilting_sick(-45.0, 40.0));
    let both = review_pairs(&model, &config, 9, 0..2).unwrap();
    let second = review_pairs(&model, &config, 9, 1..2).unwrap();
    assert_eq!(both[1], second[0]);
    assert_ne!(both[0].truth, both[1].truth);
    for pair in &both {
        assert_eq!(pair.truth, pair.world_from_query);
        let t = pair.truth.translation.vector;
        assert!(t.x.abs() <= 0.5 && t.y.abs() <= 0.5 && t.z.abs() <= 0.1);
        assert!(pair.query_points.len() as f64 >= 0.5 * pair.reference_points.len() as f64);
        assert!(pair.reference_points.len() > 5000);
    }
}

/// Unlevelled re-views turn both views: the reference stands at the scan's origin tilted and
/// turned, the truth is the query's pose seen from it, and the two views share at least half the
/// query's returns; the draws of the other configs are not changed by it (the reference there
/// stays at the scan's origin and axes).
#[test]
fn unlevelled_re_views_turn_both_views_and_keep_them_overlapping() {
    let (_, model) = room_model();
    let config = ReviewConfig::unlevelled(ReviewScanner::tilting_sick(-45.0, 40.0));
    let pairs = review_pairs(&model, &config, 4, 0..4).unwrap();
    let tilt = |p: &Pose| (p.rotation * Vec3::z()).angle(&Vec3::z()).to_degrees();
    assert!(pairs.iter().any(|p| tilt(&p.world_from_reference) > 5.0));
    for pair in &pairs {
        assert_eq!(pair.world_from_reference.translation.vector, Vec3::zeros());
        let attitude = sdem::geometry::attitude_of(&pair.world_from_reference);
        assert!(
            attitude.roll.abs() <= 30f64.to_radians() + 1e-9,
            "{attitude:?}"
        );
        assert!(
            attitude.pitch.abs() <= 30f64.to_radians() + 1e-9,
            "{attitude:?}"
        );
        let truth = pair.world_from_reference.inverse() * pair.world_from_query;
        assert!((truth.translation.vector - pair.truth.translation.vector).norm() < 1e-12);
        assert!(truth.rotation.angle_to(&pair.truth.rotation) < 1e-12);
        let shared = overlap(
            &pair.reference_points,
            &pair.world_from_reference,
            &pair.query_points,
            &pair.world_from_query,
        );
        assert!(shared >= 0.5, "{shared}");
    }
    let level = ReviewConfig::tilting(ReviewScanner::tilting_sick(-45.0, 40.0));
    for pair in review_pairs(&model, &level, 4, 0..2).unwrap() {
        assert_eq!(pair.world_from_reference, Pose::identity());
    }
}

/// A scanner is chosen like the one that took the scan: a front-half scan gets the tilting
/// scanner over its band of tilts, an all-round one a spinning LiDAR over its band of
/// elevations.
#[test]
fn the_scanner_is_chosen_like_the_scans() {
    let front = plates_scan();
    match ReviewScanner::like(&front) {
        ReviewScanner::Tilting(s) => {
            assert!(s.tilt_min_deg <= -34.0 && s.tilt_max_deg >= 34.0, "{s:?}")
        }
        other => panic!("a front-half scan re-viewed by {other:?}"),
    }
    let round: Vec<Vec3> = (0..32)
        .flat_map(|ring| (0..1800).map(move |k| (ring, k)))
        .map(|(ring, k)| {
            let (e, a) = (
                (ring as f64 - 20.0).to_radians(),
                (k as f64 * 0.2).to_radians(),
            );
            sdem::geometry::direction(a, e) * (10.0 / e.cos())
        })
        .collect();
    match ReviewScanner::like(&round) {
        ReviewScanner::Spinning(l) => {
            assert!((l.elevation_min_deg + 20.0).abs() <= 1.0, "{l:?}");
            assert!((l.elevation_max_deg - 11.0).abs() <= 1.0, "{l:?}");
        }
        other => panic!("an all-round scan re-viewed by {other:?}"),
    }
}
