//! What one stop of the loop reports: its pose, status, match, loop closures and times.

use crate::doubt::Doubt;
use crate::geometry::Pose;
use crate::map::LoopClosure;
use serde::Serialize;

/// Where the heading prior came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum HeadingPrior {
    /// The first scan: its compass reading (or 0) defines the world's heading.
    First,
    /// The odometry's relative motion from the last node.
    Odometry,
    /// The compass reading.
    Compass,
    /// The last node's heading turned by the last motion (no odometry, no compass).
    ConstantVelocity,
    /// The last node's heading.
    LastNode,
}

/// What happened to one scan.
#[derive(Debug, Clone, Serialize)]
pub struct StepReport {
    /// Index of the scan in its dataset.
    pub scan_index: usize,
    /// The node it became.
    pub node_id: usize,
    /// Wall time of the whole step (localization, loop closure, optimization, map update), ms.
    pub time_ms: f64,
    /// Wall time of the localization alone, ms.
    pub localize_ms: f64,
    /// Wall time of loop closure: the candidates' verification and the graph solve, ms.
    pub loop_closure_ms: f64,
    /// Wall time of the map's upkeep after the step: moved nodes fused again, far nodes
    /// parked in the node store, ms.
    pub map_update_ms: f64,
    /// The estimated pose of the scan's sensor in the world when the step ended, as
    /// `{x, y, z, roll_deg, …}`.
    pub world_from_sensor: crate::geometry::PoseRecord,
    /// The prediction the search started from.
    pub predicted_world_from_sensor: crate::geometry::PoseRecord,
    /// Where the heading prior came from.
    pub heading_prior: HeadingPrior,
    /// Reference nodes merged, with the query cells each one saw.
    pub reference_nodes: Vec<(usize, usize)>,
    /// Eq. (1) at the best grid candidate, m² (`None` for the first scan).
    pub cost: Option<f64>,
    /// Overlap fraction of the match.
    pub overlap_fraction: Option<f64>,
    /// Inlier fraction of the match.
    pub inlier_fraction: Option<f64>,
    /// Covariance of `[x, y, z, roll, pitch, yaw]` from the match (world axes), as its edges
    /// carry it: along a direction the scans leave free, widened by the prediction's variance.
    pub covariance: Option<[[f64; 6]; 6]>,
    /// Every reason not to trust the match (see [`crate::localize::Localization::doubts`]);
    /// empty for the first scan.
    pub doubts: Vec<Doubt>,
    /// No doubt about the match: the step's pose rests on the scans.
    pub trusted: bool,
    /// How the match's refinement went (`None` for the first scan).
    pub refinement: Option<crate::localize::RefinementSummary>,
    /// Loop closures checked at this scan, accepted or not.
    pub loop_closures: Vec<LoopClosure>,
    /// Pose-graph optimization run at this scan: iterations and time, ms.
    pub optimization: Option<OptimizationSummary>,
}

/// One pose-graph optimization, summarized.
#[derive(Debug, Clone, Serialize)]
pub struct OptimizationSummary {
    /// Iterations run.
    pub iterations: usize,
    /// Robust cost before and after.
    pub initial_cost: f64,
    /// Robust cost after.
    pub final_cost: f64,
    /// Wall time, ms.
    pub time_ms: f64,
    /// The largest move of a node, metres.
    pub max_node_shift_m: f64,
    /// Nodes the solve was free to move (the part of the graph the closure touched).
    pub free_nodes: usize,
    /// The whole graph was solved.
    pub whole_graph: bool,
}

/// How a stop went, in one word.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StepStatus {
    /// The first scan: it defines the world frame.
    First,
    /// Matched against the map with no doubt.
    Tracked,
    /// Matched, but the match has doubts ([`StepReport::doubts`]); its pose is the best guess.
    Doubtful,
}

/// One stop added by [`Slam::add`](super::Slam::add): where the sensor stood, how the match went, and the full
/// report `sdem slam` writes for it.
#[derive(Debug, Clone)]
pub struct Step {
    /// The pose of the scan's sensor in the world when the step ended (later loop closures can
    /// move it: see [`Slam::poses`](super::Slam::poses)).
    pub world_from_sensor: Pose,
    /// First, tracked, or doubtful.
    pub status: StepStatus,
    /// The localization's figures, doubts, loop closures and times.
    pub report: StepReport,
}
