//! The `.sdemvox` occupancy voxel map format, version 1 (specified in the module documentation of
//! [`crate`]).

use super::{read_bytes, write_atomic};
use crate::error::{Error, Result};
use sdem::voxel::{VoxelConfig, VoxelKey, VoxelMap, MAX_KEY};
use std::path::Path;

/// The eight bytes that start a `.sdemvox` file.
pub const VOXEL_MAGIC: [u8; 8] = *b"sdem-vox";

/// The `.sdemvox` format version this sdem writes and reads.
pub const VOXEL_VERSION: u32 = 1;

/// The file extension of voxel maps, without the dot.
pub const VOXEL_EXTENSION: &str = "sdemvox";

/// Bytes before the records: magic, version, six `f64` of configuration, the `u64` count.
const HEADER_LEN: usize = 8 + 4 + 6 * 8 + 8;

/// Bytes per record: `i32` x, y, z and `f32` log-odds.
const RECORD_LEN: usize = 16;

/// Bytes of the trailing CRC-32.
const CHECKSUM_LEN: usize = 4;

/// Writes a voxel map in the `.sdemvox` format (version 1), atomically. The records are sorted by
/// key, so the same map always gives the same bytes.
///
/// # Example
/// ```
/// use sdem::geometry::{Pose, Vec3};
/// use sdem::voxel::{VoxelConfig, VoxelMap};
/// # let dir = std::env::temp_dir().join(format!("sdem-doc-vox-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// let mut map = VoxelMap::new(VoxelConfig::default()).unwrap();
/// map.insert_scan(&Pose::identity(), &[Vec3::new(1.0, 0.2, 0.1)]);
/// let path = dir.join("map.sdemvox");
/// sdem_io::write_voxel_map(&path, &map).unwrap();
/// let back = sdem_io::read_voxel_map(&path).unwrap();
/// assert_eq!(back.counts(), map.counts());
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn write_voxel_map(path: &Path, map: &VoxelMap) -> Result<()> {
    let bytes = encode(map);
    write_atomic(path, |w| w.write_all(&bytes))
}

/// The whole file as bytes.
fn encode(map: &VoxelMap) -> Vec<u8> {
    let mut records: Vec<(VoxelKey, f32)> = map.iter().collect();
    records.sort_unstable_by_key(|(key, _)| *key);
    let c = map.config();
    let mut out = Vec::with_capacity(HEADER_LEN + RECORD_LEN * records.len() + CHECKSUM_LEN);
    out.extend_from_slice(&VOXEL_MAGIC);
    out.extend_from_slice(&VOXEL_VERSION.to_le_bytes());
    for v in [
        c.voxel_m,
        c.hit_log_odds,
        c.miss_log_odds,
        c.min_log_odds,
        c.max_log_odds,
        c.max_range_m,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&(records.len() as u64).to_le_bytes());
    for (key, log_odds) in &records {
        for v in key {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&log_odds.to_le_bytes());
    }
    let checksum = crc32(&out);
    out.extend_from_slice(&checksum.to_le_bytes());
    out
}

/// Reads a `.sdemvox` voxel map. Every malformed file — wrong magic, a newer or unknown
/// version, truncated or padded, a count that disagrees with the size, a checksum mismatch, an
/// invalid configuration, a non-finite or out-of-range log-odds, a repeated voxel — is an
/// [`Error::Parse`] naming the file; an OS failure is an [`Error::Io`].
pub fn read_voxel_map(path: &Path) -> Result<VoxelMap> {
    let bytes = read_bytes(path)?;
    decode(path, &bytes)
}

/// Parses the bytes of a file (`path` only names it in errors).
fn decode(path: &Path, bytes: &[u8]) -> Result<VoxelMap> {
    let bad = |message: String| Error::parse(path, None, message);
    let magic_len = VOXEL_MAGIC.len();
    if bytes.len() < magic_len || bytes[..magic_len] != VOXEL_MAGIC {
        let prefix = &bytes[..bytes.len().min(magic_len)];
        return Err(if VOXEL_MAGIC.starts_with(prefix) {
            bad(format!(
                "truncated: {} bytes, too short for a .{VOXEL_EXTENSION} voxel map",
                bytes.len()
            ))
        } else {
            bad(format!(
                "not an sdem voxel map: the file does not start with {:?}",
                String::from_utf8_lossy(&VOXEL_MAGIC)
            ))
        });
    }
    let mut reader = Reader {
        bytes,
        at: magic_len,
    };
    let truncated = || {
        bad(format!(
            "truncated: {} bytes, too short for the .{VOXEL_EXTENSION} header",
            bytes.len()
        ))
    };
    let version = reader.u32().ok_or_else(truncated)?;
    if version > VOXEL_VERSION {
        return Err(bad(format!(
            "format version {version} was written by a newer sdem; this sdem reads version \
             {VOXEL_VERSION}: update sdem"
        )));
    }
    if version != VOXEL_VERSION {
        return Err(bad(format!(
            "format version {version} does not exist; this sdem reads version {VOXEL_VERSION}"
        )));
    }
    let mut fields = [0.0f64; 6];
    for f in &mut fields {
        *f = reader.f64().ok_or_else(truncated)?;
    }
    let count = reader.u64().ok_or_else(truncated)?;
    // The size the count implies, before anything is allocated for the records.
    let expected = usize::try_from(count)
        .ok()
        .and_then(|n| n.checked_mul(RECORD_LEN))
        .and_then(|n| n.checked_add(HEADER_LEN + CHECKSUM_LEN));
    if expected != Some(bytes.len()) {
        let implied = expected.map_or_else(|| "more than can exist".to_string(), |n| n.to_string());
        return Err(bad(format!(
            "the header declares {count} voxels ({implied} bytes in all) but the file has {} \
             bytes: it is truncated or damaged",
            bytes.len()
        )));
    }
    let body_len = bytes.len() - CHECKSUM_LEN;
    let mut stored = [0u8; 4];
    stored.copy_from_slice(&bytes[body_len..]);
    let stored = u32::from_le_bytes(stored);
    let computed = crc32(&bytes[..body_len]);
    if stored != computed {
        return Err(bad(format!(
            "checksum mismatch (stored {stored:08x}, computed {computed:08x}): the file is damaged"
        )));
    }
    let [voxel_m, hit_log_odds, miss_log_odds, min_log_odds, max_log_odds, max_range_m] = fields;
    let config = VoxelConfig {
        voxel_m,
        hit_log_odds,
        miss_log_odds,
        min_log_odds,
        max_log_odds,
        max_range_m,
    };
    config.validate().map_err(|e| bad(e.to_string()))?;
    let (lo, hi) = (config.min_log_odds as f32, config.max_log_odds as f32);
    let mut records: Vec<(VoxelKey, f32)> = Vec::with_capacity(count as usize);
    for index in 0..records.capacity() {
        let offset = reader.at;
        // The size check above guarantees the bytes are there.
        let (Some(x), Some(y), Some(z), Some(log_odds)) =
            (reader.i32(), reader.i32(), reader.i32(), reader.f32())
        else {
            return Err(truncated());
        };
        let key = [x, y, z];
        let at = |why: String| bad(format!("record {index} (byte offset {offset}): {why}"));
        if !(log_odds.is_finite() && lo <= log_odds && log_odds <= hi) {
            return Err(at(format!(
                "voxel {key:?} has log-odds {log_odds}; it must be finite and within \
                 [min_log_odds, max_log_odds] = [{lo}, {hi}]"
            )));
        }
        if key.iter().any(|v| f64::from(v.unsigned_abs()) > MAX_KEY) {
            return Err(at(format!(
                "voxel {key:?} is out of range; keys are at most {MAX_KEY} in magnitude"
            )));
        }
        if let Some((previous, _)) = records.last() {
            if key <= *previous {
                let why = if key == *previous {
                    "appears twice"
                } else {
                    "comes after a larger key; records are sorted by (i, j, k)"
                };
                return Err(at(format!("voxel {key:?} {why}")));
            }
        }
        records.push((key, log_odds));
    }
    VoxelMap::from_voxels(config, records).map_err(|e| bad(e.to_string()))
}

/// A little-endian cursor over the file's bytes; `None` past the end.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let slice = self.bytes.get(self.at..self.at.checked_add(N)?)?;
        self.at += N;
        let mut out = [0u8; N];
        out.copy_from_slice(slice);
        Some(out)
    }

    fn u32(&mut self) -> Option<u32> {
        self.take().map(u32::from_le_bytes)
    }

    fn i32(&mut self) -> Option<i32> {
        self.take().map(i32::from_le_bytes)
    }

    fn u64(&mut self) -> Option<u64> {
        self.take().map(u64::from_le_bytes)
    }

    fn f32(&mut self) -> Option<f32> {
        self.take().map(f32::from_le_bytes)
    }

    fn f64(&mut self) -> Option<f64> {
        self.take().map(f64::from_le_bytes)
    }
}

/// CRC-32 as in zlib, PNG and gzip (CRC-32/ISO-HDLC: polynomial 0x04C11DB7, reflected;
/// `zlib.crc32` in Python gives the same number), computed by `crc32fast`.
pub(super) fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sdem::geometry::{Pose, Vec3};

    fn sample_map() -> VoxelMap {
        let mut map = VoxelMap::new(VoxelConfig {
            voxel_m: 0.1,
            max_range_m: 5.0,
            ..Default::default()
        })
        .unwrap();
        let points: Vec<Vec3> = (0..200)
            .map(|i| {
                let a = f64::from(i) * 0.1;
                Vec3::new(2.0 * a.cos(), 2.0 * a.sin(), 0.3 * (a * 3.0).sin())
            })
            .collect();
        map.insert_scan(&Pose::translation(0.03, -0.02, 0.4), &points);
        map.insert_scan(&Pose::translation(-0.5, 0.7, 0.2), &points);
        map
    }

    #[test]
    fn voxel_crc32_matches_zlib() {
        // The standard check value of CRC-32/ISO-HDLC.
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
        assert_eq!(
            crc32(b"The quick brown fox jumps over the lazy dog"),
            0x414F_A339
        );
    }

    #[test]
    fn voxel_file_round_trip_is_bit_identical() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.sdemvox");
        let map = sample_map();
        assert!(map.counts().0 > 10 && map.counts().1 > 100);
        write_voxel_map(&path, &map).unwrap();
        let back = read_voxel_map(&path).unwrap();
        assert_eq!(back.config(), map.config());
        let mut a: Vec<_> = map.iter().map(|(k, l)| (k, l.to_bits())).collect();
        let mut b: Vec<_> = back.iter().map(|(k, l)| (k, l.to_bits())).collect();
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b);
        // Writing what was read gives the same bytes.
        let again = dir.path().join("again.sdemvox");
        write_voxel_map(&again, &back).unwrap();
        assert_eq!(
            std::fs::read(&path).unwrap(),
            std::fs::read(&again).unwrap()
        );
        // An empty map round-trips too.
        let empty = VoxelMap::new(VoxelConfig::default()).unwrap();
        write_voxel_map(&path, &empty).unwrap();
        assert!(read_voxel_map(&path).unwrap().is_empty());
    }

    /// The error for `bytes`, which must be a parse error naming the file.
    fn parse_error(bytes: &[u8]) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("broken.sdemvox");
        std::fs::write(&path, bytes).unwrap();
        let err = read_voxel_map(&path).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, Error::Parse { .. }), "{msg}");
        assert!(msg.contains("broken.sdemvox"), "{msg}");
        msg
    }

    /// `bytes` with its checksum recomputed, so a check after the checksum is reached.
    fn resealed(mut bytes: Vec<u8>) -> Vec<u8> {
        let body = bytes.len() - CHECKSUM_LEN;
        let crc = crc32(&bytes[..body]);
        bytes[body..].copy_from_slice(&crc.to_le_bytes());
        bytes
    }

    #[test]
    fn voxel_file_errors_name_the_file() {
        let good = encode(&sample_map());
        // Truncated anywhere, including inside the header and the magic.
        for len in [0, 3, 8, 10, HEADER_LEN - 1, HEADER_LEN + 5, good.len() - 1] {
            let msg = parse_error(&good[..len]);
            assert!(msg.contains("truncated"), "{len}: {msg}");
        }
        // Padded.
        let mut padded = good.clone();
        padded.push(0);
        assert!(parse_error(&padded).contains("truncated or damaged"));
        // Wrong magic: a PLY file, say.
        assert!(parse_error(b"ply\nformat ascii 1.0\n").contains("not an sdem voxel map"));
        // A newer version, and a version that never existed.
        let mut newer = good.clone();
        newer[8..12].copy_from_slice(&2u32.to_le_bytes());
        assert!(parse_error(&newer).contains("newer sdem"));
        let mut zero = good.clone();
        zero[8..12].copy_from_slice(&0u32.to_le_bytes());
        assert!(parse_error(&zero).contains("does not exist"));
        // One flipped bit in a record, in the header, in the checksum itself.
        for at in [HEADER_LEN + 17, 20, good.len() - 1] {
            let mut corrupt = good.clone();
            corrupt[at] ^= 0x10;
            assert!(parse_error(&corrupt).contains("checksum"), "byte {at}");
        }
        // Absurd counts: nothing is allocated, no overflow.
        for count in [u64::MAX, u64::MAX / 16, 1 << 40] {
            let mut absurd = good.clone();
            absurd[HEADER_LEN - 8..HEADER_LEN].copy_from_slice(&count.to_le_bytes());
            assert!(parse_error(&absurd).contains("declares"), "{count}");
        }
        // Valid checksum over invalid content: a non-finite log-odds, an invalid configuration,
        // a repeated voxel.
        let mut nan = good.clone();
        nan[HEADER_LEN + 12..HEADER_LEN + 16].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(parse_error(&resealed(nan)).contains("log-odds"));
        let mut bad_size = good.clone();
        bad_size[12..20].copy_from_slice(&(-1.0f64).to_le_bytes());
        assert!(parse_error(&resealed(bad_size)).contains("voxel_m"));
        let mut twice = good.clone();
        let first = good[HEADER_LEN..HEADER_LEN + 12].to_vec();
        twice[HEADER_LEN + 16..HEADER_LEN + 28].copy_from_slice(&first);
        assert!(parse_error(&resealed(twice)).contains("twice"));
        // A missing file is an I/O error naming it.
        let err = read_voxel_map(Path::new("/nonexistent/x.sdemvox")).unwrap_err();
        assert!(matches!(err, Error::Io { .. }) && err.to_string().contains("x.sdemvox"));
    }
}
