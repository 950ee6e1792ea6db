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
    assert_eq!(
        parked.voxels().unwrap().counts(),
        whole.voxels().unwrap().counts()
    );
    assert_eq!(
        parked.merged_cloud().unwrap().len(),
        whole.merged_cloud().unwrap().len()
    );
}

/// Every voxel of a map, sorted: two maps compare voxel by voxel.
fn voxels_of(slam: &Slam) -> Vec<(sdem::voxel::VoxelKey, f32)> {
    let mut voxels: Vec<_> = slam.voxels().unwrap().iter().collect();
    voxels.sort_by_key(|a| a.0);
    voxels
}

#[test]
fn a_map_fused_when_it_is_settled_is_the_map_fused_stop_by_stop() {
    // Every node a solve moved is fused again when the map is settled (a µm tolerance: a
    // rotation compared with itself can read a few nrad), so both maps hold every node's scan
    // at its final pose; the counts do not depend on the order.
    let mut eager = SlamOptions::default();
    eager.growth.fuse_each_stop = true;
    eager.growth.refuse_tolerance_m = 1e-6;
    eager.growth.refuse_tolerance_deg = 1e-4;
    let lazy = SlamOptions {
        growth: GrowthOptions {
            fuse_each_stop: false,
            ..eager.growth.clone()
        },
        ..eager.clone()
    };
    let ((mut eager, _), (mut lazy, _)) =
        rayon::join(|| map_loop(eager, None), || map_loop(lazy, None));
    assert!(!eager.loop_closures.is_empty(), "no solve moved a node");
    // Read before it is settled, the lazy map fuses its nodes into a copy.
    let unsettled = voxels_of(&lazy);
    let fused = lazy.settle_map().unwrap();
    assert_eq!(fused, lazy.map.nodes.len(), "every node fused when settled");
    assert_eq!(lazy.settle_map().unwrap(), 0, "nothing left to fuse");
    eager.settle_map().unwrap();
    let settled = voxels_of(&lazy);
    assert!(settled.len() > 1000, "{} voxels", settled.len());
    assert_eq!(unsettled, settled);
    assert_eq!(voxels_of(&eager), settled);
}
