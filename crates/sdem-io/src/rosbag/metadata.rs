//! A rosbag2 folder's `metadata.yaml`: the storage, the files in order, the topics with their
//! types and counts, and the compression.

use crate::error::{Error, Result};
use std::path::Path;
use yaml_rust2::{Yaml, YamlLoader};

/// What `metadata.yaml` says about a bag.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Metadata {
    /// `storage_identifier`: `mcap` or `sqlite3`.
    pub storage_identifier: String,
    /// `relative_file_paths`: the bag's files, in order.
    pub relative_file_paths: Vec<String>,
    /// `topics_with_message_count`: name, type, serialization format and count of each topic.
    pub topics: Vec<MetadataTopic>,
    /// `message_count`: all messages.
    pub message_count: Option<u64>,
    /// `compression_format` (`zstd`) and `compression_mode` (`FILE` or `MESSAGE`), empty when
    /// the bag is not compressed.
    pub compression_format: String,
    /// See `compression_format`.
    pub compression_mode: String,
}

/// One topic in `metadata.yaml`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MetadataTopic {
    /// The topic's name.
    pub name: String,
    /// Its message type, `pkg/msg/Type`.
    pub type_name: String,
    /// Its serialization format (`cdr`).
    pub serialization_format: String,
    /// How many messages it holds.
    pub count: u64,
}

fn text(y: &Yaml) -> String {
    match y {
        Yaml::String(s) => s.clone(),
        Yaml::Integer(i) => i.to_string(),
        Yaml::Real(r) => r.clone(),
        _ => String::new(),
    }
}

fn count(y: &Yaml) -> Option<u64> {
    y.as_i64().and_then(|v| u64::try_from(v).ok())
}

/// Reads `metadata.yaml`.
///
/// # Errors
/// [`Error::Io`], or [`Error::Parse`] when it is not YAML or lacks
/// `rosbag2_bagfile_information` with a `storage_identifier`.
pub fn read_metadata(path: &Path) -> Result<Metadata> {
    let text_in = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_metadata(path, &text_in)
}

/// Parses the text of `metadata.yaml` (`path` names it in errors).
pub fn parse_metadata(path: &Path, source: &str) -> Result<Metadata> {
    let docs = YamlLoader::load_from_str(source).map_err(|e| {
        Error::parse(
            path,
            Some(e.marker().line()),
            format!("not YAML: {e}; metadata.yaml of a rosbag2 folder was expected"),
        )
    })?;
    let info = docs
        .first()
        .map(|d| &d["rosbag2_bagfile_information"])
        .filter(|i| !i.is_badvalue())
        .ok_or_else(|| {
            Error::parse(
                path,
                None,
                "no 'rosbag2_bagfile_information' mapping: this is not a rosbag2 metadata.yaml",
            )
        })?;
    let storage_identifier = text(&info["storage_identifier"]);
    if storage_identifier.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "rosbag2_bagfile_information has no storage_identifier (mcap or sqlite3)",
        ));
    }
    let relative_file_paths = info["relative_file_paths"]
        .as_vec()
        .map(|v| v.iter().map(text).filter(|s| !s.is_empty()).collect())
        .unwrap_or_default();
    let topics = info["topics_with_message_count"]
        .as_vec()
        .map(|v| {
            v.iter()
                .map(|t| {
                    let m = &t["topic_metadata"];
                    MetadataTopic {
                        name: text(&m["name"]),
                        type_name: text(&m["type"]),
                        serialization_format: text(&m["serialization_format"]),
                        count: count(&t["message_count"]).unwrap_or(0),
                    }
                })
                .collect()
        })
        .unwrap_or_default();
    Ok(Metadata {
        storage_identifier,
        relative_file_paths,
        topics,
        message_count: count(&info["message_count"]),
        compression_format: text(&info["compression_format"]),
        compression_mode: text(&info["compression_mode"]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "rosbag2_bagfile_information:
  version: 9
  storage_identifier: mcap
  duration:
    nanoseconds: 4000000000
  starting_time:
    nanoseconds_since_epoch: 1700000000000000000
  message_count: 12
  topics_with_message_count:
    - topic_metadata:
        name: /robot/points
        type: sensor_msgs/msg/PointCloud2
        serialization_format: cdr
        offered_qos_profiles: []
        type_description_hash: RIHS01_abc
      message_count: 2
    - topic_metadata:
        name: /imu
        type: sensor_msgs/msg/Imu
        serialization_format: cdr
        offered_qos_profiles: ''
      message_count: 10
  compression_format: ''
  compression_mode: ''
  relative_file_paths:
    - run_0.mcap
  files:
    - path: run_0.mcap
      message_count: 12
";

    #[test]
    fn a_rosbag2_metadata_file_reads() {
        let m = parse_metadata(Path::new("metadata.yaml"), SAMPLE).unwrap();
        assert_eq!(m.storage_identifier, "mcap");
        assert_eq!(m.relative_file_paths, vec!["run_0.mcap"]);
        assert_eq!(m.message_count, Some(12));
        assert_eq!(m.topics.len(), 2);
        assert_eq!(m.topics[0].name, "/robot/points");
        assert_eq!(m.topics[0].type_name, "sensor_msgs/msg/PointCloud2");
        assert_eq!(m.topics[1].count, 10);
        assert!(m.compression_mode.is_empty());
    }

    #[test]
    fn other_yaml_is_refused() {
        let e = parse_metadata(Path::new("m.yaml"), "a: 1\n").unwrap_err();
        assert!(e.to_string().contains("not a rosbag2 metadata.yaml"), "{e}");
        let e = parse_metadata(Path::new("m.yaml"), "a: [1\n").unwrap_err();
        assert!(e.to_string().contains("not YAML"), "{e}");
    }
}
