//! The 6-DoF refinement: a LiDAR's sampled first strides end on every point.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sdem::geometry::{pose_error, pose_from_parts, Attitude, Pose, Vec3};
use sdem::localize::*;
use sdem::sdem::{Sdem, SdemConfig};
use sdem::sensor::SensorConfig;
use sdem_sim::sim;

/// The scene scanned from `world_from_sensor` with `range_noise_m` of noise.
fn sdem_at(scene: &sim::Scene, world_from_sensor: &Pose, range_noise_m: f64, seed: u64) -> Sdem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sweep = sim::scan(
        scene,
        &SensorConfig::default(),
        world_from_sensor,
        range_noise_m,
        &mut rng,
    );
    let grid = SdemConfig::default();
    Sdem::from_points(&sweep.points_in_sensor(), &sweep.mean_attitude(), &grid).unwrap()
}

/// A small window (±6 cm, ±4 cm high, ±2° of heading) about the true offset.
fn near(truth: &Pose) -> LocalizeOptions {
    LocalizeOptions {
        window: SearchWindow::around(&truth.translation.vector, [0.06, 0.06, 0.04]),
        heading: HeadingWindow {
            half_range_deg: 2.0,
            step_deg: None,
        },
        ..Default::default()
    }
}

/// An even sample of 300 points takes the first strides, every point the rest: the estimate
/// is every point's (to a tenth of a millimetre), not the sample's.
#[test]
fn a_refinement_started_on_a_sample_ends_on_every_point() {
    let scene = sim::paper_room();
    let truth = pose_from_parts(
        Vec3::new(0.21, -0.13, 0.02),
        Attitude::from_degrees(1.0, -2.0, 4.0),
    );
    let reference = sdem_at(&scene, &Pose::identity(), 0.0, 11);
    let query = sdem_at(&scene, &truth, 0.0, 12);
    assert!(query.surface_points().len() > 3000);
    let options = |max_points| {
        let mut o = near(&truth);
        o.refinement.max_points = max_points;
        o
    };
    let every = localize(&reference, &query, &options(0)).unwrap();
    let sampled = localize(&reference, &query, &options(300)).unwrap();
    let (dt, dr) = pose_error(&every.reference_from_query, &sampled.reference_from_query);
    assert!(
        dt < 1e-4 && dr.to_degrees() < 0.005,
        "{dt} m, {} deg apart",
        dr.to_degrees()
    );
    let (dt, dr) = pose_error(&truth, &sampled.reference_from_query);
    assert!(
        dt < 0.005 && dr.to_degrees() < 0.1,
        "{dt} m, {} deg off",
        dr.to_degrees()
    );
}

/// The blended surface (`blend_radius_cells`, an option) refines a noisy pair to the truth as
/// the nearest planes do, to a different pose (it is not the nearest planes' residual under
/// another name), and 0 is the default.
#[test]
fn the_blended_surface_refines_to_the_truth() {
    assert_eq!(
        LocalizeOptions::default().refinement.blend_radius_cells,
        0.0
    );
    let scene = sim::paper_room();
    let truth = pose_from_parts(
        Vec3::new(0.17, 0.09, 0.01),
        Attitude::from_degrees(-1.0, 1.5, 3.0),
    );
    let reference = sdem_at(&scene, &Pose::identity(), 0.005, 21);
    let query = sdem_at(&scene, &truth, 0.005, 22);
    let options = |blend| {
        let mut o = near(&truth);
        o.refinement.blend_radius_cells = blend;
        o
    };
    let nearest = localize(&reference, &query, &options(0.0)).unwrap();
    let blended = localize(&reference, &query, &options(1.5)).unwrap();
    for found in [&nearest, &blended] {
        let (dt, dr) = pose_error(&truth, &found.reference_from_query);
        assert!(
            dt < 0.003 && dr.to_degrees() < 0.1,
            "{dt} m, {} deg off",
            dr.to_degrees()
        );
    }
    let (dt, _) = pose_error(&nearest.reference_from_query, &blended.reference_from_query);
    assert!(dt > 1e-7, "the blend changed nothing ({dt} m)");
}
