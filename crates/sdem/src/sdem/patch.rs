//! The patch of cells around a cell: the second moments of the points in it that lie near the
//! cell's own, from which surface normals and planes are fitted.

use super::{wrap_column, GridSpec};
use crate::geometry::Vec3;
use nalgebra::Matrix3;

/// The sums over a patch's points, each taken relative to the patch's centre point (so that the
/// sums stay small far from the sensor).
pub(crate) struct PatchMoments {
    /// The offsets' sum.
    pub sum: Vec3,
    /// The sum of the offsets' outer products.
    pub outer: Matrix3<f64>,
    /// How many points the patch holds.
    pub count: usize,
}

impl PatchMoments {
    /// The offsets' covariance about their mean; `None` where the patch holds fewer than
    /// `min_points` points (or none).
    pub fn covariance(&self, min_points: usize) -> Option<Matrix3<f64>> {
        (self.count >= min_points.max(1)).then(|| {
            let mean = self.sum / self.count as f64;
            self.outer / self.count as f64 - mean * mean.transpose()
        })
    }
}

/// The moments of the points of `grid`'s cells within `k` rows and columns of `cell` (columns
/// wrap round a full circle) that lie within `reach` of `centre`. `point_of_cell` gives each
/// cell's index in `points` (`u32::MAX`: none).
pub(crate) fn patch_moments(
    grid: &GridSpec,
    point_of_cell: &[u32],
    points: &[[f32; 3]],
    (cell, centre): (u32, &Vec3),
    k: i64,
    reach: f64,
) -> PatchMoments {
    let (n_az, n_el) = (grid.azimuth_cells() as i64, grid.elevation_cells() as i64);
    let full_circle = grid.is_full_circle();
    let (ie, ia) = (cell as i64 / n_az, cell as i64 % n_az);
    let reach_sq = reach * reach;
    let mut sum = Vec3::zeros();
    // Upper triangle (xx, xy, xz, yy, yz, zz): the lower holds the same products.
    let mut outer = [0f64; 6];
    let mut count = 0usize;
    for e in (ie - k).max(0)..=(ie + k).min(n_el - 1) {
        for da in -k..=k {
            let a = ia + da;
            let a = if full_circle {
                wrap_column(a as i32, n_az as i32) as i64
            } else if a < 0 || a >= n_az {
                continue;
            } else {
                a
            };
            let j = point_of_cell[(e * n_az + a) as usize];
            if j == u32::MAX {
                continue;
            }
            let q = points[j as usize];
            let q = Vec3::new(q[0] as f64, q[1] as f64, q[2] as f64) - centre;
            if q.norm_squared() <= reach_sq {
                sum += q;
                outer[0] += q.x * q.x;
                outer[1] += q.x * q.y;
                outer[2] += q.x * q.z;
                outer[3] += q.y * q.y;
                outer[4] += q.y * q.z;
                outer[5] += q.z * q.z;
                count += 1;
            }
        }
    }
    let [xx, xy, xz, yy, yz, zz] = outer;
    PatchMoments {
        sum,
        outer: Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz),
        count,
    }
}
