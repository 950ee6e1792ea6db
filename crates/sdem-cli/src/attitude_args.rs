//! The attitude at the command line (`sdem localize`, `sdem slam`): the readings' standard
//! deviations (`--attitude-sigma-deg`), `--assume-level`, `--heading-window`, the attitudes
//! given to the library, and what was assumed, in figures and words.

use crate::output::degrees;
use anyhow::{bail, Result};
use sdem::geometry::{Attitude, AttitudeSigma};
use sdem_io::Dataset;
use serde::Serialize;
use std::path::Path;

/// The attitude flags of `sdem localize`, checked.
pub struct AttitudeFlags {
    /// `--attitude-sigma-deg`: the σ of both readings, over the dataset's.
    pub sigma: Option<AttitudeSigma>,
    /// `--assume-level`: without attitude.csv, take both scans as level.
    pub assume_level: bool,
    /// `--heading-window`: the heading range instead of the σ's.
    pub heading_window_deg: Option<f64>,
}

/// A clap value parser: `--attitude-sigma-deg ROLL_PITCH,YAW` (degrees), checked as
/// sensor.toml's σ is; the message does not name the flag (clap's does).
pub fn attitude_sigma(text: &str) -> std::result::Result<AttitudeSigma, String> {
    let [rp, yaw] = crate::parse::numbers(text, "ROLL_PITCH,YAW (standard deviations in degrees)")?;
    sdem_io::attitude_sigma_from_degrees(rp, yaw, "the roll/pitch σ", "the heading σ")
}

/// Where the attitudes of a localization come from.
#[derive(Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AttitudeKind {
    /// The gyro/compass readings of attitude.csv.
    Readings,
    /// No attitude.csv, and `--assume-level`: both scans taken as level.
    AssumedLevel,
    /// No attitude.csv: the rotation is searched.
    Unknown,
}

/// The attitudes given to the localization, and where they come from.
pub struct Attitudes {
    /// Readings, assumed level, or unknown.
    pub kind: AttitudeKind,
    /// The reference's, `None` when unknown.
    pub reference: Option<Attitude>,
    /// The query's, `None` when unknown.
    pub query: Option<Attitude>,
    /// Where their σ comes from, in words.
    pub sigma_from: &'static str,
    /// `--heading-window`, when given: the heading range instead of the σ's.
    pub heading_window_deg: Option<f64>,
}

/// The two scans' attitudes: the dataset's readings (with `--attitude-sigma-deg`'s σ when
/// given), the level attitude with `--assume-level`, or unknown. Flags that need readings are
/// refused without them.
pub fn attitudes_of(
    dataset: &Dataset,
    dataset_path: &Path,
    (reference_index, query_index): (usize, usize),
    flags: &AttitudeFlags,
) -> Result<Attitudes> {
    let sigma = flags.sigma;
    let has_readings = dataset.attitudes.is_some();
    if flags.assume_level && has_readings {
        bail!(
            "--assume-level: {} has attitude.csv, whose readings are used; drop --assume-level",
            dataset_path.display()
        );
    }
    let no_readings = |flag: &str| {
        anyhow::anyhow!(
            "{flag}: {} has no attitude.csv, so there is no compass reading to search around \
             (the attitude is unknown and searched in full); add attitude.csv, or give \
             --assume-level to take the scans as level",
            dataset_path.display()
        )
    };
    if !has_readings && !flags.assume_level {
        if flags.heading_window_deg.is_some() {
            return Err(no_readings("--heading-window"));
        }
        if sigma.is_some() {
            return Err(no_readings("--attitude-sigma-deg"));
        }
    }
    let (kind, reading_of): (AttitudeKind, &dyn Fn(usize) -> Option<Attitude>) = if has_readings {
        (AttitudeKind::Readings, &|i| dataset.attitude(i))
    } else if flags.assume_level {
        (AttitudeKind::AssumedLevel, &|i| {
            dataset.attitude_or_level(i)
        })
    } else {
        (AttitudeKind::Unknown, &|_| None)
    };
    let with_sigma = |a: Attitude| Attitude {
        sigma: sigma.unwrap_or(a.sigma),
        ..a
    };
    let sigma_from = if sigma.is_some() {
        "--attitude-sigma-deg"
    } else {
        match (kind, dataset.attitude_sigma_from) {
            (AttitudeKind::Unknown, _) => "",
            (_, from) => from.describe(),
        }
    };
    Ok(Attitudes {
        kind,
        reference: reading_of(reference_index).map(with_sigma),
        query: reading_of(query_index).map(with_sigma),
        sigma_from,
        heading_window_deg: flags.heading_window_deg,
    })
}

/// A reading as the JSON shows it: degrees.
#[derive(Serialize)]
struct ReadingRecord {
    roll_deg: f64,
    pitch_deg: f64,
    yaw_deg: f64,
    sigma_roll_pitch_deg: f64,
    sigma_yaw_deg: f64,
}

impl From<&Attitude> for ReadingRecord {
    fn from(a: &Attitude) -> Self {
        let [roll_deg, pitch_deg, yaw_deg] = a.to_degrees();
        Self {
            roll_deg,
            pitch_deg,
            yaw_deg,
            sigma_roll_pitch_deg: a.sigma.roll_pitch.to_degrees(),
            sigma_yaw_deg: a.sigma.yaw.to_degrees(),
        }
    }
}

/// What a localization assumed about the attitudes, for the JSON (`attitude`) and in words.
#[derive(Serialize)]
pub struct AttitudeAssumption {
    /// `readings` (attitude.csv), `assumed_level` (--assume-level) or `unknown` (searched).
    pub source: AttitudeKind,
    /// The reference's reading with its σ; null when unknown.
    reference: Option<ReadingRecord>,
    /// The query's reading with its σ; null when unknown.
    query: Option<ReadingRecord>,
    /// Where the σ comes from: `attitude.csv`, `sensor.toml`, `the default`,
    /// `--attitude-sigma-deg`; null when the attitude is unknown.
    sigma_from: Option<&'static str>,
    /// The heading searched, ± degrees around the readings' difference (180: any heading).
    heading_searched_deg: f64,
    /// Why that range: `compass_sigma` (3σ of the readings' difference), `heading_window`
    /// (--heading-window), `unknown_attitude` (any heading).
    heading_searched_from: &'static str,
    /// Whether roll and pitch were searched too (the attitude is unknown); otherwise they
    /// come from the readings and the refinement corrects them.
    roll_pitch_searched: bool,
    /// All of it in words.
    pub summary: String,
}

/// The heading range `sdem::localize` searches for two readings: three standard deviations of
/// their difference, at most a full turn (its documentation says so).
fn heading_half_range_deg(reference: &Attitude, query: &Attitude) -> f64 {
    (3.0 * reference.sigma.yaw.hypot(query.sigma.yaw).to_degrees()).min(180.0)
}

/// What was assumed about the attitudes, with the heading range searched, in figures and words.
pub fn attitude_assumption(attitudes: &Attitudes) -> AttitudeAssumption {
    let (Some(r), Some(q)) = (attitudes.reference, attitudes.query) else {
        return AttitudeAssumption {
            source: attitudes.kind,
            reference: None,
            query: None,
            sigma_from: None,
            heading_searched_deg: 180.0,
            heading_searched_from: "unknown_attitude",
            roll_pitch_searched: true,
            summary: "unknown (no attitude.csv): roll/pitch and heading searched".to_string(),
        };
    };
    let origin = match attitudes.kind {
        AttitudeKind::AssumedLevel => "assumed level (--assume-level)",
        _ => "from attitude.csv",
    };
    let sigma = |s: fn(&Attitude) -> f64| {
        let (a, b) = (s(&r).to_degrees(), s(&q).to_degrees());
        if (a - b).abs() < 1e-9 {
            format!("{}°", degrees(a))
        } else {
            format!("{}° and {}°", degrees(a), degrees(b))
        }
    };
    let compass = format!(
        "compass σ {}, roll/pitch σ {} ({})",
        sigma(|a| a.sigma.yaw),
        sigma(|a| a.sigma.roll_pitch),
        attitudes.sigma_from
    );
    let (half, from, heading) = match attitudes.heading_window_deg {
        Some(0.0) => (
            0.0,
            "heading_window",
            "heading taken from the compass (--heading-window 0)".to_string(),
        ),
        Some(w) => (
            w,
            "heading_window",
            format!("heading searched ±{}° (--heading-window)", degrees(w)),
        ),
        None => {
            let half = heading_half_range_deg(&r, &q);
            let words = if half >= 180.0 {
                "heading searched over a full turn (3σ of the readings' difference reaches 180°)"
                    .to_string()
            } else if attitudes.kind == AttitudeKind::AssumedLevel {
                format!(
                    "heading searched ±{}° (3σ of the difference of the two headings assumed)",
                    degrees(half)
                )
            } else {
                format!(
                    "heading searched ±{}° (3σ of the two readings' difference)",
                    degrees(half)
                )
            };
            (half, "compass_sigma", words)
        }
    };
    AttitudeAssumption {
        source: attitudes.kind,
        reference: Some(ReadingRecord::from(&r)),
        query: Some(ReadingRecord::from(&q)),
        sigma_from: Some(attitudes.sigma_from),
        heading_searched_deg: half,
        heading_searched_from: from,
        roll_pitch_searched: false,
        summary: format!("{origin}, {compass}: {heading}"),
    }
}
