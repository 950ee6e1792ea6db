//! Files that sdem wrote before its CRC-32 came from `crc32fast` still load: the fixtures in
//! `tests/fixtures/map-before-crc32fast/` (a saved map of two nodes and a voxel map) were
//! written by the hand-written slicing-by-4 CRC-32 that `crc32fast` replaced. Both compute
//! CRC-32/ISO-HDLC (zlib's), so every checksum in them must match.

use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/map-before-crc32fast")
        .join(name)
}

/// The little-endian `u32` at the end of `bytes`, and the bytes before it.
fn split_checksum(bytes: &[u8]) -> (&[u8], u32) {
    let (body, tail) = bytes.split_at(bytes.len() - 4);
    (body, u32::from_le_bytes(tail.try_into().unwrap()))
}

#[test]
fn checksums_written_by_the_older_crc_match_crc32fast() {
    for name in [
        "map/nodes/000000.pts",
        "map/nodes/000001.pts",
        "map.sdemvox",
    ] {
        let bytes = std::fs::read(fixture(name)).unwrap();
        let (body, stored) = split_checksum(&bytes);
        assert_eq!(crc32fast::hash(body), stored, "{name}");
    }
    // The manifest's checksum covers the canonical JSON text of its body.
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(fixture("map/map.json")).unwrap()).unwrap();
    let canonical = serde_json::to_vec(&manifest["body"]).unwrap();
    assert_eq!(
        u64::from(crc32fast::hash(&canonical)),
        manifest["checksum"].as_u64().unwrap()
    );
    // The standard check value of CRC-32/ISO-HDLC.
    assert_eq!(crc32fast::hash(b"123456789"), 0xCBF4_3926);
}

#[test]
fn a_map_and_a_voxel_map_saved_before_crc32fast_load() {
    let saved = sdem_io::load_map(&fixture("map")).unwrap();
    assert_eq!(saved.map.nodes.len(), 2);
    assert_eq!(saved.edges.len(), 1);
    let node = &saved.map.nodes[1];
    assert_eq!(node.scan_index, 2);
    assert_eq!(node.points_in_sensor.len(), 6);
    assert_eq!(node.points_in_sensor[5], [1.25, 0.375, 0.5]);
    assert!((node.world_from_sensor.translation.vector.x - 0.5).abs() < 1e-12);

    let voxels = sdem_io::read_voxel_map(&fixture("map.sdemvox")).unwrap();
    assert_eq!(voxels.config().voxel_m, 0.25);
    let (occupied, free) = voxels.counts();
    assert!(
        occupied >= 10 && free > occupied,
        "{occupied} occupied, {free} free"
    );
}
