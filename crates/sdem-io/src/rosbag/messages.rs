//! The ROS 2 messages sdem reads from a bag, decoded from CDR ([`super::cdr`]), and the message
//! types it recognises by name.

use super::cdr::{CdrReader, CdrResult};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use sdem::geometry::Pose;

/// The message types sdem reads, by their ROS 2 names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MessageKind {
    /// `sensor_msgs/msg/PointCloud2`: a 3D scan.
    PointCloud2,
    /// `sensor_msgs/msg/LaserScan`: one line of a 2D laser range finder.
    LaserScan,
    /// `sensor_msgs/msg/JointState`: joint angles (the tilt of a tilting laser).
    JointState,
    /// `sensor_msgs/msg/Imu`: orientation (the attitude).
    Imu,
    /// `nav_msgs/msg/Odometry`: dead-reckoned poses.
    Odometry,
    /// `tf2_msgs/msg/TFMessage`: transforms (`/tf`, `/tf_static`).
    TfMessage,
}

impl MessageKind {
    /// The kind of a ROS message type name (`sensor_msgs/msg/Imu`; the ROS 1 form
    /// `sensor_msgs/Imu` is accepted too), `None` for any other type.
    pub fn of_type(type_name: &str) -> Option<Self> {
        let normal = type_name.replace("/msg/", "/");
        Some(match normal.as_str() {
            "sensor_msgs/PointCloud2" => Self::PointCloud2,
            "sensor_msgs/LaserScan" => Self::LaserScan,
            "sensor_msgs/JointState" => Self::JointState,
            "sensor_msgs/Imu" => Self::Imu,
            "nav_msgs/Odometry" => Self::Odometry,
            "tf2_msgs/TFMessage" => Self::TfMessage,
            _ => return None,
        })
    }

    /// The ROS 2 type name.
    pub fn type_name(self) -> &'static str {
        match self {
            Self::PointCloud2 => "sensor_msgs/msg/PointCloud2",
            Self::LaserScan => "sensor_msgs/msg/LaserScan",
            Self::JointState => "sensor_msgs/msg/JointState",
            Self::Imu => "sensor_msgs/msg/Imu",
            Self::Odometry => "nav_msgs/msg/Odometry",
            Self::TfMessage => "tf2_msgs/msg/TFMessage",
        }
    }
}

/// `std_msgs/Header`: the stamp (nanoseconds since the epoch) and the frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    /// The stamp, nanoseconds.
    pub stamp_ns: i64,
    /// The frame the data is in.
    pub frame_id: String,
}

fn time(r: &mut CdrReader, field: &str) -> CdrResult<i64> {
    let sec = r.i32(&format!("{field}.sec"))?;
    let nanosec = r.u32(&format!("{field}.nanosec"))?;
    Ok(i64::from(sec) * 1_000_000_000 + i64::from(nanosec))
}

fn header(r: &mut CdrReader) -> CdrResult<Header> {
    Ok(Header {
        stamp_ns: time(r, "header.stamp")?,
        frame_id: r.string("header.frame_id")?,
    })
}

fn quaternion(r: &mut CdrReader, field: &str) -> CdrResult<[f64; 4]> {
    r.f64_array::<4>(field)
}

fn vector3(r: &mut CdrReader, field: &str) -> CdrResult<[f64; 3]> {
    r.f64_array::<3>(field)
}

/// A rotation from a message's `x, y, z, w`, normalized; `None` when it is not finite or too
/// far from unit length to be a rotation (a zero quaternion: "no orientation").
pub fn rotation_of(xyzw: [f64; 4]) -> Option<UnitQuaternion<f64>> {
    let [x, y, z, w] = xyzw;
    let q = Quaternion::new(w, x, y, z);
    let norm = q.norm();
    (norm.is_finite() && (norm - 1.0).abs() < 0.01).then(|| UnitQuaternion::from_quaternion(q))
}

/// A pose from a translation and a message quaternion; `None` when either is unusable.
pub fn pose_of(translation: [f64; 3], xyzw: [f64; 4]) -> Option<Pose> {
    let rotation = rotation_of(xyzw)?;
    translation
        .iter()
        .all(|v| v.is_finite())
        .then(|| Isometry3::from_parts(Translation3::from(translation), rotation))
}

/// `sensor_msgs/PointField`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PointField {
    /// The field's name (`x`, `y`, `z`, `intensity`, …).
    pub name: String,
    /// Its offset within a point, bytes.
    pub offset: u32,
    /// Its type: 1 INT8, 2 UINT8, 3 INT16, 4 UINT16, 5 INT32, 6 UINT32, 7 FLOAT32, 8 FLOAT64.
    pub datatype: u8,
    /// How many values it holds.
    pub count: u32,
}

/// `sensor_msgs/PointCloud2`, its data borrowed from the message.
#[derive(Debug, Clone, PartialEq)]
pub struct PointCloud2<'a> {
    /// Stamp and frame.
    pub header: Header,
    /// Rows (1 for an unorganized cloud).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// The layout of a point.
    pub fields: Vec<PointField>,
    /// Whether the data is big-endian.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// The points.
    pub data: &'a [u8],
}

/// Decodes a `sensor_msgs/PointCloud2`.
pub fn point_cloud2(bytes: &[u8]) -> CdrResult<PointCloud2<'_>> {
    let mut r = CdrReader::new(bytes)?;
    let header = header(&mut r)?;
    let height = r.u32("height")?;
    let width = r.u32("width")?;
    let count = r.sequence_len("fields", 13)?;
    let mut fields = Vec::with_capacity(count);
    for i in 0..count {
        fields.push(PointField {
            name: r.string(&format!("fields[{i}].name"))?,
            offset: r.u32(&format!("fields[{i}].offset"))?,
            datatype: r.u8(&format!("fields[{i}].datatype"))?,
            count: r.u32(&format!("fields[{i}].count"))?,
        });
    }
    Ok(PointCloud2 {
        header,
        height,
        width,
        fields,
        is_bigendian: r.bool("is_bigendian")?,
        point_step: r.u32("point_step")?,
        row_step: r.u32("row_step")?,
        data: r.bytes("data")?,
    })
}

/// `sensor_msgs/LaserScan`.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Stamp (of the first beam) and frame.
    pub header: Header,
    /// Angle of the first beam, radians.
    pub angle_min: f32,
    /// Angle of the last beam, radians.
    pub angle_max: f32,
    /// Angle between beams, radians.
    pub angle_increment: f32,
    /// Time between beams, seconds.
    pub time_increment: f32,
    /// Shortest valid range, metres.
    pub range_min: f32,
    /// Longest valid range, metres.
    pub range_max: f32,
    /// The ranges, metres.
    pub ranges: Vec<f32>,
}

/// Decodes a `sensor_msgs/LaserScan` (intensities are not read).
pub fn laser_scan(bytes: &[u8]) -> CdrResult<LaserScan> {
    let mut r = CdrReader::new(bytes)?;
    let header = header(&mut r)?;
    let angle_min = r.f32("angle_min")?;
    let angle_max = r.f32("angle_max")?;
    let angle_increment = r.f32("angle_increment")?;
    let time_increment = r.f32("time_increment")?;
    let _scan_time = r.f32("scan_time")?;
    Ok(LaserScan {
        header,
        angle_min,
        angle_max,
        angle_increment,
        time_increment,
        range_min: r.f32("range_min")?,
        range_max: r.f32("range_max")?,
        ranges: r.f32_sequence("ranges")?,
    })
}

/// `sensor_msgs/JointState` (names and positions).
#[derive(Debug, Clone, PartialEq)]
pub struct JointState {
    /// Stamp and frame.
    pub header: Header,
    /// The joints' names.
    pub name: Vec<String>,
    /// Their positions (radians for a revolute joint).
    pub position: Vec<f64>,
}

/// Decodes a `sensor_msgs/JointState` (velocities and efforts are not read).
pub fn joint_state(bytes: &[u8]) -> CdrResult<JointState> {
    let mut r = CdrReader::new(bytes)?;
    let header = header(&mut r)?;
    let count = r.sequence_len("name", 4)?;
    let name = (0..count)
        .map(|i| r.string(&format!("name[{i}]")))
        .collect::<CdrResult<_>>()?;
    Ok(JointState {
        header,
        name,
        position: r.f64_sequence("position")?,
    })
}

/// `sensor_msgs/Imu` (the orientation and its covariance).
#[derive(Debug, Clone, PartialEq)]
pub struct Imu {
    /// Stamp and frame.
    pub header: Header,
    /// The orientation `world_from_imu` as `x, y, z, w`.
    pub orientation: [f64; 4],
    /// Its covariance about x, y, z, row-major, rad²; `[0] = -1` means no orientation.
    pub orientation_covariance: [f64; 9],
}

/// Decodes a `sensor_msgs/Imu` (rates and accelerations are not read).
pub fn imu(bytes: &[u8]) -> CdrResult<Imu> {
    let mut r = CdrReader::new(bytes)?;
    Ok(Imu {
        header: header(&mut r)?,
        orientation: quaternion(&mut r, "orientation")?,
        orientation_covariance: r.f64_array::<9>("orientation_covariance")?,
    })
}

/// `nav_msgs/Odometry` (the pose).
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// Stamp and the odometry frame.
    pub header: Header,
    /// The frame whose pose it is (`base_link`).
    pub child_frame_id: String,
    /// The position, metres.
    pub position: [f64; 3],
    /// The orientation as `x, y, z, w`.
    pub orientation: [f64; 4],
}

/// Decodes a `nav_msgs/Odometry` (the covariance and twist are not read).
pub fn odometry(bytes: &[u8]) -> CdrResult<Odometry> {
    let mut r = CdrReader::new(bytes)?;
    Ok(Odometry {
        header: header(&mut r)?,
        child_frame_id: r.string("child_frame_id")?,
        position: vector3(&mut r, "pose.pose.position")?,
        orientation: quaternion(&mut r, "pose.pose.orientation")?,
    })
}

/// `geometry_msgs/TransformStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// Stamp and the parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// `parent_from_child`'s translation, metres.
    pub translation: [f64; 3],
    /// `parent_from_child`'s rotation as `x, y, z, w`.
    pub rotation: [f64; 4],
}

/// Decodes a `tf2_msgs/TFMessage`.
pub fn tf_message(bytes: &[u8]) -> CdrResult<Vec<TransformStamped>> {
    let mut r = CdrReader::new(bytes)?;
    let count = r.sequence_len("transforms", 80)?;
    (0..count)
        .map(|i| {
            let field = |name: &str| format!("transforms[{i}].{name}");
            Ok(TransformStamped {
                header: Header {
                    stamp_ns: time(&mut r, &field("header.stamp"))?,
                    frame_id: r.string(&field("header.frame_id"))?,
                },
                child_frame_id: r.string(&field("child_frame_id"))?,
                translation: vector3(&mut r, &field("transform.translation"))?,
                rotation: quaternion(&mut r, &field("transform.rotation"))?,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rosbag::cdr::CdrWriter;

    fn write_header(w: &mut CdrWriter, sec: i32, nanosec: u32, frame: &str) {
        w.i32(sec);
        w.u32(nanosec);
        w.string(frame);
    }

    #[test]
    fn type_names_are_recognised_in_both_spellings() {
        assert_eq!(
            MessageKind::of_type("sensor_msgs/msg/Imu"),
            Some(MessageKind::Imu)
        );
        assert_eq!(
            MessageKind::of_type("nav_msgs/Odometry"),
            Some(MessageKind::Odometry)
        );
        assert_eq!(MessageKind::of_type("sensor_msgs/msg/Image"), None);
        for kind in [
            MessageKind::PointCloud2,
            MessageKind::LaserScan,
            MessageKind::JointState,
            MessageKind::Imu,
            MessageKind::Odometry,
            MessageKind::TfMessage,
        ] {
            assert_eq!(MessageKind::of_type(kind.type_name()), Some(kind));
        }
    }

    #[test]
    fn an_odometry_message_decodes_field_by_field() {
        let mut w = CdrWriter::new();
        write_header(&mut w, 3, 500, "odom");
        w.string("base_link");
        for v in [1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0] {
            w.f64(v);
        }
        let odom = odometry(&w.into_bytes()).unwrap();
        assert_eq!(odom.header.stamp_ns, 3_000_000_500);
        assert_eq!(odom.header.frame_id, "odom");
        assert_eq!(odom.child_frame_id, "base_link");
        assert_eq!(odom.position, [1.0, 2.0, 3.0]);
        assert_eq!(odom.orientation, [0.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn a_message_of_another_type_is_refused_with_the_field() {
        let mut w = CdrWriter::new();
        write_header(&mut w, 1, 0, "imu");
        let e = imu(&w.into_bytes()).unwrap_err();
        assert_eq!(e.field, "orientation");
    }

    #[test]
    fn unusable_quaternions_are_not_rotations() {
        assert!(rotation_of([0.0, 0.0, 0.0, 0.0]).is_none());
        assert!(rotation_of([f64::NAN, 0.0, 0.0, 1.0]).is_none());
        assert!(rotation_of([0.0, 0.0, 0.0, 1.001]).is_some());
    }
}
