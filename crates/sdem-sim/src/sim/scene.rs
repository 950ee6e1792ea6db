//! The scene: free-space boxes (the air) minus solid obstacles, cast exactly.

use super::route::Route;
use super::solids::{OrientedBox, Solid};
use super::EPS;
use sdem::geometry::Vec3;
use std::f64::consts::PI;

/// The smallest vertical gap (metres) that [`Scene::floor_height`] counts as a place to stand.
pub const MIN_STANDING_GAP_M: f64 = 0.10;

/// A scene: the union of free-space boxes (the air) minus solid obstacles.
///
/// Walls, floors and ceilings are the boundary of the air; the solids stand inside it. Scenes
/// built by [`collapsed_building`] also carry the drivable route that
/// [`collapsed_building_stops`] places stops on.
///
/// [`collapsed_building`]: super::collapsed_building
/// [`collapsed_building_stops`]: super::collapsed_building_stops
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Scene {
    free: Vec<OrientedBox>,
    solids: Vec<Solid>,
    pub(super) route: Option<Route>,
}

impl Scene {
    /// An empty scene (no air: every ray hits at once).
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a free-space volume to the air.
    pub fn add_free(&mut self, volume: OrientedBox) {
        self.free.push(volume);
    }

    /// Adds a solid obstacle.
    pub fn add_solid(&mut self, solid: Solid) {
        self.solids.push(solid);
    }

    /// The free-space volumes whose union is the air.
    pub fn free_volumes(&self) -> &[OrientedBox] {
        &self.free
    }

    /// The solid obstacles.
    pub fn solids(&self) -> &[Solid] {
        &self.solids
    }

    /// For a [`collapsed_building`]: the indices `(i, j)` of the two stops of
    /// [`collapsed_building_stops`] that stand at the same place with the same heading, where
    /// the loop in the void starts and where it comes back (`j = i + 20`). `None` for scenes
    /// without a route.
    ///
    /// [`collapsed_building`]: super::collapsed_building
    /// [`collapsed_building_stops`]: super::collapsed_building_stops
    pub fn loop_closure_stops(&self) -> Option<(usize, usize)> {
        self.route.as_ref().map(|r| (r.anchors[0], r.anchors[1]))
    }

    /// The axis-aligned bounds `(min, max)` of the air, or `None` for an empty scene.
    pub fn air_bounds(&self) -> Option<(Vec3, Vec3)> {
        self.free.iter().fold(None, |acc, b| {
            let m = b.world_from_box.matrix();
            let half =
                Vec3::from_fn(|r, _| (0..3).map(|c| m[(r, c)].abs() * b.half_extents[c]).sum());
            let (lo, hi) = (b.center - half, b.center + half);
            Some(match acc {
                None => (lo, hi),
                Some((a, z)) => (a.inf(&lo), z.sup(&hi)),
            })
        })
    }

    /// The distance along the ray `origin + t · direction` (direction a unit vector) to the first
    /// surface: where it leaves the air or enters a solid. `None` when that is beyond
    /// `max_range`. From a point that is not free the ray hits at once: `Some(0.0)`.
    ///
    /// # Example
    /// ```
    /// use sdem::geometry::Vec3;
    /// let room = sdem_sim::sim::paper_room();
    /// // The floor lies PAPER_ROOM_SENSOR_HEIGHT_M below the origin.
    /// let down = room.raycast(&Vec3::zeros(), &-Vec3::z(), 8.0).unwrap();
    /// assert!((down - sdem_sim::sim::PAPER_ROOM_SENSOR_HEIGHT_M).abs() < 1e-12);
    /// ```
    pub fn raycast(&self, origin: &Vec3, direction: &Vec3, max_range: f64) -> Option<f64> {
        let exit = self.air_exit(origin, direction, max_range);
        let hit = self
            .solids
            .iter()
            .filter_map(|s| s.hit_distance(origin, direction))
            .fold(exit, f64::min);
        (hit <= max_range).then_some(hit)
    }

    /// Where the ray leaves the union of free boxes: from the boxes that hold the current point
    /// and go on along the ray, jump to the farthest exit; repeat until none goes on. Boxes that
    /// share a face (within [`EPS`]) chain. Stops early past `max_range`.
    fn air_exit(&self, origin: &Vec3, direction: &Vec3, max_range: f64) -> f64 {
        let intervals: Vec<(f64, f64)> = self
            .free
            .iter()
            .filter_map(|b| b.ray_interval(origin, direction))
            .filter(|&(_, t_out)| t_out > EPS)
            .collect();
        let mut reach = 0.0;
        loop {
            let next = intervals
                .iter()
                .filter(|&&(t_in, t_out)| t_in <= reach + EPS && t_out > reach + EPS)
                .map(|&(_, t_out)| t_out)
                .fold(reach, f64::max);
            if next <= reach || next > max_range {
                return next;
            }
            reach = next;
        }
    }

    /// The part of the scene a sensor at `centre` can see within `range` metres: the free
    /// boxes and solids whose bounding spheres come that close (without the route). Rays from
    /// `centre` no longer than `range` meet the same surfaces in both, so a large scene is
    /// cast stop by stop at the cost of its neighbourhood.
    pub fn cropped(&self, centre: &Vec3, range: f64) -> Scene {
        let near = |c: &Vec3, radius: f64| (c - centre).norm() <= range + radius + EPS;
        Scene {
            free: (self.free.iter())
                .filter(|b| near(&b.center, b.half_extents.norm()))
                .cloned()
                .collect(),
            solids: (self.solids.iter())
                .filter(|s| near(s.center(), s.bounding_radius()))
                .cloned()
                .collect(),
            route: None,
        }
    }

    /// True when `p` is inside the air and not strictly inside any solid.
    pub fn is_free(&self, p: &Vec3) -> bool {
        self.free.iter().any(|b| b.contains(p)) && !self.solids.iter().any(|s| s.contains(p))
    }

    /// The free stretches `(t_in, t_out)` of the line `origin + t · direction`, sorted: the union
    /// of the free boxes' intervals minus the solids' intervals.
    fn free_stretches(&self, origin: &Vec3, direction: &Vec3) -> Vec<(f64, f64)> {
        let mut air: Vec<(f64, f64)> = self
            .free
            .iter()
            .filter_map(|b| b.ray_interval(origin, direction))
            .collect();
        air.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut merged: Vec<(f64, f64)> = Vec::with_capacity(air.len());
        for (t_in, t_out) in air {
            match merged.last_mut() {
                Some(last) if t_in <= last.1 + EPS => last.1 = last.1.max(t_out),
                _ => merged.push((t_in, t_out)),
            }
        }
        for solid in &self.solids {
            if let Some(cut) = solid.ray_interval(origin, direction) {
                merged = subtract_interval(&merged, cut);
            }
        }
        merged
    }

    /// The floor height at `(x, y)`: the bottom of the lowest free vertical gap there at least
    /// [`MIN_STANDING_GAP_M`] tall (the top of rubble counts as floor; thin slivers under tilted
    /// blocks do not). `None` where no air lies above `(x, y)`.
    pub fn floor_height(&self, x: f64, y: f64) -> Option<f64> {
        let (_, max) = self.air_bounds()?;
        let top = max.z + 1.0;
        let stretches = self.free_stretches(&Vec3::new(x, y, top), &-Vec3::z());
        stretches
            .iter()
            .rev()
            .find(|(t_in, t_out)| t_out - t_in >= MIN_STANDING_GAP_M)
            .map(|&(_, t_out)| top - t_out)
    }

    /// The distance from `p` to the nearest surface, sampled with rays in `direction_count`
    /// evenly spread directions (so at least the true distance; thin features between the
    /// samples can be missed). 0 when `p` is not free.
    pub fn clearance(&self, p: &Vec3, direction_count: usize) -> f64 {
        if !self.is_free(p) {
            return 0.0;
        }
        sphere_directions(direction_count)
            .iter()
            .filter_map(|d| self.raycast(p, d, f64::INFINITY))
            .fold(f64::INFINITY, f64::min)
    }
}

/// `intervals` (sorted, disjoint) minus `cut`.
fn subtract_interval(intervals: &[(f64, f64)], cut: (f64, f64)) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(intervals.len() + 1);
    for &(a, b) in intervals {
        if cut.1 <= a || cut.0 >= b {
            out.push((a, b));
            continue;
        }
        if cut.0 > a {
            out.push((a, cut.0));
        }
        if cut.1 < b {
            out.push((cut.1, b));
        }
    }
    out
}

/// `n` unit vectors spread evenly over the sphere (a Fibonacci lattice).
fn sphere_directions(n: usize) -> Vec<Vec3> {
    let golden = PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let a = golden * i as f64;
            Vec3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}
