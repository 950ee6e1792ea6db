//! The voxels a ray crosses, enumerated exactly by the 3D DDA of Amanatides and Woo (1987).

use super::keys::key_of;
use super::VoxelKey;
use crate::geometry::Vec3;

/// Calls `visit` for every voxel the segment from `origin` (in voxel `origin_key`) to `end`
/// crosses, in order, from the origin's voxel up to but **not** including `end`'s voxel (so
/// nothing when both are in one voxel) — the
/// 3D DDA of Amanatides & Woo (1987). Consecutive voxels share a face. Exactly
/// `|Δi| + |Δj| + |Δk|` voxels are visited, so the walk always ends in `end`'s voxel, whatever
/// the rounding; where the segment passes exactly through an edge or corner, one of the voxels
/// sharing it is taken.
#[inline]
pub(super) fn traverse(
    origin: &Vec3,
    origin_key: VoxelKey,
    end: &Vec3,
    inv_s: f64,
    mut visit: impl FnMut(VoxelKey),
) {
    let Some(end_key) = key_of(end, inv_s) else {
        return;
    };
    // In voxel units, relative to the origin.
    let dir = (end - origin) * inv_s;
    let o = origin * inv_s;
    let mut key = origin_key;
    let mut remaining = [0u64; 3];
    let mut step = [0i32; 3];
    // Ray parameter t ∈ [0, 1] at the next boundary along each axis, and between boundaries.
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    for axis in 0..3 {
        let diff = i64::from(end_key[axis]) - i64::from(origin_key[axis]);
        remaining[axis] = diff.unsigned_abs();
        if diff == 0 {
            continue;
        }
        step[axis] = diff.signum() as i32;
        let d = dir[axis];
        // Rounding can give a crossing with d = 0 (or of the wrong sign) only for degenerate
        // segments; such an axis is then stepped last, which keeps the walk connected.
        if d * f64::from(step[axis]) > 0.0 {
            let boundary = f64::from(origin_key[axis]) + if step[axis] > 0 { 1.0 } else { 0.0 };
            t_max[axis] = ((boundary - o[axis]) / d).clamp(0.0, f64::MAX);
            t_delta[axis] = (1.0 / d.abs()).min(f64::MAX);
        } else {
            t_max[axis] = f64::MAX;
        }
    }
    let total = remaining[0] + remaining[1] + remaining[2];
    if total == 0 {
        return;
    }
    visit(key);
    for _ in 1..total {
        // The axis whose boundary comes first. An axis with no steps left has t_max = ∞, above
        // the finite (at most f64::MAX) t_max of every axis with steps left.
        let axis = if t_max[0] <= t_max[1] {
            if t_max[0] <= t_max[2] {
                0
            } else {
                2
            }
        } else if t_max[1] <= t_max[2] {
            1
        } else {
            2
        };
        key[axis] += step[axis];
        remaining[axis] -= 1;
        t_max[axis] = if remaining[axis] == 0 {
            f64::INFINITY
        } else {
            (t_max[axis] + t_delta[axis]).min(f64::MAX)
        };
        visit(key);
    }
}
