//! The candidate grid and the searches over it that score candidates one by one: the paper's
//! exhaustive search (the oracle) and a coarse-to-fine heuristic. The exact fast search is in
//! [`crate::bnb`].

use crate::cost::{Correlation, Correlator};
use crate::error::{Error, Result};
use crate::geometry::Vec3;
use crate::sdem::Sdem;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// The box of candidate offsets (query origin minus reference origin, world axes, metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SearchWindow {
    /// Smallest offset on each axis.
    pub min: [f64; 3],
    /// Largest offset on each axis.
    pub max: [f64; 3],
}

#[doc(hidden)]
pub const AXES: [&str; 3] = ["x", "y", "z"];

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

    /// The part of this window inside `bounds` (each bound exactly one of the two windows').
    pub fn clipped_to(&self, bounds: &SearchWindow) -> Self {
        Self {
            min: std::array::from_fn(|a| self.min[a].max(bounds.min[a])),
            max: std::array::from_fn(|a| self.max[a].min(bounds.max[a])),
        }
    }

    /// Checks that the window is finite and not inverted.
    pub fn validate(&self) -> Result<()> {
        for (axis, name) in AXES.iter().enumerate() {
            let (lo, hi) = (self.min[axis], self.max[axis]);
            if !lo.is_finite() || !hi.is_finite() {
                return Err(Error::Invalid(format!(
                    "search window {name}: bounds must be finite numbers (got {lo}:{hi})"
                )));
            }
            if lo > hi {
                return Err(Error::Invalid(format!(
                    "search window {name} is inverted ({lo}:{hi}); give it as min:max with min <= max"
                )));
            }
        }
        Ok(())
    }

    /// The candidate positions along x, y and z on a grid of step `step_m`: the window's lowest
    /// corner, then every whole step that stays within it. A search scores each at every
    /// heading; the window and the step alone fix them, so a caller can size a search before
    /// any scan is read.
    ///
    /// # Errors
    /// [`Error::Invalid`] for an invalid window, a step that is not a positive number, or an
    /// axis of more than [`MAX_AXIS_STEPS`] positions.
    ///
    /// # Example
    /// ```
    /// let window = sdem::SearchWindow::paper(); // x -0.5..0.5, y -0.3..0.6, z -0.1..0.1 m
    /// assert_eq!(window.positions(0.01)?, [101, 91, 21]);
    /// # Ok::<(), sdem::Error>(())
    /// ```
    pub fn positions(&self, step_m: f64) -> Result<[usize; 3]> {
        self.validate()?;
        if !(step_m.is_finite() && step_m > 0.0) {
            return Err(Error::Invalid(format!(
                "search step {step_m} m must be a positive number"
            )));
        }
        let mut counts = [0; 3];
        for (axis, count) in counts.iter_mut().enumerate() {
            let n = ((self.max[axis] - self.min[axis]) / step_m + 1e-9).floor() + 1.0;
            if n > MAX_AXIS_STEPS as f64 {
                return Err(Error::Invalid(format!(
                    "search window {} spans {n} steps; use a larger step or a smaller window",
                    AXES[axis]
                )));
            }
            *count = n as usize;
        }
        Ok(counts)
    }
}

/// The most positions a search window may hold along one axis ([`SearchWindow::positions`]).
pub const MAX_AXIS_STEPS: usize = 100_000;

/// The most candidates (positions × headings) any search's grid may hold.
pub const MAX_GRID_CANDIDATES: usize = 2_000_000_000;

/// The heading search around the compass reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HeadingWindow {
    /// Headings within ± this of the compass reading are searched, degrees (0: trust the compass;
    /// 180: a full turn).
    pub half_range_deg: f64,
    /// The heading step, degrees; `None` matches it to the scan's extent: the step that moves a
    /// point at the query's median horizontal range by one translation step.
    pub step_deg: Option<f64>,
}

impl Default for HeadingWindow {
    fn default() -> Self {
        Self {
            half_range_deg: 10.0,
            step_deg: None,
        }
    }
}

impl HeadingWindow {
    /// Trust the compass: no heading search.
    pub fn none() -> Self {
        Self {
            half_range_deg: 0.0,
            step_deg: None,
        }
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<()> {
        if !(self.half_range_deg.is_finite() && (0.0..=180.0).contains(&self.half_range_deg)) {
            return Err(Error::Invalid(format!(
                "heading window ±{}° must lie in [0, 180] degrees",
                self.half_range_deg
            )));
        }
        if let Some(step) = self.step_deg {
            if !(step.is_finite() && step > 0.0) {
                return Err(Error::Invalid(format!(
                    "heading step {step}° must be a positive number of degrees"
                )));
            }
        }
        Ok(())
    }

    /// The heading samples, radians: `k · step` for `k` in `-m..=m`, with the step shrunk so that
    /// `±half_range` are samples (a full turn is not sampled twice).
    pub fn samples(&self, matched_step_rad: f64) -> Vec<f64> {
        let half = self.half_range_deg.to_radians();
        if half <= 0.0 {
            return vec![0.0];
        }
        let step = self
            .step_deg
            .map_or(matched_step_rad, f64::to_radians)
            .max(1e-6);
        let m = (half / step).ceil().max(1.0) as i64;
        let step = half / m as f64;
        let full_turn = (half - std::f64::consts::PI).abs() < 1e-9;
        (-m..=m)
            .filter(|&k| !(full_turn && k == m))
            .map(|k| k as f64 * step)
            .collect()
    }
}

/// The finest heading step [`matched_heading_step`] gives, degrees.
pub const MIN_MATCHED_HEADING_STEP_DEG: f64 = 0.05;

/// The coarsest heading step [`matched_heading_step`] gives, degrees: a heading window holds at
/// least as many headings as at this step, whatever the scan.
pub const MAX_MATCHED_HEADING_STEP_DEG: f64 = 2.0;

/// The heading step matched to a query's extent: a point at the median horizontal range moves by
/// one translation step (clamped to [`MIN_MATCHED_HEADING_STEP_DEG`]..
/// [`MAX_MATCHED_HEADING_STEP_DEG`]). Farther points move more; the 6-DoF refinement takes the
/// heading below the step.
pub fn matched_heading_step(query: &Sdem, step_m: f64) -> f64 {
    heading_step_for_extent(horizontal_extent(query), step_m)
}

/// [`matched_heading_step`] for a query of horizontal extent `extent`
/// ([`horizontal_extent`]; 1° without one).
pub fn heading_step_for_extent(extent: Option<f64>, step_m: f64) -> f64 {
    let Some(extent) = extent else {
        return 1f64.to_radians();
    };
    (step_m / extent).clamp(
        MIN_MATCHED_HEADING_STEP_DEG.to_radians(),
        MAX_MATCHED_HEADING_STEP_DEG.to_radians(),
    )
}

/// The median horizontal range of a query's points, at least 10 cm: how far a turn of one
/// radian moves a typical point. `None` without points.
pub fn horizontal_extent(query: &Sdem) -> Option<f64> {
    let mut ranges: Vec<f32> = query
        .points()
        .iter()
        .map(|p| (p[0] * p[0] + p[1] * p[1]).sqrt())
        .collect();
    if ranges.is_empty() {
        return None;
    }
    let k = ranges.len() / 2;
    let (_, r, _) = ranges.select_nth_unstable_by(k, f32::total_cmp);
    Some((*r as f64).max(0.1))
}

/// The regular grid of candidates: translation on `counts[0..3]`, heading on `yaws`.
#[derive(Debug, Clone)]
#[doc(hidden)]
pub struct CandidateGrid {
    pub min: [f64; 3],
    pub step: f64,
    pub counts: [usize; 4],
    pub yaws: Vec<f64>,
    /// Candidates left out of every search: the runner-up search excludes the peak's
    /// neighbourhood (at every heading) and the optimum's own slopes (at their headings only).
    pub exclude: Vec<Exclusion>,
}

/// Candidates left out of a search: those whose translation lies within `radius` (metres) of
/// `centre` and whose heading index lies in `headings` (inclusive).
#[derive(Debug, Clone, Copy, PartialEq)]
#[doc(hidden)]
pub struct Exclusion {
    pub centre: Vec3,
    pub radius: f64,
    pub headings: [usize; 2],
}

impl Exclusion {
    /// The candidates within `radius` of `centre`, at every heading.
    pub fn ball(centre: Vec3, radius: f64) -> Self {
        Self::at_headings(centre, radius, [0, usize::MAX])
    }

    /// The candidates within `radius` of `centre` at the heading indices `first..=last`.
    pub fn at_headings(centre: Vec3, radius: f64, [first, last]: [usize; 2]) -> Self {
        Self {
            centre,
            radius,
            headings: [first, last],
        }
    }
}

/// Integer coordinates of a candidate: x, y, z, heading.
#[doc(hidden)]
pub type Index = [usize; 4];

impl CandidateGrid {
    pub fn new(window: &SearchWindow, step: f64, yaws: Vec<f64>) -> Result<Self> {
        let [x, y, z] = window.positions(step)?;
        let counts = [x, y, z, yaws.len().max(1)];
        let total = counts.iter().product::<usize>();
        if total > MAX_GRID_CANDIDATES {
            return Err(Error::Invalid(format!(
                "the search grid has {total} candidates; use a larger step or a smaller window"
            )));
        }
        Ok(Self {
            min: window.min,
            step,
            counts,
            yaws: if yaws.is_empty() { vec![0.0] } else { yaws },
            exclude: Vec::new(),
        })
    }

    /// True when the candidate is left out (see [`Self::exclude`]).
    pub fn excluded(&self, idx: Index) -> bool {
        let offset = self.offset(idx);
        self.exclude.iter().any(|e| {
            let [first, last] = e.headings;
            (first..=last).contains(&idx[3]) && (offset - e.centre).norm() <= e.radius
        })
    }

    /// True when every candidate of the box `lo..=hi` lies within one of the excluded balls
    /// (a box the balls cover only together is kept: its candidates are left out one by one).
    pub fn box_excluded(&self, lo: Index, hi: Index) -> bool {
        self.exclude.iter().any(|e| {
            let (a, b) = (self.offset(lo) - e.centre, self.offset(hi) - e.centre);
            let far = Vec3::new(
                a.x.abs().max(b.x.abs()),
                a.y.abs().max(b.y.abs()),
                a.z.abs().max(b.z.abs()),
            );
            e.headings[0] <= lo[3] && hi[3] <= e.headings[1] && far.norm() <= e.radius
        })
    }

    pub fn len(&self) -> usize {
        self.counts.iter().product()
    }

    /// Whether the grid has no candidate.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn index(&self, flat: usize) -> Index {
        let [nx, ny, nz, _] = self.counts;
        [
            flat % nx,
            (flat / nx) % ny,
            (flat / (nx * ny)) % nz,
            flat / (nx * ny * nz),
        ]
    }

    pub fn flat(&self, idx: Index) -> usize {
        let [nx, ny, nz, _] = self.counts;
        idx[0] + nx * (idx[1] + ny * (idx[2] + nz * idx[3]))
    }

    /// The offset at (possibly fractional) translation coordinates.
    pub fn offset_at(&self, idx: [f64; 3]) -> Vec3 {
        Vec3::new(
            self.min[0] + idx[0] * self.step,
            self.min[1] + idx[1] * self.step,
            self.min[2] + idx[2] * self.step,
        )
    }

    pub fn offset(&self, idx: Index) -> Vec3 {
        self.offset_at([idx[0] as f64, idx[1] as f64, idx[2] as f64])
    }

    pub fn yaw(&self, idx: Index) -> f64 {
        self.yaws[idx[3]]
    }

    /// True when the candidate lies on the boundary of the translation window, or of a heading
    /// window that is not a full turn.
    pub fn on_edge(&self, idx: Index, full_turn: bool) -> bool {
        (0..4).any(|a| {
            self.counts[a] > 1
                && (idx[a] == 0 || idx[a] + 1 == self.counts[a])
                && !(a == 3 && full_turn)
        })
    }

    /// The neighbour displaced by `d`, if inside the grid (headings wrap on a full turn).
    pub fn neighbour(&self, idx: Index, d: [i64; 4], full_turn: bool) -> Option<Index> {
        let mut out = [0; 4];
        for a in 0..4 {
            let n = self.counts[a] as i64;
            let mut v = idx[a] as i64 + d[a];
            if a == 3 && full_turn {
                v = v.rem_euclid(n);
            }
            if v < 0 || v >= n {
                return None;
            }
            out[a] = v as usize;
        }
        Some(out)
    }
}

/// A scored candidate: `(cost, flat index)`, ordered by cost then index so every search breaks
/// ties the same way.
#[doc(hidden)]
pub type Scored = (f64, usize);

#[doc(hidden)]
pub fn better(a: &Scored, b: &Scored) -> bool {
    a.0 < b.0 || (a.0 == b.0 && a.1 < b.1)
}

/// Scores candidates in parallel and memoizes them, so each is evaluated once.
#[doc(hidden)]
pub struct Evaluator<'a> {
    pub grid: &'a CandidateGrid,
    pub memo: HashMap<usize, Option<Correlation>>,
    /// Candidates scored so far.
    pub evaluated: usize,
    /// Cloned for each worker.
    prototype: Correlator<'a>,
}

impl<'a> Evaluator<'a> {
    /// Scores the candidates of `grid` with clones of `prototype`.
    pub fn new(prototype: Correlator<'a>, grid: &'a CandidateGrid) -> Self {
        Self {
            prototype,
            grid,
            memo: HashMap::new(),
            evaluated: 0,
        }
    }

    /// A correlator of its own for a worker.
    pub fn correlator(&self) -> Correlator<'a> {
        self.prototype.clone()
    }

    /// Scores (or recalls) each candidate; returns those with enough overlap.
    pub fn score(&mut self, flats: &[usize]) -> Vec<Scored> {
        let mut fresh: Vec<usize> = flats
            .iter()
            .copied()
            .filter(|f| !self.memo.contains_key(f))
            .collect();
        fresh.sort_unstable();
        fresh.dedup();
        let grid = self.grid;
        let results: Vec<(usize, Option<Correlation>)> = fresh
            .par_iter()
            .map_init(
                || self.correlator(),
                |c, &flat| {
                    let idx = grid.index(flat);
                    if grid.excluded(idx) {
                        return (flat, None);
                    }
                    (flat, c.evaluate(&grid.offset(idx), grid.yaw(idx)))
                },
            )
            .collect();
        self.evaluated += results.len();
        self.memo.extend(results);
        flats
            .iter()
            .filter_map(|f| self.memo[f].map(|c| (c.cost, *f)))
            .collect()
    }

    /// The paper's search: every candidate of the grid, in parallel.
    pub fn exhaustive(&mut self) -> Option<Scored> {
        let grid = self.grid;
        let best = (0..grid.len())
            .into_par_iter()
            .map_init(
                || self.correlator(),
                |c, flat| {
                    let idx = grid.index(flat);
                    if grid.excluded(idx) {
                        return None;
                    }
                    c.evaluate(&grid.offset(idx), grid.yaw(idx))
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
        self.evaluated += grid.len();
        let (cost, flat, r) = best?;
        self.memo.insert(flat, Some(r));
        Some((cost, flat))
    }

    /// Coarse-to-fine: score a coarse sub-grid, keep the best few, score their neighbourhoods on
    /// the next finer level, and finish with a descent to a local minimum of the full grid.
    pub fn coarse_to_fine(
        &mut self,
        coarse_step_m: f64,
        keep: usize,
        full_turn: bool,
    ) -> Option<Scored> {
        let grid = self.grid;
        let max_count = *grid.counts[..3].iter().max().unwrap_or(&1);
        let mut level = 0u32;
        while grid.step * f64::from(1u32 << (level + 1)) <= coarse_step_m + 1e-12
            && (1usize << (level + 1)) < max_count
        {
            level += 1;
        }
        let spacing = 1usize << level;
        let samples = |n: usize| -> Vec<usize> {
            let mut v: Vec<usize> = (0..n).step_by(spacing).collect();
            if v.last() != Some(&(n - 1)) {
                v.push(n - 1);
            }
            v
        };
        let axes: Vec<Vec<usize>> = (0..4).map(|a| samples(grid.counts[a])).collect();
        let mut flats = Vec::new();
        for &l in &axes[3] {
            for &k in &axes[2] {
                for &j in &axes[1] {
                    for &i in &axes[0] {
                        flats.push(grid.flat([i, j, k, l]));
                    }
                }
            }
        }
        let keep = keep.max(1);
        let mut kept = best_few(self.score(&flats), keep);
        while level > 0 {
            level -= 1;
            let s = 1i64 << level;
            let mut next = Vec::new();
            for &(_, flat) in &kept {
                let idx = grid.index(flat);
                for_each_offset(2, grid.counts[3] > 1, |d| {
                    let d = [d[0] * s, d[1] * s, d[2] * s, d[3] * s];
                    if let Some(n) = grid.neighbour(idx, d, full_turn) {
                        next.push(grid.flat(n));
                    }
                });
            }
            kept = best_few(self.score(&next), keep);
        }
        let mut best = *kept.first()?;
        loop {
            let idx = grid.index(best.1);
            let mut around = Vec::with_capacity(80);
            for_each_offset(1, grid.counts[3] > 1, |d| {
                if let Some(n) = grid.neighbour(idx, d, full_turn) {
                    around.push(grid.flat(n));
                }
            });
            let candidate =
                self.score(&around)
                    .into_iter()
                    .fold(best, |b, s| if better(&s, &b) { s } else { b });
            if candidate == best {
                return Some(best);
            }
            best = candidate;
        }
    }
}

/// Calls `f` with every offset in `[-r, r]^3` (and the heading axis when `with_heading`).
fn for_each_offset(r: i64, with_heading: bool, mut f: impl FnMut([i64; 4])) {
    let rh = if with_heading { r } else { 0 };
    for dl in -rh..=rh {
        for dz in -r..=r {
            for dy in -r..=r {
                for dx in -r..=r {
                    f([dx, dy, dz, dl]);
                }
            }
        }
    }
}

fn best_few(mut scored: Vec<Scored>, keep: usize) -> Vec<Scored> {
    scored.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    scored.dedup_by_key(|s| s.1);
    scored.truncate(keep);
    scored
}
