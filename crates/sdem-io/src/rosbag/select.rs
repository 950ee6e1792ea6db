//! Choosing the bag's topics: the scans, the IMU, the odometry and a tilting laser's joint,
//! by message type when there is one of a kind, by name when the user says.

use super::collect::{Collected, TopicStats};
use super::messages::MessageKind;
use crate::error::{Error, Result};

/// A topic chosen for one role, and why.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Chosen {
    /// The topic.
    pub topic: String,
    /// Its message kind.
    #[serde(skip)]
    pub kind: MessageKind,
    /// How it was chosen: `--scan-topic`, or `the only PointCloud2 topic`.
    pub why: String,
}

fn short(kind: MessageKind) -> &'static str {
    kind.type_name().rsplit('/').next().unwrap_or("")
}

/// The bag's topics in words, one `name (type, N messages)` each, for error messages.
pub fn topic_list(collected: &Collected) -> String {
    if collected.topics.is_empty() {
        return "no messages at all".to_string();
    }
    collected
        .topics
        .iter()
        .map(|t| {
            let type_name = if t.type_name.is_empty() {
                "no type"
            } else {
                &t.type_name
            };
            format!("{} ({type_name}, {} messages)", t.name, t.count)
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Checks that the topic the user named exists and holds one of `kinds`.
fn named(collected: &Collected, name: &str, flag: &str, kinds: &[MessageKind]) -> Result<Chosen> {
    let wanted = kinds
        .iter()
        .map(|k| k.type_name())
        .collect::<Vec<_>>()
        .join(" or ");
    let Some(topic) = collected.topic(name) else {
        return Err(Error::Invalid(format!(
            "{flag} {name}: the bag has no such topic (it holds {}); name a topic of type \
             {wanted}",
            topic_list(collected)
        )));
    };
    check_type(topic, flag, kinds, &wanted)?;
    let kind = MessageKind::of_type(&topic.type_name).expect("the type was checked");
    Ok(Chosen {
        topic: name.to_string(),
        kind,
        why: flag.to_string(),
    })
}

fn check_type(topic: &TopicStats, flag: &str, kinds: &[MessageKind], wanted: &str) -> Result<()> {
    if topic.type_name.is_empty() {
        return Err(Error::Invalid(format!(
            "{flag} {}: the bag does not say its message type (no schema); sdem needs {wanted}: \
             record it with a rosbag2 that stores types, or name another topic",
            topic.name
        )));
    }
    match MessageKind::of_type(&topic.type_name) {
        Some(k) if kinds.contains(&k) => Ok(()),
        _ => Err(Error::Invalid(format!(
            "{flag} {}: its type is {}, which sdem cannot use here; it needs {wanted}",
            topic.name, topic.type_name
        ))),
    }
}

/// The one topic of `kind`, `None` when there is none.
///
/// # Errors
/// Several topics of the kind: the message lists them and names the flag that chooses.
fn only_one(collected: &Collected, kind: MessageKind, flag: &str) -> Result<Option<Chosen>> {
    let topics = collected.topics_of(kind);
    match topics.as_slice() {
        [] => Ok(None),
        [one] => Ok(Some(Chosen {
            topic: one.name.clone(),
            kind,
            why: format!("the only {} topic", short(kind)),
        })),
        several => Err(Error::Invalid(format!(
            "the bag holds {} {} topics: {}; choose one with {flag}",
            several.len(),
            short(kind),
            several
                .iter()
                .map(|t| format!("{} ({} messages)", t.name, t.count))
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    }
}

/// The scan topic: `--scan-topic`, else the only `PointCloud2` topic, else the only
/// `LaserScan` topic.
///
/// # Errors
/// A named topic that is missing or of another type; several candidates; none at all (the
/// message lists the bag's topics).
pub fn scan_topic(collected: &Collected, name: Option<&str>) -> Result<Chosen> {
    let kinds = [MessageKind::PointCloud2, MessageKind::LaserScan];
    if let Some(name) = name {
        return named(collected, name, "--scan-topic", &kinds);
    }
    if let Some(chosen) = only_one(collected, MessageKind::PointCloud2, "--scan-topic")? {
        return Ok(chosen);
    }
    if let Some(chosen) = only_one(collected, MessageKind::LaserScan, "--scan-topic")? {
        return Ok(chosen);
    }
    Err(Error::Invalid(format!(
        "the bag holds no sensor_msgs/msg/PointCloud2 or sensor_msgs/msg/LaserScan topic to \
         take scans from (it holds {}); record the LiDAR's or laser's topic",
        topic_list(collected)
    )))
}

/// A topic of one `kind` for an optional role (IMU, odometry, joints): the named one, else
/// the only one, else none.
///
/// # Errors
/// A named topic that is missing or of another type; several candidates and none named.
pub fn optional_topic(
    collected: &Collected,
    kind: MessageKind,
    name: Option<&str>,
    flag: &str,
) -> Result<Option<Chosen>> {
    match name {
        Some(name) => named(collected, name, flag, &[kind]).map(Some),
        None => only_one(collected, kind, flag),
    }
}

/// The tilt joint among `names` (the joints a `JointState` topic reports): the named one, else
/// the one whose name holds "tilt", else the only one.
///
/// # Errors
/// A named joint that is not there; several joints and none named or with "tilt" in its name.
pub fn tilt_joint(topic: &str, names: &[String], wanted: Option<&str>) -> Result<String> {
    let list = names.join(", ");
    if let Some(wanted) = wanted {
        return names
            .iter()
            .find(|n| n.as_str() == wanted)
            .cloned()
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "--tilt-joint {wanted}: {topic} reports no such joint (it reports {list})"
                ))
            });
    }
    let tilts: Vec<&String> = names
        .iter()
        .filter(|n| n.to_ascii_lowercase().contains("tilt"))
        .collect();
    match (tilts.as_slice(), names) {
        ([one], _) => Ok((*one).clone()),
        ([], [only]) => Ok(only.clone()),
        _ => Err(Error::Invalid(format!(
            "{topic} reports the joints {list}; name the laser's tilt joint with --tilt-joint"
        ))),
    }
}
