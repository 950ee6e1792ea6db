//! A mapped run as an MCAP file that Foxglove and RViz (through `ros2 bag play`) open: the
//! fused map and each stop's scan as `sensor_msgs/msg/PointCloud2`, the trajectory as
//! `nav_msgs/msg/Path`, the poses as `/tf` (`map` → `base_link`), the loop closures as
//! `visualization_msgs/msg/MarkerArray`. Every channel carries its ROS 2 message definition
//! (schema encoding `ros2msg`, the ROS 2 Jazzy definitions) and CDR messages, profile `ros2`.
//!
//! | topic | type | when | frame |
//! |---|---|---|---|
//! | `/sdem/map` | `sensor_msgs/msg/PointCloud2` | once, at the first stop | `map` |
//! | `/sdem/scans` | `sensor_msgs/msg/PointCloud2` | at each stop, that stop's scan | `map` |
//! | `/sdem/trajectory` | `nav_msgs/msg/Path` | once, at the first stop: every stop's pose | `map` |
//! | `/tf` | `tf2_msgs/msg/TFMessage` | at each stop: `map` → `base_link` | |
//! | `/sdem/loop_closures` | `visualization_msgs/msg/MarkerArray` | once, at the first stop: a line per accepted loop closure, a sphere per stop | `map` |
//!
//! Stop `i` is stamped `1 + i` seconds (the dataset keeps no clock). `base_link` is the frame
//! of the dataset's scans: the sensor. Point clouds have `x`, `y`, `z` as FLOAT32.

use crate::error::{Error, Result};
use crate::rosbag::CdrWriter;
use crate::write_atomic;
use sdem::geometry::{Pose, Vec3};
use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::Path;

const POINT_CLOUD2: &str = include_str!("schemas/PointCloud2.msg");
const PATH: &str = include_str!("schemas/Path.msg");
const TF_MESSAGE: &str = include_str!("schemas/TFMessage.msg");
const MARKER_ARRAY: &str = include_str!("schemas/MarkerArray.msg");

/// The frame of the map.
pub const MAP_FRAME: &str = "map";
/// The frame of the robot (the scans' sensor frame).
pub const ROBOT_FRAME: &str = "base_link";

/// A mapped run, as [`write_map_mcap`] writes it.
#[derive(Debug, Clone, Copy)]
pub struct MapScene<'a> {
    /// `world_from_sensor` of each stop.
    pub world_from_sensor: &'a [Pose],
    /// Each stop's scan in the world (map) frame, metres.
    pub scans_in_world: &'a [Vec<Vec3>],
    /// The fused map's points, world frame.
    pub map_cloud: &'a [Vec3],
    /// The accepted loop closures, as pairs of stop indices.
    pub loop_closures: &'a [(usize, usize)],
}

/// What [`write_map_mcap`] wrote.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct McapSummary {
    /// The file's size, bytes.
    pub bytes: u64,
    /// The messages written.
    pub messages: u64,
    /// Each topic with its type and message count.
    pub topics: TopicCounts,
}

fn stamp_ns(stop: usize) -> u64 {
    (1 + stop as u64) * 1_000_000_000
}

fn header(w: &mut CdrWriter, stamp: u64, frame: &str) {
    w.i32(i32::try_from(stamp / 1_000_000_000).unwrap_or(i32::MAX));
    w.u32((stamp % 1_000_000_000) as u32);
    w.string(frame);
}

fn pose(w: &mut CdrWriter, p: &Pose) {
    let t = p.translation.vector;
    let q = p.rotation.coords; // x, y, z, w
    for v in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
        w.f64(v);
    }
}

/// A `sensor_msgs/msg/PointCloud2` of `points` (x, y, z as FLOAT32, little-endian, dense).
pub fn point_cloud2_message(points: &[Vec3], stamp: u64, frame: &str) -> Vec<u8> {
    let mut w = CdrWriter::new();
    header(&mut w, stamp, frame);
    w.u32(1);
    w.u32(u32::try_from(points.len()).unwrap_or(u32::MAX));
    w.sequence_len(3);
    for (i, name) in ["x", "y", "z"].iter().enumerate() {
        w.string(name);
        w.u32(4 * i as u32);
        w.u8(7);
        w.u32(1);
    }
    w.bool(false);
    w.u32(12);
    w.u32(u32::try_from(points.len() * 12).unwrap_or(u32::MAX));
    let mut data = Vec::with_capacity(points.len() * 12);
    for p in points {
        for v in [p.x, p.y, p.z] {
            data.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    w.bytes(&data);
    w.bool(true);
    w.into_bytes()
}

fn path_message(poses: &[Pose], stamp: u64) -> Vec<u8> {
    let mut w = CdrWriter::new();
    header(&mut w, stamp, MAP_FRAME);
    w.sequence_len(poses.len());
    for (i, p) in poses.iter().enumerate() {
        header(&mut w, stamp_ns(i), MAP_FRAME);
        pose(&mut w, p);
    }
    w.into_bytes()
}

fn tf_message(world_from_sensor: &Pose, stamp: u64) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.sequence_len(1);
    header(&mut w, stamp, MAP_FRAME);
    w.string(ROBOT_FRAME);
    pose(&mut w, world_from_sensor);
    w.into_bytes()
}

/// One `visualization_msgs/msg/Marker` (ROS 2 Jazzy layout) of `points` in the map frame.
fn marker(w: &mut CdrWriter, id: i32, kind: i32, points: &[Vec3], scale: f64, rgba: [f32; 4]) {
    header(w, stamp_ns(0), MAP_FRAME);
    w.string("sdem");
    w.i32(id);
    w.i32(kind);
    w.i32(0); // ADD
    pose(w, &Pose::identity());
    for v in [scale, scale, scale] {
        w.f64(v);
    }
    for v in rgba {
        w.f32(v);
    }
    w.i32(0); // lifetime: forever
    w.u32(0);
    w.bool(false); // frame_locked
    w.sequence_len(points.len());
    for p in points {
        for v in [p.x, p.y, p.z] {
            w.f64(v);
        }
    }
    w.sequence_len(0); // colors
    w.string(""); // texture_resource
    header(w, 0, ""); // texture: CompressedImage
    w.string("");
    w.bytes(&[]);
    w.sequence_len(0); // uv_coordinates
    w.string(""); // text
    w.string(""); // mesh_resource
    w.string(""); // mesh_file.filename
    w.bytes(&[]); // mesh_file.data
    w.bool(false); // mesh_use_embedded_materials
}

fn loop_closure_message(scene: &MapScene) -> Vec<u8> {
    let position = |i: usize| scene.world_from_sensor[i].translation.vector;
    let lines: Vec<Vec3> = scene
        .loop_closures
        .iter()
        .filter(|(a, b)| *a < scene.world_from_sensor.len() && *b < scene.world_from_sensor.len())
        .flat_map(|&(a, b)| [position(a), position(b)])
        .collect();
    let stops: Vec<Vec3> = (0..scene.world_from_sensor.len()).map(position).collect();
    let mut w = CdrWriter::new();
    w.sequence_len(2);
    marker(&mut w, 0, 5, &lines, 0.03, [1.0, 0.3, 0.1, 1.0]); // LINE_LIST
    marker(&mut w, 1, 7, &stops, 0.08, [0.2, 0.6, 1.0, 1.0]); // SPHERE_LIST
    w.into_bytes()
}

/// The writer of the file, with a channel per topic.
struct Out {
    writer: mcap::Writer<Cursor<Vec<u8>>>,
    channels: Vec<(String, String, u16, u64)>,
}

impl Out {
    fn channel(
        &mut self,
        topic: &str,
        type_name: &str,
        definition: &str,
    ) -> mcap::McapResult<usize> {
        let schema = self
            .writer
            .add_schema(type_name, "ros2msg", definition.as_bytes())?;
        let id = self
            .writer
            .add_channel(schema, topic, "cdr", &BTreeMap::new())?;
        self.channels.push((topic.into(), type_name.into(), id, 0));
        Ok(self.channels.len() - 1)
    }

    fn write(&mut self, channel: usize, stamp: u64, data: &[u8]) -> mcap::McapResult<()> {
        let entry = &mut self.channels[channel];
        let header = mcap::records::MessageHeader {
            channel_id: entry.2,
            sequence: u32::try_from(entry.3).unwrap_or(u32::MAX),
            log_time: stamp,
            publish_time: stamp,
        };
        entry.3 += 1;
        self.writer.write_to_known_channel(&header, data)
    }
}

/// Each topic with its type and message count.
type TopicCounts = Vec<(String, String, u64)>;

fn encode(scene: &MapScene) -> mcap::McapResult<(Vec<u8>, TopicCounts)> {
    let options = mcap::WriteOptions::new()
        .profile("ros2")
        .library(concat!("sdem-io/", env!("CARGO_PKG_VERSION")));
    let mut out = Out {
        writer: options.create(Cursor::new(Vec::new()))?,
        channels: Vec::new(),
    };
    let map = out.channel("/sdem/map", "sensor_msgs/msg/PointCloud2", POINT_CLOUD2)?;
    let scans = out.channel("/sdem/scans", "sensor_msgs/msg/PointCloud2", POINT_CLOUD2)?;
    let path = out.channel("/sdem/trajectory", "nav_msgs/msg/Path", PATH)?;
    let tf = out.channel("/tf", "tf2_msgs/msg/TFMessage", TF_MESSAGE)?;
    let closures = out.channel(
        "/sdem/loop_closures",
        "visualization_msgs/msg/MarkerArray",
        MARKER_ARRAY,
    )?;
    let t0 = stamp_ns(0);
    out.write(
        map,
        t0,
        &point_cloud2_message(scene.map_cloud, t0, MAP_FRAME),
    )?;
    out.write(path, t0, &path_message(scene.world_from_sensor, t0))?;
    out.write(closures, t0, &loop_closure_message(scene))?;
    for (i, world_from_sensor) in scene.world_from_sensor.iter().enumerate() {
        let t = stamp_ns(i);
        out.write(tf, t, &tf_message(world_from_sensor, t))?;
        if let Some(points) = scene.scans_in_world.get(i) {
            out.write(scans, t, &point_cloud2_message(points, t, MAP_FRAME))?;
        }
    }
    out.writer.finish()?;
    let topics = out
        .channels
        .iter()
        .map(|(t, ty, _, n)| (t.clone(), ty.clone(), *n))
        .collect();
    Ok((out.writer.into_inner().into_inner(), topics))
}

/// Writes `scene` to `path` as MCAP (see the module documentation), atomically.
///
/// # Errors
/// [`Error::Invalid`] for a scene with no stop, or one with scans for other than its stops;
/// [`Error::Io`] when the file cannot be written.
pub fn write_map_mcap(path: &Path, scene: &MapScene) -> Result<McapSummary> {
    if scene.world_from_sensor.is_empty() {
        return Err(Error::Invalid(format!(
            "cannot write {}: the map has no stop",
            path.display()
        )));
    }
    if scene.scans_in_world.len() > scene.world_from_sensor.len() {
        return Err(Error::Invalid(format!(
            "cannot write {}: {} scans for {} stops",
            path.display(),
            scene.scans_in_world.len(),
            scene.world_from_sensor.len()
        )));
    }
    let (bytes, topics) = encode(scene)
        .map_err(|e| Error::io(path, std::io::Error::other(format!("encoding MCAP: {e}"))))?;
    write_atomic(path, |w| w.write_all(&bytes))?;
    Ok(McapSummary {
        bytes: bytes.len() as u64,
        messages: topics.iter().map(|t| t.2).sum(),
        topics,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rosbag::{Bag, BagMessage};

    #[test]
    fn a_written_map_reads_back_through_the_bag_reader() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.mcap");
        let poses = vec![Pose::identity(), Pose::translation(1.0, 0.0, 0.0)];
        let scans = vec![
            vec![Vec3::new(1.0, 2.0, 3.0)],
            vec![Vec3::new(2.0, 2.0, 3.0)],
        ];
        let map = vec![Vec3::new(0.5, 0.25, -1.0); 4];
        let scene = MapScene {
            world_from_sensor: &poses,
            scans_in_world: &scans,
            map_cloud: &map,
            loop_closures: &[(0, 1)],
        };
        let summary = write_map_mcap(&path, &scene).unwrap();
        assert_eq!(summary.messages, 3 + 2 * 2);
        let bag = Bag::open(&path).unwrap();
        let mut seen = Vec::new();
        let damage = bag
            .read(
                &mut |m: &BagMessage| {
                    seen.push((m.topic.to_string(), m.type_name.to_string(), m.data.len()));
                    Ok(())
                },
                &mut |_| {},
            )
            .unwrap();
        assert!(damage.is_none());
        assert_eq!(seen.len(), 7);
        assert!(seen
            .iter()
            .any(|s| s.0 == "/tf" && s.1 == "tf2_msgs/msg/TFMessage"));
        let first = &seen[0];
        assert_eq!(
            (first.0.as_str(), first.1.as_str()),
            ("/sdem/map", "sensor_msgs/msg/PointCloud2")
        );
    }
}
