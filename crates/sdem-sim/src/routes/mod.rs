//! Routes that robots really drive, seeded, with truth: what `sdem bench --suite routes` maps.
//!
//! Each [`RouteKind`] is a way a stop-and-go run goes wrong for a scan matcher that trusts its
//! prediction. Every route is drawn from a seed in a [`sim::collapsed_building`] of that seed,
//! along its drivable centre line ([`sim::waypoint_stops`]): a room, a narrow ditch (the
//! corridor) and a void with a loop round a rubble pile.
//!
//! | kind | what the robot does |
//! |---|---|
//! | [`RouteKind::LongSteps`] | drives with 1–2 m between stops (fewer where the route turns: at most 30° of heading a step) |
//! | [`RouteKind::TurnAround`] | drives into the ditch, turns round (the scanner sees only its front half) and drives back out |
//! | [`RouteKind::Kidnapped`] | is carried 5 m back along the route (its odometry feels nothing), put down turned by up to 20°, and drives on over ground it mapped |
//! | [`RouteKind::HalfBlocked`] | drives on while, at one or two stops, a board 25–40 cm in front of the scanner hides half its view |
//! | [`RouteKind::Revisit`] | drives most of the route, turns round and drives all the way back: every place revisited from the other direction |
//! | [`RouteKind::SecondRun`] | a first run maps part of the route; a second run starts at an unknown place in that map, facing either way, and drives on |
//!
//! The spacing of ordinary steps, where a route turns, how far it goes, which stops are
//! blocked and on which side, where the robot is carried and where the second run starts are
//! all drawn from the seed; a draw where the robot does not fit (a track off the floor, the
//! sensor too close to a surface) is drawn again. Odometry is simulated along the true steps
//! ([`crate::odometry::simulate_odometry`]), except that a carried robot's odometry measures no
//! motion for the step it was carried.
//!
//! # Example
//! ```no_run
//! use sdem_sim::routes::{route, RouteConfig, RouteKind};
//! let r = route(RouteKind::TurnAround, 3, &RouteConfig::default())?;
//! assert!(r.run.stops.len() > 4);
//! # Ok::<(), sdem::Error>(())
//! ```

mod run;

pub use run::{
    relocalize_every_stop, run_route, truth_from_map, RelocalizationOutcome, RouteOutcome,
    RouteStopOutcome, RELOCALIZED_WITHIN_M,
};

use crate::odometry::{simulate_odometry, OdometryNoise};
use crate::sim::{self, OrientedBox, Scene, SimStop, Solid, Waypoint};
use nalgebra::Rotation3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sdem::error::{Error, Result};
use sdem::geometry::{Pose, Vec3};
use sdem::sensor::SensorConfig;
use serde::Serialize;
use std::borrow::Cow;
use std::f64::consts::PI;

/// Mixed into the seed of the routes' draws, so they do not repeat the scene's.
const ROUTE_STREAM_SALT: u64 = 0x7a0d_e5ee_d000_0022;
/// Draws of a route before giving up on one where the robot fits.
const MAX_DRAWS: usize = 40;

/// The kinds of route (see the module's table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RouteKind {
    /// 1–2 m between stops.
    LongSteps,
    /// Into the ditch, a half turn, and back out.
    TurnAround,
    /// Carried 5 m back along the route, and on over known ground.
    Kidnapped,
    /// A board in front of the scanner hides half its view at one or two stops.
    HalfBlocked,
    /// Most of the route, a half turn, and all the way back.
    Revisit,
    /// A second run started at an unknown place in the first run's map.
    SecondRun,
}

impl RouteKind {
    /// Every kind, in the order the bench reports them.
    pub const ALL: [RouteKind; 6] = [
        RouteKind::LongSteps,
        RouteKind::TurnAround,
        RouteKind::Kidnapped,
        RouteKind::HalfBlocked,
        RouteKind::Revisit,
        RouteKind::SecondRun,
    ];

    /// The name in reports.
    pub fn name(self) -> &'static str {
        match self {
            RouteKind::LongSteps => "long-steps",
            RouteKind::TurnAround => "turn-around",
            RouteKind::Kidnapped => "kidnapped",
            RouteKind::HalfBlocked => "half-blocked",
            RouteKind::Revisit => "revisit",
            RouteKind::SecondRun => "second-run",
        }
    }
}

impl std::str::FromStr for RouteKind {
    type Err = Error;

    /// The kind named `text` (as [`RouteKind::name`] gives it).
    fn from_str(text: &str) -> Result<Self> {
        RouteKind::ALL
            .into_iter()
            .find(|k| k.name() == text)
            .ok_or_else(|| {
                let known: Vec<&str> = RouteKind::ALL.iter().map(|k| k.name()).collect();
                Error::Invalid(format!(
                    "unknown route {text:?}; the routes are {}",
                    known.join(", ")
                ))
            })
    }
}

/// What happened to the robot on the way to a stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StopEvent {
    /// The first stop of a run.
    Start,
    /// An ordinary step.
    Step,
    /// A step of a metre or more.
    LongStep,
    /// The robot turned round since the last stop.
    TurnedAround,
    /// The robot was carried here (its odometry measured no motion).
    Carried,
    /// A board in front of the scanner hides half its view.
    HalfBlocked,
}

/// How routes are drawn.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RouteConfig {
    /// The scanner (default: the tilting LRF, with a compass off by σ 2°, as near steel).
    pub sensor: SensorConfig,
    /// The odometry's noise.
    pub odometry: OdometryNoise,
    /// Ordinary steps are drawn from this range, metres.
    pub step_m: (f64, f64),
    /// Long steps are drawn from this range, metres.
    pub long_step_m: (f64, f64),
    /// How far a kidnapped robot is carried, metres.
    pub carried_m: f64,
}

impl Default for RouteConfig {
    fn default() -> Self {
        Self {
            sensor: SensorConfig {
                compass_noise_deg: 2.0,
                ..Default::default()
            },
            odometry: OdometryNoise::default(),
            step_m: (0.3, 0.45),
            long_step_m: (1.0, 2.0),
            carried_m: 5.0,
        }
    }
}

/// One run of a route: the stops with their sweeps and truth, the odometry, and what happened
/// on the way to each stop.
#[derive(Debug, Clone)]
pub struct RouteRun {
    /// The stops: true `world_from_sensor` and the sweep.
    pub stops: Vec<SimStop>,
    /// The odometry's `odom_from_sensor` at each stop (dead reckoning; only the steps count).
    pub odometry: Vec<Pose>,
    /// What happened on the way to each stop.
    pub events: Vec<StopEvent>,
    /// Where each stop is on the route, metres along it, and which way it faces.
    pub waypoints: Vec<Waypoint>,
}

impl RouteRun {
    /// The true `world_from_sensor` of every stop.
    pub fn truth(&self) -> Vec<Pose> {
        self.stops.iter().map(|s| s.world_from_sensor).collect()
    }
}

/// A route with its scene: one run, or for [`RouteKind::SecondRun`] the run that makes the map
/// and the run into it.
#[derive(Debug, Clone)]
pub struct SimRoute {
    /// The kind.
    pub kind: RouteKind,
    /// The seed it was drawn from (the scene's too).
    pub seed: u64,
    /// The scene.
    pub scene: Scene,
    /// For [`RouteKind::SecondRun`]: the first run, which makes the map.
    pub map_run: Option<RouteRun>,
    /// The run.
    pub run: RouteRun,
}

/// Draws the route `kind` from `seed` in `sim::collapsed_building(seed)`.
///
/// # Errors
/// [`Error::Invalid`] for an invalid sensor or odometry noise, or when no draw of the route
/// fits the scene.
pub fn route(kind: RouteKind, seed: u64, config: &RouteConfig) -> Result<SimRoute> {
    config.sensor.validate()?;
    config.odometry.validate()?;
    let scene = sim::collapsed_building(seed);
    let length = sim::route_length_m(&scene).expect("a collapsed building has a route");
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ ROUTE_STREAM_SALT);
    let mut last_error = None;
    for draw in 0..MAX_DRAWS {
        let plan = draw_plan(kind, &scene, length, config, &mut rng);
        match build(kind, seed, &scene, &plan, config, draw as u64) {
            Ok(route) => return Ok(route),
            Err(e) => last_error = Some(e),
        }
    }
    Err(Error::Invalid(format!(
        "route {}: no draw of {MAX_DRAWS} fits the scene of seed {seed} (last: {})",
        kind.name(),
        last_error.map_or_else(String::new, |e| e.to_string())
    )))
}

/// The waypoints of one run and what happened on the way to each.
#[derive(Debug, Clone, Default)]
struct RunPlan {
    waypoints: Vec<Waypoint>,
    events: Vec<StopEvent>,
    /// Per stop with a board: the side it hides (+1 left, −1 right) and its distance, metres.
    boards: Vec<Option<(f64, f64)>>,
}

impl RunPlan {
    fn push(&mut self, waypoint: Waypoint, event: StopEvent) {
        self.waypoints.push(waypoint);
        self.events.push(event);
        self.boards.push(None);
    }
}

/// The runs of a route: the map run (second run only) and the run.
struct Plan {
    map_run: Option<RunPlan>,
    run: RunPlan,
}

fn draw_plan(
    kind: RouteKind,
    scene: &Scene,
    length: f64,
    config: &RouteConfig,
    rng: &mut ChaCha8Rng,
) -> Plan {
    let step = |rng: &mut ChaCha8Rng| rng.random_range(config.step_m.0..=config.step_m.1);
    let run = match kind {
        RouteKind::LongSteps => long_steps(scene, length, config, rng),
        RouteKind::TurnAround => {
            // The ditch runs from 1 m to about 4–4.5 m along the route.
            let turn = rng.random_range(2.2..3.6);
            let mut plan = drive(0.0, turn, true, StopEvent::Start, rng, &step);
            let back = (turn - rng.random_range(0.0..0.3)).max(0.0);
            plan.push(Waypoint::backward(back), StopEvent::TurnedAround);
            extend(&mut plan, back, 0.0, false, rng, &step);
            plan
        }
        RouteKind::Kidnapped => {
            // Carried back along the route to a place it mapped, put down facing on (turned by
            // up to 20°), and driving on over known ground.
            let from =
                rng.random_range(config.carried_m + 0.5..(config.carried_m + 3.0).min(length));
            let to = from - config.carried_m;
            let mut plan = drive(0.0, from, true, StopEvent::Start, rng, &step);
            let turn = rng.random_range(-20f64..20.0).to_radians();
            plan.push(
                Waypoint {
                    along_m: to,
                    heading_offset: turn,
                },
                StopEvent::Carried,
            );
            let end = (from + rng.random_range(0.5..1.5)).min(length);
            extend(&mut plan, to, end, true, rng, &step);
            plan
        }
        RouteKind::HalfBlocked => {
            let end = rng.random_range(0.45..0.6) * length;
            let mut plan = drive(0.0, end, true, StopEvent::Start, rng, &step);
            let n = plan.waypoints.len();
            let blocked = rng.random_range(1..=2usize);
            for _ in 0..blocked {
                let i = rng.random_range(2..n);
                let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                plan.boards[i] = Some((side, rng.random_range(0.25..0.4)));
                plan.events[i] = StopEvent::HalfBlocked;
            }
            plan
        }
        RouteKind::Revisit => {
            let end = rng.random_range(0.7..0.95) * length;
            let mut plan = drive(0.0, end, true, StopEvent::Start, rng, &step);
            let back = (end - rng.random_range(0.0..0.3)).max(0.0);
            plan.push(Waypoint::backward(back), StopEvent::TurnedAround);
            extend(&mut plan, back, 0.0, false, rng, &step);
            plan
        }
        RouteKind::SecondRun => {
            let mapped = rng.random_range(0.55..0.75) * length;
            let first = drive(0.0, mapped, true, StopEvent::Start, rng, &step);
            let start = rng.random_range(1.0..mapped - 1.0);
            let forward = rng.random_bool(0.5);
            let jitter = rng.random_range(-10f64..10.0).to_radians();
            let mut run = RunPlan::default();
            let (w, end) = if forward {
                (Waypoint::forward(start), (start + 4.0).min(length))
            } else {
                (Waypoint::backward(start), (start - 4.0).max(0.0))
            };
            run.push(
                Waypoint {
                    heading_offset: w.heading_offset + jitter,
                    ..w
                },
                StopEvent::Start,
            );
            extend(&mut run, start, end, forward, rng, &step);
            return Plan {
                map_run: Some(first),
                run,
            };
        }
    };
    Plan { map_run: None, run }
}

/// A run from `from` to `to` along the route (forward or backward), its first stop `first`.
fn drive(
    from: f64,
    to: f64,
    forward: bool,
    first: StopEvent,
    rng: &mut ChaCha8Rng,
    step: &dyn Fn(&mut ChaCha8Rng) -> f64,
) -> RunPlan {
    let mut plan = RunPlan::default();
    let w = if forward {
        Waypoint::forward(from)
    } else {
        Waypoint::backward(from)
    };
    plan.push(w, first);
    extend(&mut plan, from, to, forward, rng, step);
    plan
}

/// Ordinary steps from `from` (not included) until `to` is reached.
fn extend(
    plan: &mut RunPlan,
    from: f64,
    to: f64,
    forward: bool,
    rng: &mut ChaCha8Rng,
    step: &dyn Fn(&mut ChaCha8Rng) -> f64,
) {
    let mut s = from;
    loop {
        let d = step(rng);
        let remaining = (to - s).abs();
        if remaining < 0.05 {
            break;
        }
        let d = if remaining < d + 0.5 * d {
            remaining
        } else {
            d
        };
        s = if forward { s + d } else { s - d };
        plan.push(
            if forward {
                Waypoint::forward(s)
            } else {
                Waypoint::backward(s)
            },
            StopEvent::Step,
        );
    }
}

/// Steps drawn from `config.long_step_m`, cut where the route would turn more than 30° in one.
fn long_steps(scene: &Scene, length: f64, config: &RouteConfig, rng: &mut ChaCha8Rng) -> RunPlan {
    const MAX_TURN: f64 = 30.0 * PI / 180.0;
    let mut plan = RunPlan::default();
    plan.push(Waypoint::forward(0.0), StopEvent::Start);
    let end = rng.random_range(0.85..1.0) * length;
    let heading = |s: f64| sim::route_at(scene, s).map_or(0.0, |(_, yaw)| yaw);
    let mut s = 0.0;
    while s < end - 0.3 {
        let mut d = rng.random_range(config.long_step_m.0..=config.long_step_m.1);
        d = d.min(end - s);
        // Shorten the step until the route turns at most MAX_TURN over it.
        while d > 0.3 && turn_between(&heading, s, s + d) > MAX_TURN {
            d *= 0.8;
        }
        s += d;
        let event = if d >= 1.0 {
            StopEvent::LongStep
        } else {
            StopEvent::Step
        };
        plan.push(Waypoint::forward(s), event);
    }
    plan
}

/// The largest heading change of the route between `a` and `b` (sampled every 5 cm), radians.
fn turn_between(heading: &dyn Fn(f64) -> f64, a: f64, b: f64) -> f64 {
    let h0 = heading(a);
    let n = ((b - a) / 0.05).ceil().max(1.0) as usize;
    (0..=n)
        .map(|k| sim_wrap(heading(a + (b - a) * k as f64 / n as f64) - h0).abs())
        .fold(0.0, f64::max)
}

fn sim_wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

fn build(
    kind: RouteKind,
    seed: u64,
    scene: &Scene,
    plan: &Plan,
    config: &RouteConfig,
    draw: u64,
) -> Result<SimRoute> {
    let map_run = match &plan.map_run {
        Some(p) => Some(simulate(scene, p, config, seed, draw, 1)?),
        None => None,
    };
    let run = simulate(scene, &plan.run, config, seed, draw, 0)?;
    Ok(SimRoute {
        kind,
        seed,
        scene: scene.clone(),
        map_run,
        run,
    })
}

/// Simulates one run of `plan`: stops, sweeps (with boards where planned) and odometry.
fn simulate(
    scene: &Scene,
    plan: &RunPlan,
    config: &RouteConfig,
    seed: u64,
    draw: u64,
    run_index: u64,
) -> Result<RouteRun> {
    let stream = seed
        .wrapping_mul(31)
        .wrapping_add(draw * 7 + run_index)
        .wrapping_add(ROUTE_STREAM_SALT);
    let stops = sim::waypoint_stops(scene, stream, &plan.waypoints, &config.sensor.lift)?;
    let poses: Vec<Pose> = stops
        .iter()
        .map(|s| s.world_from_sensor(&config.sensor.lift))
        .collect::<Result<_>>()?;
    let blocked: Vec<Option<Scene>> = plan
        .boards
        .iter()
        .zip(&poses)
        .map(|(board, pose)| board.map(|(side, d)| with_board(scene, pose, side, d)))
        .collect();
    let sim_stops = sim::simulate_changing_run(&stops, &config.sensor, stream, |i| {
        blocked[i]
            .as_ref()
            .map_or(Cow::Borrowed(scene), Cow::Borrowed)
    })?;
    let odometry = odometry_of(&poses, &plan.events, &config.odometry, stream)?;
    Ok(RouteRun {
        stops: sim_stops,
        odometry,
        events: plan.events.clone(),
        waypoints: plan.waypoints.clone(),
    })
}

/// `scene` with a board (1 m wide, 1.2 m high) `distance_m` in front of the sensor at
/// `world_from_sensor`, covering the half of its view on `side` (+1 left, −1 right).
fn with_board(scene: &Scene, world_from_sensor: &Pose, side: f64, distance_m: f64) -> Scene {
    let yaw = sdem::geometry::attitude_of(world_from_sensor).yaw;
    let turn = Rotation3::from_axis_angle(&Vec3::z_axis(), yaw);
    let centre =
        world_from_sensor.translation.vector + turn * Vec3::new(distance_m, side * 0.5, 0.0);
    let mut blocked = scene.clone();
    let board = OrientedBox::new(centre, Vec3::new(0.01, 0.5, 0.6), turn)
        .expect("a board's extents are positive");
    blocked.add_solid(Solid::Box(board));
    blocked
}

/// Dead reckoning along the true steps, except that a carried step measures no motion.
fn odometry_of(
    poses: &[Pose],
    events: &[StopEvent],
    noise: &OdometryNoise,
    seed: u64,
) -> Result<Vec<Pose>> {
    let mut felt = Vec::with_capacity(poses.len());
    for (i, pose) in poses.iter().enumerate() {
        if i == 0 {
            felt.push(*pose);
            continue;
        }
        let step = if events[i] == StopEvent::Carried {
            Pose::identity()
        } else {
            poses[i - 1].inverse() * pose
        };
        let previous: Pose = *felt.last().expect("the first pose was pushed");
        felt.push(previous * step);
    }
    simulate_odometry(&felt, noise, seed)
}

#[cfg(test)]
mod tests;
