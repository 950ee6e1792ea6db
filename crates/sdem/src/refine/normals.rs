//! The reference's surface normals, and the refinement's pairing: the reference point with a
//! normal nearest to a query point, looked up through the reference S-DEM's own cells where a
//! small cone of them holds every point near enough, and through a k-d tree where it would not.
//!
//! A reference point within `d` of `x` (at range `r > 2d`) lies within the angle `asin(d / r)`
//! of `x`'s direction, so in a few cells around `x`'s own: a refinement's pairs move by
//! millimetres between associations, and the last pair (or, the first time, the point in `x`'s
//! cell) bounds `d` by about a cell's width.

use super::{plane_normal, MIN_PATCH_WIDTH_M};
use crate::geometry::Vec3;
use crate::sdem::{patch_moments, wrap_column, Derived, GridSpec, Sdem};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
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
    /// The boundary points with a normal, and the index into `Sdem::points()` of each.
    with_normal: (Vec<[f32; 3]>, Vec<u32>),
    /// Those points in a k-d tree, built on the first lookup that needs it (most pairings never
    /// do: on KITTI frames building a tree for every S-DEM was 13 % of `sdem slam`'s
    /// instructions); `None` when no point has a normal.
    neighbours: std::sync::OnceLock<Option<ImmutableKdTree<f32, 3>>>,
    /// Per grid cell, its surface point when it has a normal, else NaN (see `nearest`).
    paired_of_cell: Vec<[f32; 3]>,
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
        let normals = sdem
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
                    return [f32::NAN; 3];
                };
                // Not a surface patch (a line, a corner, a blob): no normal.
                let Some(mut n) = plane_normal(&cov, min_width) else {
                    return [f32::NAN; 3];
                };
                if n.dot(&centre) > 0.0 {
                    n = -n;
                }
                [n.x as f32, n.y as f32, n.z as f32]
            })
            .collect::<Vec<[f32; 3]>>();
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
        Self {
            point_of_cell,
            normals,
            with_normal: (coordinates, with_normal),
            neighbours: std::sync::OnceLock::new(),
            paired_of_cell,
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
}
