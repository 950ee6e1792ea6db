//! Fixed scenes: the paper's room and a featureless corridor.

use super::scene::Scene;
use super::solids::Solid;
use super::{aabb, yawed_box};
use sdem::error::{Error, Result};

/// Height of the sensor above the floor at the world origin of [`paper_room`], metres.
pub const PAPER_ROOM_SENSOR_HEIGHT_M: f64 = 0.30;
/// Height of the sensor above the floor at the world origin of [`corridor`], metres.
pub const CORRIDOR_SENSOR_HEIGHT_M: f64 = 0.40;

/// The paper's preparatory experiment (Sec. V): a simple indoor room with a flat floor and
/// several obstacles. Deterministic.
///
/// The room is 4 m (x) × 3.5 m (y) × 2.4 m: x ∈ [−1.5, 2.5], y ∈ [−1.75, 1.75], with the floor
/// at `z = −PAPER_ROOM_SENSOR_HEIGHT_M` so that a sensor at the world origin stands 0.3 m above
/// it (and one at (0, 0, 0.3) is free too). In front of the origin: boxes of various sizes on the
/// floor, a column, a shelf against the front wall and a beam under the ceiling, none of them
/// symmetric, so one scan from the origin fixes x, y and z.
pub fn paper_room() -> Scene {
    let f = -PAPER_ROOM_SENSOR_HEIGHT_M;
    let mut scene = Scene::new();
    scene.add_free(aabb([-1.5, -1.75, f], [2.5, 1.75, f + 2.4]));
    let solids = [
        // Boxes on the floor.
        yawed_box([1.3, 0.7, f + 0.2], [0.30, 0.25, 0.20], 15.0),
        yawed_box([1.9, -0.9, f + 0.3], [0.20, 0.20, 0.30], -25.0),
        yawed_box([0.8, -0.45, f + 0.1], [0.15, 0.10, 0.10], 40.0),
        yawed_box([-0.9, 1.1, f + 0.25], [0.30, 0.30, 0.25], 0.0),
        // A column, floor to ceiling.
        yawed_box([0.9, -1.4, f + 1.2], [0.15, 0.15, 1.2], 0.0),
        // A shelf against the front wall.
        yawed_box([2.3, 0.9, f + 0.8], [0.2, 0.6, 0.8], 0.0),
        // A beam under the ceiling.
        yawed_box([1.6, 0.0, f + 2.25], [0.1, 1.75, 0.15], 0.0),
    ];
    for b in solids {
        scene.add_solid(Solid::Box(b));
    }
    scene
}

/// A long, straight, featureless corridor along x: 1.2 m wide, 1.0 m high, `length_m` long,
/// centred on the world origin (x ∈ [−length/2, length/2], y ∈ [−0.6, 0.6]), floor at
/// `z = −CORRIDOR_SENSOR_HEIGHT_M`. Its scans do not fix x: localization should report that.
///
/// # Errors
/// [`Error::Invalid`] unless `length_m` is a finite length above 0.1 m.
pub fn corridor(length_m: f64) -> Result<Scene> {
    if !(length_m.is_finite() && length_m > 0.1) {
        return Err(Error::Invalid(format!(
            "corridor: length {length_m} m must be a finite length above 0.1 m"
        )));
    }
    let f = -CORRIDOR_SENSOR_HEIGHT_M;
    let h = 0.5 * length_m;
    let mut scene = Scene::new();
    scene.add_free(aabb([-h, -0.6, f], [h, 0.6, f + 1.0]));
    Ok(scene)
}
