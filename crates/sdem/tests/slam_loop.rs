use sdem::doubt::Doubt;
use sdem::geometry::{pose_from_parts, Attitude, Pose, Vec3};
use sdem::map::{verify_loop_closure, LoopClosure, Map, Node};
use sdem::sensor::SensorConfig;
use sdem::slam::*;
use sdem_sim::odometry::{simulate_odometry, OdometryNoise};
use sdem_sim::sim;
use std::sync::OnceLock;

/// The loop of the simulated collapsed building (stops i..=j of the 40-stop route, where
/// stop j stands where stop i stood), 5 mm range noise, compass noise 2°, odometry 5 % and
/// 0.5° per step, mapped once and shared by the tests below.
struct LoopRun {
    slam: Slam,
    truth: Vec<Pose>,
    steps: Vec<StepReport>,
}

fn loop_run() -> &'static LoopRun {
    static RUN: OnceLock<LoopRun> = OnceLock::new();
    RUN.get_or_init(|| {
        let seed = 1;
        let scene = sim::collapsed_building(seed);
        let sensor = SensorConfig {
            compass_noise_deg: 2.0,
            ..Default::default()
        };
        let stops =
            sim::collapsed_building_stops(&scene, seed, sim::MAX_STOPS, &sensor.lift).unwrap();
        let (i, j) = scene.loop_closure_stops().unwrap();
        let run = sim::simulate_run(&scene, &stops[i..=j], &sensor, seed).unwrap();
        let truth: Vec<Pose> = run.iter().map(|s| s.world_from_sensor).collect();
        let odometry = simulate_odometry(&truth, &OdometryNoise::default(), seed).unwrap();
        let mut slam = Slam::new(SlamOptions::default()).unwrap();
        let steps = run
            .iter()
            .enumerate()
            .map(|(k, stop)| {
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
                .unwrap()
            })
            .collect();
        LoopRun { slam, truth, steps }
    })
}

#[test]
fn the_simulated_loop_is_closed_and_the_map_stays_within_2_cm() {
    let run = loop_run();
    assert!(run.truth.len() >= 20, "a loop of {} stops", run.truth.len());
    let accepted: Vec<&LoopClosure> = run
        .steps
        .iter()
        .flat_map(|s| &s.loop_closures)
        .filter(|c| c.accepted)
        .collect();
    let last = run.truth.len() - 1;
    assert!(
        accepted.iter().any(|c| c.to == last && c.from <= 2),
        "the return to the loop's start was not closed: {:?}",
        run.steps
            .iter()
            .flat_map(|s| &s.loop_closures)
            .collect::<Vec<_>>()
    );
    assert!(run.steps.iter().any(|s| s.optimization.is_some()));
    let errors = trajectory_errors(&run.slam.poses(), &run.truth).unwrap();
    assert!(
        errors.ate_rmse_m <= 0.02,
        "ATE RMSE {} m",
        errors.ate_rmse_m
    );
    // Every step's own match is good too.
    assert!(errors.rpe_translation_rmse_m <= 0.01, "{errors:?}");
}

#[test]
fn a_wrong_loop_closure_proposed_on_purpose_is_rejected() {
    let run = loop_run();
    let map = &run.slam.map;
    // Claim that the node on the far side of the loop (about 2 m away) stands where node 0
    // stood.
    let far = map.nodes.len() / 2;
    let claimed = map.nodes[0].world_from_sensor;
    let closure = verify_loop_closure(
        map,
        0,
        far,
        &claimed,
        &run.slam.config().sdem,
        &run.slam.config().localize,
        &run.slam.config().loop_closure,
    )
    .unwrap();
    assert!(!closure.accepted, "accepted a wrong closure: {closure:?}");
    assert!(!closure.reason.is_empty());
    // The true revisit, with the same prior, is accepted.
    let last = map.nodes.len() - 1;
    let closure = verify_loop_closure(
        map,
        0,
        last,
        &map.nodes[last].world_from_sensor,
        &run.slam.config().sdem,
        &run.slam.config().localize,
        &run.slam.config().loop_closure,
    )
    .unwrap();
    assert!(closure.accepted, "{closure:?}");
}

#[test]
fn the_fused_map_holds_the_scene_and_free_space() {
    let run = loop_run();
    let (occupied, free) = run.slam.voxels.counts();
    assert!(
        occupied > 1000 && free > occupied,
        "{occupied} occupied, {free} free"
    );
    // Every sensor origin stood in free space.
    for node in &run.slam.map.nodes {
        assert_eq!(
            run.slam.voxels.occupancy(&node.position()),
            sdem::voxel::Occupancy::Free,
            "node {}",
            node.node_id
        );
    }
    let cloud = run.slam.merged_cloud();
    assert!(cloud.len() > 1000 && cloud.len() <= occupied);
}

#[test]
fn trajectory_errors_ignore_a_rigid_offset_and_see_a_bent_path() {
    let path: Vec<Pose> = (0..10)
        .map(|i| {
            pose_from_parts(
                Vec3::new(0.3 * i as f64, 0.05 * i as f64, 0.0),
                Attitude::default(),
            )
        })
        .collect();
    let offset = pose_from_parts(
        Vec3::new(1.0, -2.0, 0.5),
        Attitude::from_degrees(0.0, 0.0, 30.0),
    );
    let moved: Vec<Pose> = path.iter().map(|p| offset * p).collect();
    let e = trajectory_errors(&moved, &path).unwrap();
    assert!(
        e.ate_rmse_m < 1e-9 && e.rpe_translation_rmse_m < 1e-9,
        "{e:?}"
    );
    assert!(e.unaligned_rmse_m > 1.0);
    let mut bent = path.clone();
    bent[9] = pose_from_parts(
        bent[9].translation.vector + Vec3::new(0.0, 0.1, 0.0),
        Attitude::default(),
    );
    let e = trajectory_errors(&bent, &path).unwrap();
    assert!(e.ate_max_m > 0.05 && e.ate_max_m < 0.1, "{e:?}");
    assert!(trajectory_errors(&bent[..3], &path).is_err());
}

#[test]
fn scans_out_of_order_and_empty_scans_are_errors() {
    let mut slam = Slam::new(SlamOptions::default()).unwrap();
    let points: Vec<Vec3> = (0..2000)
        .map(|k| {
            let a = k as f64 * 0.01;
            Vec3::new(2.0 * a.cos(), 2.0 * a.sin(), -0.3 + 0.0003 * k as f64)
        })
        .collect();
    let scan = |i, p: &'static [Vec3]| ScanInput {
        scan_index: i,
        points_in_sensor: p,
        attitude: None,
        odometry: None,
    };
    let leaked: &'static [Vec3] = Box::leak(points.into_boxed_slice());
    slam.add_scan(&scan(3, leaked)).unwrap();
    let err = slam.add_scan(&scan(3, leaked)).unwrap_err().to_string();
    assert!(err.contains("in order"), "{err}");
    let err = slam.add_scan(&scan(4, &[])).unwrap_err().to_string();
    assert!(err.contains("no usable point"), "{err}");
    assert_eq!(
        slam.map.nodes.len(),
        1,
        "a failed step leaves the map as it was"
    );
}

/// A forward-looking scan in a straight corridor says nothing of the motion along it: the
/// match's position there is the sampling's (it came out 20 % short at every step, 1.0 m
/// short after 5.5 m). The loop takes the odometry's position along the flat direction and
/// the scans' across it.
#[test]
fn along_a_featureless_corridor_the_odometry_decides() {
    use rand::SeedableRng;
    let scene = sim::corridor(40.0).unwrap();
    let sensor = SensorConfig::default();
    let truth: Vec<Pose> = (0..6)
        .map(|i| {
            pose_from_parts(
                Vec3::new(-5.0 + 0.5 * i as f64, 0.02 * (i % 3) as f64, 0.0),
                Attitude::default(),
            )
        })
        .collect();
    let odometry = simulate_odometry(&truth, &OdometryNoise::default(), 7).unwrap();
    let mut slam = Slam::new(SlamOptions::default()).unwrap();
    let mut fused = 0;
    for (i, pose) in truth.iter().enumerate() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(100 + i as u64);
        let sweep = sim::scan(&scene, &sensor, pose, 0.0, &mut rng);
        let report = slam
            .add_scan(&ScanInput {
                scan_index: i,
                points_in_sensor: &sweep.points_in_sensor(),
                attitude: Some(sweep.mean_attitude()),
                odometry: (i > 0).then(|| Odometry {
                    odom_from_sensor: odometry[i],
                    odom_from_previous_sensor: odometry[i - 1],
                }),
            })
            .unwrap();
        fused += usize::from(report.doubts.iter().any(taken_from_prediction));
    }
    assert_eq!(fused, 5, "every step after the first is along the corridor");
    let estimate = slam.poses();
    let travelled = |poses: &[Pose]| poses[5].translation.vector - poses[0].translation.vector;
    let (e, t, o) = (
        travelled(&estimate),
        travelled(&truth),
        travelled(&odometry),
    );
    // Along: the odometry's travel (5 % noise); across: the scans' (5 mm over the 5 steps
    // when written; the flat direction leans up to 1 % out of the corridor's axis).
    assert!(
        (e.x - o.x).abs() < 0.01,
        "along: {} m, odometry {} m",
        e.x,
        o.x
    );
    assert!((e.x - t.x).abs() < 0.1, "along: {} m, truth {} m", e.x, t.x);
    assert!(
        (e.y - t.y).abs() < 0.01 && (e.z - t.z).abs() < 0.01,
        "across: {e:?} against {t:?}"
    );
}

/// Relocalized in a corridor with a prediction, the position along the corridor is the
/// prediction's and across it the scan's; with a rough position only, the match is flagged;
/// a σ that is no length is refused.
#[test]
fn a_relocalization_with_a_prediction_takes_it_along_a_corridor() {
    use rand::SeedableRng;
    let scene = sim::corridor(40.0).unwrap();
    let sensor = SensorConfig::default();
    let config = SlamOptions::default();
    let scan = |pose: &Pose, seed| {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        sim::scan(&scene, &sensor, pose, 0.0, &mut rng).points_in_sensor()
    };
    let origin = Pose::identity();
    let node = Node::from_scan(0, 0, origin, None, &scan(&origin, 1), &config.sdem).unwrap();
    let map = Map { nodes: vec![node] };
    let truth = pose_from_parts(Vec3::new(0.3, 0.05, 0.0), Attitude::default());
    let points = scan(&truth, 2);
    let level = Some(Attitude::default());
    let relocalized = |near: Near| {
        let found = relocalize(&map, &config, &points, level, Some(near), 1).unwrap();
        let pose = Pose::from(&found.world_from_sensor);
        (pose.translation.vector, found.diagnostics, found.doubts)
    };
    // A prediction 4 cm ahead of the truth along the corridor.
    let predicted = truth.translation.vector + Vec3::new(0.04, 0.0, 0.0);
    let (at, _, doubts) = relocalized(Near {
        position: predicted,
        sigma_m: Some(0.05),
    });
    assert!((at.x - predicted.x).abs() < 0.002, "along: {at:?}");
    let across = (at - truth.translation.vector).yz();
    assert!(across.norm() < 0.01, "across: {at:?}");
    assert!(doubts.iter().any(taken_from_prediction), "{doubts:?}");
    // Only a rough position: the match's own (14 cm short when written, the grid's, the
    // refinement refusing to follow it), flagged; nothing taken from the rough position.
    let (at, diagnostics, doubts) = relocalized(Near {
        position: predicted,
        sigma_m: None,
    });
    assert!(diagnostics.ambiguous, "{at:?} {diagnostics:?}");
    assert!(!doubts.iter().any(taken_from_prediction), "{doubts:?}");
    for sigma_m in [0.0, -1.0, f64::NAN] {
        let bad = relocalize(
            &map,
            &config,
            &points,
            level,
            Some(Near {
                position: predicted,
                sigma_m: Some(sigma_m),
            }),
            1,
        );
        assert!(bad.is_err(), "σ {sigma_m} accepted");
    }
}

/// The doubt a step carries when the prediction, not the scans, set its position along a free
/// direction.
fn taken_from_prediction(doubt: &Doubt) -> bool {
    matches!(doubt, Doubt::TakenFromPrediction { .. })
}
