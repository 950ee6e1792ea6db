//! Helpers shared by the integration tests of the readers.

/// CRC-32 (IEEE), as zlib computes it: the checksum of voxel maps, node files and manifests.
/// Written here apart from the library's, so the tests do not trust the code they check.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                0xEDB8_8320 ^ (crc >> 1)
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// `bytes` with the trailing CRC-32 recomputed, so that the reader gets past the checksum.
pub fn resealed(mut bytes: Vec<u8>) -> Vec<u8> {
    let body = bytes.len() - 4;
    let crc = crc32(&bytes[..body]);
    bytes[body..].copy_from_slice(&crc.to_le_bytes());
    bytes
}
