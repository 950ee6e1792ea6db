//! A line scanner's geometry measured from its scans: the angular step between the beams of a
//! line and between the lines, and the farthest range it reports for "no return"; and the
//! sensor model an import writes from them ([`measured_sensor`]).
//!
//! A 3DTK `.3d` file lists a scan's points in the order the scanner took them: a 2D laser sweeps
//! one line of beams (a plane through the sensor), then the mechanism nods or turns it to the
//! next line. Two neighbours in the file are then one beam step apart, a jump of many steps
//! starts a new line, and the planes of two successive lines lie one line step apart. That is
//! what [`measure_line_scanner`] reads, so that an import describes the scanner that took the
//! scans rather than the one of 3DTK's example scans: a dataset taken at 1° and matched on the
//! example scanner's 0.52° cells would leave every other cell a hole.
//!
//! A file in another order (a spinning LiDAR's rings, a shuffled or merged cloud) has no
//! planar lines of regular beams; the measurement says so ([`None`]) rather than guessing.

use nalgebra::{Matrix3, SymmetricEigen};
use sdem::geometry::Vec3;
use sdem::sensor::SensorConfig;

/// What [`measure_line_scanner`] found in one scan, degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineScannerSteps {
    /// The median angle between neighbouring beams of a line.
    pub beam_step_deg: f64,
    /// The median angle between the planes of successive lines.
    pub line_step_deg: f64,
    /// The number of lines measured.
    pub lines: usize,
    /// The lines' planes stand within 45° of the vertical (most of them): a scanner that turns
    /// its lines about the vertical axis, whose line step is one of azimuth and beam step one
    /// of elevation. Otherwise they lie near the horizontal, as a nodding scanner's, whose line
    /// step is one of elevation.
    pub lines_stand_vertical: bool,
}

/// The fewest lines a scan must show for its steps to be measured.
const MIN_LINES: usize = 10;

/// The fewest beams a line must have for its plane to be fitted.
const MIN_BEAMS_PER_LINE: usize = 10;

/// Two neighbours in the file more than this many beam steps apart lie on different lines.
const LINE_BREAK_STEPS: f64 = 4.0;

/// The largest beam step a line scanner is taken to have, degrees: a file whose neighbours lie
/// farther apart (a shuffled cloud) is no scanner's order.
const MAX_BEAM_STEP_DEG: f64 = 10.0;

/// The share of a scan's returns that must lie on the measured lines.
const MIN_SHARE_ON_LINES: f64 = 0.8;

/// The share of a line's beams that may lie off its plane.
const MAX_OFF_PLANE: f64 = 0.05;

/// Planes of successive lines closer than this many beam steps are pieces of one line.
const SAME_LINE_STEPS: f64 = 0.2;

/// Measures a line scanner's beam and line steps from one scan's points in the order the
/// scanner took them (any frame centred on the sensor). `None` where the order shows no regular
/// planar lines: fewer than [`MIN_LINES`] lines of [`MIN_BEAMS_PER_LINE`] beams that are planes
/// through the sensor (a spinning LiDAR's rings are cones), neighbours farther apart than
/// [`MAX_BEAM_STEP_DEG`], or fewer than [`MIN_SHARE_ON_LINES`] of the returns on such lines. A
/// scanner that sweeps its lines back and forth is measured too: a line ends where the sweep
/// turns round.
/// Points at the origin (no direction) are skipped.
pub fn measure_line_scanner(points: &[Vec3]) -> Option<LineScannerSteps> {
    let directions: Vec<Vec3> = points
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()) && p.norm() > 1e-6)
        .map(|p| p.normalize())
        .collect();
    let gap = |i: usize| angle_deg(&directions[i], &directions[i + 1]);
    let n_gaps = directions.len().saturating_sub(1);
    // The median of every gap, held as `f32` (a survey's `.3d` file holds millions of points);
    // the lines below take the gaps again one by one.
    let mut gaps: Vec<f32> = (0..n_gaps).map(|i| gap(i) as f32).collect();
    if gaps.is_empty() {
        return None;
    }
    let mid = gaps.len() / 2;
    let beam_step_deg = *gaps.select_nth_unstable_by(mid, f32::total_cmp).1 as f64;
    drop(gaps);
    if !(beam_step_deg > 1e-3 && beam_step_deg <= MAX_BEAM_STEP_DEG) {
        return None;
    }
    // Runs of neighbours within a few beam steps of each other, sweeping on the same way: a
    // scanner that sweeps its lines back and forth turns round between two of them, one line
    // step from where it was.
    let mut lines: Vec<&[Vec3]> = Vec::new();
    let mut start = 0;
    for i in 0..n_gaps {
        // Against the step two back: the sweep turns round through a step across to the next
        // line (at right angles to both), and a stray beam off the line, whose steps to and from
        // it lean either way, does not turn it.
        let step = |k: usize| directions[k + 1] - directions[k];
        let turns_round = i >= start + 2 && step(i).dot(&step(i - 2)) < 0.0;
        if gap(i) > LINE_BREAK_STEPS * beam_step_deg || turns_round {
            lines.push(&directions[start..=i]);
            start = i + 1;
        }
    }
    lines.push(&directions[start..]);
    // Each line's plane through the sensor: its normal is the direction its beams least spread
    // along. A line with more than `MAX_OFF_PLANE` of its beams farther from the plane than half
    // a step is no plane (a spinning LiDAR's ring is a cone) and is left out; a stray beam or
    // two (a mixed return, a coordinate rounded to the centimetre near the sensor) is not.
    let tolerance = (0.5 * beam_step_deg).to_radians().sin();
    let mut normals: Vec<Vec3> = Vec::new();
    let mut on_lines = 0;
    for line in lines.iter().filter(|l| l.len() >= MIN_BEAMS_PER_LINE) {
        let mut normal = plane_normal(line.iter());
        let off_plane = line
            .iter()
            .filter(|d| d.dot(&normal).abs() > tolerance)
            .count();
        if off_plane as f64 > MAX_OFF_PLANE * line.len() as f64 {
            continue;
        }
        if off_plane > 0 {
            // Fitted again without the stray beams, which tilted the first fit.
            let on_plane = line.iter().filter(|d| d.dot(&normal).abs() <= tolerance);
            normal = plane_normal(on_plane);
        }
        // Successive normals point the same way, so that their angle is the step, not its
        // supplement.
        if normals.last().is_some_and(|last| last.dot(&normal) < 0.0) {
            normal = -normal;
        }
        normals.push(normal);
        on_lines += line.len();
    }
    if normals.len() < MIN_LINES || (on_lines as f64) < MIN_SHARE_ON_LINES * directions.len() as f64
    {
        return None;
    }
    // Two pieces of one line (split where the beams found nothing over more than four steps)
    // lie in one plane: their angle is no step between lines.
    let line_step_deg = median(
        (normals.windows(2))
            .map(|w| angle_deg(&w[0], &w[1]))
            .filter(|&a| a > SAME_LINE_STEPS * beam_step_deg)
            .collect(),
    )?;
    // A plane stands vertical where its normal lies within 45° of the horizontal.
    let vertical = (normals.iter())
        .filter(|n| n.z.abs() < std::f64::consts::FRAC_1_SQRT_2)
        .count();
    (line_step_deg > 1e-3 && line_step_deg <= 45.0).then_some(LineScannerSteps {
        beam_step_deg,
        line_step_deg,
        lines: normals.len(),
        lines_stand_vertical: 2 * vertical > normals.len(),
    })
}

/// The sensor model an import writes from its scans' measured steps (`min_range_m` the
/// nearest return it kept): the median of the scans' measured steps (rounded to a
/// thousandth of a degree; a nodding scanner's line step as the tilt step and its beam step as
/// the pan step, a turning scanner's the other way round, as most scans' lines stand), the extents of the kept returns' directions
/// (elevation as tilt, azimuth as pan; a full turn where no azimuth is left out) and ranges, and
/// a 1 cm range noise (not in the files; a SICK LMS's). `Err` saying why when no scan's steps
/// were measured, or when the model they make is not valid.
pub(super) fn measured_sensor(
    steps: &[LineScannerSteps],
    extents: &Extents,
    min_range_m: f64,
) -> Result<SensorConfig, String> {
    let round = |v: f64| (v * 1e3).round() / 1e3;
    let unordered = || {
        "no scan lists its points in a line scanner's order (lines of beams at a regular step), \
         so the scanner's steps are unknown"
            .to_string()
    };
    let beam = median(steps.iter().map(|s| s.beam_step_deg).collect()).ok_or_else(unordered)?;
    let line = median(steps.iter().map(|s| s.line_step_deg).collect()).ok_or_else(unordered)?;
    let turning = 2 * steps.iter().filter(|s| s.lines_stand_vertical).count() > steps.len();
    let (tilt_step, pan_step) = if turning { (beam, line) } else { (line, beam) };
    let (pan_min_deg, pan_max_deg) = extents.azimuth_deg();
    let sensor = SensorConfig {
        tilt_min_deg: round(extents.elevation_deg.0).max(-90.0),
        tilt_max_deg: round(extents.elevation_deg.1).min(90.0),
        tilt_step_deg: round(tilt_step).max(1e-3),
        pan_min_deg,
        pan_max_deg,
        pan_step_deg: round(pan_step).max(1e-3),
        min_range_m,
        // Up to the next 10 cm above the farthest return kept.
        max_range_m: ((extents.max_range_m * 10.0).floor() + 1.0) / 10.0,
        range_noise_m: 0.01,
        ..SensorConfig::default()
    };
    sensor.validate().map_err(|e| {
        format!("the scanner measured (beams {beam:.3}° and lines {line:.3}° apart) makes no valid sensor model: {e}")
    })?;
    Ok(sensor)
}

/// The directions and ranges the kept returns of every scan cover.
pub(super) struct Extents {
    /// Lowest and highest elevation, degrees.
    elevation_deg: (f64, f64),
    /// Per 1° bin of azimuth (from −180°), the least and greatest azimuth of a return in it,
    /// degrees (`None`: no return).
    azimuth_bins: [Option<(f64, f64)>; 360],
    max_range_m: f64,
}

impl Extents {
    pub(super) fn new() -> Self {
        Self {
            elevation_deg: (90.0, -90.0),
            azimuth_bins: [None; 360],
            max_range_m: 0.0,
        }
    }

    pub(super) fn add(&mut self, points: &[Vec3]) {
        for p in points {
            let r = p.norm();
            let elevation = (p.z / r).asin().to_degrees();
            let azimuth = p.y.atan2(p.x).to_degrees();
            self.elevation_deg.0 = self.elevation_deg.0.min(elevation);
            self.elevation_deg.1 = self.elevation_deg.1.max(elevation);
            let bin = &mut self.azimuth_bins[((azimuth + 180.0).floor() as usize).min(359)];
            *bin = Some(bin.map_or((azimuth, azimuth), |(lo, hi)| {
                (lo.min(azimuth), hi.max(azimuth))
            }));
            self.max_range_m = self.max_range_m.max(r);
        }
    }

    /// The azimuth extent, degrees to a thousandth: the circle without its longest run of empty
    /// 1° bins (−180..180 where that run is shorter than 10°, a scanner that turns all the way,
    /// or where the returns lie across ±180°, behind the scanner).
    fn azimuth_deg(&self) -> (f64, f64) {
        let bins = &self.azimuth_bins;
        let (mut gap_start, mut gap_len) = (0, 0);
        for start in 0..360 {
            let len = (0..360)
                .take_while(|k| bins[(start + k) % 360].is_none())
                .count();
            if len > gap_len {
                (gap_start, gap_len) = (start, len);
            }
        }
        if gap_len < 10 || gap_len == 360 {
            return (-180.0, 180.0);
        }
        // The returns run from the bin after the gap to the bin before it.
        let first = bins[(gap_start + gap_len) % 360].map_or(-180.0, |b| b.0);
        let last = bins[(gap_start + 359) % 360].map_or(180.0, |b| b.1);
        let round = |v: f64| (v * 1e3).round() / 1e3;
        if first < last {
            (round(first), round(last))
        } else {
            (-180.0, 180.0)
        }
    }
}

/// The width of the band of ranges a scanner's "no return" value fills, metres: 3DTK's example
/// scans report it as 32.759–32.767 m (a SICK's 32,767 mm, rounded through centimetres and
/// three coordinates).
const NO_RETURN_BAND_M: f64 = 0.02;

/// The share of a scan's points that must lie in that band for it to be a "no return" range:
/// 1.6–1.8 % on the example scans.
const NO_RETURN_MIN_SHARE: f64 = 0.005;

/// The range a scanner writes for a beam that saw nothing, if the scan has one: where the
/// returns pile up at the far end of the scan. Among the farthest fifth of the returns, the
/// band of [`NO_RETURN_BAND_M`] that holds the most; it is the "no return" range when it holds
/// at least [`NO_RETURN_MIN_SHARE`] of the points, twice as many as the ten times wider band
/// just short of it (where a real surface at the farthest range thins out), and ten times as
/// many as lie beyond it (a stray return or two farther than the pile-up does not hide it; a
/// wall seen head-on, with the room's far side beyond, is no pile-up). Returns from that range
/// on are no surface. `None` when the farthest returns are surfaces like any other (a scanner
/// that leaves out the beams without a return).
pub fn no_return_range(points: &[Vec3]) -> Option<f64> {
    let mut ranges: Vec<f64> = points
        .iter()
        .map(|p| p.norm())
        .filter(|r| r.is_finite())
        .collect();
    ranges.sort_by(f64::total_cmp);
    let n = ranges.len();
    // The number of ranges in [from, to).
    let count = |from: f64, to: f64| {
        ranges.partition_point(|&r| r < to) - ranges.partition_point(|&r| r < from)
    };
    let (start, in_band) = (n * 4 / 5..n)
        .map(|i| (ranges[i], count(ranges[i], ranges[i] + NO_RETURN_BAND_M)))
        .max_by(|a, b| a.1.cmp(&b.1).then(a.0.total_cmp(&b.0)))?;
    let below = count(start - 10.0 * NO_RETURN_BAND_M, start);
    let beyond = n - ranges.partition_point(|&r| r < start + NO_RETURN_BAND_M);
    (start > NO_RETURN_BAND_M
        && in_band as f64 >= NO_RETURN_MIN_SHARE * n as f64
        && in_band >= 2 * below
        && in_band >= 10 * beyond)
        .then_some(start)
}

/// The normal of the plane through the origin that `directions` spread least from: the
/// eigenvector of their scatter with the least eigenvalue.
fn plane_normal<'a>(directions: impl Iterator<Item = &'a Vec3>) -> Vec3 {
    let scatter: Matrix3<f64> = directions.map(|d| d * d.transpose()).sum();
    let eigen = SymmetricEigen::new(scatter);
    eigen
        .eigenvectors
        .column(eigen.eigenvalues.imin())
        .into_owned()
}

fn angle_deg(a: &Vec3, b: &Vec3) -> f64 {
    // atan2 of the cross and dot products: exact for the small angles of neighbouring beams.
    a.cross(b).norm().atan2(a.dot(b)).to_degrees()
}

/// The median (the upper one of an even count); `None` for no values.
fn median(mut values: Vec<f64>) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mid = values.len() / 2;
    let (_, m, _) = values.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*m)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use nalgebra::Rotation3;

    /// A scan of a line scanner in the order it takes it: `lines` lines, each `line_step_deg`
    /// further about `axis` (through the sensor), of `beams` beams `beam_step_deg` apart in the
    /// line's plane from −90° on; each surface `range(line, beam)` metres away.
    pub fn line_scan(
        axis: Vec3,
        first_line_deg: f64,
        line_step_deg: f64,
        lines: usize,
        beam_step_deg: f64,
        beams: usize,
        range: impl Fn(usize, usize) -> f64,
    ) -> Vec<Vec3> {
        // The line's plane at angle 0 contains `axis` and the direction `start`.
        let axis = nalgebra::Unit::new_normalize(axis);
        let start = if axis.z.abs() < 0.9 {
            axis.cross(&Vec3::z()).normalize()
        } else {
            Vec3::x()
        };
        let in_plane_normal = nalgebra::Unit::new_normalize(axis.cross(&start));
        let mut points = Vec::new();
        for l in 0..lines {
            let nod = Rotation3::from_axis_angle(
                &axis,
                (first_line_deg + l as f64 * line_step_deg).to_radians(),
            );
            for b in 0..beams {
                let sweep = Rotation3::from_axis_angle(
                    &in_plane_normal,
                    (-90.0 + b as f64 * beam_step_deg).to_radians(),
                );
                points.push(nod * (sweep * start) * range(l, b));
            }
        }
        points
    }

    /// A room 2–6 m across, as a range by line and beam: every range in between, evenly.
    pub fn room(l: usize, b: usize) -> f64 {
        2.0 + ((l * 7919 + b * 104_729) % 10_007) as f64 * 4.0 / 10_007.0
    }

    /// The beam and line steps measured, to a millionth of a degree.
    fn assert_steps(steps: &LineScannerSteps, beam_step_deg: f64, line_step_deg: f64) {
        assert!(
            (steps.beam_step_deg - beam_step_deg).abs() < 1e-6,
            "{steps:?}"
        );
        assert!(
            (steps.line_step_deg - line_step_deg).abs() < 1e-6,
            "{steps:?}"
        );
    }

    #[test]
    fn a_nodding_scanner_shows_its_beam_and_line_steps() {
        // Nodded about the sensor's left axis (y): lines pitched −40..+40° at 0.8°, 1° beams.
        let scan = line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room);
        let steps = measure_line_scanner(&scan).expect("a nodding scanner's lines");
        assert_steps(&steps, 1.0, 0.8);
        assert_eq!(steps.lines, 101);
        assert!(!steps.lines_stand_vertical);
    }

    #[test]
    fn a_turning_scanner_and_missing_returns_are_measured_too() {
        // Vertical lines turned about z, 1.5° apart over a full turn, 0.25° beams; every tenth
        // return missing (at the origin) and a few at the "no return" range.
        let mut scan = line_scan(Vec3::z(), 0.0, 1.5, 240, 0.25, 721, room);
        for (i, p) in scan.iter_mut().enumerate() {
            if i % 10 == 3 {
                *p = Vec3::zeros();
            } else if i % 97 == 5 {
                *p = p.normalize() * 81.91;
            }
        }
        let steps = measure_line_scanner(&scan).expect("a turning scanner's lines");
        assert_steps(&steps, 0.25, 1.5);
        assert!(steps.lines_stand_vertical);
    }

    /// The sensor model puts a nodding scanner's line step in tilt and its beam step in pan,
    /// and a turning scanner's the other way round.
    #[test]
    fn the_sensor_model_steps_follow_how_the_lines_stand() {
        let model = |scan: &[Vec3]| {
            let steps = measure_line_scanner(scan).expect("a line scanner");
            let mut extents = Extents::new();
            extents.add(scan);
            measured_sensor(&[steps], &extents, 0.1).expect("a sensor model")
        };
        let nodding = model(&line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room));
        assert_eq!((nodding.tilt_step_deg, nodding.pan_step_deg), (0.8, 1.0));
        let turning = model(&line_scan(Vec3::z(), 0.0, 1.5, 240, 0.25, 721, room));
        assert_eq!((turning.tilt_step_deg, turning.pan_step_deg), (0.25, 1.5));
    }

    /// A stray beam in every line (a mixed return off the line's plane) and every line split
    /// by a stretch of sky (no returns over 20 beams) leave the steps as they are.
    #[test]
    fn stray_beams_and_split_lines_leave_the_steps() {
        let scan = line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room);
        let kept: Vec<Vec3> = (scan.iter().enumerate())
            .filter(|(i, _)| !(60..80).contains(&(i % 181)))
            .map(|(i, p)| {
                if i % 181 == 100 {
                    // 1.5–2° off the line's plane: beyond half a step, within the line's run.
                    p + Vec3::new(0.0, 0.0, p.norm() * 2f64.to_radians().tan())
                } else {
                    *p
                }
            })
            .collect();
        let steps = measure_line_scanner(&kept).expect("lines with a stray beam and a gap");
        assert_steps(&steps, 1.0, 0.8);
        assert_eq!(steps.lines, 202, "two pieces a line");
    }

    /// A scanner that sweeps every other line the other way: each line ends where the sweep
    /// turns round, one line step from the next line's first beam.
    #[test]
    fn a_scanner_sweeping_back_and_forth_is_measured() {
        let scan = line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room);
        let zigzag: Vec<Vec3> = (scan.chunks(181).enumerate())
            .flat_map(|(l, line)| {
                let mut line = line.to_vec();
                if l % 2 == 1 {
                    line.reverse();
                }
                line
            })
            .collect();
        let steps = measure_line_scanner(&zigzag).expect("lines swept both ways");
        assert_steps(&steps, 1.0, 0.8);
        assert_eq!(steps.lines, 101);
    }

    #[test]
    fn a_cloud_in_no_scanner_order_is_not_measured() {
        let scan = line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room);
        // Shuffled by a fixed stride coprime to the count.
        let n = scan.len();
        let shuffled: Vec<Vec3> = (0..n).map(|i| scan[(i * 7919) % n]).collect();
        assert_eq!(measure_line_scanner(&shuffled), None);
        // A spinning LiDAR's rings: cones, not planes through the sensor.
        let rings: Vec<Vec3> = (0..16)
            .flat_map(|ring| (0..900).map(move |k| (ring, k)))
            .map(|(ring, k)| {
                let (el, az) = (
                    (-15.0 + 2.0 * ring as f64).to_radians(),
                    (0.4 * k as f64).to_radians(),
                );
                Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin()) * 10.0
            })
            .collect();
        assert_eq!(measure_line_scanner(&rings), None);
        // Too few points for any line.
        assert_eq!(measure_line_scanner(&scan[..50]), None);
        assert_eq!(measure_line_scanner(&[]), None);
    }

    #[test]
    fn the_no_return_range_is_found_only_where_returns_pile_up_at_the_far_end() {
        let mut scan = line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room);
        // The farthest returns are surfaces: no "no return" range.
        assert_eq!(no_return_range(&scan), None);
        // 2 % of the beams report 32.760–32.764 m.
        for (i, p) in scan.iter_mut().enumerate().filter(|(i, _)| i % 50 == 0) {
            *p = p.normalize() * (32.76 + 0.001 * ((i / 50) % 5) as f64);
        }
        let from = no_return_range(&scan).expect("a pile-up at the far end");
        assert!((32.755..32.761).contains(&from), "{from}");
        // A stray return or two beyond the pile-up does not hide it.
        scan[1] = scan[1].normalize() * 40.0;
        scan[2] = scan[2].normalize() * 55.0;
        assert_eq!(no_return_range(&scan), Some(from));
        // A far wall seen by a few beams is a surface.
        let mut far_wall = line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room);
        for p in far_wall.iter_mut().take(20) {
            *p = p.normalize() * 150.0;
        }
        assert_eq!(no_return_range(&far_wall), None);
        // A band full of returns with the room's far side beyond it (a wall seen head-on) is no
        // pile-up at the far end.
        let mut wall = line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room);
        for p in wall.iter_mut().step_by(5) {
            *p = p.normalize() * 5.5;
        }
        assert_eq!(no_return_range(&wall), None);
        assert_eq!(no_return_range(&[]), None);
    }
}
