//! What one stop of the loop reports: its pose, status, match, loop closures and times.

use crate::doubt::Doubt;
use crate::geometry::Pose;
use crate::map::LoopClosure;
use serde::{Deserialize, Serialize};

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

/// Where a search of one stop started from ([`Attempt::source`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PredictionSource {
    /// The last node's pose moved by the odometry's motion.
    Odometry,
    /// The last node's pose moved by the last motion again (constant velocity).
    ConstantVelocity,
    /// The last node's pose: the robot did not move.
    NoMotion,
    /// The pose of a node the last node is linked to: the robot went back there.
    Neighbour,
    /// The best prediction again, matched against the nodes of the whole segment that see most
    /// of what the scan sees there, not only the recent ones (after a turn, a robot sees what
    /// older nodes saw).
    OtherNodes,
    /// A prediction's window, grown.
    WiderWindow,
    /// Every heading (and the tilt when the scan has no attitude reading) near the last node.
    EveryHeading,
    /// No prior: nodes anywhere in the map, by place descriptor, over every heading.
    Relocalization,
}

/// How a stop whose first prediction failed was found ([`StepReport::recovery`]).
pub type Recovery = PredictionSource;

/// One search tried for a stop: where it started, what it found, and whether the loop took it.
#[derive(Debug, Clone, Serialize)]
pub struct Attempt {
    /// Where the search started.
    pub source: PredictionSource,
    /// The nodes it was matched against.
    pub nodes: Vec<usize>,
    /// The window's half-size, metres.
    pub window_half_m: [f64; 3],
    /// The heading window's half-width, degrees (180: every heading).
    pub heading_half_deg: f64,
    /// Without a prior: how unlike the scan's place descriptor the node's is (mean |ln r₁/r₂|
    /// over every heading, [`crate::map::Descriptor`]).
    pub descriptor_distance: Option<f64>,
    /// Eq. (1) at the best candidate, m², when something matched.
    pub cost: Option<f64>,
    /// The share of the query's points that matched.
    pub inlier_fraction: Option<f64>,
    /// The match's doubts.
    pub doubts: Vec<Doubt>,
    /// Taken for the stop.
    pub accepted: bool,
    /// Why not, in words (empty when accepted).
    pub reason: String,
    /// Wall time, ms.
    pub time_ms: f64,
}

/// Two map segments made one ([`StepReport::joined`]): a confident match placed `absorbed`'s
/// nodes in `into`'s frame.
#[derive(Debug, Clone, Serialize)]
pub struct SegmentJoin {
    /// The segment that keeps its frame.
    pub into: usize,
    /// The segment whose nodes were moved into it.
    pub absorbed: usize,
    /// The match that links them: a node of `into` and one of `absorbed`.
    pub link: (usize, usize),
    /// How far the absorbed segment's first node moved, metres.
    pub moved_m: f64,
}

/// What happened to one scan.
#[derive(Debug, Clone, Serialize)]
pub struct StepReport {
    /// Index of the scan in its dataset.
    pub scan_index: usize,
    /// The run it belongs to (0 for the run that started the map).
    pub run: usize,
    /// The node it became.
    pub node_id: usize,
    /// How the stop went: tracked, recovered, relocalized, a new segment, doubtful.
    pub status: StepStatus,
    /// How it was found when the first prediction failed.
    pub recovery: Option<Recovery>,
    /// The map segment it belongs to when the step ended (0: the world's).
    pub segment: usize,
    /// Every search tried, in order.
    pub attempts: Vec<Attempt>,
    /// Segments joined at this step.
    pub joined: Vec<SegmentJoin>,
    /// Loop closures accepted earlier and withdrawn at this step, because the closures found
    /// since agree with one another but not with them.
    pub withdrawn_closures: Vec<(usize, usize)>,
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
    /// Matched against the map from the first prediction, with no doubt.
    Tracked,
    /// Matched with no doubt after the first prediction failed: from another prediction, a
    /// wider window, or every heading ([`StepReport::recovery`] says which).
    Recovered,
    /// Found with no prior in the map (a run started in a saved map, a robot carried
    /// elsewhere): over every heading, at nodes whose places look alike.
    Relocalized,
    /// Found nowhere with confidence: the stop starts a new map segment, in a frame of its own
    /// (its pose is a guess, [`StepReport::doubts`] says why), until a later match joins it.
    NewSegment,
    /// Matched, with doubts its pose-graph edge carries: along a direction the scans leave
    /// free the position is the odometry's, with the odometry's uncertainty.
    Doubtful,
}

impl StepStatus {
    /// The status as report.json spells it.
    pub fn name(self) -> &'static str {
        match self {
            StepStatus::First => "first",
            StepStatus::Tracked => "tracked",
            StepStatus::Recovered => "recovered",
            StepStatus::Relocalized => "relocalized",
            StepStatus::NewSegment => "new_segment",
            StepStatus::Doubtful => "doubtful",
        }
    }
}

/// One stop added by [`Slam::add`](super::Slam::add): where the sensor stood, how the match went, and the full
/// report `sdem slam` writes for it.
#[derive(Debug, Clone)]
pub struct Step {
    /// The pose of the scan's sensor in the world when the step ended (later loop closures can
    /// move it: see [`Slam::poses`](super::Slam::poses)).
    pub world_from_sensor: Pose,
    /// First, tracked, recovered, relocalized, a new segment, or doubtful.
    pub status: StepStatus,
    /// The localization's figures, doubts, loop closures and times.
    pub report: StepReport,
}
