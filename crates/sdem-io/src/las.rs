//! ASPRS LAS and LAZ point clouds (`.las`, `.laz`), read with the `las` crate (LAZ decoded by
//! `laz`, always built in: it adds about 2 s to a clean build).
//!
//! Coordinates are the header's `X = x_raw · x_scale + x_offset` (and so for y, z), which
//! `las` applies; sdem takes them as metres in the sensor frame, like every scan (a
//! georeferenced file is refused by [`crate::read_points`]'s unit check). Other attributes
//! (intensity, returns, colour, GPS time) are ignored. Every LAS version 1.0–1.4 and point format
//! 0–10 that `las` reads is accepted; another version is refused, naming it.
//!
//! Before `las` sees the file, the counts it would trust are checked against the file's size:
//! the point records (uncompressed), the first extended VLR's length (LAS 1.4), and for LAZ the
//! chunk table (its chunk count must fit in the compressed bytes, and for fixed-size chunks
//! match the header's point count), so a header that lies is an error naming it, never a huge
//! allocation. Points are then decoded in batches of at most [`BATCH_BYTES`].

use super::read_bytes;
use crate::error::{Error, Result};
use sdem::geometry::Vec3;
use std::io::Cursor;
use std::path::Path;

/// Points are decoded this many bytes of records at a time.
const BATCH_BYTES: usize = 4 << 20;

/// The newest LAS version read is 1.this (LAS 1.4, the latest ASPRS specification).
const MAX_LAS_MINOR: u8 = 4;

/// The LASzip VLR: user id and record id.
const LASZIP_USER_ID: &str = "laszip encoded";
const LASZIP_RECORD_ID: u16 = 22204;

/// Reads the x, y, z of every point of a LAS or LAZ file (see the module documentation).
pub(super) fn read_las(path: &Path) -> Result<Vec<Vec3>> {
    let bytes = read_bytes(path)?;
    let err = |message: String| Error::parse(path, None, message);
    if bytes.is_empty() {
        return Err(err(
            "the file is empty; expected a LAS header starting with 'LASF'".into(),
        ));
    }
    if !bytes.starts_with(b"LASF") {
        let start = String::from_utf8_lossy(bytes.get(..4).unwrap_or(&bytes));
        return Err(err(format!(
            "the file starts with {start:?}, not the LAS magic 'LASF'; it is not a LAS or LAZ \
             file"
        )));
    }
    // The version (bytes 24 and 25) decides the header's layout: checked before it is read.
    if let (Some(&major), Some(&minor)) = (bytes.get(24), bytes.get(25)) {
        if !(major == 1 && minor <= MAX_LAS_MINOR) {
            return Err(err(format!(
                "LAS version {major}.{minor} is not supported: sdem reads LAS 1.0 to \
                 1.{MAX_LAS_MINOR}, the versions ASPRS has published (the header's bytes 24 and \
                 25); the file is damaged or of a newer format"
            )));
        }
    }
    let raw = las::raw::Header::read_from(&bytes[..]).map_err(|e| {
        err(format!(
            "the file ({} bytes) ends inside the LAS header, or the header is malformed ({e}); \
             the file is truncated or damaged",
            bytes.len()
        ))
    })?;
    let declared = check_raw_header(path, &raw, &bytes)?;
    let header = las::Header::new(Cursor::new(&bytes[..]))
        .map_err(|e| err(format!("the LAS header or its VLRs are malformed: {e}")))?;
    if header.point_format().is_compressed {
        let data_start = u64::from(raw.offset_to_point_data);
        let layout = (data_start, raw.point_data_record_length);
        check_laz_chunks(path, &header, &bytes, layout, declared)?;
    }
    let record_len = usize::from(raw.point_data_record_length);
    read_points_of(path, bytes, record_len, declared)
}

/// Checks the raw header's numbers against the file's size; returns the declared point count.
fn check_raw_header(path: &Path, raw: &las::raw::Header, bytes: &[u8]) -> Result<u64> {
    let file_len = bytes.len() as u64;
    let err = |message: String| Error::parse(path, None, message);
    let scales = [raw.x_scale_factor, raw.y_scale_factor, raw.z_scale_factor];
    let offsets = [raw.x_offset, raw.y_offset, raw.z_offset];
    if scales.iter().any(|s| !s.is_finite() || *s == 0.0) || offsets.iter().any(|o| !o.is_finite())
    {
        return Err(err(format!(
            "the header's scale factors {scales:?} and offsets {offsets:?} must be finite, the \
             scales non-zero; the header is damaged"
        )));
    }
    let declared = match (raw.number_of_point_records, &raw.large_file) {
        (0, Some(large)) => large.number_of_point_records,
        (legacy, _) => u64::from(legacy),
    };
    let start = u64::from(raw.offset_to_point_data);
    if start > file_len {
        return Err(err(format!(
            "the header puts the point records at byte offset {start}, past the end of the file \
             ({file_len} bytes); the file is truncated"
        )));
    }
    let record_len = u64::from(raw.point_data_record_length);
    let compressed = raw.point_data_record_format & 0x80 != 0;
    if !compressed {
        let held = (file_len - start) / record_len.max(1);
        if declared
            .checked_mul(record_len)
            .is_none_or(|n| n > file_len - start)
        {
            return Err(err(format!(
                "the header declares {declared} points of {record_len} bytes from byte offset \
                 {start}, but the file ({file_len} bytes) holds {held}: the file is truncated or \
                 the header is wrong"
            )));
        }
        check_no_uncounted_points(path, raw, file_len, declared)?;
    } else if declared.checked_mul(record_len).is_none() {
        return Err(err(format!(
            "the header declares {declared} points of {record_len} bytes, more than any file \
             holds; the header is damaged"
        )));
    }
    if let Some(evlr) = &raw.evlr {
        check_first_evlr(path, evlr, bytes)?;
    }
    Ok(declared)
}

/// Refuses uncompressed point records beyond the header's count: `las` reads only the declared
/// count, so a header that a writer did not update (or points appended after it) would silently
/// lose the rest. The points end where the first extended VLR (LAS 1.4) or an internal waveform
/// packet record (LAS 1.3) starts, else at the end of the file; fewer bytes than one record
/// left over are not a point and are tolerated, as padding some writers add.
fn check_no_uncounted_points(
    path: &Path,
    raw: &las::raw::Header,
    file_len: u64,
    declared: u64,
) -> Result<()> {
    let start = u64::from(raw.offset_to_point_data);
    let record_len = u64::from(raw.point_data_record_length);
    let evlr = raw
        .evlr
        .as_ref()
        .filter(|e| e.number_of_evlrs > 0)
        .map(|e| e.start_of_first_evlr);
    let end = [evlr, raw.start_of_waveform_data_packet_record]
        .into_iter()
        .flatten()
        .filter(|&at| at > start)
        .fold(file_len, u64::min);
    // The caller checked that the declared records fit in the file.
    let points_end = start + declared * record_len;
    let extra = end.saturating_sub(points_end);
    if record_len > 0 && extra >= record_len {
        let held = (end - start) / record_len;
        return Err(Error::parse(
            path,
            None,
            format!(
                "the file holds {held} point records of {record_len} bytes from byte offset \
                 {start}, more than the {declared} the header declares; the header's point count \
                 is wrong or points were appended (rewrite the file with a tool that updates the \
                 header, e.g. `las2las`)"
            ),
        ));
    }
    Ok(())
}

/// The first extended VLR (LAS 1.4), which `las` reads, must hold no more data than the file.
fn check_first_evlr(path: &Path, evlr: &las::raw::header::Evlr, bytes: &[u8]) -> Result<()> {
    let start = evlr.start_of_first_evlr;
    if evlr.number_of_evlrs == 0 || start == 0 {
        return Ok(());
    }
    // 2 reserved, 16 user id, 2 record id, 8 length, 32 description, then the data. A header cut
    // off before its length is left to `las`, which stops there before allocating anything.
    const EVLR_HEADER: u64 = 60;
    let length = usize::try_from(start.saturating_add(20))
        .ok()
        .and_then(|at| bytes.get(at..at + 8))
        .map(|b| u64::from_le_bytes(b.try_into().unwrap_or_default()));
    let Some(length) = length else {
        return Ok(());
    };
    let file_len = bytes.len() as u64;
    if start.saturating_add(EVLR_HEADER).saturating_add(length) > file_len {
        return Err(Error::parse(
            path,
            None,
            format!(
                "the extended VLR at byte offset {start} declares {length} bytes of data, past \
                 the end of the file ({file_len} bytes); the file is truncated or damaged"
            ),
        ));
    }
    Ok(())
}

/// The LASzip VLR's items against the record length, and the LAZ chunk table's count, checked
/// before `laz` allocates a table of that many entries.
fn check_laz_chunks(
    path: &Path,
    header: &las::Header,
    bytes: &[u8],
    (data_start, record_len): (u64, u16),
    declared: u64,
) -> Result<()> {
    let err = |message: String| Error::parse(path, None, message);
    let Some(vlr) = header
        .all_vlrs()
        .find(|v| v.user_id == LASZIP_USER_ID && v.record_id == LASZIP_RECORD_ID)
    else {
        return Err(err(
            "the point format says LAZ, but the file has no LASzip VLR ('laszip encoded', \
             22204); the file is damaged"
                .into(),
        ));
    };
    let field = |at: usize, len: usize| vlr.data.get(at..at + len);
    let compressor = field(0, 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let chunk_size = field(12, 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let (Some(compressor), Some(chunk_size)) = (compressor, chunk_size) else {
        return Err(err(format!(
            "the LASzip VLR holds {} bytes, too few for its fields; the file is damaged",
            vlr.data.len()
        )));
    };
    check_laz_items(path, &vlr.data, record_len)?;
    if compressor < 2 {
        return Ok(()); // Not chunked: no chunk table.
    }
    let i64_at = |at: u64| -> Option<u64> {
        let at = usize::try_from(at).ok()?;
        let raw = bytes.get(at..at.checked_add(8)?)?;
        u64::try_from(i64::from_le_bytes(raw.try_into().ok()?)).ok()
    };
    // As LASzip: the offset before the points, else (when the writer could not seek back) the
    // last 8 bytes of the file.
    let table = [
        i64_at(data_start),
        i64_at((bytes.len() as u64).saturating_sub(8)),
    ]
    .into_iter()
    .flatten()
    .find(|&offset| offset > data_start);
    let Some(table) = table else {
        return Ok(()); // No chunk table: `laz` reads the chunks in order or says it is missing.
    };
    let count = usize::try_from(table.saturating_add(4))
        .ok()
        .and_then(|at| bytes.get(at..at + 4))
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let Some(count) = count else {
        return Err(err(format!(
            "the LAZ chunk table is at byte offset {table}, past the end of the file ({} bytes); \
             the file is truncated",
            bytes.len()
        )));
    };
    let compressed_bytes = table.saturating_sub(data_start + 8);
    if u64::from(count) > compressed_bytes {
        return Err(err(format!(
            "the LAZ chunk table (byte offset {table}) declares {count} chunks, more than the \
             {compressed_bytes} bytes of compressed points can hold; the file is damaged"
        )));
    }
    let variable = chunk_size == 0 || chunk_size == u32::MAX;
    if !variable {
        let expected = declared.div_ceil(u64::from(chunk_size));
        if u64::from(count) != expected {
            return Err(err(format!(
                "the header declares {declared} points, but the LAZ chunk table holds {count} \
                 chunks of {chunk_size} points ({expected} expected); the header is wrong or the \
                 file is truncated"
            )));
        }
    }
    Ok(())
}

/// The LASzip VLR's items (type, size, version; 6 bytes each, after their count at byte 32)
/// split each point record: `laz` panics when an item's size is not its type's, or when the
/// items do not add up to the header's record length, so both are checked here.
fn check_laz_items(path: &Path, vlr: &[u8], record_len: u16) -> Result<()> {
    let u16_at = |at: usize| {
        vlr.get(at..at + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
    };
    let count = usize::from(u16_at(32).unwrap_or(0));
    let mut total = 0u32;
    for i in 0..count {
        let (Some(kind), Some(size)) = (u16_at(34 + 6 * i), u16_at(36 + 6 * i)) else {
            return Err(Error::parse(
                path,
                None,
                format!("the LASzip VLR declares {count} items but ends after {i}; it is damaged"),
            ));
        };
        // LASzip's item types and their sizes (0 and 14: extra bytes, any size).
        let fixed = match kind {
            6 => Some(20),
            7 => Some(8),
            8 | 11 => Some(6),
            9 | 13 => Some(29),
            10 => Some(30),
            12 => Some(8),
            _ => None,
        };
        if fixed.is_some_and(|fixed| fixed != size) {
            return Err(Error::parse(
                path,
                None,
                format!(
                    "the LASzip VLR's item {i} (type {kind}) declares {size} bytes, but that type \
                     has {}; the file is damaged",
                    fixed.unwrap_or_default()
                ),
            ));
        }
        total += u32::from(size);
    }
    if total != u32::from(record_len) {
        return Err(Error::parse(
            path,
            None,
            format!(
                "the LASzip VLR's {count} items make {total} bytes, but the header's point \
                 records are {record_len}; the file is damaged"
            ),
        ));
    }
    Ok(())
}

/// Decodes every point in batches; an error names the first point that could not be read.
fn read_points_of(
    path: &Path,
    bytes: Vec<u8>,
    record_len: usize,
    declared: u64,
) -> Result<Vec<Vec3>> {
    let mut reader = las::Reader::new(Cursor::new(bytes))
        .map_err(|e| Error::parse(path, None, format!("cannot read the points: {e}")))?;
    let batch = (BATCH_BYTES / record_len.max(1)).max(1) as u64;
    let mut points = Vec::new();
    let mut read = 0u64;
    while read < declared {
        let data = reader
            .read_points(batch.min(declared - read))
            .map_err(|e| {
                Error::parse(
                    path,
                    None,
                    format!(
                        "point {read} of the {declared} the header declares cannot be read ({e}); \
                     the file is truncated or damaged"
                    ),
                )
            })?;
        if data.is_empty() {
            return Err(Error::parse(
                path,
                None,
                format!(
                    "the file ends after {read} of the {declared} points the header declares; it \
                     is truncated or the header is wrong"
                ),
            ));
        }
        read += data.len() as u64;
        for ((x, y), z) in data.x().zip(data.y()).zip(data.z()) {
            points.push(Vec3::new(x, y, z));
        }
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::read_points;
    use std::path::PathBuf;

    /// A LAS 1.4 file (LAZ when `compressed`) of `points`, stored as millimetre steps from an
    /// offset of (1000, -2000, 50) m: the reader must apply the scale and the offset.
    pub(crate) fn las_bytes(points: &[[f64; 3]], compressed: bool) -> Vec<u8> {
        let mut builder = las::Builder::from((1, 4));
        builder.point_format = las::point::Format::new(0).unwrap();
        builder.point_format.is_compressed = compressed;
        let transform = |offset| las::Transform {
            scale: 0.001,
            offset,
        };
        builder.transforms = las::Vector {
            x: transform(1000.0),
            y: transform(-2000.0),
            z: transform(50.0),
        };
        let header = builder.into_header().unwrap();
        let mut writer = las::Writer::new(Cursor::new(Vec::new()), header).unwrap();
        for p in points {
            writer
                .write_point(las::Point {
                    x: p[0],
                    y: p[1],
                    z: p[2],
                    intensity: 7,
                    ..Default::default()
                })
                .unwrap();
        }
        writer.into_inner().unwrap().into_inner()
    }

    const POINTS: [[f64; 3]; 4] = [
        [1.5, -2.25, 0.125],
        [10.0, 0.001, -1.0],
        [-3.25, 4.5, 2.0],
        [0.5, 0.5, 0.5],
    ];

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    fn expect_err(name: &str, bytes: &[u8]) -> String {
        let dir = tempfile::tempdir().unwrap();
        let err = read_points(&write(dir.path(), name, bytes)).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, Error::Parse { .. }), "{msg}");
        assert!(msg.contains(name), "{msg}");
        msg
    }

    #[test]
    fn las_and_laz_apply_the_header_scale_and_offset() {
        let dir = tempfile::tempdir().unwrap();
        for (name, compressed) in [("a.las", false), ("a.laz", true)] {
            let bytes = las_bytes(&POINTS, compressed);
            let points = read_points(&write(dir.path(), name, &bytes)).unwrap();
            assert_eq!(points.len(), POINTS.len(), "{name}");
            for (p, q) in points.iter().zip(POINTS) {
                assert!((p - Vec3::from(q)).norm() < 1e-9, "{name}: {p:?} vs {q:?}");
            }
        }
    }

    #[test]
    fn malformed_las() {
        let good = las_bytes(&POINTS, false);
        assert!(expect_err("e.las", b"").contains("empty"));
        let mut magic = good.clone();
        magic[..4].copy_from_slice(b"LASG");
        assert!(expect_err("m.las", &magic).contains("'LASF'"));
        assert!(expect_err("h.las", &good[..100]).contains("ends inside the LAS header"));
        assert!(expect_err("t.las", &good[..good.len() - 3]).contains("declares 4 points"));
        // A header that lies: 1000 points declared (LAS 1.4 keeps the count in both places).
        let mut lying = good.clone();
        lying[107..111].copy_from_slice(&1000u32.to_le_bytes());
        lying[247..255].copy_from_slice(&1000u64.to_le_bytes());
        let msg = expect_err("c.las", &lying);
        assert!(
            msg.contains("declares 1000 points") && msg.contains("holds 4"),
            "{msg}"
        );
        let mut scale = good.clone();
        scale[131..139].copy_from_slice(&0f64.to_le_bytes());
        assert!(expect_err("s.las", &scale).contains("scale"));
        // A scale of 1e300 gives coordinates no f32 holds: the message prints them compactly.
        scale[131..139].copy_from_slice(&1e300f64.to_le_bytes());
        let msg = expect_err("h.las", &scale);
        assert!(msg.contains("e30") && msg.len() < 400, "{msg}");
    }

    #[test]
    fn a_las_version_other_than_1_0_to_1_4_is_named() {
        let good = las_bytes(&POINTS, false);
        for (major, minor, wanted) in [(1, 9, "1.9"), (2, 0, "2.0"), (1, 5, "1.5")] {
            let mut bytes = good.clone();
            (bytes[24], bytes[25]) = (major, minor);
            let msg = expect_err("v.las", &bytes);
            assert!(
                msg.contains(&format!("LAS version {wanted}")) && msg.contains("1.0 to 1.4"),
                "{msg}"
            );
        }
        let mut laz = las_bytes(&POINTS, true);
        laz[25] = 9;
        assert!(expect_err("v.laz", &laz).contains("LAS version 1.9"));
    }

    /// The header's point count at bytes 107 (legacy) and 247 (LAS 1.4) set to `count`.
    fn with_count(bytes: &[u8], count: u32) -> Vec<u8> {
        let mut bytes = bytes.to_vec();
        bytes[107..111].copy_from_slice(&count.to_le_bytes());
        bytes[247..255].copy_from_slice(&u64::from(count).to_le_bytes());
        bytes
    }

    #[test]
    fn points_beyond_the_declared_count_are_an_error() {
        let good = las_bytes(&POINTS, false);
        let msg = expect_err("short.las", &with_count(&good, 3));
        assert!(
            msg.contains("holds 4 point records") && msg.contains("than the 3 the header declares"),
            "{msg}"
        );
        // A few bytes of padding after the points are not a point: read.
        let dir = tempfile::tempdir().unwrap();
        let mut padded = good.clone();
        padded.extend([0u8; 3]);
        assert_eq!(
            read_points(&write(dir.path(), "p.las", &padded))
                .unwrap()
                .len(),
            4
        );
        // LAS 1.4 with an extended VLR after the points: the points end where it starts.
        let mut builder = las::Builder::from((1, 4));
        builder.evlrs.push(las::Vlr {
            user_id: "sdem".into(),
            record_id: 1,
            description: "test".into(),
            data: vec![7; 100],
        });
        let header = builder.into_header().unwrap();
        let mut writer = las::Writer::new(Cursor::new(Vec::new()), header).unwrap();
        for p in POINTS {
            let point = las::Point {
                x: p[0],
                y: p[1],
                z: p[2],
                ..Default::default()
            };
            writer.write_point(point).unwrap();
        }
        let with_evlr = writer.into_inner().unwrap().into_inner();
        let points = read_points(&write(dir.path(), "e.las", &with_evlr)).unwrap();
        assert_eq!(points.len(), 4);
        let msg = expect_err("es.las", &with_count(&with_evlr, 2));
        assert!(msg.contains("than the 2 the header declares"), "{msg}");
        // LAZ is compressed: its length says nothing about the count, and is not checked.
        let laz = las_bytes(&POINTS, true);
        assert_eq!(
            read_points(&write(dir.path(), "a.laz", &laz))
                .unwrap()
                .len(),
            4
        );
    }

    #[test]
    fn malformed_laz() {
        let good = las_bytes(&POINTS, true);
        let msg = expect_err("t.laz", &good[..good.len() - 20]);
        assert!(
            msg.contains("truncated") || msg.contains("damaged"),
            "{msg}"
        );
        // More points than the one 50000-point chunk holds.
        let mut lying = good.clone();
        lying[107..111].copy_from_slice(&60000u32.to_le_bytes());
        lying[247..255].copy_from_slice(&60000u64.to_le_bytes());
        let msg = expect_err("c.laz", &lying);
        assert!(msg.contains("declares 60000 points"), "{msg}");
        // A chunk table that declares four billion chunks (the allocation `laz` would make).
        let data_start = u32::from_le_bytes(good[96..100].try_into().unwrap()) as usize;
        let table = u64::from_le_bytes(good[data_start..data_start + 8].try_into().unwrap());
        let mut chunks = good.clone();
        let at = table as usize + 4;
        chunks[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        let msg = expect_err("k.laz", &chunks);
        assert!(msg.contains("4294967295 chunks"), "{msg}");
    }

    #[test]
    fn no_cut_or_flipped_byte_panics() {
        let dir = tempfile::tempdir().unwrap();
        for (name, file) in [
            ("cut.las", las_bytes(&POINTS, false)),
            ("cut.laz", las_bytes(&POINTS, true)),
        ] {
            for len in 0..file.len() {
                let _ = read_points(&write(dir.path(), name, &file[..len]));
            }
            for i in 0..file.len() {
                let mut corrupt = file.clone();
                corrupt[i] ^= 0x55;
                let _ = read_points(&write(dir.path(), name, &corrupt));
            }
        }
    }
}
