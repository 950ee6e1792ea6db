//! Correlation localization (Nagatani et al. 2003, Sec. III-C).
//!
//! A reference S-DEM's boundary points are re-projected around a candidate origin into a *virtual
//! S-DEM*; the candidate whose virtual S-DEM differs least from the new (local) S-DEM is the
//! sensor's position. Both S-DEMs are levelled by the gyro/compass, so the search runs over
//! translation only: the candidate is the query sensor's origin minus the reference sensor's
//! origin, on world axes.
//!
//! Two searches share one cost: the paper's exhaustive search over a window at a step (the oracle,
//! kept forever), and a coarse-to-fine search that evaluates a small fraction of the candidates.

use crate::error::{Error, Result};
use crate::geometry::{Attitude, Pose, Vec3};
use crate::refine::{refine, RefineConfig, Refinement, SurfaceNormals};
use crate::sdem::Sdem;
use nalgebra::{Isometry3, SMatrix, SVector, Translation3, UnitQuaternion};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// How the difference between a virtual and a local S-DEM is scored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CostConfig {
    /// Range differences are truncated at this value, metres, so moved rubble or a person walking
    /// by adds a bounded penalty instead of dragging the estimate.
    pub truncation_m: f64,
    /// A candidate must compare at least this many cells.
    pub min_overlap_cells: usize,
    /// … and at least this fraction of the local S-DEM's known cells.
    pub min_overlap_fraction: f64,
}

impl Default for CostConfig {
    fn default() -> Self {
        Self {
            truncation_m: 0.10,
            min_overlap_cells: 200,
            min_overlap_fraction: 0.2,
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
        Ok(())
    }

    /// The overlap (cells) a candidate needs against a local S-DEM with `local_known` cells.
    pub fn min_overlap(&self, local_known: usize) -> usize {
        let fraction = (self.min_overlap_fraction * local_known as f64).ceil() as usize;
        self.min_overlap_cells.max(fraction).max(1)
    }
}

/// The score of one candidate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Correlation {
    /// Mean truncated squared range difference over the compared cells, m² (the paper's `d`).
    pub cost: f64,
    /// Number of cells known in both S-DEMs.
    pub overlap: usize,
}

/// Accumulates eq. (1) cell by cell; shared by [`correlate`] and [`Correlator`] so both compute
/// exactly the same number.
struct CostSum {
    sum: f64,
    count: usize,
    truncation_sq: f32,
}

impl CostSum {
    fn new(truncation_m: f64) -> Self {
        let t = truncation_m as f32;
        Self {
            sum: 0.0,
            count: 0,
            truncation_sq: t * t,
        }
    }

    #[inline]
    fn add(&mut self, virtual_range: f32, local_range: f32) {
        // Nagatani 2003, Sec. III-C, eq. (1): the difference between the virtual S-DEM's and the
        // local S-DEM's range in the same cell, here squared and truncated (robust), summed over the
        // cells known in both.
        let e = virtual_range - local_range;
        self.sum += (e * e).min(self.truncation_sq) as f64;
        self.count += 1;
    }

    fn finish(self, min_overlap: usize) -> Option<Correlation> {
        // Eq. (1), normalized by the cells compared, so a candidate cannot win by seeing less.
        (self.count >= min_overlap && self.count > 0).then(|| Correlation {
            cost: self.sum / self.count as f64,
            overlap: self.count,
        })
    }
}

/// Eq. (1) between a virtual S-DEM and the local S-DEM: the mean truncated squared range
/// difference over cells known in both, or `None` when they share too few cells.
pub fn correlate(virtual_sdem: &Sdem, local: &Sdem, cost: &CostConfig) -> Option<Correlation> {
    let mut acc = CostSum::new(cost.truncation_m);
    for &cell in local.cells() {
        let c = cell as usize;
        let v = virtual_sdem.ranges()[c];
        if !v.is_nan() {
            acc.add(v, local.ranges()[c]);
        }
    }
    acc.finish(cost.min_overlap(local.known_cells()))
}

/// Evaluates eq. (1) at many candidate origins without allocating: the virtual S-DEM is rendered
/// into a reusable z-buffer. `evaluate(o)` equals `correlate(&reference.virtual_at(o), local)`.
pub struct Correlator<'a> {
    reference: &'a Sdem,
    local: &'a Sdem,
    truncation_m: f64,
    min_overlap: usize,
    min_range: f32,
    zbuffer: Vec<f32>,
}

impl<'a> Correlator<'a> {
    /// A correlator of `local` against virtual S-DEMs of `reference`; both must share one grid.
    pub fn new(reference: &'a Sdem, local: &'a Sdem, cost: &CostConfig) -> Result<Self> {
        cost.validate()?;
        if reference.grid() != local.grid() {
            return Err(Error::Invalid(
                "the reference and local S-DEMs use different grids; build both with one SdemConfig"
                    .into(),
            ));
        }
        Ok(Self {
            reference,
            local,
            truncation_m: cost.truncation_m,
            min_overlap: cost.min_overlap(local.known_cells()),
            min_range: reference.config().min_range_m as f32,
            zbuffer: vec![f32::NAN; reference.grid().len()],
        })
    }

    /// The score of the candidate origin `origin` (reference levelled frame, metres).
    pub fn evaluate(&mut self, origin: &Vec3) -> Option<Correlation> {
        let o = [origin.x as f32, origin.y as f32, origin.z as f32];
        let grid = *self.reference.grid();
        self.zbuffer.fill(f32::NAN);
        // Paper Sec. III-C: move each boundary point of the reference to the candidate origin and
        // keep the nearest per cell (the virtual S-DEM).
        for p in self.reference.points() {
            let q = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
            if let Some((cell, r)) = grid.cell_of(q) {
                let z = &mut self.zbuffer[cell as usize];
                if r >= self.min_range && !(*z <= r) {
                    *z = r;
                }
            }
        }
        let mut acc = CostSum::new(self.truncation_m);
        let local_ranges = self.local.ranges();
        for &cell in self.local.cells() {
            let v = self.zbuffer[cell as usize];
            if !v.is_nan() {
                acc.add(v, local_ranges[cell as usize]);
            }
        }
        acc.finish(self.min_overlap)
    }
}

/// The box of candidate offsets (query origin minus reference origin, world axes, metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SearchWindow {
    /// Smallest offset on each axis.
    pub min: [f64; 3],
    /// Largest offset on each axis.
    pub max: [f64; 3],
}

impl SearchWindow {
    /// The paper's window (Sec. V, P-3): x −0.5..0.5, y −0.3..0.6, z −0.1..0.1 m.
    pub fn paper() -> Self {
        Self {
            min: [-0.5, -0.3, -0.1],
            max: [0.5, 0.6, 0.1],
        }
    }

    /// A window of half-size `half` (metres per axis) around `center`.
    pub fn around(center: &Vec3, half: [f64; 3]) -> Self {
        Self {
            min: [center.x - half[0], center.y - half[1], center.z - half[2]],
            max: [center.x + half[0], center.y + half[1], center.z + half[2]],
        }
    }

    /// Checks that the window is finite and not inverted.
    pub fn validate(&self) -> Result<()> {
        for axis in 0..3 {
            let (lo, hi) = (self.min[axis], self.max[axis]);
            if !lo.is_finite() || !hi.is_finite() {
                return Err(Error::Invalid(format!(
                    "search window {}: bounds must be finite numbers (got {lo}:{hi})",
                    AXES[axis]
                )));
            }
            if lo > hi {
                return Err(Error::Invalid(format!(
                    "search window {} is inverted ({lo}:{hi}); give it as min:max with min <= max",
                    AXES[axis]
                )));
            }
        }
        Ok(())
    }
}

const AXES: [&str; 3] = ["x", "y", "z"];

/// Which search runs over the window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SearchMode {
    /// Every candidate of the grid (the paper's method; the oracle).
    Exhaustive,
    /// A pyramid of coarser grids, keeping the best candidates at each level, then a descent to a
    /// local minimum on the full grid.
    CoarseToFine,
}

/// Everything a localization needs besides the two S-DEMs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalizeConfig {
    /// The candidate window.
    pub window: SearchWindow,
    /// Grid step, metres (paper: 1 cm).
    pub step_m: f64,
    /// Exhaustive or coarse-to-fine.
    pub mode: SearchMode,
    /// The cost.
    pub cost: CostConfig,
    /// Refine the grid optimum to sub-grid accuracy: robust 6-DoF point-to-plane refinement
    /// ([`crate::refine`]), falling back to a quadratic fit of the grid costs around the optimum.
    pub refine: bool,
    /// Settings of the 6-DoF refinement.
    pub refinement: RefineConfig,
    /// Coarse-to-fine: spacing of the coarsest level, metres (rounded down to step · 2^k).
    pub coarse_step_m: f64,
    /// Coarse-to-fine: candidates kept at each level.
    pub keep: usize,
}

impl Default for LocalizeConfig {
    fn default() -> Self {
        Self {
            window: SearchWindow::paper(),
            step_m: 0.01,
            mode: SearchMode::CoarseToFine,
            cost: CostConfig::default(),
            refine: true,
            refinement: RefineConfig::default(),
            coarse_step_m: 0.08,
            keep: 8,
        }
    }
}

/// The result of a localization.
#[derive(Debug, Clone, PartialEq)]
pub struct Localization {
    /// The query sensor's pose in the reference sensor's frame:
    /// `inverse(world_from_reference) * world_from_query`.
    pub reference_from_query: Pose,
    /// The estimated offset (query origin − reference origin, world axes), refined when asked.
    pub offset: Vec3,
    /// The best grid candidate's offset.
    pub grid_offset: Vec3,
    /// The best grid candidate's integer coordinates in the window's grid.
    pub grid_index: [usize; 3],
    /// Eq. (1) at the best grid candidate, m².
    pub cost: f64,
    /// Cells compared at the best grid candidate.
    pub overlap: usize,
    /// Candidate origins scored.
    pub candidates_evaluated: usize,
    /// True when the grid optimum lies on the window's boundary (the true minimum may be outside).
    pub on_window_edge: bool,
    /// How the estimate was refined below the grid.
    pub refined: RefineOutcome,
    /// The 6-DoF refinement's result, when it succeeded.
    pub refinement: Option<Refinement>,
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

/// The regular grid of candidates over a window.
#[derive(Debug, Clone, Copy)]
struct CandidateGrid {
    min: [f64; 3],
    step: f64,
    counts: [usize; 3],
}

impl CandidateGrid {
    fn new(window: &SearchWindow, step: f64) -> Result<Self> {
        window.validate()?;
        if !(step.is_finite() && step > 0.0) {
            return Err(Error::Invalid(format!(
                "search step {step} m must be a positive number"
            )));
        }
        let mut counts = [0; 3];
        for axis in 0..3 {
            let n = ((window.max[axis] - window.min[axis]) / step + 1e-9).floor() + 1.0;
            if n > 100_000.0 {
                return Err(Error::Invalid(format!(
                    "search window {} spans {n} steps; use a larger step or a smaller window",
                    AXES[axis]
                )));
            }
            counts[axis] = n as usize;
        }
        let total = counts.iter().product::<usize>();
        if total > 200_000_000 {
            return Err(Error::Invalid(format!(
                "the search grid has {total} candidates; use a larger step or a smaller window"
            )));
        }
        Ok(Self {
            min: window.min,
            step,
            counts,
        })
    }

    fn len(&self) -> usize {
        self.counts.iter().product()
    }

    fn index(&self, flat: usize) -> [usize; 3] {
        let i = flat % self.counts[0];
        let j = (flat / self.counts[0]) % self.counts[1];
        let k = flat / (self.counts[0] * self.counts[1]);
        [i, j, k]
    }

    fn flat(&self, idx: [usize; 3]) -> usize {
        idx[0] + self.counts[0] * (idx[1] + self.counts[1] * idx[2])
    }

    fn offset_at(&self, idx: [f64; 3]) -> Vec3 {
        Vec3::new(
            self.min[0] + idx[0] * self.step,
            self.min[1] + idx[1] * self.step,
            self.min[2] + idx[2] * self.step,
        )
    }

    fn offset(&self, idx: [usize; 3]) -> Vec3 {
        self.offset_at([idx[0] as f64, idx[1] as f64, idx[2] as f64])
    }

    fn on_edge(&self, idx: [usize; 3]) -> bool {
        (0..3).any(|a| self.counts[a] > 1 && (idx[a] == 0 || idx[a] + 1 == self.counts[a]))
    }

    /// The neighbour of `idx` displaced by `d` grid steps, if it lies inside the grid.
    fn neighbour(&self, idx: [usize; 3], d: [i64; 3]) -> Option<[usize; 3]> {
        let mut out = [0; 3];
        for a in 0..3 {
            let v = idx[a] as i64 + d[a];
            if v < 0 || v >= self.counts[a] as i64 {
                return None;
            }
            out[a] = v as usize;
        }
        Some(out)
    }
}

/// A scored candidate: `(cost, flat index)`, ordered by cost then index so every search breaks
/// ties the same way.
type Scored = (f64, usize);

fn better(a: &Scored, b: &Scored) -> bool {
    a.0 < b.0 || (a.0 == b.0 && a.1 < b.1)
}

/// Scores candidates in parallel and memoizes them, so each is evaluated once.
struct Evaluator<'a> {
    reference: &'a Sdem,
    local: &'a Sdem,
    cost: &'a CostConfig,
    grid: CandidateGrid,
    memo: HashMap<usize, Option<Correlation>>,
    /// Candidates scored so far (the refinement's included).
    evaluated: usize,
}

impl<'a> Evaluator<'a> {
    fn score(&mut self, flats: &[usize]) -> Result<Vec<Scored>> {
        let fresh: Vec<usize> = {
            let mut f: Vec<usize> = flats
                .iter()
                .copied()
                .filter(|f| !self.memo.contains_key(f))
                .collect();
            f.sort_unstable();
            f.dedup();
            f
        };
        // Validate once (grids, cost) before fanning out.
        Correlator::new(self.reference, self.local, self.cost)?;
        let grid = self.grid;
        let results: Vec<(usize, Option<Correlation>)> = fresh
            .par_iter()
            .map_init(
                || Correlator::new(self.reference, self.local, self.cost).expect("validated above"),
                |c, &flat| (flat, c.evaluate(&grid.offset(grid.index(flat)))),
            )
            .collect();
        self.evaluated += results.len();
        self.memo.extend(results);
        Ok(flats
            .iter()
            .filter_map(|f| self.memo[f].map(|c| (c.cost, *f)))
            .collect())
    }
}

/// Localizes `query` against `reference`.
///
/// # Arguments
/// * `reference`, `query` — S-DEMs on one grid, each levelled by its own attitude reading.
/// * `reference_attitude`, `query_attitude` — those readings (they set the relative rotation).
/// * `config` — window, step, search mode, cost.
///
/// # Returns
/// The best candidate with its cost and overlap, or an error when the configuration is invalid or
/// no candidate in the window shares enough cells with the query.
///
/// # Example
/// ```
/// use sdem::geometry::{Attitude, Vec3};
/// use sdem::localize::{localize, LocalizeConfig, SearchWindow};
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
/// let reference = Sdem::from_points(&room, &level.rotation(), &cfg).unwrap();
/// let moved: Vec<Vec3> = room.iter().map(|p| p - Vec3::new(0.1, 0.0, 0.0)).collect();
/// let query = Sdem::from_points(&moved, &level.rotation(), &cfg).unwrap();
/// let config = LocalizeConfig {
///     window: SearchWindow { min: [-0.2, -0.1, -0.05], max: [0.2, 0.1, 0.05] },
///     ..Default::default()
/// };
/// let found = localize(&reference, &level, &query, &level, &config).unwrap();
/// assert!((found.offset - Vec3::new(0.1, 0.0, 0.0)).norm() < 0.01);
/// ```
pub fn localize(
    reference: &Sdem,
    reference_attitude: &Attitude,
    query: &Sdem,
    query_attitude: &Attitude,
    config: &LocalizeConfig,
) -> Result<Localization> {
    config.cost.validate()?;
    let grid = CandidateGrid::new(&config.window, config.step_m)?;
    let mut evaluator = Evaluator {
        reference,
        local: query,
        cost: &config.cost,
        grid,
        memo: HashMap::new(),
        evaluated: 0,
    };
    let best = match config.mode {
        SearchMode::Exhaustive => exhaustive(&mut evaluator)?,
        SearchMode::CoarseToFine => coarse_to_fine(&mut evaluator, config)?,
    };
    let Some((cost, flat)) = best else {
        return Err(Error::Localize(format!(
            "no candidate in the window shares {} cells with the query S-DEM ({} known); \
             check the window and the attitudes, or lower the minimum overlap",
            config.cost.min_overlap(query.known_cells()),
            query.known_cells()
        )));
    };
    let grid_index = grid.index(flat);
    let grid_offset = grid.offset(grid_index);
    let overlap = evaluator.memo[&flat].map_or(0, |c| c.overlap);
    let mut rotation_correction = UnitQuaternion::identity();
    let mut refinement = None;
    let (offset, refined) = if !config.refine {
        (grid_offset, RefineOutcome::None)
    } else {
        let normals = SurfaceNormals::new(reference, config.refinement.normal_radius_cells);
        let initial =
            Isometry3::from_parts(Translation3::from(grid_offset), UnitQuaternion::identity());
        match refine(reference, &normals, query, &initial, &config.refinement) {
            Ok(r) => {
                rotation_correction = r.transform.rotation;
                let t = r.transform.translation.vector;
                refinement = Some(r);
                (t, RefineOutcome::SixDof)
            }
            Err(_) => match refine_quadratic(&mut evaluator, grid_index)? {
                Some(o) => (o, RefineOutcome::Quadratic),
                None => (grid_offset, RefineOutcome::Failed),
            },
        }
    };
    // reference_level_from_query_level = (correction, offset); the levelled frames are the sensor
    // frames rotated by their attitude readings.
    let world_from_reference = rotation_only(reference_attitude);
    let world_from_query = Isometry3::from_parts(
        Translation3::from(offset),
        rotation_correction * rotation_only(query_attitude).rotation,
    );
    Ok(Localization {
        reference_from_query: world_from_reference.inverse() * world_from_query,
        offset,
        grid_offset,
        grid_index,
        cost,
        overlap,
        candidates_evaluated: evaluator.evaluated,
        on_window_edge: grid.on_edge(grid_index),
        refined,
        refinement,
    })
}

fn rotation_only(attitude: &Attitude) -> Pose {
    Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&attitude.rotation()),
    )
}

/// The paper's search: every candidate of the grid, in parallel.
fn exhaustive(evaluator: &mut Evaluator) -> Result<Option<Scored>> {
    let grid = evaluator.grid;
    Correlator::new(evaluator.reference, evaluator.local, evaluator.cost)?;
    let (reference, local, cost) = (evaluator.reference, evaluator.local, evaluator.cost);
    let best = (0..grid.len())
        .into_par_iter()
        .map_init(
            || Correlator::new(reference, local, cost).expect("validated above"),
            |c, flat| {
                c.evaluate(&grid.offset(grid.index(flat)))
                    .map(|r| (r.cost, flat, r))
            },
        )
        .flatten()
        .reduce_with(|a, b| {
            if better(&(b.0, b.1), &(a.0, a.1)) {
                b
            } else {
                a
            }
        });
    // Record only the winner in the memo (the refinement reads it); count every candidate.
    if let Some((_, flat, r)) = best {
        evaluator.memo.insert(flat, Some(r));
    }
    evaluator.evaluated += grid.len();
    Ok(best.map(|(c, f, _)| (c, f)))
}

/// Coarse-to-fine: score a coarse sub-grid, keep the best few, score their neighbourhoods on the
/// next finer level, and finish with a descent to a local minimum of the full grid.
fn coarse_to_fine(evaluator: &mut Evaluator, config: &LocalizeConfig) -> Result<Option<Scored>> {
    let grid = evaluator.grid;
    let max_count = *grid.counts.iter().max().unwrap_or(&1);
    let mut level = 0u32;
    while grid.step * f64::from(1u32 << (level + 1)) <= config.coarse_step_m + 1e-12
        && (1usize << (level + 1)) < max_count
    {
        level += 1;
    }
    // Level `level`: every 2^level-th candidate, plus the last one on each axis.
    let spacing = 1usize << level;
    let axis_samples = |n: usize| -> Vec<usize> {
        let mut v: Vec<usize> = (0..n).step_by(spacing).collect();
        if v.last() != Some(&(n - 1)) {
            v.push(n - 1);
        }
        v
    };
    let (xs, ys, zs) = (
        axis_samples(grid.counts[0]),
        axis_samples(grid.counts[1]),
        axis_samples(grid.counts[2]),
    );
    let mut flats = Vec::with_capacity(xs.len() * ys.len() * zs.len());
    for &k in &zs {
        for &j in &ys {
            for &i in &xs {
                flats.push(grid.flat([i, j, k]));
            }
        }
    }
    let mut kept = best_few(evaluator.score(&flats)?, config.keep.max(1));
    while level > 0 {
        level -= 1;
        let s = 1i64 << level;
        let mut next = Vec::new();
        for &(_, flat) in &kept {
            let idx = grid.index(flat);
            for dz in -2..=2 {
                for dy in -2..=2 {
                    for dx in -2..=2 {
                        if let Some(n) = grid.neighbour(idx, [dx * s, dy * s, dz * s]) {
                            next.push(grid.flat(n));
                        }
                    }
                }
            }
        }
        kept = best_few(evaluator.score(&next)?, config.keep.max(1));
    }
    // Descend on the full grid until the best candidate beats all 26 neighbours.
    let Some(mut best) = kept.first().copied() else {
        return Ok(None);
    };
    loop {
        let idx = grid.index(best.1);
        let mut around = Vec::with_capacity(26);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if let Some(n) = grid.neighbour(idx, [dx, dy, dz]) {
                        around.push(grid.flat(n));
                    }
                }
            }
        }
        let scored = evaluator.score(&around)?;
        let candidate = scored
            .into_iter()
            .fold(best, |b, s| if better(&s, &b) { s } else { b });
        if candidate == best {
            return Ok(Some(best));
        }
        best = candidate;
    }
}

fn best_few(mut scored: Vec<Scored>, keep: usize) -> Vec<Scored> {
    scored.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    scored.dedup_by_key(|s| s.1);
    scored.truncate(keep);
    scored
}

/// Sub-grid refinement: fits `c(u) = a + bᵀu + ½ uᵀHu` to the 27 costs around the grid optimum
/// (u in grid steps) and returns the fitted minimum when the fit is convex and the minimum lies
/// within one step. Neighbours outside the window are scored too: the cost exists there.
fn refine_quadratic(evaluator: &mut Evaluator, idx: [usize; 3]) -> Result<Option<Vec3>> {
    let grid = evaluator.grid;
    let mut correlator = Correlator::new(evaluator.reference, evaluator.local, evaluator.cost)?;
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
                let Some(c) = correlator.evaluate(&grid.offset_at(at)) else {
                    return Ok(None);
                };
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
    let Some(theta) = ata.cholesky().map(|ch| ch.solve(&atb)) else {
        return Ok(None);
    };
    let b = nalgebra::Vector3::new(theta[1], theta[2], theta[3]);
    let h = nalgebra::Matrix3::new(
        theta[4], theta[7], theta[8], theta[7], theta[5], theta[9], theta[8], theta[9], theta[6],
    );
    let Some(chol) = h.cholesky() else {
        return Ok(None);
    };
    let u = -chol.solve(&b);
    if u.iter().any(|v| !v.is_finite() || v.abs() > 1.0) {
        return Ok(None);
    }
    Ok(Some(grid.offset_at([
        idx[0] as f64 + u[0],
        idx[1] as f64 + u[1],
        idx[2] as f64 + u[2],
    ])))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::pose_from_parts;
    use crate::sensor::SensorConfig;
    use crate::sim;
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A scan of `scene` from `world_from_sensor`, as an S-DEM with its attitude reading.
    fn sdem_at(
        scene: &sim::Scene,
        world_from_sensor: &Pose,
        sensor: &SensorConfig,
        grid: &SdemConfig,
        seed: u64,
    ) -> (Sdem, Attitude) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let sweep = sim::scan(scene, sensor, world_from_sensor, 0.0, &mut rng);
        let attitude = sweep.mean_attitude();
        let s = Sdem::from_points(&sweep.points_in_sensor(), &attitude.rotation(), grid).unwrap();
        (s, attitude)
    }

    fn noise_free(step_deg: f64) -> SensorConfig {
        SensorConfig {
            range_noise_m: 0.0,
            tilt_sensor_noise_deg: 0.0,
            compass_noise_deg: 0.0,
            tilt_step_deg: step_deg,
            pan_step_deg: step_deg,
            ..Default::default()
        }
    }

    use crate::sdem::SdemConfig;

    #[test]
    fn correlator_equals_the_virtual_sdem_correlation() {
        let scene = sim::paper_room();
        let grid = SdemConfig::default();
        let sensor = SensorConfig::default();
        let (reference, _) = sdem_at(&scene, &Pose::identity(), &sensor, &grid, 1);
        let moved = pose_from_parts(Vec3::new(0.1, 0.05, 0.02), Attitude::default());
        let (local, _) = sdem_at(&scene, &moved, &sensor, &grid, 2);
        let cost = CostConfig::default();
        let mut correlator = Correlator::new(&reference, &local, &cost).unwrap();
        for o in [
            Vec3::zeros(),
            Vec3::new(0.1, 0.05, 0.02),
            Vec3::new(-0.3, 0.2, -0.05),
        ] {
            let fast = correlator.evaluate(&o);
            let slow = correlate(&reference.virtual_at(&o), &local, &cost);
            assert_eq!(fast, slow, "at {o:?}");
        }
        // The truth scores better than a candidate 5 cm away.
        let at_truth = correlator.evaluate(&Vec3::new(0.1, 0.05, 0.02)).unwrap();
        let off = correlator.evaluate(&Vec3::new(0.15, 0.05, 0.02)).unwrap();
        assert!(at_truth.cost < off.cost);
    }

    #[test]
    fn exhaustive_finds_on_grid_truth_without_noise() {
        let scene = sim::paper_room();
        let grid = SdemConfig::default();
        let sensor = noise_free(1.0);
        let truth = Vec3::new(0.06, -0.04, 0.02);
        let (reference, ra) = sdem_at(&scene, &Pose::identity(), &sensor, &grid, 3);
        let (query, qa) = sdem_at(
            &scene,
            &pose_from_parts(truth, Attitude::default()),
            &sensor,
            &grid,
            4,
        );
        let config = LocalizeConfig {
            window: SearchWindow {
                min: [-0.1, -0.1, -0.1],
                max: [0.1, 0.1, 0.1],
            },
            step_m: 0.02,
            mode: SearchMode::Exhaustive,
            refine: false,
            ..Default::default()
        };
        let found = localize(&reference, &ra, &query, &qa, &config).unwrap();
        assert_eq!(found.candidates_evaluated, 11 * 11 * 11);
        assert!(
            (found.grid_offset - truth).norm() < 1e-9,
            "found {:?}, truth {truth:?}",
            found.grid_offset
        );
        assert!(!found.on_window_edge);
    }

    #[test]
    fn tilted_query_is_localized() {
        // The paper's second case: the body stands on a rock, tilted 8°.
        let scene = sim::paper_room();
        let grid = SdemConfig::default();
        let sensor = SensorConfig::default();
        let truth = pose_from_parts(
            Vec3::new(0.22, 0.36, 0.05),
            Attitude::from_degrees(3.0, 8.0, 0.0),
        );
        let (reference, ra) = sdem_at(&scene, &Pose::identity(), &sensor, &grid, 5);
        let (query, qa) = sdem_at(&scene, &truth, &sensor, &grid, 6);
        let found = localize(&reference, &ra, &query, &qa, &LocalizeConfig::default()).unwrap();
        let error =
            (found.reference_from_query.translation.vector - truth.translation.vector).norm();
        assert!(error < 0.01, "error {error} m");
    }

    #[test]
    fn bad_windows_and_steps_are_errors() {
        let scene = sim::paper_room();
        let grid = SdemConfig::default();
        let (s, a) = sdem_at(
            &scene,
            &Pose::identity(),
            &SensorConfig::default(),
            &grid,
            7,
        );
        let inverted = LocalizeConfig {
            window: SearchWindow {
                min: [0.1, 0.0, 0.0],
                max: [-0.1, 0.0, 0.0],
            },
            ..Default::default()
        };
        let message = localize(&s, &a, &s, &a, &inverted).unwrap_err().to_string();
        assert!(message.contains("inverted"), "{message}");
        for step in [0.0, -0.01, f64::NAN] {
            let config = LocalizeConfig {
                step_m: step,
                ..Default::default()
            };
            assert!(localize(&s, &a, &s, &a, &config).is_err());
        }
        let nan = LocalizeConfig {
            window: SearchWindow {
                min: [f64::NAN, 0.0, 0.0],
                max: [0.1, 0.0, 0.0],
            },
            ..Default::default()
        };
        assert!(localize(&s, &a, &s, &a, &nan).is_err());
    }

    #[test]
    fn no_overlap_is_an_error_not_a_pose() {
        let scene = sim::paper_room();
        let grid = SdemConfig::default();
        let (s, a) = sdem_at(
            &scene,
            &Pose::identity(),
            &SensorConfig::default(),
            &grid,
            8,
        );
        // Candidates 50 m away see nothing of the reference.
        let far = LocalizeConfig {
            window: SearchWindow {
                min: [50.0, 50.0, 0.0],
                max: [50.1, 50.1, 0.0],
            },
            ..Default::default()
        };
        let error = localize(&s, &a, &s, &a, &far).unwrap_err();
        assert!(matches!(error, Error::Localize(_)), "{error}");
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

        /// The default search lands on the same grid minimum as the exhaustive oracle.
        #[test]
        fn coarse_to_fine_finds_the_exhaustive_minimum(
            seed in 0u64..1_000_000,
            x in -0.3f64..0.3, y in -0.2f64..0.4, z in -0.05f64..0.05,
            yaw in -30.0f64..30.0,
        ) {
            let scene = sim::paper_room();
            let grid = SdemConfig { resolution_deg: 2.0, ..Default::default() };
            let sensor = SensorConfig { tilt_step_deg: 2.0, pan_step_deg: 2.0, ..Default::default() };
            let truth = pose_from_parts(Vec3::new(x, y, z), Attitude::from_degrees(0.0, 0.0, yaw));
            let (reference, ra) = sdem_at(&scene, &Pose::identity(), &sensor, &grid, seed);
            let (query, qa) = sdem_at(&scene, &truth, &sensor, &grid, seed + 1);
            let window = SearchWindow::around(&Vec3::new(x, y, z), [0.12, 0.12, 0.06]);
            let base = LocalizeConfig { window, step_m: 0.02, refine: false, ..Default::default() };
            let oracle = localize(&reference, &ra, &query, &qa,
                &LocalizeConfig { mode: SearchMode::Exhaustive, ..base.clone() }).unwrap();
            let fast = localize(&reference, &ra, &query, &qa, &base).unwrap();
            prop_assert_eq!(fast.grid_index, oracle.grid_index);
            prop_assert_eq!(fast.cost, oracle.cost);
            prop_assert!(fast.candidates_evaluated < oracle.candidates_evaluated);
        }
    }
}
