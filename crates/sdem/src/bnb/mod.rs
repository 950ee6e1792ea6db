//! Exact branch-and-bound search over translation and heading for the projective cost
//! ([`crate::cost::CostModel::Projective`]), after correlative scan matching with precomputed
//! multi-resolution tables (Olson 2009; Hess et al. 2016, Cartographer).
//!
//! A node is a box of grid candidates (index intervals in x, y, z and heading), halved at a power
//! of two along the axis it reaches farthest in (a heading step counts as far as it moves a
//! typical query point), as a k-d tree splits space. Each query point's term depends on its own moved
//! position only (the cost is a plain sum: a cell the reference does not see costs `τ²`), so a
//! lower bound on every point's term over a box bounds the box:
//!
//! * over the box, a point moves within the translation box, plus the arc the heading interval
//!   turns it through, plus (for a group of nearby points bounded together) the group's radius;
//!   that region sees the reference through a cone of S-DEM cells;
//! * in each cell of the cone, its distance to the cell's plane can shrink by at most the
//!   region's extent along the plane's normal (the box's support, and the arc's radial and
//!   tangential parts), and a cell whose range gate the region cannot reach, or that the
//!   reference does not see, costs `τ²`; the smallest over the cone bounds the point (large
//!   cones fall back to the range tables: `τ²` when no cell of the cone can be reached, else 0).
//!
//! The search is best first: the box with the lowest bound is expanded next (by one worker per
//! thread, each taking the lowest box of a shared queue and bounding its children), after a first
//! dive into the most promising child at each level finds a good candidate. Boxes whose bound
//! exceeds the best cost so far are dropped, and every bound and every candidate is summed point
//! block by point block and cut short as soon as the sum passes the best (the terms are >= 0).
//! Points certainly at `τ²` in a box are not bounded again in its children. Single candidates are
//! scored with the same [`Correlator`] the exhaustive search uses, so both return the same minimum,
//! bit for bit.
//!
//! Query points are grouped (by cubes of 2, 4, 8 … cm) at coarser levels, so large boxes are
//! bounded from a few hundred groups instead of every point: a group's reach covers its members'.
//!
//! The module's files, by concept: `tables` (the reference's lookup tables), `groups` (the query's
//! points grouped at several scales), `queue` (boxes of candidates, the best-first queue and what
//! a search found and set aside), `bound` (the lower bound over a box, in its AVX2 and portable
//! builds) and `search` (what is prepared once per pair, and the best-first loop).
//!
//! [`Correlator`]: crate::cost::Correlator

mod bound;
mod groups;
mod queue;
mod search;
mod tables;

pub use groups::QueryGroups;
pub use queue::{Node, PointHint, Reserve};
pub use search::{BranchAndBound, Prepared};
pub use tables::RangeTables;

use crate::search::{CandidateGrid, Scored};

/// What the search did, for reports and benchmarks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BranchAndBoundStats {
    /// Boxes bounded.
    pub nodes_bounded: usize,
    /// Single candidates scored (each stops as soon as its sum exceeds the best so far).
    pub leaves_evaluated: usize,
}

/// Runs the exact search; see the module documentation. With a finite `cap`, only candidates
/// costing at most `cap` are looked for (the minimum among them, or `None`): a much cheaper
/// question when the cap is low.
///
/// With `reserve_ratio`, the search also returns what it set aside for [`runner_up`]: the boxes
/// and candidates that may cost up to that multiple of the best.
#[doc(hidden)]
pub fn search(
    prepared: &Prepared,
    grid: &CandidateGrid,
    cap: f64,
    reserve_ratio: Option<f64>,
) -> (Option<Scored>, BranchAndBoundStats, Option<Reserve>) {
    BranchAndBound::new(prepared, grid, cap).run(reserve_ratio)
}

/// The best candidate of `grid` (which leaves out at least the first search's peak: any balls
/// of [`CandidateGrid::exclude`], at some or all headings) costing at most `cap`, searched
/// among what the first search set aside: the same answer as a search of the whole grid with
/// that cap, since every box and candidate the first search dropped below the cap is in the
/// reserve (`cap` must be at most the reserve's ratio × the first search's best). The reserve is only read, so one serves
/// several searches, each leaving out more.
#[doc(hidden)]
pub fn runner_up(
    prepared: &Prepared,
    grid: &CandidateGrid,
    cap: f64,
    reserve: &Reserve,
) -> (Option<Scored>, BranchAndBoundStats) {
    BranchAndBound::new(prepared, grid, cap).run_from(reserve)
}
