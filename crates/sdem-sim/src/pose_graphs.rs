//! Synthetic pose graphs with truth: a seeded, drifting loop for the pose graph's tests and
//! benchmarks (`sdem bench`, `benches/posegraph.rs` in `sdem`).

use nalgebra::{Isometry3, UnitQuaternion, Vector3, Vector6};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use sdem::error::Result;
use sdem::geometry::Pose;
use sdem::posegraph::{
    diagonal_information, optimize, position_rmse, se3_exp, Edge, EdgeKind, OptimizeConfig,
    OptimizeReport, PoseGraph,
};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::time::Instant;

/// The trajectory and noise of [`synthetic_loop`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SyntheticLoopConfig {
    /// Distance between stops along the loop, metres. Default 0.5; the loop's radius follows
    /// from it: `nodes · step / 2π`.
    pub step_m: f64,
    /// Odometry noise, per translation axis, metres. Default 0.01.
    pub odometry_sigma_m: f64,
    /// Odometry noise, per rotation axis, degrees. Default 0.05.
    pub odometry_sigma_deg: f64,
    /// Unmodelled odometry yaw bias (a drifting gyro), degrees per metre driven. Default 0.02:
    /// a fifth of the rotation noise per 0.5 m step, 10° over the 500 m of the 1,000-node
    /// benchmark loop. Keep it under the noise per step: the odometry information does not know about
    /// it, and a bias far above the noise makes the loop closures look like the outliers.
    pub odometry_yaw_bias_deg_per_m: f64,
    /// Loop-closure edges between the last nodes and the first ones. Default 3.
    pub loop_closures: usize,
    /// Loop-closure noise, per translation axis, metres. Default 0.05.
    pub loop_closure_sigma_m: f64,
    /// Loop-closure noise, per rotation axis, degrees. Default 0.5.
    pub loop_closure_sigma_deg: f64,
}

impl Default for SyntheticLoopConfig {
    fn default() -> Self {
        Self {
            step_m: 0.5,
            odometry_sigma_m: 0.01,
            odometry_sigma_deg: 0.05,
            odometry_yaw_bias_deg_per_m: 0.02,
            loop_closures: 3,
            loop_closure_sigma_m: 0.05,
            loop_closure_sigma_deg: 0.5,
        }
    }
}

/// A seeded loop for tests and benchmarks: the robot drives once around a hilly circle,
/// rolling and pitching a little, and comes back near its start.
///
/// # Arguments
/// * `nodes` — stops on the loop.
/// * `seed` — the noise (ChaCha8: the same graph on every machine).
/// * `config` — step length and noise.
///
/// # Returns
/// The graph and the true `world_from_node`. The graph's poses are dead reckoning (the noisy,
/// yaw-biased odometry chained from the true first pose), so they drift; its edges are the
/// odometry `k → k+1` (information from the noise only: the bias is unmodelled, as in a real
/// robot) and `config.loop_closures` closures `m → nodes−1−m` (those that do not repeat an
/// odometry edge), each measurement the truth times Gaussian noise on the right, with the matching
/// diagonal information.
pub fn synthetic_loop(
    nodes: usize,
    seed: u64,
    config: &SyntheticLoopConfig,
) -> (PoseGraph, Vec<Pose>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let radius = nodes as f64 * config.step_m / TAU;
    let truth: Vec<Pose> = (0..nodes)
        .map(|k| {
            let phi = TAU * k as f64 / nodes.max(1) as f64;
            let position = Vector3::new(
                radius * phi.sin(),
                radius * (1.0 - phi.cos()),
                0.5 * (3.0 * phi).sin(),
            );
            let rotation = UnitQuaternion::from_euler_angles(
                0.05 * (5.0 * phi).sin(),
                0.04 * (7.0 * phi).cos(),
                phi,
            );
            Isometry3::from_parts(position.into(), rotation)
        })
        .collect();
    let mut noisy = |sigma_m: f64, sigma_rad: f64| {
        let mut delta = Vector6::zeros();
        for k in 0..6 {
            let normal: f64 = StandardNormal.sample(&mut rng);
            delta[k] = normal * if k < 3 { sigma_m } else { sigma_rad };
        }
        se3_exp(&delta)
    };
    let odometry_rad = config.odometry_sigma_deg.to_radians();
    let yaw_bias_rad_per_m = config.odometry_yaw_bias_deg_per_m.to_radians();
    let closure_rad = config.loop_closure_sigma_deg.to_radians();
    let mut graph = PoseGraph::default();
    // Noise-free graphs get a finite information (σ floored at 1e-6).
    let odometry_information =
        diagonal_information(config.odometry_sigma_m.max(1e-6), odometry_rad.max(1e-6));
    for k in 0..nodes {
        if k == 0 {
            graph.world_from_node.push(truth[0]);
            continue;
        }
        let true_from_to = truth[k - 1].inverse() * truth[k];
        let bias = UnitQuaternion::from_axis_angle(
            &Vector3::z_axis(),
            yaw_bias_rad_per_m * true_from_to.translation.vector.norm(),
        );
        let from_from_to = true_from_to * noisy(config.odometry_sigma_m, odometry_rad) * bias;
        let world_from_node = graph.world_from_node[k - 1] * from_from_to;
        graph.world_from_node.push(world_from_node);
        graph.edges.push(Edge {
            from: k - 1,
            to: k,
            from_from_to,
            information: odometry_information,
            kind: EdgeKind::Odometry,
        });
    }
    let closure_information =
        diagonal_information(config.loop_closure_sigma_m.max(1e-6), closure_rad.max(1e-6));
    for m in 0..config.loop_closures {
        let (from, to) = (m, nodes.saturating_sub(1 + m));
        if to <= from + 1 {
            break;
        }
        graph.edges.push(Edge {
            from,
            to,
            from_from_to: truth[from].inverse()
                * truth[to]
                * noisy(config.loop_closure_sigma_m, closure_rad),
            information: closure_information,
            kind: EdgeKind::LoopClosure,
        });
    }
    (graph, truth)
}

/// Nodes of the benchmark loop ([`bench_1000_nodes`], `benches/posegraph.rs`).
pub const BENCH_NODES: usize = 1000;
/// Seed of the benchmark loop.
pub const BENCH_SEED: u64 = 2003;

/// One timed optimization of the benchmark loop, for `sdem bench`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PoseGraphBench {
    /// Nodes in the graph.
    pub nodes: usize,
    /// Edges in the graph.
    pub edges: usize,
    /// Wall time of [`optimize`], milliseconds.
    pub time_ms: f64,
    /// Position RMSE of the dead-reckoning input against the truth, metres.
    pub ate_before_m: f64,
    /// Position RMSE of the optimized poses against the truth, metres.
    pub ate_after_m: f64,
    /// What the optimizer reported.
    pub report: OptimizeReport,
}

/// Optimizes the [`BENCH_NODES`]-node synthetic loop ([`BENCH_SEED`], default noise and
/// settings) once and times it.
///
/// # Returns
/// Time, accuracy before and after, and the optimizer's report.
pub fn bench_1000_nodes() -> Result<PoseGraphBench> {
    let (graph, truth) = synthetic_loop(BENCH_NODES, BENCH_SEED, &SyntheticLoopConfig::default());
    let start = Instant::now();
    let (world_from_node, report) = optimize(&graph, 0, &OptimizeConfig::default())?;
    let time_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok(PoseGraphBench {
        nodes: graph.world_from_node.len(),
        edges: graph.edges.len(),
        time_ms,
        ate_before_m: position_rmse(&truth, &graph.world_from_node)?,
        ate_after_m: position_rmse(&truth, &world_from_node)?,
        report,
    })
}
