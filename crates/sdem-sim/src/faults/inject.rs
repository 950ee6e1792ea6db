//! The faults put into sweeps: dust, lost returns, a walking person, and where people and moved
//! rubble find room.

use super::FaultConfig;
use crate::benchmark::symmetric;
use crate::sim::{Ellipsoid, OrientedBox, Scene};
use nalgebra::Rotation3;
use rand::Rng;
use rand_distr::StandardNormal;
use sdem::geometry::{attitude_of, Pose, Vec3};
use sdem::sensor::{beam_direction, SensorConfig, Sweep};

/// Places drawn for a person or a piece of rubble before giving up.
const MAX_PLACE_DRAWS: usize = 2_000;
/// A standing person's semi-axes: shoulders 0.5 m, chest 0.4 m, height 1.7 m.
pub(super) const PERSON_RADII_M: [f64; 3] = [0.25, 0.2, 0.85];
/// A crawling person's semi-axes (length along the way they crawl, width, height), where there
/// is no headroom to stand: in the ditch.
const CRAWLING_RADII_M: [f64; 3] = [0.6, 0.25, 0.2];
/// People and rubble stay at least this far from either sensor, metres (nobody stands on the
/// robot; the robot does not stand in rubble).
pub(super) const KEEP_CLEAR_M: f64 = 0.35;

/// Replaces a `fraction` of the beams of `sweep` (with or without a return) by a return from
/// dust: a range uniform between the sensor's minimum range and the surface (or the usable
/// range where the beam saw nothing). Returns the number of dust returns.
pub fn add_dust(
    sweep: &mut Sweep,
    fraction: f64,
    sensor: &SensorConfig,
    rng: &mut impl Rng,
) -> usize {
    let mut count = 0;
    for line in &mut sweep.lines {
        for range in &mut line.ranges {
            if rng.random::<f64>() >= fraction {
                continue;
            }
            let surface = if range.is_finite() {
                *range as f64
            } else {
                sensor.usable_range_m()
            };
            if surface > sensor.min_range_m {
                *range = rng.random_range(sensor.min_range_m..surface) as f32;
                count += 1;
            }
        }
    }
    count
}

/// Loses at least `fraction` of the returns of `sweep`, in runs of 1 to `run_max` neighbouring
/// beams of a line (dark, wet or glancing surfaces lose stretches, not single beams). Returns
/// the number of returns lost.
pub fn drop_returns(sweep: &mut Sweep, fraction: f64, run_max: usize, rng: &mut impl Rng) -> usize {
    let returns = sweep
        .lines
        .iter()
        .flat_map(|l| &l.ranges)
        .filter(|r| r.is_finite())
        .count();
    let target = (fraction * returns as f64).ceil() as usize;
    let (lines, beams) = (
        sweep.lines.len(),
        sweep.lines.first().map_or(0, |l| l.ranges.len()),
    );
    let mut lost = 0;
    if lines == 0 || beams == 0 {
        return 0;
    }
    while lost < target {
        let line = &mut sweep.lines[rng.random_range(0..lines)];
        let start = rng.random_range(0..beams);
        let length = rng.random_range(1..=run_max.max(1));
        for range in line.ranges.iter_mut().skip(start).take(length) {
            if range.is_finite() && lost < target {
                *range = f32::NAN;
                lost += 1;
            }
        }
    }
    lost
}

/// A person moving in a straight line while the sensor sweeps: an ellipsoid whose centre goes
/// from `start` to `end` over the sweep's lines, its first axis along the way.
#[derive(Debug, Clone, PartialEq)]
pub struct WalkingPerson {
    /// The centre when the first line is taken, world frame, metres.
    pub start: Vec3,
    /// The centre when the last line is taken.
    pub end: Vec3,
    /// The body's semi-axes: along the way, across it, up; metres.
    pub radii: Vec3,
}

impl WalkingPerson {
    /// The person's body while line `line` of `lines` is taken.
    pub fn body_at(&self, line: usize, lines: usize) -> Ellipsoid {
        let s = if lines > 1 {
            line as f64 / (lines - 1) as f64
        } else {
            0.0
        };
        let center = self.start + (self.end - self.start) * s;
        let heading = (self.end - self.start).y.atan2((self.end - self.start).x);
        Ellipsoid::new(
            center,
            self.radii,
            Rotation3::from_axis_angle(&Vec3::z_axis(), heading),
        )
        .expect("finite centre and positive radii")
    }
}

/// Puts `person` into `sweep` taken at `world_from_sensor`: each beam of line `i` that meets
/// the person's body at line `i` before its surface returns from the body (with the sensor's
/// range noise). Returns the number of beams that hit the person.
pub fn add_walking_person(
    sweep: &mut Sweep,
    world_from_sensor: &Pose,
    person: &WalkingPerson,
    sensor: &SensorConfig,
    rng: &mut impl Rng,
) -> usize {
    let origin = world_from_sensor.translation.vector;
    let lines = sweep.lines.len();
    let (pan_min, pan_step) = (sweep.pan_min_deg, sweep.pan_step_deg);
    let mut count = 0;
    for (i, line) in sweep.lines.iter_mut().enumerate() {
        let body = person.body_at(i, lines);
        let tilt = line.tilt_deg.to_radians();
        for (k, range) in line.ranges.iter_mut().enumerate() {
            let pan = (pan_min + k as f64 * pan_step).to_radians();
            let direction = world_from_sensor.rotation * beam_direction(tilt, pan);
            let Some((t_in, _)) = body.ray_interval(&origin, &direction) else {
                continue;
            };
            if t_in <= 0.0 || (range.is_finite() && t_in >= *range as f64) {
                continue;
            }
            let noise: f64 = rng.sample(StandardNormal);
            let measured = t_in + noise * sensor.range_noise_m;
            if measured >= sensor.min_range_m && measured <= sensor.usable_range_m() {
                *range = measured as f32;
                count += 1;
            }
        }
    }
    count
}

/// The number of returns of `sweep` (taken at `world_from_sensor`) that lie on one of `solids`
/// (within 2 cm of its surface).
pub(super) fn returns_on<'a>(
    sweep: &Sweep,
    world_from_sensor: &Pose,
    solids: impl Iterator<Item = &'a OrientedBox> + Clone,
) -> usize {
    sweep
        .points_in_sensor()
        .iter()
        .filter(|p| {
            let w = world_from_sensor * nalgebra::Point3::from(**p);
            solids.clone().any(|b| b.distance_to(&w.coords) < 0.02)
        })
        .count()
}

/// A place in front of the query sensor (within ±80° of its heading) `min..max` metres away
/// horizontally, on the floor there: the floor height, or `None` where there is no floor.
fn place_in_view(
    scene: &Scene,
    world_from_query: &Pose,
    min_m: f64,
    max_m: f64,
    rng: &mut impl Rng,
) -> Option<(Vec3, f64)> {
    let origin = world_from_query.translation.vector;
    let heading = attitude_of(world_from_query).yaw;
    let bearing = heading + symmetric(rng, 80f64.to_radians());
    let distance = rng.random_range(min_m..max_m);
    let x = origin.x + distance * bearing.cos();
    let y = origin.y + distance * bearing.sin();
    let floor = scene.floor_height(x, y)?;
    Some((Vec3::new(x, y, floor), floor))
}

/// A person who moves `walk_m` in a straight line, 0.8–2.5 m in front of the query sensor, on
/// the floor and in free space all the way, never nearer than [`KEEP_CLEAR_M`] plus their size:
/// standing ([`PERSON_RADII_M`]) where there is headroom, else crawling ([`CRAWLING_RADII_M`]).
pub(super) fn place_person(
    scene: &Scene,
    world_from_query: &Pose,
    walk_m: f64,
    rng: &mut impl Rng,
) -> Option<WalkingPerson> {
    let origin = world_from_query.translation.vector;
    for radii in [PERSON_RADII_M, CRAWLING_RADII_M] {
        let radii = Vec3::from(radii);
        for _ in 0..MAX_PLACE_DRAWS / 2 {
            let Some((feet, _)) = place_in_view(scene, world_from_query, 0.8, 2.5, rng) else {
                continue;
            };
            let direction = rng.random_range(0.0..std::f64::consts::TAU);
            let start = feet + Vec3::new(0.0, 0.0, radii.z);
            let end = start + Vec3::new(direction.cos(), direction.sin(), 0.0) * walk_m;
            let path_clear = (0..=10).all(|j| {
                let c = start + (end - start) * (j as f64 / 10.0);
                let head = c + Vec3::new(0.0, 0.0, 0.8 * radii.z);
                let horizontal = (c - origin).xy().norm();
                scene.is_free(&c) && scene.is_free(&head) && horizontal > KEEP_CLEAR_M + radii.x
            });
            if path_clear {
                return Some(WalkingPerson { start, end, radii });
            }
        }
    }
    None
}

/// [`FaultConfig::rubble_pieces`] blocks on the floor in view of the query, each as it lay at the
/// reference scan and as it lies at the query scan (moved
/// `rubble_move_min_m..rubble_move_max_m` along the floor). Every block keeps
/// [`KEEP_CLEAR_M`] from both sensors in both places.
pub(super) fn place_moved_rubble(
    scene: &Scene,
    reference_origin: &Vec3,
    world_from_query: &Pose,
    config: &FaultConfig,
    rng: &mut impl Rng,
) -> Option<Vec<(OrientedBox, OrientedBox)>> {
    let query_origin = world_from_query.translation.vector;
    let mut pieces = Vec::with_capacity(config.rubble_pieces);
    let mut draws = 0;
    while pieces.len() < config.rubble_pieces {
        draws += 1;
        if draws > MAX_PLACE_DRAWS {
            return None;
        }
        let Some((after_foot, _)) = place_in_view(scene, world_from_query, 0.6, 2.5, rng) else {
            continue;
        };
        let half = Vec3::new(
            rng.random_range(0.1..0.3),
            rng.random_range(0.1..0.3),
            rng.random_range(0.1..0.25),
        );
        let yaw = rng.random_range(0.0..std::f64::consts::TAU);
        let move_direction = rng.random_range(0.0..std::f64::consts::TAU);
        let move_m = rng.random_range(config.rubble_move_min_m..=config.rubble_move_max_m);
        let before_xy = after_foot.xy()
            + nalgebra::Vector2::new(move_direction.cos(), move_direction.sin()) * move_m;
        let Some(before_floor) = scene.floor_height(before_xy.x, before_xy.y) else {
            continue;
        };
        let turn = Rotation3::from_axis_angle(&Vec3::z_axis(), yaw);
        let at = |x: f64, y: f64, floor: f64| {
            OrientedBox::new(Vec3::new(x, y, floor + half.z), half, turn).ok()
        };
        let (Some(before), Some(after)) = (
            at(before_xy.x, before_xy.y, before_floor),
            at(after_foot.x, after_foot.y, after_foot.z),
        ) else {
            continue;
        };
        let clear = [&before, &after].iter().all(|b| {
            b.distance_to(reference_origin) > KEEP_CLEAR_M
                && b.distance_to(&query_origin) > KEEP_CLEAR_M
        });
        if clear {
            pieces.push((before, after));
        }
    }
    Some(pieces)
}
