//! Scenes the unit tests of several modules share.

use crate::geometry::Vec3;

/// A box-shaped room seen from inside (walls at x = 2, −1.5 and y = 1.7, −1.3 m, ceiling at
/// 1.1 m, floor at −0.4 m) with a pillar's face 0.4 m wide at y = 0.5 m, sampled every `step`
/// metres over ±2 m of each surface's two coordinates.
pub(crate) fn room(step: f64) -> Vec<Vec3> {
    let n = (2.0 / step).round() as i32;
    let pillar = (0.2 / step).round() as i32;
    let mut points = Vec::new();
    for i in -n..=n {
        for j in -n..=n {
            let (u, v) = (i as f64 * step, j as f64 * step);
            let walls = [[2.0, u, v], [-1.5, u, v], [u, 1.7, v], [u, -1.3, v]];
            for p in walls.into_iter().chain([[u, v, 1.1], [u, v, -0.4]]) {
                points.push(Vec3::new(p[0], p[1], p[2]));
            }
            if i.abs() <= pillar {
                points.push(Vec3::new(0.8 + u, 0.5, 0.3 * v));
            }
        }
    }
    points
}
