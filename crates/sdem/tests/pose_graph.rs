use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3, Vector6};
use sdem::error::Error;
use sdem::geometry::pose_error;
use sdem::geometry::Pose;
use sdem::posegraph::*;
use sdem_sim::pose_graphs::{synthetic_loop, SyntheticLoopConfig};

/// A drifting gyro: 0.1°/m of yaw bias (5° around a 100-node loop) under 0.1° of noise per
/// step. One loop closure can undo the bias, not the random walk, so the ATE after
/// optimization stays near 0.1 m.
fn drifting() -> SyntheticLoopConfig {
    SyntheticLoopConfig {
        odometry_sigma_m: 0.01,
        odometry_sigma_deg: 0.1,
        odometry_yaw_bias_deg_per_m: 0.1,
        ..Default::default()
    }
}

fn rotation_rmse_deg(truth: &[Pose], estimate: &[Pose]) -> f64 {
    let sum: f64 = truth
        .iter()
        .zip(estimate)
        .map(|(t, e)| pose_error(t, e).1.powi(2))
        .sum();
    (sum / truth.len() as f64).sqrt().to_degrees()
}

#[test]
fn log_inverts_the_exponential() {
    // The SE(3) exponential: t = V(ω) ρ.
    for (rho, omega) in [
        (Vector3::new(0.3, -0.2, 1.0), Vector3::new(0.1, 0.4, -0.7)),
        (Vector3::new(1.0, 2.0, 3.0), Vector3::new(1e-5, 0.0, 2e-5)),
        (Vector3::new(-1.0, 0.5, 0.0), Vector3::new(0.0, 0.0, 3.0)),
    ] {
        let theta: f64 = omega.norm();
        let w = omega.cross_matrix();
        let v = nalgebra::Matrix3::identity()
            + (1.0 - theta.cos()) / theta.powi(2) * w
            + (theta - theta.sin()) / theta.powi(3) * w * w;
        let pose = Isometry3::from_parts((v * rho).into(), UnitQuaternion::from_scaled_axis(omega));
        let log = se3_log(&pose);
        let expected = Vector6::new(rho.x, rho.y, rho.z, omega.x, omega.y, omega.z);
        assert!((log - expected).amax() < 1e-9, "{log} vs {expected}");
    }
}

#[test]
fn noise_free_graph_is_a_fixed_point() {
    let (mut graph, truth) = synthetic_loop(50, 1, &SyntheticLoopConfig::default());
    for edge in &mut graph.edges {
        edge.from_from_to = truth[edge.from].inverse() * truth[edge.to];
    }
    graph.world_from_node = truth.clone();
    let (world_from_node, report) = optimize(&graph, 0, &OptimizeConfig::default()).unwrap();
    assert!(report.converged);
    assert!(report.initial_cost < 1e-12, "{}", report.initial_cost);
    assert!(report.final_cost <= report.initial_cost);
    for (t, e) in truth.iter().zip(&world_from_node) {
        let (dt, dr) = pose_error(t, e);
        assert!(dt < 1e-9 && dr < 1e-9, "moved by {dt} m, {dr} rad");
    }
    assert!(report.edge_weights.iter().all(|&w| w > 1.0 - 1e-9));
}

#[test]
fn drifting_loop_is_closed() {
    let (graph, truth) = synthetic_loop(100, 2, &drifting());
    let before = position_rmse(&truth, &graph.world_from_node).unwrap();
    let (world_from_node, report) = optimize(&graph, 0, &OptimizeConfig::default()).unwrap();
    let after = position_rmse(&truth, &world_from_node).unwrap();
    let rotation_after = rotation_rmse_deg(&truth, &world_from_node);
    eprintln!(
        "ATE {before:.3} m -> {after:.3} m, rotation {:.3}° -> {rotation_after:.3}°, {} \
         iterations, cost {:.1} -> {:.1}",
        rotation_rmse_deg(&truth, &graph.world_from_node),
        report.iterations,
        report.initial_cost,
        report.final_cost
    );
    assert!(report.converged);
    assert!(report.final_cost < report.initial_cost);
    assert!(before > 0.3, "the input should drift, ATE {before} m");
    assert!(after < before / 4.0, "ATE {before} m -> {after} m");
    assert!(after < 0.15, "ATE {after} m");
    assert!(rotation_after < 1.0, "rotation RMSE {rotation_after}°");
    // Consistent edges keep most of their weight.
    let mean_weight = report.edge_weights.iter().sum::<f64>() / report.edge_weights.len() as f64;
    assert!(mean_weight > 0.6, "mean weight {mean_weight}");
}

#[test]
fn wrong_loop_closure_is_down_weighted() {
    let config = drifting();
    let (mut graph, truth) = synthetic_loop(100, 5, &config);
    let (reference, _) = optimize(&graph, 0, &OptimizeConfig::default()).unwrap();
    let reference_ate = position_rmse(&truth, &reference).unwrap();
    // A false match 11 stops apart that claims an offset 2 m off the truth.
    let (from, to) = (5, 90);
    let true_from_to = truth[from].inverse() * truth[to];
    graph.edges.push(Edge {
        from,
        to,
        from_from_to: Translation3::new(2.0, 0.0, 0.0) * true_from_to,
        information: diagonal_information(
            config.loop_closure_sigma_m,
            config.loop_closure_sigma_deg.to_radians(),
        ),
        kind: EdgeKind::LoopClosure,
    });
    let wrong = graph.edges.len() - 1;
    let (world_from_node, report) = optimize(&graph, 0, &OptimizeConfig::default()).unwrap();
    let after = position_rmse(&truth, &world_from_node).unwrap();
    let weights: Vec<f64> = graph
        .edges
        .iter()
        .zip(&report.edge_weights)
        .filter(|(e, _)| e.kind == EdgeKind::LoopClosure)
        .map(|(_, &w)| w)
        .collect();
    eprintln!(
        "ATE {:.3} m -> {after:.3} m (good closures only {reference_ate:.3} m), loop-closure \
         weights {weights:?}",
        position_rmse(&truth, &graph.world_from_node).unwrap()
    );
    assert!(report.converged);
    assert!(
        report.edge_weights[wrong] < 0.05,
        "{}",
        report.edge_weights[wrong]
    );
    assert!(
        weights[..weights.len() - 1].iter().all(|&w| w > 0.3),
        "{weights:?}"
    );
    assert!(
        after < reference_ate + 0.03,
        "ATE {after} m vs {reference_ate} m"
    );

    // Without the kernel the wrong edge drags the trajectory.
    let plain = OptimizeConfig {
        robust_kernel_width: f64::INFINITY,
        ..Default::default()
    };
    let (dragged, _) = optimize(&graph, 0, &plain).unwrap();
    let dragged_ate = position_rmse(&truth, &dragged).unwrap();
    assert!(dragged_ate > after + 0.1, "{dragged_ate} m vs {after} m");
}

#[test]
fn gauge_node_does_not_move() {
    let (graph, truth) = synthetic_loop(60, 3, &drifting());
    let fixed = 30;
    let (world_from_node, report) = optimize(&graph, fixed, &OptimizeConfig::default()).unwrap();
    assert!(report.iterations > 0);
    assert_eq!(world_from_node[fixed], graph.world_from_node[fixed]);
    // The other nodes move, and relative to the gauge the shape gets closer to the truth.
    assert_ne!(world_from_node[0], graph.world_from_node[0]);
    let aligned = |poses: &[Pose]| -> Vec<Pose> {
        let correction = truth[fixed] * poses[fixed].inverse();
        poses.iter().map(|p| correction * p).collect()
    };
    let before = position_rmse(&truth, &aligned(&graph.world_from_node)).unwrap();
    let after = position_rmse(&truth, &aligned(&world_from_node)).unwrap();
    assert!(after < before / 2.0, "{before} m -> {after} m");
}

#[test]
fn zero_iterations_return_the_input() {
    let (graph, _) = synthetic_loop(20, 2, &SyntheticLoopConfig::default());
    let config = OptimizeConfig {
        max_iterations: 0,
        ..Default::default()
    };
    let (world_from_node, report) = optimize(&graph, 0, &config).unwrap();
    assert_eq!(world_from_node, graph.world_from_node);
    assert_eq!(report.iterations, 0);
    assert!(!report.converged);
    assert_eq!(report.initial_cost, report.final_cost);
}

#[test]
fn single_node_graph_is_trivially_optimal() {
    let graph = PoseGraph {
        world_from_node: vec![Pose::identity()],
        edges: vec![],
    };
    let (world_from_node, report) = optimize(&graph, 0, &OptimizeConfig::default()).unwrap();
    assert_eq!(world_from_node, graph.world_from_node);
    assert!(report.converged);
}

fn expect_invalid(graph: &PoseGraph, fixed: usize, config: &OptimizeConfig, needle: &str) {
    match optimize(graph, fixed, config) {
        Err(Error::Invalid(message)) => {
            assert!(
                message.contains(needle),
                "{message:?} should mention {needle:?}"
            )
        }
        other => panic!("expected an Invalid error about {needle:?}, got {other:?}"),
    }
}

#[test]
fn invalid_inputs_are_errors() {
    let (graph, _) = synthetic_loop(10, 4, &SyntheticLoopConfig::default());
    let config = OptimizeConfig::default();
    expect_invalid(&graph, 10, &config, "fixed node 10 does not exist");
    expect_invalid(&PoseGraph::default(), 0, &config, "has 0 nodes");

    let mut missing = graph.clone();
    missing.edges[0].to = 12;
    expect_invalid(&missing, 0, &config, "references node 12");

    let mut itself = graph.clone();
    itself.edges[0].to = itself.edges[0].from;
    expect_invalid(&itself, 0, &config, "to itself");

    let mut nan = graph.clone();
    nan.edges[2].information[1][1] = f64::NAN;
    expect_invalid(&nan, 0, &config, "non-finite information");

    let mut asymmetric = graph.clone();
    asymmetric.edges[2].information[0][1] = 5.0;
    expect_invalid(&asymmetric, 0, &config, "non-symmetric");

    let mut indefinite = graph.clone();
    indefinite.edges[3].information[4][4] = -1.0;
    expect_invalid(&indefinite, 0, &config, "not positive semi-definite");

    let mut bad_measurement = graph.clone();
    bad_measurement.edges[1].from_from_to.translation.x = f64::INFINITY;
    expect_invalid(&bad_measurement, 0, &config, "non-finite measurement");

    let mut bad_pose = graph.clone();
    bad_pose.world_from_node[4].translation.y = f64::NAN;
    expect_invalid(&bad_pose, 0, &config, "node 4's pose");

    let mut disconnected = graph.clone();
    disconnected.world_from_node.push(Pose::identity());
    expect_invalid(&disconnected, 0, &config, "node 10 is not connected");

    for width in [0.0, -1.0, f64::NAN] {
        let bad = OptimizeConfig {
            robust_kernel_width: width,
            ..Default::default()
        };
        expect_invalid(&graph, 0, &bad, "robust_kernel_width");
    }
    let bad = OptimizeConfig {
        tolerance: f64::NAN,
        ..Default::default()
    };
    expect_invalid(&graph, 0, &bad, "tolerance");
}

#[test]
fn synthetic_loop_is_reproducible_and_small_sizes_do_not_panic() {
    let config = SyntheticLoopConfig::default();
    assert_eq!(
        synthetic_loop(30, 9, &config),
        synthetic_loop(30, 9, &config)
    );
    for nodes in 0..5 {
        let (graph, truth) = synthetic_loop(nodes, 9, &config);
        assert_eq!(graph.world_from_node.len(), nodes);
        assert_eq!(truth.len(), nodes);
        if nodes > 0 {
            optimize(&graph, 0, &OptimizeConfig::default()).unwrap();
        }
    }
}

#[test]
fn config_round_trips_through_toml() {
    let config = OptimizeConfig::default();
    let text = toml::to_string(&config).unwrap();
    assert_eq!(toml::from_str::<OptimizeConfig>(&text).unwrap(), config);
    let partial: OptimizeConfig = toml::from_str("max_iterations = 5").unwrap();
    assert_eq!(partial.max_iterations, 5);
    assert_eq!(partial.robust_kernel_width, 3.55);
    assert_eq!(
        serde_json::to_string(&EdgeKind::LoopClosure).unwrap(),
        "\"loop_closure\""
    );
}
