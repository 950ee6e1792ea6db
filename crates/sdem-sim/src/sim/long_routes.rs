//! Long stop-and-go runs with loops: laps of a furnished room, a floor of nine rooms toured in
//! three different laps, and a building whose two wings are joined by a ditch and a corridor.
//! Each gives as many stops as asked (thousands), lap after lap, with the truth.

use super::plan::{furnish, furnish_walls, Lap, Room, Tube, CORNER_RADIUS_M};
use super::route::COLLAPSED_BUILDING_START_HEIGHT_M;
use super::scanner::{scan, SimStop};
use super::scene::Scene;
use super::solids::Solid;
use super::stops::{check_clearance, first_stop, lift_settings, place_stop, Stop};
use super::{aabb, yawed_box};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use sdem::error::{Error, Result};
use sdem::sensor::{LiftConfig, SensorConfig};
use serde::Serialize;

/// Most stops a long run may have.
pub const MAX_LONG_STOPS: usize = 100_000;
/// Longitudinal jitter of each stop along its lap, metres (± this, uniform).
const ALONG_JITTER_M: f64 = 0.015;
/// Sideways jitter of each stop off its lap's path, metres (± this, uniform).
const SIDEWAYS_JITTER_M: f64 = 0.02;
/// Standard deviation of the random part of roll and pitch, degrees.
const TILT_JITTER_DEG: f64 = 0.5;
/// Distance between the centres of neighbouring rooms on a floor, metres.
const ROOM_PITCH_M: f64 = 4.4;
/// Half the side of a room's air (the walls between rooms are 20 cm thick), metres.
const ROOM_HALF_M: f64 = 2.1;
/// Half the width of a door, metres.
const DOOR_HALF_WIDTH_M: f64 = 0.5;
/// Height of a door, metres.
const DOOR_HEIGHT_M: f64 = 2.1;
/// Mixed into the seed of the stops' jitter, so it does not repeat the scene's stream.
const STOPS_SALT: u64 = 0x5709_1a95_0000_0001;

/// The long routes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LongRoute {
    /// Laps of one furnished room (7 m × 6 m) round a pile in its middle, 30 stops a lap.
    RoomLaps,
    /// A floor of 3 × 3 furnished rooms (13 m × 13 m) joined by doors, toured in three laps
    /// in turn: round the outer eight rooms (95 stops), through the middle row (70) and
    /// through the middle column (70).
    Floor,
    /// Two wings of 2 × 2 rooms joined by a narrow, low ditch full of rubble (the lift goes
    /// down in it) and a corridor: a lap through both wings (120 stops) and a lap of the first
    /// wing alone (45), in turn.
    Wings,
}

impl LongRoute {
    /// Every route, in the order the bench runs them.
    pub const ALL: [LongRoute; 3] = [LongRoute::RoomLaps, LongRoute::Floor, LongRoute::Wings];

    /// The route's name, as `sdem simulate --route` takes it.
    pub fn name(self) -> &'static str {
        match self {
            LongRoute::RoomLaps => "room-laps",
            LongRoute::Floor => "floor",
            LongRoute::Wings => "wings",
        }
    }
}

impl std::str::FromStr for LongRoute {
    type Err = Error;

    fn from_str(text: &str) -> Result<Self> {
        LongRoute::ALL
            .into_iter()
            .find(|r| r.name() == text)
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "unknown route {text:?}; the long routes are room-laps, floor and wings"
                ))
            })
    }
}

/// A long run: the scene, the stops and where each lap begins.
#[derive(Debug, Clone)]
pub struct LongRun {
    /// Which route.
    pub route: LongRoute,
    /// The scene the stops stand in.
    pub scene: Scene,
    /// The stops, in order; stop 0's sensor is the world origin.
    pub stops: Vec<Stop>,
    /// The index of the first stop of each lap (the first is 0). Stop `lap_starts[k] + i` and
    /// `lap_starts[k'] + i` of two laps of the same kind stand at the same place (± the
    /// stops' jitter) with the same heading: that is where loops close.
    pub lap_starts: Vec<usize>,
}

/// A long run of `count` stops along `route` (see [`LongRoute`]): the scene (seeded), and the
/// stops lap after lap, each jittered along (±1.5 cm) and across (±2 cm) its path, with roll
/// and pitch from the floor under the tracks plus N(0, 0.5°), and the lift lowered in the
/// ditch. Stop 0's sensor pose is exactly the identity, 0.4 m above a flat floor.
///
/// # Errors
/// [`Error::Invalid`] when `count` is 0 or above [`MAX_LONG_STOPS`], when the lift cannot
/// reach the start height, or a stop's sensor would come within 15 cm of a surface (a lift
/// that does not fit the scene).
///
/// # Example
/// ```
/// use sdem_sim::sim::{long_run, LongRoute};
/// let run = long_run(LongRoute::RoomLaps, 1, 65, &Default::default())?;
/// assert_eq!(run.stops.len(), 65);
/// assert_eq!(run.lap_starts, vec![0, 30, 60]);
/// # Ok::<(), sdem::Error>(())
/// ```
pub fn long_run(route: LongRoute, seed: u64, count: usize, lift: &LiftConfig) -> Result<LongRun> {
    if count == 0 || count > MAX_LONG_STOPS {
        return Err(Error::Invalid(format!(
            "long_run: {count} stops; a long run has 1 to {MAX_LONG_STOPS}"
        )));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (scene, laps, low_zones) = match route {
        LongRoute::RoomLaps => room_laps(&mut rng)?,
        LongRoute::Floor => floor(&mut rng)?,
        LongRoute::Wings => wings(&mut rng)?,
    };
    let (stops, lap_starts) = place_stops(&scene, &laps, &low_zones, seed, count, lift)?;
    Ok(LongRun {
        route,
        scene,
        stops,
        lap_starts,
    })
}

/// The scene, the kinds of lap driven in turn, and the zones where the lift is low.
type Layout = (Scene, Vec<Lap>, Vec<[f64; 4]>);

/// Where the plans put their first corner: the lap starts after its arc, at the origin.
const FIRST_CORNER: [f64; 2] = [-CORNER_RADIUS_M, 0.0];
/// Height of the floor under the first stop.
const FLOOR_Z: f64 = -COLLAPSED_BUILDING_START_HEIGHT_M;

/// The corners of a lap given as room centres (column, row) on a grid of rooms whose (0, 0)
/// is [`FIRST_CORNER`].
fn corners_of(rooms: &[[usize; 2]]) -> Vec<[f64; 2]> {
    rooms.iter().map(|&[i, j]| room_centre(i, j)).collect()
}

fn room_centre(i: usize, j: usize) -> [f64; 2] {
    [
        FIRST_CORNER[0] + ROOM_PITCH_M * i as f64,
        FIRST_CORNER[1] + ROOM_PITCH_M * j as f64,
    ]
}

fn grid_room(rng: &mut ChaCha8Rng, i: usize, j: usize) -> Room {
    let [x, y] = room_centre(i, j);
    Room {
        min: [x - ROOM_HALF_M, y - ROOM_HALF_M],
        max: [x + ROOM_HALF_M, y + ROOM_HALF_M],
        floor: FLOOR_Z,
        height: rng.random_range(2.4..3.0),
    }
}

/// A door between neighbouring rooms `a` and `b` of the grid: air through the wall.
fn door(scene: &mut Scene, a: [usize; 2], b: [usize; 2]) {
    let (ca, cb) = (room_centre(a[0], a[1]), room_centre(b[0], b[1]));
    let mid = [0.5 * (ca[0] + cb[0]), 0.5 * (ca[1] + cb[1])];
    let along_x = a[1] == b[1];
    let (hx, hy) = if along_x {
        (0.3, DOOR_HALF_WIDTH_M)
    } else {
        (DOOR_HALF_WIDTH_M, 0.3)
    };
    scene.add_free(aabb(
        [mid[0] - hx, mid[1] - hy, FLOOR_Z],
        [mid[0] + hx, mid[1] + hy, FLOOR_Z + DOOR_HEIGHT_M],
    ));
}

/// Laps of one room round a pile in its middle.
fn room_laps(rng: &mut ChaCha8Rng) -> Result<Layout> {
    let lap = Lap::through(
        &[FIRST_CORNER, [2.4, 0.0], [2.4, 2.7], [FIRST_CORNER[0], 2.7]],
        [0.0, 0.0],
    )?;
    let room = Room {
        min: [-2.7, -1.6],
        max: [4.0, 4.3],
        floor: FLOOR_Z,
        height: rng.random_range(2.4..2.8),
    };
    let mut scene = Scene::new();
    scene.add_free(room.air());
    let laps = vec![lap];
    let tube = Tube::around(&scene, &laps);
    // The pile in the middle of the lap: blocks of rubble and a fallen cabinet.
    let centre = [0.65, 1.35];
    for _ in 0..rng.random_range(5..=8) {
        for _ in 0..20 {
            let half = [
                rng.random_range(0.1..0.4),
                rng.random_range(0.1..0.3),
                rng.random_range(0.1..0.45),
            ];
            let c = [
                centre[0] + rng.random_range(-0.7..0.7),
                centre[1] + rng.random_range(-0.4..0.4),
            ];
            let yaw = rng.random_range(-90.0..90.0);
            let block = Solid::Box(yawed_box([c[0], c[1], FLOOR_Z + half[2]], half, yaw));
            if tube.is_clear_of(&block) {
                scene.add_solid(block);
                break;
            }
        }
    }
    furnish(&mut scene, &tube, rng, &room);
    furnish(&mut scene, &tube, rng, &room);
    Ok((scene, laps, Vec::new()))
}

/// A floor of 3 × 3 rooms, toured round the outside, through the middle row and through the
/// middle column in turn.
fn floor(rng: &mut ChaCha8Rng) -> Result<Layout> {
    let laps = vec![
        Lap::through(&corners_of(&[[0, 0], [2, 0], [2, 2], [0, 2]]), [0.0, 0.0])?,
        Lap::through(&corners_of(&[[0, 0], [2, 0], [2, 1], [0, 1]]), [0.0, 0.0])?,
        Lap::through(&corners_of(&[[0, 0], [1, 0], [1, 2], [0, 2]]), [0.0, 0.0])?,
    ];
    let mut scene = Scene::new();
    let mut rooms = Vec::new();
    for j in 0..3 {
        for i in 0..3 {
            let room = grid_room(rng, i, j);
            scene.add_free(room.air());
            rooms.push(room);
        }
    }
    let doors: [([usize; 2], [usize; 2]); 12] = [
        ([0, 0], [1, 0]),
        ([1, 0], [2, 0]),
        ([2, 0], [2, 1]),
        ([2, 1], [2, 2]),
        ([2, 2], [1, 2]),
        ([1, 2], [0, 2]),
        ([0, 2], [0, 1]),
        ([0, 1], [0, 0]),
        ([2, 1], [1, 1]),
        ([1, 1], [0, 1]),
        ([1, 0], [1, 1]),
        ([1, 1], [1, 2]),
    ];
    for (a, b) in doors {
        door(&mut scene, a, b);
    }
    let tube = Tube::around(&scene, &laps);
    for room in &rooms {
        furnish(&mut scene, &tube, rng, room);
    }
    Ok((scene, laps, Vec::new()))
}

/// Two wings of 2 × 2 rooms, the second three room pitches along x from the first, joined
/// by a ditch (row 0) and a corridor (row 1).
fn wings(rng: &mut ChaCha8Rng) -> Result<Layout> {
    let laps = vec![
        Lap::through(&corners_of(&[[0, 0], [4, 0], [4, 1], [0, 1]]), [0.0, 0.0])?,
        Lap::through(&corners_of(&[[0, 0], [1, 0], [1, 1], [0, 1]]), [0.0, 0.0])?,
    ];
    let mut scene = Scene::new();
    let mut rooms = Vec::new();
    for i in [0, 1, 3, 4] {
        for j in 0..2 {
            let room = grid_room(rng, i, j);
            scene.add_free(room.air());
            rooms.push(room);
        }
    }
    for (a, b) in [
        ([0, 0], [1, 0]),
        ([1, 0], [1, 1]),
        ([1, 1], [0, 1]),
        ([0, 1], [0, 0]),
        ([3, 0], [4, 0]),
        ([4, 0], [4, 1]),
        ([4, 1], [3, 1]),
    ] {
        door(&mut scene, a, b);
    }
    // The gap between the wings' walls, and a little into each.
    let from = room_centre(1, 0)[0] + ROOM_HALF_M - 0.3;
    let to = room_centre(3, 0)[0] - ROOM_HALF_M + 0.3;
    let ditch = Room {
        min: [from, -0.55],
        max: [to, 0.55],
        floor: FLOOR_Z,
        height: 0.85,
    };
    scene.add_free(ditch.air());
    let y1 = room_centre(0, 1)[1];
    let corridor = Room {
        min: [from, y1 - 0.75],
        max: [to, y1 + 0.75],
        floor: FLOOR_Z,
        height: 2.2,
    };
    scene.add_free(corridor.air());
    let tube = Tube::around(&scene, &laps);
    for room in &rooms {
        furnish(&mut scene, &tube, rng, room);
    }
    furnish_walls(&mut scene, &tube, rng, &corridor, 4);
    add_ditch_rubble(&mut scene, &tube, rng, &ditch);
    let low_zone = [from - 0.3, -0.8, to + 0.3, 0.8];
    Ok((scene, laps, vec![low_zone]))
}

/// Rubble in the ditch: blocks at its walls, broken concrete sticking out of them, debris
/// hanging from its ceiling, flat pieces on its floor the robot drives over.
fn add_ditch_rubble(scene: &mut Scene, tube: &Tube, rng: &mut ChaCha8Rng, ditch: &Room) {
    let length = ditch.max[0] - ditch.min[0];
    for k in 0..(length / 0.25) as usize {
        let x = ditch.min[0] + 0.3 + k as f64 * 0.25;
        if x > ditch.max[0] - 0.3 {
            break;
        }
        let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let candidates = [
            // A block at a wall.
            {
                let half = [
                    rng.random_range(0.05..0.12),
                    rng.random_range(0.05..0.12),
                    rng.random_range(0.05..0.15),
                ];
                let y = side * (ditch.max[1] - rng.random_range(0.0..0.08));
                Solid::Box(yawed_box(
                    [x, y, FLOOR_Z + half[2] * 0.8],
                    half,
                    rng.random_range(-40.0..40.0),
                ))
            },
            // Concrete sticking out of the other wall.
            {
                let half = [
                    rng.random_range(0.08..0.15),
                    rng.random_range(0.1..0.2),
                    rng.random_range(0.05..0.15),
                ];
                let y = -side * (ditch.max[1] + half[1] - rng.random_range(0.03..0.14));
                let z = FLOOR_Z + rng.random_range(0.1..ditch.height);
                Solid::Box(yawed_box([x, y, z], half, rng.random_range(-20.0..20.0)))
            },
            // Debris hanging from the ceiling.
            {
                let half = [
                    rng.random_range(0.05..0.15),
                    rng.random_range(0.05..0.15),
                    rng.random_range(0.05..0.12),
                ];
                let y = rng.random_range(-ditch.max[1]..ditch.max[1]);
                let z = FLOOR_Z + ditch.height - rng.random_range(-0.05..0.12);
                Solid::Box(yawed_box([x, y, z], half, rng.random_range(-90.0..90.0)))
            },
        ];
        for solid in candidates {
            if tube.is_clear_of(&solid) {
                scene.add_solid(solid);
            }
        }
    }
}

/// The stops, `count` of them, lap after lap (the lap kinds in turn), and where each lap
/// begins.
fn place_stops(
    scene: &Scene,
    laps: &[Lap],
    low_zones: &[[f64; 4]],
    seed: u64,
    count: usize,
    lift: &LiftConfig,
) -> Result<(Vec<Stop>, Vec<usize>)> {
    let (high, low) = lift_settings(lift)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ STOPS_SALT);
    let mut stops = Vec::with_capacity(count);
    let mut lap_starts = Vec::new();
    let mut kind = 0;
    while stops.len() < count {
        let lap = &laps[kind % laps.len()];
        kind += 1;
        lap_starts.push(stops.len());
        let spacing = lap.length() / lap.stops as f64;
        for j in 0..lap.stops.min(count - stops.len()) {
            // Four draws per stop, whatever the branches below take.
            let along = rng.random_range(-ALONG_JITTER_M..ALONG_JITTER_M);
            let sideways = rng.random_range(-SIDEWAYS_JITTER_M..SIDEWAYS_JITTER_M);
            let roll_noise: f64 = rng.sample(StandardNormal);
            let pitch_noise: f64 = rng.sample(StandardNormal);
            let index = stops.len();
            let ([x, y], yaw) = lap.at(j as f64 * spacing + along);
            let xy = [x - sideways * yaw.sin(), y + sideways * yaw.cos()];
            let is_low = low_zones
                .iter()
                .any(|z| (z[0]..=z[2]).contains(&xy[0]) && (z[1]..=z[3]).contains(&xy[1]));
            let slide = if is_low { low } else { high };
            let stop = if index == 0 {
                first_stop(lift, high)?
            } else {
                let noise = TILT_JITTER_DEG.to_radians();
                place_stop(
                    scene,
                    lift,
                    (xy, yaw),
                    slide,
                    (roll_noise * noise, pitch_noise * noise),
                )
                .map_err(|e| renamed(e, index))?
            };
            check_clearance(scene, lift, &stop, index).map_err(|e| renamed(e, index))?;
            stops.push(stop);
        }
    }
    Ok((stops, lap_starts))
}

/// The stop placer's error, said of a long run.
fn renamed(error: Error, index: usize) -> Error {
    match error {
        Error::Invalid(why) => Error::Invalid(format!(
            "long_run, stop {index}: {}",
            why.trim_start_matches("collapsed_building_stops: ")
        )),
        other => other,
    }
}

impl LongRun {
    /// The true `world_from_sensor` of every stop for the lift `lift`.
    ///
    /// # Errors
    /// [`Error::Invalid`] when a stop's slide is outside the lift's range (another lift than
    /// the run was made with).
    pub fn truth(&self, lift: &LiftConfig) -> Result<Vec<sdem::geometry::Pose>> {
        self.stops
            .iter()
            .map(|s| s.world_from_sensor(lift))
            .collect()
    }

    /// Simulates the sweeps of stops `range` (in parallel), each cast in the part of the scene
    /// within the sensor's range: the same sweeps, in a fraction of the time a floor of
    /// hundreds of obstacles takes whole. Stop `i` draws its noise from
    /// `ChaCha8Rng::seed_from_u64(seed)` on stream `i`, as [`super::simulate_run`] does, so a
    /// run simulated in pieces is the run simulated at once.
    ///
    /// # Errors
    /// [`Error::Invalid`] when `sensor` is invalid, `range` runs past the stops, or a stop's
    /// slide is outside the lift's range.
    pub fn simulate(
        &self,
        sensor: &SensorConfig,
        seed: u64,
        range: std::ops::Range<usize>,
    ) -> Result<Vec<SimStop>> {
        sensor.validate()?;
        if range.end > self.stops.len() || range.start > range.end {
            return Err(Error::Invalid(format!(
                "stops {range:?} of a run of {}",
                self.stops.len()
            )));
        }
        range
            .into_par_iter()
            .map(|index| {
                let stop = &self.stops[index];
                let world_from_sensor = stop.world_from_sensor(&sensor.lift)?;
                let near = self
                    .scene
                    .cropped(&world_from_sensor.translation.vector, sensor.max_range_m);
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                rng.set_stream(index as u64);
                let sweep = scan(
                    &near,
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
}
