//! The seeded collapsed building: a room, a narrow ditch and a wider void, with obstacles that
//! keep the route drivable.

use super::route::{
    plan_route, Route, COLLAPSED_BUILDING_START_HEIGHT_M, MOUTH_X_M, TURN_RADIUS_M,
};
use super::scene::Scene;
use super::solids::{Ellipsoid, OrientedBox, Solid};
use super::{aabb, yaw_rotation, yawed_box, Frame2};
use nalgebra::Rotation3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sdem::geometry::Vec3;
use std::f64::consts::PI;

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
///
/// [`collapsed_building_stops`]: super::collapsed_building_stops
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
