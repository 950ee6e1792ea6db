//! Scenes and a seeded simulator of the tilting-LRF sensor (Nagatani 2003, Sec. IV–V).
//!
//! A [`Scene`] is the union of *free-space* boxes (the air the robot moves in: rooms, a ditch, a
//! void) minus *solid* obstacles inside that air (rubble blocks, slabs, columns, rocks). Rays are
//! cast against it exactly ([`Scene::raycast`]).
//!
//! Scenes: [`paper_room`] (the preparatory experiment of Sec. V), [`corridor`] (long and
//! featureless, for ambiguity tests) and [`collapsed_building`] (a room, a narrow ditch and a wider
//! void, with a drivable stop-and-go route: [`collapsed_building_stops`]). [`scan`] simulates one
//! raw sweep and [`simulate_run`] a whole run.
//!
//! World frame (DESIGN.md): every scene is built so that the world origin is the first scan's
//! sensor origin. The first sensor pose of [`collapsed_building_stops`] is exactly the identity,
//! with the floor flat at `z = -COLLAPSED_BUILDING_START_HEIGHT_M` beneath it.
//!
//! Everything random comes from `ChaCha8Rng` (a fixed algorithm), so a seed gives the same scene,
//! path and sweeps on every machine and for any number of threads.
//!
//! # Example
//! ```
//! use sdem::sensor::SensorConfig;
//! use sdem_sim::sim;
//! let scene = sim::collapsed_building(7);
//! let sensor = SensorConfig::default();
//! let stops = sim::collapsed_building_stops(&scene, 7, 2, &sensor.lift)?;
//! let run = sim::simulate_run(&scene, &stops, &sensor, 7)?;
//! assert_eq!(run.len(), 2);
//! assert_eq!(run[0].world_from_sensor, sdem::geometry::Pose::identity());
//! # Ok::<(), sdem::Error>(())
//! ```

use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use sdem::error::{Error, Result};
use sdem::geometry::{attitude_of, pose_from_parts, Attitude, Pose, Vec3};
use sdem::sensor::{beam_direction, LiftConfig, SensorConfig, Sweep, SweepLine};
use std::borrow::Cow;
use std::f64::consts::{PI, TAU};

/// Tolerance (metres) for points on a shared face and for ray intervals that touch.
const EPS: f64 = 1e-9;

/// The smallest vertical gap (metres) that [`Scene::floor_height`] counts as a place to stand.
pub const MIN_STANDING_GAP_M: f64 = 0.10;
/// Height of the sensor above the floor at the world origin of [`paper_room`], metres.
pub const PAPER_ROOM_SENSOR_HEIGHT_M: f64 = 0.30;
/// Height of the sensor above the floor at the world origin of [`corridor`], metres.
pub const CORRIDOR_SENSOR_HEIGHT_M: f64 = 0.40;
/// Height of the sensor above the flat room floor at the first stop of [`collapsed_building`],
/// metres: the room floor lies at `z = -COLLAPSED_BUILDING_START_HEIGHT_M`.
pub const COLLAPSED_BUILDING_START_HEIGHT_M: f64 = 0.40;
/// The most stops [`collapsed_building_stops`] can place along its route.
pub const MAX_STOPS: usize = 40;
/// Every stop's sensor origin is at least this far from any surface, metres.
pub const MIN_SENSOR_CLEARANCE_M: f64 = 0.15;

// ---------------------------------------------------------------------------------------------
// Primitives
// ---------------------------------------------------------------------------------------------

/// A box with its own orientation: the building block of free space and of solid obstacles.
#[derive(Debug, Clone, PartialEq)]
pub struct OrientedBox {
    center: Vec3,
    half_extents: Vec3,
    world_from_box: Rotation3<f64>,
}

impl OrientedBox {
    /// A box centred at `center` (world, metres) with `half_extents` along its own axes, turned
    /// by `world_from_box`.
    ///
    /// # Errors
    /// [`Error::Invalid`] when a value is not finite or a half extent is not positive.
    pub fn new(center: Vec3, half_extents: Vec3, world_from_box: Rotation3<f64>) -> Result<Self> {
        let finite = center
            .iter()
            .chain(world_from_box.matrix().iter())
            .all(|v| v.is_finite());
        let positive = half_extents.iter().all(|h| h.is_finite() && *h > 0.0);
        if finite && positive {
            Ok(Self::build(center, half_extents, world_from_box))
        } else {
            Err(Error::Invalid(format!(
                "box: need a finite centre and rotation and positive half extents \
                 (got centre {center:?}, half extents {half_extents:?})"
            )))
        }
    }

    /// An axis-aligned box between the corners `min` and `max`.
    ///
    /// # Errors
    /// [`Error::Invalid`] unless `min < max` on every axis.
    pub fn axis_aligned(min: Vec3, max: Vec3) -> Result<Self> {
        Self::new((min + max) * 0.5, (max - min) * 0.5, Rotation3::identity())
    }

    /// A box from values the caller knows to be valid.
    fn build(center: Vec3, half_extents: Vec3, world_from_box: Rotation3<f64>) -> Self {
        debug_assert!(half_extents.iter().all(|h| *h > 0.0));
        Self {
            center,
            half_extents,
            world_from_box,
        }
    }

    /// The centre, world frame, metres.
    pub fn center(&self) -> &Vec3 {
        &self.center
    }

    /// Half the size along each of the box's own axes, metres.
    pub fn half_extents(&self) -> &Vec3 {
        &self.half_extents
    }

    /// The rotation `world_from_box`.
    pub fn rotation(&self) -> &Rotation3<f64> {
        &self.world_from_box
    }

    fn to_local(&self, p: &Vec3) -> Vec3 {
        self.world_from_box
            .inverse_transform_vector(&(p - self.center))
    }

    /// True when `p` lies inside the box or on its surface (within 1 nm).
    pub fn contains(&self, p: &Vec3) -> bool {
        let local = self.to_local(p);
        (0..3).all(|i| local[i].abs() <= self.half_extents[i] + EPS)
    }

    /// True when `p` lies strictly inside the box.
    fn contains_strictly(&self, p: &Vec3) -> bool {
        let local = self.to_local(p);
        (0..3).all(|i| local[i].abs() < self.half_extents[i])
    }

    /// The parameters `(t_in, t_out)` where the line `origin + t · direction` enters and leaves
    /// the box (slab method, exact), or `None` when it misses. `t_in` is negative when `origin`
    /// is inside.
    pub fn ray_interval(&self, origin: &Vec3, direction: &Vec3) -> Option<(f64, f64)> {
        let o = self.to_local(origin);
        let d = self.world_from_box.inverse_transform_vector(direction);
        let (mut t_in, mut t_out) = (f64::NEG_INFINITY, f64::INFINITY);
        for i in 0..3 {
            let h = self.half_extents[i];
            if d[i] == 0.0 {
                if o[i].abs() > h {
                    return None;
                }
                continue;
            }
            let a = (-h - o[i]) / d[i];
            let b = (h - o[i]) / d[i];
            t_in = t_in.max(a.min(b));
            t_out = t_out.min(a.max(b));
        }
        (t_in <= t_out).then_some((t_in, t_out))
    }

    /// Euclidean distance from `p` to the box (0 inside).
    pub fn distance_to(&self, p: &Vec3) -> f64 {
        let local = self.to_local(p);
        Vec3::from_fn(|i, _| (local[i].abs() - self.half_extents[i]).max(0.0)).norm()
    }

    /// Half the box's vertical extent (its world AABB is `center.z ± this`).
    fn half_height(&self) -> f64 {
        let m = self.world_from_box.matrix();
        (0..3).map(|i| m[(2, i)].abs() * self.half_extents[i]).sum()
    }
}

/// An ellipsoid (a rock): a unit sphere scaled by `radii` along its own axes and turned.
#[derive(Debug, Clone, PartialEq)]
pub struct Ellipsoid {
    center: Vec3,
    radii: Vec3,
    world_from_ellipsoid: Rotation3<f64>,
}

impl Ellipsoid {
    /// An ellipsoid centred at `center` with semi-axes `radii` along its own axes, turned by
    /// `world_from_ellipsoid`.
    ///
    /// # Errors
    /// [`Error::Invalid`] when a value is not finite or a radius is not positive.
    pub fn new(center: Vec3, radii: Vec3, world_from_ellipsoid: Rotation3<f64>) -> Result<Self> {
        let finite = center
            .iter()
            .chain(world_from_ellipsoid.matrix().iter())
            .all(|v| v.is_finite());
        let positive = radii.iter().all(|r| r.is_finite() && *r > 0.0);
        if finite && positive {
            Ok(Self::build(center, radii, world_from_ellipsoid))
        } else {
            Err(Error::Invalid(format!(
                "ellipsoid: need a finite centre and rotation and positive radii \
                 (got centre {center:?}, radii {radii:?})"
            )))
        }
    }

    fn build(center: Vec3, radii: Vec3, world_from_ellipsoid: Rotation3<f64>) -> Self {
        debug_assert!(radii.iter().all(|r| *r > 0.0));
        Self {
            center,
            radii,
            world_from_ellipsoid,
        }
    }

    /// The centre, world frame, metres.
    pub fn center(&self) -> &Vec3 {
        &self.center
    }

    /// The semi-axes along the ellipsoid's own axes, metres.
    pub fn radii(&self) -> &Vec3 {
        &self.radii
    }

    /// `p` in the frame where the ellipsoid is the unit sphere.
    fn to_unit(&self, p: &Vec3) -> Vec3 {
        self.world_from_ellipsoid
            .inverse_transform_vector(&(p - self.center))
            .component_div(&self.radii)
    }

    /// The parameters `(t_in, t_out)` where the line `origin + t · direction` enters and leaves
    /// the ellipsoid, or `None` when it misses.
    pub fn ray_interval(&self, origin: &Vec3, direction: &Vec3) -> Option<(f64, f64)> {
        let o = self.to_unit(origin);
        let d = self
            .world_from_ellipsoid
            .inverse_transform_vector(direction)
            .component_div(&self.radii);
        let a = d.norm_squared();
        if a == 0.0 {
            return None;
        }
        let b = o.dot(&d);
        let c = o.norm_squared() - 1.0;
        let disc = b * b - a * c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        Some(((-b - s) / a, (-b + s) / a))
    }

    /// True when `p` lies strictly inside.
    pub fn contains(&self, p: &Vec3) -> bool {
        self.to_unit(p).norm_squared() < 1.0
    }

    /// Half the vertical extent (exact support of the ellipsoid along z).
    fn half_height(&self) -> f64 {
        let m = self.world_from_ellipsoid.matrix();
        (0..3)
            .map(|i| (m[(2, i)] * self.radii[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    }
}

/// A solid obstacle inside the air.
#[derive(Debug, Clone, PartialEq)]
pub enum Solid {
    /// An oriented box: a rubble block, a slab, a column, a shelf.
    Box(OrientedBox),
    /// An ellipsoid: a rock.
    Ellipsoid(Ellipsoid),
}

impl Solid {
    /// The parameters where the line `origin + t · direction` enters and leaves the solid.
    pub fn ray_interval(&self, origin: &Vec3, direction: &Vec3) -> Option<(f64, f64)> {
        match self {
            Solid::Box(b) => b.ray_interval(origin, direction),
            Solid::Ellipsoid(e) => e.ray_interval(origin, direction),
        }
    }

    /// True when `p` lies strictly inside the solid (its surface counts as free).
    pub fn contains(&self, p: &Vec3) -> bool {
        match self {
            Solid::Box(b) => b.contains_strictly(p),
            Solid::Ellipsoid(e) => e.contains(p),
        }
    }

    fn center(&self) -> &Vec3 {
        match self {
            Solid::Box(b) => &b.center,
            Solid::Ellipsoid(e) => &e.center,
        }
    }

    /// Moves the solid vertically so that its lowest point lies 40 % of its half height below
    /// `base`.
    fn rest_on(&mut self, base: f64) {
        let (lo, hi) = self.z_range();
        let dz = base + 0.6 * 0.5 * (hi - lo) - 0.5 * (lo + hi);
        match self {
            Solid::Box(b) => b.center.z += dz,
            Solid::Ellipsoid(e) => e.center.z += dz,
        }
    }

    /// Radius of a sphere around [`Self::center`] that holds the solid.
    fn bounding_radius(&self) -> f64 {
        match self {
            Solid::Box(b) => b.half_extents.norm(),
            Solid::Ellipsoid(e) => e.radii.max(),
        }
    }

    /// Lowest and highest z of the solid (exact for ellipsoids, the AABB for boxes).
    fn z_range(&self) -> (f64, f64) {
        let (z, h) = match self {
            Solid::Box(b) => (b.center.z, b.half_height()),
            Solid::Ellipsoid(e) => (e.center.z, e.half_height()),
        };
        (z - h, z + h)
    }

    /// A distance from `p` to the solid that never exceeds the true one.
    fn distance_lower_bound(&self, p: &Vec3) -> f64 {
        match self {
            Solid::Box(b) => b.distance_to(p),
            Solid::Ellipsoid(e) => ((p - e.center).norm() - e.radii.max()).max(0.0),
        }
    }

    /// Distance along a unit ray to the solid's surface; 0 when `origin` is inside.
    fn hit_distance(&self, origin: &Vec3, direction: &Vec3) -> Option<f64> {
        if !sphere_may_hit(self.center(), self.bounding_radius(), origin, direction) {
            return None;
        }
        let (t_in, t_out) = self.ray_interval(origin, direction)?;
        (t_out > EPS).then_some(t_in.max(0.0))
    }
}

/// Cheap rejection: false when the unit ray cannot touch the sphere.
fn sphere_may_hit(center: &Vec3, radius: f64, origin: &Vec3, direction: &Vec3) -> bool {
    let oc = center - origin;
    let along = oc.dot(direction);
    if along < -radius {
        return false;
    }
    oc.norm_squared() - along * along <= radius * radius + EPS
}

// ---------------------------------------------------------------------------------------------
// Scene
// ---------------------------------------------------------------------------------------------

/// A scene: the union of free-space boxes (the air) minus solid obstacles.
///
/// Walls, floors and ceilings are the boundary of the air; the solids stand inside it. Scenes
/// built by [`collapsed_building`] also carry the drivable route that
/// [`collapsed_building_stops`] places stops on.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Scene {
    free: Vec<OrientedBox>,
    solids: Vec<Solid>,
    route: Option<Route>,
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

/// The angle in [-π, π).
fn wrap_angle(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

fn yaw_rotation(yaw: f64) -> Rotation3<f64> {
    Rotation3::from_axis_angle(&Vector3::z_axis(), yaw)
}

/// A box from literal corners (internal scenes only).
fn aabb(min: [f64; 3], max: [f64; 3]) -> OrientedBox {
    let (min, max) = (Vec3::from(min), Vec3::from(max));
    OrientedBox::build((min + max) * 0.5, (max - min) * 0.5, Rotation3::identity())
}

/// A box turned about z (internal scenes only).
fn yawed_box(center: [f64; 3], half: [f64; 3], yaw_deg: f64) -> OrientedBox {
    OrientedBox::build(
        Vec3::from(center),
        Vec3::from(half),
        yaw_rotation(yaw_deg.to_radians()),
    )
}

// ---------------------------------------------------------------------------------------------
// Fixed scenes
// ---------------------------------------------------------------------------------------------

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

// ---------------------------------------------------------------------------------------------
// The collapsed building
// ---------------------------------------------------------------------------------------------

/// Where the room's front wall and the ditch's mouth are, x in metres.
const MOUTH_X_M: f64 = 1.0;
/// Turning radius of every bend of the route, metres.
const TURN_RADIUS_M: f64 = 1.1;
/// Stops on the loop in the void; the spacing is the loop's length over this.
const LOOP_STEPS: usize = 20;
/// Shortest stretch from the void's entry to the start of the loop, metres.
const MIN_STEM_M: f64 = 1.6;
/// Longitudinal jitter of each stop along the route, metres (± this, uniform).
const STEP_JITTER_M: f64 = 0.015;
/// Radius of the tube around the route kept clear of obstacles in the room and the void, metres.
const TUBE_RADIUS_M: f64 = 0.27;
/// The same in the ditch above the robot's tracks, where its sensor squeezes past broken
/// concrete, metres.
const TUBE_RADIUS_DITCH_M: f64 = 0.22;
/// Below this height above the floor (the tracks), the tube keeps [`TUBE_RADIUS_M`] everywhere.
const TRACK_ZONE_TOP_M: f64 = 0.15;
/// Rubble no higher than this above the floor may lie on the route (the robot drives on it).
const LOW_RUBBLE_TOP_M: f64 = 0.03;
/// Height of the kept-clear tube above the floor where the lift is low (ditch), metres.
const TUBE_TOP_LOW_M: f64 = 0.30;
/// Height of the kept-clear tube above the floor elsewhere, metres.
const TUBE_TOP_HIGH_M: f64 = 0.50;
/// The void's extent along its axis (the ditch's second leg), from the ditch's end, metres.
const VOID_LENGTH_M: f64 = 5.0;
/// The void's extent to the right of the ditch's centre line, metres.
const VOID_RIGHT_M: f64 = 1.5;
/// The void's extent to the left of the ditch's centre line (the loop turns left), metres.
const VOID_LEFT_M: f64 = 2.9;
/// Largest half width of a ditch piece, metres.
const DITCH_MAX_HALF_WIDTH_M: f64 = 0.45;

/// One piece of the route: a straight line or a circular arc (positive angle turns left).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Segment {
    Line(f64),
    Arc { radius: f64, angle: f64 },
}

impl Segment {
    fn length(&self) -> f64 {
        match *self {
            Segment::Line(l) => l,
            Segment::Arc { radius, angle } => radius * angle.abs(),
        }
    }
}

/// The drivable centre line of the collapsed building for the sensor origin, starting at the
/// world origin heading +x, with where stops go.
#[derive(Debug, Clone, PartialEq)]
struct Route {
    segments: Vec<Segment>,
    /// Distance along the route between stops, metres.
    spacing_m: f64,
    /// Arc-length range of the ditch, where the lift is lowered.
    low_lift: (f64, f64),
    /// Stops placed exactly (no jitter): the loop's start and its return to the same place.
    anchors: [usize; 2],
}

impl Route {
    fn length(&self) -> f64 {
        self.segments.iter().map(Segment::length).sum()
    }

    /// Position (x, y) and heading at arc length `s`; before the start and past the end the
    /// first and last segments are extended.
    fn at(&self, s: f64) -> ([f64; 2], f64) {
        let (mut x, mut y, mut yaw) = (0.0f64, 0.0f64, 0.0f64);
        let mut rest = s;
        let n = self.segments.len();
        for (i, seg) in self.segments.iter().enumerate() {
            let len = seg.length();
            let ends_here = rest <= len || i + 1 == n;
            let step = if ends_here { rest } else { len };
            match *seg {
                Segment::Line(_) => {
                    x += step * yaw.cos();
                    y += step * yaw.sin();
                }
                Segment::Arc { radius, angle } => {
                    let sign = angle.signum();
                    let (cx, cy) = (x - sign * radius * yaw.sin(), y + sign * radius * yaw.cos());
                    yaw += sign * step / radius;
                    x = cx + sign * radius * yaw.sin();
                    y = cy - sign * radius * yaw.cos();
                }
            }
            if ends_here {
                break;
            }
            rest -= len;
        }
        ([x, y], wrap_angle(yaw))
    }

    fn lift_is_low(&self, s: f64) -> bool {
        (self.low_lift.0..=self.low_lift.1).contains(&s)
    }
}

/// A 2D frame on the floor plan: origin and heading.
#[derive(Debug, Clone, Copy)]
struct Frame2 {
    origin: [f64; 2],
    yaw: f64,
}

impl Frame2 {
    /// The plan position of the point at `x` ahead and `y` left of the frame's origin.
    fn point(&self, x: f64, y: f64) -> [f64; 2] {
        let (s, c) = self.yaw.sin_cos();
        [
            self.origin[0] + c * x - s * y,
            self.origin[1] + s * x + c * y,
        ]
    }
}

/// The seeded layout: the ditch's two legs, the bend, the void and the route.
struct Plan {
    leg1: f64,
    leg2: f64,
    bend: f64,
    corner: [f64; 2],
    void_frame: Frame2,
    void_height: f64,
    /// Where the loop starts and ends, in the void's frame (on its axis).
    loop_start_x: f64,
    route: Route,
}

impl Plan {
    fn draw(rng: &mut ChaCha8Rng) -> Self {
        let length = rng.random_range(3.0..3.5);
        let share = rng.random_range(0.4..0.6);
        let (leg1, leg2) = (share * length, (1.0 - share) * length);
        let bend = random_sign(rng) * rng.random_range(15f64..35.0).to_radians();
        let void_height = rng.random_range(1.5..2.5);
        let corner = [MOUTH_X_M + leg1, 0.0];
        let end = [corner[0] + leg2 * bend.cos(), corner[1] + leg2 * bend.sin()];
        let (route, loop_start_x) = plan_route(leg1, leg2, bend);
        Plan {
            leg1,
            leg2,
            bend,
            corner,
            void_frame: Frame2 {
                origin: end,
                yaw: bend,
            },
            void_height,
            loop_start_x,
            route,
        }
    }
}

/// The route for a ditch with legs `leg1`, `leg2` and a `bend` between them: along the legs
/// with an arc at the bend, into the void, one full loop to the left that comes back to where
/// it began, then straight on. Returns the route and where the loop starts on the void's axis.
fn plan_route(leg1: f64, leg2: f64, bend: f64) -> (Route, f64) {
    let r = TURN_RADIUS_M;
    let tangent = r * (0.5 * bend.abs()).tan();
    let line1 = MOUTH_X_M + leg1 - tangent;
    let bend_arc = Segment::Arc {
        radius: r,
        angle: bend,
    };
    let exit = line1 + bend_arc.length() + (leg2 - tangent);
    let spacing = TAU * r / LOOP_STEPS as f64;
    // The loop starts on a stop, so that the stop LOOP_STEPS later is at the same place.
    let loop_stop = ((exit + MIN_STEM_M) / spacing).ceil() as usize;
    let loop_start = loop_stop as f64 * spacing;
    let loop_start_x = loop_start - exit;
    let loop_end = loop_start + TAU * r;
    // Room for MAX_STOPS stops (and their jitter) in all.
    let tail = ((MAX_STOPS - 1) as f64 * spacing + 0.2 - loop_end).max(0.2);
    let route = Route {
        segments: vec![
            Segment::Line(line1),
            bend_arc,
            Segment::Line(leg2 - tangent + loop_start_x),
            Segment::Arc {
                radius: r,
                angle: TAU,
            },
            Segment::Line(tail),
        ],
        spacing_m: spacing,
        low_lift: (MOUTH_X_M, exit),
        anchors: [loop_stop, loop_stop + LOOP_STEPS],
    };
    (route, loop_start_x)
}

/// One straight piece of the ditch: a free box along a leg.
#[derive(Debug, Clone, Copy)]
struct DitchPiece {
    /// The leg's start and heading.
    leg: Frame2,
    /// Start of the piece along the leg, metres.
    from: f64,
    /// End of the piece along the leg, metres.
    to: f64,
    /// Half the ditch's width here, metres.
    half_width: f64,
    /// Height of the floor, metres.
    floor: f64,
    /// Height of the ceiling, metres.
    ceiling: f64,
}

impl DitchPiece {
    fn air(&self) -> OrientedBox {
        let [x, y] = self.leg.point(0.5 * (self.from + self.to), 0.0);
        OrientedBox::build(
            Vec3::new(x, y, 0.5 * (self.floor + self.ceiling)),
            Vec3::new(
                0.5 * (self.to - self.from),
                self.half_width,
                0.5 * (self.ceiling - self.floor),
            ),
            yaw_rotation(self.leg.yaw),
        )
    }
}

/// A point of the kept-clear tube: on the route, with the floor and the tube's height there.
#[derive(Debug, Clone, Copy)]
struct TubeSample {
    x: f64,
    y: f64,
    floor: f64,
    top: f64,
    radius: f64,
}

/// Builds the collapsed building: air first, then the tube around the route, then obstacles,
/// each kept only if it leaves the tube clear.
struct Builder {
    scene: Scene,
    tube: Vec<TubeSample>,
    rng: ChaCha8Rng,
}

impl Builder {
    /// Samples the route every 10 cm (from 0.6 m behind the start, where the robot's body is)
    /// with the floor of the air built so far.
    fn freeze_tube(&mut self, route: &Route) {
        let end = route.length() + 0.3;
        let mut s = -0.6;
        while s <= end {
            let ([x, y], _) = route.at(s);
            if let Some(floor) = self.scene.floor_height(x, y) {
                let (top, radius) = if route.lift_is_low(s) {
                    (TUBE_TOP_LOW_M, TUBE_RADIUS_DITCH_M)
                } else {
                    (TUBE_TOP_HIGH_M, TUBE_RADIUS_M)
                };
                self.tube.push(TubeSample {
                    x,
                    y,
                    floor,
                    top,
                    radius,
                });
            }
            s += 0.1;
        }
    }

    /// True when `solid` keeps the tube's radius from it, or is low rubble the robot
    /// drives over.
    fn clear_of_tube(&self, solid: &Solid) -> bool {
        let c = solid.center();
        let reach = solid.bounding_radius() + TUBE_RADIUS_M.max(TUBE_RADIUS_DITCH_M);
        let (_, z_top) = solid.z_range();
        self.tube.iter().all(|t| {
            if (c.x - t.x).hypot(c.y - t.y) > reach || z_top <= t.floor + LOW_RUBBLE_TOP_M {
                return true;
            }
            let mut z = t.floor + LOW_RUBBLE_TOP_M + 0.005;
            while z <= t.floor + t.top + 1e-9 {
                let radius = if z < t.floor + TRACK_ZONE_TOP_M {
                    TUBE_RADIUS_M
                } else {
                    t.radius
                };
                if solid.distance_lower_bound(&Vec3::new(t.x, t.y, z)) < radius {
                    return false;
                }
                z += 0.05;
            }
            true
        })
    }

    /// Draws up to `tries` candidates and adds the first that leaves the tube clear.
    fn place(&mut self, tries: usize, mut make: impl FnMut(&mut ChaCha8Rng) -> Solid) -> bool {
        for _ in 0..tries {
            let solid = make(&mut self.rng);
            if self.clear_of_tube(&solid) {
                self.scene.add_solid(solid);
                return true;
            }
        }
        false
    }

    /// Like [`Self::place`], but first sets each candidate down on the floor or rubble under
    /// its centre, a fifth of its height sunk into it.
    fn place_resting(
        &mut self,
        tries: usize,
        mut make: impl FnMut(&mut ChaCha8Rng) -> Solid,
    ) -> bool {
        for _ in 0..tries {
            let mut solid = make(&mut self.rng);
            let c = *solid.center();
            if let Some(base) = self.scene.floor_height(c.x, c.y) {
                solid.rest_on(base);
            }
            if self.clear_of_tube(&solid) {
                self.scene.add_solid(solid);
                return true;
            }
        }
        false
    }

    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.rng.random_range(lo..hi)
    }

    fn count(&mut self, lo: usize, hi: usize) -> usize {
        self.rng.random_range(lo..=hi)
    }

    /// Splits a leg's range `[from, to]` into pieces of air of random width, floor and ceiling.
    fn add_ditch_leg(&mut self, leg: Frame2, from: f64, to: f64, floor: f64) -> Vec<DitchPiece> {
        let mut pieces = Vec::new();
        let mut a = from;
        while a < to - 1e-9 {
            let mut len = self.uniform(0.45, 0.9);
            if to - (a + len) < 0.3 {
                len = to - a;
            }
            let piece_floor = floor + self.uniform(-0.01, 0.01);
            let piece = DitchPiece {
                leg,
                from: a,
                to: a + len,
                half_width: self.uniform(0.3, DITCH_MAX_HALF_WIDTH_M),
                floor: piece_floor,
                ceiling: piece_floor + self.uniform(0.6, 0.9),
            };
            self.scene.add_free(piece.air());
            pieces.push(piece);
            a += len;
        }
        pieces
    }

    fn add_void_air(&mut self, plan: &Plan, floor: f64) {
        let v = plan.void_frame;
        let h = plan.void_height;
        let main = v.point(0.5 * VOID_LENGTH_M, 0.5 * (VOID_LEFT_M - VOID_RIGHT_M));
        self.scene.add_free(OrientedBox::build(
            Vec3::new(main[0], main[1], floor + 0.5 * h),
            Vec3::new(
                0.5 * VOID_LENGTH_M,
                0.5 * (VOID_LEFT_M + VOID_RIGHT_M),
                0.5 * h,
            ),
            yaw_rotation(v.yaw),
        ));
        // Irregular walls: an alcove at the far end and one on the right, turned a little.
        let far_half = [self.uniform(0.5, 0.8), self.uniform(0.8, 1.4)];
        let far = v.point(
            VOID_LENGTH_M - 0.2 + far_half[0] * 0.8,
            self.uniform(-0.5, 1.5),
        );
        let far_h = h * self.uniform(0.7, 1.2);
        let far_yaw = v.yaw + self.uniform(-25f64, 25.0).to_radians();
        self.scene.add_free(OrientedBox::build(
            Vec3::new(far[0], far[1], floor + 0.5 * far_h),
            Vec3::new(far_half[0], far_half[1], 0.5 * far_h),
            yaw_rotation(far_yaw),
        ));
        let side_half = [self.uniform(0.5, 0.9), self.uniform(0.4, 0.7)];
        let side = v.point(
            self.uniform(1.6, 3.5),
            -VOID_RIGHT_M - self.uniform(0.2, 0.4),
        );
        let side_h = h * self.uniform(0.6, 1.0);
        let side_yaw = v.yaw + self.uniform(-20f64, 20.0).to_radians();
        self.scene.add_free(OrientedBox::build(
            Vec3::new(side[0], side[1], floor + 0.5 * side_h),
            Vec3::new(side_half[0], side_half[1], 0.5 * side_h),
            yaw_rotation(side_yaw),
        ));
    }

    fn add_room_obstacles(&mut self, floor: f64) {
        // A pillar, floor to ceiling.
        self.place(20, |rng| {
            let side = random_sign(rng);
            let c = [
                rng.random_range(-2.0..0.6),
                side * rng.random_range(0.8..1.4),
            ];
            Solid::Box(yawed_box([c[0], c[1], floor + 1.1], [0.15, 0.15, 1.1], 0.0))
        });
        // A cabinet against the front wall.
        self.place(20, |rng| {
            let side = random_sign(rng);
            let half = [0.2, rng.random_range(0.3..0.45), rng.random_range(0.5..0.8)];
            let y = side * rng.random_range(0.9..1.3);
            Solid::Box(yawed_box(
                [MOUTH_X_M - half[0], y, floor + half[2]],
                half,
                0.0,
            ))
        });
        // Boxes on the floor.
        let n = self.count(2, 4);
        for _ in 0..n {
            self.place(20, |rng| {
                let half = [
                    rng.random_range(0.12..0.35),
                    rng.random_range(0.12..0.35),
                    rng.random_range(0.1..0.35),
                ];
                let c = [rng.random_range(-2.2..0.8), rng.random_range(-1.5..1.5)];
                let yaw = rng.random_range(-90.0..90.0);
                Solid::Box(yawed_box([c[0], c[1], floor + half[2]], half, yaw))
            });
        }
    }

    fn add_ditch_obstacles(&mut self, pieces: &[DitchPiece]) {
        let n = pieces.len();
        for (k, p) in pieces.iter().enumerate() {
            for _ in 0..self.count(1, 3) {
                self.place(4, |rng| {
                    let lateral = rng.random_range(-p.half_width..p.half_width);
                    let [x, y] = p.leg.point(rng.random_range(p.from..p.to), lateral);
                    low_rubble(rng, x, y, p.floor)
                });
            }
            for _ in 0..self.count(0, 2) {
                self.place(6, |rng| wall_rubble(rng, p));
            }
            for _ in 0..self.count(2, 4) {
                self.place(6, |rng| wall_chunk(rng, p));
            }
            // Not at the ditch's ends, where the lift is high.
            if k > 0 && k + 1 < n {
                for _ in 0..self.count(1, 3) {
                    self.place(8, |rng| hanging_debris(rng, p));
                }
            }
        }
        if n >= 3 {
            for _ in 0..self.count(1, 2) {
                let p = pieces[self.rng.random_range(1..n - 1)];
                self.place(12, |rng| leaning_across(rng, &p));
            }
        }
    }

    fn add_void_obstacles(&mut self, plan: &Plan, floor: f64) {
        let v = plan.void_frame;
        let h = plan.void_height;
        let in_void = |rng: &mut ChaCha8Rng| {
            v.point(
                rng.random_range(0.3..VOID_LENGTH_M - 0.2),
                rng.random_range(-VOID_RIGHT_M + 0.2..VOID_LEFT_M - 0.2),
            )
        };
        // The pile the loop goes round, and two more piles.
        let centre = v.point(plan.loop_start_x, TURN_RADIUS_M);
        self.add_pile(centre, floor, 0.45, 5, 8);
        for _ in 0..self.count(2, 3) {
            let c = in_void(&mut self.rng);
            self.add_pile(c, floor, 0.5, 3, 6);
        }
        // Pillars still standing, a little askew, some broken off.
        for _ in 0..self.count(1, 2) {
            self.place_resting(20, |rng| {
                let [x, y] = in_void(rng);
                let half = Vec3::new(
                    rng.random_range(0.12..0.2),
                    rng.random_range(0.12..0.2),
                    0.5 * h * rng.random_range(0.4..1.2),
                );
                let tilt = 5f64.to_radians();
                let rotation = Rotation3::from_euler_angles(
                    rng.random_range(-tilt..tilt),
                    rng.random_range(-tilt..tilt),
                    rng.random_range(-PI..PI),
                );
                Solid::Box(OrientedBox::build(Vec3::new(x, y, floor), half, rotation))
            });
        }
        // A fallen column, one end propped up.
        self.place(40, |rng| {
            let [x, y] = in_void(rng);
            let half = Vec3::new(rng.random_range(0.8..1.1), 0.15, 0.15);
            let pitch = rng.random_range(-7f64..7.0).to_radians();
            let yaw = rng.random_range(-PI..PI);
            let z = floor + 0.15 * pitch.cos() + half.x * pitch.sin().abs() - 0.01;
            let rotation = Rotation3::from_euler_angles(0.0, pitch, yaw);
            Solid::Box(OrientedBox::build(Vec3::new(x, y, z), half, rotation))
        });
        // Slabs leaning against the walls.
        let leaning = self.count(1, 2);
        for _ in 0..leaning {
            self.place(20, |rng| leaning_slab(rng, &v, floor));
        }
        // Tilted pieces of the ceiling.
        let ceiling_pieces = self.count(2, 3);
        for _ in 0..ceiling_pieces {
            self.place(20, |rng| {
                let [x, y] = in_void(rng);
                let half = Vec3::new(rng.random_range(0.4..0.8), rng.random_range(0.3..0.6), 0.05);
                let rotation = Rotation3::from_euler_angles(
                    rng.random_range(-25f64..25.0).to_radians(),
                    rng.random_range(-25f64..25.0).to_radians(),
                    rng.random_range(-PI..PI),
                );
                let z = floor + h - rng.random_range(0.1..0.35);
                Solid::Box(OrientedBox::build(Vec3::new(x, y, z), half, rotation))
            });
        }
        // Small rubble scattered on the floor.
        let scattered = self.count(8, 12);
        for _ in 0..scattered {
            self.place(4, |rng| {
                let [x, y] = in_void(rng);
                low_rubble(rng, x, y, floor)
            });
        }
    }

    /// A pile of `lo..=hi` blocks and rocks within `radius` of `centre`, each resting on the
    /// floor or on the rubble already there.
    fn add_pile(&mut self, centre: [f64; 2], floor: f64, radius: f64, lo: usize, hi: usize) {
        for i in 0..self.count(lo, hi) {
            self.place_resting(8, |rng| {
                let r = radius * rng.random::<f64>().sqrt();
                let a = rng.random_range(-PI..PI);
                let (x, y) = (centre[0] + r * a.cos(), centre[1] + r * a.sin());
                if i % 3 == 2 {
                    let radii = Vec3::new(
                        rng.random_range(0.1..0.28),
                        rng.random_range(0.1..0.28),
                        rng.random_range(0.08..0.22),
                    );
                    let rotation = random_rotation(rng);
                    Solid::Ellipsoid(Ellipsoid::build(Vec3::new(x, y, floor), radii, rotation))
                } else {
                    rubble_piece(rng, x, y, floor, 0.08, 0.25)
                }
            });
        }
    }
}

fn random_sign(rng: &mut ChaCha8Rng) -> f64 {
    if rng.random_bool(0.5) {
        1.0
    } else {
        -1.0
    }
}

/// A block of rubble against one of the ditch piece's walls, on the floor.
fn wall_rubble(rng: &mut ChaCha8Rng, p: &DitchPiece) -> Solid {
    let lateral = random_sign(rng) * (p.half_width - rng.random_range(0.0..0.05));
    let [x, y] = p.leg.point(rng.random_range(p.from..p.to), lateral);
    rubble_piece(rng, x, y, p.floor, 0.05, 0.12)
}

/// Broken concrete sticking 3–15 cm out of one of the ditch piece's walls, at any height.
fn wall_chunk(rng: &mut ChaCha8Rng, p: &DitchPiece) -> Solid {
    let half = Vec3::new(
        rng.random_range(0.05..0.15),
        rng.random_range(0.1..0.2),
        rng.random_range(0.05..0.2),
    );
    let lateral = random_sign(rng) * (p.half_width + half.y - rng.random_range(0.03..0.15));
    let [x, y] = p.leg.point(rng.random_range(p.from..p.to), lateral);
    let z = rng.random_range(p.floor..p.ceiling);
    let tilt = 20f64.to_radians();
    let rotation = Rotation3::from_euler_angles(
        rng.random_range(-tilt..tilt),
        rng.random_range(-tilt..tilt),
        p.leg.yaw + rng.random_range(-tilt..tilt),
    );
    Solid::Box(OrientedBox::build(Vec3::new(x, y, z), half, rotation))
}

/// A block hanging from the ditch piece's ceiling, partly in it.
fn hanging_debris(rng: &mut ChaCha8Rng, p: &DitchPiece) -> Solid {
    let lateral = rng.random_range(-p.half_width..p.half_width);
    let [x, y] = p.leg.point(rng.random_range(p.from..p.to), lateral);
    let half = Vec3::new(
        rng.random_range(0.06..0.18),
        rng.random_range(0.06..0.18),
        rng.random_range(0.06..0.18),
    );
    let z = p.ceiling - rng.random_range(-0.05..0.1);
    Solid::Box(OrientedBox::build(
        Vec3::new(x, y, z),
        half,
        random_rotation(rng),
    ))
}

/// A slab leaning across the ditch under its ceiling: rolled 10–28° about the ditch's axis,
/// its ends in the walls.
fn leaning_across(rng: &mut ChaCha8Rng, p: &DitchPiece) -> Solid {
    let [x, y] = p.leg.point(rng.random_range(p.from + 0.1..p.to - 0.1), 0.0);
    let roll = random_sign(rng) * rng.random_range(10f64..28.0).to_radians();
    let pitch = rng.random_range(-8f64..8.0).to_radians();
    let half = Vec3::new(rng.random_range(0.15..0.3), p.half_width + 0.12, 0.025);
    let z = p.ceiling - rng.random_range(0.0..0.12);
    let rotation = Rotation3::from_euler_angles(roll, pitch, p.leg.yaw);
    Solid::Box(OrientedBox::build(Vec3::new(x, y, z), half, rotation))
}

/// A full random rotation (rubble lies any way up).
fn random_rotation(rng: &mut ChaCha8Rng) -> Rotation3<f64> {
    Rotation3::from_euler_angles(
        rng.random_range(-PI..PI),
        rng.random_range(-0.5 * PI..0.5 * PI),
        rng.random_range(-PI..PI),
    )
}

/// A flat piece of rubble whose top lies 1–2.8 cm above `floor` at (x, y): the robot drives
/// over it.
fn low_rubble(rng: &mut ChaCha8Rng, x: f64, y: f64, floor: f64) -> Solid {
    let half = Vec3::new(
        rng.random_range(0.03..0.1),
        rng.random_range(0.03..0.1),
        rng.random_range(0.008..0.015),
    );
    let rotation = Rotation3::from_euler_angles(
        rng.random_range(-5f64..5.0).to_radians(),
        rng.random_range(-5f64..5.0).to_radians(),
        rng.random_range(-PI..PI),
    );
    let mut b = OrientedBox::build(Vec3::new(x, y, floor), half, rotation);
    b.center.z = floor + rng.random_range(0.01..0.028) - b.half_height();
    Solid::Box(b)
}

/// A block of rubble of half size `lo..hi` resting with its centre a little above `base`.
fn rubble_piece(rng: &mut ChaCha8Rng, x: f64, y: f64, base: f64, lo: f64, hi: f64) -> Solid {
    let half = Vec3::new(
        rng.random_range(lo..hi),
        rng.random_range(lo..hi),
        rng.random_range(lo..hi),
    );
    let mut b = OrientedBox::build(Vec3::new(x, y, base), half, random_rotation(rng));
    b.center.z = base + 0.6 * b.half_height();
    Solid::Box(b)
}

/// A slab leaning against one of the void's walls (the right, left or far one).
fn leaning_slab(rng: &mut ChaCha8Rng, v: &Frame2, floor: f64) -> Solid {
    // Wall: a point on it and its inward normal, both in the void's frame.
    let (wall_point, inward) = match rng.random_range(0..3) {
        0 => ([rng.random_range(0.8..4.5), -VOID_RIGHT_M], [0.0, 1.0]),
        1 => ([rng.random_range(0.8..4.5), VOID_LEFT_M], [0.0, -1.0]),
        _ => ([VOID_LENGTH_M, rng.random_range(-1.0..2.4)], [-1.0, 0.0]),
    };
    let length = rng.random_range(0.8..1.5);
    let width = rng.random_range(0.5..1.0);
    let angle = rng.random_range(50f64..75.0).to_radians();
    let foot = length * angle.cos();
    // Centre: halfway up the slab, which rises from its foot toward the wall.
    let run = foot - 0.5 * length * angle.cos();
    let c = v.point(
        wall_point[0] + inward[0] * run,
        wall_point[1] + inward[1] * run,
    );
    let toward_wall = v.yaw + (-inward[1]).atan2(-inward[0]);
    let rotation = Rotation3::from_euler_angles(0.0, -angle, toward_wall);
    let z = floor + 0.5 * length * angle.sin();
    Solid::Box(OrientedBox::build(
        Vec3::new(c[0], c[1], z),
        Vec3::new(0.5 * length, 0.5 * width, 0.04),
        rotation,
    ))
}

/// A seeded collapsed building: a room, a narrow ditch and a wider void (Nagatani 2003's
/// motivating scenario), with a drivable route for [`collapsed_building_stops`].
///
/// World frame: the first stop's sensor origin is the world origin, heading +x, and the room's
/// floor is flat at `z = −COLLAPSED_BUILDING_START_HEIGHT_M` (0.4 m) around it.
///
/// - **Room**: 3.5 m × 3.5 m × 2.2 m, x ∈ [−2.5, 1.0], y ∈ [−1.75, 1.75], with a pillar, a
///   cabinet against the front wall and boxes on the floor (none on the route).
/// - **Ditch**: from the room's front wall at x = 1.0, 3.0–3.5 m long, bending once by 15–35°
///   left or right; made of pieces 0.45–0.9 m long, each 0.6–0.9 m wide with its own floor
///   (±1 cm) and ceiling 0.6–0.9 m above it; hanging debris, one or two slabs leaning across
///   under the ceiling, rubble at the walls and flat rubble (≤ 2.8 cm) on the floor.
/// - **Void**: 5 m along the ditch's direction × 4.4 m, 1.5–2.5 m high, with two alcoves, three
///   or four rubble piles (blocks and rocks; the route loops round one), one or two pillars
///   askew, a fallen column, slabs leaning on the walls, tilted pieces of the ceiling and
///   scattered flat rubble.
///
/// Obstacles are drawn and kept only if they leave a tube of 0.27 m around the route clear
/// (flat rubble excepted), so the route stays drivable and the sensor clear of every surface.
/// The same seed gives the same scene on every machine.
pub fn collapsed_building(seed: u64) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let plan = Plan::draw(&mut rng);
    let floor = -COLLAPSED_BUILDING_START_HEIGHT_M;
    let mut b = Builder {
        scene: Scene::new(),
        tube: Vec::new(),
        rng,
    };
    b.scene
        .add_free(aabb([-2.5, -1.75, floor], [MOUTH_X_M, 1.75, floor + 2.2]));
    // The two legs overlap past the bend so that their union has no gap at the outer corner.
    let overlap = DITCH_MAX_HALF_WIDTH_M * (0.5 * plan.bend.abs()).tan() + 0.02;
    let leg1 = Frame2 {
        origin: [MOUTH_X_M, 0.0],
        yaw: 0.0,
    };
    let leg2 = Frame2 {
        origin: plan.corner,
        yaw: plan.bend,
    };
    let mut pieces = b.add_ditch_leg(leg1, 0.0, plan.leg1 + overlap, floor);
    pieces.extend(b.add_ditch_leg(leg2, -overlap, plan.leg2, floor));
    b.add_void_air(&plan, floor);
    b.freeze_tube(&plan.route);
    b.add_room_obstacles(floor);
    b.add_ditch_obstacles(&pieces);
    b.add_void_obstacles(&plan, floor);
    let mut scene = b.scene;
    scene.route = Some(plan.route);
    scene
}

// ---------------------------------------------------------------------------------------------
// Stops
// ---------------------------------------------------------------------------------------------

/// One stop of a stop-and-go run: where the robot's body stands and the lift's setting.
///
/// The body frame's origin is on the floor under the robot's centre, x forward, z up; the
/// sensor is at `world_from_body * lift.body_from_sensor(lift_slide_m)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stop {
    /// The body's pose.
    pub world_from_body: Pose,
    /// The lift's slide `u` at this stop, metres.
    pub lift_slide_m: f64,
}

impl Stop {
    /// The sensor's pose at this stop for the lift `lift`.
    ///
    /// # Errors
    /// [`Error::Invalid`] when the slide is outside the lift's range.
    pub fn world_from_sensor(&self, lift: &LiftConfig) -> Result<Pose> {
        Ok(self.world_from_body * lift.body_from_sensor(self.lift_slide_m)?)
    }
}

/// Half the distance between the crawler's front and rear contact points, metres.
const TRACK_HALF_LENGTH_M: f64 = 0.25;
/// Half the distance between its left and right tracks, metres.
const TRACK_HALF_GAUGE_M: f64 = 0.18;
/// Largest roll and pitch of the body, degrees.
const MAX_TILT_DEG: f64 = 4.0;
/// Standard deviation of the random part of roll and pitch, degrees.
const TILT_JITTER_DEG: f64 = 0.5;
/// Sample directions for the clearance check of each stop.
const CLEARANCE_DIRECTIONS: usize = 200;

/// Roll, pitch and height of a crawler standing at `body_xy` heading `yaw`: the plane through the
/// floor under its four contact points.
fn stance(scene: &Scene, body_xy: [f64; 2], yaw: f64) -> Result<(f64, f64, f64)> {
    let body = Frame2 {
        origin: body_xy,
        yaw,
    };
    let floor = |dx: f64, dy: f64| -> Result<f64> {
        let [x, y] = body.point(dx, dy);
        scene.floor_height(x, y).ok_or_else(|| {
            Error::Invalid(format!(
                "collapsed_building_stops: no floor under the robot at ({x:.2}, {y:.2})"
            ))
        })
    };
    let (l, g) = (TRACK_HALF_LENGTH_M, TRACK_HALF_GAUGE_M);
    let front_left = floor(l, g)?;
    let front_right = floor(l, -g)?;
    let rear_left = floor(-l, g)?;
    let rear_right = floor(-l, -g)?;
    let front_rise = 0.5 * (front_left + front_right - rear_left - rear_right);
    let left_rise = 0.5 * (front_left + rear_left - front_right - rear_right);
    // Positive pitch points x down; positive roll raises the left (+y) side.
    let pitch = -front_rise.atan2(2.0 * l);
    let roll = left_rise.atan2(2.0 * g);
    let z = 0.25 * (front_left + front_right + rear_left + rear_right);
    Ok((roll, pitch, z))
}

/// The slides for the high (room, void) and low (ditch) sensor.
fn lift_settings(lift: &LiftConfig) -> Result<(f64, f64)> {
    lift.validate()?;
    let height = COLLAPSED_BUILDING_START_HEIGHT_M - lift.mount_in_body_m[2];
    let high = lift.slide_for_height(height).map_err(|e| {
        Error::Invalid(format!(
            "collapsed_building_stops: the lift cannot hold the sensor {COLLAPSED_BUILDING_START_HEIGHT_M} m \
             above the floor at the first stop ({e})"
        ))
    })?;
    let low = (lift.slide_max_m - 0.05 * (lift.slide_max_m - lift.slide_min_m)).max(high);
    Ok((high, low))
}

/// A stop-and-go path through [`collapsed_building`]`(…)`: from the room through the ditch into
/// the void, round a rubble pile and back to where the loop began.
///
/// # Arguments
/// - `scene`: a scene from [`collapsed_building`] (it carries the route).
/// - `seed`: seeds the stops' jitter along the route and the random part of their tilt.
/// - `count`: number of stops, 1 ..= [`MAX_STOPS`].
/// - `lift`: the lift; pass the same one to [`simulate_run`] (through its sensor).
///
/// # Returns
/// The stops, in order. Stop 0's sensor pose is exactly the identity (the world origin), with
/// the lift set so that the sensor stands 0.4 m above the flat room floor. Consecutive sensor
/// origins are 2πR/20 ≈ 0.35 m (± 3 cm) apart along the route, which turns with a radius
/// R = 1.1 m (≤ 19.6° of heading per stop). The lift is low (slide 5 % short of `slide_max_m`)
/// while the sensor is in the ditch and high (sensor 0.4 m up, near `slide_min_m`) in the room
/// and the void: it changes at two stops. The body stands on the floor under its four track
/// contacts (roll and pitch from their plane plus N(0, 0.5°), within ±4°). Stops 0–2 are in the
/// room, about 3–12 in the ditch, the rest in the void. The loop in the void starts at a stop
/// `i` (17 or 18, depending on the scene) and the stop `j = i + 20` is at the same place and
/// heading ([`Scene::loop_closure_stops`] gives both), so runs of `count` > `j` (38 or 39
/// stops) close the loop; a full turn at ≤ 20° per stop takes at least 18 stops, which is why
/// shorter runs cannot. Every sensor origin is checked to be free and at least
/// [`MIN_SENSOR_CLEARANCE_M`] from every surface.
///
/// # Errors
/// [`Error::Invalid`] when `count` is 0 or above [`MAX_STOPS`], when `scene` has no route (it
/// was not built by [`collapsed_building`]), when the lift cannot reach the start height, or
/// when a stop's sensor would come too close to a surface (a lift that does not fit the scene).
pub fn collapsed_building_stops(
    scene: &Scene,
    seed: u64,
    count: usize,
    lift: &LiftConfig,
) -> Result<Vec<Stop>> {
    if count == 0 || count > MAX_STOPS {
        return Err(Error::Invalid(format!(
            "collapsed_building_stops: count is {count}; the route holds 1 to {MAX_STOPS} stops"
        )));
    }
    let route = scene.route.as_ref().ok_or_else(|| {
        Error::Invalid(
            "collapsed_building_stops: the scene has no route; build it with sim::collapsed_building"
                .into(),
        )
    })?;
    let (high, low) = lift_settings(lift)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut stops = Vec::with_capacity(count);
    for index in 0..count {
        // Always three draws per stop, so the stream does not depend on the branches below.
        let jitter = rng.random_range(-STEP_JITTER_M..STEP_JITTER_M);
        let roll_noise: f64 = rng.sample(StandardNormal);
        let pitch_noise: f64 = rng.sample(StandardNormal);
        let exact = index == 0 || route.anchors.contains(&index);
        let s = index as f64 * route.spacing_m + if exact { 0.0 } else { jitter };
        let slide = if route.lift_is_low(s) { low } else { high };
        let stop = if index == 0 {
            first_stop(lift, slide)?
        } else {
            let noise = TILT_JITTER_DEG.to_radians();
            place_stop(
                scene,
                lift,
                route.at(s),
                slide,
                (roll_noise * noise, pitch_noise * noise),
            )?
        };
        check_clearance(scene, lift, &stop, index)?;
        stops.push(stop);
    }
    Ok(stops)
}

/// Stop 0: the sensor at the world origin, level, heading +x; the body on the flat floor below.
fn first_stop(lift: &LiftConfig, slide: f64) -> Result<Stop> {
    Ok(Stop {
        world_from_body: lift.body_from_sensor(slide)?.inverse(),
        lift_slide_m: slide,
    })
}

/// A stop whose sensor origin is above `sensor_xy` heading `yaw`, the body standing on the floor.
fn place_stop(
    scene: &Scene,
    lift: &LiftConfig,
    (sensor_xy, yaw): ([f64; 2], f64),
    slide: f64,
    (roll_noise, pitch_noise): (f64, f64),
) -> Result<Stop> {
    let sensor_in_body = lift.body_from_sensor(slide)?.translation.vector;
    let level_offset = yaw_rotation(yaw) * sensor_in_body;
    let guess = [sensor_xy[0] - level_offset.x, sensor_xy[1] - level_offset.y];
    let (roll, pitch, _) = stance(scene, guess, yaw)?;
    let max_tilt = MAX_TILT_DEG.to_radians();
    let attitude = Attitude::new(
        (roll + roll_noise).clamp(-max_tilt, max_tilt),
        (pitch + pitch_noise).clamp(-max_tilt, max_tilt),
        yaw,
    );
    // Put the body where the tilted sensor lands exactly above `sensor_xy`.
    let offset = attitude.rotation() * sensor_in_body;
    let body_xy = [sensor_xy[0] - offset.x, sensor_xy[1] - offset.y];
    let (_, _, z) = stance(scene, body_xy, yaw)?;
    Ok(Stop {
        world_from_body: pose_from_parts(Vec3::new(body_xy[0], body_xy[1], z), attitude),
        lift_slide_m: slide,
    })
}

fn check_clearance(scene: &Scene, lift: &LiftConfig, stop: &Stop, index: usize) -> Result<()> {
    let sensor = stop.world_from_sensor(lift)?.translation.vector;
    let clearance = scene.clearance(&sensor, CLEARANCE_DIRECTIONS);
    if clearance < MIN_SENSOR_CLEARANCE_M {
        return Err(Error::Invalid(format!(
            "collapsed_building_stops: stop {index}'s sensor at ({:.2}, {:.2}, {:.2}) is only \
             {clearance:.3} m from a surface (need {MIN_SENSOR_CLEARANCE_M} m); this lift does not \
             fit the scene's route",
            sensor.x, sensor.y, sensor.z
        )));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Sensing
// ---------------------------------------------------------------------------------------------

/// One simulated stop: the true sensor pose, the lift's slide and the raw sweep taken there.
#[derive(Debug, Clone, PartialEq)]
pub struct SimStop {
    /// True `world_from_sensor`.
    pub world_from_sensor: Pose,
    /// The lift's slide `u`, metres.
    pub lift_slide_m: f64,
    /// The sweep as the hardware reports it.
    pub sweep: Sweep,
}

/// The gyro/compass reading: the true attitude plus one error drawn for the whole sweep
/// (roll and pitch ~ N(0, `tilt_sensor_noise_deg`), yaw ~ N(0, `compass_noise_deg`)).
fn attitude_reading(
    world_from_sensor: &Pose,
    sensor: &SensorConfig,
    rng: &mut impl Rng,
) -> Attitude {
    let truth = attitude_of(world_from_sensor);
    let tilt = sensor.tilt_sensor_noise_deg.to_radians();
    let compass = sensor.compass_noise_deg.to_radians();
    let e_roll: f64 = rng.sample(StandardNormal);
    let e_pitch: f64 = rng.sample(StandardNormal);
    let e_yaw: f64 = rng.sample(StandardNormal);
    Attitude::new(
        truth.roll + tilt * e_roll,
        truth.pitch + tilt * e_pitch,
        wrap_angle(truth.yaw + compass * e_yaw),
    )
}

/// A measured range from a true hit: noise added, then dropped (NaN) when below
/// `min_range_m` or beyond the usable range.
fn measured(hit: Option<f64>, noise: f64, sensor: &SensorConfig) -> f32 {
    match hit {
        Some(r) => {
            let noisy = r + noise;
            if noisy < sensor.min_range_m || noisy > sensor.usable_range_m() {
                f32::NAN
            } else {
                noisy as f32
            }
        }
        None => f32::NAN,
    }
}

/// Simulates one raw sweep of the tilting LRF at `world_from_sensor` (paper Sec. IV).
///
/// For each tilt line of `sensor.tilt_angles_deg()` and each pan beam
/// `pan_min_deg + k · pan_step_deg` (k < `pan_count()`), the beam
/// `world_from_sensor.rotation · beam_direction(tilt, pan)` is cast from the sensor origin; its
/// range gets N(0, `range_noise_m`) noise and is NaN when nothing is hit within `max_range_m`,
/// or the noisy range is below `min_range_m` or beyond `trusted_range_m` (when set). Every line
/// carries the same gyro/compass reading (the robot stands still): the true attitude plus one
/// error per sweep. `lift_slide_m` is only recorded in the sweep: `world_from_sensor` already
/// includes the lift.
///
/// Draws from `rng`: the three attitude errors, then one seed per line; each line's range noise
/// comes from its own `ChaCha8Rng`, so the lines run in parallel and the result does not depend
/// on the number of threads.
///
/// An invalid `sensor` (see [`SensorConfig::validate`]) gives a sweep with no lines;
/// [`simulate_run`] reports it as an error instead.
pub fn scan(
    scene: &Scene,
    sensor: &SensorConfig,
    world_from_sensor: &Pose,
    lift_slide_m: f64,
    rng: &mut impl Rng,
) -> Sweep {
    let mut sweep = Sweep {
        pan_min_deg: sensor.pan_min_deg,
        pan_step_deg: sensor.pan_step_deg,
        lift_slide_m,
        lines: Vec::new(),
    };
    if sensor.validate().is_err() {
        return sweep;
    }
    let reading = attitude_reading(world_from_sensor, sensor, rng);
    let tilts = sensor.tilt_angles_deg();
    let seeds: Vec<u64> = tilts.iter().map(|_| rng.random()).collect();
    let pans: Vec<f64> = (0..sensor.pan_count())
        .map(|k| (sensor.pan_min_deg + k as f64 * sensor.pan_step_deg).to_radians())
        .collect();
    let origin = world_from_sensor.translation.vector;
    sweep.lines = tilts
        .par_iter()
        .zip(seeds.par_iter())
        .map(|(&tilt_deg, &seed)| {
            let mut line_rng = ChaCha8Rng::seed_from_u64(seed);
            let tilt = tilt_deg.to_radians();
            let ranges = pans
                .iter()
                .map(|&pan| {
                    let direction = world_from_sensor.rotation * beam_direction(tilt, pan);
                    let noise: f64 = line_rng.sample(StandardNormal);
                    let hit = scene.raycast(&origin, &direction, sensor.max_range_m);
                    measured(hit, noise * sensor.range_noise_m, sensor)
                })
                .collect();
            SweepLine {
                tilt_deg,
                attitude: reading,
                ranges,
            }
        })
        .collect();
    sweep
}

/// Simulates a whole run: at each stop the sensor pose
/// `world_from_body · sensor.lift.body_from_sensor(slide)` and its sweep ([`scan`]).
///
/// Stop `i` draws its noise from `ChaCha8Rng::seed_from_u64(seed)` on stream `i`, so the result
/// depends only on the seed, not on the thread count or on the other stops.
///
/// # Errors
/// [`Error::Invalid`] when `sensor` is invalid or a stop's slide is outside the lift's range.
pub fn simulate_run(
    scene: &Scene,
    stops: &[Stop],
    sensor: &SensorConfig,
    seed: u64,
) -> Result<Vec<SimStop>> {
    simulate_changing_run(stops, sensor, seed, |_| Cow::Borrowed(scene))
}

/// [`simulate_run`] in a scene that changes between stops (rubble moved, say): stop `i` is
/// scanned in `scene_at(i)`, with the same noise streams as [`simulate_run`], so where the
/// scenes do not differ the sweeps are the same.
///
/// # Errors
/// As [`simulate_run`].
pub fn simulate_changing_run<'a>(
    stops: &[Stop],
    sensor: &SensorConfig,
    seed: u64,
    scene_at: impl Fn(usize) -> Cow<'a, Scene> + Sync,
) -> Result<Vec<SimStop>> {
    sensor.validate()?;
    stops
        .par_iter()
        .enumerate()
        .map(|(index, stop)| {
            let world_from_sensor = stop.world_from_sensor(&sensor.lift)?;
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(index as u64);
            let sweep = scan(
                &scene_at(index),
                sensor,
                &world_from_sensor,
                stop.lift_slide_m,
                &mut rng,
            );
            Ok(SimStop {
                world_from_sensor,
                lift_slide_m: stop.lift_slide_m,
                sweep,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn room_with(free: &[OrientedBox], solids: &[Solid]) -> Scene {
        let mut scene = Scene::new();
        free.iter().cloned().for_each(|b| scene.add_free(b));
        solids.iter().cloned().for_each(|s| scene.add_solid(s));
        scene
    }

    fn unit(x: f64, y: f64, z: f64) -> Vec3 {
        Vec3::new(x, y, z).normalize()
    }

    #[test]
    fn raycast_inside_one_box_is_exact() {
        let scene = room_with(&[aabb([-1.0, -0.5, -0.3], [2.0, 1.5, 0.7])], &[]);
        let o = Vec3::zeros();
        let cases = [
            (Vec3::x(), 2.0),
            (-Vec3::x(), 1.0),
            (Vec3::y(), 1.5),
            (-Vec3::y(), 0.5),
            (Vec3::z(), 0.7),
            (-Vec3::z(), 0.3),
            (unit(1.0, 1.0, 0.0), 1.5 * 2f64.sqrt()),
            (unit(-1.0, 0.0, -1.0), 0.3 * 2f64.sqrt()),
        ];
        for (d, expected) in cases {
            assert_relative_eq!(
                scene.raycast(&o, &d, 10.0).unwrap(),
                expected,
                epsilon = 1e-12
            );
        }
        assert!(scene.raycast(&o, &Vec3::x(), 1.9).is_none());
        // A box turned 30° about z: along its own axes the distances are its half extents.
        let yaw = 30f64.to_radians();
        let turned =
            OrientedBox::new(Vec3::zeros(), Vec3::new(2.0, 1.0, 0.5), yaw_rotation(yaw)).unwrap();
        let scene = room_with(&[turned], &[]);
        let along = Vec3::new(yaw.cos(), yaw.sin(), 0.0);
        let across = Vec3::new(-yaw.sin(), yaw.cos(), 0.0);
        assert_relative_eq!(
            scene.raycast(&o, &along, 10.0).unwrap(),
            2.0,
            epsilon = 1e-12
        );
        assert_relative_eq!(
            scene.raycast(&o, &-across, 10.0).unwrap(),
            1.0,
            epsilon = 1e-12
        );
        // From outside the air the ray hits at once.
        assert_eq!(
            scene.raycast(&Vec3::new(0.0, 0.0, 3.0), &-Vec3::z(), 10.0),
            Some(0.0)
        );
    }

    #[test]
    fn ray_crosses_shared_faces_of_free_boxes() {
        let a = aabb([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]);
        let b = aabb([1.0, -0.5, -0.5], [4.0, 0.5, 0.5]); // shares the face x = 1
        let c = aabb([3.0, -0.2, -0.2], [6.0, 0.2, 0.2]); // overlaps b
        let scene = room_with(&[a, b, c], &[]);
        let o = Vec3::zeros();
        assert_relative_eq!(
            scene.raycast(&o, &Vec3::x(), 10.0).unwrap(),
            6.0,
            epsilon = 1e-12
        );
        // Back from the far end through both junctions to a's far wall.
        let far = Vec3::new(5.5, 0.0, 0.0);
        assert_relative_eq!(
            scene.raycast(&far, &-Vec3::x(), 10.0).unwrap(),
            6.5,
            epsilon = 1e-12
        );
        // Through the shared face but outside b's cross-section: a's wall.
        let d = unit(1.0, 0.7, 0.0);
        assert_relative_eq!(
            scene.raycast(&o, &d, 10.0).unwrap(),
            (1.0f64 + 0.49).sqrt(),
            epsilon = 1e-12
        );
        // Into b, then out through b's side wall at y = 0.5.
        let d = unit(3.0, 0.5, 0.0);
        assert_relative_eq!(
            scene.raycast(&o, &d, 10.0).unwrap(),
            (9.0f64 + 0.25).sqrt(),
            epsilon = 1e-12
        );
        // A turned leg sharing an edge region with a: continues through.
        let yaw = 20f64.to_radians();
        let leg = OrientedBox::new(
            Vec3::new(2.0 * yaw.cos(), 2.0 * yaw.sin(), 0.0),
            Vec3::new(1.5, 0.3, 0.3),
            yaw_rotation(yaw),
        )
        .unwrap();
        let scene = room_with(&[aabb([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]), leg], &[]);
        let d = Vec3::new(yaw.cos(), yaw.sin(), 0.0);
        assert_relative_eq!(scene.raycast(&o, &d, 10.0).unwrap(), 3.5, epsilon = 1e-12);
        assert!(scene.is_free(&(d * 3.4)) && !scene.is_free(&(d * 3.6)));
    }

    #[test]
    fn solids_inside_the_air_are_hit_at_the_right_distance() {
        let air = aabb([-5.0, -5.0, -1.0], [5.0, 5.0, 2.0]);
        let diamond = OrientedBox::new(
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.5, 0.5, 0.5),
            yaw_rotation(45f64.to_radians()),
        )
        .unwrap();
        let rock = Ellipsoid::new(
            Vec3::new(0.0, 2.0, 0.0),
            Vec3::new(0.3, 0.5, 0.4),
            Rotation3::identity(),
        )
        .unwrap();
        let tilted = OrientedBox::new(
            Vec3::new(0.0, -2.0, 0.0),
            Vec3::new(0.5, 0.5, 0.5),
            Rotation3::from_euler_angles(0.4, 0.0, 0.0),
        )
        .unwrap();
        let scene = room_with(
            &[air],
            &[
                Solid::Box(diamond),
                Solid::Ellipsoid(rock),
                Solid::Box(tilted),
            ],
        );
        let o = Vec3::zeros();
        // The diamond's near corner.
        assert_relative_eq!(
            scene.raycast(&o, &Vec3::x(), 10.0).unwrap(),
            2.0 - 0.5 * 2f64.sqrt(),
            epsilon = 1e-12
        );
        assert_relative_eq!(
            scene.raycast(&o, &Vec3::y(), 10.0).unwrap(),
            1.5,
            epsilon = 1e-12
        );
        // A box rolled by 0.4 rad about x: its face toward the origin is 0.5 from its centre
        // along the face normal (0, -cos 0.4, -sin 0.4).
        let along_y = 0.5 / 0.4f64.cos();
        assert_relative_eq!(
            scene.raycast(&o, &-Vec3::y(), 10.0).unwrap(),
            2.0 - along_y,
            epsilon = 1e-12
        );
        // Missed solids leave the wall; inside a solid nothing is free.
        assert_relative_eq!(
            scene.raycast(&o, &-Vec3::x(), 10.0).unwrap(),
            5.0,
            epsilon = 1e-12
        );
        assert!(!scene.is_free(&Vec3::new(2.0, 0.0, 0.0)));
        assert!(!scene.is_free(&Vec3::new(0.0, 2.0, 0.35)));
        assert!(scene.is_free(&Vec3::new(0.0, 2.0, 0.45)));
        assert_eq!(
            scene.raycast(&Vec3::new(2.0, 0.0, 0.0), &Vec3::x(), 10.0),
            Some(0.0)
        );
    }

    #[test]
    fn floor_height_is_the_lowest_place_to_stand() {
        let room = paper_room();
        let f = -PAPER_ROOM_SENSOR_HEIGHT_M;
        assert_relative_eq!(room.floor_height(0.0, 0.0).unwrap(), f, epsilon = 1e-12);
        // On top of the box at (1.3, 0.7) (there is no gap under it).
        assert_relative_eq!(
            room.floor_height(1.3, 0.7).unwrap(),
            f + 0.4,
            epsilon = 1e-12
        );
        // Under the beam the floor is still the floor.
        assert_relative_eq!(room.floor_height(1.6, 0.0).unwrap(), f, epsilon = 1e-12);
        assert!(room.floor_height(9.0, 0.0).is_none());
        assert!(room.is_free(&Vec3::zeros()) && room.is_free(&Vec3::new(0.0, 0.0, 0.3)));
    }

    #[test]
    fn corridor_is_long_and_plain() {
        let c = corridor(20.0).unwrap();
        let o = Vec3::zeros();
        assert_relative_eq!(
            c.raycast(&o, &Vec3::x(), 20.0).unwrap(),
            10.0,
            epsilon = 1e-12
        );
        assert_relative_eq!(
            c.raycast(&o, &Vec3::y(), 20.0).unwrap(),
            0.6,
            epsilon = 1e-12
        );
        assert_relative_eq!(
            c.raycast(&o, &-Vec3::z(), 20.0).unwrap(),
            0.4,
            epsilon = 1e-12
        );
        assert!(corridor(f64::NAN).is_err() && corridor(-3.0).is_err());
    }

    fn bits(run: &[SimStop]) -> Vec<u32> {
        run.iter()
            .flat_map(|s| s.sweep.lines.iter())
            .flat_map(|l| l.ranges.iter().map(|r| r.to_bits()))
            .collect()
    }

    #[test]
    fn same_seed_same_scene_and_sweep() {
        let sensor = SensorConfig::default();
        let a = collapsed_building(3);
        assert_eq!(a, collapsed_building(3));
        assert_ne!(a, collapsed_building(4));
        let stops = collapsed_building_stops(&a, 3, 2, &sensor.lift).unwrap();
        assert_eq!(
            stops,
            collapsed_building_stops(&a, 3, 2, &sensor.lift).unwrap()
        );
        let run1 = simulate_run(&a, &stops, &sensor, 3).unwrap();
        let run2 = simulate_run(&a, &stops, &sensor, 3).unwrap();
        assert_eq!(bits(&run1), bits(&run2));
        assert_eq!(
            run1[1].sweep.lines[0].attitude,
            run2[1].sweep.lines[0].attitude
        );
        let run3 = simulate_run(&a, &stops, &sensor, 4).unwrap();
        assert_ne!(bits(&run1), bits(&run3));
        // A stop's sweep does not depend on the other stops.
        let alone = simulate_run(&a, &stops[..1], &sensor, 3).unwrap();
        assert_eq!(bits(&alone), bits(&run1[..1]));
    }

    /// Checks every constraint of the collapsed-building path.
    fn check_path(seed: u64) {
        let lift = LiftConfig::default();
        let scene = collapsed_building(seed);
        let stops = collapsed_building_stops(&scene, seed, MAX_STOPS, &lift).unwrap();
        let poses: Vec<Pose> = stops
            .iter()
            .map(|s| s.world_from_sensor(&lift).unwrap())
            .collect();
        assert_eq!(poses[0], Pose::identity(), "seed {seed}");
        let mut lift_changes = 0;
        for k in 0..stops.len() {
            let a = attitude_of(&stops[k].world_from_body);
            assert!(
                a.roll.abs() <= 4f64.to_radians() + 1e-12,
                "seed {seed} stop {k}"
            );
            assert!(
                a.pitch.abs() <= 4f64.to_radians() + 1e-12,
                "seed {seed} stop {k}"
            );
            let body = stops[k].world_from_body.translation.vector;
            let floor = scene.floor_height(body.x, body.y).unwrap();
            assert!(
                (body.z - floor).abs() < 0.04,
                "seed {seed} stop {k}: body off the floor"
            );
            let p = poses[k].translation.vector;
            let clearance = scene.clearance(&p, 600);
            assert!(
                clearance >= MIN_SENSOR_CLEARANCE_M,
                "seed {seed} stop {k}: {clearance}"
            );
            if k == 0 {
                continue;
            }
            let q = poses[k - 1].translation.vector;
            let step = (p - q).xy();
            assert!(
                (0.25..=0.45).contains(&step.norm()),
                "seed {seed} stop {k}: {}",
                step.norm()
            );
            let yaw0 = attitude_of(&stops[k - 1].world_from_body).yaw;
            let heading = Vector3::new(yaw0.cos(), yaw0.sin(), 0.0).xy();
            assert!(
                step.dot(&heading) > 0.8 * step.norm(),
                "seed {seed} stop {k}: not forward"
            );
            let turn = wrap_angle(a.yaw - yaw0).abs();
            assert!(
                turn <= 20f64.to_radians(),
                "seed {seed} stop {k}: turn {}",
                turn.to_degrees()
            );
            if stops[k].lift_slide_m != stops[k - 1].lift_slide_m {
                lift_changes += 1;
            } else {
                assert!(
                    (p.z - q.z).abs() <= 0.06,
                    "seed {seed} stop {k}: dz {}",
                    p.z - q.z
                );
            }
        }
        assert_eq!(lift_changes, 2, "seed {seed}");
        // Low in the ditch, high in the void.
        assert!(stops[6].lift_slide_m > 0.5 && stops[MAX_STOPS - 1].lift_slide_m < 0.25);
        // The loop comes back to the place and heading where it began.
        let (i, j) = scene.loop_closure_stops().unwrap();
        assert!(j < MAX_STOPS, "seed {seed}: loop closes at stop {j}");
        let (pi, pj) = (poses[i].translation.vector, poses[j].translation.vector);
        assert!(
            (pi - pj).xy().norm() < 1e-9 && (pi.z - pj.z).abs() < 0.06,
            "seed {seed}"
        );
    }

    #[test]
    fn collapsed_building_path_is_drivable() {
        for seed in [0, 1, 2] {
            check_path(seed);
        }
    }

    #[test]
    fn stops_reject_bad_arguments() {
        let lift = LiftConfig::default();
        let scene = collapsed_building(1);
        assert!(collapsed_building_stops(&scene, 1, 0, &lift).is_err());
        assert!(collapsed_building_stops(&scene, 1, MAX_STOPS + 1, &lift).is_err());
        assert!(collapsed_building_stops(&paper_room(), 1, 3, &lift).is_err());
        let short = LiftConfig {
            link_length_m: 0.2,
            slide_max_m: 0.39,
            ..LiftConfig::default()
        };
        assert!(collapsed_building_stops(&scene, 1, 3, &short).is_err());
    }

    #[test]
    fn noise_free_scan_lies_on_the_surfaces() {
        let sensor = SensorConfig {
            range_noise_m: 0.0,
            tilt_sensor_noise_deg: 0.0,
            compass_noise_deg: 0.0,
            ..SensorConfig::default()
        };
        let room = paper_room();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let sweep = scan(&room, &sensor, &Pose::identity(), 0.3, &mut rng);
        sweep.validate().unwrap();
        assert_eq!(sweep.lift_slide_m, 0.3);
        assert_eq!(sweep.mean_attitude(), Attitude::default());
        let points = sweep.points_in_sensor();
        // A closed room within range: every beam returns.
        assert_eq!(points.len(), 86 * 181);
        let mut on_solids = 0;
        for p in &points {
            let d = p.normalize();
            assert!(
                room.is_free(&(p - d * 1e-4)),
                "{p:?} is not reached through air"
            );
            assert!(!room.is_free(&(p + d * 1e-4)), "{p:?} is not on a surface");
            if room.free_volumes()[0].contains(&(p + d * 1e-4)) {
                on_solids += 1;
            }
        }
        assert!(on_solids > 500, "the obstacles are seen: {on_solids}");
    }

    #[test]
    fn default_sensor_sees_most_of_the_ditch() {
        let sensor = SensorConfig::default();
        let scene = collapsed_building(5);
        let stops = collapsed_building_stops(&scene, 5, 6, &sensor.lift).unwrap();
        let (high, low) = lift_settings(&sensor.lift).unwrap();
        assert_eq!((stops[0].lift_slide_m, stops[5].lift_slide_m), (high, low));
        let run = simulate_run(&scene, &stops[5..], &sensor, 5).unwrap();
        let sweep = &run[0].sweep;
        assert_eq!(sweep.lines.len(), 86);
        assert!(sweep.lines.iter().all(|l| l.ranges.len() == 181));
        let total = 86 * 181;
        let returns = sweep.points_in_sensor().len();
        assert!(returns as f64 > 0.95 * total as f64, "{returns} of {total}");
        // The reading is near the truth and the same on every line.
        let truth = attitude_of(&run[0].world_from_sensor);
        let reading = sweep.lines[0].attitude;
        assert!(sweep.lines.iter().all(|l| l.attitude == reading));
        assert!((reading.roll - truth.roll).abs() < 1f64.to_radians());
        assert!((wrap_angle(reading.yaw - truth.yaw)).abs() < 1f64.to_radians());
    }
}
