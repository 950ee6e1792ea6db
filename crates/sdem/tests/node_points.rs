//! What a map node keeps of its scan, and what matching a new scan against it gives: the
//! node's points lie on the surfaces it saw (not in front of them), so a turn matched against
//! a node comes out as far as it really turned.

use nalgebra::Isometry3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sdem::geometry::{attitude_of, direction, Pose, Vec3};
use sdem::map::{Map, Node};
use sdem::refine::{refine, RefineConfig, SurfaceNormals};
use sdem::sdem::{Sdem, SdemConfig};
use sdem::sensor::SensorConfig;
use sdem_sim::sim::{long_run, LongRoute};

/// A wall 3 m ahead seen at 0.25° steps with 5 mm of range noise: 16 returns in each 1° cell.
/// The nearest of them lies about 9 mm in front of the wall; the node's point of the cell (the
/// mean of its returns on the surface) on it.
#[test]
fn a_nodes_points_lie_on_the_surface_where_its_cells_hold_several_returns() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let mut points = Vec::new();
    for i in -80..80 {
        for j in -40..40 {
            let d = direction(
                (i as f64 * 0.25).to_radians(),
                (j as f64 * 0.25).to_radians(),
            );
            let noise = 0.005 * rng.sample::<f64, _>(rand_distr::StandardNormal);
            points.push(d * (3.0 / d.x + noise));
        }
    }
    let node = Node::from_scan(
        0,
        0,
        Pose::identity(),
        None,
        &points,
        &SdemConfig::default(),
    )
    .unwrap();
    // 40 × 20 cells, and a column of the returns on a cell's edge rounded into the next.
    assert!(node.points_in_sensor.len() >= 40 * 20);
    // Along the ray, from the wall.
    let offsets: Vec<f64> = (node.points_in_sensor.iter())
        .map(|p| {
            let p = Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            p.norm() * (1.0 - 3.0 / p.x)
        })
        .collect();
    let mean = offsets.iter().sum::<f64>() / offsets.len() as f64;
    assert!(
        mean.abs() < 0.0005,
        "the node's points lie {:.2} mm off the wall on average",
        mean * 1e3
    );
}

/// The corners of the `wings` route: 10 steps of about 0.35 m that turn 14–19°, exact
/// attitudes, each scan matched against the node of the stop before (as the loop's merged
/// reference) and refined from the truth. With the nodes keeping their cells' nearest returns
/// they came out turned too far, by 0.024° on average (and 1.05 mm to the outside of the turn);
/// with the cells' means, 0.001° (0.04 mm). One step's heading scatters by about 0.01°, the
/// mean of ten by about 0.003°: a mean above 0.01° is a bias.
#[test]
fn a_turn_matched_against_a_node_comes_out_as_far_as_it_turned() {
    let sensor = SensorConfig {
        compass_noise_deg: 0.0,
        tilt_sensor_noise_deg: 0.0,
        ..Default::default()
    };
    let run = long_run(LongRoute::Wings, 1, 61, &sensor.lift).unwrap();
    let truth = run.truth(&sensor.lift).unwrap();
    let sims = run.simulate(&sensor, 1, 43..61).unwrap();
    let grid = SdemConfig::default();
    let config = RefineConfig::default();
    let (mut yaw_sum, mut across_sum, mut turns) = (0.0, 0.0, 0);
    for i in 44..61 {
        let heading = attitude_of(&truth[i - 1]).yaw;
        let turn = (attitude_of(&truth[i]).yaw - heading).to_degrees();
        if turn.abs() < 10.0 {
            continue;
        }
        let (before, now) = (&sims[i - 44], &sims[i - 43]);
        let node = Node::from_scan(
            0,
            i - 1,
            truth[i - 1],
            None,
            &before.sweep.points_in_sensor(),
            &grid,
        )
        .unwrap();
        let map = Map { nodes: vec![node] };
        let reference = map.merged_reference(&[0], &truth[i - 1].translation.vector, &grid);
        let reference = reference.unwrap();
        let query = Sdem::from_points(
            &now.sweep.points_in_sensor(),
            &now.sweep.mean_attitude(),
            &grid,
        )
        .unwrap();
        let offset = truth[i].translation.vector - truth[i - 1].translation.vector;
        let initial = Isometry3::translation(offset.x, offset.y, offset.z);
        let normals = SurfaceNormals::of(&reference, config.normal_radius_cells);
        let found = refine(&reference, &normals, &query, &initial, None, &config).unwrap();
        let estimate = found.reference_level_from_query_level;
        let error = estimate.translation.vector - offset;
        yaw_sum += attitude_of(&estimate).yaw.to_degrees() * turn.signum();
        across_sum += (-error.x * heading.sin() + error.y * heading.cos()) * turn.signum();
        turns += 1;
    }
    assert_eq!(turns, 10, "the route's corners moved");
    let (yaw, across) = (yaw_sum / turns as f64, across_sum / turns as f64);
    assert!(
        yaw.abs() < 0.01,
        "the turns came out {yaw:.4}° too far on average ({:.2} mm across, to the turn's \
         side)",
        across * 1e3
    );
}

/// A node knows its own scan again whatever its pose became: after a loop closure turned it by
/// half a cell (its points were binned on the grid levelled by its first pose) every point is
/// still found among the scan's returns; the next stop's scan, 0.35 m on, explains far fewer.
#[test]
fn a_node_finds_its_own_scan_again_after_its_pose_moved_and_not_the_next_one() {
    let sensor = SensorConfig::default();
    let run = long_run(LongRoute::Wings, 1, 3, &sensor.lift).unwrap();
    let truth = run.truth(&sensor.lift).unwrap();
    let sims = run.simulate(&sensor, 1, 0..2).unwrap();
    let grid = SdemConfig::default();
    let scan = sims[0].sweep.points_in_sensor();
    let mut node = Node::from_scan(0, 0, truth[0], None, &scan, &grid).unwrap();
    assert_eq!(node.share_found_in_scan(&scan, &grid).unwrap(), 1.0);
    for (roll, yaw) in [(0.0, 0.5), (1.0, 0.25), (0.3, 0.7)] {
        let turn = nalgebra::UnitQuaternion::from_euler_angles(
            f64::to_radians(roll),
            0.0,
            f64::to_radians(yaw),
        );
        node.world_from_sensor = Pose::from_parts(truth[0].translation, turn * truth[0].rotation);
        let share = node.share_found_in_scan(&scan, &grid).unwrap();
        assert!(share > 0.99, "turned roll {roll}°, yaw {yaw}°: {share}");
    }
    let moved = (truth[1].translation.vector - truth[0].translation.vector).norm();
    let next = node
        .share_found_in_scan(&sims[1].sweep.points_in_sensor(), &grid)
        .unwrap();
    assert!(next < 0.8, "the next scan, {moved:.2} m on: {next}");
}
