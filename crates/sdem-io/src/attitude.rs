//! `attitude.csv`: the gyro/compass reading at each stop, degrees.

use super::{
    attitude_sigma_from_degrees, fmt_f64, fmt_msg, numbered_lines, parse_count, parse_finite,
    read_text, write_atomic,
};
use crate::error::{Error, Result};
use sdem::geometry::{Attitude, AttitudeSigma};
use std::path::Path;

/// The header line of `attitude.csv`, exactly.
pub const ATTITUDE_HEADER: &str = "index,roll_deg,pitch_deg,yaw_deg";

/// The header line of an `attitude.csv` whose readings carry their own standard deviations,
/// degrees: roll and pitch's, and the heading's.
pub const ATTITUDE_HEADER_WITH_SIGMA: &str =
    "index,roll_deg,pitch_deg,yaw_deg,roll_pitch_sigma_deg,yaw_sigma_deg";

/// The readings of an `attitude.csv` ([`read_attitude_readings`]).
#[derive(Debug, Clone, PartialEq)]
pub struct AttitudeReadings {
    /// One reading per row, angles in radians, each with its standard deviations.
    pub attitudes: Vec<Attitude>,
    /// Whether the file gives each reading's standard deviations (the six-column header
    /// [`ATTITUDE_HEADER_WITH_SIGMA`]); otherwise every reading has the default given to
    /// [`read_attitude_readings`].
    pub sigma_per_row: bool,
}

/// The largest roll or pitch magnitude, degrees, that a gyro reading can have. A tilt sensor
/// reports angles within one turn, so a larger value is in another unit (hundredths of a degree,
/// raw counts). Yaw is bounded only by [`MAX_YAW_READING_DEG`]: a heading integrated from a gyro
/// may be unwrapped. (Radians where degrees are expected look like small angles and cannot be
/// told apart.)
pub const MAX_TILT_READING_DEG: f64 = 360.0;

/// The largest yaw magnitude, degrees, that a reading can have: an unwrapped heading of some
/// 2,800 turns. A larger one is damage or another unit, and its sine and cosine would be noise
/// (at 1e300 degrees an f64 holds no fraction of a turn).
pub const MAX_YAW_READING_DEG: f64 = 1e6;

/// The error text for a roll or pitch (degrees) beyond [`MAX_TILT_READING_DEG`], `None` when
/// both are within it.
pub(super) fn tilt_reading_problem(roll_deg: f64, pitch_deg: f64) -> Option<String> {
    [("roll", roll_deg), ("pitch", pitch_deg)]
        .into_iter()
        .find(|(_, v)| v.abs() > MAX_TILT_READING_DEG)
        .map(|(name, v)| {
            format!(
                "{name} is {} degrees, more than a full turn; a gyro reading lies within \
                 ±{MAX_TILT_READING_DEG}°, so this is not in degrees (hundredths of a degree? raw \
                 counts?)",
                fmt_msg(v)
            )
        })
}

/// The error text for a yaw (degrees) beyond [`MAX_YAW_READING_DEG`], `None` within it.
pub(super) fn yaw_reading_problem(yaw_deg: f64) -> Option<String> {
    (yaw_deg.abs() > MAX_YAW_READING_DEG).then(|| {
        format!(
            "yaw is {} degrees, more than {} turns even unwrapped; a heading in degrees lies \
             within ±{}°, so the value is damaged or in another unit",
            fmt_msg(yaw_deg),
            (MAX_YAW_READING_DEG / 360.0) as u64,
            fmt_msg(MAX_YAW_READING_DEG)
        )
    })
}

/// The error text for an attitude reading (degrees) beyond the bounds `attitude.csv` holds its
/// readings to — a roll or pitch beyond ±[`MAX_TILT_READING_DEG`], a yaw beyond
/// ±[`MAX_YAW_READING_DEG`] — or `None` within them: for a reading given elsewhere (`sdem
/// localize --attitude`) to be held to the same bounds, in the same words.
///
/// # Example
/// ```
/// assert_eq!(sdem_io::attitude_reading_problem(0.5, -1.0, 725.0), None);
/// let why = sdem_io::attitude_reading_problem(1500.0, 0.0, 90.0).unwrap();
/// assert!(why.starts_with("roll is 1500 degrees, more than a full turn"), "{why}");
/// ```
pub fn attitude_reading_problem(roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> Option<String> {
    tilt_reading_problem(roll_deg, pitch_deg).or_else(|| yaw_reading_problem(yaw_deg))
}

/// Writes `attitude.csv`: the header [`ATTITUDE_HEADER`], then `index,roll,pitch,yaw` per scan
/// with the angles in degrees, written so that they read back to the same degrees bit-for-bit.
/// When a reading's standard deviations ([`Attitude::sigma`]) are not the defaults, every row
/// carries them too, in degrees, under [`ATTITUDE_HEADER_WITH_SIGMA`]; files of readings with
/// the default σ stay in the four-column form that older readers know.
/// A non-finite angle, a roll or pitch beyond [`MAX_TILT_READING_DEG`], or an invalid σ (see
/// [`crate::attitude_sigma_from_degrees`]) is an [`Error::Invalid`].
///
/// # Example
/// ```
/// # let dir = std::env::temp_dir().join(format!("sdem-doc-att-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// use sdem::geometry::Attitude;
/// let path = dir.join("attitude.csv");
/// sdem_io::write_attitude_csv(&path, &[Attitude::from_degrees(0.5, -1.0, 90.0)]).unwrap();
/// assert_eq!(
///     std::fs::read_to_string(&path).unwrap(),
///     "index,roll_deg,pitch_deg,yaw_deg\n0,0.5,-1,90\n"
/// );
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn write_attitude_csv(path: &Path, attitudes: &[Attitude]) -> Result<()> {
    for (i, a) in attitudes.iter().enumerate() {
        if !a.is_finite() {
            return Err(Error::Invalid(format!(
                "refusing to write {}: attitude {i} has a non-finite angle",
                path.display()
            )));
        }
        let [roll, pitch, yaw] = a.to_degrees();
        let sigma = attitude_sigma_from_degrees(
            a.sigma.roll_pitch.to_degrees(),
            a.sigma.yaw.to_degrees(),
            "roll_pitch_sigma_deg",
            "yaw_sigma_deg",
        );
        if let Some(why) = attitude_reading_problem(roll, pitch, yaw).or(sigma.err()) {
            return Err(Error::Invalid(format!(
                "refusing to write {}: attitude {i}: {why}",
                path.display()
            )));
        }
    }
    let with_sigma = attitudes
        .iter()
        .any(|a| a.sigma != AttitudeSigma::default());
    write_atomic(path, |w| {
        let header = if with_sigma {
            ATTITUDE_HEADER_WITH_SIGMA
        } else {
            ATTITUDE_HEADER
        };
        writeln!(w, "{header}")?;
        for (index, a) in attitudes.iter().enumerate() {
            let [roll, pitch, yaw] = a.to_degrees();
            write!(
                w,
                "{index},{},{},{}",
                fmt_f64(roll),
                fmt_f64(pitch),
                fmt_f64(yaw)
            )?;
            if with_sigma {
                write!(
                    w,
                    ",{},{}",
                    fmt_f64(a.sigma.roll_pitch.to_degrees()),
                    fmt_f64(a.sigma.yaw.to_degrees())
                )?;
            }
            writeln!(w)?;
        }
        Ok(())
    })
}

/// Reads `attitude.csv` (see [`read_attitude_readings`]); angles come back in radians, each
/// reading with the standard deviations of its row, or [`AttitudeSigma::default`] when the file
/// has none.
pub fn read_attitude_csv(path: &Path) -> Result<Vec<Attitude>> {
    read_attitude_readings(path, AttitudeSigma::default()).map(|r| r.attitudes)
}

/// Reads `attitude.csv` (see [`write_attitude_csv`]); angles come back in radians. The header
/// must be exactly [`ATTITUDE_HEADER`] or [`ATTITUDE_HEADER_WITH_SIGMA`]; each row needs 4 fields
/// (6 with σ), an index counting 0, 1, 2, …, finite angles, a roll and pitch within
/// [`MAX_TILT_READING_DEG`], and valid standard deviations (positive, roll/pitch at most 90°,
/// yaw at most 180°); blank lines are skipped. Any violation, and a file without rows, is an
/// error naming the file and line. A file without σ columns gives every reading
/// `default_sigma` (the σ `sensor.toml` states, or [`AttitudeSigma::default`]).
///
/// # Example
/// ```
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("attitude.csv");
/// std::fs::write(&path, "index,roll_deg,pitch_deg,yaw_deg,roll_pitch_sigma_deg,yaw_sigma_deg\n\
///                        0,0.5,-1,90,0.2,20\n")?;
/// let read = sdem_io::read_attitude_readings(&path, Default::default())?;
/// assert!(read.sigma_per_row);
/// assert!((read.attitudes[0].sigma.yaw.to_degrees() - 20.0).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn read_attitude_readings(
    path: &Path,
    default_sigma: AttitudeSigma,
) -> Result<AttitudeReadings> {
    let text = read_text(path)?;
    let mut lines = numbered_lines(&text).filter(|(_, l)| !l.trim().is_empty());
    let sigma_per_row = match lines.next() {
        Some((_, header)) if header.trim() == ATTITUDE_HEADER => false,
        Some((_, header)) if header.trim() == ATTITUDE_HEADER_WITH_SIGMA => true,
        Some((line_no, header)) => {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "the header is '{}'; it must be exactly '{ATTITUDE_HEADER}', or \
                     '{ATTITUDE_HEADER_WITH_SIGMA}' when each reading gives its standard \
                     deviations",
                    header.trim()
                ),
            ))
        }
        None => {
            return Err(Error::parse(
                path,
                None,
                format!(
                "the file is empty; expected the header '{ATTITUDE_HEADER}' and one row per scan"
            ),
            ))
        }
    };
    let form = if sigma_per_row {
        ATTITUDE_HEADER_WITH_SIGMA
    } else {
        ATTITUDE_HEADER
    };
    let mut attitudes = Vec::new();
    for (line_no, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let (index, roll, pitch, yaw, sigma) = match (fields.as_slice(), sigma_per_row) {
            ([index, roll, pitch, yaw], false) => (index, roll, pitch, yaw, None),
            ([index, roll, pitch, yaw, rp_sigma, yaw_sigma], true) => {
                (index, roll, pitch, yaw, Some((rp_sigma, yaw_sigma)))
            }
            _ => {
                return Err(Error::parse(
                    path,
                    Some(line_no),
                    format!(
                        "{} fields on this line; each row is '{form}', as the header says",
                        fields.len()
                    ),
                ))
            }
        };
        let expected = attitudes.len();
        let index = parse_count(path, line_no, index, "index")?;
        if index != expected {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "index {index} is out of sequence; rows must be numbered 0, 1, 2, … in order \
                     and this one should be {expected}"
                ),
            ));
        }
        let roll = parse_finite(path, line_no, roll, "roll_deg")?;
        let pitch = parse_finite(path, line_no, pitch, "pitch_deg")?;
        let yaw = parse_finite(path, line_no, yaw, "yaw_deg")?;
        if let Some(why) = attitude_reading_problem(roll, pitch, yaw) {
            return Err(Error::parse(path, Some(line_no), why));
        }
        let sigma = match sigma {
            None => default_sigma,
            Some((rp_sigma, yaw_sigma)) => {
                let rp_sigma = parse_finite(path, line_no, rp_sigma, "roll_pitch_sigma_deg")?;
                let yaw_sigma = parse_finite(path, line_no, yaw_sigma, "yaw_sigma_deg")?;
                attitude_sigma_from_degrees(
                    rp_sigma,
                    yaw_sigma,
                    "roll_pitch_sigma_deg",
                    "yaw_sigma_deg",
                )
                .map_err(|why| Error::parse(path, Some(line_no), why))?
            }
        };
        attitudes.push(Attitude {
            sigma,
            ..Attitude::from_degrees(roll, pitch, yaw)
        });
    }
    if attitudes.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file has a header but no rows; write one row per scan",
        ));
    }
    Ok(AttitudeReadings {
        attitudes,
        sigma_per_row,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("attitude.csv");
        let attitudes: Vec<Attitude> = (0..30)
            .map(|i| {
                let t = i as f64;
                Attitude::new(0.01 * t.sin(), -0.2 + 0.013 * t, 3.0 - 0.2 * t)
            })
            .collect();
        write_attitude_csv(&path, &attitudes).unwrap();
        let back = read_attitude_csv(&path).unwrap();
        assert_eq!(back.len(), attitudes.len());
        for (a, b) in attitudes.iter().zip(&back) {
            assert!((a.roll - b.roll).abs() < 1e-14);
            assert!((a.pitch - b.pitch).abs() < 1e-14);
            assert!((a.yaw - b.yaw).abs() < 1e-14);
        }
        // Degrees survive exactly.
        let text = "index,roll_deg,pitch_deg,yaw_deg\r\n0, 1.5 ,-2,90\r\n\r\n";
        std::fs::write(&path, text).unwrap();
        let back = read_attitude_csv(&path).unwrap();
        assert_eq!(back, vec![Attitude::from_degrees(1.5, -2.0, 90.0)]);
    }

    fn expect_err(content: &str, line: Option<usize>) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("attitude.csv");
        std::fs::write(&path, content).unwrap();
        let err = read_attitude_csv(&path).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, Error::Parse { .. }), "{msg}");
        assert!(msg.contains("attitude.csv"), "{msg}");
        if let Some(line) = line {
            assert!(msg.contains(&format!("attitude.csv:{line}:")), "{msg}");
        }
        msg
    }

    #[test]
    fn malformed() {
        let h = "index,roll_deg,pitch_deg,yaw_deg\n";
        expect_err("", None);
        expect_err(h, None);
        expect_err("0,1,2,3\n", Some(1));
        expect_err("index,roll,pitch,yaw\n0,1,2,3\n", Some(1));
        expect_err(&format!("{h}0,1,2,3\n1,1,2\n"), Some(3));
        expect_err(&format!("{h}0,1,2,3\n1,1,2,3,4\n"), Some(3));
        expect_err(&format!("{h}0,1,2,3\n1,1,two,3\n"), Some(3));
        expect_err(&format!("{h}0,1,2,3\n1,1,nan,3\n"), Some(3));
        expect_err(&format!("{h}0,1,2,3\n1,inf,2,3\n"), Some(3));
        expect_err(&format!("{h}0,1,2,3\n2,1,2,3\n"), Some(3));
        expect_err(&format!("{h}1,1,2,3\n"), Some(2));
        expect_err(&format!("{h}-1,1,2,3\n"), Some(2));
        expect_err(&format!("{h}0,1,2,3\n0,1,2,3\n"), Some(3));
        expect_err(&format!("{h}0 1 2 3\n"), Some(2));
        // A yaw of 1e300 degrees is damage: refused, said with an exponent.
        let e = expect_err(&format!("{h}0,1,2,3\n1,1,2,1e300\n"), Some(3));
        assert!(e.contains("yaw is 1.000e300 degrees"), "{e}");
    }

    #[test]
    fn an_unwrapped_heading_reads() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("attitude.csv");
        std::fs::write(&path, "index,roll_deg,pitch_deg,yaw_deg\n0,1,2,7290\n").unwrap();
        let read = read_attitude_csv(&path).unwrap();
        assert!((read[0].yaw.to_degrees() - 7290.0).abs() < 1e-9);
    }

    #[test]
    fn sigma_columns_present_absent_and_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("attitude.csv");
        // Old files (no σ columns) read as before, every reading with the given default.
        std::fs::write(&path, "index,roll_deg,pitch_deg,yaw_deg\n0,1,2,3\n").unwrap();
        let wide = Attitude::default().with_sigma_deg(2.0, 30.0).sigma;
        let read = read_attitude_readings(&path, wide).unwrap();
        assert!(!read.sigma_per_row);
        assert_eq!(read.attitudes[0].sigma, wide);
        assert_eq!(
            read_attitude_csv(&path).unwrap()[0].sigma,
            AttitudeSigma::default()
        );
        // With σ columns, each row's own σ, whatever the default.
        std::fs::write(
            &path,
            format!("{ATTITUDE_HEADER_WITH_SIGMA}\n0,1,2,3,0.25,4\n1,1,2,3, 1 ,180\n"),
        )
        .unwrap();
        let read = read_attitude_readings(&path, wide).unwrap();
        assert!(read.sigma_per_row);
        let sigma_deg = |a: &Attitude| [a.sigma.roll_pitch.to_degrees(), a.sigma.yaw.to_degrees()];
        let close = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() + (a[1] - b[1]).abs() < 1e-12;
        assert!(close(sigma_deg(&read.attitudes[0]), [0.25, 4.0]));
        assert!(close(sigma_deg(&read.attitudes[1]), [1.0, 180.0]));
        // The writer keeps the old form for default σ and writes the columns otherwise.
        let plain = [Attitude::from_degrees(0.5, -1.0, 90.0)];
        write_attitude_csv(&path, &plain).unwrap();
        assert!(std::fs::read_to_string(&path)
            .unwrap()
            .starts_with(&format!("{ATTITUDE_HEADER}\n")));
        let mixed = [
            Attitude::from_degrees(0.5, -1.0, 90.0),
            Attitude::from_degrees(0.5, -1.0, 92.0).with_sigma_deg(0.2, 20.0),
        ];
        write_attitude_csv(&path, &mixed).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text,
            format!("{ATTITUDE_HEADER_WITH_SIGMA}\n0,0.5,-1,90,0.5,3.5\n1,0.5,-1,92,0.2,20\n")
        );
        let back = read_attitude_csv(&path).unwrap();
        for (a, b) in mixed.iter().zip(&back) {
            assert!(close(sigma_deg(a), sigma_deg(b)), "{a:?} {b:?}");
        }
        // An invalid σ is not written.
        let bad = [Attitude::from_degrees(0.0, 0.0, 0.0).with_sigma_deg(0.5, -1.0)];
        assert!(matches!(
            write_attitude_csv(&path, &bad),
            Err(Error::Invalid(_))
        ));
    }

    #[test]
    fn malformed_sigma_columns() {
        let h = format!("{ATTITUDE_HEADER_WITH_SIGMA}\n");
        let cases = [
            (format!("{h}0,1,2,3,0.5\n"), 2, "5 fields"),
            (format!("{h}0,1,2,3\n"), 2, "4 fields"),
            (
                format!("{ATTITUDE_HEADER}\n0,1,2,3,0.5,3.5\n"),
                2,
                "6 fields",
            ),
            (format!("{h}0,1,2,3,-0.5,3.5\n"), 2, "positive"),
            (format!("{h}0,1,2,3,0.5,0\n"), 2, "zero"),
            (
                format!("{h}0,1,2,3,0.5,3.5\n1,1,2,3,nan,3.5\n"),
                3,
                "finite",
            ),
            (format!("{h}0,1,2,3,0.5,inf\n"), 2, "finite"),
            (format!("{h}0,1,2,3,0.5,three\n"), 2, "yaw_sigma_deg"),
            (format!("{h}0,1,2,3,95,3.5\n"), 2, "more than 90"),
            (format!("{h}0,1,2,3,0.5,400\n"), 2, "more than 180"),
            (
                "index,roll_deg,pitch_deg,yaw_deg,sigma\n0,1,2,3,1\n".to_string(),
                1,
                "header",
            ),
        ];
        for (text, line, why) in cases {
            let msg = expect_err(&text, Some(line));
            assert!(msg.contains(why), "{text:?}: {msg}");
        }
    }

    #[test]
    fn writer_rejects_non_finite() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("attitude.csv");
        let bad = [Attitude::new(0.0, f64::INFINITY, 0.0)];
        assert!(matches!(
            write_attitude_csv(&path, &bad),
            Err(Error::Invalid(_))
        ));
    }
}
