//! A line scanner's geometry measured from its scans: the angular step between the beams of a
//! line and between the lines, and the farthest range it reports for "no return".
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

/// What [`measure_line_scanner`] found in one scan, degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineScannerSteps {
    /// The median angle between neighbouring beams of a line.
    pub beam_step_deg: f64,
    /// The median angle between the planes of successive lines.
    pub line_step_deg: f64,
    /// The number of lines measured.
    pub lines: usize,
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

/// Measures a line scanner's beam and line steps from one scan's points in the order the
/// scanner took them (any frame centred on the sensor). `None` where the order shows no regular
/// planar lines: fewer than [`MIN_LINES`] lines of [`MIN_BEAMS_PER_LINE`] beams, neighbours
/// farther apart than [`MAX_BEAM_STEP_DEG`], lines that are not planes through the sensor (a
/// spinning LiDAR's cones), or fewer than [`MIN_SHARE_ON_LINES`] of the returns on them.
/// Points at the origin (no direction) are skipped.
pub fn measure_line_scanner(points: &[Vec3]) -> Option<LineScannerSteps> {
    let directions: Vec<Vec3> = points
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()) && p.norm() > 1e-6)
        .map(|p| p.normalize())
        .collect();
    let gaps: Vec<f64> = directions
        .windows(2)
        .map(|w| angle_deg(&w[0], &w[1]))
        .collect();
    let beam_step_deg = median(gaps.clone())?;
    if !(beam_step_deg > 1e-3 && beam_step_deg <= MAX_BEAM_STEP_DEG) {
        return None;
    }
    // Runs of neighbours within a few beam steps of each other.
    let mut lines: Vec<&[Vec3]> = Vec::new();
    let mut start = 0;
    for (i, gap) in gaps.iter().enumerate() {
        if *gap > LINE_BREAK_STEPS * beam_step_deg {
            lines.push(&directions[start..=i]);
            start = i + 1;
        }
    }
    lines.push(&directions[start..]);
    // Each line's plane through the sensor: its normal is the direction its beams least spread
    // along; a beam farther from the plane than half a step makes it no plane.
    let tolerance = (0.5 * beam_step_deg).to_radians().sin();
    let mut normals: Vec<Vec3> = Vec::new();
    let mut on_lines = 0;
    for line in lines.iter().filter(|l| l.len() >= MIN_BEAMS_PER_LINE) {
        let scatter: Matrix3<f64> = line.iter().map(|d| d * d.transpose()).sum();
        let eigen = SymmetricEigen::new(scatter);
        let smallest = eigen.eigenvalues.imin();
        let mut normal: Vec3 = eigen.eigenvectors.column(smallest).into_owned();
        if line.iter().any(|d| d.dot(&normal).abs() > tolerance) {
            return None;
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
    let line_step_deg = median(
        normals
            .windows(2)
            .map(|w| angle_deg(&w[0], &w[1]))
            .collect(),
    )?;
    (line_step_deg > 1e-3 && line_step_deg <= 45.0).then_some(LineScannerSteps {
        beam_step_deg,
        line_step_deg,
        lines: normals.len(),
    })
}

/// How far below the farthest return a return still counts as the scanner's "no return" range,
/// metres: 3DTK's example scans report it as 32.759–32.767 m (a SICK's 32,767 mm, rounded
/// through centimetres and three coordinates).
const NO_RETURN_BAND_M: f64 = 0.02;

/// The share of a scan's points that must lie in that band for it to be a "no return" range:
/// 1.6–1.8 % on the example scans.
const NO_RETURN_MIN_SHARE: f64 = 0.005;

/// The range a scanner writes for a beam that saw nothing, if the scan has one: the farthest
/// range, when the returns pile up there: at least [`NO_RETURN_MIN_SHARE`] of the points within
/// [`NO_RETURN_BAND_M`] of it, and twice as many as in the ten times wider band just short of
/// it (where a real surface at the farthest range thins out). Returns from that range on are
/// no surface. `None` when the farthest returns are surfaces like any other (a scanner that
/// leaves out the beams without a return).
pub fn no_return_range(points: &[Vec3]) -> Option<f64> {
    let ranges: Vec<f64> = points
        .iter()
        .map(|p| p.norm())
        .filter(|r| r.is_finite())
        .collect();
    let farthest = ranges.iter().copied().reduce(f64::max)?;
    if farthest <= NO_RETURN_BAND_M {
        return None;
    }
    let from = farthest - NO_RETURN_BAND_M;
    let short_of = from - 10.0 * NO_RETURN_BAND_M;
    let in_band = ranges.iter().filter(|&&r| r >= from).count();
    let below = ranges
        .iter()
        .filter(|&&r| (short_of..from).contains(&r))
        .count();
    (in_band as f64 >= NO_RETURN_MIN_SHARE * ranges.len() as f64 && in_band >= 2 * below)
        .then_some(from)
}

fn angle_deg(a: &Vec3, b: &Vec3) -> f64 {
    // atan2 of the cross and dot products: exact for the small angles of neighbouring beams.
    a.cross(b).norm().atan2(a.dot(b)).to_degrees()
}

/// The median (the upper one of an even count); `None` for no values.
pub(super) fn median(mut values: Vec<f64>) -> Option<f64> {
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

    /// A scan of a line scanner in the order it takes it: `lines` lines, each `line_step` degrees
    /// further about `axis` (through the sensor), of beams `beam_step` degrees apart over
    /// `beam_span` degrees in the line's plane; every surface `range` metres away.
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

    #[test]
    fn a_nodding_scanner_shows_its_beam_and_line_steps() {
        // Nodded about the sensor's left axis (y): lines pitched −40..+40° at 0.8°, 1° beams.
        let scan = line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room);
        let steps = measure_line_scanner(&scan).expect("a nodding scanner's lines");
        assert!((steps.beam_step_deg - 1.0).abs() < 1e-6, "{steps:?}");
        assert!((steps.line_step_deg - 0.8).abs() < 1e-6, "{steps:?}");
        assert_eq!(steps.lines, 101);
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
        assert!((steps.beam_step_deg - 0.25).abs() < 1e-6, "{steps:?}");
        assert!((steps.line_step_deg - 1.5).abs() < 1e-6, "{steps:?}");
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
        // 2 % of the beams report 32.76 ± 0.005 m.
        for (i, p) in scan.iter_mut().enumerate().filter(|(i, _)| i % 50 == 0) {
            *p = p.normalize() * (32.76 + 0.001 * (i % 5) as f64);
        }
        let from = no_return_range(&scan).expect("a pile-up at the far end");
        assert!((32.74..32.765).contains(&from), "{from}");
        // A far wall seen by a few beams is a surface.
        let mut far_wall = line_scan(Vec3::y(), -40.0, 0.8, 101, 1.0, 181, room);
        for p in far_wall.iter_mut().take(20) {
            *p = p.normalize() * 150.0;
        }
        assert_eq!(no_return_range(&far_wall), None);
        assert_eq!(no_return_range(&[]), None);
    }
}
