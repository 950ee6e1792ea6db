//! A tilting 2D laser's lines (`sensor_msgs/LaserScan`) assembled into one 3D scan per sweep:
//! the tilt of each line from a joint angle (`sensor_msgs/JointState`) or from the laser's
//! moving frame on `/tf`, and the robot's motion during the sweep taken out with odometry.

use super::collect::{Kept, Origin};
use super::messages::LaserScan;
use super::series::{blend_f64, OutOfSpan, Series};
use super::tf::TfTree;
use sdem::geometry::{Pose, Vec3};
use sdem::sensor::beam_direction;

/// Where each line's tilt comes from.
pub enum TiltSource<'a> {
    /// The laser's frame moves on `/tf`; the scan is expressed in its parent frame.
    Tf {
        /// The transforms.
        tree: &'a TfTree,
        /// The laser's frame (the lines' `frame_id`).
        laser_frame: String,
    },
    /// A joint's angle, radians, over time: the scan plane is tilted up by `up_sign × angle`
    /// about the sensor's y axis (sdem's sensor model, [`sdem::sensor`]).
    Joint {
        /// The joint's angle over time.
        angle: Series<f64>,
        /// +1 when a positive angle tilts the plane up, −1 when it tilts it down (a joint about
        /// +y, the ROS convention).
        up_sign: f64,
    },
}

/// One sweep made into points.
#[derive(Debug, Clone)]
pub struct SweepScan {
    /// The stamp of its first line, nanoseconds: the points are in the sensor frame then.
    pub stamp_ns: i64,
    /// The points, sensor frame, metres.
    pub points: Vec<Vec3>,
    /// Its lines.
    pub lines: usize,
    /// The lowest and highest tilt, degrees.
    pub tilt_deg: (f64, f64),
    /// The largest displacement by which motion compensation moved a line's origin, metres.
    pub compensation_m: f64,
    /// Its first line, for messages.
    pub origin: Origin,
}

/// How a sweep is cut from the stream of lines.
#[derive(Debug, Clone, Copy)]
pub struct SweepRules {
    /// A sweep must span at least this much tilt, degrees.
    pub min_span_deg: f64,
    /// A pause longer than this between two lines ends a sweep, seconds.
    pub max_line_gap_s: f64,
}

/// A line with the tilt it was taken at.
struct TiltedLine<'a> {
    line: &'a Kept<LaserScan>,
    /// The scan plane's tilt, degrees (up positive), for cutting sweeps.
    tilt_deg: f64,
    /// `sensor_from_laser` for the Tf source.
    sensor_from_laser: Option<Pose>,
}

/// The tilt of each line; a line whose tilt is unknown at its stamp is an error.
fn tilted<'a>(
    lines: &'a [Kept<LaserScan>],
    source: &TiltSource,
) -> Result<Vec<TiltedLine<'a>>, (usize, OutOfSpan)> {
    lines
        .iter()
        .enumerate()
        .map(|(i, line)| match source {
            TiltSource::Joint { angle, up_sign } => {
                let a = angle.at(line.stamp_ns, blend_f64).map_err(|e| (i, e))?;
                Ok(TiltedLine {
                    line,
                    tilt_deg: (up_sign * a).to_degrees(),
                    sensor_from_laser: None,
                })
            }
            TiltSource::Tf { tree, laser_frame } => {
                let pose = tree
                    .moving_at(laser_frame, line.stamp_ns)
                    .map_err(|e| (i, e))?;
                let forward = pose.rotation * Vec3::x();
                Ok(TiltedLine {
                    line,
                    tilt_deg: forward.z.clamp(-1.0, 1.0).asin().to_degrees(),
                    sensor_from_laser: Some(pose),
                })
            }
        })
        .collect()
}

/// Cuts lines (sorted by stamp) into runs in which the tilt moves one way.
fn cut(lines: &[TiltedLine], rules: &SweepRules) -> Vec<std::ops::Range<usize>> {
    const STILL_DEG: f64 = 1e-3;
    let mut runs = Vec::new();
    let (mut start, mut direction) = (0, 0.0f64);
    for i in 1..lines.len() {
        let step = lines[i].tilt_deg - lines[i - 1].tilt_deg;
        let gap = (lines[i].line.stamp_ns - lines[i - 1].line.stamp_ns) as f64 * 1e-9;
        let turned = step.abs() > STILL_DEG && direction != 0.0 && step.signum() != direction;
        if gap > rules.max_line_gap_s || turned {
            runs.push(start..i);
            start = if turned { i - 1 } else { i };
            direction = 0.0;
        }
        if step.abs() > STILL_DEG && direction == 0.0 && i > start {
            direction = step.signum();
        }
    }
    if !lines.is_empty() {
        runs.push(start..lines.len());
    }
    runs.retain(|r| {
        let tilts = lines[r.clone()].iter().map(|l| l.tilt_deg);
        let (lo, hi) = tilts.fold((f64::MAX, f64::MIN), |(lo, hi), t| (lo.min(t), hi.max(t)));
        r.len() >= 3 && hi - lo >= rules.min_span_deg
    });
    runs
}

/// The points of one line in the sensor frame at the line's time.
fn line_points(t: &TiltedLine, up_sign_used: bool) -> Vec<Vec3> {
    let scan = &t.line.message;
    let mut points = Vec::with_capacity(scan.ranges.len());
    for (k, &r) in scan.ranges.iter().enumerate() {
        let in_limits = r.is_finite() && r > 0.0 && r >= scan.range_min && r <= scan.range_max;
        if !in_limits {
            continue;
        }
        let pan = f64::from(scan.angle_min) + k as f64 * f64::from(scan.angle_increment);
        let r = f64::from(r);
        let p = match &t.sensor_from_laser {
            Some(sensor_from_laser) => {
                sensor_from_laser * nalgebra::Point3::new(r * pan.cos(), r * pan.sin(), 0.0)
            }
            None if up_sign_used => {
                nalgebra::Point3::from(beam_direction(t.tilt_deg.to_radians(), pan) * r)
            }
            None => continue,
        };
        points.push(p.coords);
    }
    points
}

/// Assembles the sweeps of `lines` (sorted by stamp). `odom_from_sensor` gives the sensor's
/// odometry pose at a stamp, to take the motion during a sweep out (`None`: no odometry).
///
/// # Errors
/// The index (in `lines`) of a line whose tilt or odometry is unknown at its stamp, and why.
pub fn assemble(
    lines: &[Kept<LaserScan>],
    source: &TiltSource,
    rules: &SweepRules,
    odom_from_sensor: Option<&dyn Fn(i64) -> Result<Pose, OutOfSpan>>,
) -> Result<Vec<SweepScan>, (usize, OutOfSpan)> {
    let tilted = tilted(lines, source)?;
    let joint = matches!(source, TiltSource::Joint { .. });
    let mut sweeps = Vec::new();
    for run in cut(&tilted, rules) {
        let first = &tilted[run.start];
        let reference = match odom_from_sensor {
            Some(odom) => Some(odom(first.line.stamp_ns).map_err(|e| (run.start, e))?),
            None => None,
        };
        let mut points = Vec::new();
        let mut compensation_m: f64 = 0.0;
        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
        for (i, t) in tilted[run.clone()].iter().enumerate() {
            lo = lo.min(t.tilt_deg);
            hi = hi.max(t.tilt_deg);
            let mut line = line_points(t, joint);
            if let (Some(odom), Some(reference)) = (odom_from_sensor, &reference) {
                let now = odom(t.line.stamp_ns).map_err(|e| (run.start + i, e))?;
                let reference_from_now = reference.inverse() * now;
                let moved = reference_from_now.translation.vector.norm();
                let turned = reference_from_now.rotation.angle();
                // Only where odometry says the robot moved: a still robot's lines stay exact.
                if moved > 1e-4 || turned > 1e-5 {
                    compensation_m = compensation_m.max(moved);
                    for p in &mut line {
                        *p = (reference_from_now * nalgebra::Point3::from(*p)).coords;
                    }
                }
            }
            points.extend(line);
        }
        sweeps.push(SweepScan {
            stamp_ns: first.line.stamp_ns,
            points,
            lines: run.len(),
            tilt_deg: (lo, hi),
            compensation_m,
            origin: first.line.origin.clone(),
        });
    }
    Ok(sweeps)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rosbag::messages::Header;

    fn line(stamp_ns: i64, ranges: Vec<f32>) -> Kept<LaserScan> {
        Kept {
            stamp_ns,
            message: LaserScan {
                header: Header {
                    stamp_ns,
                    frame_id: "laser".into(),
                },
                angle_min: 0.0,
                angle_max: std::f32::consts::FRAC_PI_2,
                angle_increment: std::f32::consts::FRAC_PI_2,
                time_increment: 0.0,
                range_min: 0.1,
                range_max: 10.0,
                ranges,
            },
            origin: Origin {
                file: "bag.mcap".into(),
                index: 0,
            },
        }
    }

    const MS: i64 = 1_000_000;

    #[test]
    fn a_nodding_laser_gives_one_sweep_each_way_in_the_sensor_model() {
        // The joint (about +y) goes 0 → −40° (plane tilting up) and back, a line every 10 ms.
        let lines: Vec<_> = (0..81)
            .map(|i| line(i * 10 * MS, vec![2.0, f32::NAN]))
            .collect();
        let angle = Series::new(
            (0..81)
                .map(|i: i64| {
                    let deg = if i <= 40 {
                        -(i as f64)
                    } else {
                        (i - 80) as f64
                    };
                    (i * 10 * MS, deg.to_radians())
                })
                .collect(),
        );
        let source = TiltSource::Joint {
            angle,
            up_sign: -1.0,
        };
        let rules = SweepRules {
            min_span_deg: 20.0,
            max_line_gap_s: 1.0,
        };
        let sweeps = assemble(&lines, &source, &rules, None).unwrap();
        assert_eq!(sweeps.len(), 2);
        assert_eq!(sweeps[0].lines, 41);
        assert!((sweeps[0].tilt_deg.1 - 40.0).abs() < 1e-9);
        // Beam at pan 0 on the line tilted 40° up: (cos 40°, 0, sin 40°) · 2 m.
        let p = sweeps[0].points[40];
        let t = 40f64.to_radians();
        assert!(
            (p - Vec3::new(t.cos(), 0.0, t.sin()) * 2.0).norm() < 1e-9,
            "{p}"
        );
        // NaN beams are dropped.
        assert_eq!(sweeps[0].points.len(), 41);
    }

    #[test]
    fn motion_during_a_sweep_is_taken_out() {
        let lines: Vec<_> = (0..30).map(|i| line(i * 10 * MS, vec![2.0])).collect();
        let angle = Series::new(
            (0..30)
                .map(|i: i64| (i * 10 * MS, i as f64 * 0.02))
                .collect(),
        );
        let source = TiltSource::Joint {
            angle,
            up_sign: 1.0,
        };
        let rules = SweepRules {
            min_span_deg: 20.0,
            max_line_gap_s: 1.0,
        };
        // The robot drives +x at 1 m/s: a wall 2 m ahead at the start stays 2 m ahead.
        let odom = |t: i64| Ok(Pose::translation(t as f64 * 1e-9, 0.0, 0.0));
        let sweeps = assemble(&lines, &source, &rules, Some(&odom)).unwrap();
        let last = lines.len() - 1;
        let tilt = (last as f64 * 0.02).to_degrees().to_radians();
        let moved = last as f64 * 0.01;
        let p = sweeps[0].points[last];
        assert!((p.x - (2.0 * tilt.cos() + moved)).abs() < 1e-9, "{p}");
        assert!((sweeps[0].compensation_m - moved).abs() < 1e-9);
    }
}
