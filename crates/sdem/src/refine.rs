//! Continuous 6-DoF refinement of a grid optimum to sub-grid accuracy.
//!
//! The grid search finds the basin; this finds the bottom. Each point of the query S-DEM is
//! carried into the reference's levelled frame by the current estimate and looked up in the
//! reference S-DEM in the same direction (the S-DEM *is* the projective association), and the
//! point-to-plane distance to the reference surface there is minimized by robust Gauss-Newton over
//! translation and a small rotation (the gyro's roll and pitch and the compass's yaw are
//! measurements, not truth), each residual weighed by the robust kernel and by how thin its
//! reference patch is (a rough patch's plane is a poorer model of its surface). The Gauss-Newton
//! Hessian gives the information matrix of the result.

use crate::cost::OffsetPrior;
use crate::error::{Error, Result};
use crate::geometry::Vec3;
use crate::sdem::Sdem;
use nalgebra::{Isometry3, Matrix6, Rotation3, Translation3, UnitQuaternion, Vector6};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub mod discrepancy;
mod normals;

pub use normals::{SurfaceNormals, BLEND_RADIUS_CELLS};

/// Settings of the refinement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefineConfig {
    /// Gauss-Newton iterations at most.
    pub max_iterations: usize,
    /// Scale of the robust (Geman-McClure) kernel, metres: residuals much larger count little.
    /// Also the scale `s` of each residual's thickness weight `s² / (s² + λ0)`, `λ0` its
    /// reference patch's variance along the patch's normal.
    pub kernel_scale_m: f64,
    /// Pairs farther apart than this are not associated, metres.
    pub max_correspondence_m: f64,
    /// Estimate the rotation too (else translation only).
    pub estimate_rotation: bool,
    /// A rotation correction larger than this is rejected as implausible, degrees.
    pub max_rotation_deg: f64,
    /// A translation correction larger than this is rejected (left the basin), metres.
    pub max_translation_m: f64,
    /// Neighbourhood radius, in cells, for the reference surface normals.
    pub normal_radius_cells: usize,
    /// Fewer associated points than this fails the refinement.
    pub min_inliers: usize,
    /// How a query point finds its reference point.
    pub association: Association,
    /// Converged when an update moves less than this, metres (and radians). 10 µm: on the 50
    /// pairs of `sdem bench` 1 µm took 18 iterations where 10 µm took 9, with the same errors
    /// to the micrometre (median 0.77 mm, max 3.64 mm) and 16 ms less a pair; 30 µm took 4–7
    /// and let the worst pair's error grow to 4.32 mm.
    pub converged_step: f64,
    /// While the estimate moves by more than a millimetre an update (the pairs change), at most
    /// this many query points are refined (0, the default: every boundary point), one per
    /// cube of a side grown from 5 cm until they fit ([`crate::cost::even_points`], as the
    /// search's points are chosen); then, for the rest of the iterations (at least half of
    /// them), every boundary point. The sample makes the first, long strides cheap on a
    /// LiDAR's 30,000–50,000 points; it cannot finish them: spread evenly, most of it lies far
    /// away, where the reference's cells are decimetres wide and hold no plane (on re-views of
    /// KITTI frames 13 % of a 3,000-point sample paired, and it left 4–6 mm of error where every
    /// point leaves 0.6; see [`crate::localize::REFINE_POINTS`]).
    pub max_points: usize,
    /// With a radius above 0, once settled, a query point's residual is its distance from the
    /// reference's surface blended over the reference points in the 3 × 3 cells around its
    /// pair's and within this many cells' widths at its range (their planes averaged with
    /// weights `(1 − d² / R²)²` of their distance `d` from it; [`BLEND_RADIUS_CELLS`] is the
    /// radius measured best), not from its nearest point's plane alone. 0 (the default) keeps
    /// the nearest point's plane: the blend is more accurate on pairs of real scans but changed
    /// the loop's course on hard routes (see [`BLEND_RADIUS_CELLS`]). At most 2: beyond, the
    /// 3 × 3 cells hold too few of the points the radius reaches.
    pub blend_radius_cells: f64,
}

/// The largest [`RefineConfig::blend_radius_cells`]: the blend reads the 3 × 3 cells around a
/// pair's, which hold the samples up to about a cell's width from it.
pub const MAX_BLEND_RADIUS_CELLS: f64 = 2.0;

/// How the refinement pairs a query point with a reference point. Nearest is the default: on the
/// 3DTK scans the projective pairing's refinement of the second scan failed (it fell back to a
/// translation-only fit 8 cm from slam6D, nearest-neighbour check 2.90 cm) where the nearest
/// pairing's converged (3.2 cm from slam6D, 2.58 cm); on the 50 clean simulated pairs of `sdem
/// bench` projective pairing is a little tighter (0.76 mm median, 1.88 mm 95th percentile, against
/// 0.95 mm and 3.85 mm).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Association {
    /// The nearest reference point (with a normal) within `max_correspondence_m`, looked up
    /// through the reference's cells near the query point's (or a k-d tree): robust on real
    /// scans, whose 1° cells far away hold unrelated surfaces. Only query points inside the
    /// range gate of a cell the reference saw are paired (see [`crate::sdem::CellSurfaces`]):
    /// from the truth, with lost returns at the ditch's mouth
    /// (`sdem bench --faults` pair 45), the ungated pairing ran 18 cm off, the gated one 1 mm.
    Nearest,
    /// The reference point in the query point's S-DEM cell (the S-DEM *is* a projective
    /// association; cheaper, and enough on clean simulated scans).
    Projective,
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self {
            max_iterations: 30,
            kernel_scale_m: 0.02,
            max_correspondence_m: 0.10,
            estimate_rotation: true,
            max_rotation_deg: 5.0,
            max_translation_m: 0.10,
            normal_radius_cells: 2,
            min_inliers: 200,
            association: Association::Nearest,
            converged_step: 1e-5,
            max_points: 0,
            blend_radius_cells: 0.0,
        }
    }
}

impl RefineConfig {
    /// Checks the settings.
    ///
    /// # Errors
    /// [`Error::Invalid`] naming the field that is not a positive number (`max_iterations`: at
    /// least 1).
    pub fn validate(&self) -> Result<()> {
        if self.max_iterations == 0 {
            return Err(Error::Invalid(
                "refinement.max_iterations = 0: give at least 1 (or refine = false to skip the \
                 refinement)"
                    .into(),
            ));
        }
        let positive = [
            ("kernel_scale_m", self.kernel_scale_m),
            ("max_correspondence_m", self.max_correspondence_m),
            ("max_rotation_deg", self.max_rotation_deg),
            ("max_translation_m", self.max_translation_m),
            ("converged_step", self.converged_step),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::Invalid(format!(
                    "refinement.{name} = {value} must be a positive number"
                )));
            }
        }
        if !(0.0..=MAX_BLEND_RADIUS_CELLS).contains(&self.blend_radius_cells) {
            return Err(Error::Invalid(format!(
                "refinement.blend_radius_cells = {} must lie in 0..={MAX_BLEND_RADIUS_CELLS} \
                 (0, the default: the nearest point's plane alone; {BLEND_RADIUS_CELLS} measured \
                 best)",
                self.blend_radius_cells
            )));
        }
        // Each normal fits (2r + 1)² cells: 100 took 3 s a scan, 1e9 never ended.
        if !(1..=MAX_NORMAL_RADIUS_CELLS).contains(&self.normal_radius_cells) {
            return Err(Error::Invalid(format!(
                "refinement.normal_radius_cells = {} must lie in 1..={MAX_NORMAL_RADIUS_CELLS} \
                 (the default is 2)",
                self.normal_radius_cells
            )));
        }
        Ok(())
    }
}

/// The widest neighbourhood a surface normal may be fitted over, cells each way: ±10 cells are
/// 441 cells a normal, ten times ±3's (the widest measured, `docs/accuracy.md`).
pub const MAX_NORMAL_RADIUS_CELLS: usize = 10;

/// The result of a refinement.
#[derive(Debug, Clone, PartialEq)]
pub struct Refinement {
    /// Carries query-levelled points into the reference's levelled frame.
    pub reference_level_from_query_level: Isometry3<f64>,
    /// Gauss-Newton iterations run.
    pub iterations: usize,
    /// True when the last update was below the convergence threshold.
    pub converged: bool,
    /// Points associated in the last iteration.
    pub inliers: usize,
    /// Robust RMS point-to-plane residual, metres.
    pub rms_m: f64,
    /// Information matrix of `[x, y, z, rx, ry, rz]` (metres, radians; rotation about the
    /// reference levelled frame's axes), `JᵀWJ / (σ² d)`: `d` the residuals' [`design_effect`]
    /// (their correlation between neighbours). [`crate::localize()`] divides it further by the
    /// sampling bias measured by refining the other way ([`discrepancy::with_sampling_bias`]).
    pub information: Matrix6<f64>,
    /// The reference normals (levelled frame) of the last iteration's residuals within the
    /// robust kernel (weight at least ½), each with the square of its point's range: the
    /// surfaces that carry the estimate, and the area each point stands for (the S-DEM's cells
    /// are equal in angle, so a near surface holds many more points per square metre than a
    /// far one).
    pub supporting_normals: Vec<([f32; 3], f32)>,
}

impl Refinement {
    /// The share of the area of [`Self::supporting_normals`] facing along `direction` (a unit
    /// vector) within 60° (|n · direction| ≥ ½): the matched surfaces that fix the position
    /// along it.
    ///
    /// The information matrix weighs every residual by the square of its normal's component,
    /// so on a featureless corridor the noise of thousands of normals on its walls (a few
    /// degrees each, near the sensor) adds up to as much information along the axis as a real
    /// surface would give; counting the surfaces that truly face that way does not.
    pub fn support(&self, direction: &Vec3) -> f64 {
        let (mut facing, mut total) = (0.0, 0.0);
        for (n, area) in &self.supporting_normals {
            let along =
                n[0] as f64 * direction.x + n[1] as f64 * direction.y + n[2] as f64 * direction.z;
            total += *area as f64;
            if along.abs() >= 0.5 {
                facing += *area as f64;
            }
        }
        if total > 0.0 {
            facing / total
        } else {
            0.0
        }
    }
}

/// The pairs are found again after an update larger than this (metres, and radians), and
/// before convergence is declared; below it the last pairs are kept (the estimate moved by less
/// than the reference points' spacing, so few pairs would change), which saves the
/// nearest-neighbour queries of most iterations.
const REASSOCIATE_STEP: f64 = 1e-3;

/// Below an update of this (metres, and radians) the kernel is no longer annealed but set to
/// its scale (see [`refine`]).
const SETTLED_STEP: f64 = 1e-4;

/// The weight of a residual against a reference patch whose points scatter about its plane with
/// variance `thickness_sq` (m²), for residuals of scale `s` (metres): `s² / (s² + thickness²)`,
/// 1 on a flat patch. A plane fitted to a rough or cluttered patch (gravel, a bush, a cable
/// run, an edge the neighbours straddle) is a poor model of the surface where the query point
/// meets it, and its residual is off by up to that scatter whichever way the pose lies, so it
/// counts as a measurement of that much more variance (GICP weighs its pairs by their
/// neighbourhoods' covariances alike).
#[inline]
fn thickness_weight(thickness_sq: f64, s: f64) -> f64 {
    let s2 = s * s;
    if thickness_sq.is_finite() {
        s2 / (s2 + thickness_sq.max(0.0))
    } else {
        1.0
    }
}

/// Geman-McClure weight of residual `r` at scale `s`.
#[inline]
fn robust_weight(r: f64, s: f64) -> f64 {
    let u = r / s;
    let d = 1.0 + u * u;
    1.0 / (d * d)
}

/// Query points are paired and summed this many at a time (their directions' cells computed
/// together, vectorized).
const CHUNK: usize = 256;

/// The Gauss-Newton normal equations of a set of point-to-plane residuals: `JᵀWJ` (its upper
/// triangle, row by row), `JᵀWr`, `Σ w r²`, `Σ w` and the number of residuals.
#[derive(Clone, Default)]
struct NormalEquations {
    h: [f64; 21],
    g: [f64; 6],
    chi2: f64,
    wsum: f64,
    count: usize,
    /// The normals of the residuals within the kernel (robust weight at least ½), each with
    /// the square of its point's range (the area a cell of the S-DEM stands for grows with
    /// it).
    normals: Vec<([f32; 3], f32)>,
}

impl NormalEquations {
    #[inline(always)]
    fn add(&mut self, w: f64, r: f64, jac: [f64; 6]) {
        let mut k = 0;
        for i in 0..6 {
            let wi = w * jac[i];
            for jj in &jac[i..] {
                self.h[k] += wi * jj;
                k += 1;
            }
            self.g[i] += wi * r;
        }
        self.chi2 += w * r * r;
        self.wsum += w;
        self.count += 1;
    }

    fn merged(mut self, other: Self) -> Self {
        for (a, b) in self.h.iter_mut().zip(other.h) {
            *a += b;
        }
        for (a, b) in self.g.iter_mut().zip(other.g) {
            *a += b;
        }
        self.chi2 += other.chi2;
        self.wsum += other.wsum;
        self.count += other.count;
        self.normals.extend_from_slice(&other.normals);
        self
    }

    /// `(JᵀWJ, JᵀWr, Σ w r², Σ w, count)`.
    fn parts(&self) -> (Matrix6<f64>, Vector6<f64>, f64, f64, usize) {
        let mut h = Matrix6::zeros();
        let mut k = 0;
        for i in 0..6 {
            for j in i..6 {
                h[(i, j)] = self.h[k];
                h[(j, i)] = self.h[k];
                k += 1;
            }
        }
        (h, Vector6::from(self.g), self.chi2, self.wsum, self.count)
    }
}

/// Once the estimate has settled (`SETTLED_STEP`), a query point pairs only with a reference
/// point within this many cells' width at its range ([`Gate`]) …
const SETTLED_GATE_CELLS: f64 = 2.0;
/// … and never nearer than this, metres.
const SETTLED_GATE_MIN_M: f64 = 0.05;

/// How far a query point may lie from its reference point, metres. While the estimate moves,
/// [`RefineConfig::max_correspondence_m`] everywhere (pairs of a pose some centimetres off);
/// once it has settled, the width of `SETTLED_GATE_CELLS` reference cells at the point's range
/// (the reference holds a point a cell, so a surface it saw has one that near) within
/// `SETTLED_GATE_MIN_M` and `max_correspondence_m`. A pair farther apart joins a point with
/// another surface or with the edge of what the reference saw, and the plane fitted there,
/// extended by centimetres past its points, pulls the estimate. On the 300 re-views of `sdem
/// bench --suite real-geometry` the error fell from 0.63 / 1.30 / 2.16 mm (median / p95 / max)
/// to 0.58 / 1.22 / 2.15; one cell instead of two, 0.56 / 1.24 / 2.10, but on the 50 simulated
/// pairs of `sdem bench` their worst grew from 2.4 to 3.3 mm (two: 1.8).
#[derive(Clone, Copy)]
struct Gate {
    min_m: f64,
    per_metre: f64,
    max_m: f64,
    /// The blending radius per metre of range (0: the nearest point's plane alone).
    blend_per_metre: f32,
}

impl Gate {
    fn new(config: &RefineConfig, grid: &crate::sdem::GridSpec, settled: bool) -> Self {
        let max_m = config.max_correspondence_m;
        if settled {
            Self {
                min_m: SETTLED_GATE_MIN_M.min(max_m),
                per_metre: SETTLED_GATE_CELLS * grid.resolution(),
                max_m,
                blend_per_metre: (config.blend_radius_cells * grid.resolution()) as f32,
            }
        } else {
            Self {
                min_m: max_m,
                per_metre: 0.0,
                max_m,
                blend_per_metre: 0.0,
            }
        }
    }

    /// The gate of a point at `x` (reference frame), metres.
    fn at(&self, x: [f32; 3]) -> f64 {
        let range = ((x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) as f64).sqrt();
        (self.per_metre * range).clamp(self.min_m, self.max_m)
    }

    /// The residual and normal of `x` paired with reference point `j` (normal `normal`, at
    /// offset `d` from it): the blended surface's once settled, where it has one, else `j`'s
    /// plane.
    fn residual(
        &self,
        pairing: &Pairing,
        x: [f32; 3],
        j: u32,
        d: [f32; 3],
        normal: [f32; 3],
    ) -> (f64, Vec3) {
        if self.blend_per_metre > 0.0 {
            let range = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
            let cell = pairing.reference.cells()[j as usize];
            let grid = pairing.reference.grid();
            let radius = self.blend_per_metre * range;
            if let Some((r, n)) = pairing.normals.blended(grid, x, cell, radius) {
                return (r as f64, Vec3::new(n[0] as f64, n[1] as f64, n[2] as f64));
            }
        }
        let n = Vec3::new(normal[0] as f64, normal[1] as f64, normal[2] as f64);
        (n.x * d[0] as f64 + n.y * d[1] as f64 + n.z * d[2] as f64, n)
    }
}

/// What pairing a query point with the reference reads.
struct Pairing<'a> {
    reference: &'a Sdem,
    normals: &'a SurfaceNormals,
    config: &'a RefineConfig,
}

impl Pairing<'_> {
    /// The normal equations of `points` (query, levelled) moved by `pose`; with `fresh` each is
    /// paired anew (`pairs[i]`: its reference point, `u32::MAX` for none), else with its last
    /// pair. Residuals weigh by the Geman-McClure kernel at `scale`, times their reference
    /// patch's thickness weight ([`thickness_weight`]); a residual is an inlier (its patch's
    /// normal counted in the support) by its robust weight alone. Where the gate blends the
    /// surface (settled), each point's blended plane (`planes[i]`: a point on it, its normal)
    /// is found with its pair and kept while the pair stays: settled, the estimate moves by
    /// less than a millimetre a step until the pairs are found again, where the reference's
    /// points lie centimetres apart, and across such a move the blend's plane is the surface
    /// to first order.
    #[allow(clippy::too_many_arguments)]
    fn accumulate(
        &self,
        (rotation, translation): &(nalgebra::Matrix3<f32>, nalgebra::Vector3<f32>),
        points: &[[f32; 3]],
        pairs: &mut [u32],
        planes: &mut [[f32; 6]],
        fresh: bool,
        scale: f64,
        gate: Gate,
    ) -> NormalEquations {
        let reference = self.reference;
        let (grid, surfaces, reference_points) = (
            reference.grid(),
            reference.surfaces(),
            reference.surface_points(),
        );
        let n = points.len();
        let mut rotated = [[0f32; 3]; CHUNK];
        let (mut xs, mut ys, mut zs) = ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
        for (i, q) in points.iter().enumerate() {
            let y = rotation * nalgebra::Vector3::new(q[0], q[1], q[2]);
            rotated[i] = [y.x, y.y, y.z];
            (xs[i], ys[i], zs[i]) = (
                y.x + translation.x,
                y.y + translation.y,
                y.z + translation.z,
            );
        }
        let (mut cells, mut ranges) = ([u32::MAX; CHUNK], [0f32; CHUNK]);
        if fresh {
            grid.cells_of(
                &xs[..n],
                &ys[..n],
                &zs[..n],
                &mut cells[..n],
                &mut ranges[..n],
            );
        }
        let mut acc = NormalEquations::default();
        for i in 0..n {
            let x = [xs[i], ys[i], zs[i]];
            let max_distance = gate.at(x);
            let found = if fresh {
                let cell = cells[i];
                let found = match self.config.association {
                    Association::Nearest => {
                        // Only where the reference saw this direction, at about this range: a
                        // point it could not have seen would pair with the edge of what it did
                        // see and drag the estimate towards it.
                        let seen = cell != u32::MAX
                            && surfaces
                                .squared_distance(cell as usize, x, ranges[i])
                                .is_some_and(f32::is_finite);
                        if seen {
                            let hint = pairs[i];
                            (self.normals).nearest_in_cone(
                                grid,
                                reference_points,
                                x,
                                cell,
                                hint,
                                max_distance as f32,
                            )
                        } else {
                            None
                        }
                    }
                    Association::Projective => (cell != u32::MAX)
                        .then(|| self.normals.point_of_cell[cell as usize])
                        .filter(|&j| j != u32::MAX),
                };
                let paired = found.unwrap_or(u32::MAX);
                if paired != pairs[i] {
                    planes[i] = [f32::NAN; 6];
                }
                pairs[i] = paired;
                found
            } else {
                (pairs[i] != u32::MAX).then_some(pairs[i])
            };
            let Some(j) = found else {
                continue;
            };
            let normal = self.normals.normals[j as usize];
            if normal[0].is_nan() {
                continue;
            }
            let p = reference_points[j as usize];
            let d = [x[0] - p[0], x[1] - p[1], x[2] - p[2]];
            if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) as f64 > max_distance * max_distance {
                continue;
            }
            let (r, normal) = if gate.blend_per_metre > 0.0 {
                let plane = &mut planes[i];
                if plane[0].is_nan() {
                    let (r, n) = gate.residual(self, x, j, d, normal);
                    *plane = kept_plane(x, r, &n);
                }
                from_kept_plane(plane, x)
            } else {
                gate.residual(self, x, j, d, normal)
            };
            let y = rotated[i];
            let jr = Vec3::new(y[0] as f64, y[1] as f64, y[2] as f64).cross(&normal);
            let jac = [normal.x, normal.y, normal.z, jr.x, jr.y, jr.z];
            let w = robust_weight(r, scale);
            if w >= 0.5 {
                let area = x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
                acc.normals.push((self.normals.normals[j as usize], area));
            }
            // The paired point's patch, also where the residual is the blended surface's (whose
            // samples lie within 1.5 cells of it, on much the same patch).
            let thickness_sq = self.normals.thickness_sq[j as usize] as f64;
            let w = w * thickness_weight(thickness_sq, self.config.kernel_scale_m);
            acc.add(w, r, jac);
        }
        acc
    }
}

impl Pairing<'_> {
    /// Kish's design effect ([`design_effect`]) of the inlying residuals (robust weight at
    /// least ½) of `points` moved by `pose` against their `pairs`, grouped in patches of
    /// [`CORRELATION_PATCH_CELLS`]² reference cells. Where the gate blends the surface, each
    /// residual is taken from the point's kept blended plane (`planes`), as the last
    /// iteration took it.
    fn design_effect(
        &self,
        pose: &(nalgebra::Matrix3<f32>, nalgebra::Vector3<f32>),
        points: &[[f32; 3]],
        (pairs, planes): (&[u32], &[[f32; 6]]),
        scale: f64,
        gate: Gate,
    ) -> f64 {
        let n_az = self.reference.grid().azimuth_cells() as u64;
        let block = CORRELATION_PATCH_CELLS;
        let cells = self.reference.cells();
        let mut residuals: Vec<(u64, f64)> = (points.par_iter())
            .zip(pairs.par_iter().zip(planes.par_iter()))
            .filter_map(|(q, (&j, plane))| {
                let (r, _) = self.residual(pose, q, j, gate, Some(plane))?;
                let c = cells[j as usize] as u64;
                let patch = (c / n_az / block) * (n_az / block + 1) + (c % n_az) / block;
                (robust_weight(r, scale) >= 0.5).then_some((patch, r))
            })
            .collect();
        design_effect(&mut residuals)
    }

    /// The point-to-plane residual and its Jacobian of query point `q` moved by `pose` against
    /// reference point `j` (`None`: unpaired, no normal, or beyond the correspondence distance),
    /// from the point's kept blended plane `kept` where the gate blends and it has one.
    fn residual(
        &self,
        (rotation, translation): &(nalgebra::Matrix3<f32>, nalgebra::Vector3<f32>),
        q: &[f32; 3],
        j: u32,
        gate: Gate,
        kept: Option<&[f32; 6]>,
    ) -> Option<(f64, [f64; 6])> {
        if j == u32::MAX {
            return None;
        }
        let normal = self.normals.normals[j as usize];
        if normal[0].is_nan() {
            return None;
        }
        let y = rotation * nalgebra::Vector3::new(q[0], q[1], q[2]);
        let x = y + translation;
        let p = self.reference.surface_points()[j as usize];
        let d = [x.x - p[0], x.y - p[1], x.z - p[2]];
        let max_distance = gate.at([x.x, x.y, x.z]);
        if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) as f64 > max_distance * max_distance {
            return None;
        }
        let x = [x.x, x.y, x.z];
        let (r, normal) = match kept.filter(|p| gate.blend_per_metre > 0.0 && !p[0].is_nan()) {
            Some(plane) => from_kept_plane(plane, x),
            None => gate.residual(self, x, j, d, normal),
        };
        let jr = Vec3::new(y.x as f64, y.y as f64, y.z as f64).cross(&normal);
        Some((r, [normal.x, normal.y, normal.z, jr.x, jr.y, jr.z]))
    }
}

/// The plane a point at `x` with residual `r` along the unit normal `n` is kept against
/// ([`Pairing::accumulate`]): its foot `x − r n` and `n`, in `f32`.
fn kept_plane(x: [f32; 3], r: f64, n: &Vec3) -> [f32; 6] {
    [
        x[0] - (r * n.x) as f32,
        x[1] - (r * n.y) as f32,
        x[2] - (r * n.z) as f32,
        n.x as f32,
        n.y as f32,
        n.z as f32,
    ]
}

/// The residual of a point at `x` against a kept plane ([`kept_plane`]), and the plane's normal.
fn from_kept_plane(plane: &[f32; 6], x: [f32; 3]) -> (f64, Vec3) {
    let n = [plane[3], plane[4], plane[5]];
    let r = n[0] * (x[0] - plane[0]) + n[1] * (x[1] - plane[1]) + n[2] * (x[2] - plane[2]);
    (r as f64, Vec3::new(n[0] as f64, n[1] as f64, n[2] as f64))
}

/// The side, in reference cells, of the patches whose residuals [`design_effect`] compares.
/// On re-views of KITTI frames and 3DTK scans (`sdem bench --suite real-geometry`) the effect
/// grew with the patch from 3 cells (1.1–1.5) to 9 (1.1–2.1) and stayed there at 25 and 60.
pub const CORRELATION_PATCH_CELLS: u64 = 15;

/// Kish's design effect `1 + (m̄ − 1) ρ` of residuals grouped in patches (`(patch, residual)`,
/// any order; sorted here): how many times the variance of an estimate from them exceeds the
/// one they would give if independent. `ρ` is their intra-patch correlation (the one-way
/// ANOVA estimator, at least 0) and `m̄ = Σ m² / Σ m` the mean size of the patch a residual
/// lies in. Two scans sample one surface at different places, so neighbouring residuals share
/// the surface's departures from the planes fitted to it; counted as independent they make
/// the covariance too small. 1 with fewer than two patches or no residual within one.
pub fn design_effect(residuals: &mut [(u64, f64)]) -> f64 {
    residuals.sort_unstable_by_key(|x| x.0);
    let n = residuals.len() as f64;
    let mean = residuals.iter().map(|x| x.1).sum::<f64>() / n;
    let (mut between, mut within, mut patches, mut m2) = (0.0, 0.0, 0.0, 0.0);
    for patch in residuals.chunk_by(|a, b| a.0 == b.0) {
        let m = patch.len() as f64;
        let patch_mean = patch.iter().map(|x| x.1).sum::<f64>() / m;
        between += m * (patch_mean - mean).powi(2);
        within += patch
            .iter()
            .map(|x| (x.1 - patch_mean).powi(2))
            .sum::<f64>();
        patches += 1.0;
        m2 += m * m;
    }
    if patches < 2.0 || n <= patches {
        return 1.0;
    }
    let (between, within) = (between / (patches - 1.0), within / (n - patches));
    let m0 = (n - m2 / n) / (patches - 1.0);
    let rho = (between - within) / (between + (m0 - 1.0) * within);
    if !rho.is_finite() {
        return 1.0;
    }
    1.0 + (m2 / n - 1.0) * rho.clamp(0.0, 1.0)
}

/// Refines `initial` (`reference_level_from_query_level`) by robust point-to-plane Gauss-Newton,
/// each query point paired with the nearest reference point (or, with
/// [`Association::Projective`], the one in its S-DEM cell). A `prior` on the offset (the
/// motion's prediction) weighs as one more residual of the kernel's scale at one `σ`, which
/// holds the estimate where the surfaces leave a direction free.
///
/// The pairs are found again only after an update of more than 1 mm (`REASSOCIATE_STEP`), and
/// before convergence is declared (the last iteration always pairs afresh); the kernel is annealed
/// from wide until an update moves less than 0.1 mm (`SETTLED_STEP`). On the 50 bench pairs this
/// took the refinement from 17 to 11 ms (median) with the same errors to 0.02 mm.
///
/// # Errors
/// [`Error::RefinementFailed`] when too few points associate, the problem is degenerate, or the
/// correction leaves the plausible range (then the grid optimum should be kept).
pub fn refine(
    reference: &Sdem,
    normals: &SurfaceNormals,
    query: &Sdem,
    initial: &Isometry3<f64>,
    prior: Option<&OffsetPrior>,
    config: &RefineConfig,
) -> Result<Refinement> {
    refine_from(reference, normals, query, initial, prior, config, false)
}

/// [`refine`], from an `initial` estimate that is already `settled` (a refinement's own result,
/// seen from the other scan): then the kernel starts at its scale and the gate narrow, with no
/// annealing from wide to pull the estimate away and back.
pub(crate) fn refine_from(
    reference: &Sdem,
    normals: &SurfaceNormals,
    query: &Sdem,
    initial: &Isometry3<f64>,
    prior: Option<&OffsetPrior>,
    config: &RefineConfig,
    settled: bool,
) -> Result<Refinement> {
    if reference.grid() != query.grid() {
        return Err(Error::Invalid(
            "refinement needs both S-DEMs on one grid".into(),
        ));
    }
    let pairing = Pairing {
        reference,
        normals,
        config,
    };
    let mut rotation = initial.rotation.to_rotation_matrix();
    let mut translation = initial.translation.vector;
    let mut last = None;
    let mut converged = false;
    let mut iterations = 0;
    // The points refined: an even sample of them while the estimate moves by more than the
    // reference points' spacing, then every boundary point (see `RefineConfig::max_points`).
    let all = query.surface_points();
    let sample = (config.max_points > 0 && all.len() > config.max_points).then(|| {
        (crate::cost::even_indices(query, 0.05, config.max_points).iter())
            .map(|&i| all[i as usize])
            .collect::<Vec<_>>()
    });
    let mut sampling = sample.is_some();
    let mut query_points: &[[f32; 3]] = sample.as_deref().unwrap_or(all);
    // Each query point's reference point (`u32::MAX`: none), kept between iterations while
    // the estimate moves little (see [`REASSOCIATE_STEP`]).
    let mut pairs = vec![u32::MAX; query_points.len()];
    let mut planes = vec![[f32::NAN; 6]; query_points.len()];
    let mut associate = true;
    let mut settled = settled;
    // The estimates at which the pairs were found afresh once settled (see `returned_to`).
    let mut paired_at: Vec<(Rotation3<f64>, Vec3)> = Vec::new();
    for iteration in 0..config.max_iterations.max(1) {
        iterations = iteration + 1;
        let fresh = associate;
        let scale = annealed_scale(config, iteration, settled);
        let gate = Gate::new(config, reference.grid(), settled);
        let r32 = rotation.matrix().cast::<f32>();
        let t32 = translation.cast::<f32>();
        let pose = (r32, t32);
        // Summed in the chunks' order, not rayon's reduction tree (which follows the threads'
        // stealing): the same scans give the same pose to the last bit, however busy the
        // machine.
        let chunks: Vec<NormalEquations> = query_points
            .par_chunks(CHUNK)
            .zip(pairs.par_chunks_mut(CHUNK))
            .zip(planes.par_chunks_mut(CHUNK))
            .map(|((points, pairs), planes)| {
                pairing.accumulate(&pose, points, pairs, planes, fresh, scale, gate)
            })
            .collect();
        let normal_equations =
            (chunks.into_iter()).fold(NormalEquations::default(), NormalEquations::merged);
        let (h, g, chi2, wsum, inliers) = normal_equations.parts();
        let supporting = normal_equations.normals;
        if inliers < config.min_inliers {
            return Err(Error::RefinementFailed {
                reason: format!(
                    "refinement associated {inliers} points, fewer than {}",
                    config.min_inliers
                ),
            });
        }
        let sigma_sq = (chi2 / wsum.max(1e-12)).max(1e-12);
        // The information reported is the scans' alone: the prediction steers the estimate
        // where they say nothing, and a pose graph holds the odometry as its own edge.
        last = Some((h, sigma_sq, inliers, supporting));
        let delta = solve_step(h, g, &translation, prior, config)?;
        if fresh && settled {
            // Back where the pairs were found before: the same pairs again, the same steps, a
            // cycle between pairings. The estimate is as good as it gets; it stays here, with
            // the pairs that are its own.
            if returned_to(&paired_at, &rotation, &translation, config.converged_step) {
                converged = true;
                break;
            }
            paired_at.push((rotation, translation));
        }
        let omega = Vec3::new(delta[3], delta[4], delta[5]);
        let step_rotation = Rotation3::new(omega);
        rotation = step_rotation * rotation;
        translation += Vec3::new(delta[0], delta[1], delta[2]);
        let step = delta.fixed_rows::<3>(0).norm().max(omega.norm());
        if sampling && (step < REASSOCIATE_STEP || 2 * (iteration + 1) >= config.max_iterations) {
            // The sample has brought the estimate within the pairs' reach: every point from
            // here, paired afresh.
            sampling = false;
            query_points = all;
            pairs = vec![u32::MAX; all.len()];
            planes = vec![[f32::NAN; 6]; all.len()];
            associate = true;
        } else if !settled && step < SETTLED_STEP {
            // The gate narrows (see `Gate`): paired afresh under it before converging.
            associate = true;
        } else if step < config.converged_step {
            // Converged only where the pairs are the estimate's own.
            if fresh {
                converged = true;
                break;
            }
            associate = true;
        } else {
            associate = step > REASSOCIATE_STEP;
        }
        // Once an update moves less than this, the kernel's annealing (a continuation from a
        // wide kernel, for estimates some centimetres off) has done its work: the rest of the
        // schedule only crept, ~20 % less a step, for another 5-10 iterations.
        settled |= step < SETTLED_STEP;
    }
    let (h, sigma_sq, inliers, supporting) = last.expect("at least one iteration ran");
    check_plausible(initial, &rotation, &translation, prior, all, config)?;
    // The residuals of neighbouring points are not independent (see `design_effect`).
    let pose = (rotation.matrix().cast::<f32>(), translation.cast::<f32>());
    let scale = annealed_scale(config, iterations, settled);
    let gate = Gate::new(config, reference.grid(), settled);
    let deff = pairing.design_effect(&pose, query_points, (&pairs, &planes), scale, gate);
    Ok(Refinement {
        reference_level_from_query_level: Isometry3::from_parts(
            Translation3::from(translation),
            UnitQuaternion::from_rotation_matrix(&rotation),
        ),
        iterations,
        converged,
        inliers,
        rms_m: sigma_sq.sqrt(),
        information: h / (sigma_sq * deff),
        supporting_normals: supporting,
    })
}

/// True when the estimate (`rotation`, `translation`) lies within `tolerance` (metres, and
/// radians) of one of `earlier`: the pairs found afresh at it will be the ones found there.
///
/// A refinement whose steps are below [`REASSOCIATE_STEP`] keeps its pairs until a step falls
/// below [`RefineConfig::converged_step`], then pairs afresh; where a point's pair changes with
/// that (a point on the edge of its gate, between two nearest points), the new pairs may step it
/// back past the threshold, and the old ones forward again. On a 4-stop simulated run one
/// step's refinement cycled so between two pairings 16 µm and 0.001° apart until it ran out of
/// iterations.
fn returned_to(
    earlier: &[(Rotation3<f64>, Vec3)],
    rotation: &Rotation3<f64>,
    translation: &Vec3,
    tolerance: f64,
) -> bool {
    earlier.iter().any(|(r, t)| {
        (t - translation).norm() < tolerance && (r * rotation.transpose()).angle() < tolerance
    })
}

/// The kernel's scale at `iteration`: annealed from wide to the configured scale over the first
/// iterations, until the estimate has `settled`.
fn annealed_scale(config: &RefineConfig, iteration: usize, settled: bool) -> f64 {
    if settled {
        config.kernel_scale_m
    } else {
        config.kernel_scale_m * (1.0 + 3.0 * (-(iteration as f64) / 3.0).exp())
    }
}

/// The Gauss-Newton update from the normal equations `h`, `g` (with the `prior` on the offset
/// added, at the current `translation`), over all six axes or the translation alone.
///
/// # Errors
/// [`Error::RefinementFailed`] when the system is degenerate.
fn solve_step(
    h: Matrix6<f64>,
    g: Vector6<f64>,
    translation: &Vec3,
    prior: Option<&OffsetPrior>,
    config: &RefineConfig,
) -> Result<Vector6<f64>> {
    let (mut h, mut g) = (h, g);
    if let Some(p) = prior {
        // One more residual like the points': the kernel's scale at one σ of the prediction.
        let weight = (config.kernel_scale_m / p.sigma_m).powi(2);
        for a in 0..3 {
            h[(a, a)] += weight;
            g[a] += weight * (translation[a] - p.offset[a]);
        }
    }
    let delta = if config.estimate_rotation {
        h.cholesky().map(|c| -c.solve(&g))
    } else {
        let h3 = h.fixed_view::<3, 3>(0, 0).into_owned();
        let g3 = g.fixed_rows::<3>(0).into_owned();
        h3.cholesky().map(|c| {
            let d = -c.solve(&g3);
            Vector6::new(d.x, d.y, d.z, 0.0, 0.0, 0.0)
        })
    };
    delta.ok_or_else(|| Error::RefinementFailed {
        reason: "refinement is degenerate: the surfaces constrain fewer than all axes".into(),
    })
}

/// Refuses a refined pose (`rotation`, `translation`) that moved further from `initial` than
/// the configuration finds plausible. A translation within three σ of the `prior`'s offset is
/// plausible however far it moved: along a direction the surfaces leave free (a corridor's
/// axis) the prior, not the surfaces, sets the position, and it may lie farther from the grid's
/// optimum than the refinement is otherwise trusted to move. So is one within the configured
/// move plus what the refinement's turn moves the scan's points at their median range
/// (`query_points`, levelled sensor frame), that share at most the configured move again: the
/// grid is searched at the readings' tilt (and heading steps), and where that tilt is off by Δθ
/// the grid's best offset makes up for it by about the points' distance × Δθ (a scanner sees to
/// one side of itself, so the shift does not average out), which the refinement then takes
/// back.
fn check_plausible(
    initial: &Isometry3<f64>,
    rotation: &Rotation3<f64>,
    translation: &Vec3,
    prior: Option<&OffsetPrior>,
    query_points: &[[f32; 3]],
    config: &RefineConfig,
) -> Result<()> {
    let rotation_change = (rotation * initial.rotation.to_rotation_matrix().transpose()).angle();
    let translation_change = (translation - initial.translation.vector).norm();
    let vouched_for =
        prior.is_some_and(|p| (translation - Vec3::from(p.offset)).norm() <= 3.0 * p.sigma_m);
    // The turn's share is held to the configured move itself (twice it in all): a refinement
    // that went wrong in rotation must not buy itself any move by turning (5° at 15 m: 1.3 m).
    // The median range is only looked up when the move is beyond the configured one, and once.
    let plausible_m = std::cell::OnceCell::new();
    let plausible_m = || {
        *plausible_m.get_or_init(|| {
            let turn_share = rotation_change * crate::sdem::median_range(query_points);
            config.max_translation_m + turn_share.min(config.max_translation_m)
        })
    };
    if rotation_change.to_degrees() > config.max_rotation_deg
        || (translation_change > config.max_translation_m
            && !vouched_for
            && translation_change > plausible_m())
    {
        return Err(Error::RefinementFailed {
            reason: format!(
                "refinement moved {:.1} cm and {:.2}°, beyond the plausible {:.1} cm (at that \
                 turn) and {:.1}°",
                translation_change * 100.0,
                rotation_change.to_degrees(),
                plausible_m() * 100.0,
                config.max_rotation_deg
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests;
