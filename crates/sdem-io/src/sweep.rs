//! The `.sweep` raw tilting-LRF format, version 1 (specified in the module documentation of
//! [`crate`]).

use super::attitude::tilt_reading_problem;
use super::{
    fmt_f64, fmt_msg, numbered_lines, parse_count, parse_finite, read_text, write_atomic,
    MAX_MEDIAN_RANGE_M,
};
use crate::error::{Error, Result};
use sdem::geometry::Attitude;
use sdem::sensor::{Sweep, SweepLine};
use std::path::Path;

/// The magic word that starts a `.sweep` file.
pub const SWEEP_MAGIC: &str = "sdem-sweep";

/// The `.sweep` format version this sdem writes and reads.
pub const SWEEP_VERSION: u32 = 1;

/// More beams per line than this is taken for a damaged header (a 0.01° step over 360° is 36,000).
const MAX_PAN_COUNT: usize = 1_000_000;

/// Every beam's pan angle lies within ± this, degrees: a scan line covers at most a turn on each
/// side of forward (larger angles are a damaged header, and overflow to non-finite points).
const MAX_PAN_DEG: f64 = 360.0;

/// The largest lift slide a sweep may hold, metres, either sign. A slide mechanism moves the
/// scanner by centimetres to a few metres (the paper's scissor lift slides 0.20–0.58 m,
/// [`sdem::sensor::LiftConfig`]); 100 m leaves room for any such mechanism and still refuses a
/// damaged header, or a slide written in millimetres.
pub const MAX_LIFT_SLIDE_M: f64 = 100.0;

/// `Some(message)` when the lift slide `slide_m` is not finite or beyond ±[`MAX_LIFT_SLIDE_M`].
fn lift_problem(slide_m: f64) -> Option<String> {
    (!(slide_m.is_finite() && slide_m.abs() <= MAX_LIFT_SLIDE_M)).then(|| {
        format!(
            "the lift slide is {} m; it must lie within ±{MAX_LIFT_SLIDE_M} m (a lift moves the \
             scanner by centimetres to a few metres: is it in millimetres?)",
            fmt_msg(slide_m)
        )
    })
}

/// `Some(message)` when the pan angles `PAN_MIN`, …, `PAN_MIN + (PAN_COUNT − 1) · PAN_STEP`
/// leave ±[`MAX_PAN_DEG`].
fn pan_problem(pan_min_deg: f64, pan_step_deg: f64, pan_count: usize) -> Option<String> {
    let last = pan_min_deg + pan_count.saturating_sub(1) as f64 * pan_step_deg;
    let inside = |v: f64| v.is_finite() && v.abs() <= MAX_PAN_DEG;
    (!(inside(pan_min_deg) && inside(last))).then(|| {
        format!(
            "the beams' pan angles run from {pan_min_deg}° to {last}°; they must lie within \
             ±{MAX_PAN_DEG}° (a scan line covers at most a turn)"
        )
    })
}

/// When half of the sweep's returns (finite ranges > 0) are farther than
/// [`MAX_MEDIAN_RANGE_M`], the index of a line holding the median range and that range: the
/// ranges are not in metres (millimetres?).
fn ranges_problem(sweep: &Sweep) -> Option<(usize, f32)> {
    let mut returns: Vec<(f32, usize)> = sweep
        .lines
        .iter()
        .enumerate()
        .flat_map(|(i, line)| {
            line.ranges
                .iter()
                .filter(|r| r.is_finite() && **r > 0.0)
                .map(move |&r| (r, i))
        })
        .collect();
    if returns.is_empty() {
        return None;
    }
    let middle = returns.len() / 2;
    let (_, &mut (median, line), _) =
        returns.select_nth_unstable_by(middle, |a, b| a.0.total_cmp(&b.0));
    (f64::from(median) > MAX_MEDIAN_RANGE_M).then_some((line, median))
}

fn ranges_message(median: f32) -> String {
    format!(
        "half of the sweep's ranges are {median} m or more (this line holds the median); no range \
         finder a robot carries sees that far, and ranges are in metres: are they in millimetres?"
    )
}

/// A range is NaN (no return) or a finite distance >= 0.
fn is_valid_range(r: f32) -> bool {
    r.is_nan() || (r.is_finite() && r >= 0.0)
}

/// Formats a range so that it reads back to the same `f32`; `nan` for no return.
fn fmt_range(r: f32) -> String {
    if r.is_nan() {
        "nan".to_string()
    } else if r == 0.0 || r.abs() >= 1e-5 {
        format!("{r}")
    } else {
        format!("{r:e}")
    }
}

/// Writes a raw sweep in the `.sweep` format (version 1), atomically. The attitude is written in
/// degrees and every range so that it reads back to the same `f32`.
///
/// The sweep must pass [`Sweep::validate`], have at least one line of at least one beam, and
/// every range must be NaN (no return) or finite and ≥ 0; otherwise this is an
/// [`Error::Invalid`] and nothing is written.
pub fn write_sweep(path: &Path, sweep: &Sweep) -> Result<()> {
    let refuse =
        |why: String| Error::Invalid(format!("refusing to write {}: {why}", path.display()));
    sweep.validate().map_err(|e| refuse(e.to_string()))?;
    let pan_count = sweep.lines.first().map_or(0, |l| l.ranges.len());
    if sweep.lines.is_empty() || pan_count == 0 {
        return Err(refuse("the sweep has no lines or no beams".into()));
    }
    if let Some(why) = pan_problem(sweep.pan_min_deg, sweep.pan_step_deg, pan_count) {
        return Err(refuse(why));
    }
    if let Some(why) = lift_problem(sweep.lift_slide_m) {
        return Err(refuse(why));
    }
    for (i, line) in sweep.lines.iter().enumerate() {
        if let Some(k) = line.ranges.iter().position(|r| !is_valid_range(*r)) {
            return Err(refuse(format!(
                "line {i} beam {k} has range {}; a range is nan (no return) or finite and >= 0",
                line.ranges.get(k).copied().unwrap_or(f32::NAN)
            )));
        }
        let [roll, pitch, _] = line.attitude.to_degrees();
        if let Some(why) = tilt_reading_problem(roll, pitch) {
            return Err(refuse(format!("line {i}: {why}")));
        }
    }
    if let Some((i, median)) = ranges_problem(sweep) {
        return Err(refuse(format!("line {i}: {}", ranges_message(median))));
    }
    write_atomic(path, |w| {
        writeln!(w, "{SWEEP_MAGIC} {SWEEP_VERSION}")?;
        writeln!(
            w,
            "pan_deg {} {} {pan_count}",
            fmt_f64(sweep.pan_min_deg),
            fmt_f64(sweep.pan_step_deg)
        )?;
        writeln!(w, "lift_slide_m {}", fmt_f64(sweep.lift_slide_m))?;
        writeln!(w, "lines {}", sweep.lines.len())?;
        writeln!(
            w,
            "# tilt_deg roll_deg pitch_deg yaw_deg then {pan_count} ranges in metres (nan = no return)"
        )?;
        let mut row = String::new();
        for line in &sweep.lines {
            row.clear();
            let [roll, pitch, yaw] = line.attitude.to_degrees();
            for v in [line.tilt_deg, roll, pitch, yaw] {
                row.push_str(&fmt_f64(v));
                row.push(' ');
            }
            for r in &line.ranges {
                row.push_str(&fmt_range(*r));
                row.push(' ');
            }
            row.pop();
            row.push('\n');
            w.write_all(row.as_bytes())?;
        }
        Ok(())
    })
}

/// Reads a raw sweep in the `.sweep` format (version 1); see the [module documentation](crate)
/// for the format. The attitude comes back in radians.
///
/// Errors, each naming the file and line: a missing or wrong magic line, another version, a
/// header line out of order or malformed, a count that the file cannot hold, pan angles beyond
/// ±360°, a data line with the wrong number of values, a non-finite angle, a roll or pitch beyond
/// ±360° (not degrees), a range that is negative or infinite, fewer or more data lines than
/// declared, a last line without its line break (a truncated file), and ranges whose median lies
/// beyond [`MAX_MEDIAN_RANGE_M`] (not metres).
pub fn read_sweep(path: &Path) -> Result<Sweep> {
    let text = read_text(path)?;
    if text.trim().is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file is empty; a sweep starts with the line 'sdem-sweep 1'",
        ));
    }
    let last_line = text.lines().count();
    let mut header = Header {
        path,
        last_line,
        lines: numbered_lines(&text).filter(|(_, l)| {
            let t = l.trim_start();
            !t.is_empty() && !t.starts_with('#')
        }),
    };
    header.magic()?;
    let (pan_min_deg, pan_step_deg, pan_count) = header.pan()?;
    let lift_slide_m = header.lift_slide()?;
    let line_count = header.line_count(text.len(), pan_count)?;
    let (sweep_lines, line_numbers) = header.data_lines(line_count, pan_count)?;
    if !text.ends_with('\n') {
        return Err(Error::parse(
            path,
            Some(last_line),
            "the last line has no line break: the file is truncated (every line of a sweep ends \
             with one)",
        ));
    }
    let sweep = Sweep {
        pan_min_deg,
        pan_step_deg,
        lift_slide_m,
        lines: sweep_lines,
    };
    sweep
        .validate()
        .map_err(|e| Error::parse(path, None, e.to_string()))?;
    if let Some((i, median)) = ranges_problem(&sweep) {
        let line = line_numbers.get(i).copied();
        return Err(Error::parse(path, line, ranges_message(median)));
    }
    Ok(sweep)
}

/// A `.sweep` file being read: its numbered lines that are neither blank nor comments, the header
/// lines first, one at a time, then the data lines.
struct Header<'p, I> {
    path: &'p Path,
    /// The file's last line number, for errors at its end.
    last_line: usize,
    lines: I,
}

impl<'t, I: Iterator<Item = (usize, &'t str)>> Header<'_, I> {
    /// The next header line, which must start with `key` (`usage` shows the whole line): its
    /// number and its tokens.
    fn next(&mut self, key: &str, usage: &str) -> Result<(usize, Vec<&'t str>)> {
        let Some((line_no, line)) = self.lines.next() else {
            return Err(Error::parse(
                self.path,
                Some(self.last_line),
                format!(
                    "the file ends here, before the '{usage}' line; the sweep header is incomplete"
                ),
            ));
        };
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.first() != Some(&key) {
            return Err(Error::parse(
                self.path,
                Some(line_no),
                format!("expected '{usage}' here"),
            ));
        }
        Ok((line_no, tokens))
    }

    /// The magic line, `sdem-sweep 1`.
    fn magic(&mut self) -> Result<()> {
        let path = self.path;
        let (line_no, tokens) = self
            .next(SWEEP_MAGIC, "sdem-sweep 1")
            .map_err(|e| match e {
                Error::Parse { line, .. } => Error::parse(
                    path,
                    line,
                    "not an sdem sweep file: the first line must be 'sdem-sweep 1'",
                ),
                other => other,
            })?;
        match tokens.as_slice() {
            [_, version] if version.parse::<u32>() == Ok(SWEEP_VERSION) => Ok(()),
            [_, version] => Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "sweep format version '{version}' is not supported; this sdem reads version \
                     {SWEEP_VERSION}"
                ),
            )),
            _ => Err(Error::parse(
                path,
                Some(line_no),
                "expected 'sdem-sweep 1' (the magic word and the format version)",
            )),
        }
    }

    /// The `pan_deg PAN_MIN PAN_STEP PAN_COUNT` line: the first beam's angle and the step,
    /// degrees, and the beams per line.
    fn pan(&mut self) -> Result<(f64, f64, usize)> {
        let path = self.path;
        let (line_no, tokens) = self.next("pan_deg", "pan_deg PAN_MIN PAN_STEP PAN_COUNT")?;
        let [_, pan_min, pan_step, pan_count] = tokens.as_slice() else {
            return Err(Error::parse(
                path,
                Some(line_no),
                "expected 'pan_deg PAN_MIN PAN_STEP PAN_COUNT' (degrees, degrees, beams per line)",
            ));
        };
        let pan_min_deg = parse_finite(path, line_no, pan_min, "PAN_MIN")?;
        let pan_step_deg = parse_finite(path, line_no, pan_step, "PAN_STEP")?;
        if pan_step_deg <= 0.0 {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!("PAN_STEP is {pan_step_deg}; it must be > 0"),
            ));
        }
        let pan_count = parse_count(path, line_no, pan_count, "PAN_COUNT")?;
        if !(1..=MAX_PAN_COUNT).contains(&pan_count) {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!("PAN_COUNT is {pan_count}; it must lie in 1..={MAX_PAN_COUNT}"),
            ));
        }
        if let Some(why) = pan_problem(pan_min_deg, pan_step_deg, pan_count) {
            return Err(Error::parse(path, Some(line_no), why));
        }
        Ok((pan_min_deg, pan_step_deg, pan_count))
    }

    /// The `lift_slide_m U` line: the lift's slide, metres.
    fn lift_slide(&mut self) -> Result<f64> {
        let (line_no, tokens) = self.next("lift_slide_m", "lift_slide_m U")?;
        let [_, slide] = tokens.as_slice() else {
            return Err(Error::parse(
                self.path,
                Some(line_no),
                "expected 'lift_slide_m U' (the lift's slide, metres)",
            ));
        };
        let slide_m = parse_finite(self.path, line_no, slide, "the lift slide")?;
        match lift_problem(slide_m) {
            Some(why) => Err(Error::parse(self.path, Some(line_no), why)),
            None => Ok(slide_m),
        }
    }

    /// The `lines N` line: the number of scan lines, which a file of `text_len` bytes with
    /// `pan_count` beams per line must be able to hold.
    fn line_count(&mut self, text_len: usize, pan_count: usize) -> Result<usize> {
        let path = self.path;
        let (line_no, tokens) = self.next("lines", "lines N")?;
        let [_, count] = tokens.as_slice() else {
            return Err(Error::parse(
                path,
                Some(line_no),
                "expected 'lines N' (the number of scan lines that follow)",
            ));
        };
        let line_count = parse_count(path, line_no, count, "the line count")?;
        // Every value takes at least one character and one separator.
        let min_line_bytes = 2 * (4 + pan_count);
        if line_count == 0 || line_count > text_len / min_line_bytes {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "'lines {line_count}' cannot be right: a sweep has at least one line, and {} \
                     bytes hold at most {} lines of {} values",
                    text_len,
                    text_len / min_line_bytes,
                    4 + pan_count
                ),
            ));
        }
        Ok(line_count)
    }

    /// The rest of the file: exactly `line_count` data lines of `pan_count` beams, with their
    /// line numbers.
    fn data_lines(
        self,
        line_count: usize,
        pan_count: usize,
    ) -> Result<(Vec<SweepLine>, Vec<usize>)> {
        let path = self.path;
        let mut sweep_lines = Vec::with_capacity(line_count);
        let mut line_numbers = Vec::with_capacity(line_count);
        for (line_no, line) in self.lines {
            if sweep_lines.len() == line_count {
                return Err(Error::parse(
                    path,
                    Some(line_no),
                    format!("more data lines than the {line_count} that 'lines' declares"),
                ));
            }
            sweep_lines.push(data_line(path, line_no, line, pan_count)?);
            line_numbers.push(line_no);
        }
        if sweep_lines.len() != line_count {
            return Err(Error::parse(
                path,
                Some(self.last_line),
                format!(
                    "the file ends here, after {} of the {line_count} data lines that 'lines' \
                     declares; it is truncated",
                    sweep_lines.len()
                ),
            ));
        }
        Ok((sweep_lines, line_numbers))
    }
}

/// Parses `TILT ROLL PITCH YAW R_0 … R_(n−1)`.
fn data_line(path: &Path, line_no: usize, line: &str, pan_count: usize) -> Result<SweepLine> {
    let mut tokens = line.split_whitespace();
    let mut angles = [0f64; 4];
    let names = ["TILT_DEG", "ROLL_DEG", "PITCH_DEG", "YAW_DEG"];
    let found = line.split_whitespace().count();
    if found != 4 + pan_count {
        return Err(Error::parse(
            path,
            Some(line_no),
            format!(
                "{found} values on this line; a data line is tilt, roll, pitch, yaw (degrees) and \
                 {pan_count} ranges = {} values",
                4 + pan_count
            ),
        ));
    }
    for (slot, name) in angles.iter_mut().zip(names) {
        let token = tokens.next().unwrap_or_default();
        *slot = parse_finite(path, line_no, token, name)?;
    }
    let mut ranges = Vec::with_capacity(pan_count);
    for (k, token) in tokens.enumerate() {
        let r = token.parse::<f32>().map_err(|_| {
            Error::parse(
                path,
                Some(line_no),
                format!("range {k} '{token}' is not a number (write nan for no return)"),
            )
        })?;
        if !is_valid_range(r) {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "range {k} is {}; a range is nan (no return) or a finite number >= 0",
                    fmt_msg(r)
                ),
            ));
        }
        ranges.push(r);
    }
    let [tilt_deg, roll, pitch, yaw] = angles;
    if let Some(why) = tilt_reading_problem(roll, pitch) {
        return Err(Error::parse(path, Some(line_no), why));
    }
    Ok(SweepLine {
        tilt_deg,
        attitude: Attitude::from_degrees(roll, pitch, yaw),
        ranges,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_sweep() -> Sweep {
        let lines = (0..86)
            .map(|i| {
                let t = i as f64;
                SweepLine {
                    tilt_deg: -45.0 + t,
                    attitude: Attitude::from_degrees(0.01 * t, -0.02, 0.1 + 1e-3 * t),
                    ranges: (0..181)
                        .map(|k| {
                            if (i + k) % 17 == 0 {
                                f32::NAN
                            } else {
                                0.05 + (k as f32 * 0.123_456_7 + i as f32).sin().abs() * 7.9
                            }
                        })
                        .collect(),
                }
            })
            .collect();
        Sweep {
            pan_min_deg: -90.0,
            pan_step_deg: 1.0,
            lift_slide_m: 0.55,
            lines,
        }
    }

    #[test]
    fn round_trip_is_exact_for_ranges() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("000000.sweep");
        let mut sweep = sample_sweep();
        sweep.lines[3].ranges[5] = 0.0;
        sweep.lines[3].ranges[6] = 1e-7;
        sweep.lines[3].ranges[7] = f32::MAX;
        write_sweep(&path, &sweep).unwrap();
        let back = read_sweep(&path).unwrap();
        assert_eq!(back.pan_min_deg, sweep.pan_min_deg);
        assert_eq!(back.pan_step_deg, sweep.pan_step_deg);
        assert_eq!(back.lift_slide_m, sweep.lift_slide_m);
        assert_eq!(back.lines.len(), sweep.lines.len());
        for (a, b) in sweep.lines.iter().zip(&back.lines) {
            assert_eq!(a.tilt_deg, b.tilt_deg);
            assert!((a.attitude.roll - b.attitude.roll).abs() < 1e-15);
            assert!((a.attitude.pitch - b.attitude.pitch).abs() < 1e-15);
            assert!((a.attitude.yaw - b.attitude.yaw).abs() < 1e-15);
            assert_eq!(a.ranges.len(), b.ranges.len());
            for (r, s) in a.ranges.iter().zip(&b.ranges) {
                assert!(r.to_bits() == s.to_bits() || (r.is_nan() && s.is_nan()));
            }
        }
        // The points through read_points are those of the sweep.
        let points = crate::read_points(&path).unwrap();
        assert_eq!(points, sweep.points_in_sensor());
    }

    #[test]
    fn reads_the_documented_example() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.sweep");
        let text = "sdem-sweep 1\npan_deg -90 90 3\nlift_slide_m 0.55\n# comment\nlines 2\n\
                    # tilt_deg roll_deg pitch_deg yaw_deg then 3 ranges\n\
                    -45 0.01 -0.02 0.1 1.2345 nan 2\n\n  10\t0 0 0 NaN 0 3.5\n# end\n";
        std::fs::write(&path, text).unwrap();
        let sweep = read_sweep(&path).unwrap();
        assert_eq!(sweep.lines.len(), 2);
        assert_eq!(sweep.lines[0].ranges[0], 1.2345f32);
        assert!(sweep.lines[0].ranges[1].is_nan());
        assert!((sweep.lines[0].attitude.yaw - 0.1f64.to_radians()).abs() < 1e-15);
        assert_eq!(sweep.lines[1].tilt_deg, 10.0);
        assert_eq!(sweep.lines[1].ranges[2], 3.5);
    }

    fn expect_err(content: &str, line: Option<usize>) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.sweep");
        std::fs::write(&path, content).unwrap();
        let err = read_sweep(&path).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, Error::Parse { .. }), "{msg}");
        assert!(msg.contains("bad.sweep"), "{msg}");
        if let Some(line) = line {
            assert!(msg.contains(&format!("bad.sweep:{line}:")), "{msg}");
        }
        msg
    }

    #[test]
    fn malformed() {
        let head = "sdem-sweep 1\npan_deg -90 90 3\nlift_slide_m 0.5\nlines 2\n";
        let with = |body: &str| format!("{head}{body}");
        expect_err("", None);
        expect_err("# just a comment\n", None);
        expect_err("ply\n", Some(1));
        expect_err("sdem-sweep 2\n", Some(1));
        expect_err("sdem-sweep\n", Some(1));
        expect_err("sdem-sweep 1\nlift_slide_m 0.5\n", Some(2));
        expect_err("sdem-sweep 1\npan_deg -90 90\n", Some(2));
        expect_err("sdem-sweep 1\npan_deg -90 0 3\n", Some(2));
        expect_err("sdem-sweep 1\npan_deg -90 1 0\n", Some(2));
        expect_err("sdem-sweep 1\npan_deg nan 1 3\n", Some(2));
        expect_err("sdem-sweep 1\npan_deg -90 1 3\nlift_slide_m inf\n", Some(3));
        expect_err("sdem-sweep 1\npan_deg -90 1 3\nlift_slide_m 0.5\n", None);
        expect_err(
            "sdem-sweep 1\npan_deg -90 1 3\nlift_slide_m 0.5\nlines 0\n",
            Some(4),
        );
        let msg = expect_err(
            "sdem-sweep 1\npan_deg -90 1 3\nlift_slide_m 0.5\nlines 99999999999\n0 0 0 0 1 2 3\n",
            Some(4),
        );
        assert!(msg.contains("99999999999"), "{msg}");
        expect_err("sdem-sweep 1\npan_deg -90 1 99999999999\n", Some(2));
        expect_err(&with("0 0 0 0 1 2 3\n"), None);
        expect_err(&with("0 0 0 0 1 2 3\n0 0 0 0 1 2\n"), Some(6));
        expect_err(&with("0 0 0 0 1 2 3\n0 0 0 0 1 2 3 4\n"), Some(6));
        expect_err(&with("0 0 0 0 1 2 3\n0 0 nan 0 1 2 3\n"), Some(6));
        expect_err(&with("0 0 0 0 1 2 3\ninf 0 0 0 1 2 3\n"), Some(6));
        expect_err(&with("0 0 0 0 1 2 3\n0 0 0 0 1 -2 3\n"), Some(6));
        expect_err(&with("0 0 0 0 1 2 3\n0 0 0 0 1 inf 3\n"), Some(6));
        expect_err(&with("0 0 0 0 1 2 3\n0 0 0 0 1 far 3\n"), Some(6));
        expect_err(&with("0 0 0 0 1 2 3\n0 zero 0 0 1 2 3\n"), Some(6));
        expect_err(
            &with("0 0 0 0 1 2 3\n0 0 0 0 1 2 3\n0 0 0 0 1 2 3\n"),
            Some(7),
        );
    }

    #[test]
    fn an_absurd_lift_is_refused_naming_the_file_and_value() {
        for lift in ["1e9", "-150", "100.5"] {
            let text = format!(
                "sdem-sweep 1\npan_deg -90 1 3\nlift_slide_m {lift}\nlines 1\n0 0 0 0 1 2 3\n"
            );
            let msg = expect_err(&text, Some(3));
            assert!(msg.contains("lift") && msg.contains("100 m"), "{msg}");
        }
        let msg = expect_err(
            "sdem-sweep 1\npan_deg -90 1 3\nlift_slide_m 1e9\nlines 1\n0 0 0 0 1 2 3\n",
            Some(3),
        );
        assert!(msg.contains("1.000e9"), "{msg}");
        // A lift of a few metres is read.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("tall.sweep");
        let text = "sdem-sweep 1\npan_deg -90 1 3\nlift_slide_m 2.5\nlines 1\n0 0 0 0 1 2 3\n";
        std::fs::write(&path, text).unwrap();
        assert_eq!(read_sweep(&path).unwrap().lift_slide_m, 2.5);
        // The writer refuses what the reader would.
        let mut sweep = sample_sweep();
        sweep.lift_slide_m = 1e9;
        let err = write_sweep(&dir.path().join("w.sweep"), &sweep).unwrap_err();
        assert!(err.to_string().contains("lift"), "{err}");
    }

    #[test]
    fn writer_rejects_bad_sweeps() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.sweep");
        let mut sweep = sample_sweep();
        sweep.lines[2].ranges[4] = -1.0;
        assert!(matches!(write_sweep(&path, &sweep), Err(Error::Invalid(_))));
        sweep.lines[2].ranges[4] = f32::INFINITY;
        assert!(matches!(write_sweep(&path, &sweep), Err(Error::Invalid(_))));
        sweep.lines[2].ranges.pop();
        assert!(matches!(write_sweep(&path, &sweep), Err(Error::Invalid(_))));
        sweep.lines.clear();
        assert!(matches!(write_sweep(&path, &sweep), Err(Error::Invalid(_))));
        assert!(!path.exists());
    }

    #[test]
    fn no_input_prefix_panics() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.sweep");
        let mut sweep = sample_sweep();
        sweep.lines.truncate(2);
        for l in &mut sweep.lines {
            l.ranges.truncate(5);
        }
        write_sweep(&path, &sweep).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let cut = dir.path().join("cut.sweep");
        for len in 0..bytes.len() {
            std::fs::write(&cut, &bytes[..len]).unwrap();
            let _ = read_sweep(&cut);
        }
    }
}
