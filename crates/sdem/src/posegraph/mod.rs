//! Robust SE(3) pose-graph optimization, for loop closure.
//!
//! The map's nodes are sensor poses `world_from_node`; each [`Edge`] is a measured relative pose
//! `from_from_to` (an odometry step, or a scan match that closes a loop) weighted by its
//! information matrix, the inverse of the match covariance. [`optimize`] finds the poses that
//! best agree with all edges, with one node held fixed (the gauge), and down-weights edges that
//! disagree with the rest (a wrong loop closure) with a Cauchy kernel.
//!
//! # Conventions
//! - **Residual** of an edge `from → to` (`i → j`), in the `to` node's frame:
//!   `r = Log(from_from_to⁻¹ · world_from_from⁻¹ · world_from_to) ∈ R⁶`, ordered
//!   `[tx, ty, tz, rx, ry, rz]`: translation first, rotation vector second. `Log` is the SE(3)
//!   logarithm (`ρ = V(ω)⁻¹ t`, `ω` the rotation vector); for the small residuals of a converged
//!   graph `ρ ≈ t`. `r = 0` when the poses agree exactly with the measurement.
//! - **Information** `Ω` is the inverse covariance of that residual, same order, so a match
//!   covariance `Σ` over `[x, y, z, roll, pitch, yaw]`-like small perturbations in the `to`
//!   frame gives `Ω = Σ⁻¹`. The squared Mahalanobis norm of an edge is `s² = rᵀ Ω r`.
//! - **Cost** `F = Σₑ ρ(sₑ²)` with the Cauchy kernel `ρ(u) = c² ln(1 + u / c²)`, `c` =
//!   [`OptimizeConfig::robust_kernel_width`] (with `c = ∞`, plain least squares `F = Σ s²`).
//!   It is minimized by iteratively re-weighted least squares: each Gauss–Newton step weighs
//!   edge `e` by `wₑ = ρ'(sₑ²) = 1 / (1 + sₑ² / c²)` (1 = fully trusted), inside a
//!   Levenberg–Marquardt loop (Marquardt's diagonal scaling, Nielsen's damping update) that
//!   accepts a step only if the robust cost goes down.
//! - **Graduated non-convexity** ([`OptimizeConfig::graduated_kernel`]): the Cauchy cost is not
//!   convex, and from a drifted start the good loop closures are as far off as a wrong one, so
//!   a robust optimizer started at the target width can reject them all and keep the drift. The
//!   kernel therefore starts as wide as the input's largest Mahalanobis norm (plain least
//!   squares, in effect) and narrows 4× per stage to the target width, each stage starting from
//!   the previous one's poses (Black & Rangarajan 1996; Yang et al., RA-L 2020).
//! - **Updates** are applied on the right, in each node's own frame:
//!   `world_from_node ← world_from_node · Exp(δ)`, `δ = [t, ω]`, with `Exp(δ)` the translation
//!   `t` and the rotation `exp(ω)` (a retraction equal to the SE(3) exponential to first order).
//!   Jacobians are central differences of the residual with respect to `δ` (24 residual
//!   evaluations per edge), exact to ~1e-10 and simple to audit.
//!
//! # Sparse solver
//! The normal equations are solved with [`nalgebra_sparse`] 0.12 (the release built on
//! nalgebra 0.35, our version): its `CscCholesky` does the symbolic factorization once per
//! [`optimize`] call and only the numeric factorization per iteration. It does no fill-reducing
//! ordering, but the natural node order of a trajectory is already good: the odometry chain is a
//! block band, and a loop closure `i → j` only fills block column `j` from `i` to `j`, so a
//! 1,000-node loop with three closures factors in ~2 ms (about 40 % of the optimization time).
//! A crate of ~5k lines with no dependency beyond nalgebra and num-traits, it costs seconds of
//! build time; the SE(3) factor-graph crates pin an older nalgebra and take minutes (see
//! DESIGN.md). A hand-written block (6×6) Cholesky would be the next speed-up if needed.
//!
//! # Example
//! A square of four 1 m steps whose dead reckoning turned each corner 3° too far, closed by a
//! loop-closure edge from the last node back to the first (a larger, seeded loop with truth is
//! `sdem_sim::pose_graphs::synthetic_loop`).
//! ```
//! use nalgebra::{Isometry3, Vector3};
//! use sdem::posegraph::{diagonal_information, optimize, Edge, EdgeKind, OptimizeConfig, PoseGraph};
//! let step = |yaw_deg: f64| Isometry3::new(Vector3::x(), Vector3::z() * yaw_deg.to_radians());
//! let edge = |from, to, from_from_to, kind| Edge {
//!     from, to, from_from_to, kind, information: diagonal_information(0.01, 0.01),
//! };
//! // The odometry says 93° at each corner; the true square has 90°.
//! let mut graph = PoseGraph::default();
//! graph.world_from_node.push(Isometry3::identity());
//! for k in 0..4 {
//!     let last = graph.world_from_node[k];
//!     graph.world_from_node.push(last * step(93.0));
//!     graph.edges.push(edge(k, k + 1, step(93.0), EdgeKind::Odometry));
//! }
//! // Back at the start: node 4 is node 0, turned by a full square.
//! graph.edges.push(edge(4, 0, Isometry3::identity(), EdgeKind::LoopClosure));
//! let drift_before = graph.world_from_node[4].translation.vector.norm();
//! let (world_from_node, report) = optimize(&graph, 0, &OptimizeConfig::default())?;
//! assert!(report.converged);
//! let drift_after = world_from_node[4].translation.vector.norm();
//! assert!(drift_after < drift_before / 10.0, "{drift_before} m -> {drift_after} m");
//! # Ok::<(), sdem::Error>(())
//! ```

mod local;
mod solver;

pub use local::{optimize_local, LocalSolve};

use crate::error::{Error, Result};
use crate::geometry::Pose;
use nalgebra::{
    Isometry3, Matrix6, SymmetricEigen, Translation3, UnitQuaternion, Vector3, Vector6,
};
use serde::{Deserialize, Serialize};

/// What an edge's measurement comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EdgeKind {
    /// Consecutive stops: dead reckoning, or the scan match of a stop against the previous one.
    Odometry,
    /// A scan match against an older node: it closes a loop, and may be wrong.
    LoopClosure,
}

/// A measured relative pose between two nodes, with its information (inverse covariance).
#[derive(Debug, Clone, PartialEq)]
pub struct Edge {
    /// Index of the node the measurement is expressed from.
    pub from: usize,
    /// Index of the node measured.
    pub to: usize,
    /// The measured pose of `to` in the frame of `from`.
    pub from_from_to: Pose,
    /// Inverse covariance of the residual `[tx, ty, tz, rx, ry, rz]` (see the module
    /// documentation): symmetric, positive semi-definite, row-major.
    pub information: [[f64; 6]; 6],
    /// Odometry or loop closure.
    pub kind: EdgeKind,
}

/// A pose graph: node poses (the initial guess for [`optimize`]) and the edges between them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PoseGraph {
    /// The pose of each node's sensor in the world.
    pub world_from_node: Vec<Pose>,
    /// The measurements between nodes.
    pub edges: Vec<Edge>,
}

/// The settings of [`optimize`]. Missing fields in a TOML/JSON file take the defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OptimizeConfig {
    /// Most Levenberg–Marquardt iterations (linearizations). Default 100; a 1,000-node loop
    /// usually converges in 10–30.
    pub max_iterations: usize,
    /// Width `c` of the Cauchy kernel on the Mahalanobis norm `s` of each edge: an edge with
    /// `s = c` keeps half its weight. Default 3.55 ≈ √χ²₆(0.95), the norm a consistent 6-DoF
    /// edge stays under 95 % of the time. `f64::INFINITY` turns the kernel off (plain least
    /// squares). Must be positive.
    pub robust_kernel_width: f64,
    /// Convergence: stop when an accepted step lowers the cost by less than this fraction of it.
    /// Default 1e-6.
    pub tolerance: f64,
    /// Starting Levenberg–Marquardt damping, relative to the diagonal of the normal equations.
    /// Default 1e-4 (nearly Gauss–Newton).
    pub initial_damping: f64,
    /// Graduated non-convexity (default true): start with a kernel as wide as the largest
    /// Mahalanobis norm of the input, so that every edge is trusted, and narrow it by 4× per
    /// stage down to `robust_kernel_width`. Without it, loop closures far off in a drifted input
    /// look like outliers and the optimizer can keep the drift (a local minimum of the robust
    /// cost); with it, a wrong closure is still rejected once the good ones agree.
    pub graduated_kernel: bool,
}

impl Default for OptimizeConfig {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            robust_kernel_width: 3.55,
            tolerance: 1e-6,
            initial_damping: 1e-4,
            graduated_kernel: true,
        }
    }
}

impl OptimizeConfig {
    /// Checks that every setting is in its valid range.
    ///
    /// # Returns
    /// [`Error::Invalid`] naming the first bad setting and its valid range.
    pub fn validate(&self) -> Result<()> {
        if self.robust_kernel_width.is_nan() || self.robust_kernel_width <= 0.0 {
            return Err(Error::Invalid(format!(
                "pose graph: robust_kernel_width is {}, it must be positive (e.g. 3.55; \
                 inf turns the robust kernel off)",
                self.robust_kernel_width
            )));
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(Error::Invalid(format!(
                "pose graph: tolerance is {}, it must be a finite number >= 0 (e.g. 1e-6)",
                self.tolerance
            )));
        }
        if !(self.initial_damping.is_finite() && self.initial_damping > 0.0) {
            return Err(Error::Invalid(format!(
                "pose graph: initial_damping is {}, it must be finite and positive (e.g. 1e-4)",
                self.initial_damping
            )));
        }
        Ok(())
    }
}

/// What [`optimize`] did, with per-edge diagnostics in the order of [`PoseGraph::edges`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OptimizeReport {
    /// Linearizations done over all kernel stages (0 when the input was already optimal or
    /// `max_iterations` is 0).
    pub iterations: usize,
    /// Robust cost `Σ ρ(s²)` of the input poses.
    pub initial_cost: f64,
    /// Robust cost of the returned poses.
    pub final_cost: f64,
    /// Whether the last kernel stage met a stopping criterion before `max_iterations` ran out:
    /// the relative cost decrease fell under the tolerance, the cost is exact, or no step can
    /// lower it any more.
    pub converged: bool,
    /// Final robust weight of each edge, `1 / (1 + s² / c²)`: 1 = fully trusted, near 0 =
    /// rejected as an outlier.
    pub edge_weights: Vec<f64>,
    /// Final Mahalanobis norm `s = √(rᵀ Ω r)` of each edge.
    pub edge_mahalanobis: Vec<f64>,
    /// Kernel widths tried (1 without graduated non-convexity).
    pub kernel_stages: usize,
    /// The Levenberg–Marquardt damping at the end (relative to the diagonal).
    pub final_damping: f64,
}

/// A diagonal information matrix from standard deviations of translation (metres, each axis) and
/// rotation (radians, each axis).
///
/// # Returns
/// `diag(1/σₜ², 1/σₜ², 1/σₜ², 1/σᵣ², 1/σᵣ², 1/σᵣ²)`, in the residual order of [`Edge`].
pub fn diagonal_information(sigma_translation_m: f64, sigma_rotation_rad: f64) -> [[f64; 6]; 6] {
    let mut information = [[0.0; 6]; 6];
    for (k, row) in information.iter_mut().enumerate() {
        let sigma = if k < 3 {
            sigma_translation_m
        } else {
            sigma_rotation_rad
        };
        row[k] = 1.0 / (sigma * sigma);
    }
    information
}

/// The SE(3) logarithm `[ρ, ω]`, translation first: `ω` is the rotation vector and
/// `ρ = V(ω)⁻¹ t` with `V⁻¹ = I − ½[ω]× + (1 − θ sin θ / (2 (1 − cos θ))) / θ² [ω]×²`.
pub fn se3_log(pose: &Pose) -> Vector6<f64> {
    let omega = pose.rotation.scaled_axis();
    let t = pose.translation.vector;
    let theta = omega.norm();
    let c = if theta < 1e-3 {
        1.0 / 12.0 + theta * theta / 720.0
    } else {
        let half_sin = (0.5 * theta).sin();
        // 1 − cos θ = 2 sin²(θ/2), without cancellation.
        (1.0 - theta * theta.sin() / (4.0 * half_sin * half_sin)) / (theta * theta)
    };
    let omega_t = omega.cross(&t);
    let rho = t - 0.5 * omega_t + c * omega.cross(&omega_t);
    Vector6::new(rho.x, rho.y, rho.z, omega.x, omega.y, omega.z)
}

/// The update retraction, the inverse of [`se3_log`] near the identity: translation `δ[0..3]`,
/// then rotation `exp(δ[3..6])`.
pub fn se3_exp(delta: &Vector6<f64>) -> Pose {
    Isometry3::from_parts(
        Translation3::new(delta[0], delta[1], delta[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(delta[3], delta[4], delta[5])),
    )
}

/// The residual of an edge (see the module documentation) at the given poses.
///
/// # Arguments
/// * `edge` — the measurement.
/// * `world_from_from`, `world_from_to` — the poses of its two nodes.
pub fn edge_residual(edge: &Edge, world_from_from: &Pose, world_from_to: &Pose) -> Vector6<f64> {
    se3_log(&(edge.from_from_to.inverse() * world_from_from.inverse() * world_from_to))
}

/// Position root-mean-square error (metres) of `estimate` against `truth`, node by node, with no
/// alignment (both share the gauge node's pose).
///
/// # Errors
/// [`Error::Invalid`] when the two lists differ in length or are empty.
pub fn position_rmse(truth: &[Pose], estimate: &[Pose]) -> Result<f64> {
    let n = truth.len();
    if n != estimate.len() || n == 0 {
        return Err(Error::Invalid(format!(
            "cannot compare {} estimated positions with {} true ones",
            estimate.len(),
            n
        )));
    }
    let sum: f64 = truth
        .iter()
        .zip(estimate)
        .map(|(t, e)| (t.translation.vector - e.translation.vector).norm_squared())
        .sum();
    Ok((sum / n as f64).sqrt())
}

fn pose_is_valid(pose: &Pose) -> bool {
    let q = pose.rotation.quaternion();
    pose.translation.vector.iter().all(|v| v.is_finite())
        && q.coords.iter().all(|v| v.is_finite())
        && (q.norm() - 1.0).abs() < 1e-6
}

/// Checks the graph and the gauge node; see [`optimize`] for what is required.
fn validate(graph: &PoseGraph, fixed: &[usize]) -> Result<Vec<Matrix6<f64>>> {
    let nodes = graph.world_from_node.len();
    if fixed.is_empty() {
        return Err(Error::Invalid(
            "pose graph: no node is held fixed, so the poses are undetermined; hold one (usually \
             0, the first scan)"
                .into(),
        ));
    }
    if let Some(&fixed) = fixed.iter().find(|&&f| f >= nodes) {
        return Err(Error::Invalid(format!(
            "pose graph: the fixed node {fixed} does not exist, the graph has {nodes} nodes; \
             pass the index of an existing node (usually 0, the first scan)"
        )));
    }
    for (node, pose) in graph.world_from_node.iter().enumerate() {
        if !pose_is_valid(pose) {
            return Err(Error::Invalid(format!(
                "pose graph: node {node}'s pose {pose} is not finite or its rotation is not a \
                 unit quaternion; give every node a finite pose with a normalized rotation"
            )));
        }
    }
    let mut informations = Vec::with_capacity(graph.edges.len());
    for (k, edge) in graph.edges.iter().enumerate() {
        let (from, to) = (edge.from, edge.to);
        if from >= nodes || to >= nodes {
            return Err(Error::Invalid(format!(
                "pose graph: edge {k} ({from} -> {to}) references node {}, but the graph has \
                 {nodes} nodes (0..{nodes}); add the node's pose or drop the edge",
                if from >= nodes { from } else { to }
            )));
        }
        if from == to {
            return Err(Error::Invalid(format!(
                "pose graph: edge {k} connects node {from} to itself; an edge must join two \
                 different nodes"
            )));
        }
        if !pose_is_valid(&edge.from_from_to) {
            return Err(Error::Invalid(format!(
                "pose graph: edge {k} ({from} -> {to}) has a non-finite measurement or one whose \
                 rotation is not a unit quaternion; check the scan match that produced it"
            )));
        }
        let information = Matrix6::from_fn(|r, c| edge.information[r][c]);
        if information.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "pose graph: edge {k} ({from} -> {to}) has a non-finite information matrix; \
                 give the inverse of a finite, positive-definite covariance"
            )));
        }
        let scale = information.amax().max(f64::MIN_POSITIVE);
        let asymmetry = (information - information.transpose()).amax();
        if asymmetry > 1e-9 * scale {
            return Err(Error::Invalid(format!(
                "pose graph: edge {k} ({from} -> {to}) has a non-symmetric information matrix \
                 (entries differ from their transposes by up to {asymmetry:e}); symmetrize it, \
                 e.g. (Ω + Ωᵀ) / 2"
            )));
        }
        let eigen = SymmetricEigen::try_new(information, 1e-14 * scale, 1000).ok_or_else(|| {
            Error::Invalid(format!(
                "pose graph: edge {k} ({from} -> {to}): the eigenvalues of its information \
                 matrix could not be computed; check its entries"
            ))
        })?;
        let smallest = eigen.eigenvalues.min();
        if smallest < -1e-9 * scale {
            return Err(Error::Invalid(format!(
                "pose graph: edge {k} ({from} -> {to}) has an information matrix that is not \
                 positive semi-definite (smallest eigenvalue {smallest:e}); it must be the \
                 inverse of a covariance"
            )));
        }
        informations.push(information);
    }
    // Every node must be tied to the gauge, or its pose is undetermined.
    let mut parent: Vec<usize> = (0..nodes).collect();
    fn root(parent: &mut [usize], mut node: usize) -> usize {
        while parent[node] != node {
            parent[node] = parent[parent[node]];
            node = parent[node];
        }
        node
    }
    for edge in &graph.edges {
        let (a, b) = (root(&mut parent, edge.from), root(&mut parent, edge.to));
        parent[a] = b;
    }
    let mut anchored = vec![false; nodes];
    for &f in fixed {
        let r = root(&mut parent, f);
        anchored[r] = true;
    }
    if let Some(node) = (0..nodes).find(|&node| !anchored[root(&mut parent, node)]) {
        let held = match fixed {
            [one] => format!("the fixed node {one}"),
            _ => "a fixed node".to_string(),
        };
        return Err(Error::Invalid(format!(
            "pose graph: node {node} is not connected to {held} by any chain of edges, so its \
             pose is undetermined; add an odometry edge to it or remove it"
        )));
    }
    Ok(informations)
}

/// Optimizes the node poses of a pose graph, holding one node fixed.
///
/// Levenberg–Marquardt over SE(3) with a Cauchy kernel applied by iteratively re-weighted least
/// squares, from the poses in `graph` (see the module documentation for the residual, the cost
/// and the solver).
///
/// # Arguments
/// * `graph` — initial poses and edges. Every edge must join two different existing nodes, with
///   a finite measurement and a finite, symmetric, positive semi-definite information matrix;
///   every node must be connected to `fixed` through edges.
/// * `fixed` — the node held at its pose (the gauge), usually 0.
/// * `config` — iterations, robust kernel width, tolerance.
///
/// # Returns
/// The optimized `world_from_node` (the fixed node's pose unchanged, bit for bit) and a report
/// with the costs and each edge's final weight. [`Error::Invalid`] if the graph or the settings
/// break the rules above.
///
/// # Example
/// ```
/// use sdem::posegraph::{diagonal_information, optimize, Edge, EdgeKind, OptimizeConfig, PoseGraph};
/// use sdem::geometry::Pose;
/// use nalgebra::Vector3;
/// // A square of four 1 m steps whose odometry says 1.1 m, closed by a loop edge.
/// let step = |metres: f64| Pose::new(Vector3::new(metres, 0.0, 0.0), Vector3::z() * std::f64::consts::FRAC_PI_2);
/// let information = diagonal_information(0.05, 0.01);
/// let edge = |from, to, kind| Edge { from, to, from_from_to: step(1.0), information, kind };
/// let mut graph = PoseGraph::default();
/// let mut world_from_node = Pose::identity();
/// for node in 0..4 {
///     graph.world_from_node.push(world_from_node);
///     world_from_node *= step(1.1);
///     if node > 0 {
///         graph.edges.push(Edge { from_from_to: step(1.1), ..edge(node - 1, node, EdgeKind::Odometry) });
///     }
/// }
/// graph.edges.push(edge(3, 0, EdgeKind::LoopClosure));
/// let (world_from_node, report) = optimize(&graph, 0, &OptimizeConfig::default())?;
/// assert!(report.converged && report.final_cost < report.initial_cost);
/// assert_eq!(world_from_node[0], graph.world_from_node[0]);
/// # Ok::<(), sdem::Error>(())
/// ```
pub fn optimize(
    graph: &PoseGraph,
    fixed: usize,
    config: &OptimizeConfig,
) -> Result<(Vec<Pose>, OptimizeReport)> {
    optimize_holding(graph, &[fixed], config)
}

/// [`optimize`] with several nodes held at their poses: the boundary of a part of a larger
/// graph solved on its own (see [`optimize_local`]), or a map anchored at several known
/// places. Every node must be connected to one of them.
///
/// # Errors
/// As [`optimize`]; also an empty `fixed` or a fixed node that does not exist.
pub fn optimize_holding(
    graph: &PoseGraph,
    fixed: &[usize],
    config: &OptimizeConfig,
) -> Result<(Vec<Pose>, OptimizeReport)> {
    config.validate()?;
    let informations = validate(graph, fixed)?;
    let mut held = vec![false; graph.world_from_node.len()];
    for &node in fixed {
        held[node] = true;
    }
    solver::solve(graph, &held, informations, config)
}
