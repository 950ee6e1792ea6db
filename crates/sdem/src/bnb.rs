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

use crate::cost::{Capped, Correlator};
use crate::geometry::fast_atan2;
use crate::geometry::FAST_ATAN2_MAX_ERROR;
use crate::sdem::Sdem;
use crate::sdem::{floor_i32, wrap_column};
use crate::search::{better, CandidateGrid, Index, Scored};
use rayon::prelude::*;

/// The reference S-DEM's cells as the search reads them: each cell's plane (for the cone loop),
/// and the range gates' extent over coarse blocks of cells (for cones too large to visit).
#[doc(hidden)]
pub struct RangeTables {
    n_az: usize,
    n_el: usize,
    full_circle: bool,
    /// `(min lo, max hi)` of the gates over each block of [`BLOCK`] × [`BLOCK`] cells (of the
    /// stored columns), `block_columns` blocks a row; `(∞, −∞)` where every cell is unknown.
    blocks: Vec<(f32, f32)>,
    block_columns: usize,
    global: (f32, f32),
    /// The cells' planes, laid out for the cone loop of [`reach_bound`].
    planes: PlaneRows,
    elevation_min: f32,
    azimuth_min: f32,
    inv_resolution: f32,
}

/// Side of the blocks of [`RangeTables::blocks`], cells: the cones they answer for (more than
/// [`MAX_CONE_CELLS`]) span a few blocks each way.
const BLOCK: usize = 8;

const EMPTY: (f32, f32) = (f32::INFINITY, f32::NEG_INFINITY);

fn merge(a: (f32, f32), b: (f32, f32)) -> (f32, f32) {
    (a.0.min(b.0), a.1.max(b.1))
}

impl RangeTables {
    /// A sparse table (square windows of every power of two at every cell) took 7–8 ms a
    /// localization to build on the full sphere at 1° (eight levels of 130,000 entries), a
    /// tenth of a bench pair; the cone loop, once vectorized, no longer gained from asking it
    /// before visiting cones of 5–256 cells. Blocks answer for the larger cones.
    pub fn new(reference: &Sdem) -> Self {
        let grid = reference.grid();
        let (n_az, n_el) = (grid.azimuth_cells(), grid.elevation_cells());
        let config = reference.config();
        let full_circle = (config.azimuth_max_deg - config.azimuth_min_deg - 360.0).abs() < 1e-9;
        let width = if full_circle { 2 * n_az } else { n_az };
        let cells = &reference.surfaces().cells;
        let block_columns = width.div_ceil(BLOCK);
        let mut blocks = vec![EMPTY; n_el.div_ceil(BLOCK) * block_columns];
        // A row of blocks at a time, in parallel, beside the planes' rows.
        let (global, planes) = rayon::join(
            || {
                blocks
                    .par_chunks_mut(block_columns)
                    .enumerate()
                    .map(|(b, row)| {
                        let mut global = EMPTY;
                        for e in b * BLOCK..((b + 1) * BLOCK).min(n_el) {
                            for a in 0..width {
                                let c = &cells[e * n_az + if a < n_az { a } else { a - n_az }];
                                // Unknown cells (NaN) leave the block as it is.
                                if c.lo <= c.hi {
                                    row[a / BLOCK] = merge(row[a / BLOCK], (c.lo, c.hi));
                                    global = merge(global, (c.lo, c.hi));
                                }
                            }
                        }
                        global
                    })
                    .reduce(|| EMPTY, merge)
            },
            || PlaneRows::new(cells, n_az, n_el, width),
        );
        Self {
            n_az,
            n_el,
            full_circle,
            blocks,
            block_columns,
            global,
            planes,
            elevation_min: config.elevation_min_deg.to_radians() as f32,
            azimuth_min: config.azimuth_min_deg.to_radians() as f32,
            inv_resolution: (1.0 / config.resolution_deg.to_radians()) as f32,
        }
    }

    /// The index of the cell at row `e`, column `a` (columns wrap on a full circle), or `None`
    /// outside the grid.
    #[inline]
    fn cell(&self, e: i32, a: i32) -> Option<usize> {
        if e < 0 || e >= self.n_el as i32 {
            return None;
        }
        let a = if self.full_circle {
            wrap_column(a, self.n_az as i32)
        } else if a < 0 || a >= self.n_az as i32 {
            return None;
        } else {
            a
        };
        Some(e as usize * self.n_az + a as usize)
    }

    /// `(min, max)` of the gates over (at least) rows `e0..=e1` and columns `a0..=a1` (columns
    /// may run past `n_az` on a full circle; `a1 < width`); `(∞, −∞)` where every cell is
    /// unknown.
    fn window(&self, e0: usize, e1: usize, a0: usize, a1: usize) -> (f32, f32) {
        let mut acc = EMPTY;
        for be in e0 / BLOCK..=e1 / BLOCK {
            let row = &self.blocks[be * self.block_columns..][..self.block_columns];
            for &b in &row[a0 / BLOCK..=a1 / BLOCK] {
                acc = merge(acc, b);
            }
        }
        acc
    }
}

/// Cells a cone's row is read at a time in [`reach_bound`].
const LANES: usize = 8;

/// The reference's cell planes (see [`crate::sdem::CellPlane`]), one array per quantity, so that
/// the cells of a cone's row are bounded [`LANES`] at a time (the compiler vectorizes it). Rows are
/// stored `stride` apart: the table's columns (twice the azimuth cells on a full circle, so a
/// window that wraps is one run), then [`LANES`] unknown cells, so a row can be read past its end.
/// An unknown cell has a zero normal and an empty gate (`lo` = ∞, `hi` = −∞): it costs `τ²`.
struct PlaneRows {
    stride: usize,
    nx: Vec<f32>,
    ny: Vec<f32>,
    nz: Vec<f32>,
    d: Vec<f32>,
    lo: Vec<f32>,
    hi: Vec<f32>,
}

impl PlaneRows {
    fn new(cells: &[crate::sdem::CellPlane], n_az: usize, n_el: usize, width: usize) -> Self {
        let stride = width + LANES;
        let len = n_el * stride;
        let mut out = Self {
            stride,
            nx: vec![0.0; len],
            ny: vec![0.0; len],
            nz: vec![0.0; len],
            d: vec![0.0; len],
            lo: vec![f32::INFINITY; len],
            hi: vec![f32::NEG_INFINITY; len],
        };
        // Row by row in parallel.
        (
            out.nx.par_chunks_mut(stride),
            out.ny.par_chunks_mut(stride),
            out.nz.par_chunks_mut(stride),
            out.d.par_chunks_mut(stride),
            out.lo.par_chunks_mut(stride),
            out.hi.par_chunks_mut(stride),
        )
            .into_par_iter()
            .enumerate()
            .for_each(|(e, (nx, ny, nz, d, lo, hi))| {
                for a in 0..width {
                    let c = &cells[e * n_az + if a < n_az { a } else { a - n_az }];
                    if c.n[0].is_nan() {
                        continue;
                    }
                    (nx[a], ny[a], nz[a]) = (c.n[0], c.n[1], c.n[2]);
                    (d[a], lo[a], hi[a]) = (c.d, c.lo, c.hi);
                }
            });
        out
    }
}

/// One query point, or a group of nearby ones that share a bound.
#[derive(Clone, Copy, Debug)]
struct Group {
    center: [f32; 3],
    radius: f32,
    /// Horizontal distance of the farthest member from the z axis (for the heading chord).
    horizontal: f32,
    count: u32,
}

/// The query's points at several groupings: level 0 one point per group; level `m` the points in
/// one cube of side `2^m` cm.
#[doc(hidden)]
pub struct QueryGroups {
    /// The groups of each level, one field per array (for the vectorized bound).
    balls: Vec<Balls>,
    /// The 75th-percentile group radius of each level, metres.
    typical_radius: Vec<f32>,
    /// The number of query points (the sum of every level's counts).
    points: usize,
}

impl QueryGroups {
    /// Groups `points` (the points the cost compares) at `levels` levels.
    pub fn new(points: &[[f32; 3]], levels: usize) -> Self {
        // A run of `(cube, point)` keys: one group, its members in the points' order.
        let make = |run: &[([i32; 3], usize)]| -> Group {
            let members = || run.iter().map(|&(_, i)| i);
            let mut c = [0f64; 3];
            for i in members() {
                for a in 0..3 {
                    c[a] += points[i][a] as f64;
                }
            }
            let n = run.len() as f64;
            let center = [(c[0] / n) as f32, (c[1] / n) as f32, (c[2] / n) as f32];
            let mut radius = 0f32;
            let mut horizontal = 0f32;
            for i in members() {
                let p = points[i];
                let d = ((p[0] - center[0]).powi(2)
                    + (p[1] - center[1]).powi(2)
                    + (p[2] - center[2]).powi(2))
                .sqrt();
                radius = radius.max(d);
                horizontal = horizontal.max((p[0] * p[0] + p[1] * p[1]).sqrt());
            }
            // Rounding margin: the members' distance was computed in f32.
            Group {
                center,
                radius: if run.len() == 1 {
                    0.0
                } else {
                    radius * (1.0 + 1e-5) + 1e-6
                },
                horizontal,
                count: run.len() as u32,
            }
        };
        let mut out = Vec::new();
        let mut typical = Vec::new();
        for m in 0..levels.max(1) {
            let mut keys: Vec<([i32; 3], usize)> = if m == 0 {
                (0..points.len()).map(|i| ([i as i32, 0, 0], i)).collect()
            } else {
                let side = 0.01 * (1u32 << m) as f32;
                points
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (p.map(|c| floor_i32(c / side)), i))
                    .collect()
            };
            keys.sort_unstable();
            // In the order of their places (level 0: the S-DEM's cells, as the cost chose the
            // points; coarser: the cubes' raster order), so that one ball after another reads
            // neighbouring cells of the reference. Its planes and rows (~5 MB on the full
            // sphere) do not fit the L2 cache: on the 50 bench pairs this order took 6 % less
            // CPU (5.86-5.96 s against 6.21-6.36 s) than a scrambled one, which made a partial
            // bound a fairer sample, cut short a little sooner.
            let groups: Vec<Group> = keys.chunk_by(|a, b| a.0 == b.0).map(make).collect();
            // A level that hardly groups anything would only lose the finer level's detail.
            if out
                .last()
                .is_some_and(|finer: &Vec<Group>| groups.len() * 5 > finer.len() * 4)
            {
                continue;
            }
            let mut radii: Vec<f32> = groups.iter().map(|g| g.radius).collect();
            radii.sort_by(f32::total_cmp);
            typical.push(radii.get(radii.len() * 3 / 4).copied().unwrap_or(0.0));
            out.push(groups);
        }
        let balls = out
            .into_iter()
            .map(|groups| Balls {
                cx: groups.iter().map(|g| g.center[0]).collect(),
                cy: groups.iter().map(|g| g.center[1]).collect(),
                cz: groups.iter().map(|g| g.center[2]).collect(),
                radius: groups.iter().map(|g| g.radius).collect(),
                horizontal: groups.iter().map(|g| g.horizontal).collect(),
                count: groups.iter().map(|g| g.count).collect(),
            })
            .collect();
        Self {
            balls,
            typical_radius: typical,
            points: points.len(),
        }
    }
}

/// The fields of one grouping's [`Group`]s, one array each.
struct Balls {
    cx: Vec<f32>,
    cy: Vec<f32>,
    cz: Vec<f32>,
    radius: Vec<f32>,
    horizontal: Vec<f32>,
    count: Vec<u32>,
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
    fn is_leaf(&self) -> bool {
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

/// What the search did, for reports and benchmarks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BranchAndBoundStats {
    /// Boxes bounded.
    pub nodes_bounded: usize,
    /// Single candidates scored (each stops as soon as its sum exceeds the best so far).
    pub leaves_evaluated: usize,
}

/// `limit` with a margin far above rounding: bounds are computed with slack, costs exactly, and a
/// candidate that ties with the best (same cost, lower index) must still be scored to the end.
fn with_margin(limit: f64) -> f64 {
    limit * (1.0 + 1e-9) + 1e-15
}

/// A box is bounded from the coarsest grouping whose typical group radius is at most this
/// fraction of the box's reach. Measured with the plane bound (8 cm search cubes; boxes bounded on
/// bench pair 3 / the paper's pair with ±10° of heading): 0.1 → 7,796 / 5,744, 0.3 → 7,796 /
/// 6,136, 0.6 → 12,228 / 9,512, and no faster at 0.2–0.3 (larger groups widen every reach).
const GROUP_REACH_FRACTION: f64 = 0.1;

/// An axis is split with the farthest-reaching one when it reaches at least this fraction as far
/// (see [`Node::children`]): 0.7, 0.85 and 0.99 bounded 234, 220 and 228 boxes on the paper's
/// pair, 2,000, 1,820 and 1,762 with ±10° of heading, in times within the runs' spread.
const SPLIT_TIE: f64 = 0.99;

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

/// A box waiting in the queue, ordered by bound, then by the estimated cost at its centre.
struct Pending {
    bound: f64,
    estimate: f64,
    node: Node,
    /// What bounding the box point by point learned, for the boxes inside it.
    hint: Option<std::sync::Arc<PointHint>>,
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
enum Outcome {
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

/// What a search set aside for a second one with a higher cap (the runner-up, see
/// [`runner_up`]): every box it dropped and every candidate it scored or cut short whose bound
/// or cost lay within `ratio` × the best of the moment. With it, the second search starts where
/// the first stopped instead of bounding the whole window again.
#[doc(hidden)]
pub struct Reserve {
    ratio: f64,
    boxes: Vec<Pending>,
    /// Candidates, with a lower bound on their cost (their cost, when scored).
    leaves: Vec<(Node, f64)>,
}

/// What a search has found so far, and what it set aside: one per search, shared by its workers.
struct Progress {
    /// [`BranchAndBound::cap`], which the limit never exceeds.
    cap: f64,
    best: Option<Scored>,
    stats: BranchAndBoundStats,
    /// Set aside for a second search, when asked.
    reserve: Option<Reserve>,
}

impl Progress {
    fn new(cap: f64, reserve_ratio: Option<f64>) -> Self {
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
    fn limit(&self) -> f64 {
        self.best.map_or(self.cap, |(cost, _)| cost.min(self.cap))
    }

    fn prunable(&self, bound: f64) -> bool {
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
    fn cut(&self) -> f64 {
        let limit = self.limit();
        self.reserve.as_ref().map_or(limit, |r| r.ratio * limit)
    }

    /// Keeps a box dropped against the current best for a second search, when it may hold a
    /// candidate within the reserve's ratio of the best.
    fn set_aside_box(&mut self, p: Pending) {
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
    fn absorb(
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
    fn finish(mut self) -> (Option<Scored>, BranchAndBoundStats, Option<Reserve>) {
        let limit = self.limit();
        if let Some(r) = self.reserve.as_mut() {
            let keep = with_margin(r.ratio * limit);
            r.boxes.retain(|p| p.bound <= keep);
            r.leaves.retain(|l| l.1 <= keep);
        }
        (self.best, self.stats, self.reserve)
    }
}

/// What the workers of [`BranchAndBound::best_first`] share.
struct Shared {
    queue: std::collections::BinaryHeap<Pending>,
    progress: Progress,
    /// Workers bounding a box's children at the moment (their children may still open boxes).
    busy: usize,
}

/// The search: what it reads, the same for every worker.
#[doc(hidden)]
pub struct BranchAndBound<'a> {
    reference: &'a Sdem,
    grid: &'a CandidateGrid,
    tables: &'a RangeTables,
    groups: &'a QueryGroups,
    truncation_sq: f32,
    /// Only candidates costing at most this are of interest (∞: all).
    cap: f64,
    /// Cloned for each worker that scores candidates.
    prototype: &'a Correlator<'a>,
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
            tables: &prepared.tables,
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
    fn run(
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
        self.best_first(progress, queue)
    }

    /// A search for the best candidate below the cap among what `reserve` holds (the grid may
    /// now leave out candidates the first search had).
    fn run_from(&self, reserve: Reserve) -> (Option<Scored>, BranchAndBoundStats) {
        let mut progress = Progress::new(self.cap, None);
        let cap = self.cap;
        let leaves: Vec<Node> = reserve
            .leaves
            .iter()
            .filter(|(node, lb)| *lb <= with_margin(cap) && !self.grid.excluded(node.lo))
            .map(|(node, _)| *node)
            .collect();
        let scored: Vec<Option<Scored>> = leaves
            .par_iter()
            .map_init(
                || self.correlator(),
                |correlator, node| self.score_leaf(correlator, node, cap),
            )
            .collect();
        progress.stats.leaves_evaluated += leaves.len();
        for s in scored.into_iter().flatten() {
            if progress.best.is_none_or(|b| better(&s, &b)) {
                progress.best = Some(s);
            }
        }
        let boxes: Vec<Pending> = reserve
            .boxes
            .into_iter()
            .filter(|p| {
                !progress.prunable(p.bound) && !self.grid.box_excluded(p.node.lo, p.node.hi)
            })
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
                    hint: hint.map(std::sync::Arc::new).or(p.hint),
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
                    wake.notify_all();
                    return;
                }
                state = wake
                    .wait(state)
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
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
            wake.notify_all();
        }
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
        let idx = node.lo;
        if self.grid.excluded(idx) {
            return Outcome::Closed;
        }
        let cap = with_margin(limit);
        match correlator.evaluate_within(&self.grid.offset(idx), self.grid.yaw(idx), cap) {
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
            return self.try_leaf(correlator, child, limit);
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

    /// A lower bound on the cost of every candidate in `node`, and an estimate of the cost at
    /// its centre (the groups' centres looked up in their cells; only for ordering the search).
    #[doc(hidden)]
    pub fn bound(&self, node: &Node) -> (f64, f64) {
        let (bound, estimate, _) = self.bound_below(node, f64::INFINITY, None);
        (bound, estimate)
    }

    /// [`Self::bound`], cut short once the bound exceeds `limit` (then the partial sum is
    /// returned: a weaker bound, but above the limit all the same).
    ///
    /// Every member of a ball (a query point, or a group of nearby ones around their centre) lies,
    /// at every candidate of the box, within the box's translation of the ball centre's position
    /// at the box's middle candidate, plus the arc the heading interval turns it through, plus the
    /// group's radius. That region sees the reference through a cone of cells; in each, the
    /// distance to the cell's plane can shrink by at most the region's extent along its normal.
    /// The smallest over the cone's cells is a lower bound on the member's term (`τ²` for a cell
    /// the reference does not see, or a range out of the cell's gate).
    ///
    /// Compiled twice: for the baseline x86-64 the build targets (four lanes) and for AVX2
    /// (eight lanes), chosen at run time; both compute the same values, bit for bit (the same
    /// operations in the same order, no fused multiply-add).
    fn bound_below(
        &self,
        node: &Node,
        limit: f64,
        parent: Option<&PointHint>,
    ) -> (f64, f64, Option<PointHint>) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has just been found to support AVX2.
            return unsafe { self.bound_below_avx2(node, limit, parent) };
        }
        self.bound_below_any(node, limit, parent)
    }

    /// [`Self::bound_below`] with AVX2 instructions.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[doc(hidden)]
    pub unsafe fn bound_below_avx2(
        &self,
        node: &Node,
        limit: f64,
        parent: Option<&PointHint>,
    ) -> (f64, f64, Option<PointHint>) {
        self.bound_below_any(node, limit, parent)
    }

    /// [`Self::bound_below`]'s body, inlined into each of its builds.
    #[inline(always)]
    #[doc(hidden)]
    pub fn bound_below_any(
        &self,
        node: &Node,
        limit: f64,
        parent: Option<&PointHint>,
    ) -> (f64, f64, Option<PointHint>) {
        let grid = self.grid;
        let lo = grid.offset(node.lo);
        let hi = grid.offset(node.hi);
        let centre = (lo + hi) * 0.5;
        let half = ((hi - lo) * 0.5).map(|v| v as f32 + 1e-5);
        let translation_radius = half.norm();
        let (yaw_lo, yaw_hi) = (grid.yaws[node.lo[3]], grid.yaws[node.hi[3]]);
        let yaw_centre = 0.5 * (yaw_lo + yaw_hi);
        // A point at horizontal distance h turns through at most `chord · h` from its position
        // at the middle heading.
        let chord = (2.0 * (0.25 * (yaw_hi - yaw_lo)).sin() * (1.0 + 1e-6)) as f32;
        let delta = 0.5 * (yaw_hi - yaw_lo);
        let turn = (
            ((1.0 - delta.cos()) * (1.0 + 1e-6)) as f32,
            (delta.sin() * (1.0 + 1e-6)) as f32,
        );
        // The coarsest grouping whose groups are small against the box.
        let reach = translation_radius as f64 + chord as f64;
        let level = (0..self.groups.balls.len())
            .rev()
            .find(|&m| self.groups.typical_radius[m] as f64 <= GROUP_REACH_FRACTION * reach)
            .unwrap_or(0);
        let balls = &self.groups.balls[level];
        let total = self.groups.points as f64;
        // Point by point (level 0), what the parent box learned: its saturated points are
        // counted, not bounded, and the others come largest term first.
        let hint = parent.filter(|_| level == 0);
        // The prediction's term is smallest where the box comes nearest the prediction.
        let prior = self.prototype.prior_bound(&lo, &hi);
        let prior_at_centre = self.prototype.prior_cost(&centre);
        let limit_sum = if limit.is_finite() {
            (limit * (1.0 + 1e-9) - prior) * total + 1e-12
        } else {
            f64::INFINITY
        };
        let (sin, cos) = yaw_centre.sin_cos();
        let (sin, cos) = (sin as f32, cos as f32);
        let t = centre.cast::<f32>();
        let tables = self.tables;
        let planes = self.reference.surfaces();
        let truncation_sq = self.truncation_sq;
        let margin = 2.0 * FAST_ATAN2_MAX_ERROR;
        let mut saturated = hint.map_or(0, |h| h.saturated);
        let mut bound_sum = truncation_sq as f64 * saturated as f64;
        let mut estimate_sum = bound_sum;
        if bound_sum > limit_sum {
            return (bound_sum / total + prior, f64::INFINITY, None);
        }
        // The child boxes' order: the terms found here, in four classes, largest first.
        let mut classes: Option<[Vec<u32>; 4]> = (level == 0).then(Default::default);
        const CHUNK: usize = 64;
        // One array per quantity, so the compiler vectorizes the geometry.
        let mut bx = [0f32; CHUNK];
        let mut by = [0f32; CHUNK];
        let mut bz = [0f32; CHUNK];
        let mut br = [0f32; CHUNK];
        let mut bh = [0f32; CHUNK];
        let mut ux = [0f32; CHUNK];
        let mut uy = [0f32; CHUNK];
        let mut uz = [0f32; CHUNK];
        let mut ranges = [0f32; CHUNK];
        let mut horizontals = [0f32; CHUNK];
        let mut laterals = [0f32; CHUNK];
        let mut reaches = [0f32; CHUNK];
        let mut nears = [0f32; CHUNK];
        let mut fars = [0f32; CHUNK];
        let mut spreads = [0f32; CHUNK];
        let mut cells = [[0i32; 6]; CHUNK];
        let order = hint.map(|h| h.order.as_slice());
        let n = order.map_or(balls.cx.len(), <[u32]>::len);
        let ball = |j: usize| order.map_or(j, |o| o[j] as usize);
        for start in (0..n).step_by(CHUNK) {
            let len = CHUNK.min(n - start);
            for i in 0..len {
                let k = ball(start + i);
                (bx[i], by[i], bz[i]) = (balls.cx[k], balls.cy[k], balls.cz[k]);
                (br[i], bh[i]) = (balls.radius[k], balls.horizontal[k]);
            }
            for i in 0..len {
                let (x, y, z) = (bx[i], by[i], bz[i]);
                let u0 = cos * x - sin * y + t.x;
                let u1 = sin * x + cos * y + t.y;
                let u2 = z + t.z;
                // A group member turns about the query origin with its centre, so its offset
                // from the centre keeps its length.
                let spread = br[i] + 1e-4;
                let arc = chord * bh[i];
                let horizontal = (u0 * u0 + u1 * u1).sqrt();
                let range = (horizontal * horizontal + u2 * u2).sqrt();
                let Footprint {
                    lowest,
                    highest,
                    beta,
                    near,
                    far,
                    reach,
                    lateral,
                } = footprint(
                    [u0, u1, u2],
                    [horizontal, range],
                    [half.x, half.y, half.z],
                    arc,
                    spread,
                );
                let elevation = fast_atan2(u2, horizontal);
                let azimuth = fast_atan2(u1, u0);
                let el = (elevation - tables.elevation_min) * tables.inv_resolution;
                let az = (azimuth - tables.azimuth_min) * tables.inv_resolution;
                let db = (beta + margin) * tables.inv_resolution;
                ux[i] = u0;
                uy[i] = u1;
                uz[i] = u2;
                ranges[i] = range;
                horizontals[i] = horizontal;
                laterals[i] = lateral;
                reaches[i] = reach;
                nears[i] = near;
                fars[i] = far;
                spreads[i] = spread;
                cells[i] = [
                    floor_i32((lowest - margin - tables.elevation_min) * tables.inv_resolution),
                    floor_i32((highest + margin - tables.elevation_min) * tables.inv_resolution),
                    floor_i32(az - db),
                    floor_i32(az + db),
                    floor_i32(el),
                    floor_i32(az),
                ];
            }
            for i in 0..len {
                let k = ball(start + i);
                let count = balls.count[k] as f64;
                let [e0, e1, a0, a1, ec, ac] = cells[i];
                let g = Reach {
                    term: ConeTerm {
                        x: [ux[i], uy[i], uz[i]],
                        arm: [ux[i] - t.x, uy[i] - t.y],
                        half: [half.x, half.y, half.z],
                        turn,
                        spread: spreads[i],
                        gate: (nears[i], fars[i]),
                        truncation_sq,
                    },
                    range: ranges[i],
                    holds_origin: ranges[i] <= reaches[i] * 1.0001,
                    holds_axis: horizontals[i] <= laterals[i] * 1.0001,
                    e0,
                    e1,
                    a0,
                    a1,
                    ec,
                    ac,
                };
                let (lb, at_centre) = reach_bound(tables, planes, &g);
                estimate_sum += at_centre as f64 * count;
                bound_sum += lb as f64 * count;
                if let Some(classes) = classes.as_mut() {
                    if lb >= truncation_sq {
                        saturated += 1;
                    } else {
                        let class = if lb >= 0.25 * truncation_sq {
                            0
                        } else if lb >= 0.0625 * truncation_sq {
                            1
                        } else if lb > 0.0 {
                            2
                        } else {
                            3
                        };
                        classes[class].push(k as u32);
                    }
                }
            }
            if bound_sum > limit_sum {
                return (bound_sum / total + prior, f64::INFINITY, None);
            }
        }
        let hint = classes.map(|classes| PointHint {
            saturated,
            order: classes.concat(),
        });
        (
            bound_sum / total + prior,
            estimate_sum / total + prior_at_centre,
            hint,
        )
    }
}

/// Where a ball's members may lie over a box, seen from the reference's origin (see
/// [`footprint`]); angles in radians, before the arctangent's error.
struct Footprint {
    lowest: f32,
    highest: f32,
    /// Azimuth half-width about the centre's azimuth.
    beta: f32,
    /// The members' ranges lie in `[near, far]`.
    near: f32,
    far: f32,
    /// Every member lies within this of the centre, and within `lateral` of it horizontally.
    reach: f32,
    lateral: f32,
}

/// The directions and ranges at which a ball's members may lie over a box. The members lie within
/// `half` (the box's translation), plus `arc` horizontally (the heading turns them about the
/// vertical), plus `spread` (the group's radius, any direction) of the centre `u`, which lies at
/// `[horizontal, range]` from the z axis and the origin.
///
/// A horizontal offset w (w_t across the ray, w_r along it) turns the direction by
/// atan(w_t / (h + w_r)): the box's support across and along the ray plus the arc and the spread
/// bound both parts. Height varies by at most `half.z` + `spread`, distance from the z axis by
/// |half_xy| + `arc` + `spread`, so the elevations lie between the corners' of that rectangle. An
/// offset w changes the range by at least its part along the ray (the box's support along it plus
/// the arc and the spread) and at most to √((r + w_∥)² + |w|²). Tighter than the ball around all
/// of it: on the bench pairs 25 % less time, with the same minima.
#[inline(always)]
fn footprint(
    u: [f32; 3],
    [horizontal, range]: [f32; 2],
    half: [f32; 3],
    arc: f32,
    spread: f32,
) -> Footprint {
    let (across_ray, along_ray) = if horizontal > 0.0 {
        let (s, c) = ((u[1] / horizontal).abs(), (u[0] / horizontal).abs());
        (half[0] * s + half[1] * c, half[0] * c + half[1] * s)
    } else {
        let h = (half[0] * half[0] + half[1] * half[1]).sqrt();
        (h, h)
    };
    let turned = arc + spread;
    // tan ψ ≤ w_t / (h − w_r) ≥ ψ; where the members may stand on the z axis it is not
    // positive, and every azimuth is seen (`Reach::holds_axis`).
    let beta = (across_ray + turned) / (horizontal - along_ray - turned);
    let vertical = half[2] + spread;
    let lateral = (half[0] * half[0] + half[1] * half[1]).sqrt() + turned;
    let (z_lo, z_hi) = (u[2] - vertical, u[2] + vertical);
    let (h_lo, h_hi) = ((horizontal - lateral).max(0.0), horizontal + lateral);
    let lowest = fast_atan2(z_lo, if z_lo >= 0.0 { h_hi } else { h_lo });
    let highest = fast_atan2(z_hi, if z_hi >= 0.0 { h_lo } else { h_hi });
    let along =
        (half[0] * u[0].abs() + half[1] * u[1].abs() + half[2] * u[2].abs()) / range + turned;
    let reach = (half[0] * half[0] + half[1] * half[1] + half[2] * half[2]).sqrt() + turned;
    Footprint {
        lowest,
        highest,
        beta,
        near: range - along,
        far: ((range + along) * (range + along) + reach * reach).sqrt(),
        reach,
        lateral,
    }
}

/// Where a ball's members may be over a box of candidates (see [`BranchAndBound::bound_below`]).
struct Reach {
    /// What a cell's term depends on.
    term: ConeTerm,
    /// The centre's range.
    range: f32,
    /// The ball holds the origin, or the z axis (then it sees every direction, or every azimuth).
    holds_origin: bool,
    holds_axis: bool,
    /// The cone's cell rows and columns (unclamped), and the centre's cell.
    e0: i32,
    e1: i32,
    a0: i32,
    a1: i32,
    ec: i32,
    ac: i32,
}

/// What the term of a cell's plane depends on, for one ball over one box (see [`reach_bound`]).
struct ConeTerm {
    /// The ball centre's position at the box's middle candidate.
    x: [f32; 3],
    /// Its horizontal offset from the query's origin there (the arm the heading turns).
    arm: [f32; 2],
    /// The box's translation half-extent per axis.
    half: [f32; 3],
    /// `(1 − cos δ, sin δ)` of the heading interval's half-width δ.
    turn: (f32, f32),
    /// The group's own radius (and a rounding margin).
    spread: f32,
    /// The members' ranges lie within this interval.
    gate: (f32, f32),
    truncation_sq: f32,
}

impl ConeTerm {
    /// The lower bound over one cell: the members' distance to the cell's plane can shrink by
    /// at most the region's extent along its normal; `τ²` for an unknown cell (NaN or an empty
    /// gate) and a gate the members cannot reach. Written without branches (the gate selects)
    /// and with plain comparisons, not `f32::max`/`min`, so that the cone loop is vectorized
    /// into packed instructions: it is most of the search's time.
    #[inline(always)]
    fn term(&self, n: [f32; 3], d: f32, lo: f32, hi: f32) -> f32 {
        let (one_minus_cos, sin) = self.turn;
        let (r_lo, r_hi) = self.gate;
        let reachable = lo <= r_hi && hi >= r_lo;
        // Turning by θ (|θ| ≤ δ) from the middle heading moves the centre by
        // (cos θ − 1) arm + sin θ (ẑ × arm): along the normal, at most this.
        let radial = (n[0] * self.arm[0] + n[1] * self.arm[1]).abs();
        let tangential = (n[1] * self.arm[0] - n[0] * self.arm[1]).abs();
        let along_normal = self.half[0] * n[0].abs()
            + self.half[1] * n[1].abs()
            + self.half[2] * n[2].abs()
            + one_minus_cos * radial
            + sin * tangential
            + self.spread;
        let distance = (n[0] * self.x[0] + n[1] * self.x[1] + n[2] * self.x[2] - d).abs();
        let gap = distance - along_normal;
        let v = if gap > 0.0 { gap } else { 0.0 };
        let squared = v * v;
        let squared = if squared < self.truncation_sq {
            squared
        } else {
            self.truncation_sq
        };
        if reachable {
            squared
        } else {
            self.truncation_sq
        }
    }

    /// The smallest [`Self::term`] over the [`LANES`] cells from `start` on (those from `valid`
    /// on count `τ²`), one array per quantity, so that it is vectorized.
    #[inline(always)]
    fn lanes_min(&self, rows: &PlaneRows, start: usize, valid: usize) -> f32 {
        let lane = |v: &[f32]| -> [f32; LANES] {
            v[start..start + LANES].try_into().expect("LANES cells")
        };
        let (nx, ny, nz) = (lane(&rows.nx), lane(&rows.ny), lane(&rows.nz));
        let (d, lo, hi) = (lane(&rows.d), lane(&rows.lo), lane(&rows.hi));
        let mut out = [0f32; LANES];
        for j in 0..LANES {
            let t = self.term([nx[j], ny[j], nz[j]], d[j], lo[j], hi[j]);
            out[j] = if j < valid { t } else { self.truncation_sq };
        }
        let mut width = LANES;
        while width > 1 {
            width /= 2;
            for j in 0..width {
                out[j] = if out[j + width] < out[j] {
                    out[j + width]
                } else {
                    out[j]
                };
            }
        }
        out[0]
    }
}

/// Cones of up to this many cells are bounded cell by cell, from each cell's plane; larger ones
/// from the range tables alone (whether any cell could compare the members at all). Boxes bounded
/// on bench pair 3 / the paper's pair with ±10° of heading: 16 → 23,236 / 20,032, 64 → 11,444 /
/// 7,928, 256 → 7,796 / 5,744, 1,024 → 8,052 / 5,424 (no faster).
const MAX_CONE_CELLS: i32 = 256;

/// A lower bound on the term of every member of a ball over the box (see
/// [`BranchAndBound::bound_below`]).
#[inline(always)]
fn reach_bound(tables: &RangeTables, planes: &crate::sdem::CellSurfaces, g: &Reach) -> (f32, f32) {
    let p = &g.term;
    let (truncation_sq, (r_lo, r_hi)) = (p.truncation_sq, p.gate);
    // The centre's own cell: the estimate (the squared distance there), and for a point on a
    // surface often a bound of 0 at once.
    let centre_cell = tables.cell(g.ec, g.ac);
    let centre = centre_cell.map(|c| &planes.cells[c]);
    let estimate = centre_cell
        .and_then(|c| planes.squared_distance(c, p.x, g.range))
        .map_or(truncation_sq, |e2| e2.min(truncation_sq));
    if g.holds_origin {
        // Any direction, any range: the reference's whole extent.
        let (min, max) = tables.global;
        return (if min > max { truncation_sq } else { 0.0 }, estimate);
    }
    let last_row = tables.n_el as i32 - 1;
    if g.e1 < 0 || g.e0 > last_row {
        return (truncation_sq, estimate);
    }
    let (e0, e1) = (g.e0.max(0), g.e1.min(last_row));
    let n_az = tables.n_az as i32;
    let (mut a0, mut a1) = (g.a0, g.a1);
    if g.holds_axis || (tables.full_circle && a1 - a0 + 1 >= n_az) {
        (a0, a1) = (0, n_az - 1);
    } else if tables.full_circle {
        // Columns run from a0 in [0, n_az) for at most n_az - 1 more, so wrap at most once.
        let start = wrap_column(a0, n_az);
        (a0, a1) = (start, start + (a1 - a0));
    } else {
        if a1 < 0 || a0 >= n_az {
            return (truncation_sq, estimate);
        }
        (a0, a1) = (a0.max(0), a1.min(n_az - 1));
    }
    let rows = &tables.planes;
    let mut best = truncation_sq;
    if let Some(c) = centre {
        // One cell: its 24 bytes, not a line of each of the rows' six arrays.
        best = p.term(c.n, c.d, c.lo, c.hi);
        if best == 0.0 {
            return (0.0, estimate);
        }
    }
    if e0 == e1 && a0 == a1 {
        // A single cell: the centre's (or one outside the grid).
        return (best, estimate);
    }
    let cone_cells = (e1 - e0 + 1) * (a1 - a0 + 1);
    if cone_cells > MAX_CONE_CELLS {
        // Too many cells to visit: whether any gate near the cone reaches the members' ranges
        // (if none does, every cell costs τ²), else 0.
        let (min, max) = tables.window(e0 as usize, e1 as usize, a0 as usize, a1 as usize);
        return (
            if min > r_hi || max < r_lo {
                truncation_sq
            } else {
                0.0
            },
            estimate,
        );
    }
    // Columns a0..=a1 of a row are one run of the stored row (see `PlaneRows`).
    let len = (a1 - a0 + 1) as usize;
    for e in e0..=e1 {
        let row = e as usize * rows.stride + a0 as usize;
        for k in (0..len).step_by(LANES) {
            let t = p.lanes_min(rows, row + k, len - k);
            best = if t < best { t } else { best };
        }
        if best == 0.0 {
            return (0.0, estimate);
        }
    }
    (best, estimate)
}

/// What the search precomputes for one reference/query pair: the reference's range tables, the
/// query's groups, and the correlator that scores candidates. Built once per localization and
/// shared by its searches (the best and the runner-up).
#[doc(hidden)]
pub struct Prepared<'a> {
    tables: RangeTables,
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
            || RangeTables::new(correlator.reference()),
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

/// The best candidate of `grid` (which leaves out the first search's peak) costing at most
/// `cap`, searched among what the first search set aside: the same answer as a search of the
/// whole grid with that cap, since every box and candidate the first search dropped below the
/// cap is in the reserve (`cap` must be at most the reserve's ratio × the first search's best).
#[doc(hidden)]
pub fn runner_up(
    prepared: &Prepared,
    grid: &CandidateGrid,
    cap: f64,
    reserve: Reserve,
) -> (Option<Scored>, BranchAndBoundStats) {
    BranchAndBound::new(prepared, grid, cap).run_from(reserve)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::FAST_ATAN2_MAX_ERROR;
    use rand::SeedableRng;

    /// Every position a member can take over a box (the translation box's corners and inside,
    /// plus a horizontal arc and an offset of up to the spread in any direction) lies in the
    /// directions and ranges [`footprint`] gives, near and far, level and steep, wide boxes and
    /// thin ones.
    #[test]
    fn footprint_holds_every_position_of_the_members() {
        use rand::Rng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let margin = 2.0 * FAST_ATAN2_MAX_ERROR as f64 + 1e-5;
        let mut azimuth_checked = 0;
        for _ in 0..2000 {
            let range = rng.random_range(0.3..6.0f64);
            let elevation = rng.random_range(-1.5..1.5f64);
            let azimuth = rng.random_range(-3.1..3.1f64);
            let u = [
                range * elevation.cos() * azimuth.cos(),
                range * elevation.cos() * azimuth.sin(),
                range * elevation.sin(),
            ];
            let half = [0, 1, 2].map(|_| rng.random_range(0.0..0.3f64));
            let arc = rng.random_range(0.0..0.2f64);
            let spread = rng.random_range(0.0..0.05f64);
            let horizontal = u[0].hypot(u[1]);
            let f = footprint(
                u.map(|v| v as f32),
                [horizontal as f32, range as f32],
                half.map(|v| v as f32),
                arc as f32,
                spread as f32,
            );
            let (lowest, highest, beta) = (f.lowest as f64, f.highest as f64, f.beta as f64);
            let (near, far) = (f.near as f64, f.far as f64);
            let (reach, lateral) = (f.reach as f64, f.lateral as f64);
            // As `bound_below` decides whether every azimuth is seen.
            let stands_off_axis = horizontal > lateral * 1.0001;
            azimuth_checked += stands_off_axis as usize;
            for k in 0..64 {
                // Corners of the box first, then anywhere in it; the offset on its sphere.
                let a: [f64; 3] = std::array::from_fn(|i| {
                    let side = if k < 8 {
                        if (k >> i) & 1 == 1 {
                            1.0
                        } else {
                            -1.0
                        }
                    } else {
                        rng.random_range(-1.0..1.0)
                    };
                    side * half[i]
                });
                let w: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0f64));
                let norm = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt().max(1e-12);
                let heading = rng.random_range(-3.2..3.2f64);
                let b = [arc * heading.cos(), arc * heading.sin(), 0.0];
                let x: [f64; 3] =
                    std::array::from_fn(|i| u[i] + a[i] + b[i] + w[i] / norm * spread);
                let offset: [f64; 3] = std::array::from_fn(|i| x[i] - u[i]);
                let slack = 1e-5 * range;
                assert!(
                    offset[0].hypot(offset[1]).hypot(offset[2]) <= reach + slack
                        && offset[0].hypot(offset[1]) <= lateral + slack,
                    "offset {offset:?} beyond {reach} (horizontally {lateral}) (u {u:?}, \
                     half {half:?}, arc {arc}, spread {spread})"
                );
                let h = x[0].hypot(x[1]);
                let r = h.hypot(x[2]);
                assert!(
                    r >= near - 1e-5 * range && r <= far + 1e-5 * range,
                    "range {r} outside [{near}, {far}] (u {u:?}, half {half:?}, arc {arc}, \
                     spread {spread})"
                );
                let e = x[2].atan2(h);
                assert!(
                    e >= lowest - margin && e <= highest + margin,
                    "elevation {e} outside [{lowest}, {highest}] (u {u:?}, half {half:?}, \
                     arc {arc}, spread {spread})"
                );
                if stands_off_axis {
                    let turn = (x[1].atan2(x[0]) - u[1].atan2(u[0]) + 3.0 * std::f64::consts::PI)
                        .rem_euclid(2.0 * std::f64::consts::PI)
                        - std::f64::consts::PI;
                    assert!(
                        turn.abs() <= beta + margin,
                        "azimuth {turn} beyond ±{beta} (u {u:?}, half {half:?}, arc {arc}, spread {spread})"
                    );
                }
            }
        }
        assert!(
            azimuth_checked > 1000,
            "{azimuth_checked} of 2000 off the axis"
        );
    }
}
