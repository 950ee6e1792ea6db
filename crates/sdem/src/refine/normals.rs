//! The reference's surface normals, and the refinement's pairing: the reference point with a
//! normal nearest to a query point, looked up through the reference S-DEM's own cells where a
//! small cone of them holds every point near enough, and through a k-d tree where it would not.
//!
//! A reference point within `d` of `x` (at range `r > 2d`) lies within the angle `asin(d / r)`
//! of `x`'s direction, so in a few cells around `x`'s own: a refinement's pairs move by
//! millimetres between associations, and the last pair (or, the first time, the point in `x`'s
//! cell) bounds `d` by about a cell's width.

use crate::geometry::Vec3;
use crate::sdem::{patch_moments, wrap_column, Derived, GridSpec, Sdem};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Matrix3;
use rayon::prelude::*;

/// A cone spanning more cells than this is left to the k-d tree.
const MAX_CONE_CELLS: i32 = 64;

/// Added to the cone's half-width each way, cells: a point's surface mean (which is what is
/// compared) may lie a hair outside the cell its boundary point fell in, and the angles are
/// computed in `f32`.
const MARGIN_CELLS: f32 = 0.05;

/// `asin(s) <= ASIN_SLOPE * s` for `0 <= s <= 1/2` (`asin(1/2) = π/6`).
const ASIN_SLOPE: f32 = std::f32::consts::FRAC_PI_3;

/// Surface normals of an S-DEM's boundary points, from a plane fit over neighbouring cells.
#[derive(Debug, Clone)]
pub struct SurfaceNormals {
    /// Per grid cell, the index into `Sdem::points()`, or `u32::MAX` when unknown.
    pub(super) point_of_cell: Vec<u32>,
    /// Per boundary point, its unit normal facing the sensor, or NaN where none fits.
    pub(super) normals: Vec<[f32; 3]>,
    /// Per boundary point, its patch's variance along the normal, m² (NaN where none fits).
    pub(super) thickness_sq: Vec<f32>,
    /// The boundary points with a normal, and the index into `Sdem::points()` of each.
    with_normal: (Vec<[f32; 3]>, Vec<u32>),
    /// Those points in a k-d tree, built on the first lookup that needs it (most pairings never
    /// do: on KITTI frames building a tree for every S-DEM was 13 % of `sdem slam`'s
    /// instructions); `None` when no point has a normal.
    neighbours: std::sync::OnceLock<Option<ImmutableKdTree<f32, 3>>>,
    /// Per grid cell, its surface point when it has a normal, else NaN (see `nearest`).
    paired_of_cell: Vec<[f32; 3]>,
    /// Per grid cell, its surface point and that point's normal (NaN where it has none), side
    /// by side for [`Self::blended`], which reads nine cells a point.
    surface_of_cell: Vec<[f32; 6]>,
}

impl SurfaceNormals {
    /// The surface normals of `sdem` fitted over `radius_cells` ([`Self::new`]): made once, on
    /// first use, and kept with the S-DEM for that radius; another radius is fitted anew.
    pub fn of(sdem: &Sdem, radius_cells: usize) -> std::borrow::Cow<'_, SurfaceNormals> {
        let (radius, normals) = sdem.derived(Derived::SurfaceNormals, || {
            (radius_cells, SurfaceNormals::new(sdem, radius_cells))
        });
        if *radius == radius_cells {
            std::borrow::Cow::Borrowed(normals)
        } else {
            std::borrow::Cow::Owned(SurfaceNormals::new(sdem, radius_cells))
        }
    }

    /// Fits a plane to each boundary point and its neighbours within `radius_cells` cells whose
    /// points lie close to it (so edges and occlusion boundaries do not blur the normal).
    pub fn new(sdem: &Sdem, radius_cells: usize) -> Self {
        let grid = sdem.grid();
        let mut point_of_cell = vec![u32::MAX; grid.len()];
        for (i, &c) in sdem.cells().iter().enumerate() {
            point_of_cell[c as usize] = i as u32;
        }
        let k = radius_cells.max(1) as i64;
        let points = sdem.surface_points();
        let fits = sdem
            .cells()
            .par_iter()
            .zip(points.par_iter())
            .map(|(&cell, p)| {
                let centre = Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                // Neighbours must lie within the patch the cells span at this range, plus noise.
                let reach = 2.5 * k as f64 * grid.resolution() * centre.norm() + 0.02;
                // A patch of (2k + 1)² cells spreads by about k/√3 cells each way. One spread
                // by less than a fifth of a cell's width across its longer direction is a line
                // (a floor seen at a grazing angle keeps only the neighbours beside it, not
                // those beyond), and one narrower than MIN_PATCH_WIDTH_M is a cluster of returns
                // (the floor straight below, where the cells meet at the pole): either way the
                // range noise, not a surface, would set its "normal".
                let min_width = (0.2 * grid.resolution() * centre.norm()).max(MIN_PATCH_WIDTH_M);
                let patch = patch_moments(grid, &point_of_cell, points, (cell, &centre), k, reach);
                let Some(cov) = patch.covariance(6) else {
                    return ([f32::NAN; 3], f32::NAN);
                };
                // Not a surface patch (a line, a corner, a blob): no normal.
                let Some((mut n, thickness_sq)) = plane_fit(&cov, min_width) else {
                    return ([f32::NAN; 3], f32::NAN);
                };
                if n.dot(&centre) > 0.0 {
                    n = -n;
                }
                ([n.x as f32, n.y as f32, n.z as f32], thickness_sq as f32)
            })
            .collect::<Vec<([f32; 3], f32)>>();
        let (normals, thickness_sq): (Vec<[f32; 3]>, Vec<f32>) = fits.into_iter().unzip();
        let with_normal: Vec<u32> = (0..points.len() as u32)
            .filter(|&i| !normals[i as usize][0].is_nan())
            .collect();
        let coordinates: Vec<[f32; 3]> = with_normal.iter().map(|&i| points[i as usize]).collect();
        let paired_of_cell = (point_of_cell.iter())
            .map(|&j| match normals.get(j as usize) {
                Some(n) if !n[0].is_nan() => points[j as usize],
                _ => [f32::NAN; 3],
            })
            .collect();
        let surface_of_cell = (point_of_cell.iter())
            .map(|&j| match normals.get(j as usize) {
                Some(n) if !n[0].is_nan() => {
                    let p = points[j as usize];
                    [p[0], p[1], p[2], n[0], n[1], n[2]]
                }
                _ => [f32::NAN; 6],
            })
            .collect();
        Self {
            point_of_cell,
            normals,
            thickness_sq,
            with_normal: (coordinates, with_normal),
            neighbours: std::sync::OnceLock::new(),
            paired_of_cell,
            surface_of_cell,
        }
    }

    /// Number of boundary points with a normal.
    pub fn count(&self) -> usize {
        self.normals.iter().filter(|n| !n[0].is_nan()).count()
    }
}

impl SurfaceNormals {
    /// The boundary point with a normal nearest to `x` within `max_distance`, by index into
    /// `Sdem::points()` (`points`: the reference's surface points, which are the ones compared).
    /// `cell`: `x`'s cell of `grid`; `hint`: a point likely near (the last pair, `u32::MAX` for
    /// none). The same point as [`Self::nearest`] (ties aside), found faster.
    pub(super) fn nearest_in_cone(
        &self,
        grid: &GridSpec,
        points: &[[f32; 3]],
        x: [f32; 3],
        cell: u32,
        hint: u32,
        max_distance: f32,
    ) -> Option<u32> {
        let max_sq = max_distance * max_distance;
        let squared = |p: [f32; 3]| {
            let d = [x[0] - p[0], x[1] - p[1], x[2] - p[2]];
            d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        };
        let mut best: Option<(f32, u32)> = None;
        for j in [hint, self.point_of_cell[cell as usize]] {
            if j != u32::MAX && !self.normals[j as usize][0].is_nan() {
                let d = squared(points[j as usize]);
                if d <= max_sq && best.is_none_or(|b| d < b.0) {
                    best = Some((d, j));
                }
            }
        }
        let reach = best.map_or(max_distance, |b| b.0.sqrt());
        let Some(cone) = Cone::of(grid, x, reach) else {
            return self.nearest(x, max_distance);
        };
        let n_az = grid.azimuth_cells() as i32;
        let mut best_cell = None;
        let mut best_sq = best.map_or(max_sq, |b| b.0);
        for e in cone.rows {
            let row = e as usize * n_az as usize;
            for a in cone.columns.clone() {
                let a = if grid.is_full_circle() {
                    wrap_column(a, n_az)
                } else {
                    a
                };
                // NaN (no point with a normal) never compares below.
                let d = squared(self.paired_of_cell[row + a as usize]);
                if d < best_sq {
                    (best_sq, best_cell) = (d, Some(row + a as usize));
                }
            }
        }
        match best_cell {
            Some(c) => Some(self.point_of_cell[c]),
            None => best.map(|b| b.1),
        }
    }

    /// The boundary point with a normal nearest to `x` within `max_distance`, by index into
    /// `Sdem::points()`, from the k-d tree (kiddo). A spatial hash of 10 cm cells, scanning the
    /// 27 cells around `x` (a few hundred points near the sensor), took twice the tree's time.
    pub(super) fn nearest(&self, x: [f32; 3], max_distance: f32) -> Option<u32> {
        let (coordinates, index) = &self.with_normal;
        let tree = self
            .neighbours
            .get_or_init(|| {
                (!coordinates.is_empty()).then(|| ImmutableKdTree::new_from_slice(coordinates))
            })
            .as_ref()?;
        let found = tree.nearest_one::<SquaredEuclidean>(&x);
        (found.distance <= max_distance * max_distance).then(|| index[found.item as usize])
    }
}

/// The reach of the blended surface's weights that measured best (the refinement's residual once
/// settled, where [`super::RefineConfig::blend_radius_cells`] turns it on: the planes of the
/// reference points around the paired one, averaged with weights of their distance from the
/// query point), in cells' widths at the query point's range: a reference point farther from
/// the query point does not count. At 1.5 a point half a cell away weighs 0.79, one a cell away
/// 0.31. On the 300 re-views of `sdem bench --suite real-geometry` it takes the error from 0.58 /
/// 1.22 / 2.15 mm (median / p95 / max) to 0.53 / 1.18 / 2.01 and the re-views within the
/// per-view bound from 283 to 291; on one 3DTK scan and one KITTI frame (50 re-views each) 1.0
/// kept 47 and 48 within it, 1.4 49 and 48, 2.0 48 of the frame's, the nearest plane alone 47
/// and 44 (those four with the blend found afresh at every iteration). It is not the default:
/// in the loop (`sdem bench --suite routes`, seeds 1–7) it placed 71 of 84 runs within 2 cm
/// against 73, and one run (seed 6, `long-steps` without odometry) accepted a false loop
/// closure, where the nearest planes accept none.
pub const BLEND_RADIUS_CELLS: f64 = 1.5;

impl SurfaceNormals {
    /// The signed distance of `x` from the reference's surface near its cell `cell` (the cell
    /// of the reference point `x` is paired with), and that surface's normal: the reference
    /// points with a normal in the 3 × 3 cells around `cell`, each as the plane through it, their
    /// distances and normals averaged with weights `(1 − d² / R²)²` of their distance `d` from
    /// `x` (`R` = `radius`); an implicit moving-least-squares surface after Kolluri (2008) and
    /// IMLS-SLAM, with a weight of compact support instead of their Gaussian. The plane of the
    /// nearest point alone passes through that one sample, whose range noise goes whole into
    /// the residual. Blended, a residual averages the noise of the samples around `x` (GICP's
    /// covariances over 20 neighbours do the same). Only the 3 × 3 cells are read: samples up
    /// to about a cell's width from the pair's are weighed, farther ones not even within
    /// `radius` (an azimuth cell is narrower than a cell's width away from the horizon).
    /// `None` when no point lies within `radius`.
    pub(super) fn blended(
        &self,
        grid: &GridSpec,
        x: [f32; 3],
        cell: u32,
        radius: f32,
    ) -> Option<(f32, [f32; 3])> {
        let inverse = 1.0 / (radius * radius);
        let (mut weights, mut distance) = (0f32, 0f32);
        let mut normal = [0f32; 3];
        for c in grid.cells_around(cell as usize).into_iter().flatten() {
            let s = &self.surface_of_cell[c];
            let d = [x[0] - s[0], x[1] - s[1], x[2] - s[2]];
            let t = 1.0 - (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) * inverse;
            // NaN: no point with a normal in the cell.
            if t.is_nan() || t <= 0.0 {
                continue;
            }
            let w = t * t;
            weights += w;
            distance += w * (s[3] * d[0] + s[4] * d[1] + s[5] * d[2]);
            for k in 0..3 {
                normal[k] += w * s[3 + k];
            }
        }
        let length = (normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]).sqrt();
        (weights > 0.0 && length > 1e-6 * weights).then(|| {
            (
                distance / weights,
                [normal[0] / length, normal[1] / length, normal[2] / length],
            )
        })
    }
}

/// The cells holding every direction within `asin(reach / |x|)` of `x`'s.
struct Cone {
    rows: std::ops::RangeInclusive<i32>,
    /// Unwrapped: they may run past the grid's on a full circle.
    columns: std::ops::RangeInclusive<i32>,
}

impl Cone {
    /// `x`'s cone of radius `reach`, or `None` where it is too wide to visit: more than
    /// [`MAX_CONE_CELLS`], near a pole, or `x` within `2 reach` of the origin.
    fn of(grid: &GridSpec, x: [f32; 3], reach: f32) -> Option<Cone> {
        let horizontal = (x[0] * x[0] + x[1] * x[1]).sqrt();
        let range = (horizontal * horizontal + x[2] * x[2]).sqrt();
        let sine = reach / range;
        // The cap of angular radius α about a direction at elevation φ spans
        // asin(sin α / cos φ) of azimuth each way.
        let spread = reach / horizontal;
        if !(sine <= 0.5 && spread <= 0.5) {
            return None;
        }
        let (fa, fe) = grid.position_in_cells(x)?;
        let per_cell = 1.0 / grid.resolution() as f32;
        let rows_half = ASIN_SLOPE * sine * per_cell + MARGIN_CELLS;
        let columns_half = ASIN_SLOPE * spread * per_cell + MARGIN_CELLS;
        let (n_az, n_el) = (grid.azimuth_cells() as i32, grid.elevation_cells() as i32);
        let rows = ((fe - rows_half).floor() as i32).max(0)
            ..=((fe + rows_half).floor() as i32).min(n_el - 1);
        let (a0, a1) = (
            (fa - columns_half).floor() as i32,
            (fa + columns_half).floor() as i32,
        );
        let columns = if grid.is_full_circle() {
            a0..=a1
        } else {
            a0.max(0)..=a1.min(n_az - 1)
        };
        let count = (rows.end() - rows.start() + 1) * (columns.end() - columns.start() + 1);
        (count <= MAX_CONE_CELLS && a1 - a0 < n_az).then_some(Cone { rows, columns })
    }
}

/// The least spread (standard deviation, metres) a surface patch must have across its longer
/// direction for its normal to be fitted: well above a laser range finder's noise (5 mm for the
/// SICK), so the noise of a cluster of returns is not taken for a surface.
const MIN_PATCH_WIDTH_M: f64 = 0.01;

/// The unit normal of a surface patch with point covariance `cov` (the eigenvector of its
/// smallest eigenvalue `λ0`) and that eigenvalue, the patch's variance along the normal (m²: how
/// far its points scatter about the plane fitted to them); or `None` where the patch is not a
/// surface (`λ0 > λ1 / 4`: a corner, a blob; or `λ1 < min_width²`: a line, whose second spread
/// is only its noise).
///
/// In closed form: the eigenvalues are the roots of the characteristic cubic (its trigonometric
/// solution), the eigenvector the longest cross product of two rows of `cov − λ0 I` (of rank 2
/// when `λ0 < λ1`). With nalgebra's iterative `symmetric_eigen` instead, the normals of a
/// 10,000-point S-DEM took 7.6 ms on one core, 4.5 ms with this.
pub(super) fn plane_fit(cov: &Matrix3<f64>, min_width: f64) -> Option<(Vec3, f64)> {
    let off = cov[(0, 1)].powi(2) + cov[(0, 2)].powi(2) + cov[(1, 2)].powi(2);
    let mean = cov.trace() / 3.0;
    let spread = (0..3).map(|i| (cov[(i, i)] - mean).powi(2)).sum::<f64>() + 2.0 * off;
    let p = (spread / 6.0).sqrt();
    if p.is_nan() || p <= 0.0 {
        // Isotropic (or not a number): no direction stands out.
        return None;
    }
    let b = (cov - Matrix3::identity() * mean) / p;
    let phi = (0.5 * b.determinant()).clamp(-1.0, 1.0).acos() / 3.0;
    let largest = mean + 2.0 * p * phi.cos();
    let smallest = mean + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let middle = 3.0 * mean - largest - smallest;
    if middle <= 0.0 || smallest > 0.25 * middle || middle < min_width * min_width {
        return None;
    }
    let m = cov - Matrix3::identity() * smallest;
    let rows = [
        m.row(0).transpose(),
        m.row(1).transpose(),
        m.row(2).transpose(),
    ];
    let n = [
        rows[0].cross(&rows[1]),
        rows[0].cross(&rows[2]),
        rows[1].cross(&rows[2]),
    ]
    .into_iter()
    .max_by(|a, b| a.norm_squared().total_cmp(&b.norm_squared()))
    .expect("three products");
    let length = n.norm();
    (length > 0.0).then(|| (n / length, smallest.max(0.0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Attitude;
    use crate::sdem::SdemConfig;
    use crate::test_scenes::room;

    /// A deterministic scatter in [-1, 1).
    fn jitter(k: usize) -> f64 {
        let h = (k as u64)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .rotate_left(17);
        (h >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    #[test]
    fn the_cone_of_cells_finds_the_point_the_tree_finds() {
        let sdem =
            Sdem::from_points(&room(0.02), &Attitude::default(), &SdemConfig::default()).unwrap();
        let normals = SurfaceNormals::new(&sdem, 2);
        let (grid, points) = (sdem.grid(), sdem.surface_points());
        let (mut compared, mut in_cone, mut paired) = (0, 0, 0);
        for (k, p) in points.iter().enumerate().step_by(3) {
            // Moved off the surface by up to 1.5 cm each way.
            let x = [
                p[0] + 0.015 * jitter(3 * k) as f32,
                p[1] + 0.015 * jitter(3 * k + 1) as f32,
                p[2] + 0.015 * jitter(3 * k + 2) as f32,
            ];
            let Some((cell, _)) = grid.cell_of(x) else {
                continue;
            };
            let max_distance = [0.02, 0.05, 0.1][k % 3];
            let expected = normals.nearest(x, max_distance);
            // No hint, a near one (the point itself) and a far one.
            let far = ((k * 7919) % points.len()) as u32;
            for hint in [u32::MAX, k as u32, far] {
                let found = normals.nearest_in_cone(grid, points, x, cell, hint, max_distance);
                assert_eq!(
                    found, expected,
                    "x {x:?}, hint {hint}, within {max_distance}"
                );
                compared += 1;
            }
            let reach = expected.map_or(max_distance, |j| {
                let q = points[j as usize];
                ((x[0] - q[0]).powi(2) + (x[1] - q[1]).powi(2) + (x[2] - q[2]).powi(2)).sqrt()
            });
            in_cone += Cone::of(grid, x, reach).is_some() as usize;
            paired += expected.is_some() as usize;
        }
        // Most lookups went through the cells (the rest, near the poles, through the tree), and
        // most found a point.
        let looked_up = compared / 3;
        assert!(in_cone * 10 > looked_up * 9, "{in_cone} of {looked_up}");
        assert!(paired * 3 > looked_up * 2, "{paired} of {looked_up}");
    }

    /// The room's floor (z = −0.4 m) seen with 5 mm of range noise: points of the true floor
    /// between the samples lie nearer the blended surface than the plane of their nearest
    /// sample, whose noise the nearest plane carries whole.
    #[test]
    fn the_blended_surface_averages_the_samples_noise() {
        let noisy: Vec<Vec3> = (room(0.02).iter().enumerate())
            .map(|(k, p)| p * (1.0 + 0.005 * jitter(k) * 3f64.sqrt() / p.norm()))
            .collect();
        let sdem = Sdem::from_points(&noisy, &Attitude::default(), &SdemConfig::default()).unwrap();
        let normals = SurfaceNormals::new(&sdem, 2);
        let (grid, points) = (sdem.grid(), sdem.surface_points());
        let (mut nearest_sq, mut blended_sq, mut count) = (0.0, 0.0, 0);
        for k in 0..2000 {
            // The floor within 1 m of the sensor's foot, away from the walls.
            let y = -0.25 + 0.55 * jitter(2 * k + 1);
            let x = [0.9 * jitter(2 * k) as f32, y as f32, -0.4];
            let Some(j) = normals.nearest(x, 0.05) else {
                continue;
            };
            let (p, n) = (points[j as usize], normals.normals[j as usize]);
            let plane = n[0] * (x[0] - p[0]) + n[1] * (x[1] - p[1]) + n[2] * (x[2] - p[2]);
            let range = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
            let radius = (BLEND_RADIUS_CELLS * grid.resolution()) as f32 * range;
            let cell = sdem.cells()[j as usize];
            // None where the floor is seen at a grazing angle, its samples farther apart than
            // the radius (the refinement keeps the nearest plane there).
            let Some((distance, _)) = normals.blended(grid, x, cell, radius) else {
                continue;
            };
            nearest_sq += (plane * plane) as f64;
            blended_sq += (distance * distance) as f64;
            count += 1;
        }
        assert!(count > 1000, "{count} floor points blended");
        let (nearest, blended) = (
            (nearest_sq / count as f64).sqrt(),
            (blended_sq / count as f64).sqrt(),
        );
        // Measured: 1.96 mm against 2.33 mm (each cell already averages the returns in it).
        assert!(
            blended < 0.9 * nearest,
            "rms from the blended surface {blended} m, from the nearest plane {nearest} m"
        );
    }

    /// Off a noise-free plane, the blended distance is the distance from the plane, and no
    /// sample within the radius gives none.
    #[test]
    fn the_blended_surface_of_a_plane_is_the_plane() {
        let sdem =
            Sdem::from_points(&room(0.02), &Attitude::default(), &SdemConfig::default()).unwrap();
        let normals = SurfaceNormals::new(&sdem, 2);
        let grid = sdem.grid();
        let mut checked = 0;
        for k in 0..200 {
            // The floor 1 cm below, away from the walls and the pillar (y = 0.5 m).
            let y = -0.25 + 0.5 * jitter(2 * k + 1);
            let x = [0.8 * jitter(2 * k) as f32, y as f32, -0.39];
            let Some(j) = normals.nearest(x, 0.05) else {
                continue;
            };
            let cell = sdem.cells()[j as usize];
            let (distance, normal) = normals.blended(grid, x, cell, 0.05).unwrap();
            assert!((distance - 0.01).abs() < 2e-4, "{distance} at {x:?}");
            assert!(normal[2] > 0.9999, "{normal:?}");
            // Every sample lies on the floor, at least 1 cm from x.
            assert!(normals.blended(grid, x, cell, 0.0099).is_none());
            checked += 1;
        }
        assert!(checked > 100, "{checked} of 200");
    }
}
