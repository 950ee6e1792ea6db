//! Faults of a disaster site, injected into simulated scans, and the pairs that measure them.
//!
//! A collapsed building is hard on sensors. Each [`Fault`] is one thing that goes wrong there,
//! modelled in the simulator with the sizes of [`FaultConfig`]:
//!
//! | fault | what the simulator does |
//! |---|---|
//! | [`Fault::Compass`] | the query's heading reading is off by up to ±20° (steel in the rubble) |
//! | [`Fault::GyroDrift`] | the query's roll and pitch readings are off by up to ±2° (the gyro drifted since it was last levelled) |
//! | [`Fault::Dust`] | 5 % of the beams of both scans return from dust in the air, anywhere between the sensor and the surface |
//! | [`Fault::Missing`] | 30 % of the returns of both scans are lost, in runs of up to 20 beams (dark, wet or glancing surfaces) |
//! | [`Fault::Tilt`] | the robot stands on rubble with roll and pitch up to ±30° at the query |
//! | [`Fault::Rubble`] | three pieces of rubble (0.2–0.6 m blocks) in view were moved 0.2–0.5 m between the two scans |
//! | [`Fault::Person`] | a person (1.7 m tall; crawling where there is no headroom) moves 1.5 m through the query's view while it sweeps |
//!
//! [`fault_pairs`] draws seeded pairs like [`crate::benchmark::bench_pairs`] (a reference at a
//! stop of [`sim::collapsed_building`], a query within ±0.5 m of it, turned up to ±15°) with any
//! set of faults, and the robot's prior for the query: the true motion with a 5 % odometry error
//! (tracks slip on rubble). [`localize_config`] is how sdem localizes such a pair in the field: a
//! ±0.15 m (±0.08 m in height) window around the prior and headings within ±25° of the compass,
//! because the robot cannot tell a disturbed compass from a good one. `sdem bench --faults`
//! prints the success rate and errors per fault and for all faults together.
//!
//! [`sim::collapsed_building`]: crate::sim::collapsed_building
//!
//! # Example
//! ```
//! use sdem_sim::faults::{fault_pairs, Fault, FaultConfig};
//! let mut config = FaultConfig::default();
//! // A coarse sweep keeps the example quick.
//! config.pairs.sensor.tilt_step_deg = 3.0;
//! config.pairs.sensor.pan_step_deg = 3.0;
//! let pairs = fault_pairs(7, 2, &[Fault::Dust, Fault::Person], &config)?;
//! assert_eq!(pairs.len(), 2);
//! assert!(pairs[0].injected.dust_returns > 0);
//! # Ok::<(), sdem::Error>(())
//! ```

mod inject;
mod pairs;
mod run;
#[cfg(test)]
mod tests;

pub use inject::{add_dust, add_walking_person, drop_returns, WalkingPerson};
pub use pairs::{
    fault_pair, fault_pairs, localize_config, localize_fault_pair, FaultPair, MIN_PRIOR_SIGMA_M,
};
pub use run::{simulate_run_with_faults, TILT_NOT_INJECTED};

use crate::benchmark::PairConfig;
use sdem::error::{Error, Result};
use sdem::localize::HeadingWindow;
use std::fmt;
use std::str::FromStr;

/// Mixed into the seed of the fault pairs' random streams.
pub(super) const FAULT_STREAM_SALT: u64 = 0xfa17_5eed_0000_0006;

/// One thing that goes wrong at a disaster site.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Fault {
    /// The compass is disturbed by steel: the heading reading is off.
    Compass,
    /// The gyro drifted: the roll and pitch readings are off.
    GyroDrift,
    /// Dust in the air returns some beams early.
    Dust,
    /// Many returns are lost (dark, wet or glancing surfaces).
    Missing,
    /// The robot stands steeply tilted on rubble.
    Tilt,
    /// Rubble was moved between the scans.
    Rubble,
    /// A person walks through the scan.
    Person,
}

impl Fault {
    /// Every fault, in the order the bench reports them.
    pub const ALL: [Fault; 7] = [
        Fault::Compass,
        Fault::GyroDrift,
        Fault::Dust,
        Fault::Missing,
        Fault::Tilt,
        Fault::Rubble,
        Fault::Person,
    ];

    /// The name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Fault::Compass => "compass",
            Fault::GyroDrift => "gyro-drift",
            Fault::Dust => "dust",
            Fault::Missing => "missing",
            Fault::Tilt => "tilt",
            Fault::Rubble => "rubble",
            Fault::Person => "person",
        }
    }

    /// One line on what the simulator does, with the sizes of `config`.
    pub fn describe(self, config: &FaultConfig) -> String {
        match self {
            Fault::Compass => format!(
                "heading reading off by up to ±{}°",
                config.compass_error_max_deg
            ),
            Fault::GyroDrift => format!(
                "roll and pitch readings off by up to ±{}°",
                config.gyro_error_max_deg
            ),
            Fault::Dust => format!(
                "{} % of beams return from dust",
                config.dust_fraction * 100.0
            ),
            Fault::Missing => format!(
                "{} % of returns lost, in runs of up to {} beams",
                config.missing_fraction * 100.0,
                config.missing_run_max
            ),
            Fault::Tilt => format!("robot tilted up to ±{}°", config.tilt_max_deg),
            Fault::Rubble => format!(
                "{} pieces of rubble moved {}–{} m",
                config.rubble_pieces, config.rubble_move_min_m, config.rubble_move_max_m
            ),
            Fault::Person => format!("a person walks {} m through the scan", config.person_walk_m),
        }
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Fault {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        Fault::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Fault::ALL.iter().map(|f| f.name()).collect();
                Error::Invalid(format!(
                    "unknown fault '{s}'; the faults are {}",
                    names.join(", ")
                ))
            })
    }
}

/// The sizes of the faults, the pairs they are injected into and how the robot localizes.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultConfig {
    /// The pairs without faults: windows, spreads, sensor. The default is
    /// [`PairConfig::default`] with no compass error of its own (faults add it).
    pub pairs: PairConfig,
    /// [`Fault::Compass`]: the heading reading is off by a uniform error within ± this, degrees.
    pub compass_error_max_deg: f64,
    /// [`Fault::GyroDrift`]: roll and pitch readings off by uniform errors within ± this, degrees.
    pub gyro_error_max_deg: f64,
    /// [`Fault::Dust`]: the fraction of beams that return from dust.
    pub dust_fraction: f64,
    /// [`Fault::Missing`]: the fraction of returns lost.
    pub missing_fraction: f64,
    /// [`Fault::Missing`]: returns are lost in runs along the scan line of 1 to this many beams.
    pub missing_run_max: usize,
    /// [`Fault::Tilt`]: the query's roll and pitch are uniform within ± this, degrees.
    pub tilt_max_deg: f64,
    /// [`Fault::Rubble`]: pieces moved between the scans.
    pub rubble_pieces: usize,
    /// [`Fault::Rubble`]: each piece moves at least this far, metres.
    pub rubble_move_min_m: f64,
    /// [`Fault::Rubble`]: … and at most this far, metres.
    pub rubble_move_max_m: f64,
    /// [`Fault::Person`]: how far the person walks during the sweep, metres.
    pub person_walk_m: f64,
    /// The prior's error: a random direction, this fraction of the true motion's length.
    pub odometry_error_fraction: f64,
    /// The search window's half-size around the prior, metres.
    pub window_half_m: [f64; 3],
    /// Headings searched around the compass reading, degrees.
    pub heading_half_range_deg: f64,
    /// The search's grid step, metres (the refinement goes below it).
    pub step_m: f64,
}

impl Default for FaultConfig {
    fn default() -> Self {
        Self {
            pairs: PairConfig {
                compass_error_max_deg: 0.0,
                ..PairConfig::default()
            },
            compass_error_max_deg: 20.0,
            gyro_error_max_deg: 2.0,
            dust_fraction: 0.05,
            missing_fraction: 0.30,
            missing_run_max: 20,
            tilt_max_deg: 30.0,
            rubble_pieces: 3,
            rubble_move_min_m: 0.2,
            rubble_move_max_m: 0.5,
            person_walk_m: 1.5,
            odometry_error_fraction: 0.05,
            window_half_m: [0.15, 0.15, 0.08],
            heading_half_range_deg: 25.0,
            step_m: 0.02,
        }
    }
}

impl FaultConfig {
    /// Checks every field; the message names the field.
    ///
    /// # Errors
    /// [`Error::Invalid`] for a value out of its range.
    pub fn validate(&self) -> Result<()> {
        self.pairs.validate()?;
        let non_negative = [
            ("compass_error_max_deg", self.compass_error_max_deg),
            ("gyro_error_max_deg", self.gyro_error_max_deg),
            ("tilt_max_deg", self.tilt_max_deg),
            ("rubble_move_min_m", self.rubble_move_min_m),
            ("rubble_move_max_m", self.rubble_move_max_m),
            ("person_walk_m", self.person_walk_m),
            ("odometry_error_fraction", self.odometry_error_fraction),
            ("window_half_m[0]", self.window_half_m[0]),
            ("window_half_m[1]", self.window_half_m[1]),
            ("window_half_m[2]", self.window_half_m[2]),
        ];
        for (name, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(Error::Invalid(format!(
                    "faults: {name} is {value}; it must be a finite number >= 0"
                )));
            }
        }
        for (name, value) in [
            ("dust_fraction", self.dust_fraction),
            ("missing_fraction", self.missing_fraction),
        ] {
            if !(0.0..1.0).contains(&value) {
                return Err(Error::Invalid(format!(
                    "faults: {name} is {value}; it must be in [0, 1)"
                )));
            }
        }
        if self.compass_error_max_deg >= 180.0 || self.tilt_max_deg >= 90.0 {
            return Err(Error::Invalid(
                "faults: compass_error_max_deg must be below 180 and tilt_max_deg below 90".into(),
            ));
        }
        if self.gyro_error_max_deg >= 45.0 {
            return Err(Error::Invalid(
                "faults: gyro_error_max_deg must be below 45".into(),
            ));
        }
        if self.rubble_move_min_m > self.rubble_move_max_m {
            return Err(Error::Invalid(
                "faults: rubble_move_min_m must not exceed rubble_move_max_m".into(),
            ));
        }
        if self.missing_run_max == 0 {
            return Err(Error::Invalid(
                "faults: missing_run_max must be >= 1".into(),
            ));
        }
        if !(self.step_m.is_finite() && self.step_m > 0.0) {
            return Err(Error::Invalid(format!(
                "faults: step_m {} must be a positive number",
                self.step_m
            )));
        }
        HeadingWindow {
            half_range_deg: self.heading_half_range_deg,
            step_deg: None,
        }
        .validate()
    }
}

/// What was injected into one pair, for the report and the tests.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Injected {
    /// Beams of both scans that return from dust.
    pub dust_returns: usize,
    /// Returns of both scans that were lost.
    pub lost_returns: usize,
    /// Returns of the query on the walking person.
    pub person_returns: usize,
    /// Returns of both scans on the moved rubble.
    pub rubble_returns: usize,
    /// The compass error added to the query's heading reading, degrees.
    pub compass_error_deg: f64,
    /// The errors added to the query's roll and pitch readings, degrees.
    pub gyro_error_deg: [f64; 2],
}

/// What was injected, in words: only what the pair has (`nothing injected` for a clean pair).
impl std::fmt::Display for Injected {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut parts = Vec::new();
        for (count, what) in [
            (self.dust_returns, "returns from dust"),
            (self.lost_returns, "returns lost"),
            (self.person_returns, "returns on a walking person"),
            (self.rubble_returns, "returns on moved rubble"),
        ] {
            if count > 0 {
                parts.push(format!("{count} {what}"));
            }
        }
        if self.compass_error_deg != 0.0 {
            parts.push(format!("compass off {:+.1}°", self.compass_error_deg));
        }
        if self.gyro_error_deg != [0.0; 2] {
            let [roll, pitch] = self.gyro_error_deg;
            parts.push(format!("roll off {roll:+.2}°, pitch {pitch:+.2}°"));
        }
        if parts.is_empty() {
            f.write_str("nothing injected")
        } else {
            write!(f, "injected: {}", parts.join(", "))
        }
    }
}
