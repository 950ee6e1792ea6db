//! `sdem info BAG`: what a bag holds, like `ros2 bag info`: its files, storage, time span,
//! and each topic's type, count and rate.

use super::collect::{count_topic, TopicStats};
use super::messages::MessageKind;
use super::storage::{Bag, Damage, Storage};
use crate::error::Result;
use std::collections::HashMap;
use std::path::PathBuf;

/// What a bag holds.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BagInfo {
    /// The bag (folder or file).
    pub path: PathBuf,
    /// Its storage.
    pub storage: Storage,
    /// Its files, in order.
    pub files: Vec<PathBuf>,
    /// Their size, bytes.
    pub size_bytes: u64,
    /// `zstd (FILE)` or `zstd (MESSAGE)` when the bag is compressed.
    pub compression: Option<String>,
    /// The messages read.
    pub messages: u64,
    /// What `metadata.yaml` says the bag holds, when it says.
    pub metadata_messages: Option<u64>,
    /// The first message's log time, seconds since the epoch.
    pub start_s: f64,
    /// The last message's log time, seconds since the epoch.
    pub end_s: f64,
    /// From the first message to the last, seconds.
    pub duration_s: f64,
    /// Every topic, in the order of its first message.
    pub topics: Vec<TopicInfo>,
    /// Where the bag stopped being readable, if it did.
    pub damage: Option<Damage>,
}

/// One topic of a bag.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TopicInfo {
    /// Name, type, serialization format, count, first and last log time.
    #[serde(flatten)]
    pub stats: TopicStats,
    /// Messages per second.
    pub rate_hz: f64,
    /// What `sdem import` can take from it: `scans`, `attitude`, `odometry`, `tilt`,
    /// `transforms`; `None` for a type sdem does not read.
    pub sdem_use: Option<&'static str>,
}

/// The use `sdem import` has for a message type.
pub fn sdem_use(type_name: &str) -> Option<&'static str> {
    Some(match MessageKind::of_type(type_name)? {
        MessageKind::PointCloud2 | MessageKind::LaserScan => "scans",
        MessageKind::Imu => "attitude",
        MessageKind::Odometry => "odometry",
        MessageKind::JointState => "tilt",
        MessageKind::TfMessage => "transforms",
    })
}

/// Reads the whole bag (every message, none decoded) and says what it holds; a damaged bag
/// is described up to the damage, which [`BagInfo::damage`] names.
///
/// # Errors
/// A bag that cannot be opened.
pub fn bag_info(path: &std::path::Path, progress: &mut dyn FnMut(u64)) -> Result<BagInfo> {
    let bag = Bag::open(path)?;
    let mut topics = Vec::new();
    let mut index = HashMap::new();
    let mut messages = 0u64;
    let damage = bag.read(
        &mut |m| {
            count_topic(&mut topics, &mut index, m);
            messages += 1;
            Ok(())
        },
        progress,
    )?;
    let start = topics
        .iter()
        .map(|t: &TopicStats| t.first_ns)
        .min()
        .unwrap_or(0);
    let end = topics.iter().map(|t| t.last_ns).max().unwrap_or(0);
    let compression = match (bag.file_compressed, bag.message_compressed) {
        (true, _) => Some("zstd (FILE)".to_string()),
        (_, true) => Some("zstd (MESSAGE)".to_string()),
        _ => None,
    };
    Ok(BagInfo {
        size_bytes: bag.size_bytes(),
        path: bag.path.clone(),
        storage: bag.storage,
        files: bag.files.clone(),
        compression,
        messages,
        metadata_messages: bag.metadata.as_ref().and_then(|m| m.message_count),
        start_s: start as f64 * 1e-9,
        end_s: end as f64 * 1e-9,
        duration_s: (end - start) as f64 * 1e-9,
        topics: topics
            .into_iter()
            .map(|stats| TopicInfo {
                rate_hz: stats.rate_hz(),
                sdem_use: sdem_use(&stats.type_name),
                stats,
            })
            .collect(),
        damage,
    })
}
