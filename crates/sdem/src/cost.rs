//! The correlation cost of Nagatani et al. (2003), Sec. III-C, eq. (1), in two forms.
//!
//! A candidate is an offset `t` and a heading correction `ψ`: a point `q` of the query's levelled
//! frame lies at `x = Rz(ψ) q + t` in the reference's levelled frame.
//!
//! * [`CostModel::VirtualSdem`] — the paper's literal form: the reference's boundary points are
//!   moved to the candidate origin and z-buffered into a *virtual S-DEM*, which is compared cell by
//!   cell with the query (local) S-DEM.
//! * [`CostModel::Projective`] — the same comparison taken the other way round: the query's
//!   boundary points are moved by the candidate and looked up in the reference S-DEM in their
//!   direction (a virtual S-DEM of the query at the reference origin, without the z-buffer). Each
//!   query point then contributes a term that depends on its own moved position only, which is
//!   what lets [`crate::bnb`] bound the cost over a box of candidates and search exactly.
//!
//! The projective form measures each moved query point's distance to the plane of the reference
//! cell it falls in (the cell's return and a normal from its neighbours), within a range gate of
//! the cell's return: the paper's range difference times the cosine of incidence, which a 1° cell
//! of a glancing floor does not blow up to decimetres. The virtual form compares ranges per cell.
//! Both truncate the squared difference at `τ` and take the mean over the query's compared points
//! (its known cells), a cell the reference does not see counting `τ²` (a full mismatch), so a
//! candidate cannot win by seeing less and the sum stays additive.

use crate::error::{Error, Result};
use crate::geometry::Vec3;
use crate::sdem::Sdem;
use crate::voxel::{Key, KeyMap};
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// Which form of eq. (1) is scored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CostModel {
    /// Query points looked up in the reference S-DEM (exact branch-and-bound applies).
    Projective,
    /// The reference re-projected into a z-buffered virtual S-DEM at the candidate (the paper).
    VirtualSdem,
}

/// How the difference between two S-DEMs is scored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CostConfig {
    /// Which form of eq. (1).
    pub model: CostModel,
    /// Differences (distances to the reference cell's plane in the projective form, range
    /// differences in the virtual-S-DEM form) are truncated at this value, metres, so moved
    /// rubble or a person walking by adds a bounded penalty instead of dragging the estimate;
    /// a cell the reference does not see costs as much. 5 cm: on the paper's pair with ±10° of
    /// heading the exact search bounded 1.6× as many boxes at 8 cm and 2.9× at 12 cm (the
    /// outliers' `τ²` dominate the optimum's cost), and was no faster at 3 cm.
    pub truncation_m: f64,
    /// A candidate must compare at least this many cells. 100: with one point per
    /// [`Self::search_voxel_m`] cube a scan in the ditch compares only ~400 points, and at 200 the
    /// true pose of a robot at the ditch's mouth (pair 45 of `sdem bench --faults`, 116 cells
    /// seen by both) was no candidate at all, so a wrong one 13 cm away won.
    pub min_overlap_cells: usize,
    /// … and at least this fraction of the cells the query is scored over.
    pub min_overlap_fraction: f64,
    /// The best candidate is accepted only when at least this fraction of the query's compared
    /// points match it within the truncation; otherwise the search reports that nothing matched
    /// (a best candidate far from everything is still a best candidate).
    pub min_inlier_fraction: f64,
    /// The projective cost compares one query point per cube of this side, metres (the one
    /// nearest the cube's centre; 0 keeps every point). An S-DEM samples 1° of directions, so
    /// it holds a point every few millimetres on the floor under the sensor and every few
    /// centimetres on far walls: the cubes even that out, and the grid search does not need
    /// more to find the basin (the refinement uses every point).
    pub search_voxel_m: f64,
    /// At most this many query points are compared (0: no limit): the search cubes grow by a
    /// quarter at a time until the scan's points fit. The search's time grows with the points
    /// and the refinement (every point) decides the final pose: on 20 seeded pairs of `sdem
    /// bench` (432–4,782 points at 8 cm) a cap of 1,500 left every error the same to the
    /// micrometre and cut the median time from 935 to 602 ms (1,000: 430 ms, 500: 283 ms). 1,000
    /// kept every single fault of `sdem bench --faults` at 100 % but lost a pair with all faults
    /// at once (pair 75: 9.7 cm off, flagged), which 1,500 keeps.
    pub max_search_points: usize,
    /// The motion's prediction (odometry, or the last motion repeated), added to eq. (1) as a
    /// weak quadratic term; `None` (the default) scores the scans alone. Set per localization,
    /// not saved with a configuration.
    #[serde(skip)]
    pub prior: Option<OffsetPrior>,
}

/// A prediction of the offset a localization estimates, and how far to trust it.
///
/// Added to eq. (1) as `(τ² / n) · |t − offset|² / σ²` (`n` the compared points): the prediction
/// counts as much as *one* more point whose error is `τ` at one `σ`. Against the hundreds or
/// thousands of points a scan compares it moves no minimum the scans decide; where they decide
/// nothing — a ditch or corridor along its axis, whose cost is flat to the last digit — it keeps
/// the estimate at the prediction instead of wherever the grid or the window edge happens to
/// leave it (Cartographer's scan matchers weigh their prediction the same way). The refinement
/// weighs it as one more residual of the same kind.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OffsetPrior {
    /// The predicted offset (query origin minus reference origin, levelled axes), metres.
    pub offset: [f64; 3],
    /// Its standard deviation, metres (each axis).
    pub sigma_m: f64,
}

impl OffsetPrior {
    /// Checks the values.
    pub fn validate(&self) -> Result<()> {
        if !self.offset.iter().all(|v| v.is_finite()) {
            return Err(Error::Invalid(format!(
                "the predicted offset {:?} m must be finite",
                self.offset
            )));
        }
        if !(self.sigma_m.is_finite() && self.sigma_m > 0.0) {
            return Err(Error::Invalid(format!(
                "the prediction's standard deviation {} m must be a positive number",
                self.sigma_m
            )));
        }
        Ok(())
    }

    /// `|t − offset|²`, m².
    pub fn squared_distance(&self, t: &Vec3) -> f64 {
        (0..3).map(|a| (t[a] - self.offset[a]).powi(2)).sum()
    }

    /// The smallest `|t − offset|²` over the box `lo ≤ t ≤ hi`.
    pub fn squared_distance_to_box(&self, lo: &Vec3, hi: &Vec3) -> f64 {
        (0..3)
            .map(|a| {
                let o = self.offset[a];
                let d = if o < lo[a] {
                    lo[a] - o
                } else if o > hi[a] {
                    o - hi[a]
                } else {
                    0.0
                };
                d * d
            })
            .sum()
    }
}

/// Default of [`CostConfig::max_search_points`].
pub const MAX_SEARCH_POINTS: usize = 1500;

impl Default for CostConfig {
    fn default() -> Self {
        Self {
            model: CostModel::Projective,
            truncation_m: 0.05,
            min_overlap_cells: 100,
            min_overlap_fraction: 0.2,
            min_inlier_fraction: 0.1,
            search_voxel_m: 0.08,
            max_search_points: MAX_SEARCH_POINTS,
            prior: None,
        }
    }
}

impl CostConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<()> {
        if !(self.truncation_m.is_finite() && self.truncation_m > 0.0) {
            return Err(Error::Invalid(format!(
                "cost truncation {} m must be a positive number",
                self.truncation_m
            )));
        }
        if !(0.0..=1.0).contains(&self.min_overlap_fraction) {
            return Err(Error::Invalid(format!(
                "minimum overlap fraction {} must lie in [0, 1]",
                self.min_overlap_fraction
            )));
        }
        if !(self.search_voxel_m.is_finite() && self.search_voxel_m >= 0.0) {
            return Err(Error::Invalid(format!(
                "search voxel {} m must be a number >= 0",
                self.search_voxel_m
            )));
        }
        if !(0.0..=1.0).contains(&self.min_inlier_fraction) {
            return Err(Error::Invalid(format!(
                "minimum inlier fraction {} must lie in [0, 1]",
                self.min_inlier_fraction
            )));
        }
        if let Some(prior) = &self.prior {
            prior.validate()?;
        }
        Ok(())
    }

    /// The overlap (cells) a candidate needs against a query S-DEM with `query_known` cells.
    pub fn min_overlap(&self, query_known: usize) -> usize {
        let fraction = (self.min_overlap_fraction * query_known as f64).ceil() as usize;
        self.min_overlap_cells.max(fraction).max(1)
    }

    /// The highest cost a candidate may have to be a match, m²: `(1 − min_inlier_fraction) τ²`.
    /// Every compared point beyond the truncation, or in a cell the reference does not see,
    /// costs `τ²`, so a candidate costing no more keeps at least `min_inlier_fraction` of its
    /// points within the truncation; the searches leave out every box bounded above it, so a
    /// pair that matches nowhere in the window ends without scoring the whole window.
    pub fn max_match_cost(&self) -> f64 {
        (1.0 - self.min_inlier_fraction) * self.truncation_m * self.truncation_m
    }

    /// `τ²` in single precision, as every term is computed.
    #[doc(hidden)]
    pub fn truncation_sq(&self) -> f32 {
        let t = self.truncation_m as f32;
        t * t
    }
}

/// The score of one candidate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Correlation {
    /// Mean truncated squared difference over the query's compared points (its known cells), a
    /// cell the reference does not see counting as a full mismatch `τ²`, m² (the paper's `d`),
    /// plus the prediction's term when there is one ([`OffsetPrior`]).
    pub cost: f64,
    /// Number of cells compared (known on both sides).
    pub overlap: usize,
    /// Of those, cells whose difference lies within the truncation (the matched cells).
    pub inliers: usize,
}

/// Accumulates eq. (1) cell by cell; every evaluator goes through it so all compute exactly the
/// same number for the same candidate.
///
/// The sum is additive over the query's cells: a cell the reference does not see adds `τ²`, as
/// much as a mismatch, rather than being left out. So a candidate cannot win by seeing less, and
/// each cell's term depends on that cell alone, which is what gives the exact search its bound
/// (a normalization by the cells compared would couple every term to every other).
#[doc(hidden)]
pub struct CostSum {
    sum: f64,
    count: usize,
    inliers: usize,
    unseen: usize,
    truncation_sq: f32,
}

impl CostSum {
    #[doc(hidden)]
    pub fn new(truncation_sq: f32) -> Self {
        Self {
            sum: 0.0,
            count: 0,
            inliers: 0,
            unseen: 0,
            truncation_sq,
        }
    }

    #[inline]
    #[doc(hidden)]
    pub fn add(&mut self, a: f32, b: f32) {
        // Nagatani 2003, Sec. III-C, eq. (1): the difference of the two ranges in one direction,
        // here squared and truncated (robust), summed over the query's cells.
        let e = a - b;
        self.add_squared(e * e);
    }

    /// A compared cell whose squared difference is `e2` (truncated here; `∞` for a mismatch).
    #[inline]
    #[doc(hidden)]
    pub fn add_squared(&mut self, e2: f32) {
        self.sum += e2.min(self.truncation_sq) as f64;
        self.count += 1;
        self.inliers += (e2 < self.truncation_sq) as usize;
    }

    /// A query cell whose direction the reference does not see: a full mismatch.
    #[inline]
    #[doc(hidden)]
    pub fn add_unseen(&mut self) {
        self.sum += self.truncation_sq as f64;
        self.unseen += 1;
    }

    /// The sum so far (never decreases: every term is >= 0).
    #[inline]
    #[doc(hidden)]
    pub fn partial(&self) -> f64 {
        self.sum
    }

    #[doc(hidden)]
    pub fn finish(self, min_overlap: usize) -> Option<Correlation> {
        // Eq. (1) as the mean over the query's cells; too little overlap is no candidate at all.
        let total = self.count + self.unseen;
        (self.count >= min_overlap && self.count > 0).then(|| Correlation {
            cost: self.sum / total as f64,
            overlap: self.count,
            inliers: self.inliers,
        })
    }
}

/// Eq. (1) between a virtual S-DEM and the local S-DEM in the paper's form: the mean truncated
/// squared range difference over cells known in both, or `None` when they share too few cells.
pub fn correlate(virtual_sdem: &Sdem, local: &Sdem, cost: &CostConfig) -> Option<Correlation> {
    let mut acc = CostSum::new(cost.truncation_sq());
    for &cell in local.cells() {
        let c = cell as usize;
        let v = virtual_sdem.ranges()[c];
        if v.is_nan() {
            acc.add_unseen();
        } else {
            acc.add(v, local.ranges()[c]);
        }
    }
    acc.finish(cost.min_overlap(local.known_cells()))
}

/// The query points the projective cost compares (see [`CostConfig::search_voxel_m`] and
/// [`CostConfig::max_search_points`]): one per cube (the point nearest the cube's centre), the
/// cubes grown by a quarter at a time from `cost.search_voxel_m` until at most
/// `cost.max_search_points` remain; every boundary point for a voxel of 0. In S-DEM cell order.
///
/// Where a cube size leaves more than [`JUMP_RATIO`] times the cap (a LiDAR's 30,000 boundary
/// points against 1,500), the next size is the one that would leave 0.9 times the cap if the
/// points thinned out as they did over the last two sizes, taken as at least the first power
/// of the cube's side (the square on open surfaces; nearer the first power on a street seen
/// from a car; less while the cubes are smaller than the points' spacing), and so on until
/// less than a quarter over the cap: three or four passes instead of fifteen, each over every
/// boundary point. Otherwise (every SICK scan of `sdem bench`: at most 3.2 times the cap) the
/// cubes grow by a quarter at a time.
pub fn search_points_of(query: &Sdem, cost: &CostConfig) -> Vec<[f32; 3]> {
    even_points(query, cost.search_voxel_m, cost.max_search_points)
}

/// See [`search_points_of`].
pub const JUMP_RATIO: f64 = 4.0;

/// One boundary point of `query` per cube, the cubes grown from `voxel_m` until at most `cap`
/// remain (0: no cap); see [`search_points_of`].
pub fn even_points(query: &Sdem, voxel_m: f64, cap: usize) -> Vec<[f32; 3]> {
    let points = query.points();
    (even_indices(query, voxel_m, cap).iter())
        .map(|&i| points[i as usize])
        .collect()
}

/// [`even_points`] as indices into `query.points()`, ascending.
pub fn even_indices(query: &Sdem, voxel_m: f64, cap: usize) -> Vec<u32> {
    let mut voxel = voxel_m;
    let mut last: Option<(f64, usize)> = None;
    loop {
        let points = search_indices(query, voxel);
        let n = points.len();
        if voxel <= 0.0 || cap == 0 || n <= cap {
            return points;
        }
        let ratio = n as f64 / cap as f64;
        // Once a first jump was taken, the jumps go on down to a quarter over the cap.
        let next = if ratio > JUMP_RATIO || (last.is_some() && ratio > 1.25) {
            // How the count fell with the cube's side over the last two sizes (2 until known).
            let exponent = last
                .map(|(v, m)| (m as f64 / n as f64).ln() / (voxel / v).ln())
                .filter(|e| e.is_finite() && *e > 0.0)
                .unwrap_or(2.0)
                .clamp(1.0, 3.0);
            voxel * (ratio / 0.9).powf(1.0 / exponent)
        } else {
            voxel * 1.25
        };
        if ratio > JUMP_RATIO || last.is_some() {
            last = Some((voxel, n));
        }
        voxel = next;
    }
}

/// The query points the projective cost compares: one per cube of side `voxel_m` (the point
/// nearest the cube's centre), or every boundary point for `voxel_m = 0`; in S-DEM cell order.
pub fn search_points(query: &Sdem, voxel_m: f64) -> Vec<[f32; 3]> {
    let points = query.points();
    (search_indices(query, voxel_m).iter())
        .map(|&i| points[i as usize])
        .collect()
}

/// [`search_points`] as indices into `query.points()`, ascending.
fn search_indices(query: &Sdem, voxel_m: f64) -> Vec<u32> {
    if voxel_m <= 0.0 {
        return (0..query.points().len() as u32).collect();
    }
    let v = voxel_m as f32;
    let points = query.points();
    let mut chosen: KeyMap<(u32, f32)> =
        KeyMap::with_capacity_and_hasher(points.len() / 4, Default::default());
    // The cube's point so far: the first of the nearest to its centre.
    let settle = |chosen: &mut KeyMap<(u32, f32)>, (key, i, d): (Key, u32, f32)| {
        chosen
            .entry(key)
            .and_modify(|e| {
                if d < e.1 {
                    *e = (i, d)
                }
            })
            .or_insert((i, d));
    };
    // The points come in S-DEM cell order, so neighbours often share a cube: a run of them is
    // settled here and enters the table once. With `floor_i32` for `floorf`, a pass over the
    // paper's query took 0.180 ms instead of 0.254.
    let mut run: Option<(Key, u32, f32)> = None;
    for (i, p) in points.iter().enumerate() {
        let key = Key(p.map(|c| crate::sdem::floor_i32(c / v)));
        let off = [0, 1, 2].map(|a| p[a] - (key.0[a] as f32 + 0.5) * v);
        let d = off[0] * off[0] + off[1] * off[1] + off[2] * off[2];
        match run.as_mut() {
            Some((k, best, best_d)) if *k == key => {
                if d < *best_d {
                    (*best, *best_d) = (i as u32, d);
                }
            }
            _ => {
                if let Some(done) = run.replace((key, i as u32, d)) {
                    settle(&mut chosen, done);
                }
            }
        }
    }
    if let Some(done) = run {
        settle(&mut chosen, done);
    }
    let mut kept: Vec<u32> = chosen.values().map(|e| e.0).collect();
    kept.sort_unstable();
    kept
}

/// Points per block of a capped evaluation: the sum is checked against the cap after each.
const BLOCK: usize = 512;

/// A query point `q` moved by a candidate: `rotation * q + t`, written out so that every
/// evaluation of a candidate moves its points with the same operations in the same order (the
/// exact search's lower bounds of a candidate must not exceed its cost by a rounding).
#[inline(always)]
fn moved(rotation: &Matrix3<f32>, t: &nalgebra::Vector3<f32>, [x, y, z]: [f32; 3]) -> [f32; 3] {
    let m = rotation;
    [
        m[(0, 0)] * x + m[(0, 1)] * y + m[(0, 2)] * z + t.x,
        m[(1, 0)] * x + m[(1, 1)] * y + m[(1, 2)] * z + t.y,
        m[(2, 0)] * x + m[(2, 1)] * y + m[(2, 2)] * z + t.z,
    ]
}

/// Points per chunk of [`Correlator::ordered_lower_bound`]: its sum is checked after each.
const ORDERED_CHUNK: usize = 64;

/// A fixed permutation of `0..n` that spreads neighbours apart: `i ↦ i · s mod n` with a stride
/// `s` near `n / φ` coprime to `n` (every index once).
#[doc(hidden)]
pub fn scrambled_order(n: usize) -> Vec<usize> {
    if n < 3 {
        return (0..n).collect();
    }
    let gcd = |mut a: usize, mut b: usize| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    let mut stride = ((n as f64) * 0.618_033_988_75) as usize;
    while gcd(stride, n) != 1 {
        stride += 1;
    }
    (0..n).map(|i| (i * stride) % n).collect()
}

/// A capped evaluation's answer (see [`Correlator::evaluate_capped`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[doc(hidden)]
pub enum Capped {
    /// At or below the cap.
    Scored(Correlation),
    /// Above the cap: the mean cost reached when the sum was cut short (at most the full cost).
    Above(f64),
    /// Too few cells compared: no candidate.
    NoOverlap,
}

/// `Rz(yaw)` in single precision.
#[doc(hidden)]
pub fn yaw_matrix(yaw: f64) -> Matrix3<f32> {
    let (s, c) = yaw.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0).cast::<f32>()
}

/// Scores candidates of one reference/query pair without allocating. For the virtual-S-DEM model
/// `evaluate(t, 0)` equals `correlate(&reference.virtual_at(t), query)`.
///
/// Every search of a localization and each of its workers clone one correlator: cloning copies
/// the chosen query points, where [`Correlator::new`] chooses them again.
#[derive(Clone)]
pub struct Correlator<'a> {
    reference: &'a Sdem,
    query: &'a Sdem,
    model: CostModel,
    truncation_sq: f32,
    min_overlap: usize,
    min_range: f32,
    zbuffer: Vec<f32>,
    /// The query's boundary points, one coordinate per array (projective model).
    query_xyz: [Vec<f32>; 3],
    /// Where each of [`Self::search_points`] lies in `query_xyz`.
    slot_of_point: Vec<u32>,
    /// Scratch: moved points, their cells and ranges.
    moved: [Vec<f32>; 3],
    cells: Vec<u32>,
    ranges: Vec<f32>,
    /// The prediction and its weight in cost units per m² (see [`OffsetPrior`]).
    prior: Option<(OffsetPrior, f64)>,
}

impl<'a> Correlator<'a> {
    /// A correlator of `query` against `reference`; both must share one grid.
    pub fn new(reference: &'a Sdem, query: &'a Sdem, cost: &CostConfig) -> Result<Self> {
        cost.validate()?;
        if reference.grid() != query.grid() {
            return Err(Error::Invalid(
                "the reference and query S-DEMs use different grids; build both with one SdemConfig"
                    .into(),
            ));
        }
        let zbuffer = match cost.model {
            CostModel::VirtualSdem => vec![f32::NAN; reference.grid().len()],
            CostModel::Projective => Vec::new(),
        };
        let points = match cost.model {
            CostModel::Projective => search_points_of(query, cost),
            CostModel::VirtualSdem => Vec::new(),
        };
        let n = points.len();
        let compared = match cost.model {
            CostModel::Projective => n,
            CostModel::VirtualSdem => query.known_cells(),
        };
        let prior = cost.prior.map(|p| {
            let weight = cost.truncation_m.powi(2) / (compared.max(1) as f64 * p.sigma_m.powi(2));
            (p, weight)
        });
        // The points in a scrambled order, so that a partial sum is a fair sample of the whole
        // and a capped evaluation can stop early (see `evaluate_capped`).
        let order = scrambled_order(n);
        let column = |k: usize| -> Vec<f32> { order.iter().map(|&i| points[i][k]).collect() };
        let mut slot_of_point = vec![0u32; n];
        for (slot, &i) in order.iter().enumerate() {
            slot_of_point[i] = slot as u32;
        }
        Ok(Self {
            query_xyz: [column(0), column(1), column(2)],
            slot_of_point,
            moved: [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            cells: vec![0; n],
            ranges: vec![0.0; n],
            reference,
            query,
            model: cost.model,
            truncation_sq: cost.truncation_sq(),
            min_overlap: match cost.model {
                CostModel::Projective => cost.min_overlap(n),
                CostModel::VirtualSdem => cost.min_overlap(query.known_cells()),
            },
            min_range: reference.config().min_range_m as f32,
            zbuffer,
            prior,
        })
    }

    /// The reference S-DEM.
    #[doc(hidden)]
    pub fn reference(&self) -> &'a Sdem {
        self.reference
    }

    /// `τ²` in single precision.
    #[doc(hidden)]
    pub fn truncation_sq(&self) -> f32 {
        self.truncation_sq
    }

    /// The query points it compares (projective model), in the order [`search_points_of`]
    /// chose them (the correlator keeps them scrambled).
    #[doc(hidden)]
    pub fn search_points(&self) -> Vec<[f32; 3]> {
        let [x, y, z] = &self.query_xyz;
        let mut points = vec![[0.0; 3]; x.len()];
        for (k, i) in scrambled_order(x.len()).into_iter().enumerate() {
            points[i] = [x[k], y[k], z[k]];
        }
        points
    }

    /// The prediction's term at `offset` (0 without one), m².
    #[inline]
    pub fn prior_cost(&self, offset: &Vec3) -> f64 {
        self.prior
            .as_ref()
            .map_or(0.0, |(p, w)| w * p.squared_distance(offset))
    }

    /// The smallest prediction term over the box of offsets `lo ≤ t ≤ hi` (0 without one).
    #[doc(hidden)]
    pub fn prior_bound(&self, lo: &Vec3, hi: &Vec3) -> f64 {
        self.prior
            .as_ref()
            .map_or(0.0, |(p, w)| w * p.squared_distance_to_box(lo, hi))
    }

    /// The overlap a candidate needs.
    pub fn min_overlap(&self) -> usize {
        self.min_overlap
    }

    /// The number of query cells each candidate is scored over: the search points of the
    /// projective cost, the known cells of the virtual S-DEM cost.
    pub fn compared_points(&self) -> usize {
        match self.model {
            CostModel::Projective => self.query_xyz[0].len(),
            CostModel::VirtualSdem => self.query.known_cells(),
        }
    }

    /// The score of the candidate `(offset, yaw)`: query point `q` at `Rz(yaw) q + offset` in the
    /// reference's levelled frame.
    pub fn evaluate(&mut self, offset: &Vec3, yaw: f64) -> Option<Correlation> {
        match self.model {
            CostModel::Projective => {
                match self.evaluate_projective(offset, &yaw_matrix(yaw), f64::INFINITY) {
                    Capped::Scored(c) => Some(c),
                    Capped::Above(_) | Capped::NoOverlap => None,
                }
            }
            CostModel::VirtualSdem => self.evaluate_virtual(offset, &yaw_matrix(yaw)),
        }
    }

    /// The score of `(offset, yaw)` unless it certainly exceeds `cap` (a mean cost, m²): the
    /// sum is checked against the cap as it grows, point block by point block, and `None` is
    /// returned as soon as it is above (every term is >= 0, so the full sum would be too), or
    /// when the candidate compares too few cells. Below the cap, the result equals
    /// [`Self::evaluate`]'s bit for bit: the terms are added in the same order.
    ///
    /// The exact search scores its candidates this way, against the best cost found so far.
    pub fn evaluate_capped(&mut self, offset: &Vec3, yaw: f64, cap: f64) -> Option<Correlation> {
        match self.evaluate_within(offset, yaw, cap) {
            Capped::Scored(c) => Some(c),
            Capped::Above(_) | Capped::NoOverlap => None,
        }
    }

    /// [`Self::evaluate`] with the query turned by a whole rotation (`rotation`: its tilt as well
    /// as its heading, about the levelled axes) instead of a heading alone: the cost about a
    /// refined pose, whose tilt the query's attitude reading did not give. The virtual-S-DEM
    /// model takes the rotation's heading only.
    pub fn evaluate_turned(
        &mut self,
        offset: &Vec3,
        rotation: &nalgebra::UnitQuaternion<f64>,
    ) -> Option<Correlation> {
        match self.model {
            CostModel::Projective => {
                let m = rotation.to_rotation_matrix().into_inner().cast::<f32>();
                match self.evaluate_projective(offset, &m, f64::INFINITY) {
                    Capped::Scored(c) => Some(c),
                    Capped::Above(_) | Capped::NoOverlap => None,
                }
            }
            CostModel::VirtualSdem => {
                let (_, _, yaw) = rotation.euler_angles();
                self.evaluate_virtual(offset, &yaw_matrix(yaw))
            }
        }
    }

    /// [`Self::evaluate_capped`], saying why there is no score: above the cap (with the mean
    /// cost reached when the sum was cut short, a lower bound on the full cost), or too little
    /// overlap.
    #[doc(hidden)]
    pub fn evaluate_within(&mut self, offset: &Vec3, yaw: f64, cap: f64) -> Capped {
        match self.model {
            CostModel::Projective => self.evaluate_projective(offset, &yaw_matrix(yaw), cap),
            CostModel::VirtualSdem => match self.evaluate_virtual(offset, &yaw_matrix(yaw)) {
                Some(c) if c.cost <= cap => Capped::Scored(c),
                Some(c) => Capped::Above(c.cost),
                None => Capped::NoOverlap,
            },
        }
    }

    /// Eq. (1) of the query moved by `rotation` and `offset` against the reference's cell
    /// planes, stopped once its sum passes `cap`. Compiled twice, as the exact search's bound
    /// is: for the baseline x86-64 the build targets and for AVX2 (eight lanes where the moved
    /// points are binned into cells), chosen at run time; both compute the same values, bit for
    /// bit (the same operations in the same order, no fused multiply-add).
    fn evaluate_projective(&mut self, offset: &Vec3, rotation: &Matrix3<f32>, cap: f64) -> Capped {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has just been found to support AVX2.
            return unsafe { self.evaluate_projective_avx2(offset, rotation, cap) };
        }
        self.evaluate_projective_any(offset, rotation, cap)
    }

    /// [`Self::evaluate_projective`] with AVX2 instructions.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn evaluate_projective_avx2(
        &mut self,
        offset: &Vec3,
        rotation: &Matrix3<f32>,
        cap: f64,
    ) -> Capped {
        self.evaluate_projective_any(offset, rotation, cap)
    }

    /// [`Self::evaluate_projective`]'s body, inlined into each of its builds with the binning
    /// of the moved points ([`crate::sdem::GridSpec::cells_of`]).
    #[inline(always)]
    fn evaluate_projective_any(
        &mut self,
        offset: &Vec3,
        rotation: &Matrix3<f32>,
        cap: f64,
    ) -> Capped {
        let prior = self.prior_cost(offset);
        let grid = self.reference.grid();
        let surfaces = self.reference.surfaces();
        let t = offset.cast::<f32>();
        let m = rotation;
        let [qx, qy, qz] = &self.query_xyz;
        let [mx, my, mz] = &mut self.moved;
        let n = qx.len();
        // The cap on the sum of the points' terms; `f64::INFINITY` when uncapped.
        let cap_sum = (cap - prior) * n as f64;
        if cap_sum < 0.0 {
            return Capped::Above(prior);
        }
        let mut acc = CostSum::new(self.truncation_sq);
        for start in (0..n).step_by(BLOCK) {
            let end = (start + BLOCK).min(n);
            // Written as plain loops over arrays so the compiler vectorizes them.
            for i in start..end {
                [mx[i], my[i], mz[i]] = moved(m, &t, [qx[i], qy[i], qz[i]]);
            }
            grid.cells_of_any(
                &mx[start..end],
                &my[start..end],
                &mz[start..end],
                &mut self.cells[start..end],
                &mut self.ranges[start..end],
            );
            for i in start..end {
                let cell = self.cells[i];
                let found = if cell == u32::MAX {
                    None
                } else {
                    surfaces.squared_distance(cell as usize, [mx[i], my[i], mz[i]], self.ranges[i])
                };
                match found {
                    Some(e2) => acc.add_squared(e2),
                    None => acc.add_unseen(),
                }
            }
            if acc.partial() > cap_sum {
                return Capped::Above(acc.partial() / n as f64 + prior);
            }
        }
        match acc.finish(self.min_overlap) {
            Some(c) => Capped::Scored(Correlation {
                cost: c.cost + prior,
                ..c
            }),
            None => Capped::NoOverlap,
        }
    }

    /// A lower bound on eq. (1) at `(offset, yaw)` from the points in a given order: `saturated`
    /// points whose term is known to be `τ²` there (counted, not scored), then the points
    /// `order` names (indices into [`Self::search_points`]), summed until the sum passes `cap`
    /// (a mean cost, m²). The mean reached is returned: above `cap` when cut short, else the
    /// full cost in this order (equal to [`Self::evaluate`]'s up to rounding, when `saturated`
    /// and `order` cover every point; the overlap is not counted). The exact search scores a
    /// candidate this way first, its points in the order its box's bound found their terms
    /// largest (see `bnb::PointHint`): most candidates it scores lie above the best so far,
    /// and in that order their sums pass it after fewer points.
    #[doc(hidden)]
    pub fn ordered_lower_bound(
        &mut self,
        offset: &Vec3,
        yaw: f64,
        saturated: u32,
        order: &[u32],
        cap: f64,
    ) -> f64 {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has just been found to support AVX2.
            return unsafe { self.ordered_lower_bound_avx2(offset, yaw, saturated, order, cap) };
        }
        self.ordered_lower_bound_any(offset, yaw, saturated, order, cap)
    }

    /// [`Self::ordered_lower_bound`] with AVX2 instructions.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn ordered_lower_bound_avx2(
        &mut self,
        offset: &Vec3,
        yaw: f64,
        saturated: u32,
        order: &[u32],
        cap: f64,
    ) -> f64 {
        self.ordered_lower_bound_any(offset, yaw, saturated, order, cap)
    }

    /// [`Self::ordered_lower_bound`]'s body, inlined into each of its builds.
    #[inline(always)]
    fn ordered_lower_bound_any(
        &mut self,
        offset: &Vec3,
        yaw: f64,
        saturated: u32,
        order: &[u32],
        cap: f64,
    ) -> f64 {
        let prior = self.prior_cost(offset);
        let n = self.query_xyz[0].len();
        let mean = |sum: f64| sum / n as f64 + prior;
        let cap_sum = (cap - prior) * n as f64;
        let truncation_sq = self.truncation_sq;
        let mut sum = truncation_sq as f64 * saturated as f64;
        if sum > cap_sum {
            return mean(sum);
        }
        let grid = self.reference.grid();
        let surfaces = self.reference.surfaces();
        let t = offset.cast::<f32>();
        let m = yaw_matrix(yaw);
        let [qx, qy, qz] = &self.query_xyz;
        let [mx, my, mz] = &mut self.moved;
        for chunk in order.chunks(ORDERED_CHUNK) {
            let len = chunk.len();
            for (i, &p) in chunk.iter().enumerate() {
                let k = self.slot_of_point[p as usize] as usize;
                [mx[i], my[i], mz[i]] = moved(&m, &t, [qx[k], qy[k], qz[k]]);
            }
            grid.cells_of_any(
                &mx[..len],
                &my[..len],
                &mz[..len],
                &mut self.cells[..len],
                &mut self.ranges[..len],
            );
            for i in 0..len {
                let cell = self.cells[i];
                let term = if cell == u32::MAX {
                    None
                } else {
                    surfaces.squared_distance(cell as usize, [mx[i], my[i], mz[i]], self.ranges[i])
                };
                sum += term.map_or(truncation_sq, |e2| e2.min(truncation_sq)) as f64;
            }
            if sum > cap_sum {
                break;
            }
        }
        mean(sum)
    }

    fn evaluate_virtual(&mut self, offset: &Vec3, rotation: &Matrix3<f32>) -> Option<Correlation> {
        let grid = *self.reference.grid();
        let o = offset.cast::<f32>();
        let back = rotation.transpose();
        let identity = *rotation == Matrix3::identity();
        self.zbuffer.fill(f32::NAN);
        // Paper Sec. III-C: move each boundary point of the reference to the candidate origin and
        // keep the nearest per cell (the virtual S-DEM).
        for p in self.reference.points() {
            let d = [p[0] - o.x, p[1] - o.y, p[2] - o.z];
            let q = if identity {
                d
            } else {
                let v = back * nalgebra::Vector3::new(d[0], d[1], d[2]);
                [v.x, v.y, v.z]
            };
            if let Some((cell, r)) = grid.cell_of(q) {
                let z = &mut self.zbuffer[cell as usize];
                if r >= self.min_range && (z.is_nan() || r < *z) {
                    *z = r;
                }
            }
        }
        let mut acc = CostSum::new(self.truncation_sq);
        let local_ranges = self.query.ranges();
        for &cell in self.query.cells() {
            let v = self.zbuffer[cell as usize];
            if v.is_nan() {
                acc.add_unseen();
            } else {
                acc.add(v, local_ranges[cell as usize]);
            }
        }
        let prior = self.prior_cost(offset);
        acc.finish(self.min_overlap).map(|c| Correlation {
            cost: c.cost + prior,
            ..c
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Attitude;
    use crate::sdem::SdemConfig;

    /// The build chosen at run time (AVX2 where the processor has it) and the baseline build
    /// score every candidate alike, bit for bit, capped or not.
    #[test]
    fn both_builds_of_the_cost_score_alike() {
        let room = crate::test_scenes::room(0.05);
        let cfg = SdemConfig::default();
        let level = Attitude::default();
        let reference = Sdem::from_points(&room, &level, &cfg).unwrap();
        let moved: Vec<Vec3> = room
            .iter()
            .map(|p| p - Vec3::new(0.1, -0.05, 0.02))
            .collect();
        let query = Sdem::from_points(&moved, &level, &cfg).unwrap();
        let mut correlator = Correlator::new(&reference, &query, &CostConfig::default()).unwrap();
        let (mut scored, mut above) = (0, 0);
        for k in 0..400 {
            let t = k as f64;
            let offset = Vec3::new(
                0.1 + 0.2 * (0.37 * t).sin(),
                -0.05 + 0.2 * (0.53 * t).cos(),
                0.02 + 0.05 * (0.71 * t).sin(),
            );
            let m = yaw_matrix(0.1 * (0.29 * t).sin());
            let cap = if k % 2 == 0 { f64::INFINITY } else { 5e-4 };
            let any = correlator.evaluate_projective_any(&offset, &m, cap);
            let chosen = correlator.evaluate_projective(&offset, &m, cap);
            assert_eq!(
                format!("{chosen:?}"),
                format!("{any:?}"),
                "offset {offset:?}"
            );
            match chosen {
                Capped::Scored(_) => scored += 1,
                Capped::Above(_) => above += 1,
                Capped::NoOverlap => {}
            }
        }
        assert!(
            scored > 50 && above > 50,
            "{scored} scored, {above} above the cap"
        );
    }
}
