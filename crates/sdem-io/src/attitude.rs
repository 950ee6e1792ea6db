//! `attitude.csv`: the gyro/compass reading at each stop, degrees.

use super::{fmt_f64, numbered_lines, parse_count, parse_finite, read_text, write_atomic};
use crate::error::{Error, Result};
use sdem::geometry::Attitude;
use std::path::Path;

/// The header line of `attitude.csv`, exactly.
pub const ATTITUDE_HEADER: &str = "index,roll_deg,pitch_deg,yaw_deg";

/// The largest roll or pitch magnitude, degrees, that a gyro reading can have. A tilt sensor
/// reports angles within one turn, so a larger value is in another unit (hundredths of a degree,
/// raw counts). Yaw is not bounded: a heading integrated from a gyro may be unwrapped. (Radians
/// where degrees are expected look like small angles and cannot be told apart.)
pub const MAX_TILT_READING_DEG: f64 = 360.0;

/// The error text for a roll or pitch (degrees) beyond [`MAX_TILT_READING_DEG`], `None` when
/// both are within it.
pub(super) fn tilt_reading_problem(roll_deg: f64, pitch_deg: f64) -> Option<String> {
    [("roll", roll_deg), ("pitch", pitch_deg)]
        .into_iter()
        .find(|(_, v)| v.abs() > MAX_TILT_READING_DEG)
        .map(|(name, v)| {
            format!(
                "{name} is {v} degrees, more than a full turn; a gyro reading lies within \
                 ±{MAX_TILT_READING_DEG}°, so this is not in degrees (hundredths of a degree? raw \
                 counts?)"
            )
        })
}

/// Writes `attitude.csv`: the header [`ATTITUDE_HEADER`], then `index,roll,pitch,yaw` per scan
/// with the angles in degrees, written so that they read back to the same degrees bit-for-bit.
/// A non-finite angle, or a roll or pitch beyond [`MAX_TILT_READING_DEG`], is an
/// [`Error::Invalid`].
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
        let [roll, pitch, _] = a.to_degrees();
        if let Some(why) = tilt_reading_problem(roll, pitch) {
            return Err(Error::Invalid(format!(
                "refusing to write {}: attitude {i}: {why}",
                path.display()
            )));
        }
    }
    write_atomic(path, |w| {
        writeln!(w, "{ATTITUDE_HEADER}")?;
        for (index, a) in attitudes.iter().enumerate() {
            let [roll, pitch, yaw] = a.to_degrees();
            writeln!(
                w,
                "{index},{},{},{}",
                fmt_f64(roll),
                fmt_f64(pitch),
                fmt_f64(yaw)
            )?;
        }
        Ok(())
    })
}

/// Reads `attitude.csv` (see [`write_attitude_csv`]); angles come back in radians. The header
/// must be exactly [`ATTITUDE_HEADER`]; each row needs 4 fields, an index counting 0, 1, 2, …,
/// finite angles, and a roll and pitch within [`MAX_TILT_READING_DEG`]; blank lines are skipped.
/// Any violation, and a file without rows, is an error naming the file and line.
pub fn read_attitude_csv(path: &Path) -> Result<Vec<Attitude>> {
    let text = read_text(path)?;
    let mut lines = numbered_lines(&text).filter(|(_, l)| !l.trim().is_empty());
    match lines.next() {
        Some((_, header)) if header.trim() == ATTITUDE_HEADER => {}
        Some((line_no, header)) => {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "the header is '{}'; it must be exactly '{ATTITUDE_HEADER}'",
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
    }
    let mut attitudes = Vec::new();
    for (line_no, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let [index, roll, pitch, yaw] = fields.as_slice() else {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "{} fields on this line; each row is 'index,roll_deg,pitch_deg,yaw_deg'",
                    fields.len()
                ),
            ));
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
        if let Some(why) = tilt_reading_problem(roll, pitch) {
            return Err(Error::parse(path, Some(line_no), why));
        }
        attitudes.push(Attitude::from_degrees(roll, pitch, yaw));
    }
    if attitudes.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file has a header but no rows; write one row per scan",
        ));
    }
    Ok(attitudes)
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
