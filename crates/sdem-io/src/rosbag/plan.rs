//! What a bag's import is asked to do ([`BagImportOptions`]) and what it plans from the bag: the
//! scan topic's candidate scans before they become stops, and how the sensor is mounted.

use super::collect::Origin;
use super::select::Chosen;
use super::stops::StopRules;
use super::sweeps::SweepScan;
use super::tf::TfTree;
use sdem::geometry::{Attitude, Pose};
use sdem::sensor::SensorConfig;

/// What to import from a bag and how.
#[derive(Debug, Clone, PartialEq)]
pub struct BagImportOptions {
    /// The scan topic (`PointCloud2` or `LaserScan`); `None`: the only one of either type.
    pub scan_topic: Option<String>,
    /// The IMU topic; `None`: the only `Imu` topic, if any.
    pub imu_topic: Option<String>,
    /// The odometry topic; `None`: the only `Odometry` topic, if any.
    pub odom_topic: Option<String>,
    /// A tilting laser's `JointState` topic; `None`: the only one, if any.
    pub joint_topic: Option<String>,
    /// A tilting laser's joint; `None`: the one named `*tilt*`, or the only one.
    pub tilt_joint: Option<String>,
    /// A positive joint angle tilts the scan plane up (default: down, a joint about +y).
    pub tilt_positive_up: bool,
    /// Leave the IMU out (no `attitude.csv`).
    pub no_imu: bool,
    /// Leave the odometry out (no `odometry.txt`, no motion compensation).
    pub no_odometry: bool,
    /// How scans become stops.
    pub stops: StopRules,
    /// The least tilt a laser's sweep must span, degrees.
    pub min_sweep_deg: f64,
    /// Use what is readable before damage; leave out the scans that cannot be used.
    pub salvage: bool,
}

impl Default for BagImportOptions {
    fn default() -> Self {
        Self {
            scan_topic: None,
            imu_topic: None,
            odom_topic: None,
            joint_topic: None,
            tilt_joint: None,
            tilt_positive_up: false,
            no_imu: false,
            no_odometry: false,
            stops: StopRules::default(),
            min_sweep_deg: 20.0,
            salvage: false,
        }
    }
}

/// A scan before it becomes a stop.
pub(super) struct Candidate {
    pub(super) stamp_ns: i64,
    pub(super) origin: Origin,
    pub(super) sweep: Option<SweepScan>,
}

/// The scans of a bag before the stops are chosen.
pub(super) struct Plan {
    pub(super) scan: Chosen,
    pub(super) sensor_frame: String,
    pub(super) candidates: Vec<Candidate>,
    /// Where a laser's tilt came from, in words.
    pub(super) tilt: Option<String>,
    /// A laser's sensor model.
    pub(super) laser: Option<SensorConfig>,
    pub(super) left_out: Vec<String>,
}

/// `base_from_sensor` from `/tf_static`, or identity, with the mounting in words.
pub(super) fn mounting(tree: &TfTree, base_frame: &str, sensor_frame: &str) -> (Pose, String) {
    match tree.fixed_transform(base_frame, sensor_frame) {
        // One frame: nothing to join, whatever /tf_static holds.
        Some(pose) if base_frame == sensor_frame => (
            pose,
            format!("identity: the clouds are in {base_frame}, the robot's own frame"),
        ),
        Some(pose) => {
            let t = pose.translation.vector;
            let [r, p, y] = Attitude::from_quaternion(&pose.rotation).to_degrees();
            (
                pose,
                format!(
                    "{base_frame} → {sensor_frame} from /tf_static: ({:.3}, {:.3}, {:.3}) m, roll \
                     {r:.2}° pitch {p:.2}° yaw {y:.2}°",
                    t.x, t.y, t.z
                ),
            )
        }
        None => (
            Pose::identity(),
            format!(
                "identity: no /tf_static transform joins {base_frame} and {sensor_frame}, so the \
                 sensor is taken to sit at the robot's origin, axes aligned"
            ),
        ),
    }
}
