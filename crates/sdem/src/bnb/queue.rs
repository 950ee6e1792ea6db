//! Boxes of candidates and the best-first queue: how a box splits, what waits in the queue, and
//! what a search has found so far and set aside for a second one.

use super::BranchAndBoundStats;
use crate::search::{better, CandidateGrid, Index, Scored};

/// What a box's bound, taken point by point (grouping level 0), learned for the boxes inside it.
#[doc(hidden)]
pub struct PointHint {
    /// The points whose term is `τ²` at every candidate of the box: they are `τ²` in every box
    /// inside it too, and are counted without being bounded again.
    #[doc(hidden)]
    pub saturated: u32,
    /// The other points (indices at level 0), those whose term was largest here first: a box
    /// inside whose bound passes the best cost so far is then cut short after fewer points.
    /// On the bench pairs the boxes cut short had summed 80 % of their points with the points
    /// in a scrambled order.
    #[doc(hidden)]
    pub order: Vec<u32>,
}

/// A box of candidates: inclusive index intervals per axis (x, y, z, heading), halved at powers
/// of two (see [`Node::children`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[doc(hidden)]
pub struct Node {
    #[doc(hidden)]
    pub lo: Index,
    #[doc(hidden)]
    pub hi: Index,
}

impl Node {
    pub(super) fn is_leaf(&self) -> bool {
        self.lo == self.hi
    }

    /// The boxes this one splits into: the axes along which the box reaches farthest (`step`:
    /// metres per index along each axis; within [`SPLIT_TIE`] of the farthest) are halved at the
    /// power of two below their length. Splitting every axis at once (up to 16 children) bounded
    /// 532 boxes in 42–51 ms on the paper's pair, 6,040 in 421–439 ms with ±10° of heading; the
    /// widest axis alone 228 in 23–25 ms and 1,762 in 134–154 ms, the same minima: a thin axis
    /// (the window's ±10 cm of height) is no longer halved with the wide ones, and a box's
    /// children are no more than it takes to tell where the minimum is not.
    #[doc(hidden)]
    pub fn children(&self, step: &[f64; 4]) -> Vec<Node> {
        let reach = |a: usize| (self.hi[a] - self.lo[a] + 1) as f64 * step[a];
        let widest = (0..4)
            .filter(|&a| self.hi[a] > self.lo[a])
            .map(reach)
            .fold(0.0, f64::max);
        let mut out = vec![*self];
        for a in 0..4 {
            let extent = self.hi[a] - self.lo[a] + 1;
            if extent > 1 && reach(a) >= SPLIT_TIE * widest {
                let half = extent.next_power_of_two() / 2;
                let mid = self.lo[a] + half - 1;
                out = out
                    .into_iter()
                    .flat_map(|n| {
                        let mut left = n;
                        let mut right = n;
                        left.hi[a] = mid;
                        right.lo[a] = mid + 1;
                        [left, right]
                    })
                    .collect();
            }
        }
        out
    }
}

/// `limit` with a margin far above rounding: bounds are computed with slack, costs exactly, and a
/// candidate that ties with the best (same cost, lower index) must still be scored to the end.
pub(super) fn with_margin(limit: f64) -> f64 {
    limit * (1.0 + 1e-9) + 1e-15
}

/// An axis is split with the farthest-reaching one when it reaches at least this fraction as far
/// (see [`Node::children`]): 0.7, 0.85 and 0.99 bounded 234, 220 and 228 boxes on the paper's
/// pair, 2,000, 1,820 and 1,762 with ±10° of heading, in times within the runs' spread.
const SPLIT_TIE: f64 = 0.99;

/// A box waiting in the queue, ordered by bound, then by the estimated cost at its centre.
#[derive(Clone)]
pub(super) struct Pending {
    pub(super) bound: f64,
    pub(super) estimate: f64,
    pub(super) node: Node,
    /// What bounding the box point by point learned, for the boxes inside it.
    pub(super) hint: Option<std::sync::Arc<PointHint>>,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    /// Reversed, so that `BinaryHeap` pops the lowest bound first.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other
            .bound
            .total_cmp(&self.bound)
            .then(other.estimate.total_cmp(&self.estimate))
            .then(other.node.lo.cmp(&self.node.lo))
    }
}

/// What one child of an expanded box turned out to be.
pub(super) enum Outcome {
    /// A candidate scored at or below the limit.
    Leaf(Scored),
    /// A candidate above the limit: its cost is at least this.
    LeafAbove(Node, f64),
    /// A box that may hold a candidate below the limit.
    Open(Pending),
    /// A box whose bound lies above the limit.
    Pruned(Pending),
    /// Nothing at all (a candidate left out, or without overlap).
    Closed,
}

/// What a search set aside for later ones with a higher cap (the runner-up and the candidates
/// of other basins after it, see [`runner_up`]): every box it dropped and every candidate it scored or cut short whose bound
/// or cost lay within `ratio` × the best of the moment. With it, the second search starts where
/// the first stopped instead of bounding the whole window again.
///
/// [`runner_up`]: super::runner_up
#[doc(hidden)]
pub struct Reserve {
    ratio: f64,
    pub(super) boxes: Vec<Pending>,
    /// Candidates, with a lower bound on their cost (their cost, when scored).
    pub(super) leaves: Vec<(Node, f64)>,
}

/// What a search has found so far, and what it set aside: one per search, shared by its workers.
pub(super) struct Progress {
    /// [`BranchAndBound::cap`], which the limit never exceeds.
    ///
    /// [`BranchAndBound::cap`]: super::BranchAndBound::cap
    cap: f64,
    pub(super) best: Option<Scored>,
    pub(super) stats: BranchAndBoundStats,
    /// Set aside for a second search, when asked.
    reserve: Option<Reserve>,
}

impl Progress {
    pub(super) fn new(cap: f64, reserve_ratio: Option<f64>) -> Self {
        Self {
            cap,
            best: None,
            stats: BranchAndBoundStats::default(),
            reserve: reserve_ratio.map(|ratio| Reserve {
                ratio,
                boxes: Vec::new(),
                leaves: Vec::new(),
            }),
        }
    }

    /// The cost below which a candidate is of interest: the best so far, or the cap.
    pub(super) fn limit(&self) -> f64 {
        self.best.map_or(self.cap, |(cost, _)| cost.min(self.cap))
    }

    pub(super) fn prunable(&self, bound: f64) -> bool {
        bound > with_margin(self.limit())
    }

    /// Where a box's bound may stop summing: the limit, or with a reserve its ratio × the limit.
    /// With a reserve, a box's bound is summed on up to the reserve's ratio × the best, not cut
    /// short at the best: one that ends below is set aside with its whole bound, one cut short
    /// above can hold no runner-up at all. Re-bounding the boxes cut short at the best cost the
    /// runner-up search 10–270 ms a bench pair; this way the first search's bounds take a few
    /// more points, and 50 bench pairs went from 149–157 to 127–129 ms. Resuming the bounds cut
    /// short at the best from where they stopped, when the runner-up search reaches them, was
    /// 1–3 ms a pair slower still: with no runner-up below the cap it sums on most of them.
    pub(super) fn cut(&self) -> f64 {
        let limit = self.limit();
        self.reserve.as_ref().map_or(limit, |r| r.ratio * limit)
    }

    /// Keeps a box dropped against the current best for a second search, when it may hold a
    /// candidate within the reserve's ratio of the best.
    pub(super) fn set_aside_box(&mut self, p: Pending) {
        let limit = self.limit();
        if let Some(r) = self.reserve.as_mut() {
            if p.bound <= with_margin(r.ratio * limit) {
                r.boxes.push(p);
            }
        }
    }

    /// Keeps a candidate for a second search (see [`Self::set_aside_box`]).
    fn set_aside_leaf(&mut self, node: Node, lower_bound: f64) {
        let limit = self.limit();
        if let Some(r) = self.reserve.as_mut() {
            if lower_bound <= with_margin(r.ratio * limit) {
                r.leaves.push((node, lower_bound));
            }
        }
    }

    /// Takes in what bounding or scoring `children` turned out: updates the best candidate and
    /// the counts, sets aside what is dropped, and returns the boxes still open.
    pub(super) fn absorb(
        &mut self,
        grid: &CandidateGrid,
        children: &[(Node, Option<&PointHint>)],
        outcomes: Vec<Outcome>,
    ) -> Vec<Pending> {
        let mut open = Vec::new();
        for ((child, _), outcome) in children.iter().zip(outcomes) {
            if child.is_leaf() {
                self.stats.leaves_evaluated += 1;
            } else {
                self.stats.nodes_bounded += 1;
            }
            match outcome {
                Outcome::Leaf(s) => {
                    if self.best.is_none_or(|b| better(&s, &b)) {
                        if let Some(old) = self.best.replace(s) {
                            let node = grid.index(old.1);
                            self.set_aside_leaf(Node { lo: node, hi: node }, old.0);
                        }
                    } else {
                        self.set_aside_leaf(*child, s.0);
                    }
                }
                Outcome::LeafAbove(node, lower_bound) => self.set_aside_leaf(node, lower_bound),
                Outcome::Open(p) if self.prunable(p.bound) => self.set_aside_box(p),
                Outcome::Open(p) => open.push(p),
                Outcome::Pruned(p) => self.set_aside_box(p),
                Outcome::Closed => {}
            }
        }
        open
    }

    /// The best candidate, the counts, and what was set aside within the reserve's ratio of the
    /// final best.
    pub(super) fn finish(mut self) -> (Option<Scored>, BranchAndBoundStats, Option<Reserve>) {
        let limit = self.limit();
        if let Some(r) = self.reserve.as_mut() {
            let keep = with_margin(r.ratio * limit);
            r.boxes.retain(|p| p.bound <= keep);
            r.leaves.retain(|l| l.1 <= keep);
        }
        (self.best, self.stats, self.reserve)
    }
}
