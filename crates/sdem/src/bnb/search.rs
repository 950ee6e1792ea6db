//! The search itself: what it prepares once per reference/query pair, and the best-first loop
//! over boxes (a first dive, then one worker per thread on a shared queue).

use super::groups::QueryGroups;
use super::queue::{with_margin, Node, Outcome, Pending, PointHint, Progress, Reserve};
use super::tables::RangeTables;
use super::BranchAndBoundStats;
use crate::cost::{Capped, Correlator};
use crate::sdem::Sdem;
use crate::search::{better, CandidateGrid, Scored};
use rayon::prelude::*;

/// [`BranchAndBound::run_from`] scores the reserve's candidates this many per worker at a time,
/// each batch against the best found before it.
const RESERVE_BATCH_PER_WORKER: usize = 4;

/// The least candidates in a grid for [`BranchAndBound::polish`] to descend from the dive's.
const POLISHED_GRID: usize = 4096;

/// What the workers of [`BranchAndBound::best_first`] share.
struct Shared {
    queue: std::collections::BinaryHeap<Pending>,
    progress: Progress,
    /// Workers bounding a box's children at the moment (their children may still open boxes).
    busy: usize,
    /// Workers waiting for boxes: a worker that puts boxes back wakes them only when there
    /// are any (a notification is a system call even when no one waits).
    waiting: usize,
}

/// The search: what it reads, the same for every worker.
#[doc(hidden)]
pub struct BranchAndBound<'a> {
    pub(super) reference: &'a Sdem,
    pub(super) grid: &'a CandidateGrid,
    pub(super) tables: &'a RangeTables,
    pub(super) groups: &'a QueryGroups,
    pub(super) truncation_sq: f32,
    /// Only candidates costing at most this are of interest (∞: all).
    cap: f64,
    /// Cloned for each worker that scores candidates.
    pub(super) prototype: &'a Correlator<'a>,
    /// Metres per index along x, y, z and heading (a heading step times the query's median
    /// horizontal range: how far it moves a typical point), for choosing which axes to split.
    #[doc(hidden)]
    pub axis_step: [f64; 4],
}

impl<'a> BranchAndBound<'a> {
    /// A search of `grid` for candidates costing at most `cap`.
    #[doc(hidden)]
    pub fn new(prepared: &'a Prepared<'a>, grid: &'a CandidateGrid, cap: f64) -> Self {
        Self {
            reference: prepared.correlator.reference(),
            grid,
            tables: prepared.tables,
            groups: &prepared.groups,
            truncation_sq: prepared.correlator.truncation_sq(),
            cap,
            prototype: &prepared.correlator,
            axis_step: {
                let yaw_step = match grid.yaws.as_slice() {
                    [a, b, ..] => (b - a).abs(),
                    _ => 0.0,
                };
                let s = grid.step;
                [s, s, s, yaw_step * prepared.median_horizontal_m]
            },
        }
    }

    /// Runs the search over the whole grid; returns the exhaustive search's minimum.
    ///
    /// Best first: the box with the lowest bound is expanded next, so no box whose bound lies
    /// above the minimum is ever expanded. A first dive (always into the most promising child)
    /// finds a good candidate early, against which every later box and candidate is cut short.
    pub(super) fn run(
        &self,
        reserve_ratio: Option<f64>,
    ) -> (Option<Scored>, BranchAndBoundStats, Option<Reserve>) {
        let mut progress = Progress::new(self.cap, reserve_ratio);
        let c = self.grid.counts;
        let root = Node {
            lo: [0; 4],
            hi: [c[0] - 1, c[1] - 1, c[2] - 1, c[3] - 1],
        };
        if root.is_leaf() {
            let mut correlator = self.correlator();
            progress.best = self.score_leaf(&mut correlator, &root, self.cap);
            progress.stats.leaves_evaluated += 1;
            return (progress.best, progress.stats, None);
        }
        let mut queue = std::collections::BinaryHeap::new();
        // The dive.
        let mut current = Some(Pending {
            bound: 0.0,
            estimate: 0.0,
            node: root,
            hint: None,
        });
        while let Some(node) = current.take() {
            let mut open = self.expand(&mut progress, &node);
            open.sort_by(|a, b| b.cmp(a));
            let mut open = open.into_iter();
            current = open.next();
            queue.extend(open);
        }
        self.polish(&mut progress);
        self.best_first(progress, queue)
    }

    /// A search for the best candidate below the cap among what `reserve` holds (the grid may
    /// now leave out candidates the first search had).
    pub(super) fn run_from(&self, reserve: &Reserve) -> (Option<Scored>, BranchAndBoundStats) {
        let mut progress = Progress::new(self.cap, None);
        let cap = self.cap;
        // The candidates, lowest bound first: their bounds are their costs where the first
        // search scored them, and nearly so where it cut their sums short, so the best comes
        // first and every candidate after it whose bound lies above it is left unscored.
        let mut leaves: Vec<(f64, usize, Node)> = reserve
            .leaves
            .iter()
            .filter(|(node, lb)| *lb <= with_margin(cap) && !self.grid.excluded(node.lo))
            .map(|&(node, lb)| (lb, self.grid.flat(node.lo), node))
            .collect();
        leaves.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        // A few per worker at a time, each against the best found before them.
        let batch = RESERVE_BATCH_PER_WORKER * rayon::current_num_threads().max(1);
        for chunk in leaves.chunks(batch) {
            let limit = progress.limit();
            let open: Vec<Node> = (chunk.iter())
                .take_while(|(lb, _, _)| !progress.prunable(*lb))
                .map(|&(_, _, node)| node)
                .collect();
            if open.is_empty() {
                break;
            }
            progress.stats.leaves_evaluated += open.len();
            let scored: Vec<Option<Scored>> = open
                .par_iter()
                .map_init(
                    || self.correlator(),
                    |correlator, node| self.score_leaf(correlator, node, limit),
                )
                .collect();
            for s in scored.into_iter().flatten() {
                if progress.best.is_none_or(|b| better(&s, &b)) {
                    progress.best = Some(s);
                }
            }
        }
        let boxes: Vec<Pending> = reserve
            .boxes
            .iter()
            .filter(|p| {
                !progress.prunable(p.bound) && !self.grid.box_excluded(p.node.lo, p.node.hi)
            })
            .cloned()
            .collect();
        // A box whose bound the first search cut short (its estimate is then ∞) holds only a
        // partial sum: bounded again against this search's limit, most drop out. (Rare: with a
        // reserve the first search sums bounds up to the reserve's ratio, see `Progress::cut`.)
        let limit = progress.limit();
        let boxes: Vec<Pending> = boxes
            .into_par_iter()
            .map(|p| {
                if p.estimate.is_finite() {
                    return p;
                }
                let (bound, estimate, hint) = self.bound_below(&p.node, limit, p.hint.as_deref());
                Pending {
                    bound,
                    estimate,
                    node: p.node,
                    hint: hint.map(std::sync::Arc::new),
                }
            })
            .collect();
        progress.stats.nodes_bounded += boxes.iter().filter(|p| p.estimate.is_finite()).count();
        let queue: std::collections::BinaryHeap<Pending> = boxes
            .into_iter()
            .filter(|p| !progress.prunable(p.bound))
            .collect();
        let (best, stats, _) = self.best_first(progress, queue);
        (best, stats)
    }

    /// Expands the queue's boxes, lowest bound first, until every box left is above the best.
    ///
    /// One worker per thread, each taking the lowest box of a shared queue, bounding its
    /// children alone and putting the open ones back: no worker waits for another's boxes, as
    /// a batch bounded in parallel must for its slowest child (the boxes' bounds take 5–140 µs).
    /// A worker that finds the queue empty, or its lowest box above the best, waits while
    /// another is still bounding (whose children may open boxes); the search ends when none is.
    /// The minimum is the same whatever order the workers finish in; the boxes bounded, a few
    /// more or fewer from run to run.
    fn best_first(
        &self,
        progress: Progress,
        queue: std::collections::BinaryHeap<Pending>,
    ) -> (Option<Scored>, BranchAndBoundStats, Option<Reserve>) {
        let shared = std::sync::Mutex::new(Shared {
            queue,
            progress,
            busy: 0,
            waiting: 0,
        });
        let wake = std::sync::Condvar::new();
        rayon::scope(|scope| {
            for _ in 0..rayon::current_num_threads().max(1) {
                scope.spawn(|_| self.work(&shared, &wake));
            }
        });
        let Shared {
            queue,
            mut progress,
            ..
        } = shared
            .into_inner()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        for p in queue {
            progress.set_aside_box(p);
        }
        progress.finish()
    }

    /// One worker of [`Self::best_first`].
    fn work(&self, shared: &std::sync::Mutex<Shared>, wake: &std::sync::Condvar) {
        let lock = || {
            shared
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
        };
        let mut correlator = None;
        let mut state = lock();
        loop {
            let open = state
                .queue
                .peek()
                .is_some_and(|top| !state.progress.prunable(top.bound));
            if !open {
                if state.busy == 0 {
                    if state.waiting > 0 {
                        wake.notify_all();
                    }
                    return;
                }
                state.waiting += 1;
                state = wake
                    .wait(state)
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                state.waiting -= 1;
                continue;
            }
            let parent = state.queue.pop().expect("peeked");
            state.busy += 1;
            let (limit, cut) = (state.progress.limit(), state.progress.cut());
            drop(state);
            let children = self.children_of(&parent);
            let outcomes: Vec<Outcome> = children
                .iter()
                .map(|(child, hint)| self.outcome(child, *hint, limit, cut, &mut correlator))
                .collect();
            state = lock();
            let open = state.progress.absorb(self.grid, &children, outcomes);
            state.queue.extend(open);
            state.busy -= 1;
            if state.waiting > 0 {
                wake.notify_all();
            }
        }
    }

    /// Descends from the dive's candidate to a local minimum of the cost, which becomes the best
    /// so far when lower. Every box the best-first loop bounds is then cut short against a
    /// lower cost: on the 50 bench pairs the dive's candidate cost 1.4× the minimum on average
    /// (1.0 on 24 pairs), after the descent 1.0 on 24 more; the bound's instructions fell by 6 %
    /// for 2.6 % more in scoring candidates. Descents from the centres of the 4 or 16 open boxes
    /// that cost least at their centres found the minimum more often (on 35 and 39 pairs) but
    /// saved little more in bounds and cost 4 and 15 times as much in scoring.
    ///
    /// The candidates scored here lie in boxes still queued (or in boxes the dive already
    /// scored), so what the best-first loop drops or sets aside is unchanged, and with it the
    /// minimum and the runner-up's reserve. Grids of fewer than [`POLISHED_GRID`] candidates
    /// are left as they are: their whole search scores a few dozen candidates, as many as a
    /// descent.
    fn polish(&self, progress: &mut Progress) {
        if self.grid.len() < POLISHED_GRID {
            return;
        }
        let Some(dived) = progress.best else { return };
        let mut correlator = self.correlator();
        let mut scored = 0;
        let found = self.descend(&mut correlator, dived, &mut scored);
        progress.stats.leaves_evaluated += scored;
        if better(&found, &dived) {
            let at = self.grid.index(found.1);
            let node = Node { lo: at, hi: at };
            progress.absorb(self.grid, &[(node, None)], vec![Outcome::Leaf(found)]);
        }
    }

    /// A local minimum of the cost over the grid's neighbours (steps of 4, 2, then 1 index along
    /// each axis), from the scored candidate `start`; `scored` counts the candidates scored.
    fn descend(
        &self,
        correlator: &mut Correlator<'a>,
        start: Scored,
        scored: &mut usize,
    ) -> Scored {
        let counts = self.grid.counts;
        let mut best = start;
        for stride in [4usize, 2, 1] {
            loop {
                let at = self.grid.index(best.1);
                let mut moved = false;
                for a in 0..4 {
                    let below = at[a].checked_sub(stride);
                    let above = Some(at[a] + stride).filter(|&i| i < counts[a]);
                    for i in below.into_iter().chain(above) {
                        let mut idx = at;
                        idx[a] = i;
                        *scored += 1;
                        let leaf = Node { lo: idx, hi: idx };
                        if let Outcome::Leaf(s) = self.try_leaf(correlator, &leaf, best.0) {
                            if better(&s, &best) {
                                best = s;
                                moved = true;
                            }
                        }
                    }
                }
                if !moved {
                    break;
                }
            }
        }
        best
    }

    fn correlator(&self) -> Correlator<'a> {
        (*self.prototype).clone()
    }

    fn score_leaf(&self, correlator: &mut Correlator, node: &Node, limit: f64) -> Option<Scored> {
        match self.try_leaf(correlator, node, limit) {
            Outcome::Leaf(s) => Some(s),
            _ => None,
        }
    }

    /// Scores one candidate against the limit.
    fn try_leaf(&self, correlator: &mut Correlator, node: &Node, limit: f64) -> Outcome {
        self.try_leaf_hinted(correlator, node, limit, limit, None)
    }

    /// Scores one candidate against the limit, first from what its box's bound learned
    /// (`hint`): its saturated points counted, the others largest term first, summed up to
    /// `cut` (the limit, or with a reserve its ratio × the limit). A candidate whose sum passes
    /// the limit so is dropped, or set aside with that sum as its bound; only one that stays
    /// below is scored in the cost's own order, whose sum is the exact cost. On the unlevelled
    /// suite's quick pairs the candidates above the limit had summed 97 % of their points in
    /// the cost's order before their sums passed it.
    fn try_leaf_hinted(
        &self,
        correlator: &mut Correlator,
        node: &Node,
        limit: f64,
        cut: f64,
        hint: Option<&PointHint>,
    ) -> Outcome {
        let idx = node.lo;
        if self.grid.excluded(idx) {
            return Outcome::Closed;
        }
        let (offset, yaw) = (self.grid.offset(idx), self.grid.yaw(idx));
        if let Some(hint) = hint {
            let reached = correlator.ordered_lower_bound(
                &offset,
                yaw,
                hint.saturated,
                &hint.order,
                with_margin(cut),
            );
            if reached > with_margin(limit) {
                return Outcome::LeafAbove(*node, reached);
            }
        }
        let cap = with_margin(limit);
        match correlator.evaluate_within(&offset, yaw, cap) {
            Capped::Scored(c) if c.cost <= self.cap => Outcome::Leaf((c.cost, self.grid.flat(idx))),
            Capped::Scored(c) => Outcome::LeafAbove(*node, c.cost),
            Capped::Above(partial) => Outcome::LeafAbove(*node, partial),
            Capped::NoOverlap => Outcome::Closed,
        }
    }

    /// The children of `parent` the grid does not leave out, each with what the parent's bound
    /// learned for them.
    fn children_of<'p>(&self, parent: &'p Pending) -> Vec<(Node, Option<&'p PointHint>)> {
        let hint = parent.hint.as_deref();
        parent
            .node
            .children(&self.axis_step)
            .into_iter()
            .filter(|c| !self.grid.box_excluded(c.lo, c.hi))
            .map(|c| (c, hint))
            .collect()
    }

    /// Bounds a box, or scores a candidate, against `limit` (a box's bound summed up to `cut`).
    fn outcome(
        &self,
        child: &Node,
        hint: Option<&PointHint>,
        limit: f64,
        cut: f64,
        correlator: &mut Option<Correlator<'a>>,
    ) -> Outcome {
        if child.is_leaf() {
            let correlator = correlator.get_or_insert_with(|| self.correlator());
            return self.try_leaf_hinted(correlator, child, limit, cut, hint);
        }
        let (bound, estimate, hint) = self.bound_below(child, cut, hint);
        let pending = Pending {
            bound,
            estimate,
            node: *child,
            hint: hint.map(std::sync::Arc::new),
        };
        if bound > with_margin(limit) {
            Outcome::Pruned(pending)
        } else {
            Outcome::Open(pending)
        }
    }

    /// Bounds or scores the children of `parent` in parallel against the current limit; updates
    /// the best candidate and returns the boxes still open (for the dive).
    fn expand(&self, progress: &mut Progress, parent: &Pending) -> Vec<Pending> {
        let children = self.children_of(parent);
        let (limit, cut) = (progress.limit(), progress.cut());
        let outcomes: Vec<Outcome> = children
            .par_iter()
            .map_init(
                || None,
                |correlator, (child, hint)| self.outcome(child, *hint, limit, cut, correlator),
            )
            .collect();
        progress.absorb(self.grid, &children, outcomes)
    }
}

/// What the search precomputes for one reference/query pair: the reference's range tables, the
/// query's groups, and the correlator that scores candidates. Built once per localization and
/// shared by its searches (the best and the runner-up).
#[doc(hidden)]
pub struct Prepared<'a> {
    tables: &'a RangeTables,
    groups: QueryGroups,
    /// The compared points' median horizontal distance from the query's origin, metres.
    median_horizontal_m: f64,
    correlator: Correlator<'a>,
}

impl<'a> Prepared<'a> {
    /// Prepares the search of `correlator`'s pair (projective cost): groups of the points it
    /// compares.
    pub fn new(correlator: &Correlator<'a>) -> Self {
        let points = correlator.search_points();
        let mut horizontal: Vec<f64> = points
            .iter()
            .map(|p| (p[0] as f64).hypot(p[1] as f64))
            .collect();
        let median_horizontal_m = if horizontal.is_empty() {
            1.0
        } else {
            let k = horizontal.len() / 2;
            *horizontal.select_nth_unstable_by(k, f64::total_cmp).1
        };
        let (tables, groups) = rayon::join(
            || RangeTables::of(correlator.reference()),
            || QueryGroups::new(&points, 6),
        );
        Self {
            tables,
            groups,
            median_horizontal_m,
            correlator: correlator.clone(),
        }
    }
}
