//! Helpers shared by the integration tests of the readers.

pub mod formats;

/// CRC-32 (IEEE), as zlib computes it: the checksum of voxel maps, node files and manifests.
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

/// `bytes` with the trailing CRC-32 recomputed, so that the reader gets past the checksum.
pub fn resealed(mut bytes: Vec<u8>) -> Vec<u8> {
    let body = bytes.len() - 4;
    let crc = crc32(&bytes[..body]);
    bytes[body..].copy_from_slice(&crc.to_le_bytes());
    bytes
}
