//! Which scans become stops: every scan of a stop-and-go robot, or one per distance or angle
//! travelled for a LiDAR that scans while the robot moves.

use super::series::OutOfSpan;
use sdem::geometry::Pose;

/// How scans become stops.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopPolicy {
    /// `EachScan` for scans that come at most once a second (a stop-and-go robot) and for
    /// tilting-laser sweeps, `Travelled` for faster scans (a spinning LiDAR on the move).
    #[default]
    Auto,
    /// Every scan is a stop.
    EachScan,
    /// A scan becomes a stop when the robot has moved [`StopRules::distance_m`] or turned
    /// [`StopRules::angle_deg`] since the last stop (by odometry), or, without odometry, every
    /// [`StopRules::interval_s`].
    Travelled,
}

/// The thresholds of [`StopPolicy::Travelled`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopRules {
    /// How the stops are chosen.
    pub policy: StopPolicy,
    /// Distance travelled between stops, metres.
    pub distance_m: f64,
    /// Angle turned between stops, degrees.
    pub angle_deg: f64,
    /// Time between stops without odometry, seconds.
    pub interval_s: f64,
}

impl Default for StopRules {
    fn default() -> Self {
        Self {
            policy: StopPolicy::Auto,
            distance_m: 1.0,
            angle_deg: 10.0,
            interval_s: 1.0,
        }
    }
}

/// Scans that come faster than this (median interval, seconds) are a LiDAR on the move.
pub const CONTINUOUS_BELOW_S: f64 = 1.0;

/// The policy `Auto` resolves to for scans at `stamps` (sorted), and why, in words.
pub fn resolve(policy: StopPolicy, stamps: &[i64], sweeps: bool) -> (StopPolicy, String) {
    match policy {
        StopPolicy::EachScan => (policy, "every scan (--stops each-scan)".into()),
        StopPolicy::Travelled => (
            policy,
            "by distance and angle travelled (--stops travelled)".into(),
        ),
        StopPolicy::Auto if sweeps => (
            StopPolicy::EachScan,
            "every sweep of the tilting laser".into(),
        ),
        StopPolicy::Auto => {
            let mut gaps: Vec<i64> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
            gaps.sort_unstable();
            let median_s = gaps
                .get(gaps.len() / 2)
                .map_or(f64::INFINITY, |&g| g as f64 * 1e-9);
            if median_s < CONTINUOUS_BELOW_S {
                (
                    StopPolicy::Travelled,
                    format!(
                        "by distance and angle travelled: the scans come every {median_s:.3} s \
                         (a LiDAR on the move)"
                    ),
                )
            } else if median_s.is_finite() {
                (
                    StopPolicy::EachScan,
                    format!("every scan: they come every {median_s:.1} s (a stop-and-go robot)"),
                )
            } else {
                (StopPolicy::EachScan, "every scan".into())
            }
        }
    }
}

/// The indices of the scans at `stamps` that become stops under `rules` (with `policy`
/// resolved), given the sensor's odometry pose at a stamp (`None` without odometry). A scan
/// whose odometry is unknown is never a stop of `Travelled`; the first known one always is.
pub fn choose(
    stamps: &[i64],
    policy: StopPolicy,
    rules: &StopRules,
    odom_from_sensor: Option<&dyn Fn(i64) -> Result<Pose, OutOfSpan>>,
) -> Vec<usize> {
    if policy != StopPolicy::Travelled {
        return (0..stamps.len()).collect();
    }
    let mut stops = Vec::new();
    match odom_from_sensor {
        Some(odom) => {
            let mut last: Option<Pose> = None;
            for (i, &t) in stamps.iter().enumerate() {
                let Ok(pose) = odom(t) else { continue };
                let far = last.is_none_or(|last| {
                    let delta = last.inverse() * pose;
                    delta.translation.vector.norm() >= rules.distance_m
                        || delta.rotation.angle().to_degrees() >= rules.angle_deg
                });
                if far {
                    stops.push(i);
                    last = Some(pose);
                }
            }
        }
        None => {
            let mut last: Option<i64> = None;
            for (i, &t) in stamps.iter().enumerate() {
                if last.is_none_or(|l| (t - l) as f64 * 1e-9 >= rules.interval_s) {
                    stops.push(i);
                    last = Some(t);
                }
            }
        }
    }
    stops
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: i64 = 1_000_000_000;

    #[test]
    fn auto_tells_a_stop_and_go_robot_from_a_moving_lidar() {
        let slow: Vec<i64> = (0..5).map(|i| i * 6 * S).collect();
        let fast: Vec<i64> = (0..50).map(|i| i * S / 10).collect();
        assert_eq!(
            resolve(StopPolicy::Auto, &slow, false).0,
            StopPolicy::EachScan
        );
        assert_eq!(
            resolve(StopPolicy::Auto, &fast, false).0,
            StopPolicy::Travelled
        );
        assert_eq!(
            resolve(StopPolicy::Auto, &fast, true).0,
            StopPolicy::EachScan
        );
    }

    #[test]
    fn travelled_stops_every_metre_or_ten_degrees() {
        // 0.51 m/s along x for 10 s, scans at 10 Hz, then a turn on the spot at 21°/s.
        let stamps: Vec<i64> = (0..150).map(|i| i * S / 10).collect();
        let odom = |t: i64| {
            let s = t as f64 * 1e-9;
            let x = 0.51 * s.min(10.0);
            let yaw = (21f64 * (s - 10.0).max(0.0)).to_radians();
            Ok(Pose::from_parts(
                nalgebra::Translation3::new(x, 0.0, 0.0),
                nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
            ))
        };
        let stops = choose(
            &stamps,
            StopPolicy::Travelled,
            &StopRules::default(),
            Some(&odom),
        );
        // Every 2 s (20 scans) along the line, then every 0.5 s (5 scans) in the turn.
        assert_eq!(&stops[..6], &[0, 20, 40, 60, 80, 100]);
        assert_eq!(&stops[6..], &[105, 110, 115, 120, 125, 130, 135, 140, 145]);
        let rules = StopRules {
            interval_s: 0.95,
            ..StopRules::default()
        };
        let timed = choose(&stamps, StopPolicy::Travelled, &rules, None);
        assert_eq!(timed.len(), 15);
    }
}
