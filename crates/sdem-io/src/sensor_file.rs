//! `sensor.toml`: the sensor model and the attitude readings' uncertainty.
//!
//! The sensor model's keys are those of [`SensorConfig`]; two more keys state how far the
//! gyro/compass readings of `attitude.csv` can be off ([`AttitudeSigma`]), which sets how far
//! `sdem::localize` searches around them. They are read here, beside the sensor model, because
//! they describe the same hardware; they are not part of [`SensorConfig`], whose noise fields
//! (`tilt_sensor_noise_deg`, `compass_noise_deg`) are what the simulator adds to its readings.

use super::{at_named_key, count_newlines, fmt_f64, read_text, toml_error, write_atomic};
use crate::error::{Error, Result};
use sdem::geometry::AttitudeSigma;
use sdem::sensor::SensorConfig;
use serde::Deserialize;
use std::path::Path;

/// The `sensor.toml` key of the standard deviation of the roll and the pitch readings, degrees.
pub const ATTITUDE_SIGMA_ROLL_PITCH_KEY: &str = "attitude_sigma_roll_pitch_deg";
/// The `sensor.toml` key of the standard deviation of the compass heading (yaw) reading, degrees.
pub const ATTITUDE_SIGMA_YAW_KEY: &str = "attitude_sigma_yaw_deg";
/// The largest standard deviation of roll or pitch, degrees: beyond it the reading says nothing
/// about the tilt (a value above is not in degrees, or not a σ).
pub const MAX_ATTITUDE_SIGMA_ROLL_PITCH_DEG: f64 = 90.0;
/// The largest standard deviation of the heading, degrees: 180 says that the compass tells
/// nothing (the heading is searched over a full turn).
pub const MAX_ATTITUDE_SIGMA_YAW_DEG: f64 = 180.0;

/// What `sensor.toml` holds: the sensor model and, when the file states it, the attitude
/// readings' standard deviations.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SensorFile {
    /// The sensor model.
    pub sensor: SensorConfig,
    /// The standard deviations of the gyro/compass readings, when the file states at least one
    /// of them (the other takes [`AttitudeSigma::default`]'s); `None` when it states neither.
    pub attitude_sigma: Option<AttitudeSigma>,
}

/// Checks one standard deviation of an attitude reading, degrees; `name` says which in the
/// message. Returns the problem in words, or `None` when it is a positive number within the
/// bound ([`MAX_ATTITUDE_SIGMA_ROLL_PITCH_DEG`] for roll and pitch,
/// [`MAX_ATTITUDE_SIGMA_YAW_DEG`] for the heading).
fn sigma_problem(name: &str, value_deg: f64, max_deg: f64, default_deg: f64) -> Option<String> {
    if value_deg.is_finite() && value_deg > 0.0 && value_deg <= max_deg {
        return None;
    }
    let what = if value_deg.is_finite() && value_deg > max_deg {
        format!("is more than {max_deg}°, which says nothing about the reading (degrees?)")
    } else if value_deg == 0.0 {
        "is zero: no reading is exact; give a small positive number (0.1)".to_string()
    } else {
        "must be a positive number of degrees".to_string()
    };
    Some(format!(
        "{name} {value_deg} {what}; the default is {default_deg}°"
    ))
}

/// The standard deviations of an attitude reading from degrees, checked: both positive and
/// finite, roll/pitch at most [`MAX_ATTITUDE_SIGMA_ROLL_PITCH_DEG`], the heading at most
/// [`MAX_ATTITUDE_SIGMA_YAW_DEG`]. The error says which value is wrong and why, in words, with
/// `roll_pitch_name` and `yaw_name` naming the two values (a file's keys or columns, a flag).
///
/// # Example
/// ```
/// let sigma = sdem_io::attitude_sigma_from_degrees(0.2, 20.0, "roll/pitch σ", "yaw σ").unwrap();
/// assert!((sigma.yaw.to_degrees() - 20.0).abs() < 1e-12);
/// let why = sdem_io::attitude_sigma_from_degrees(-1.0, 20.0, "roll/pitch σ", "yaw σ").unwrap_err();
/// assert!(why.contains("roll/pitch σ -1 must be a positive number"));
/// ```
pub fn attitude_sigma_from_degrees(
    roll_pitch_deg: f64,
    yaw_deg: f64,
    roll_pitch_name: &str,
    yaw_name: &str,
) -> std::result::Result<AttitudeSigma, String> {
    let default = AttitudeSigma::default();
    let problems = [
        sigma_problem(
            roll_pitch_name,
            roll_pitch_deg,
            MAX_ATTITUDE_SIGMA_ROLL_PITCH_DEG,
            default.roll_pitch.to_degrees(),
        ),
        sigma_problem(
            yaw_name,
            yaw_deg,
            MAX_ATTITUDE_SIGMA_YAW_DEG,
            default.yaw.to_degrees(),
        ),
    ];
    match problems.into_iter().flatten().next() {
        Some(problem) => Err(problem),
        None => Ok(AttitudeSigma {
            roll_pitch: roll_pitch_deg.to_radians(),
            yaw: yaw_deg.to_radians(),
        }),
    }
}

/// Removes `key` from the top of a parsed `sensor.toml` and reads it as degrees, when it is
/// there. A value that is not a number is a parse error at its line.
fn take_degrees(
    path: &Path,
    text: &str,
    root: &mut toml::de::DeTable<'_>,
    key: &str,
) -> Result<Option<(f64, usize)>> {
    let Some((key_spanned, value)) = root.remove_entry(key) else {
        return Ok(None);
    };
    let line = 1 + text
        .get(..key_spanned.span().start)
        .map_or(0, |t| count_newlines(t.as_bytes()));
    let degrees = f64::deserialize(toml::de::ValueDeserializer::from(value)).map_err(|e| {
        let message = e.message().split_whitespace().collect::<Vec<_>>().join(" ");
        Error::parse(
            path,
            Some(line),
            format!("{key}: {message}; write a number of degrees, e.g. {key} = 2.0"),
        )
    })?;
    Ok(Some((degrees, line)))
}

/// A σ key inside a `[table]` (written below `[lift]`, where TOML puts it into that table) is a
/// parse error at its line that says where it belongs.
fn misplaced_sigma(path: &Path, text: &str, root: &toml::de::DeTable<'_>) -> Result<()> {
    for (table, value) in root.iter() {
        let Some(inner) = value.get_ref().as_table() else {
            continue;
        };
        for (key, _) in inner.iter() {
            let name: &str = key.get_ref();
            if name == ATTITUDE_SIGMA_ROLL_PITCH_KEY || name == ATTITUDE_SIGMA_YAW_KEY {
                let line = 1 + text
                    .get(..key.span().start)
                    .map_or(0, |t| count_newlines(t.as_bytes()));
                return Err(Error::parse(
                    path,
                    Some(line),
                    format!(
                        "{name} is inside [{}]; write it at the top of the file, before any \
                         [table]",
                        table.get_ref()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Reads `sensor.toml`: the sensor model ([`SensorConfig`]'s keys; unknown keys are errors,
/// missing keys take the defaults, then [`SensorConfig::validate`]) and the attitude readings'
/// standard deviations, degrees, at the top of the file (before any `[table]`):
///
/// ```toml
/// attitude_sigma_roll_pitch_deg = 0.5   # σ of the roll and of the pitch reading (gyro)
/// attitude_sigma_yaw_deg = 3.5          # σ of the heading reading (compass)
/// ```
///
/// Each is optional; one left out takes [`AttitudeSigma::default`]'s value (0.5° and 3.5°).
/// Values must be positive, roll/pitch at most [`MAX_ATTITUDE_SIGMA_ROLL_PITCH_DEG`], yaw at most
/// [`MAX_ATTITUDE_SIGMA_YAW_DEG`] (180: the compass tells nothing). Every error is a parse error
/// naming the file and the line; an empty file is an error (a truncated one: remove the file to
/// use the defaults).
///
/// # Example
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("sensor.toml");
/// std::fs::write(&path, "attitude_sigma_yaw_deg = 20\nmax_range_m = 30.0\n")?;
/// let file = sdem_io::read_sensor_file(&path)?;
/// assert_eq!(file.sensor.max_range_m, 30.0);
/// let sigma = file.attitude_sigma.unwrap();
/// assert!((sigma.yaw.to_degrees() - 20.0).abs() < 1e-12);
/// assert!((sigma.roll_pitch.to_degrees() - 0.5).abs() < 1e-12); // the default
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn read_sensor_file(path: &Path) -> Result<SensorFile> {
    const KEYS: &str =
        "the keys are those of sdem's SensorConfig and attitude_sigma_roll_pitch_deg, \
                        attitude_sigma_yaw_deg; angles in degrees, lengths in metres";
    let text = read_text(path)?;
    if text.trim().is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file is empty (truncated?); write the sensor model's keys, or remove the file to \
             use the default sensor model",
        ));
    }
    let mut root = toml::de::DeTable::parse(&text).map_err(|e| toml_error(path, &text, e, KEYS))?;
    misplaced_sigma(path, &text, root.get_ref())?;
    let roll_pitch = take_degrees(path, &text, root.get_mut(), ATTITUDE_SIGMA_ROLL_PITCH_KEY)?;
    let yaw = take_degrees(path, &text, root.get_mut(), ATTITUDE_SIGMA_YAW_KEY)?;
    let sensor = SensorConfig::deserialize(toml::de::Deserializer::from(root))
        .map_err(|e| toml_error(path, &text, e, KEYS))?;
    at_named_key(path, &text, sensor.validate())?;
    let attitude_sigma = if roll_pitch.is_none() && yaw.is_none() {
        None
    } else {
        let default = AttitudeSigma::default();
        let (rp, rp_line) = roll_pitch.unwrap_or((default.roll_pitch.to_degrees(), 0));
        let (yaw, yaw_line) = yaw.unwrap_or((default.yaw.to_degrees(), 0));
        let sigma = attitude_sigma_from_degrees(
            rp,
            yaw,
            ATTITUDE_SIGMA_ROLL_PITCH_KEY,
            ATTITUDE_SIGMA_YAW_KEY,
        )
        .map_err(|why| {
            let line = if why.starts_with(ATTITUDE_SIGMA_ROLL_PITCH_KEY) {
                rp_line
            } else {
                yaw_line
            };
            Error::parse(path, Some(line).filter(|&l| l > 0), why)
        })?;
        Some(sigma)
    };
    Ok(SensorFile {
        sensor,
        attitude_sigma,
    })
}

/// Writes `sensor.toml` (see [`read_sensor_file`]): the attitude readings' standard deviations
/// first when there are any, then the sensor model. Both are checked first, so sdem never
/// writes a file it would refuse to read.
///
/// # Example
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("sensor.toml");
/// let file = sdem_io::SensorFile {
///     sensor: Default::default(),
///     attitude_sigma: Some(sdem::Attitude::default().with_sigma_deg(2.0, 20.0).sigma),
/// };
/// sdem_io::write_sensor_file(&path, &file)?;
/// assert!(std::fs::read_to_string(&path)?.contains("attitude_sigma_yaw_deg = 20\n"));
/// assert_eq!(sdem_io::read_sensor_file(&path)?.sensor, file.sensor);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_sensor_file(path: &Path, file: &SensorFile) -> Result<()> {
    file.sensor.validate()?;
    let sigma_lines = match file.attitude_sigma {
        Some(sigma) => {
            let (rp, yaw) = (sigma.roll_pitch.to_degrees(), sigma.yaw.to_degrees());
            attitude_sigma_from_degrees(
                rp,
                yaw,
                ATTITUDE_SIGMA_ROLL_PITCH_KEY,
                ATTITUDE_SIGMA_YAW_KEY,
            )
            .map_err(|why| {
                Error::Invalid(format!("refusing to write {}: {why}", path.display()))
            })?;
            format!(
                "# How far the attitude readings (attitude.csv) can be off: standard deviations, degrees.\n\
                 {ATTITUDE_SIGMA_ROLL_PITCH_KEY} = {}\n{ATTITUDE_SIGMA_YAW_KEY} = {}\n",
                fmt_f64(rp),
                fmt_f64(yaw)
            )
        }
        None => String::new(),
    };
    let body = toml::to_string_pretty(&file.sensor).map_err(|e| {
        Error::Invalid(format!(
            "cannot write {}: the sensor model does not serialize as TOML: {e}",
            path.display()
        ))
    })?;
    write_atomic(path, |w| {
        w.write_all(
            b"# sdem sensor model: angles in degrees, lengths in metres. Missing keys take the defaults.\n",
        )?;
        w.write_all(sigma_lines.as_bytes())?;
        w.write_all(body.as_bytes())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Result<SensorFile> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sensor.toml");
        std::fs::write(&path, text).unwrap();
        read_sensor_file(&path)
    }

    fn degrees(sigma: AttitudeSigma) -> [f64; 2] {
        [sigma.roll_pitch.to_degrees(), sigma.yaw.to_degrees()]
    }

    #[test]
    fn sigma_present_partial_and_absent() {
        let both = read(
            "attitude_sigma_roll_pitch_deg = 2.0\nattitude_sigma_yaw_deg = 20\nmax_range_m = 6.0\n",
        )
        .unwrap();
        let [rp, yaw] = degrees(both.attitude_sigma.unwrap());
        assert!((rp - 2.0).abs() < 1e-12 && (yaw - 20.0).abs() < 1e-12);
        assert_eq!(both.sensor.max_range_m, 6.0);
        // One key: the other takes the library's default.
        let yaw_only = read("attitude_sigma_yaw_deg = 45.0\n").unwrap();
        let [rp, yaw] = degrees(yaw_only.attitude_sigma.unwrap());
        assert!((rp - 0.5).abs() < 1e-12 && (yaw - 45.0).abs() < 1e-12);
        // Neither: None, and the sensor model is read as before.
        let absent = read("max_range_m = 6.0\n[lift]\nlink_length_m = 0.5\n").unwrap();
        assert_eq!(absent.attitude_sigma, None);
        assert_eq!(absent.sensor.lift.link_length_m, 0.5);
        // The bounds are allowed.
        let bounds = read("attitude_sigma_roll_pitch_deg = 90\nattitude_sigma_yaw_deg = 180\n");
        assert!(bounds.is_ok(), "{bounds:?}");
    }

    #[test]
    fn invalid_sigma_names_file_line_and_key() {
        let cases = [
            (
                "attitude_sigma_yaw_deg = -3.5\n",
                1,
                "attitude_sigma_yaw_deg",
                "positive",
            ),
            (
                "max_range_m = 6.0\nattitude_sigma_yaw_deg = 0\n",
                2,
                "attitude_sigma_yaw_deg",
                "zero",
            ),
            (
                "attitude_sigma_roll_pitch_deg = nan\n",
                1,
                "attitude_sigma_roll_pitch_deg",
                "positive",
            ),
            (
                "attitude_sigma_roll_pitch_deg = inf\n",
                1,
                "attitude_sigma_roll_pitch_deg",
                "positive",
            ),
            (
                "attitude_sigma_roll_pitch_deg = 0.5\nattitude_sigma_yaw_deg = \"3.5\"\n",
                2,
                "attitude_sigma_yaw_deg",
                "degrees",
            ),
            (
                "attitude_sigma_roll_pitch_deg = true\n",
                1,
                "attitude_sigma_roll_pitch_deg",
                "degrees",
            ),
            (
                "attitude_sigma_roll_pitch_deg = 120\n",
                1,
                "attitude_sigma_roll_pitch_deg",
                "more than 90",
            ),
            (
                "attitude_sigma_yaw_deg = 350\n",
                1,
                "attitude_sigma_yaw_deg",
                "more than 180",
            ),
        ];
        for (text, line, key, why) in cases {
            let err = read(text).unwrap_err();
            let msg = err.to_string();
            assert!(matches!(err, Error::Parse { .. }), "{text:?}: {msg}");
            assert!(
                msg.contains(&format!("sensor.toml:{line}:")),
                "{text:?}: {msg}"
            );
            assert!(msg.contains(key) && msg.contains(why), "{text:?}: {msg}");
            assert!(!msg.contains('\n'), "one line: {msg:?}");
        }
        // In a table (appended below [lift]) it is refused, saying where it belongs.
        let err = read("[lift]\nlink_length_m = 0.5\nattitude_sigma_yaw_deg = 3.5\n").unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("sensor.toml:3:") && msg.contains("inside [lift]"),
            "{msg}"
        );
        assert!(msg.contains("before any [table]"), "{msg}");
        // The sensor model's own errors keep their lines with σ keys above them.
        let err = read("attitude_sigma_yaw_deg = 3.5\nmax_rnage_m = 8.0\n").unwrap_err();
        assert!(err.to_string().contains("sensor.toml:2:"), "{err}");
        let err = read("attitude_sigma_yaw_deg = 3.5\n\npan_step_deg = 0.0\n").unwrap_err();
        assert!(err.to_string().contains("sensor.toml:3:"), "{err}");
    }

    #[test]
    fn round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sensor.toml");
        for attitude_sigma in [
            None,
            Some(AttitudeSigma::default()),
            Some(AttitudeSigma {
                roll_pitch: 0.3f64.to_radians(),
                yaw: 12.5f64.to_radians(),
            }),
        ] {
            let file = SensorFile {
                sensor: SensorConfig {
                    trusted_range_m: Some(3.0),
                    ..Default::default()
                },
                attitude_sigma,
            };
            write_sensor_file(&path, &file).unwrap();
            let back = read_sensor_file(&path).unwrap();
            assert_eq!(back.sensor, file.sensor);
            match (back.attitude_sigma, attitude_sigma) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    assert!((a.roll_pitch - b.roll_pitch).abs() < 1e-15);
                    assert!((a.yaw - b.yaw).abs() < 1e-15);
                }
                other => panic!("{other:?}"),
            }
        }
        let bad = SensorFile {
            attitude_sigma: Some(AttitudeSigma {
                roll_pitch: -1.0,
                yaw: 0.1,
            }),
            ..Default::default()
        };
        assert!(matches!(
            write_sensor_file(&path, &bad),
            Err(Error::Invalid(_))
        ));
    }
}
