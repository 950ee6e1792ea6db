//! The loop with its far nodes parked in a store maps exactly as the loop with every node in
//! memory, while at most `growth.resident_nodes` nodes hold their points.

mod common;

use common::Memory;
use sdem::geometry::Pose;
use sdem::sensor::SensorConfig;
use sdem::slam::*;
use sdem_sim::odometry::{simulate_odometry, OdometryNoise};
use sdem_sim::sim;
use std::sync::Arc;

/// Maps the loop of the simulated collapsed building (seed 1), with `store` attached when
/// given; returns the loop and the most nodes that held their points after a step.
fn map_loop(options: SlamOptions, store: Option<Arc<Memory>>) -> (Slam, usize) {
    let seed = 1;
    let scene = sim::collapsed_building(seed);
    let sensor = SensorConfig {
        compass_noise_deg: 2.0,
        ..Default::default()
    };
    let stops = sim::collapsed_building_stops(&scene, seed, sim::MAX_STOPS, &sensor.lift).unwrap();
    let (i, j) = scene.loop_closure_stops().unwrap();
    let run = sim::simulate_run(&scene, &stops[i..=j], &sensor, seed).unwrap();
    let truth: Vec<Pose> = run.iter().map(|s| s.world_from_sensor).collect();
    let odometry = simulate_odometry(&truth, &OdometryNoise::default(), seed).unwrap();
    let mut slam = Slam::new(options).unwrap();
    if let Some(store) = store {
        slam.set_node_store(store);
    }
    let mut most_resident = 0;
    for (k, stop) in run.iter().enumerate() {
        let points = stop.sweep.points_in_sensor();
        slam.add_scan(&ScanInput {
            scan_index: k,
            points_in_sensor: &points,
            attitude: Some(stop.sweep.mean_attitude()),
            odometry: (k > 0).then(|| Odometry {
                odom_from_sensor: odometry[k],
                odom_from_previous_sensor: odometry[k - 1],
            }),
        })
        .unwrap();
        most_resident = most_resident.max(slam.resident_nodes());
    }
    (slam, most_resident)
}

#[test]
fn a_loop_with_its_far_nodes_parked_maps_as_one_with_every_node_in_memory() {
    let mut options = SlamOptions::default();
    // The 11 newest nodes are never parked (the references and the loop's own chain).
    options.growth.resident_nodes = 12;
    let store = Arc::new(Memory::default());
    let ((parked, most_resident), (whole, _)) = rayon::join(
        || map_loop(options.clone(), Some(store.clone())),
        || map_loop(options.clone(), None),
    );
    let nodes = whole.map.nodes.len();
    assert!(nodes > 20, "{nodes} nodes");
    assert!(
        most_resident <= 12,
        "{most_resident} nodes held their points"
    );
    assert!(store.kept.lock().unwrap().len() >= nodes - 12);
    // The loop's closure went back to parked nodes, and they came back as they were.
    assert!(!whole.loop_closures.is_empty());
    assert!(*store.fetches.lock().unwrap() > 0);
    // The same poses, to the last few bits: two runs of the loop with every node in memory,
    // side by side, differ by an ulp here and there too (the threads' parallel sums).
    for (k, (a, b)) in parked.poses().iter().zip(whole.poses()).enumerate() {
        let moved = (a.translation.vector - b.translation.vector).norm();
        let turned = a.rotation.angle_to(&b.rotation);
        assert!(
            moved < 1e-9 && turned < 1e-9,
            "node {k}: {moved} m, {turned} rad"
        );
    }
    let closed = |slam: &Slam| -> Vec<(usize, usize, bool)> {
        (slam.loop_closures.iter())
            .map(|c| (c.from, c.to, c.accepted))
            .collect()
    };
    assert_eq!(closed(&parked), closed(&whole));
    assert_eq!(parked.voxels().counts(), whole.voxels().counts());
    assert_eq!(
        parked.merged_cloud().unwrap().len(),
        whole.merged_cloud().unwrap().len()
    );
}
