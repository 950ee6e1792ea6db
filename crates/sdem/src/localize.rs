//! Correlation localization (Nagatani et al. 2003, Sec. III-C): the search for the candidate
//! whose comparison with the reference S-DEM (eq. 1, [`crate::cost`]) is smallest, then a
//! continuous refinement of that grid optimum ([`crate::refine`]).
//!
//! Both S-DEMs are levelled by their gyro/compass readings, so a candidate is a translation (the
//! query origin minus the reference origin on world axes) and a heading correction (the compass
//! is disturbed near steel). Three searches share one cost:
//! * [`SearchMode::Exhaustive`] — every candidate of the grid (the paper's method; the oracle,
//!   kept forever);
//! * [`SearchMode::BranchAndBound`] — the exact fast search ([`crate::bnb`]): the same minimum as
//!   the exhaustive search, provably, for the projective cost;
//! * [`SearchMode::CoarseToFine`] — a pyramid heuristic, for the paper's virtual-S-DEM cost.

use crate::bnb::{self, BranchAndBoundStats};
use crate::cost::Correlator;
use crate::doubt::Doubt;
use crate::error::{Error, Result};
use crate::geometry::{Attitude, Pose, Vec3};
use crate::refine::{refine, Refinement, SurfaceNormals};
use crate::sdem::Sdem;
use crate::search::{
    heading_step_for_extent, horizontal_extent, CandidateGrid, Evaluator, Index, Scored,
};
use nalgebra::{Isometry3, Matrix6, SMatrix, SVector, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

pub use crate::cost::{correlate, Correlation, CostConfig, OffsetPrior};
pub use crate::search::{HeadingWindow, SearchWindow};

mod diagnose;
mod edge;
mod options;
mod runner_up;
pub use diagnose::PRIOR_CONFLICT_RATIO;
use diagnose::{attitude_corrected, diagnose, in_query_frame, prior_conflict};
use edge::stays_on_edge;
pub use options::{
    scan_footprint_m, LocalizeOptions, SearchMode, MAX_EXHAUSTIVE_CANDIDATES, MAX_STEP_M,
    MIN_STEP_M, MIN_TRUSTED_SUPPORT, REFINE_POINTS,
};
use runner_up::{RunnerUp, RunnerUpSearch};

/// The result of a localization.
#[derive(Debug, Clone, PartialEq)]
pub struct Localization {
    /// The query sensor's pose in the reference sensor's frame:
    /// `inverse(world_from_reference) * world_from_query`.
    pub reference_from_query: Pose,
    /// Covariance of the pose over `[x, y, z, rx, ry, rz]` in the query sensor's frame: metres
    /// along its axes, then small rotations (radians) about them. From the curvature of the
    /// refinement's cost, widened by the residuals' correlation and by the bias of how the two
    /// scans sample their surfaces ([`crate::refine::discrepancy`]); `None` without a 6-DoF
    /// refinement. ([`Diagnostics::covariance`] is the same on the levelled reference's axes.)
    pub covariance: Option<Matrix6<f64>>,
    /// The lowest cost (eq. 1, m²) found more than [`LocalizeOptions::peak_radius_m`] from the
    /// optimum and off its own slopes ([`Diagnostics::runner_up_cost`]), when it lies below
    /// [`LocalizeOptions::ambiguous_cost_ratio`] × [`Self::cost`]: another place that looks
    /// almost the same. `None`: nothing came that close.
    pub runner_up: Option<f64>,
    /// The estimated offset (query origin − reference origin, on the reference's levelled axes:
    /// the world's axes with the reference sensor's origin), refined when asked.
    pub offset: Vec3,
    /// The estimated heading correction to the query's compass reading, radians.
    pub heading_correction: f64,
    /// The best grid candidate's offset.
    pub grid_offset: Vec3,
    /// The best grid candidate's heading correction, radians.
    pub grid_heading: f64,
    /// The best grid candidate's integer coordinates (x, y, z, heading).
    pub grid_index: [usize; 4],
    /// Eq. (1) at the best grid candidate, m².
    pub cost: f64,
    /// Cells compared at the best grid candidate.
    pub overlap: usize,
    /// Candidates in the grid.
    pub candidates_total: usize,
    /// Candidates scored exactly.
    pub candidates_evaluated: usize,
    /// Boxes of candidates bounded (branch-and-bound only).
    pub nodes_bounded: usize,
    /// True when the optimum lies on the caller's window's edge, so that the true minimum may lie
    /// outside it: the refined pose within half a step of that edge, or without a refinement the
    /// grid optimum within a step of it.
    pub on_window_edge: bool,
    /// How the estimate was refined below the grid.
    pub refined: RefineOutcome,
    /// The 6-DoF refinement's result, when it succeeded.
    pub refinement: Option<Refinement>,
    /// The figures that say how far the result can be trusted.
    pub diagnostics: Diagnostics,
    /// Every reason not to trust the pose: the match's shape (see
    /// [`Diagnostics::ambiguous`]), and an optimum on the window's edge.
    pub doubts: Vec<Doubt>,
    /// `doubts` is empty: the pose can be used as it is. A result with doubts is still the best
    /// candidate the search found, to be used only as a guess.
    pub trusted: bool,
    /// Wall time of the localization.
    pub time: std::time::Duration,
}

/// How far a localization can be trusted.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Diagnostics {
    /// Cells compared at the best candidate over the query points compared (one per search
    /// cube, see [`CostConfig::search_voxel_m`]).
    pub overlap_fraction: f64,
    /// Cells within the truncation at the best candidate over the query points compared.
    pub inlier_fraction: f64,
    /// The same at the refined pose (its rotation, tilt included), when there is one. On a
    /// grid as coarse as a LiDAR's (15–25 cm) the best candidate lies up to half a step from
    /// the pose, where fewer cells fall within the truncation: a KITTI frame matched against
    /// its own node's place in a map, 49 % at the grid's best candidate, 69 % at the refined
    /// pose.
    pub refined_inlier_fraction: Option<f64>,
    /// The smallest cost outside the peak's neighbourhood, when it lies below
    /// [`LocalizeOptions::ambiguous_cost_ratio`] × the best (the runner-up search looks no
    /// higher); `None` otherwise. Candidates on the optimum's own slope (within twice the peak
    /// radius, eq. (1) never rising along the line to within a grid step of the optimum) and
    /// beside it are passed over, up to four such slopes: they are no other place.
    pub runner_up_cost: Option<f64>,
    /// Every candidate outside the peak's neighbourhood and the slopes passed over costs at
    /// least this (the cap of the runner-up search, or the runner-up's cost); `None` when not
    /// searched.
    pub runner_up_cost_at_least: Option<f64>,
    /// How many of the optimum's own slopes the runner-up search passed over (0 to 4).
    pub runner_up_slopes_passed: usize,
    /// Where that runner-up lies (offset, metres).
    pub runner_up_offset: Option<[f64; 3]>,
    /// Its heading correction, degrees.
    pub runner_up_heading_deg: Option<f64>,
    /// Covariance of `[x, y, z, roll, pitch, yaw]` (metres, radians; rotations about the
    /// reference's levelled axes) from the curvature of the refinement's cost, widened by the
    /// residuals' correlation and the scans' sampling bias ([`crate::refine::discrepancy`]);
    /// `None` without a 6-DoF refinement.
    pub covariance: Option<[[f64; 6]; 6]>,
    /// The translational direction the scans constrain least (unit vector, levelled reference
    /// axes).
    pub weakest_direction: Option<[f64; 3]>,
    /// Standard deviation along it, metres.
    pub weakest_sigma_m: Option<f64>,
    /// The share of the refinement's matched points on surfaces facing along
    /// `weakest_direction` within 60° ([`Refinement::support`]); below
    /// [`LocalizeOptions::min_trusted_support`] the doubt [`Doubt::Unconstrained`].
    pub weakest_support: Option<f64>,
    /// Standard deviation along the best-constrained direction, metres.
    pub strongest_sigma_m: Option<f64>,
    /// The translational direction along which the pose is free (a corridor's axis; unit
    /// vector, levelled reference axes), when it is: the refinement's weakest direction when its
    /// σ exceeds [`LocalizeOptions::ambiguous_sigma_ratio`] × the strongest; else the direction
    /// along which the grid's cost rises less than [`LocalizeOptions::ambiguous_rise_ratio`] ×
    /// the steepest, when the refinement's weakest direction lies within about 25° of it (or
    /// there is no refinement). Along it the scans do not fix the pose (what curvature there is
    /// comes from the sampling, not the scene): `sdem slam` takes the prediction's position
    /// along it.
    pub flat_direction: Option<[f64; 3]>,
    /// The share of either scan's returns, among those that land where the other has returns
    /// about them, lying in space the other scan saw through at the pose
    /// ([`crate::free_space`]): near 0 at a right pose of an unchanged scene, up to tenths at a
    /// wrong basin of a scene that repeats itself ([`SEEN_THROUGH_DOUBT`]).
    pub seen_through_fraction: f64,
    /// True when another, distant candidate scores almost as well or the cost is flat along
    /// some direction (the pose along [`Self::weakest_direction`] should not be trusted), when
    /// the 6-DoF refinement failed (the pose is the grid's, unconfirmed), or when too few of the
    /// query's points matched, or when the other scan saw through a quarter of its returns: when
    /// [`Localization::doubts`] holds a doubt about the match itself ([`Doubt::is_ambiguity`]).
    pub ambiguous: bool,
}

impl Diagnostics {
    /// The share of the compared cells within the truncation, the larger of the grid's best
    /// candidate's ([`Self::inlier_fraction`]) and the refined pose's
    /// ([`Self::refined_inlier_fraction`]): how much of the scan the match explains.
    pub fn matching_fraction(&self) -> f64 {
        self.inlier_fraction
            .max(self.refined_inlier_fraction.unwrap_or(0.0))
    }

    /// The share of the compared cells within the truncation (inliers over overlap): how well
    /// the scans agree where they both see; 0 when no cell was compared.
    pub fn shared_inlier_fraction(&self) -> f64 {
        if self.overlap_fraction > 0.0 {
            self.inlier_fraction / self.overlap_fraction
        } else {
            0.0
        }
    }
}

/// Which refinement produced the final estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RefineOutcome {
    /// Refinement was not asked for: the grid optimum.
    None,
    /// The robust 6-DoF point-to-plane refinement.
    SixDof,
    /// The 6-DoF refinement failed; a quadratic fit of the grid costs gave the translation.
    Quadratic,
    /// Both refinements failed; the grid optimum.
    Failed,
}

/// How the refinement of a match went, for reports: a refinement that stopped at its iteration
/// limit (`converged: false`) was still moving, as on ill-conditioned matches (a street seen by
/// a moving car) where each update is small but they add up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RefinementSummary {
    /// Which refinement produced the estimate.
    pub outcome: RefineOutcome,
    /// Gauss-Newton iterations run (6-DoF refinement only).
    pub iterations: Option<usize>,
    /// Whether the last update was below `RefineConfig::converged_step`.
    pub converged: Option<bool>,
    /// Robust RMS point-to-plane residual, metres.
    pub rms_m: Option<f64>,
}

impl RefinementSummary {
    /// The summary of a localization's `refined` and `refinement`.
    pub fn new(outcome: RefineOutcome, refinement: Option<&Refinement>) -> Self {
        Self {
            outcome,
            iterations: refinement.map(|r| r.iterations),
            converged: refinement.map(|r| r.converged),
            rms_m: refinement.map(|r| r.rms_m),
        }
    }
}

/// Localizes `query` against `reference`.
///
/// # Arguments
/// * `reference`, `query` — S-DEMs on one grid, each levelled by its own attitude reading,
///   which it keeps ([`Sdem::attitude`]): the readings set the relative rotation.
/// * `config` — window, step, heading window, search mode, cost.
///
/// # Returns
/// The best candidate with its cost and overlap, or an error when the configuration is invalid or
/// no candidate in the window shares enough cells with the query.
///
/// # Example
/// ```
/// use sdem::geometry::{Attitude, Vec3};
/// use sdem::localize::{localize, HeadingWindow, LocalizeOptions, SearchWindow};
/// use sdem::sdem::{Sdem, SdemConfig};
/// // A box-shaped room sampled densely; the query stands 10 cm further along x.
/// let mut room = Vec::new();
/// for i in -40..=40 {
///     for j in -40..=40 {
///         let (u, v) = (i as f64 * 0.05, j as f64 * 0.05);
///         for p in [[2.0, u, v], [-1.5, u, v], [u, 1.7, v], [u, -1.3, v], [u, v, 1.1], [u, v, -0.4]] {
///             room.push(Vec3::new(p[0], p[1], p[2]));
///         }
///     }
/// }
/// let level = Attitude::default();
/// let cfg = SdemConfig::default();
/// let reference = Sdem::from_points(&room, &level, &cfg).unwrap();
/// let moved: Vec<Vec3> = room.iter().map(|p| p - Vec3::new(0.1, 0.0, 0.0)).collect();
/// let query = Sdem::from_points(&moved, &level, &cfg).unwrap();
/// let config = LocalizeOptions {
///     window: SearchWindow { min: [-0.2, -0.1, -0.05], max: [0.2, 0.1, 0.05] },
///     heading: HeadingWindow::none(),
///     ..Default::default()
/// };
/// let found = localize(&reference, &query, &config).unwrap();
/// assert!((found.offset - Vec3::new(0.1, 0.0, 0.0)).norm() < 0.01);
/// ```
pub fn localize(reference: &Sdem, query: &Sdem, config: &LocalizeOptions) -> Result<Localization> {
    // Unreachable error: with no cap a search that finds nothing is an error below.
    localize_below(reference, query, config, f64::INFINITY)?.ok_or(Error::NoMatch {
        matched: 0,
        compared: 0,
        needed: 0,
        truncation_m: config.cost.truncation_m,
    })
}

/// [`localize`], but only a candidate costing at most `cap` counts: `Ok(None)` when the window
/// holds none. The exact search prunes every box whose bound exceeds the cap, so a search that
/// cannot beat a cost already found elsewhere (another rotation hypothesis) ends early.
pub(crate) fn localize_below(
    reference: &Sdem,
    query: &Sdem,
    config: &LocalizeOptions,
    cap: f64,
) -> Result<Option<Localization>> {
    let start = std::time::Instant::now();
    let Some(searched) = search_below(reference, query, config, cap, &config.window)? else {
        return Ok(None);
    };
    let mut found = not_seen_through(reference, query, config, searched);
    found.time = start.elapsed();
    Ok(Some(found))
}

/// A match's returns seen through by this share or more ([`crate::free_space`]) send the
/// search to the candidates of other basins (in [`localize`]: the runner-up and up to
/// four in all). At right poses the share stays small (see [`SEEN_THROUGH_DOUBT`] for the
/// fault bench's and the real re-views'); at the wrong basins eq. (1) preferred on the
/// `unlevelled` suite, up to 60 %.
pub const SEEN_THROUGH_TO_RECHECK: f64 = 0.05;

/// A pose whose compared returns the other scan saw through by this share or more is doubtful
/// ([`Doubt::FreeSpaceConflict`]). At right poses of `sdem bench --faults`' pairs (100 a
/// fault) the share was at most 0.2 % with clean scans or a drifting gyro, 0.8 % with lost
/// returns, 4.7 % with dust, 7.2 % with a person walking by, 18.6 % with rubble moved between
/// the scans and 16.5 % with every fault at once; at the right poses of real re-views up to
/// 5.4 % (3DTK) and 0.1 % (KITTI). A kidnapped robot's wide window on the route bench held a
/// wrong place matching 33 % of its cells, seen through by 31 %, that a refinement a hair
/// different left with no other doubt. A board 25–40 cm in front of the scanner hiding half its
/// view (the route bench's `half-blocked` stops) reaches 26 % at the right pose: so large a
/// change of the scene is flagged too.
pub const SEEN_THROUGH_DOUBT: f64 = 0.25;

/// Another candidate replaces the optimum when the share of its returns seen through is lower
/// by at least this …
const SEEN_THROUGH_MARGIN: f64 = 0.05;
/// … and at most this fraction of the optimum's: a moved stone or a person shows at every pose
/// alike, a wrong basin adds what it contradicts.
const SEEN_THROUGH_RATIO: f64 = 0.5;

/// Whether a candidate whose returns are seen through by the share `other` beats one whose
/// are by `than` (see [`SEEN_THROUGH_MARGIN`] and [`SEEN_THROUGH_RATIO`]).
pub(crate) fn seen_through_less(other: f64, than: f64) -> bool {
    other <= than - SEEN_THROUGH_MARGIN && other <= SEEN_THROUGH_RATIO * than
}

/// `found`, or, where the other scan saw through its returns and a candidate of another basin
/// far less ([`Searched::less_seen_through`]), that candidate searched in full (a window of half
/// the peak's radius around it, every heading the first search had), with
/// [`Doubt::SeenThrough`] naming the cheaper optimum. Eq. (1) counts a return the other scan
/// could not see and one it saw through alike; a basin whose surfaces stand where the other's
/// beams passed is no place the scans were taken, whatever it costs.
fn not_seen_through(
    reference: &Sdem,
    query: &Sdem,
    config: &LocalizeOptions,
    searched: Searched,
) -> Localization {
    let Searched {
        found,
        less_seen_through,
    } = searched;
    let Some(offset) = less_seen_through else {
        return found;
    };
    let half = config.peak_radius_m / 2.0;
    let window = SearchWindow::around(&offset, [half; 3]).clipped_to(&config.window);
    let options = LocalizeOptions {
        window,
        runner_up: false,
        ..config.clone()
    };
    // On the small window's edge is a doubt only where that edge is the caller's (the heading
    // window is the caller's own).
    let Ok(Some(Searched {
        found: mut again, ..
    })) = search_below(reference, query, &options, f64::INFINITY, &config.window)
    else {
        return found;
    };
    let seen_through = found.diagnostics.seen_through_fraction;
    if !seen_through_less(again.diagnostics.seen_through_fraction, seen_through) {
        return found;
    }
    prefer_to_seen_through(&mut again, &found);
    again.diagnostics.runner_up_cost = Some(found.cost);
    again.diagnostics.runner_up_cost_at_least = Some(found.cost);
    again.diagnostics.runner_up_offset = Some(found.grid_offset.into());
    again.diagnostics.runner_up_heading_deg = Some(found.grid_heading.to_degrees());
    again.runner_up = Some(found.cost);
    again
}

/// Marks `found` as taken instead of the cheaper `seen_through`, whose returns the other scan
/// saw through far more ([`seen_through_less`]): [`Doubt::SeenThrough`] naming it, so neither
/// trusted nor unambiguous.
pub(crate) fn prefer_to_seen_through(found: &mut Localization, seen_through: &Localization) {
    found.doubts.push(Doubt::SeenThrough {
        distance_m: (seen_through.offset - found.offset).norm(),
        cost: seen_through.cost,
        seen_through_fraction: seen_through.diagnostics.seen_through_fraction,
    });
    found.diagnostics.ambiguous = true;
    found.trusted = false;
}

/// What [`search_below`] found: the best candidate, localized, and where the other scan saw
/// through its returns, a candidate of another basin it saw through far less.
struct Searched {
    found: Localization,
    /// Grid offset of the first candidate, best first among the first [`SEEN_THROUGH_BASINS`]
    /// below the ambiguity ratio × the optimum's cost, each outside the peak radius of the
    /// optimum (and the optimum's slopes the runner-up search passed over) and of the
    /// candidates before it ([`RunnerUpSearch::less_seen_through`]), whose
    /// returns are seen through far less ([`seen_through_less`]); looked for only when
    /// `found`'s are seen through by [`SEEN_THROUGH_TO_RECHECK`] or more and the search looks
    /// for a runner-up.
    less_seen_through: Option<Vec3>,
}

/// [`localize_below`] without the check of what the scans saw through. An optimum on the
/// search window's edge is one only where it lies on the edge of `edges`, the caller's window,
/// which holds the search's (see [`stays_on_edge`]).
fn search_below(
    reference: &Sdem,
    query: &Sdem,
    config: &LocalizeOptions,
    cap: f64,
    edges: &SearchWindow,
) -> Result<Option<Searched>> {
    let start = std::time::Instant::now();
    let (reference_attitude, query_attitude) = (reference.attitude(), query.attitude());
    config.validate()?;
    // The query's extent sets the heading step, and how far a turn reaches in the runner-up
    // search.
    let extent = horizontal_extent(query);
    let yaws = config
        .heading
        .samples(heading_step_for_extent(extent, config.step_m));
    let full_turn = (config.heading.half_range_deg - 180.0).abs() < 1e-9;
    let grid = CandidateGrid::new(&config.window, config.step_m, yaws)?;
    if config.mode == SearchMode::Exhaustive && grid.len() > config.max_exhaustive_candidates {
        return Err(Error::TooManyCandidates {
            candidates: grid.len(),
            grid: grid.counts,
            limit: config.max_exhaustive_candidates,
        });
    }
    // Chooses the compared points once; every search and worker below clones it. Meanwhile the
    // reference's cell planes, which the search's tables and the cost read, are fitted.
    let (correlator, _) = rayon::join(
        || Correlator::new(reference, query, &config.cost),
        || reference.surfaces(),
    );
    let mut correlator = correlator?;
    let mut evaluator = Evaluator::new(correlator.clone(), &grid);
    // Shared by the search for the best candidate and the one for the runner-up.
    let prepared =
        (config.mode == SearchMode::BranchAndBound).then(|| bnb::Prepared::new(&correlator));
    let ((best, stats, reserve), normals) = search_and_fit_normals(
        &mut evaluator,
        prepared.as_ref(),
        reference,
        query,
        config,
        full_turn,
        cap.min(config.cost.max_match_cost()),
    );
    if best.is_none() && cap.is_finite() {
        return Ok(None);
    }
    let best = best_candidate(&mut correlator, &grid, best, config)?;
    let (cost, grid_index, grid_offset, grid_heading) = (
        best.cost,
        best.grid_index,
        best.grid_offset,
        best.grid_heading,
    );
    let refined = refine_best(reference, query, normals, &mut evaluator, &best, config);
    let (offset, rotation) = (refined.offset, refined.rotation);
    let heading_correction = {
        let (_, _, yaw) = rotation.euler_angles();
        yaw
    };
    let (level_from_query, reference_from_query) = query_poses(reference, query, offset, rotation);
    let seen_through =
        crate::free_space::free_space(reference, query, &reference_from_query).fraction();
    // The runner-up; and where the other scan saw through the optimum's returns, the first of
    // the candidates of other basins it saw through far less.
    let (runner_up, less_seen_through, slopes_passed) = if config.runner_up {
        let search = RunnerUpSearch {
            grid: &grid,
            correlator: &correlator,
            prepared: prepared.as_ref(),
            reserve: reserve.as_ref(),
            full_turn,
            extent: extent.unwrap_or(0.1),
        };
        let RunnerUp {
            found: runner_up,
            outside,
            slopes_passed,
        } = search.run((grid_offset, grid_heading), cost, config);
        let less_seen_through = (seen_through >= SEEN_THROUGH_TO_RECHECK)
            .then(|| {
                search.less_seen_through(
                    reference,
                    query,
                    outside,
                    (cost, seen_through),
                    runner_up,
                    config,
                )
            })
            .flatten();
        (runner_up, less_seen_through, slopes_passed)
    } else {
        (None, None, 0)
    };
    // Eq. (1) about the grid optimum (`false`: at its heading, the query levelled by its
    // reading) or about the refined pose (`true`: turned by the refined rotation, its tilt as
    // well as its heading; at the reading's tilt the cost has its minimum elsewhere when the
    // refinement corrected it, and under `sdem bench --faults`' gyro drift half the right poses
    // came out flat there).
    // Eq. (1) at the refined pose, once: the cost's shape is probed about it, and its inliers
    // are `Diagnostics::refined_inlier_fraction`.
    let refined_at = (refined.refinement.is_some())
        .then(|| correlator.evaluate_turned(&offset, &rotation))
        .flatten();
    let mut cost_at = |offset: Vec3, refined: bool| {
        let scored = if refined {
            correlator.evaluate_turned(&offset, &rotation)
        } else {
            correlator.evaluate(&offset, grid_heading)
        };
        scored.map_or(f64::INFINITY, |c| c.cost)
    };
    let (mut diagnostics, mut doubts) = diagnose(
        config,
        best.compared,
        &best.at_best,
        grid_offset,
        runner_up,
        (refined.refinement.as_ref(), refined_at.as_ref()),
        refined.error.as_deref(),
        &mut cost_at,
    );
    if let Some(doubt) = attitude_corrected(&refined.rotation, reference_attitude, query_attitude) {
        doubts.push(doubt);
    }
    if let Some(doubt) = prior_conflict(reference, query, config, &correlator, &grid_offset, cost)?
    {
        doubts.push(doubt);
    }
    let refined_pose = refined
        .refinement
        .is_some()
        .then_some((offset, heading_correction));
    let on_window_edge = grid.on_edge(grid_index, full_turn)
        && stays_on_edge(&grid, grid_index, full_turn, edges, refined_pose);
    if on_window_edge {
        doubts.push(Doubt::OnWindowEdge);
    }
    let covariance = diagnostics
        .covariance
        .map(|c| in_query_frame(&Matrix6::from_fn(|i, j| c[i][j]), &level_from_query));
    diagnostics.seen_through_fraction = seen_through;
    diagnostics.runner_up_slopes_passed = slopes_passed;
    if seen_through >= SEEN_THROUGH_DOUBT {
        doubts.push(Doubt::FreeSpaceConflict {
            seen_through_fraction: seen_through,
            trusted_below: SEEN_THROUGH_DOUBT,
        });
    }
    let found = Localization {
        reference_from_query,
        covariance,
        runner_up: diagnostics.runner_up_cost,
        offset,
        heading_correction,
        grid_offset,
        grid_heading,
        grid_index,
        cost,
        overlap: best.at_best.overlap,
        candidates_total: grid.len(),
        candidates_evaluated: evaluator.evaluated,
        nodes_bounded: stats.nodes_bounded,
        on_window_edge,
        refined: refined.outcome,
        refinement: refined.refinement,
        diagnostics,
        trusted: doubts.is_empty(),
        doubts,
        time: start.elapsed(),
    };
    Ok(Some(Searched {
        found,
        less_seen_through,
    }))
}

/// What a search returns: its best candidate, its statistics, and what the exact search set
/// aside for the runner-up search.
type SearchResult = (Option<Scored>, BranchAndBoundStats, Option<bnb::Reserve>);

/// Runs the search for the best candidate and, when a refinement is asked for, fits the
/// reference's and the query's surface normals meanwhile (the refinement reads the first, its
/// run the other way the second): they depend on their scan alone, so they are fitted while the
/// search runs, on the cores its sequential steps leave idle.
fn search_and_fit_normals<'r>(
    evaluator: &mut Evaluator,
    prepared: Option<&bnb::Prepared>,
    reference: &'r Sdem,
    query: &Sdem,
    config: &LocalizeOptions,
    full_turn: bool,
    cap: f64,
) -> (SearchResult, Option<std::borrow::Cow<'r, SurfaceNormals>>) {
    // The exact search sets aside what may cost up to the ambiguity ratio × the best, so the
    // runner-up search continues from there instead of bounding the window again.
    let reserve_ratio = config.runner_up.then_some(config.ambiguous_cost_ratio);
    rayon::join(
        || run_search(evaluator, prepared, config, full_turn, cap, reserve_ratio),
        || {
            config.refine.then(|| {
                // The query's too, and its cell planes: the refinement the other way reads them
                // (they stay with the query, as a reference's stay with it). Fitted there, the
                // planes held up that refinement's first pairing (1.7 ms of a bench pair's
                // 2.1 ms, the other workers waiting).
                let radius = config.refinement.normal_radius_cells;
                let (normals, _) = rayon::join(
                    || crate::refine::SurfaceNormals::of(reference, radius),
                    || {
                        query.surfaces();
                        crate::refine::SurfaceNormals::of(query, radius)
                    },
                );
                normals
            })
        },
    )
}

/// The search's best grid candidate, scored again.
struct BestCandidate {
    /// Its cost, as the search found it.
    cost: f64,
    grid_index: Index,
    grid_offset: Vec3,
    grid_heading: f64,
    /// Its comparison, scored again (overlap and inliers).
    at_best: Correlation,
    /// The query points compared.
    compared: usize,
}

/// The search's best candidate scored again, or the error that says why there is no match:
/// nothing overlaps enough, or too few of the compared points find their reference point.
fn best_candidate(
    correlator: &mut Correlator,
    grid: &CandidateGrid,
    best: Option<Scored>,
    config: &LocalizeOptions,
) -> Result<BestCandidate> {
    let Some((cost, flat)) = best else {
        return Err(Error::NoOverlap {
            needed: correlator.min_overlap(),
            compared: correlator.compared_points(),
            max_cost_m2: config.cost.max_match_cost(),
        });
    };
    let grid_index = grid.index(flat);
    let grid_offset = grid.offset(grid_index);
    let grid_heading = grid.yaw(grid_index);
    // Scores the best candidate again here and, for the diagnostics, its neighbours.
    let at_best =
        (correlator.evaluate(&grid_offset, grid_heading)).ok_or_else(|| Error::NoOverlap {
            needed: correlator.min_overlap(),
            compared: correlator.compared_points(),
            max_cost_m2: config.cost.max_match_cost(),
        })?;
    let compared = correlator.compared_points();
    let needed_inliers = (config.cost.min_inlier_fraction * compared as f64).ceil();
    if (at_best.inliers as f64) < needed_inliers {
        return Err(Error::NoMatch {
            matched: at_best.inliers,
            compared,
            needed: needed_inliers as usize,
            truncation_m: config.cost.truncation_m,
        });
    }
    Ok(BestCandidate {
        cost,
        grid_index,
        grid_offset,
        grid_heading,
        at_best,
        compared,
    })
}

/// The estimate below the grid: the refinement's pose, the quadratic fit's translation, or the
/// grid's own.
struct Refined {
    offset: Vec3,
    rotation: UnitQuaternion<f64>,
    outcome: RefineOutcome,
    /// The 6-DoF refinement's result, when it succeeded.
    refinement: Option<Refinement>,
    /// Why the 6-DoF refinement failed, when it was asked for and did.
    error: Option<String>,
}

/// Refines the best grid candidate: the robust 6-DoF refinement when `normals` were fitted (it
/// was asked for), falling back to a quadratic fit of the grid costs around it.
fn refine_best(
    reference: &Sdem,
    query: &Sdem,
    normals: Option<std::borrow::Cow<'_, SurfaceNormals>>,
    evaluator: &mut Evaluator,
    best: &BestCandidate,
    config: &LocalizeOptions,
) -> Refined {
    let grid_offset = best.grid_offset;
    let grid_rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), best.grid_heading);
    let mut rotation = grid_rotation;
    let mut refinement = None;
    let mut error = None;
    let (offset, outcome) = if let Some(normals) = normals {
        let initial = Isometry3::from_parts(Translation3::from(grid_offset), grid_rotation);
        match refine(
            reference,
            &normals,
            query,
            &initial,
            config.cost.prior.as_ref(),
            &config.refinement,
        ) {
            Ok(r) => {
                // The covariance of the residuals' spread, widened by the bias of how the
                // two scans sample their surfaces (`refine::discrepancy`).
                let r = crate::refine::discrepancy::with_sampling_bias(
                    r,
                    reference,
                    query,
                    &config.refinement,
                );
                rotation = r.reference_level_from_query_level.rotation;
                let t = r.reference_level_from_query_level.translation.vector;
                refinement = Some(r);
                (t, RefineOutcome::SixDof)
            }
            Err(e) => {
                error = Some(e.to_string());
                match refine_quadratic(evaluator, best.grid_index) {
                    Some(o) => (o, RefineOutcome::Quadratic),
                    None => (grid_offset, RefineOutcome::Failed),
                }
            }
        }
    } else {
        (grid_offset, RefineOutcome::None)
    };
    Refined {
        offset,
        rotation,
        outcome,
        refinement,
        error,
    }
}

/// The query sensor's pose at `(rotation, offset)` between the levelled frames (the sensor
/// frames rotated by their attitude readings, both with the reference sensor's origin: what
/// the search finds), in the reference's levelled frame and in the reference sensor's frame.
fn query_poses(
    reference: &Sdem,
    query: &Sdem,
    offset: Vec3,
    rotation: UnitQuaternion<f64>,
) -> (Pose, Pose) {
    let level_from_query = Isometry3::from_parts(
        Translation3::from(offset),
        rotation * rotation_only(query.attitude()).rotation,
    );
    let reference_from_query = rotation_only(reference.attitude()).inverse() * level_from_query;
    (level_from_query, reference_from_query)
}

/// Runs the configured search over the evaluator's grid.
fn run_search(
    evaluator: &mut Evaluator,
    prepared: Option<&bnb::Prepared>,
    config: &LocalizeOptions,
    full_turn: bool,
    cap: f64,
    reserve_ratio: Option<f64>,
) -> (Option<Scored>, BranchAndBoundStats, Option<bnb::Reserve>) {
    let capped = |best: Option<Scored>| best.filter(|s| s.0 <= cap);
    match config.mode {
        SearchMode::Exhaustive => (
            capped(evaluator.exhaustive()),
            BranchAndBoundStats::default(),
            None,
        ),
        SearchMode::CoarseToFine => (
            capped(evaluator.coarse_to_fine(config.coarse_step_m, config.keep, full_turn)),
            BranchAndBoundStats::default(),
            None,
        ),
        SearchMode::BranchAndBound => {
            let (best, stats, reserve) = bnb::search(
                prepared.expect("localize prepares the tables for branch-and-bound"),
                evaluator.grid,
                cap,
                reserve_ratio,
            );
            evaluator.evaluated += stats.leaves_evaluated;
            (best, stats, reserve)
        }
    }
}

fn rotation_only(attitude: &Attitude) -> Pose {
    Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&attitude.rotation()),
    )
}

/// Sub-grid fallback: fits `c(u) = a + bᵀu + ½ uᵀHu` to the 27 costs around the grid optimum
/// (u in grid steps, heading fixed) and returns the fitted minimum when the fit is convex and the
/// minimum lies within one step. Neighbours outside the window are scored too: the cost exists
/// there.
fn refine_quadratic(evaluator: &mut Evaluator, idx: Index) -> Option<Vec3> {
    let grid = evaluator.grid;
    let mut correlator = evaluator.correlator();
    let yaw = grid.yaw(idx);
    let mut ata = SMatrix::<f64, 10, 10>::zeros();
    let mut atb = SVector::<f64, 10>::zeros();
    for dz in -1..=1 {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let u = [dx as f64, dy as f64, dz as f64];
                let at = [
                    idx[0] as f64 + u[0],
                    idx[1] as f64 + u[1],
                    idx[2] as f64 + u[2],
                ];
                evaluator.evaluated += 1;
                let c = correlator.evaluate(&grid.offset_at(at), yaw)?;
                let row = SVector::<f64, 10>::from_column_slice(&[
                    1.0,
                    u[0],
                    u[1],
                    u[2],
                    0.5 * u[0] * u[0],
                    0.5 * u[1] * u[1],
                    0.5 * u[2] * u[2],
                    u[0] * u[1],
                    u[0] * u[2],
                    u[1] * u[2],
                ]);
                ata += row * row.transpose();
                atb += row * c.cost;
            }
        }
    }
    let theta = ata.cholesky()?.solve(&atb);
    let b = Vector3::new(theta[1], theta[2], theta[3]);
    let h = nalgebra::Matrix3::new(
        theta[4], theta[7], theta[8], theta[7], theta[5], theta[9], theta[8], theta[9], theta[6],
    );
    let u = -h.cholesky()?.solve(&b);
    if u.iter().any(|v| !v.is_finite() || v.abs() > 1.0) {
        return None;
    }
    Some(grid.offset_at([
        idx[0] as f64 + u[0],
        idx[1] as f64 + u[1],
        idx[2] as f64 + u[2],
    ]))
}
