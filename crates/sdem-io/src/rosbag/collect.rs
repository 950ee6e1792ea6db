//! The first pass over a bag: every topic counted, the small messages sdem uses (IMU,
//! odometry, transforms, joint states, laser lines) decoded and kept, and each point cloud's
//! stamp, frame and layout noted (its points are read in the second pass).

use super::messages::{self, MessageKind, TransformStamped};
use super::pointcloud::CloudLayout;
use super::storage::{Bag, BagMessage, Damage};
use super::tf::MovingSamples;
use crate::error::{Error, Result};
use std::collections::HashMap;
use std::path::PathBuf;

/// One topic as seen in the bag.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TopicStats {
    /// The topic.
    pub name: String,
    /// Its message type; empty when the bag does not name one.
    #[serde(rename = "type")]
    pub type_name: String,
    /// Its serialization format (`cdr`).
    pub serialization_format: String,
    /// How many messages it holds.
    pub count: u64,
    /// The first message's log time, nanoseconds.
    pub first_ns: i64,
    /// The last message's log time, nanoseconds.
    pub last_ns: i64,
}

impl TopicStats {
    /// The mean rate, messages per second (0 with fewer than two messages).
    pub fn rate_hz(&self) -> f64 {
        let span = (self.last_ns - self.first_ns) as f64 * 1e-9;
        if self.count < 2 || span <= 0.0 {
            0.0
        } else {
            (self.count - 1) as f64 / span
        }
    }
}

/// Where a message came from, for errors.
#[derive(Debug, Clone, PartialEq)]
pub struct Origin {
    /// The file.
    pub file: PathBuf,
    /// The message's index in its topic.
    pub index: u64,
}

/// A point cloud noted in the first pass.
#[derive(Debug, Clone)]
pub struct CloudEntry {
    /// Its stamp (the header's; the log time when the header has none), nanoseconds.
    pub stamp_ns: i64,
    /// Its frame.
    pub frame_id: String,
    /// Where it is.
    pub origin: Origin,
    /// Its points with a return, or why it cannot be read.
    pub returns: std::result::Result<usize, String>,
}

/// A message kept with its origin.
#[derive(Debug, Clone)]
pub struct Kept<T> {
    /// Its stamp, nanoseconds.
    pub stamp_ns: i64,
    /// The message.
    pub message: T,
    /// Where it is.
    pub origin: Origin,
}

/// What the first pass found.
#[derive(Debug, Default)]
pub struct Collected {
    /// Every topic, in the order of their first message.
    pub topics: Vec<TopicStats>,
    /// The point clouds of each `PointCloud2` topic.
    pub clouds: HashMap<String, Vec<CloudEntry>>,
    /// The lines of each `LaserScan` topic.
    pub laser: HashMap<String, Vec<Kept<messages::LaserScan>>>,
    /// The messages of each `Imu` topic.
    pub imu: HashMap<String, Vec<Kept<messages::Imu>>>,
    /// The messages of each `Odometry` topic.
    pub odometry: HashMap<String, Vec<Kept<messages::Odometry>>>,
    /// The messages of each `JointState` topic.
    pub joints: HashMap<String, Vec<Kept<messages::JointState>>>,
    /// The transforms of `/tf_static` (any `TFMessage` topic whose name ends in `tf_static`).
    pub tf_static: Vec<TransformStamped>,
    /// The transforms of the other `TFMessage` topics (`/tf`).
    pub tf_moving: MovingSamples,
    /// Where the bag stopped being readable, if it did.
    pub damage: Option<Damage>,
    /// Messages skipped with `salvage` because they did not decode, in words.
    pub skipped: Vec<String>,
}

impl Collected {
    /// The topic of that name.
    pub fn topic(&self, name: &str) -> Option<&TopicStats> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// The topics of a kind, by name.
    pub fn topics_of(&self, kind: MessageKind) -> Vec<&TopicStats> {
        self.topics
            .iter()
            .filter(|t| MessageKind::of_type(&t.type_name) == Some(kind))
            .collect()
    }
}

/// The stamp of a message: its header's, or its log time when the header's is zero.
fn stamp(header_ns: i64, log_ns: i64) -> i64 {
    if header_ns == 0 {
        log_ns
    } else {
        header_ns
    }
}

/// Reads every message of `bag` once; see [`Collected`]. With `salvage`, a message that does
/// not decode is skipped (and noted) instead of failing.
///
/// # Errors
/// A message of a kind sdem reads that is not CDR or does not decode (without `salvage`),
/// or a file that cannot be opened.
pub fn collect(bag: &Bag, salvage: bool, progress: &mut dyn FnMut(u64)) -> Result<Collected> {
    let mut out = Collected::default();
    let mut topic_index: HashMap<String, usize> = HashMap::new();
    let damage = bag.read(
        &mut |m: &BagMessage| {
            count_topic(&mut out.topics, &mut topic_index, m);
            let Some(kind) = MessageKind::of_type(m.type_name) else {
                return Ok(());
            };
            match keep(&mut out, kind, m) {
                Ok(()) => Ok(()),
                Err(why) if salvage => {
                    out.skipped.push(format!(
                        "{} #{} ({}): {why}",
                        m.topic,
                        m.index,
                        m.file.display()
                    ));
                    Ok(())
                }
                Err(why) => Err(Error::parse(
                    m.file,
                    None,
                    format!(
                        "{} message #{} ({}) does not decode: {why}; the bag is damaged or the \
                         topic's messages are not of this type; --salvage skips such messages",
                        m.topic, m.index, m.type_name
                    ),
                )),
            }
        },
        progress,
    )?;
    out.damage = damage;
    Ok(out)
}

pub(super) fn count_topic(
    topics: &mut Vec<TopicStats>,
    index: &mut HashMap<String, usize>,
    m: &BagMessage,
) {
    let i = *index.entry(m.topic.to_string()).or_insert_with(|| {
        topics.push(TopicStats {
            name: m.topic.to_string(),
            type_name: m.type_name.to_string(),
            serialization_format: m.serialization_format.to_string(),
            count: 0,
            first_ns: m.log_time_ns,
            last_ns: m.log_time_ns,
        });
        topics.len() - 1
    });
    let t = &mut topics[i];
    t.count += 1;
    t.first_ns = t.first_ns.min(m.log_time_ns);
    t.last_ns = t.last_ns.max(m.log_time_ns);
}

/// Decodes and keeps one message of a kind sdem reads.
fn keep(out: &mut Collected, kind: MessageKind, m: &BagMessage) -> std::result::Result<(), String> {
    if !m.serialization_format.eq_ignore_ascii_case("cdr") {
        return Err(format!(
            "its serialization format is '{}'; sdem reads CDR only",
            m.serialization_format
        ));
    }
    let origin = Origin {
        file: m.file.to_path_buf(),
        index: m.index,
    };
    let text = |e: super::cdr::CdrError| e.to_string();
    let topic = m.topic.to_string();
    match kind {
        MessageKind::PointCloud2 => {
            let cloud = messages::point_cloud2(m.data).map_err(text)?;
            let returns = CloudLayout::of(&cloud).map(|l| l.count_returns(&cloud));
            out.clouds.entry(topic).or_default().push(CloudEntry {
                stamp_ns: stamp(cloud.header.stamp_ns, m.log_time_ns),
                frame_id: cloud.header.frame_id,
                origin,
                returns,
            });
        }
        MessageKind::LaserScan => {
            let scan = messages::laser_scan(m.data).map_err(text)?;
            let stamp_ns = stamp(scan.header.stamp_ns, m.log_time_ns);
            push(&mut out.laser, topic, stamp_ns, scan, origin);
        }
        MessageKind::Imu => {
            let imu = messages::imu(m.data).map_err(text)?;
            let stamp_ns = stamp(imu.header.stamp_ns, m.log_time_ns);
            push(&mut out.imu, topic, stamp_ns, imu, origin);
        }
        MessageKind::Odometry => {
            let odom = messages::odometry(m.data).map_err(text)?;
            let stamp_ns = stamp(odom.header.stamp_ns, m.log_time_ns);
            push(&mut out.odometry, topic, stamp_ns, odom, origin);
        }
        MessageKind::JointState => {
            let joints = messages::joint_state(m.data).map_err(text)?;
            let stamp_ns = stamp(joints.header.stamp_ns, m.log_time_ns);
            push(&mut out.joints, topic, stamp_ns, joints, origin);
        }
        MessageKind::TfMessage => {
            let transforms = messages::tf_message(m.data).map_err(text)?;
            if m.topic.ends_with("tf_static") {
                out.tf_static.extend(transforms);
            } else {
                out.tf_moving.add(&transforms);
            }
        }
    }
    Ok(())
}

fn push<T>(
    map: &mut HashMap<String, Vec<Kept<T>>>,
    topic: String,
    stamp_ns: i64,
    message: T,
    origin: Origin,
) {
    map.entry(topic).or_default().push(Kept {
        stamp_ns,
        message,
        origin,
    });
}
