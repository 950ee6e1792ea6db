//! Exact branch-and-bound search over translation and heading for the projective cost
//! ([`crate::cost::CostModel::Projective`]), after the idea of correlative scan matching with
//! precomputed multi-resolution tables (Olson 2009; Hess et al. 2016, Cartographer).
//!
//! A node is a box of grid candidates (index intervals in x, y, z and heading). For every
//! candidate in it, each query point lies within a ball around its position at the box centre:
//! the radius is the half-diagonal of the translation box plus the chord the heading interval
//! sweeps. The ball spans a range interval and a cone of directions; precomputed tables give the
//! smallest and largest reference range and the count of known cells over that cone. From them
//! each point gets a valid lower bound on its truncated squared difference, and whether it is
//! certainly, possibly or never compared. The smallest mean any candidate of the box can reach is
//! then a lower bound on its cost (normalization and the minimum overlap included). Boxes whose
//! bound exceeds the best cost found so far are dropped; single candidates are scored exactly with
//! the same [`Correlator`] the exhaustive search uses, so both return the same minimum.
//!
//! Query points are grouped (by S-DEM block and range) at coarser levels, so large boxes are
//! bounded from a few hundred groups instead of every point: a group's ball covers its members'.

use crate::cost::{yaw_matrix, Correlator, CostConfig};
use crate::geometry::fast_atan2;
use crate::geometry::FAST_ATAN2_MAX_ERROR;
use crate::sdem::floor_i32;
use crate::sdem::Sdem;
use crate::search::{better, CandidateGrid, Index, Scored};
use rayon::prelude::*;
use std::collections::HashMap;

/// Range minimum, maximum and known-cell count of the reference S-DEM over rectangles of cells.
pub(crate) struct RangeTables {
    n_az: usize,
    n_el: usize,
    /// Columns stored: twice the azimuth cells on a full circle, so windows can wrap.
    width: usize,
    full_circle: bool,
    /// Known-cell prefix sums, `(n_el + 1) × (width + 1)`.
    known_prefix: Vec<u32>,
    /// Square sparse tables: level `k` holds `(min, max)` over the `2^k × 2^k` square starting at
    /// each cell, `n_el × width` entries (squares running off the grid are clipped).
    squares: Vec<Vec<(f32, f32)>>,
    /// 1-D sparse table over whole rows: level `k` holds `(min, max)` over rows `e..e + 2^k`.
    rows: Vec<Vec<(f32, f32)>>,
    global: (u32, f32, f32),
    elevation_min: f32,
    elevation_max: f32,
    azimuth_min: f32,
    inv_resolution: f32,
}

const EMPTY: (f32, f32) = (f32::INFINITY, f32::NEG_INFINITY);

fn merge(a: (f32, f32), b: (f32, f32)) -> (f32, f32) {
    (a.0.min(b.0), a.1.max(b.1))
}

impl RangeTables {
    pub fn new(reference: &Sdem) -> Self {
        let grid = reference.grid();
        let (n_az, n_el) = (grid.azimuth_cells(), grid.elevation_cells());
        let config = reference.config();
        let full_circle = (config.azimuth_max_deg - config.azimuth_min_deg - 360.0).abs() < 1e-9;
        let width = if full_circle { 2 * n_az } else { n_az };
        let ranges = reference.ranges();
        let cell = |e: usize, a: usize| ranges[e * n_az + a % n_az];
        let mut base = vec![EMPTY; n_el * width];
        let mut known_prefix = vec![0u32; (n_el + 1) * (width + 1)];
        for e in 0..n_el {
            for a in 0..width {
                let r = cell(e, a);
                let known = !r.is_nan();
                if known {
                    base[e * width + a] = (r, r);
                }
                known_prefix[(e + 1) * (width + 1) + a + 1] = known_prefix[e * (width + 1) + a + 1]
                    + known_prefix[(e + 1) * (width + 1) + a]
                    - known_prefix[e * (width + 1) + a]
                    + known as u32;
            }
        }
        let mut squares = vec![base];
        while (1usize << squares.len()) <= n_el.min(width) && squares.len() < 8 {
            let half = 1usize << (squares.len() - 1);
            let prev = squares.last().expect("level 0 exists");
            let mut next = vec![EMPTY; n_el * width];
            for e in 0..n_el {
                for a in 0..width {
                    let mut v = prev[e * width + a];
                    if e + half < n_el {
                        v = merge(v, prev[(e + half) * width + a]);
                    }
                    if a + half < width {
                        v = merge(v, prev[e * width + a + half]);
                        if e + half < n_el {
                            v = merge(v, prev[(e + half) * width + a + half]);
                        }
                    }
                    next[e * width + a] = v;
                }
            }
            squares.push(next);
        }
        let row: Vec<(f32, f32)> = (0..n_el)
            .map(|e| (0..n_az).fold(EMPTY, |acc, a| merge(acc, squares[0][e * width + a])))
            .collect();
        let mut rows = vec![row];
        while (1usize << rows.len()) <= n_el {
            let half = 1usize << (rows.len() - 1);
            let prev = rows.last().expect("level 0 exists");
            let next = (0..n_el)
                .map(|e| {
                    if e + half < n_el {
                        merge(prev[e], prev[e + half])
                    } else {
                        prev[e]
                    }
                })
                .collect();
            rows.push(next);
        }
        let global_range = rows[0].iter().fold(EMPTY, |acc, &r| merge(acc, r));
        Self {
            n_az,
            n_el,
            width,
            full_circle,
            known_prefix,
            squares,
            rows,
            global: (
                reference.known_cells() as u32,
                global_range.0,
                global_range.1,
            ),
            elevation_min: config.elevation_min_deg.to_radians() as f32,
            elevation_max: config.elevation_max_deg.to_radians() as f32,
            azimuth_min: config.azimuth_min_deg.to_radians() as f32,
            inv_resolution: (1.0 / config.resolution_deg.to_radians()) as f32,
        }
    }

    fn known(&self, e0: usize, e1: usize, a0: usize, a1: usize) -> u32 {
        let w = self.width + 1;
        self.known_prefix[(e1 + 1) * w + a1 + 1] + self.known_prefix[e0 * w + a0]
            - self.known_prefix[e0 * w + a1 + 1]
            - self.known_prefix[(e1 + 1) * w + a0]
    }

    /// The range of the cell at row `e`, column `a` (columns wrap on a full circle), or `None`
    /// when it is unknown or outside the grid.
    fn range_at(&self, e: i32, a: i32) -> Option<f32> {
        if e < 0 || e >= self.n_el as i32 {
            return None;
        }
        let a = if self.full_circle {
            a.rem_euclid(self.n_az as i32)
        } else if a < 0 || a >= self.n_az as i32 {
            return None;
        } else {
            a
        };
        let (lo, _) = self.squares[0][e as usize * self.width + a as usize];
        lo.is_finite().then_some(lo)
    }

    fn rows_range(&self, e0: usize, e1: usize) -> (f32, f32) {
        let h = e1 - e0 + 1;
        let k = (usize::BITS - 1 - h.leading_zeros()) as usize;
        let s = 1usize << k;
        merge(self.rows[k][e0], self.rows[k][e1 + 1 - s])
    }

    /// `(known, cells, min, max)` over rows `e0..=e1` and columns `a0..=a1` (columns may run past
    /// `n_az` on a full circle; `a1 - a0 < n_az`).
    fn window(&self, e0: usize, e1: usize, a0: usize, a1: usize) -> (u32, u32, f32, f32) {
        let (h, w) = (e1 - e0 + 1, a1 - a0 + 1);
        let cells = (h * w) as u32;
        let known = self.known(e0, e1, a0, a1);
        if known == 0 {
            return (0, cells, f32::INFINITY, f32::NEG_INFINITY);
        }
        let k = ((usize::BITS - 1 - h.min(w).leading_zeros()) as usize).min(self.squares.len() - 1);
        let s = 1usize << k;
        let (ne, na) = (h.div_ceil(s), w.div_ceil(s));
        if ne * na > 12 {
            // A wide band near a pole: whole rows bound it (a superset, still valid).
            let (lo, hi) = self.rows_range(e0, e1);
            return (known, cells, lo, hi);
        }
        let table = &self.squares[k];
        let mut acc = EMPTY;
        for i in 0..ne {
            let e = (e0 + i * s).min(e1 + 1 - s);
            for j in 0..na {
                let a = (a0 + j * s).min(a1 + 1 - s);
                acc = merge(acc, table[e * self.width + a]);
            }
        }
        (known, cells, acc.0, acc.1)
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

/// The query's points at several groupings: level 0 one point per group; level `m` the points of
/// a `2^m × 2^m` block of cells whose ranges fall in one `2^m · 2 cm` bin.
pub(crate) struct QueryGroups {
    /// The groups of each level, one field per array (for the vectorized bound).
    balls: Vec<Balls>,
    /// The 75th-percentile group radius of each level, metres.
    typical_radius: Vec<f32>,
}

impl QueryGroups {
    pub fn new(query: &Sdem, levels: usize) -> Self {
        let n_az = query.grid().azimuth_cells() as u32;
        let points = query.points();
        let make = |members: &[usize]| -> Group {
            let mut c = [0f64; 3];
            for &i in members {
                for a in 0..3 {
                    c[a] += points[i][a] as f64;
                }
            }
            let n = members.len() as f64;
            let center = [(c[0] / n) as f32, (c[1] / n) as f32, (c[2] / n) as f32];
            let mut radius = 0f32;
            let mut horizontal = 0f32;
            for &i in members {
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
                radius: radius * (1.0 + 1e-5) + 1e-6,
                horizontal,
                count: members.len() as u32,
            }
        };
        let mut out = Vec::new();
        let mut typical = Vec::new();
        for m in 0..levels.max(1) {
            let mut buckets: HashMap<(u32, u32, u32), Vec<usize>> = HashMap::new();
            for (i, (&cell, p)) in query.cells().iter().zip(points).enumerate() {
                let range = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                let bin = (range / (0.02 * (1u32 << m) as f32)) as u32;
                let key = ((cell / n_az) >> m, (cell % n_az) >> m, bin);
                buckets.entry(key).or_default().push(i);
            }
            let mut keys: Vec<_> = buckets.keys().copied().collect();
            keys.sort_unstable();
            let groups: Vec<Group> = keys.iter().map(|k| make(&buckets[k])).collect();
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

/// A box of candidates: inclusive index intervals per axis (x, y, z, heading).
#[derive(Clone, Copy, Debug)]
struct Node {
    lo: Index,
    hi: Index,
}

impl Node {
    fn is_leaf(&self) -> bool {
        self.lo == self.hi
    }

    fn children(&self) -> Vec<Node> {
        let mut out = vec![*self];
        for a in 0..4 {
            if self.hi[a] > self.lo[a] {
                let mid = (self.lo[a] + self.hi[a]) / 2;
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
    /// Single candidates scored exactly.
    pub leaves_evaluated: usize,
}

/// A box is bounded from the coarsest grouping whose typical group radius is at most this
/// fraction of the box's reach. Measured on the paper's pair: at 0.5, 2,131 boxes and 237
/// candidates; at 0.1, 1,206 and 164 (larger groups widen every ball, which costs more boxes than
/// it saves per box).
const GROUP_REACH_FRACTION: f64 = 0.1;

/// The search state shared by the recursion.
pub(crate) struct BranchAndBound<'a> {
    reference: &'a Sdem,
    query: &'a Sdem,
    cost: &'a CostConfig,
    grid: &'a CandidateGrid,
    tables: &'a RangeTables,
    groups: &'a QueryGroups,
    min_overlap: u64,
    truncation_sq: f32,
    /// Only candidates costing at most this are of interest (∞: all).
    cap: f64,
    best: Option<Scored>,
    stats: BranchAndBoundStats,
}

impl<'a> BranchAndBound<'a> {
    pub fn new(
        reference: &'a Sdem,
        query: &'a Sdem,
        cost: &'a CostConfig,
        grid: &'a CandidateGrid,
        tables: &'a RangeTables,
        groups: &'a QueryGroups,
    ) -> crate::Result<Self> {
        let correlator = Correlator::new(reference, query, cost)?;
        Ok(Self {
            reference,
            query,
            cost,
            grid,
            tables,
            groups,
            min_overlap: correlator.min_overlap() as u64,
            truncation_sq: cost.truncation_sq(),
            cap: f64::INFINITY,
            best: None,
            stats: BranchAndBoundStats::default(),
        })
    }

    /// Runs the search over the whole grid; returns the exhaustive search's minimum.
    pub fn run(mut self) -> (Option<Scored>, BranchAndBoundStats) {
        let c = self.grid.counts;
        let root = Node {
            lo: [0; 4],
            hi: [c[0] - 1, c[1] - 1, c[2] - 1, c[3] - 1],
        };
        if root.is_leaf() {
            let (score, _) = self.score_leaf(&mut self.correlator(), &root);
            self.stats.leaves_evaluated += 1;
            return (score.filter(|s| s.0 <= self.cap), self.stats);
        }
        self.visit(root);
        (self.best, self.stats)
    }

    fn prunable(&self, bound: f64) -> bool {
        let limit = self.best.map_or(self.cap, |(cost, _)| cost.min(self.cap));
        if limit.is_infinite() {
            return bound.is_infinite();
        }
        // A margin far above rounding: bounds are computed with slack, costs exactly.
        bound > limit * (1.0 + 1e-9) + 1e-15
    }

    fn correlator(&self) -> Correlator<'a> {
        Correlator::new(self.reference, self.query, self.cost).expect("validated in new()")
    }

    fn score_leaf(&self, correlator: &mut Correlator, node: &Node) -> (Option<Scored>, f64) {
        let idx = node.lo;
        let flat = self.grid.flat(idx);
        if self.grid.excluded(idx) {
            return (None, f64::INFINITY);
        }
        match correlator.evaluate(&self.grid.offset(idx), self.grid.yaw(idx)) {
            Some(c) => (Some((c.cost, flat)), c.cost),
            None => (None, f64::INFINITY),
        }
    }

    fn visit(&mut self, node: Node) {
        let mut children = node.children();
        children.retain(|c| !self.grid.box_excluded(c.lo, c.hi));
        // One correlator (with its scratch buffers) per worker that meets a leaf, not per leaf.
        let scored: Vec<(Node, f64, f64, Option<Scored>)> = children
            .par_iter()
            .map_init(
                || None,
                |correlator: &mut Option<Correlator>, child| {
                    if child.is_leaf() {
                        let correlator = correlator.get_or_insert_with(|| self.correlator());
                        let (score, bound) = self.score_leaf(correlator, child);
                        (*child, bound, bound, score)
                    } else {
                        let (bound, estimate) = self.bound(child);
                        (*child, bound, estimate, None)
                    }
                },
            )
            .collect();
        let mut pending = Vec::with_capacity(scored.len());
        for (child, bound, estimate, score) in scored {
            if child.is_leaf() {
                self.stats.leaves_evaluated += 1;
                if let Some(s) = score.filter(|s| s.0 <= self.cap) {
                    if self.best.is_none_or(|b| better(&s, &b)) {
                        self.best = Some(s);
                    }
                }
            } else {
                self.stats.nodes_bounded += 1;
                pending.push((bound, estimate, child));
            }
        }
        // By bound (so the first prunable box ends the loop), ties (every bound is 0 while boxes
        // are large) broken by the estimated cost at the box's centre, so the search reaches a
        // good candidate early and prunes with it.
        pending.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        for (bound, _, child) in pending {
            if self.prunable(bound) {
                break;
            }
            self.visit(child);
        }
    }

    /// A lower bound on the cost of every candidate in `node` (∞ when none can reach the minimum
    /// overlap), and an estimate of the cost at its centre (the groups' centres looked up in
    /// their cells; only for ordering the search).
    fn bound(&self, node: &Node) -> (f64, f64) {
        let grid = self.grid;
        let lo = grid.offset(node.lo);
        let hi = grid.offset(node.hi);
        let centre = (lo + hi) * 0.5;
        let translation_radius = ((hi - lo) * 0.5).norm();
        let (yaw_lo, yaw_hi) = (grid.yaws[node.lo[3]], grid.yaws[node.hi[3]]);
        let yaw_centre = 0.5 * (yaw_lo + yaw_hi);
        let chord = 2.0 * (0.25 * (yaw_hi - yaw_lo)).sin();
        // The coarsest grouping whose groups are small against the box.
        let reach = translation_radius + chord;
        let level = (0..self.groups.balls.len())
            .rev()
            .find(|&m| self.groups.typical_radius[m] as f64 <= GROUP_REACH_FRACTION * reach)
            .unwrap_or(0);
        let balls = &self.groups.balls[level];
        let m = yaw_matrix(yaw_centre);
        let t = centre.cast::<f32>();
        let tables = self.tables;
        let truncation_sq = self.truncation_sq;
        let (rt, chord) = (translation_radius as f32, chord as f32);
        let margin = 2.0 * FAST_ATAN2_MAX_ERROR;
        // 2 |t_c,h| δ, with δ the largest turn from the middle heading (slightly enlarged for
        // rounding).
        let yaw_spread = (2.0 * centre.xy().norm() * 0.5 * (yaw_hi - yaw_lo) * (1.0 + 1e-6)) as f32;
        let mut certain_sum = 0f64;
        let mut certain_count = 0u64;
        let mut maybe: Vec<(f32, u32)> = Vec::new();
        let mut maybe_count = 0u64;
        let (mut estimate_sum, mut estimate_count) = (0f64, 0u64);
        const CHUNK: usize = 64;
        let mut geometry = [BallGeometry::default(); CHUNK];
        let n = balls.cx.len();
        for start in (0..n).step_by(CHUNK) {
            let len = CHUNK.min(n - start);
            // Vectorizable: each ball's position, range and angular extent.
            for (i, g) in geometry[..len].iter_mut().enumerate() {
                let k = start + i;
                let (x, y, z) = (balls.cx[k], balls.cy[k], balls.cz[k]);
                let u0 = m[(0, 0)] * x + m[(0, 1)] * y + m[(0, 2)] * z + t.x;
                let u1 = m[(1, 0)] * x + m[(1, 1)] * y + m[(1, 2)] * z + t.y;
                let u2 = m[(2, 0)] * x + m[(2, 1)] * y + m[(2, 2)] * z + t.z;
                // Every member at every candidate of the box lies within `rt + group radius` of
                // the group centre's arc `Rz(ψ) c + t_c`, and the arc within `chord · ρ` of its
                // middle: a ball bounds the azimuths (slack covers single-precision rounding).
                let near = rt + balls.radius[k] + 1e-4;
                let radius = near + chord * balls.horizontal[k];
                let horizontal = (u0 * u0 + u1 * u1).sqrt();
                let range = (horizontal * horizontal + u2 * u2).sqrt();
                // Turning about z keeps the height, and changes the squared horizontal distance
                // by at most 2 ρ |t_c,h| δ: in the (horizontal, height) plane the members lie
                // within `near + dh` of the centre's middle position, which bounds their range
                // and elevation far tighter than the ball.
                let w = yaw_spread * balls.horizontal[k];
                let dh = horizontal - (horizontal * horizontal - w).max(0.0).sqrt();
                let radial = (near + dh).min(radius);
                // Angular radius: tan(asin(ρ/|u|)) ≥ asin(ρ/|u|), plus the arctangent's error.
                let alpha = radial / (range * range - radial * radial).sqrt() + margin;
                let elevation = fast_atan2(u2, horizontal);
                let beta = radius / (horizontal * horizontal - radius * radius).sqrt() + margin;
                let azimuth = fast_atan2(u1, u0);
                let (el_lo, el_hi) = (elevation - alpha, elevation + alpha);
                *g = BallGeometry {
                    range,
                    radius,
                    radial,
                    horizontal,
                    el_lo,
                    el_hi,
                    e0: floor_i32((el_lo - tables.elevation_min) * tables.inv_resolution),
                    e1: floor_i32((el_hi - tables.elevation_min) * tables.inv_resolution),
                    a0: floor_i32((azimuth - beta - tables.azimuth_min) * tables.inv_resolution),
                    a1: floor_i32((azimuth + beta - tables.azimuth_min) * tables.inv_resolution),
                    ec: floor_i32((elevation - tables.elevation_min) * tables.inv_resolution),
                    ac: floor_i32((azimuth - tables.azimuth_min) * tables.inv_resolution),
                };
            }
            for (i, g) in geometry[..len].iter().enumerate() {
                let count = balls.count[start + i];
                if let Some(r) = tables.range_at(g.ec, g.ac) {
                    let e = g.range - r;
                    estimate_sum += (e * e).min(truncation_sq) as f64 * count as f64;
                    estimate_count += count as u64;
                }
                match ball_bound(tables, g, truncation_sq) {
                    (Status::Never, _) => {}
                    (Status::Certain, lb) => {
                        certain_sum += lb as f64 * count as f64;
                        certain_count += count as u64;
                    }
                    (Status::Maybe, lb) => {
                        maybe.push((lb, count));
                        maybe_count += count as u64;
                    }
                }
            }
        }
        let estimate = if estimate_count == 0 {
            f64::INFINITY
        } else {
            estimate_sum / estimate_count as f64
        };
        if certain_count + maybe_count < self.min_overlap {
            return (f64::INFINITY, estimate);
        }
        // The smallest mean over the certain terms plus any subset of the possible ones that
        // reaches the minimum overlap: take the possible ones from the smallest up.
        maybe.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut sum, mut count) = (certain_sum, certain_count);
        for (lb, n) in maybe {
            let lb = lb as f64;
            if count < self.min_overlap {
                let take = (self.min_overlap - count).min(n as u64);
                sum += lb * take as f64;
                count += take;
                if take < n as u64 && lb * (count as f64) < sum {
                    let rest = n as u64 - take;
                    sum += lb * rest as f64;
                    count += rest;
                }
            } else if lb * (count as f64) < sum {
                sum += lb * n as f64;
                count += n as u64;
            } else {
                break;
            }
        }
        if count == 0 {
            (f64::INFINITY, estimate)
        } else {
            (sum / count as f64, estimate)
        }
    }
}

enum Status {
    Never,
    Maybe,
    Certain,
}

/// A ball's position against the reference (see [`ball_bound`]).
#[derive(Clone, Copy, Default)]
struct BallGeometry {
    /// Distance of the ball's centre from the reference origin, and its horizontal part.
    range: f32,
    horizontal: f32,
    /// The ball's radius (bounds the azimuths, and decides whether it holds the origin or the z
    /// axis).
    radius: f32,
    /// Radius in the (horizontal, height) plane (bounds the range and the elevation).
    radial: f32,
    /// Elevation interval the ball spans, radians, and its cell rows (unclamped).
    el_lo: f32,
    el_hi: f32,
    e0: i32,
    e1: i32,
    /// Azimuth cell columns the ball spans (unclamped), when it does not hold the z axis.
    a0: i32,
    a1: i32,
    /// The cell of the centre's direction (unclamped).
    ec: i32,
    ac: i32,
}

/// Bounds one ball: whether the points it may hold are compared with a known reference cell,
/// and a lower bound on their truncated squared range difference.
#[inline]
fn ball_bound(t: &RangeTables, g: &BallGeometry, truncation_sq: f32) -> (Status, f32) {
    let (range, radius) = (g.range, g.radius);
    let (lo_r, hi_r) = (range - g.radial, range + g.radial);
    let lb_of = |min: f32, max: f32| -> f32 {
        let d = if min > hi_r {
            min - hi_r
        } else if max < lo_r {
            lo_r - max
        } else {
            0.0
        };
        (d * d).min(truncation_sq)
    };
    if range <= radius * 1.0001 {
        // The ball holds the origin: any direction.
        let (known, min, max) = t.global;
        return if known == 0 {
            (Status::Never, 0.0)
        } else {
            (Status::Maybe, lb_of(min, max))
        };
    }
    let mut outside = g.el_lo < t.elevation_min || g.el_hi > t.elevation_max;
    let last_row = t.n_el as i32 - 1;
    let e0 = g.e0.clamp(0, last_row) as usize;
    let e1 = g.e1.clamp(0, last_row) as usize;
    let (a0, a1) = if g.horizontal <= radius * 1.0001 {
        // The ball holds the z axis: every azimuth.
        if !t.full_circle {
            outside = true;
        }
        (0, t.n_az - 1)
    } else {
        let (lo, hi) = (g.a0 as i64, g.a1 as i64);
        let n = t.n_az as i64;
        if t.full_circle {
            if hi - lo + 1 >= n {
                (0, t.n_az - 1)
            } else {
                let start = lo.rem_euclid(n);
                (start as usize, (start + hi - lo) as usize)
            }
        } else {
            if lo < 0 || hi >= n {
                outside = true;
            }
            (lo.clamp(0, n - 1) as usize, hi.clamp(0, n - 1) as usize)
        }
    };
    let (known, cells, min, max) = t.window(e0, e1, a0, a1);
    if known == 0 {
        (Status::Never, 0.0)
    } else if known == cells && !outside {
        (Status::Certain, lb_of(min, max))
    } else {
        (Status::Maybe, lb_of(min, max))
    }
}

/// What the search precomputes for one reference/query pair: the reference's range tables and
/// the query's groups. Built once per localization and shared by its searches (the best and the
/// runner-up).
pub(crate) struct Prepared {
    tables: RangeTables,
    groups: QueryGroups,
}

impl Prepared {
    pub fn new(reference: &Sdem, query: &Sdem) -> Self {
        Self {
            tables: RangeTables::new(reference),
            groups: QueryGroups::new(query, 4),
        }
    }
}

/// Runs the exact search; see the module documentation. With a finite `cap`, only candidates
/// costing at most `cap` are looked for (the minimum among them, or `None`): a much cheaper
/// question when the cap is low.
pub(crate) fn search(
    prepared: &Prepared,
    reference: &Sdem,
    query: &Sdem,
    cost: &CostConfig,
    grid: &CandidateGrid,
    cap: f64,
) -> crate::Result<(Option<Scored>, BranchAndBoundStats)> {
    let (tables, groups) = (&prepared.tables, &prepared.groups);
    let mut bnb = BranchAndBound::new(reference, query, cost, grid, tables, groups)?;
    bnb.cap = cap;
    Ok(bnb.run())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_from_parts, Attitude, Pose, Vec3};
    use crate::localize::SearchWindow;
    use crate::sdem::SdemConfig;
    use crate::sensor::SensorConfig;
    use crate::sim;
    use rand::SeedableRng;

    /// The bound of every box is at most the smallest cost of its candidates (the property the
    /// exactness rests on), at every box size, with and without a heading interval; and it is
    /// tight enough near the optimum to prune most small boxes.
    #[test]
    fn bound_never_exceeds_the_boxes_minimum() {
        let scene = sim::paper_room();
        let sensor = SensorConfig {
            tilt_step_deg: 2.0,
            pan_step_deg: 2.0,
            ..Default::default()
        };
        let grid_cfg = SdemConfig {
            resolution_deg: 2.0,
            ..Default::default()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut at = |p: &Pose| {
            let s = sim::scan(&scene, &sensor, p, 0.0, &mut rng);
            let a = s.mean_attitude();
            Sdem::from_points(&s.points_in_sensor(), &a.rotation(), &grid_cfg).unwrap()
        };
        let r = at(&Pose::identity());
        let truth = Vec3::new(0.22, 0.36, 0.05);
        let q = at(&pose_from_parts(
            truth,
            Attitude::from_degrees(0.0, 0.0, 1.0),
        ));
        let cost = CostConfig::default();
        let window = SearchWindow::around(&truth, [0.08, 0.08, 0.04]);
        let yaws: Vec<f64> = (-2..=2).map(|k| (k as f64).to_radians()).collect();
        let grid = CandidateGrid::new(&window, 0.02, yaws).unwrap();
        let tables = RangeTables::new(&r);
        let groups = QueryGroups::new(&q, 4);
        let bnb = BranchAndBound::new(&r, &q, &cost, &grid, &tables, &groups).unwrap();
        let mut c = Correlator::new(&r, &q, &cost).unwrap();
        let n = grid.counts;
        let costs: Vec<f64> = (0..grid.len())
            .map(|f| {
                let i = grid.index(f);
                c.evaluate(&grid.offset(i), grid.yaw(i))
                    .map_or(f64::INFINITY, |x| x.cost)
            })
            .collect();
        let best = costs.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(best.is_finite());
        for (size, yaw_size) in [(2, 1), (4, 1), (8, 1), (2, 2), (4, 5), (9, 5)] {
            let (mut pruned, mut boxes) = (0, 0);
            for l in (0..n[3]).step_by(yaw_size) {
                for z in (0..n[2]).step_by(size) {
                    for y in (0..n[1]).step_by(size) {
                        for x in (0..n[0]).step_by(size) {
                            let lo = [x, y, z, l];
                            let hi = [
                                (x + size).min(n[0]) - 1,
                                (y + size).min(n[1]) - 1,
                                (z + size).min(n[2]) - 1,
                                (l + yaw_size).min(n[3]) - 1,
                            ];
                            let node = Node { lo, hi };
                            if node.is_leaf() {
                                continue;
                            }
                            let (bound, _) = bnb.bound(&node);
                            let mut min = f64::INFINITY;
                            for ll in lo[3]..=hi[3] {
                                for zz in lo[2]..=hi[2] {
                                    for yy in lo[1]..=hi[1] {
                                        for xx in lo[0]..=hi[0] {
                                            min = min.min(costs[grid.flat([xx, yy, zz, ll])]);
                                        }
                                    }
                                }
                            }
                            assert!(
                                bound <= min,
                                "box {lo:?}..{hi:?}: bound {bound:e} above its minimum {min:e}"
                            );
                            boxes += 1;
                            pruned += (bound > best) as usize;
                        }
                    }
                }
            }
            println!("boxes of {size}^3 x {yaw_size} headings: {pruned} of {boxes} pruned");
            if (size, yaw_size) == (2, 1) {
                assert!(
                    pruned * 2 > boxes,
                    "only {pruned} of {boxes} small boxes pruned"
                );
            }
        }
    }
}
