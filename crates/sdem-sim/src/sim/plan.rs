//! Closed laps drawn on a floor plan, for long runs: corners joined by straight lines and
//! rounded with arcs, stops spaced evenly along each lap, and the tube around the path that
//! obstacles must leave clear.

use super::route::{pose_along, Segment};
use super::scene::Scene;
use super::solids::{OrientedBox, Solid};
use super::{yawed_box, Frame2};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use sdem::error::{Error, Result};
use sdem::geometry::Vec3;
use std::f64::consts::PI;

/// Radius of the arcs that round every corner of a lap, metres.
pub(super) const CORNER_RADIUS_M: f64 = 1.1;
/// Stops are about this far apart along a lap, metres (the collapsed building's spacing).
pub(super) const STOP_SPACING_M: f64 = 0.35;
/// Radius of the tube kept clear of obstacles around the path, metres.
pub(super) const TUBE_RADIUS_M: f64 = 0.35;
/// Height of the kept-clear tube above the floor, metres.
const TUBE_TOP_M: f64 = 0.55;
/// Rubble no higher than this above the floor may lie on the path (the robot drives on it).
const LOW_RUBBLE_TOP_M: f64 = 0.03;

/// One closed lap: corners on the plan, each rounded with an arc of [`CORNER_RADIUS_M`]. The
/// lap starts where the arc of the first corner ends, heading along its first side, and comes
/// back there.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Lap {
    /// Straight lines and arcs from the start back to it.
    pub(super) segments: Vec<Segment>,
    /// Stops on the lap; they lie `length / stops` apart.
    pub(super) stops: usize,
}

impl Lap {
    /// The lap through `corners` (plan frame, metres; at least three, consecutive ones apart
    /// by more than their arcs take), whose start the caller puts at the world origin:
    /// `origin` is where it lies on the plan, and its heading must be +x.
    ///
    /// # Errors
    /// [`Error::Invalid`] when a side is too short for the arcs at its ends, or the lap does
    /// not start at `origin` heading +x.
    pub(super) fn through(corners: &[[f64; 2]], origin: [f64; 2]) -> Result<Self> {
        let n = corners.len();
        let bad = |why: String| Error::Invalid(format!("lap through {corners:?}: {why}"));
        if n < 3 {
            return Err(bad("a lap needs at least three corners".into()));
        }
        let direction = |a: [f64; 2], b: [f64; 2]| {
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let length = dx.hypot(dy);
            ([dx / length, dy / length], length)
        };
        // The turn at each corner and the length of line its arc takes from each side.
        let turns: Vec<(f64, f64)> = (0..n)
            .map(|i| {
                let (d_in, _) = direction(corners[(i + n - 1) % n], corners[i]);
                let (d_out, _) = direction(corners[i], corners[(i + 1) % n]);
                let cross = d_in[0] * d_out[1] - d_in[1] * d_out[0];
                let dot = d_in[0] * d_out[0] + d_in[1] * d_out[1];
                let turn = cross.atan2(dot);
                (turn, CORNER_RADIUS_M * (0.5 * turn.abs()).tan())
            })
            .collect();
        let (d0, _) = direction(corners[0], corners[1]);
        let start = [
            corners[0][0] + d0[0] * turns[0].1,
            corners[0][1] + d0[1] * turns[0].1,
        ];
        if (start[0] - origin[0]).hypot(start[1] - origin[1]) > 1e-9 || d0[1].abs() > 1e-12 {
            return Err(bad(format!(
                "it starts at {start:?} heading ({:.3}, {:.3}), not at {origin:?} heading +x",
                d0[0], d0[1]
            )));
        }
        let mut segments = Vec::with_capacity(2 * n);
        for i in 0..n {
            let j = (i + 1) % n;
            let (_, side) = direction(corners[i], corners[j]);
            let line = side - turns[i].1 - turns[j].1;
            if line < -1e-9 {
                return Err(bad(format!(
                    "side {i}-{j} is {side:.2} m, too short for the arcs at its ends"
                )));
            }
            segments.push(Segment::Line(line.max(0.0)));
            if turns[j].0.abs() > 1e-12 {
                segments.push(Segment::Arc {
                    radius: CORNER_RADIUS_M,
                    angle: turns[j].0,
                });
            }
        }
        let length: f64 = segments.iter().map(Segment::length).sum();
        let stops = ((length / STOP_SPACING_M).round() as usize).max(1);
        Ok(Self { segments, stops })
    }

    pub(super) fn length(&self) -> f64 {
        self.segments.iter().map(Segment::length).sum()
    }

    /// Position and heading at arc length `s` along the lap, in the world (the lap starts at
    /// the origin heading +x).
    pub(super) fn at(&self, s: f64) -> ([f64; 2], f64) {
        pose_along(&self.segments, s)
    }
}

/// A sample of the path with the floor under it: what obstacles must keep clear of.
#[derive(Debug, Clone, Copy)]
struct TubeSample {
    x: f64,
    y: f64,
    floor: f64,
}

/// The tube around every lap's path, sampled every 10 cm.
#[derive(Debug, Clone, Default)]
pub(super) struct Tube {
    samples: Vec<TubeSample>,
}

impl Tube {
    /// Samples every lap of `laps` in `scene` (its air built already).
    pub(super) fn around(scene: &Scene, laps: &[Lap]) -> Self {
        let mut samples = Vec::new();
        for lap in laps {
            let mut s = 0.0;
            while s <= lap.length() {
                let ([x, y], _) = lap.at(s);
                if let Some(floor) = scene.floor_height(x, y) {
                    samples.push(TubeSample { x, y, floor });
                }
                s += 0.1;
            }
        }
        Self { samples }
    }

    /// True when `solid` leaves the tube clear, or is low rubble the robot drives over.
    pub(super) fn is_clear_of(&self, solid: &Solid) -> bool {
        let c = solid.center();
        let reach = solid.bounding_radius() + TUBE_RADIUS_M;
        let (_, z_top) = solid.z_range();
        self.samples.iter().all(|t| {
            if (c.x - t.x).hypot(c.y - t.y) > reach || z_top <= t.floor + LOW_RUBBLE_TOP_M {
                return true;
            }
            let mut z = t.floor + LOW_RUBBLE_TOP_M + 0.005;
            while z <= t.floor + TUBE_TOP_M + 1e-9 {
                if solid.distance_lower_bound(&Vec3::new(t.x, t.y, z)) < TUBE_RADIUS_M {
                    return false;
                }
                z += 0.05;
            }
            true
        })
    }
}

/// A room's air on the plan: an axis-aligned rectangle with its floor and ceiling.
#[derive(Debug, Clone, Copy)]
pub(super) struct Room {
    pub(super) min: [f64; 2],
    pub(super) max: [f64; 2],
    pub(super) floor: f64,
    pub(super) height: f64,
}

impl Room {
    pub(super) fn air(&self) -> OrientedBox {
        super::aabb(
            [self.min[0], self.min[1], self.floor],
            [self.max[0], self.max[1], self.floor + self.height],
        )
    }

    /// A uniform point inside, `margin` from the walls.
    fn inside(&self, rng: &mut ChaCha8Rng, margin: f64) -> [f64; 2] {
        [
            rng.random_range(self.min[0] + margin..self.max[0] - margin),
            rng.random_range(self.min[1] + margin..self.max[1] - margin),
        ]
    }

    /// A point against one of the walls (`inset` from it) and the wall's heading.
    fn at_wall(&self, rng: &mut ChaCha8Rng, inset: f64) -> ([f64; 2], f64) {
        let t: f64 = rng.random_range(0.15..0.85);
        let (x0, y0, x1, y1) = (self.min[0], self.min[1], self.max[0], self.max[1]);
        match rng.random_range(0..4) {
            0 => ([x0 + t * (x1 - x0), y0 + inset], 0.0),
            1 => ([x0 + t * (x1 - x0), y1 - inset], 0.0),
            2 => ([x0 + inset, y0 + t * (y1 - y0)], 0.5 * PI),
            _ => ([x1 - inset, y0 + t * (y1 - y0)], 0.5 * PI),
        }
    }
}

/// Furnishes `room` with seeded obstacles, each kept only if it leaves `tube` clear: a pillar,
/// cabinets and shelves against the walls, boxes and rubble on the floor, a table. Rooms that
/// look alike would make loop closure a guessing game; these differ in every draw.
pub(super) fn furnish(scene: &mut Scene, tube: &Tube, rng: &mut ChaCha8Rng, room: &Room) {
    let floor = room.floor;
    let place = |scene: &mut Scene,
                 rng: &mut ChaCha8Rng,
                 tries,
                 make: &dyn Fn(&mut ChaCha8Rng) -> Solid| {
        place_clear(scene, tube, rng, tries, make)
    };
    let h = room.height;
    // A pillar, floor to ceiling.
    place(scene, rng, 20, &|rng| {
        let [x, y] = room.inside(rng, 0.3);
        let half = rng.random_range(0.12..0.22);
        Solid::Box(yawed_box(
            [x, y, floor + 0.5 * h],
            [half, half, 0.5 * h],
            0.0,
        ))
    });
    let walls = rng.random_range(2..=4);
    furnish_walls(scene, tube, rng, room, walls);
    // Boxes and blocks on the floor, turned any way.
    for _ in 0..rng.random_range(3..=6) {
        place(scene, rng, 20, &|rng| {
            let half = [
                rng.random_range(0.1..0.35),
                rng.random_range(0.1..0.35),
                rng.random_range(0.08..0.4),
            ];
            let [x, y] = room.inside(rng, 0.2);
            let yaw = rng.random_range(-90.0..90.0);
            Solid::Box(yawed_box([x, y, floor + half[2]], half, yaw))
        });
    }
    // A table: a top on four legs.
    let table = room.inside(rng, 0.8);
    let top_half = [
        rng.random_range(0.35..0.6),
        rng.random_range(0.3..0.45),
        0.025,
    ];
    let top_z = floor + rng.random_range(0.7..0.8);
    let yaw: f64 = rng.random_range(-45.0..45.0);
    let frame = Frame2 {
        origin: table,
        yaw: yaw.to_radians(),
    };
    let mut parts = vec![Solid::Box(yawed_box(
        [table[0], table[1], top_z],
        top_half,
        yaw,
    ))];
    for (sx, sy) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
        let [x, y] = frame.point(sx * (top_half[0] - 0.04), sy * (top_half[1] - 0.04));
        let leg_half = 0.5 * (top_z - floor);
        parts.push(Solid::Box(yawed_box(
            [x, y, floor + leg_half],
            [0.025, 0.025, leg_half],
            yaw,
        )));
    }
    if parts.iter().all(|p| tube.is_clear_of(p)) {
        for p in parts {
            scene.add_solid(p);
        }
    }
}

/// Puts `count` cabinets and shelves against the walls of `room` (a corridor too), each kept
/// only if it leaves `tube` clear.
pub(super) fn furnish_walls(
    scene: &mut Scene,
    tube: &Tube,
    rng: &mut ChaCha8Rng,
    room: &Room,
    count: usize,
) {
    let floor = room.floor;
    for _ in 0..count {
        place_clear(scene, tube, rng, 20, &|rng| {
            let depth = rng.random_range(0.12..0.3);
            let ([x, y], yaw) = room.at_wall(rng, depth);
            let half = [
                rng.random_range(0.2..0.6),
                depth,
                rng.random_range(0.3..0.9),
            ];
            Solid::Box(yawed_box([x, y, floor + half[2]], half, yaw.to_degrees()))
        });
    }
}

/// Adds the first of up to `tries` solids drawn by `make` that leaves `tube` clear.
pub(super) fn place_clear(
    scene: &mut Scene,
    tube: &Tube,
    rng: &mut ChaCha8Rng,
    tries: usize,
    make: &dyn Fn(&mut ChaCha8Rng) -> Solid,
) {
    for _ in 0..tries {
        let solid = make(rng);
        if tube.is_clear_of(&solid) {
            scene.add_solid(solid);
            return;
        }
    }
}
