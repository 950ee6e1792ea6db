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
//! Both compare ranges in the same direction, truncate the squared difference at `τ`, skip cells
//! unknown on either side and normalize by the cells compared.

use crate::error::{Error, Result};
use crate::geometry::Vec3;
use crate::sdem::Sdem;
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
    /// Range differences are truncated at this value, metres, so moved rubble or a person walking
    /// by adds a bounded penalty instead of dragging the estimate.
    pub truncation_m: f64,
    /// A candidate must compare at least this many cells.
    pub min_overlap_cells: usize,
    /// … and at least this fraction of the query S-DEM's known cells.
    pub min_overlap_fraction: f64,
    /// The best candidate is accepted only when at least this fraction of the query's known
    /// cells match it within the truncation; otherwise the search reports that nothing matched
    /// (a best candidate far from everything is still a best candidate).
    pub min_inlier_fraction: f64,
}

impl Default for CostConfig {
    fn default() -> Self {
        Self {
            model: CostModel::Projective,
            truncation_m: 0.10,
            min_overlap_cells: 200,
            min_overlap_fraction: 0.2,
            min_inlier_fraction: 0.1,
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
        if !(0.0..=1.0).contains(&self.min_inlier_fraction) {
            return Err(Error::Invalid(format!(
                "minimum inlier fraction {} must lie in [0, 1]",
                self.min_inlier_fraction
            )));
        }
        Ok(())
    }

    /// The overlap (cells) a candidate needs against a query S-DEM with `query_known` cells.
    pub fn min_overlap(&self, query_known: usize) -> usize {
        let fraction = (self.min_overlap_fraction * query_known as f64).ceil() as usize;
        self.min_overlap_cells.max(fraction).max(1)
    }

    /// `τ²` in single precision, as every term is computed.
    pub(crate) fn truncation_sq(&self) -> f32 {
        let t = self.truncation_m as f32;
        t * t
    }
}

/// The score of one candidate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Correlation {
    /// Mean truncated squared range difference over the compared cells, m² (the paper's `d`).
    pub cost: f64,
    /// Number of cells compared.
    pub overlap: usize,
    /// Of those, cells whose range difference lies within the truncation (the matched cells).
    pub inliers: usize,
}

/// Accumulates eq. (1) cell by cell; every evaluator goes through it so all compute exactly the
/// same number for the same candidate.
pub(crate) struct CostSum {
    sum: f64,
    count: usize,
    inliers: usize,
    truncation_sq: f32,
}

impl CostSum {
    pub(crate) fn new(truncation_sq: f32) -> Self {
        Self {
            sum: 0.0,
            count: 0,
            inliers: 0,
            truncation_sq,
        }
    }

    #[inline]
    pub(crate) fn add(&mut self, a: f32, b: f32) {
        // Nagatani 2003, Sec. III-C, eq. (1): the difference of the two ranges in one direction,
        // here squared and truncated (robust), summed over the cells known on both sides.
        let e = a - b;
        let e2 = e * e;
        self.sum += e2.min(self.truncation_sq) as f64;
        self.count += 1;
        self.inliers += (e2 < self.truncation_sq) as usize;
    }

    pub(crate) fn finish(self, min_overlap: usize) -> Option<Correlation> {
        // Eq. (1), normalized by the cells compared, so a candidate cannot win by seeing less.
        (self.count >= min_overlap && self.count > 0).then(|| Correlation {
            cost: self.sum / self.count as f64,
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
        if !v.is_nan() {
            acc.add(v, local.ranges()[c]);
        }
    }
    acc.finish(cost.min_overlap(local.known_cells()))
}

/// `Rz(yaw)` in single precision.
pub(crate) fn yaw_matrix(yaw: f64) -> Matrix3<f32> {
    let (s, c) = yaw.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0).cast::<f32>()
}

/// Scores candidates of one reference/query pair without allocating. For the virtual-S-DEM model
/// `evaluate(t, 0)` equals `correlate(&reference.virtual_at(t), query)`.
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
    /// Scratch: moved points, their cells and ranges.
    moved: [Vec<f32>; 3],
    cells: Vec<u32>,
    ranges: Vec<f32>,
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
        let n = match cost.model {
            CostModel::Projective => query.points().len(),
            CostModel::VirtualSdem => 0,
        };
        let column = |k: usize| -> Vec<f32> { query.points()[..n].iter().map(|p| p[k]).collect() };
        Ok(Self {
            query_xyz: [column(0), column(1), column(2)],
            moved: [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            cells: vec![0; n],
            ranges: vec![0.0; n],
            reference,
            query,
            model: cost.model,
            truncation_sq: cost.truncation_sq(),
            min_overlap: cost.min_overlap(query.known_cells()),
            min_range: reference.config().min_range_m as f32,
            zbuffer,
        })
    }

    /// The overlap a candidate needs.
    pub fn min_overlap(&self) -> usize {
        self.min_overlap
    }

    /// The score of the candidate `(offset, yaw)`: query point `q` at `Rz(yaw) q + offset` in the
    /// reference's levelled frame.
    pub fn evaluate(&mut self, offset: &Vec3, yaw: f64) -> Option<Correlation> {
        match self.model {
            CostModel::Projective => self.evaluate_projective(offset, &yaw_matrix(yaw)),
            CostModel::VirtualSdem => self.evaluate_virtual(offset, &yaw_matrix(yaw)),
        }
    }

    fn evaluate_projective(
        &mut self,
        offset: &Vec3,
        rotation: &Matrix3<f32>,
    ) -> Option<Correlation> {
        let grid = self.reference.grid();
        let reference_ranges = self.reference.ranges();
        let t = offset.cast::<f32>();
        let m = rotation;
        let [qx, qy, qz] = &self.query_xyz;
        let [mx, my, mz] = &mut self.moved;
        // Written as plain loops over arrays so the compiler vectorizes them; the same
        // arithmetic as `rotation * q + t`.
        for i in 0..qx.len() {
            let (x, y, z) = (qx[i], qy[i], qz[i]);
            mx[i] = m[(0, 0)] * x + m[(0, 1)] * y + m[(0, 2)] * z + t.x;
            my[i] = m[(1, 0)] * x + m[(1, 1)] * y + m[(1, 2)] * z + t.y;
            mz[i] = m[(2, 0)] * x + m[(2, 1)] * y + m[(2, 2)] * z + t.z;
        }
        grid.cells_of(mx, my, mz, &mut self.cells, &mut self.ranges);
        let mut acc = CostSum::new(self.truncation_sq);
        for (&cell, &r) in self.cells.iter().zip(&self.ranges) {
            if cell != u32::MAX {
                let reference_range = reference_ranges[cell as usize];
                if !reference_range.is_nan() {
                    acc.add(r, reference_range);
                }
            }
        }
        acc.finish(self.min_overlap)
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
            if !v.is_nan() {
                acc.add(v, local_ranges[cell as usize]);
            }
        }
        acc.finish(self.min_overlap)
    }
}
