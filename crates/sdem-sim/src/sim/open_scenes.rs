//! Open scenes, seeded: a large hall with pillars and boxes, and a street between facades with
//! side streets, parked cars, poles and trees. Floors lie at `z = 0`; a sensor stands anywhere
//! in the scene's sensor region ([`open_hall_sensor_region`], [`street_sensor_region`]) that
//! has clearance.

use super::scene::Scene;
use super::solids::{Ellipsoid, Solid};
use super::{aabb, yaw_rotation, yawed_box};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sdem::geometry::Vec3;
use std::f64::consts::PI;

/// Mixed into the seed of the hall's layout.
const HALL_SALT: u64 = 0x4a11_0000_0000_0001;
/// Mixed into the seed of the street's layout.
const STREET_SALT: u64 = 0x57ee_7000_0000_0001;

/// The hall's air: x ∈ [−9, 9], y ∈ [−6.5, 6.5], z ∈ [0, 4.5] metres.
const HALL_MAX: [f64; 3] = [9.0, 6.5, 4.5];
/// Half the street's width between the facades, metres.
const STREET_HALF_WIDTH_M: f64 = 9.0;
/// How far the street runs each way, metres: beyond a LiDAR's reach from its sensor region.
const STREET_HALF_LENGTH_M: f64 = 150.0;
/// The facades' height (the street's air is open to here; beyond a LiDAR's +15° rings), metres.
const STREET_HEIGHT_M: f64 = 40.0;
/// The facades carry set-backs, doorways and shop fronts along this much of the street, each
/// way, metres.
const FACADE_DETAIL_M: f64 = 100.0;

/// Where a sensor may stand in [`open_hall`]: `[min, max]` corners, metres (0.4–1.6 m above
/// the floor, 2 m or more from the walls).
pub fn open_hall_sensor_region() -> [[f64; 3]; 2] {
    [[-7.0, -4.5, 0.4], [7.0, 4.5, 1.6]]
}

/// Where a sensor may stand in [`street`]: `[min, max]` corners, metres (on the road's middle
/// lanes, 1.6–1.9 m above it, as on a car's roof).
pub fn street_sensor_region() -> [[f64; 3]; 2] {
    [[-40.0, -3.0, 1.6], [40.0, 3.0, 1.9]]
}

/// A seeded open hall: 18 m × 13 m × 4.5 m (x ∈ [−9, 9], y ∈ [−6.5, 6.5], floor at z = 0), a
/// door recess in one wall, 4–6 pillars from floor to ceiling and 6–9 boxes of 0.4–1.6 m on the
/// floor, turned at random. The same seed gives the same hall.
pub fn open_hall(seed: u64) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ HALL_SALT);
    let [mx, my, mz] = HALL_MAX;
    let mut scene = Scene::new();
    scene.add_free(aabb([-mx, -my, 0.0], [mx, my, mz]));
    // A door recess in the +y wall, somewhere along it.
    let door_x = rng.random_range(-6.0..6.0);
    scene.add_free(aabb(
        [door_x - 1.0, my - 0.01, 0.0],
        [door_x + 1.0, my + 1.2, 2.4],
    ));
    let pillars = rng.random_range(4..=6);
    for _ in 0..pillars {
        let (x, y) = (rng.random_range(-7.5..7.5), rng.random_range(-5.0..5.0));
        let half = rng.random_range(0.2..0.3);
        let yaw = rng.random_range(0.0..90.0);
        scene.add_solid(Solid::Box(yawed_box(
            [x, y, 0.5 * mz],
            [half, half, 0.5 * mz],
            yaw,
        )));
    }
    let boxes = rng.random_range(6..=9);
    for _ in 0..boxes {
        let (x, y) = (rng.random_range(-8.0..8.0), rng.random_range(-5.5..5.5));
        let half = [
            rng.random_range(0.2..0.8),
            rng.random_range(0.2..0.8),
            rng.random_range(0.2..0.8),
        ];
        let yaw = rng.random_range(-180.0..180.0);
        scene.add_solid(Solid::Box(yawed_box([x, y, half[2]], half, yaw)));
    }
    scene
}

/// A seeded street: a road 18 m wide between facades 40 m high (x along it, ±150 m; y across,
/// ±9 m; the road at z = 0), crossed by two side streets 10–14 m wide. Along ±100 m the facades
/// step back by up to 2.5 m every 6–15 m and open into doorways and shop fronts 0.5–1.5 m deep;
/// cars are parked along both kerbs with gaps, and poles and trees stand on the pavements. The
/// same seed gives the same street.
pub fn street(seed: u64) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ STREET_SALT);
    let (w, l, h) = (STREET_HALF_WIDTH_M, STREET_HALF_LENGTH_M, STREET_HEIGHT_M);
    let mut scene = Scene::new();
    scene.add_free(aabb([-l, -w, 0.0], [l, w, h]));
    let crossings = [
        (rng.random_range(-45.0..-25.0), rng.random_range(5.0..7.0)),
        (rng.random_range(20.0..40.0), rng.random_range(5.0..7.0)),
    ];
    for &(x, half) in &crossings {
        scene.add_free(aabb([x - half, -l, 0.0], [x + half, l, h]));
    }
    let in_crossing = |x: f64, margin: f64| {
        crossings
            .iter()
            .any(|&(c, half)| (x - c).abs() < half + margin)
    };
    for side in [-1.0, 1.0] {
        add_facade(&mut scene, &mut rng, side, &in_crossing);
        add_kerb_side(&mut scene, &mut rng, side, &in_crossing);
    }
    scene
}

/// One side's facade (`side` = ±1: the +y or −y one): set-backs, doorways and shop fronts.
fn add_facade(
    scene: &mut Scene,
    rng: &mut ChaCha8Rng,
    side: f64,
    in_crossing: &dyn Fn(f64, f64) -> bool,
) {
    let (w, h) = (STREET_HALF_WIDTH_M, STREET_HEIGHT_M);
    // A y interval from the facade line `w` outwards by `depth`, on this side.
    let outwards = |depth: f64| {
        let (a, b) = (side * (w - 0.01), side * (w + depth));
        (a.min(b), a.max(b))
    };
    let mut x = -FACADE_DETAIL_M;
    while x < FACADE_DETAIL_M {
        let length = rng.random_range(6.0..15.0);
        let setback = if rng.random_bool(0.5) {
            rng.random_range(0.3..2.5)
        } else {
            0.0
        };
        if setback > 0.0 && !in_crossing(x + 0.5 * length, 0.5 * length) {
            let (y0, y1) = outwards(setback);
            scene.add_free(aabb([x, y0, 0.0], [x + length, y1, h]));
        }
        // Doorways and shop fronts in this stretch of facade.
        for _ in 0..rng.random_range(1..=2) {
            let width = rng.random_range(1.2..3.0);
            let at = x + rng.random_range(0.0..(length - width).max(0.1));
            let depth = setback + rng.random_range(0.5..1.5);
            let height = rng.random_range(2.2..3.5);
            if !in_crossing(at + 0.5 * width, 0.5 * width) {
                let (y0, y1) = outwards(depth);
                scene.add_free(aabb([at, y0, 0.0], [at + width, y1, height]));
            }
        }
        x += length;
    }
}

/// One side's kerb (`side` = ±1): parked cars, then poles and trees on the pavement.
fn add_kerb_side(
    scene: &mut Scene,
    rng: &mut ChaCha8Rng,
    side: f64,
    in_crossing: &dyn Fn(f64, f64) -> bool,
) {
    let w = STREET_HALF_WIDTH_M;
    let mut x = -FACADE_DETAIL_M;
    while x < FACADE_DETAIL_M {
        let gap = rng.random_range(1.0..9.0);
        let parked = rng.random_bool(0.65);
        let length = rng.random_range(3.8..4.8);
        let centre = x + gap + 0.5 * length;
        if parked && !in_crossing(centre, 0.5 * length + 1.0) {
            let height = rng.random_range(1.4..1.9);
            let y = side * (w - 2.6 + rng.random_range(-0.2..0.2));
            let yaw = rng.random_range(-3.0..3.0);
            scene.add_solid(Solid::Box(yawed_box(
                [centre, y, 0.5 * height],
                [0.5 * length, 0.9, 0.5 * height],
                yaw,
            )));
        }
        x += gap + length;
    }
    let mut x = -FACADE_DETAIL_M + rng.random_range(0.0..10.0);
    while x < FACADE_DETAIL_M {
        if !in_crossing(x, 1.5) {
            let y = side * (w - 1.0);
            if rng.random_bool(0.5) {
                // A lamp post.
                scene.add_solid(Solid::Box(yawed_box([x, y, 3.5], [0.1, 0.1, 3.5], 0.0)));
            } else {
                // A tree: a trunk and a crown.
                let trunk = rng.random_range(2.5..3.5);
                scene.add_solid(Solid::Box(yawed_box(
                    [x, y, 0.5 * trunk],
                    [0.15, 0.15, 0.5 * trunk],
                    rng.random_range(0.0..90.0),
                )));
                let radii = Vec3::new(
                    rng.random_range(1.3..2.0),
                    rng.random_range(1.3..2.0),
                    rng.random_range(1.2..1.8),
                );
                let crown = Vec3::new(x, y, trunk + 0.8 * radii.z);
                let turn = yaw_rotation(rng.random_range(-PI..PI));
                scene.add_solid(Solid::Ellipsoid(Ellipsoid::build(crown, radii, turn)));
            }
        }
        x += rng.random_range(12.0..22.0);
    }
}
