//! A saved map used again from the library, as `sdem localize --map` and `sdem slam --map` use
//! it: `SavedMap::relocalize` with the map's own settings, and `SavedMap::into_slam` to go on.

use sdem::sensor::SensorConfig;
use sdem::slam::{Near, ScanInput, Slam, SlamOptions};
use sdem_io::{load_map, save_map, NodeFiles};
use sdem_sim::sim;

#[test]
fn a_saved_map_relocalizes_its_scans_and_goes_on_as_a_slam() {
    let seed = 4;
    let sensor = SensorConfig::default();
    let scene = sim::collapsed_building(seed);
    let route = sim::collapsed_building_stops(&scene, seed, 5, &sensor.lift).unwrap();
    let run = sim::simulate_run(&scene, &route, &sensor, seed).unwrap();
    let mut slam = Slam::new(SlamOptions::default()).unwrap();
    let scans: Vec<_> = run.iter().map(|s| s.sweep.points_in_sensor()).collect();
    for (i, (stop, points)) in run.iter().zip(&scans).enumerate() {
        slam.add_scan(&ScanInput {
            scan_index: i,
            points_in_sensor: points,
            attitude: Some(stop.sweep.mean_attitude()),
            odometry: None,
        })
        .unwrap();
    }
    let dir = tempfile::tempdir().unwrap();
    let mut files = NodeFiles::default();
    let (map, edges, closures) = (&slam.map, &slam.edges, &slam.loop_closures);
    save_map(
        dir.path(),
        &mut files,
        slam.config(),
        map,
        edges,
        closures,
        &[None],
    )
    .unwrap();
    let saved = load_map(dir.path()).unwrap();

    // Stop 3's scan, with no prior and near its node: found at its node's pose.
    let node = saved.map.nodes[3].world_from_sensor.translation.vector;
    let attitude = Some(run[3].sweep.mean_attitude());
    for near in [
        None,
        Some(Near {
            position: node,
            sigma_m: None,
        }),
    ] {
        let found = saved.relocalize(&scans[3], attitude, near, None).unwrap();
        let pose = found.world_from_sensor;
        assert!(found.trusted, "{near:?}: {:?}", found.doubts);
        assert!((pose.translation.vector - node).norm() < 0.05, "{near:?}");
    }

    // Restored, a second run goes on in the same map.
    let mut again = saved.into_slam().unwrap();
    assert_eq!(again.map.nodes.len(), 5);
    again.begin_run();
    let step = again
        .add_scan(&ScanInput {
            scan_index: 0,
            points_in_sensor: &scans[4],
            attitude: Some(run[4].sweep.mean_attitude()),
            odometry: None,
        })
        .unwrap();
    assert_eq!(step.status.name(), "relocalized", "{step:?}");
}
