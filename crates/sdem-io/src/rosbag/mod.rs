//! ROS 2 bags: reading rosbag2 recordings (MCAP or SQLite3 storage) without a ROS
//! installation, and making a dataset folder of them ([`import_rosbag`]).
//!
//! # What is read
//!
//! A bag is a rosbag2 folder (`metadata.yaml` and its `.mcap` or `.db3` files, optionally
//! zstd-compressed by file or by message) or a single `.mcap` or `.db3` file. Messages are read
//! in file order ([`Bag::read`]) with the `mcap` crate or SQLite (`rusqlite`, bundled) and
//! decoded from CDR by this module (`cdr.rs`); these types are used:
//!
//! | type | becomes |
//! |---|---|
//! | `sensor_msgs/msg/PointCloud2` | a scan: `x`, `y`, `z` as FLOAT32 or FLOAT64 at any offset, other fields ignored, `point_step` and `row_step` honoured, either byte order, organized or not; points with a NaN or infinite coordinate, or at exactly the origin, are dropped |
//! | `sensor_msgs/msg/LaserScan` | a tilting 2D laser's line; the lines of one sweep (the tilt moving one way) make one scan |
//! | `sensor_msgs/msg/JointState` | the laser's tilt: the joint named by `tilt_joint`, else the one with `tilt` in its name, else the only one |
//! | `sensor_msgs/msg/Imu` | the attitude: the orientation, interpolated (slerp) at each scan's stamp; its covariance, when it gives one, sets the σ in `attitude.csv` |
//! | `nav_msgs/msg/Odometry` | `odometry.txt`: the pose, interpolated at each scan's stamp |
//! | `tf2_msgs/msg/TFMessage` | on `/tf_static`: the mountings (`base_from_sensor`, `imu_from_sensor`); on `/tf`: a moving laser frame |
//!
//! Stamps are the messages' header stamps (the log time where a header's is zero).
//!
//! # Frames
//!
//! sdem's dataset holds points in the sensor frame and the attitude of the sensor. A cloud's
//! `frame_id` is the sensor frame. The IMU's orientation (`world_from_imu`) becomes the
//! sensor's attitude through `imu_from_sensor` from `/tf_static`: `world_from_imu ·
//! imu_from_sensor`. The odometry's pose of its child frame (`odom_from_base`) becomes the
//! sensor's through `base_from_sensor`. Where `/tf_static` joins no such frames the transform
//! is identity, and the summary says so. A tilting laser's scans are in the frame that `/tf`
//! moves the laser in, or, with a joint, in the laser's frame at zero tilt (sdem's sensor
//! model, [`sdem::sensor`]).
//!
//! # Damage
//!
//! A file cut short or otherwise unreadable stops the reading where the damage is
//! ([`Damage`]: the file, the byte, the last whole message). The import then refuses, unless
//! asked to salvage, when it uses every message before the damage.

mod cdr;
mod collect;
mod import;
mod info;
mod laser;
mod messages;
mod metadata;
mod plan;
mod pointcloud;
mod select;
mod series;
mod sqlite_pages;
mod stops;
mod storage;
mod sweeps;
mod tf;

pub use cdr::{CdrError, CdrReader, CdrWriter};
pub use collect::TopicStats;
pub use import::{import_rosbag, BagImportSummary, ImportProgress};
pub use info::{bag_info, sdem_use, BagInfo, TopicInfo};
pub use plan::BagImportOptions;
pub use select::Chosen;
pub use stops::{StopPolicy, StopRules, CONTINUOUS_BELOW_S};
pub use storage::{Bag, BagMessage, Damage, Storage};

/// Whether `path` looks like a ROS 2 bag: a folder with `metadata.yaml`, or one holding
/// `.mcap` or `.db3` files and neither a KITTI sequence's `velodyne/` nor 3DTK's scans (a bag
/// folder whose `metadata.yaml` was lost: a recording killed before writing it), or a file that
/// is MCAP or SQLite by its extension in any case (optionally `.zstd`) or its first bytes.
pub fn is_rosbag(path: &std::path::Path) -> bool {
    if path.is_dir() {
        if path.join("metadata.yaml").is_file() {
            return true;
        }
        let Ok(entries) = std::fs::read_dir(path) else {
            return false;
        };
        let holds_bag_files = entries
            .flatten()
            .map(|e| e.path())
            .any(|p| p.is_file() && storage::storage_by_name(&p).is_some());
        return holds_bag_files && !crate::import::holds_scans(path);
    }
    path.is_file() && storage::storage_of_file(path).is_some()
}
