//! PCL `.pcd` point clouds: `DATA ascii`, `binary` and `binary_compressed` (LZF, by the `lzf`
//! crate).
//!
//! The header is a sequence of `KEY values` lines ending with `DATA`; see
//! <https://pointclouds.org/documentation/tutorials/pcd_file_format.html>. sdem needs fields `x`,
//! `y`, `z` of type `F` (size 4 or 8) with count 1, in any order among the other fields, which
//! may be of any type and count and are skipped using their `SIZE` and `COUNT`. Binary data is
//! little-endian, one point after another; compressed data is an LZF block of the fields one
//! after another (see [`read_compressed`]). An organized cloud (`HEIGHT` > 1) is read row after
//! row; its points with a NaN coordinate (no return) are dropped. A `VIEWPOINT` (where the sensor
//! stood in the points' frame, PCL's `tx ty tz qw qx qy qz`) takes the points into the sensor's
//! frame; `VERSION` and unknown keys are ignored.

mod header;

use super::{count_newlines, fmt_point, read_bytes};
use crate::error::{Error, Result};
use header::{axis_layout, check_header, parse_header, AxisLayout, Layout};
use sdem::geometry::Vec3;
use std::path::Path;

/// Reads the x, y, z of every point of a PCD file (see the module documentation).
pub(super) fn read_pcd(path: &Path) -> Result<Vec<Vec3>> {
    let bytes = read_bytes(path)?;
    if bytes.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file is empty; expected a PCD header (FIELDS, SIZE, TYPE, ..., DATA)",
        ));
    }
    let (header, body_start, header_lines) = parse_header(path, &bytes)?;
    let viewpoint = header.viewpoint;
    let header = check_header(path, header)?;
    let axes = axis_layout(path, &header.fields)?;
    let body = Body {
        bytes: bytes.get(body_start..).unwrap_or_default(),
        start: body_start,
        first_line: header_lines + 1,
    };
    let mut points = match header.data.as_str() {
        "ascii" => read_ascii(path, &body, &header, axes),
        "binary" => read_binary(path, &body, &header, axes),
        "binary_compressed" => read_compressed(path, &body, &header, axes),
        other => Err(Error::parse(
            path,
            header.data_line,
            format!("unknown DATA '{other}'; expected ascii, binary or binary_compressed"),
        )),
    }?;
    // The points are in a frame where the sensor stood at the viewpoint: into the sensor's.
    let identity = nalgebra::Isometry3::identity();
    if let Some(sensor_from_points) = viewpoint.filter(|v| *v != identity).map(|v| v.inverse()) {
        for p in &mut points {
            *p = sensor_from_points.transform_point(&(*p).into()).coords;
        }
    }
    Ok(points)
}

/// The data after the `DATA` line: its bytes, its byte offset in the file and its first line.
struct Body<'a> {
    bytes: &'a [u8],
    start: usize,
    first_line: usize,
}

fn check_point(
    path: &Path,
    line: Option<usize>,
    index: usize,
    xyz: [f64; 3],
) -> Result<Option<Vec3>> {
    if xyz.iter().any(|v| v.is_nan()) {
        return Ok(None);
    }
    if xyz.iter().any(|v| v.is_infinite()) {
        return Err(Error::parse(
            path,
            line,
            format!(
                "point {index} is {}; coordinates must be finite (or nan for no return)",
                fmt_point(xyz)
            ),
        ));
    }
    Ok(Some(Vec3::new(xyz[0], xyz[1], xyz[2])))
}

fn read_binary(path: &Path, body: &Body, header: &Layout, layout: AxisLayout) -> Result<Vec<Vec3>> {
    let point_count = header.point_count;
    let point_bytes = header.point_bytes();
    let needed = point_count.checked_mul(point_bytes);
    let body_start = body.start;
    let body = body.bytes;
    if needed.is_none_or(|n| n > body.len()) {
        // The first point that does not fit, and where it starts.
        let cut = body.len() / point_bytes.max(1);
        return Err(Error::parse(
            path,
            header.count_line,
            format!(
                "the header declares {point_count} points of {point_bytes} bytes, but the file ends \
                 at byte offset {}: point {cut} (byte offset {}) is cut off; the file is truncated \
                 or the header is wrong",
                body_start + body.len(),
                body_start + cut * point_bytes
            ),
        ));
    }
    // More data than the header declares, by a point or more: the count is wrong (a writer
    // that patched it, a cloud appended), and the points beyond it would be dropped unsaid. Less
    // than a point (a final newline) is let pass.
    let extra = body.len() - point_count * point_bytes;
    if extra >= point_bytes.max(1) {
        return Err(Error::parse(
            path,
            header.count_line,
            format!(
                "the header declares {point_count} points of {point_bytes} bytes, but {extra} more \
                 bytes follow them from byte offset {} ({} points' worth); the header's count is \
                 wrong or data were appended",
                body_start + point_count * point_bytes,
                extra / point_bytes.max(1)
            ),
        ));
    }
    let mut points = Vec::with_capacity(point_count);
    for (index, record) in body
        .chunks_exact(point_bytes.max(1))
        .take(point_count)
        .enumerate()
    {
        let mut xyz = [0f64; 3];
        for (value, &(offset, _, size)) in xyz.iter_mut().zip(&layout) {
            let raw = offset
                .checked_add(size)
                .and_then(|end| record.get(offset..end))
                .unwrap_or_default();
            *value = le_float(raw);
        }
        if let Some(p) = check_point(path, None, index, xyz)? {
            points.push(p);
        }
    }
    Ok(points)
}

/// LZF's largest expansion: a back reference of 3 bytes repeats at most 264 bytes.
const LZF_MAX_RATIO: usize = 88;

/// `DATA binary_compressed`, as PCL and Open3D write it: the `u32` compressed size, the `u32`
/// uncompressed size, then an LZF block. Uncompressed, the data are field after field (every
/// point's `x`, then every point's `y`, …), each field `SIZE × COUNT` bytes per point.
fn read_compressed(
    path: &Path,
    body: &Body,
    header: &Layout,
    layout: AxisLayout,
) -> Result<Vec<Vec3>> {
    let at = |offset: usize| body.start + offset;
    let word = |offset: usize| {
        body.bytes
            .get(offset..offset + 4)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_le_bytes)
    };
    let (Some(compressed), Some(uncompressed)) = (word(0), word(4)) else {
        return Err(Error::parse(
            path,
            None,
            format!(
                "the file ends at byte offset {}, inside the 8 bytes of sizes that follow DATA                  binary_compressed; the file is truncated",
                at(body.bytes.len())
            ),
        ));
    };
    let (compressed, uncompressed) = (compressed as usize, uncompressed as usize);
    let point_count = header.point_count;
    let point_bytes = header.point_bytes();
    let needed = point_count.saturating_mul(point_bytes);
    if uncompressed != needed {
        return Err(Error::parse(
            path,
            header.count_line,
            format!(
                "the header declares {point_count} points of {point_bytes} bytes ({needed} \
                 bytes), but the compressed block at byte offset {} unpacks to {uncompressed} \
                 bytes; the header is wrong or the file is damaged",
                at(0)
            ),
        ));
    }
    let data = body.bytes.get(8..8 + compressed).ok_or_else(|| {
        Error::parse(
            path,
            None,
            format!(
                "the compressed block declares {compressed} bytes from byte offset {}, but the \
                 file ends at byte offset {}; the file is truncated",
                at(8),
                at(body.bytes.len())
            ),
        )
    })?;
    if point_count == 0 {
        return Ok(Vec::new());
    }
    if uncompressed > compressed.saturating_mul(LZF_MAX_RATIO) {
        return Err(Error::parse(
            path,
            None,
            format!(
                "the compressed block at byte offset {} declares {uncompressed} bytes unpacked \
                 from {compressed}, more than LZF can pack into so few; the sizes are damaged",
                at(0)
            ),
        ));
    }
    let damaged = |why: String| {
        Error::parse(
            path,
            None,
            format!(
                "the compressed block ({compressed} bytes at byte offset {}) is damaged: {why}",
                at(8)
            ),
        )
    };
    let unpacked = lzf::decompress(data, uncompressed).map_err(|e| {
        damaged(match e {
            lzf::LzfError::BufferTooSmall => {
                format!("it unpacks to more than the {uncompressed} bytes declared")
            }
            _ => "it is not valid LZF data".to_string(),
        })
    })?;
    if unpacked.len() != uncompressed {
        return Err(damaged(format!(
            "it unpacks to {} bytes, not the {uncompressed} declared",
            unpacked.len()
        )));
    }
    let mut points = Vec::with_capacity(point_count);
    for index in 0..point_count {
        let mut xyz = [0f64; 3];
        for (value, &(offset, _, size)) in xyz.iter_mut().zip(&layout) {
            // Field after field: this field's column starts at `point_count × offset`.
            let start = point_count * offset + index * size;
            *value = le_float(unpacked.get(start..start + size).unwrap_or_default());
        }
        if let Some(p) = check_point(path, None, index, xyz)? {
            points.push(p);
        }
    }
    Ok(points)
}

/// A little-endian `f32` (4 bytes) or `f64` (8 bytes).
fn le_float(raw: &[u8]) -> f64 {
    match raw.try_into() {
        Ok(four) => f64::from(f32::from_le_bytes(four)),
        Err(_) => f64::from_le_bytes(raw.try_into().unwrap_or([0; 8])),
    }
}

fn read_ascii(path: &Path, body: &Body, header: &Layout, layout: AxisLayout) -> Result<Vec<Vec3>> {
    let point_count = header.point_count;
    let header_lines = body.first_line - 1;
    let body = body.bytes;
    let tokens_per_point: usize = header.fields.iter().map(|f| f.count).sum();
    // Every point takes at least a line break; short lines are reported with their line number.
    if point_count > body.len() {
        return Err(Error::parse(
            path,
            header.count_line,
            format!(
                "the header declares {point_count} points, more than the {} bytes after the DATA \
                 line can hold; the file is truncated or the header is wrong",
                body.len()
            ),
        ));
    }
    let text = std::str::from_utf8(body).map_err(|e| {
        let line =
            header_lines + 1 + count_newlines(body.get(..e.valid_up_to()).unwrap_or_default());
        Error::parse(path, Some(line), "the ASCII data is not text")
    })?;
    // Every value takes at least one character and one separator: the declared count is not
    // trusted for the allocation.
    let mut points =
        Vec::with_capacity(point_count.min(body.len() / (2 * tokens_per_point).max(1)));
    let mut index = 0usize;
    let mut last_line = header_lines;
    for (i, line) in text.lines().enumerate() {
        let line_no = header_lines + 1 + i;
        last_line = line_no;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if index == point_count {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!("more data lines than the {point_count} points the header declares"),
            ));
        }
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.len() != tokens_per_point {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "{} values on this line, but the fields declare {tokens_per_point} per point",
                    tokens.len()
                ),
            ));
        }
        let mut xyz = [0f64; 3];
        for ((value, &(_, token_index, size)), axis) in
            xyz.iter_mut().zip(&layout).zip(["x", "y", "z"])
        {
            let token = tokens.get(token_index).copied().unwrap_or_default();
            let parsed = if size == 4 {
                token.parse::<f32>().map(f64::from).ok()
            } else {
                token.parse::<f64>().ok()
            };
            *value = parsed.ok_or_else(|| {
                Error::parse(
                    path,
                    Some(line_no),
                    format!("{axis} '{token}' is not a number"),
                )
            })?;
        }
        if let Some(p) = check_point(path, Some(line_no), index, xyz)? {
            points.push(p);
        }
        index += 1;
    }
    if index != point_count {
        return Err(Error::parse(
            path,
            Some(last_line),
            format!(
                "the file ends here, after {index} of the {point_count} points the header declares; \
                 it is truncated or the header is wrong"
            ),
        ));
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::read_points;
    use std::path::PathBuf;

    fn write(dir: &Path, name: &str, content: &[u8]) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, content).unwrap();
        path
    }

    fn expect_err(content: &[u8], line: Option<usize>) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "bad.pcd", content);
        let err = read_points(&path).expect_err("malformed PCD must be an error");
        let msg = err.to_string();
        assert!(matches!(err, Error::Parse { .. }), "{msg}");
        assert!(msg.contains("bad.pcd"), "{msg}");
        if let Some(line) = line {
            assert!(msg.contains(&format!("bad.pcd:{line}:")), "{msg}");
        }
        msg
    }

    const ASCII: &str = "# .PCD v0.7 - Point Cloud Data file format\n\
        VERSION 0.7\n\
        FIELDS x y z rgb normal\n\
        SIZE 4 4 4 4 4\n\
        TYPE F F F U F\n\
        COUNT 1 1 1 1 3\n\
        WIDTH 3\n\
        HEIGHT 1\n\
        VIEWPOINT 0 0 0 1 0 0 0\n\
        POINTS 3\n\
        DATA ascii\n\
        0.5 -1.25 2 4278190080 0 0 1\n\
        nan nan nan 0 0 0 0\n\
        1e1 2.5e-1 -3 16711680 1 0 0\n";

    #[test]
    fn ascii_pcd() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "a.pcd", ASCII.as_bytes());
        assert_eq!(
            read_points(&path).unwrap(),
            vec![Vec3::new(0.5, -1.25, 2.0), Vec3::new(10.0, 0.25, -3.0)]
        );
    }

    fn binary_pcd() -> Vec<u8> {
        // x and z as F4, y as F8, with an intensity field and PCL's '_' padding between.
        let mut bytes = b"VERSION .7\nFIELDS x _ y intensity z\nSIZE 4 1 8 2 4\nTYPE F U F U F\n\
                          COUNT 1 4 1 1 1\nWIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA binary\n"
            .to_vec();
        for (x, y, z) in [
            (1.5f32, 2.25f64, -3.0f32),
            (f32::NAN, 0.0, 0.0),
            (0.1, 0.2, 0.3),
            (-7.0, 1e-9, 100.0),
        ] {
            bytes.extend(x.to_le_bytes());
            bytes.extend([0xAA; 4]);
            bytes.extend(y.to_le_bytes());
            bytes.extend(7u16.to_le_bytes());
            bytes.extend(z.to_le_bytes());
        }
        bytes
    }

    #[test]
    fn binary_pcd_with_mixed_sizes_and_padding() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "b.pcd", &binary_pcd());
        assert_eq!(
            read_points(&path).unwrap(),
            vec![
                Vec3::new(1.5, 2.25, -3.0),
                Vec3::new(f64::from(0.1f32), 0.2, f64::from(0.3f32)),
                Vec3::new(-7.0, 1e-9, 100.0),
            ]
        );
    }

    /// The points of [`binary_pcd`], organized 2 × 2, as `DATA binary_compressed`: the fields
    /// one after another, then LZF.
    fn compressed_pcd() -> Vec<u8> {
        let points = [
            (1.5f32, 2.25f64, -3.0f32),
            (f32::NAN, f64::NAN, f32::NAN),
            (0.1, 0.2, 0.3),
            (-7.0, 1e-9, 100.0),
        ];
        let mut columns = Vec::new();
        points
            .iter()
            .for_each(|p| columns.extend(p.0.to_le_bytes()));
        points.iter().for_each(|_| columns.extend([0xAA; 4]));
        points
            .iter()
            .for_each(|p| columns.extend(p.1.to_le_bytes()));
        points
            .iter()
            .for_each(|_| columns.extend(7u16.to_le_bytes()));
        points
            .iter()
            .for_each(|p| columns.extend(p.2.to_le_bytes()));
        let packed = lzf::compress(&columns).unwrap();
        let mut bytes = b"VERSION 0.7\nFIELDS x _ y intensity z\nSIZE 4 1 8 2 4\nTYPE F U F U F\n\
                          COUNT 1 4 1 1 1\nWIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA binary_compressed\n"
            .to_vec();
        bytes.extend((packed.len() as u32).to_le_bytes());
        bytes.extend((columns.len() as u32).to_le_bytes());
        bytes.extend(packed);
        bytes
    }

    #[test]
    fn compressed_organized_pcd_drops_nan_points() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "c.pcd", &compressed_pcd());
        assert_eq!(
            read_points(&path).unwrap(),
            vec![
                Vec3::new(1.5, 2.25, -3.0),
                Vec3::new(f64::from(0.1f32), 0.2, f64::from(0.3f32)),
                Vec3::new(-7.0, 1e-9, 100.0),
            ]
        );
    }

    #[test]
    fn malformed_compressed_pcd() {
        let good = compressed_pcd();
        let data = good.windows(5).position(|w| w == b"ssed\n").unwrap() + 5;
        let mut cut = good.clone();
        cut.truncate(good.len() - 3);
        assert!(expect_err(&cut, None).contains("truncated"));
        cut.truncate(data + 6);
        assert!(expect_err(&cut, None).contains("truncated"));
        // A header that declares more points than the block holds.
        let lying = String::from_utf8_lossy(&good[..data])
            .replace("HEIGHT 2\nPOINTS 4", "HEIGHT 3\nPOINTS 6");
        let mut bytes = lying.into_bytes();
        bytes.extend(&good[data..]);
        let msg = expect_err(&bytes, None);
        assert!(msg.contains("declares 6 points"), "{msg}");
        // A block that declares a size its LZF data cannot hold (checked before the allocation).
        let huge = String::from_utf8_lossy(&good[..data]).replace(
            "WIDTH 2\nHEIGHT 2\nPOINTS 4",
            "WIDTH 100000\nHEIGHT 1\nPOINTS 100000",
        );
        let mut bytes = huge.into_bytes();
        let sizes = bytes.len();
        bytes.extend(&good[data..]);
        bytes[sizes + 4..sizes + 8].copy_from_slice(&2_200_000u32.to_le_bytes());
        let msg = expect_err(&bytes, None);
        assert!(msg.contains("more than LZF"), "{msg}");
        // A damaged block.
        let mut damaged = good.clone();
        for b in &mut damaged[data + 8..] {
            *b = 0xFF;
        }
        assert!(expect_err(&damaged, None).contains("damaged"));
    }

    #[test]
    fn malformed_pcd() {
        expect_err(b"", None);
        let msg = expect_err(
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA binary_compressed\n",
            None,
        );
        assert!(msg.contains("truncated"), "{msg}");
        expect_err(
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\n",
            None,
        );
        expect_err(
            b"FIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n",
            None,
        );
        expect_err(
            b"FIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2\n",
            None,
        );
        expect_err(
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F I\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n",
            None,
        );
        expect_err(
            b"FIELDS x y z\nSIZE 4 4 3\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n",
            Some(2),
        );
        expect_err(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n", None);
        expect_err(
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nWIDTH 1\nDATA ascii\n1 2 3\n",
            Some(5),
        );
        expect_err(
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nDATA ascii\n1 2 3\n",
            None,
        );
        expect_err(
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH -1\nDATA ascii\n1 2 3\n",
            Some(4),
        );
        expect_err(b"\xff\xfe\n", Some(1));
    }

    #[test]
    fn absurd_point_counts() {
        for data in ["ascii", "binary"] {
            let text = format!(
                "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 99999999999\nHEIGHT 1\n\
                 POINTS 99999999999\nDATA {data}\n1 2 3\n"
            );
            let msg = expect_err(text.as_bytes(), None);
            assert!(msg.contains("99999999999"), "{msg}");
        }
        let text = format!(
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH {m}\nHEIGHT {m}\nDATA binary\n",
            m = u64::MAX
        );
        expect_err(text.as_bytes(), None);
        let text = format!(
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS {}\nDATA binary\n",
            u64::MAX
        );
        expect_err(text.as_bytes(), None);
    }

    /// A viewpoint 1 m along x turned 90° about z: a point 2 m ahead of the sensor (its x)
    /// lies at (1, 2, 0) in the file's frame.
    #[test]
    fn a_viewpoint_takes_the_points_into_the_sensors_frame() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let header = |viewpoint: &str| {
            format!(
                "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nHEIGHT 1\n{viewpoint}\nPOINTS 1\n\
                 DATA ascii\n1 2 0\n"
            )
        };
        let dir = tempfile::tempdir().unwrap();
        let turned = header(&format!("VIEWPOINT 1 0 0 {h} 0 0 {h}"));
        let points = read_pcd(&write(dir.path(), "v.pcd", turned.as_bytes())).unwrap();
        assert!(
            (points[0] - Vec3::new(2.0, 0.0, 0.0)).norm() < 1e-6,
            "{}",
            points[0]
        );
        let e = read_pcd(&write(
            dir.path(),
            "q.pcd",
            header("VIEWPOINT 0 0 0 2 0 0 0").as_bytes(),
        ))
        .unwrap_err();
        assert!(e.to_string().contains("not 1"), "{e}");
    }

    #[test]
    fn binary_body_longer_than_the_header_declares() {
        let dir = tempfile::tempdir().unwrap();
        let whole = read_pcd(&write(dir.path(), "whole.pcd", &binary_pcd())).unwrap();
        let mut bytes = binary_pcd();
        bytes.push(b'\n'); // less than a point: let pass
        let path = write(dir.path(), "newline.pcd", &bytes);
        assert_eq!(read_pcd(&path).unwrap(), whole);
        let point = bytes.len() / 4; // more than one point's worth of bytes
        bytes.extend(std::iter::repeat_n(0u8, point));
        let e = read_pcd(&write(dir.path(), "more.pcd", &bytes)).unwrap_err();
        assert!(e.to_string().contains("more bytes follow them"), "{e}");
    }

    #[test]
    fn truncated_binary_body() {
        let mut bytes = binary_pcd();
        bytes.truncate(bytes.len() - 1);
        let msg = expect_err(&bytes, None);
        assert!(msg.contains("truncated"), "{msg}");
    }

    #[test]
    fn malformed_ascii_data_names_the_line() {
        let head = "FIELDS x y z\nSIZE 4 4 8\nTYPE F F F\nWIDTH 2\nPOINTS 2\nDATA ascii\n";
        let with = |body: &str| format!("{head}{body}").into_bytes();
        expect_err(&with("1 2 3\n4 5\n"), Some(8));
        expect_err(&with("1 2 3\n4 5 6 7\n"), Some(8));
        expect_err(&with("1 2 3\n4 five 6\n"), Some(8));
        expect_err(&with("1 2 3\n4 5 inf\n"), Some(8));
        expect_err(&with("1 2 3\n4 5 6\n7 8 9\n"), Some(9));
        expect_err(&with("1 2 3\n"), None);
    }

    #[test]
    fn no_input_prefix_panics() {
        let dir = tempfile::tempdir().unwrap();
        for file in [ASCII.as_bytes().to_vec(), binary_pcd(), compressed_pcd()] {
            for len in 0..file.len() {
                let p = write(dir.path(), "cut.pcd", &file[..len]);
                let _ = read_points(&p);
            }
            for i in 0..file.len() {
                let mut corrupt = file.clone();
                corrupt[i] = corrupt[i].wrapping_add(0x55);
                let p = write(dir.path(), "flip.pcd", &corrupt);
                let _ = read_points(&p);
            }
        }
    }
}
