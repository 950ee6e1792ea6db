//! A saved map's node files (`nodes/NNNNNN.pts`): each node's points, written once with a
//! CRC-32 and read back checked, and the record of which ones a folder holds.

use super::NODES_DIR;
use crate::error::{Error, Result};
use crate::voxels::crc32;
use crate::write_atomic;
use sdem::map::Node;
use std::path::Path;

const POINTS_MAGIC: &[u8; 8] = b"SDEMPTS1";
const POINTS_VERSION: u32 = 1;

/// The node files a map folder holds, as far as this process knows: node `i`'s file's CRC-32
/// and point count at index `i` (written by [`crate::save_map`] or a [`crate::MapFolder`], or checked
/// by [`crate::load_map`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeFiles {
    pub(super) files: Vec<Option<NodeFile>>,
}

/// One node file: its CRC-32 and its number of points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct NodeFile {
    pub(crate) crc32: u32,
    pub(crate) points: usize,
}

impl NodeFiles {
    /// Node `node_id`'s file, when it is written.
    pub(crate) fn get(&self, node_id: usize) -> Option<NodeFile> {
        self.files.get(node_id).copied().flatten()
    }

    /// Records node `node_id`'s file.
    pub(crate) fn set(&mut self, node_id: usize, file: NodeFile) {
        if self.files.len() <= node_id {
            self.files.resize(node_id + 1, None);
        }
        self.files[node_id] = Some(file);
    }

    /// Whether node `node_id`'s file is written.
    pub fn holds(&self, node_id: usize) -> bool {
        self.get(node_id).is_some()
    }
}

pub(super) fn points_file_name(node_id: usize) -> String {
    format!("{NODES_DIR}/{node_id:06}.pts")
}

pub(super) fn encode_points(points: &[[f32; 3]]) -> Vec<u8> {
    let mut out = Vec::with_capacity(24 + points.len() * 12);
    out.extend_from_slice(POINTS_MAGIC);
    out.extend_from_slice(&POINTS_VERSION.to_le_bytes());
    out.extend_from_slice(&(points.len() as u64).to_le_bytes());
    for p in points {
        for v in p {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    let crc = crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

pub(super) fn decode_points(path: &Path, bytes: &[u8], expected_crc: u32) -> Result<Vec<[f32; 3]>> {
    let bad = |why: String| Error::parse(path, None, why);
    if bytes.len() < 24 && POINTS_MAGIC.starts_with(&bytes[..bytes.len().min(8)]) {
        return Err(bad(format!(
            "truncated: {} bytes, too short for a node file (24 bytes at least); the map is \
             damaged: re-run sdem slam",
            bytes.len()
        )));
    }
    if bytes.len() < 24 || &bytes[..8] != POINTS_MAGIC {
        return Err(bad(format!(
            "not an sdem node file (it must start with {:?}); the map is damaged: re-run sdem slam",
            std::str::from_utf8(POINTS_MAGIC).unwrap_or("")
        )));
    }
    let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if version != POINTS_VERSION {
        return Err(bad(format!(
            "node file version {version}; this build reads version {POINTS_VERSION}"
        )));
    }
    let count = u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes"));
    let expected_len = count
        .checked_mul(12)
        .and_then(|b| b.checked_add(24))
        .filter(|&len| len == bytes.len() as u64);
    if expected_len.is_none() {
        return Err(bad(format!(
            "declares {count} points but holds {} bytes (truncated or damaged)",
            bytes.len()
        )));
    }
    let body = &bytes[..bytes.len() - 4];
    let stored = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().expect("4 bytes"));
    let computed = crc32(body);
    if stored != computed || computed != expected_crc {
        return Err(bad(format!(
            "checksum mismatch (file says {stored:08x}, content gives {computed:08x}, the map \
             expects {expected_crc:08x}): the file is damaged or from another map"
        )));
    }
    let mut points = Vec::with_capacity(count as usize);
    for (index, chunk) in body[20..].chunks_exact(12).enumerate() {
        let v = |k: usize| f32::from_le_bytes(chunk[k..k + 4].try_into().expect("4 bytes"));
        let p = [v(0), v(4), v(8)];
        if !p.iter().all(|x| x.is_finite()) {
            return Err(bad(format!(
                "point {index} (byte offset {}) is ({}, {}, {}); coordinates must be finite",
                20 + 12 * index,
                p[0],
                p[1],
                p[2]
            )));
        }
        points.push(p);
    }
    Ok(points)
}

/// Writes `node`'s points file into the map `folder` (its `nodes/` folder made already).
///
/// # Errors
/// A node without points in memory (parked in a node store: save through the
/// [`crate::MapFolder`] that keeps them), or the file system's errors.
pub(crate) fn write_node_file(folder: &Path, node: &Node) -> Result<NodeFile> {
    if node.points_in_sensor.is_empty() {
        return Err(Error::Invalid(format!(
            "node {} has no points in memory and no file in {}: a node parked in a node store \
             is saved by the store's own map folder (sdem_io::MapFolder)",
            node.node_id,
            folder.display()
        )));
    }
    let bytes = encode_points(&node.points_in_sensor);
    let crc = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().expect("4 bytes"));
    write_atomic(&folder.join(points_file_name(node.node_id)), |w| {
        w.write_all(&bytes)
    })?;
    Ok(NodeFile {
        crc32: crc,
        points: node.points_in_sensor.len(),
    })
}

/// Reads node `node_id`'s points file back from the map `folder`, checked against `file`.
///
/// # Errors
/// A missing, truncated or damaged file, naming it.
pub(crate) fn read_node_file(
    folder: &Path,
    node_id: usize,
    file: NodeFile,
) -> Result<Vec<[f32; 3]>> {
    let path = folder.join(points_file_name(node_id));
    let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
    let points = decode_points(&path, &bytes, file.crc32)?;
    if points.len() != file.points {
        return Err(Error::parse(
            &path,
            None,
            format!(
                "holds {} points, the map says {}",
                points.len(),
                file.points
            ),
        ));
    }
    Ok(points)
}
