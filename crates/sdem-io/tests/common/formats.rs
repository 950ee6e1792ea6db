//! Builders of valid files in the formats read through other crates (PCD's LZF blocks, LAS and
//! LAZ by `las`, E57 by `e57`), shared by the bad-input table and the fuzz targets.
#![allow(dead_code)]

use sdem::geometry::{pose_from_parts, Attitude, Pose, Vec3};

/// The body of a `DATA binary_compressed` PCD of fields `x y z` (`F 4`): the compressed and
/// uncompressed sizes, then every x, every y, every z as an LZF stream of literal runs only
/// (ctrl byte `len - 1`, then `len` bytes), which any LZF decoder reads.
pub fn pcd_lzf_block(points: &[[f32; 3]]) -> Vec<u8> {
    let columns: Vec<u8> = (0..3)
        .flat_map(|axis| points.iter().flat_map(move |p| p[axis].to_le_bytes()))
        .collect();
    let mut packed = Vec::new();
    for run in columns.chunks(32) {
        packed.push(run.len() as u8 - 1);
        packed.extend_from_slice(run);
    }
    let mut block = (packed.len() as u32).to_le_bytes().to_vec();
    block.extend((columns.len() as u32).to_le_bytes());
    block.extend(packed);
    block
}

/// A LAS 1.4 file (LAZ when `compressed`) written by the `las` crate: point format 0, stored
/// as millimetre steps from an offset of (100, -200, 5) m.
pub fn las_file(points: &[[f32; 3]], compressed: bool) -> Vec<u8> {
    let mut builder = las::Builder::from((1, 4));
    builder.point_format = las::point::Format::new(0).unwrap();
    builder.point_format.is_compressed = compressed;
    let transform = |offset| las::Transform {
        scale: 0.001,
        offset,
    };
    builder.transforms = las::Vector {
        x: transform(100.0),
        y: transform(-200.0),
        z: transform(5.0),
    };
    let header = builder.into_header().unwrap();
    let mut writer = las::Writer::new(std::io::Cursor::new(Vec::new()), header).unwrap();
    for p in points {
        let point = las::Point {
            x: f64::from(p[0]),
            y: f64::from(p[1]),
            z: f64::from(p[2]),
            ..Default::default()
        };
        writer.write_point(point).unwrap();
    }
    writer.into_inner().unwrap().into_inner()
}

/// `bytes` of a LAS 1.4 file with the point count set to `count` in both of its places.
pub fn las_count(mut bytes: Vec<u8>, count: u32) -> Vec<u8> {
    bytes[107..111].copy_from_slice(&count.to_le_bytes());
    bytes[247..255].copy_from_slice(&u64::from(count).to_le_bytes());
    bytes
}

/// An E57 survey written by `sdem_io::write_e57`: one scan per entry of `scans`, scan `i` posed
/// `i` metres along x, turned `30 i`° with a slight tilt.
pub fn e57_file(scans: &[&[[f32; 3]]]) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("survey.e57");
    let poses: Vec<Pose> = (0..scans.len())
        .map(|i| {
            let turn = 30.0 * i as f64;
            pose_from_parts(
                Vec3::new(i as f64, 0.0, 0.5),
                Attitude::from_degrees(1.0, -2.0, turn),
            )
        })
        .collect();
    let names: Vec<String> = (0..scans.len()).map(|i| format!("scan {i}")).collect();
    let out: Vec<sdem_io::E57ScanOut> = scans
        .iter()
        .zip(&poses)
        .zip(&names)
        .map(|((points, pose), name)| sdem_io::E57ScanOut {
            name,
            points_in_sensor: points,
            world_from_sensor: pose,
        })
        .collect();
    sdem_io::write_e57(&path, &out).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    // Resealing a valid file changes nothing: the page checksums are computed as E57's.
    assert_eq!(e57_resealed(bytes.clone()), bytes);
    bytes
}

/// An E57 file of no scan at all, written by the `e57` crate.
pub fn e57_without_scans() -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    let mut writer = e57::E57Writer::new(&mut out, "{empty}").unwrap();
    writer.finalize().unwrap();
    drop(writer);
    out.into_inner()
}

/// A LAS 1.4 file of `points` in point `format` (3 or 7: with GPS time and colour), LAZ when
/// `compressed`, written by the `las` crate with its default scale and offset.
pub fn las_seed(points: &[[f32; 3]], format: u8, compressed: bool) -> Vec<u8> {
    let mut builder = las::Builder::from((1, 4));
    builder.point_format = las::point::Format::new(format).unwrap();
    builder.point_format.is_compressed = compressed;
    let header = builder.into_header().unwrap();
    let cursor = std::io::Cursor::new(Vec::new());
    let mut writer = las::Writer::new(cursor, header).unwrap();
    for (i, p) in points.iter().enumerate() {
        let point = las::Point {
            x: f64::from(p[0]),
            y: f64::from(p[1]),
            z: f64::from(p[2]),
            intensity: 100 * i as u16,
            gps_time: Some(i as f64),
            color: Some(las::Color::new(1, 2, 3)),
            ..Default::default()
        };
        writer.write_point(point).unwrap();
    }
    writer.into_inner().unwrap().into_inner()
}

/// `bytes` with every whole 1024-byte E57 page's checksum (CRC-32C of its first 1020 bytes,
/// big-endian) recomputed, so that the reader gets past the page checksums.
pub fn e57_resealed(mut bytes: Vec<u8>) -> Vec<u8> {
    for page in bytes.chunks_exact_mut(1024) {
        let mut crc = !0u32;
        for &b in &page[..1020] {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    0x82F6_3B78 ^ (crc >> 1)
                } else {
                    crc >> 1
                };
            }
        }
        page[1020..].copy_from_slice(&(!crc).to_be_bytes());
    }
    bytes
}
