//! On a route that passes the same places lap after lap, the nodes near the robot grow with
//! the laps; the nodes one stop brings back from the store to weigh do not.

mod common;

use common::Memory;
use sdem::sensor::SensorConfig;
use sdem::slam::*;
use sdem_sim::odometry::{simulate_odometry, OdometryNoise};
use sdem_sim::sim::{long_run, LongRoute};
use std::sync::Arc;

#[test]
fn the_nodes_a_stop_brings_back_stay_bounded_as_laps_pass_the_same_place() {
    const LAPS: usize = 3;
    let seed = 1;
    let sensor = SensorConfig {
        compass_noise_deg: 2.0,
        ..Default::default()
    };
    let run = long_run(LongRoute::RoomLaps, seed, 30 * LAPS, &sensor.lift).unwrap();
    let truth = run.truth(&sensor.lift).unwrap();
    let odometry = simulate_odometry(&truth, &OdometryNoise::default(), seed).unwrap();
    let mut options = SlamOptions::default();
    options.growth.resident_nodes = 20;
    options.growth.closure_candidate_nodes = 8;
    let growth = options.growth.clone();
    let recent = options.loop_closure.min_node_separation + 1;
    let mut slam = Slam::new(options).unwrap();
    let store = Arc::new(Memory::default());
    slam.set_node_store(store.clone());
    let mut most_fetched = 0;
    let mut closed_in_last_lap = 0;
    let stops = run.stops.len();
    for chunk in (0..stops).step_by(16) {
        let sims = run
            .simulate(&sensor, seed, chunk..(chunk + 16).min(stops))
            .unwrap();
        for (k, stop) in sims.iter().enumerate() {
            let i = chunk + k;
            let points = stop.sweep.points_in_sensor();
            let before = *store.fetches.lock().unwrap();
            let report = slam
                .add_scan(&ScanInput {
                    scan_index: i,
                    points_in_sensor: &points,
                    attitude: Some(stop.sweep.mean_attitude()),
                    odometry: (i > 0).then(|| Odometry {
                        odom_from_sensor: odometry[i],
                        odom_from_previous_sensor: odometry[i - 1],
                    }),
                })
                .unwrap();
            assert!(report.trusted, "stop {i}: {:?}", report.doubts);
            let fetched = *store.fetches.lock().unwrap() - before;
            most_fetched = most_fetched.max(fetched);
            if i >= 30 * (LAPS - 1) {
                closed_in_last_lap += report.loop_closures.iter().filter(|c| c.accepted).count();
            }
        }
    }
    // By the last lap every parked node lies within the recovery radius of a stop (the room
    // is 7 m × 6 m), a third of them within loop closure's; a stop brings back at most the
    // closure's candidates, the moved nodes it fuses again and its recent nodes.
    let bound = growth.closure_candidate_nodes + growth.refuse_per_stop + recent;
    assert!(
        most_fetched <= bound,
        "a stop brought back {most_fetched} nodes (bound {bound})"
    );
    assert!(
        *store.fetches.lock().unwrap() > 0,
        "no node was brought back"
    );
    // The bound leaves the loops closing.
    assert!(
        closed_in_last_lap >= 3,
        "{closed_in_last_lap} closures in the last lap"
    );
}
