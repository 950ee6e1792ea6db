//! Point-cloud dispatch and the simple formats: `.xyz` / `.txt`, 3DTK `.3d`, KITTI `.bin`.

use super::{
    fmt_msg, fmt_point, numbered_lines, parse_finite, read_bytes, read_text, sweep_points,
};
use crate::error::{Error, Result};
use sdem::geometry::Vec3;
use std::path::Path;

/// The file extensions [`read_points`] understands (lower case, without the dot).
pub const POINT_EXTENSIONS: &[&str] = &[
    "ply", "pcd", "xyz", "txt", "bin", "3d", "sweep", "las", "laz",
];

/// A point-cloud file format, chosen by file extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointFormat {
    /// `.ply`: PLY, ASCII or binary.
    Ply,
    /// `.pcd`: PCL point cloud data, ASCII or binary.
    Pcd,
    /// `.xyz` or `.txt`: text, `x y z` per line.
    Xyz,
    /// `.bin`: KITTI Velodyne, little-endian `f32` `x y z intensity`.
    KittiBin,
    /// `.3d`: 3DTK "uos" text, centimetres, left-handed (x right, y up, z forward).
    Uos3d,
    /// `.sweep`: sdem's raw tilting-LRF sweep.
    Sweep,
    /// `.las` or `.laz`: ASPRS LAS, uncompressed or LASzip-compressed.
    Las,
}

impl PointFormat {
    /// The format of `path` from its extension (case-insensitive), `None` when not supported.
    ///
    /// # Example
    /// ```
    /// use sdem_io::PointFormat;
    /// assert_eq!(PointFormat::from_path("scans/000001.PLY".as_ref()), Some(PointFormat::Ply));
    /// assert_eq!(PointFormat::from_path("notes.md".as_ref()), None);
    /// ```
    pub fn from_path(path: &Path) -> Option<PointFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "ply" => PointFormat::Ply,
            "pcd" => PointFormat::Pcd,
            "xyz" | "txt" => PointFormat::Xyz,
            "bin" => PointFormat::KittiBin,
            "3d" => PointFormat::Uos3d,
            "sweep" => PointFormat::Sweep,
            "las" | "laz" => PointFormat::Las,
            _ => return None,
        })
    }
}

/// Reads a point cloud, in metres in the file's (sensor) frame, choosing the format by extension:
/// `.ply`, `.pcd`, `.xyz`/`.txt`, KITTI `.bin`, 3DTK `.3d`, `.las`/`.laz` or sdem's `.sweep` (see the
/// [module documentation](crate) for each format's details).
///
/// Points with a NaN coordinate are skipped (no return); an infinite or unparsable coordinate is
/// an error naming the file and line. A file that yields no point at all is an error.
///
/// # Example
/// ```
/// # let dir = std::env::temp_dir().join(format!("sdem-doc-points-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("two.xyz");
/// std::fs::write(&path, "# x y z\n1 2 3\n4,5,6,0.9\n").unwrap();
/// let points = sdem_io::read_points(&path).unwrap();
/// assert_eq!(points.len(), 2);
/// assert_eq!(points[1].z, 6.0);
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn read_points(path: &Path) -> Result<Vec<Vec3>> {
    read_points_within(path, None)
}

/// [`read_points`], and with `sensor_reach` (a dataset's `sensor.toml` `max_range_m`) a scan
/// whose median range is more than [`UNIT_CHECK_REACHES`] times it is refused as another unit.
pub(crate) fn read_points_within(path: &Path, sensor_reach: Option<f64>) -> Result<Vec<Vec3>> {
    let format = PointFormat::from_path(path).ok_or_else(|| {
        let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase());
        let message = match ext.as_deref() {
            Some("e57") => "an E57 file holds a survey of scans, not one scan; turn it into a \
                            dataset with `sdem import FILE.e57 --out DATASET`"
                .to_string(),
            _ => format!(
                "{} is not a point-cloud format sdem reads; use .ply, .pcd, .xyz or .txt, .bin \
                 (KITTI), .3d (3DTK), .las or .laz, or .sweep",
                ext.map_or_else(|| "no extension".to_string(), |e| format!("'.{e}'"))
            ),
        };
        Error::parse(path, None, message)
    })?;
    let points = match format {
        PointFormat::Ply => super::ply::read_ply(path)?,
        PointFormat::Pcd => super::pcd::read_pcd(path)?,
        PointFormat::Xyz => read_xyz(path)?,
        PointFormat::KittiBin => read_kitti_bin(path)?,
        PointFormat::Uos3d => read_uos_3d(path)?,
        PointFormat::Sweep => sweep_points(path)?,
        PointFormat::Las => super::las::read_las(path)?,
    };
    if points.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file holds no points (or only points with NaN coordinates); a scan needs points",
        ));
    }
    check_magnitudes(path, &points, sensor_reach)?;
    Ok(points)
}

/// Scans are in metres in the sensor frame. When half of a scan's points lie farther than this
/// from the sensor, the file is in another unit (millimetres) or in world (e.g. georeferenced)
/// coordinates: no range finder a robot carries sees most of its returns beyond a kilometre.
/// (Centimetres, or millimetres of a scan taken within a metre, cannot be told from metres.)
pub const MAX_MEDIAN_RANGE_M: f64 = 1000.0;

/// A dataset's scan is refused when its median range exceeds this many times the sensor's
/// maximum range ([`crate::Dataset::load_scan`]): no scanner sees most of its returns beyond
/// its reach, and a scan in millimetres lies a thousand times farther.
const UNIT_CHECK_REACHES: f64 = 10.0;

/// Checks what every format shares: each coordinate fits in `f32` (sdem keeps points as `f32`),
/// and the median distance from the sensor is at most [`MAX_MEDIAN_RANGE_M`] (and, given the
/// sensor's reach, at most [`UNIT_CHECK_REACHES`] times it).
pub(crate) fn check_magnitudes(
    path: &Path,
    points: &[Vec3],
    sensor_reach: Option<f64>,
) -> Result<()> {
    let limit = f64::from(f32::MAX);
    if let Some((i, p)) = points
        .iter()
        .enumerate()
        .find(|(_, p)| p.iter().any(|v| v.abs() > limit))
    {
        return Err(Error::parse(
            path,
            None,
            format!(
                "point {i} is {}; sdem keeps coordinates as 32-bit floats, and this one does not \
                 fit (the file is damaged or not in metres)",
                fmt_point([p.x, p.y, p.z])
            ),
        ));
    }
    let (median, i) = median_range(points);
    if median > MAX_MEDIAN_RANGE_M {
        let p = points.get(i).copied().unwrap_or_default();
        return Err(Error::parse(
            path,
            None,
            format!(
                "half of the points lie farther than {} m from the sensor (point {i} is at {}); \
                 sdem reads scans in metres in the sensor frame: is the file in millimetres, or in \
                 world coordinates?",
                fmt_msg(median.round()),
                fmt_point([p.x, p.y, p.z])
            ),
        ));
    }
    // A millimetre scan taken within a metre passes the kilometre, not the sensor's reach.
    if let Some(reach) = sensor_reach.filter(|&r| median > UNIT_CHECK_REACHES * r) {
        return Err(Error::parse(
            path,
            None,
            format!(
                "half of the points lie farther than {median:.1} m from the sensor, {:.0} times \
                 the {reach} m the sensor reaches (sensor.toml's max_range_m): is the file in \
                 millimetres?",
                median / reach
            ),
        ));
    }
    Ok(())
}

/// The median distance of `points` from the sensor, with the index of a point at it (0 for
/// no points).
pub(crate) fn median_range(points: &[Vec3]) -> (f64, usize) {
    let mut ranges: Vec<(f64, usize)> = points.iter().map(|p| p.norm()).zip(0..).collect();
    if ranges.is_empty() {
        return (0.0, 0);
    }
    let middle = ranges.len() / 2;
    let (_, &mut at, _) = ranges.select_nth_unstable_by(middle, |a, b| a.0.total_cmp(&b.0));
    at
}

/// Splits a data line into fields: on commas when it has any (each field trimmed, empty fields
/// kept so that they are reported), else on whitespace.
fn fields(line: &str) -> Vec<&str> {
    if line.contains(',') {
        line.split(',').map(str::trim).collect()
    } else {
        line.split_whitespace().collect()
    }
}

/// Reads the first three fields of a text line as a point: `None` for a point with a NaN
/// coordinate (no return, dropped as every other reader drops it); an infinite coordinate or a
/// field that is no number is refused with its line.
fn text_point(path: &Path, line_no: usize, line: &str, unit: &str) -> Result<Option<[f64; 3]>> {
    let f = fields(line);
    let [x, y, z] = match f.as_slice() {
        [x, y, z, ..] => [*x, *y, *z],
        _ => {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "expected at least 3 numbers 'x y z' ({unit}), found {} field(s)",
                    f.len()
                ),
            ))
        }
    };
    let coordinate = |token: &str, what: &str| match token.parse::<f64>() {
        Ok(v) if v.is_nan() => Ok(v),
        _ => parse_finite(path, line_no, token, what),
    };
    let point = [
        coordinate(x, "coordinate x")?,
        coordinate(y, "coordinate y")?,
        coordinate(z, "coordinate z")?,
    ];
    Ok(point.iter().all(|v| !v.is_nan()).then_some(point))
}

/// The part of a text line before any `#` comment, trimmed; `None` for comment-only lines.
fn strip_comment(line: &str) -> Option<&str> {
    let data = line.split('#').next().unwrap_or("").trim();
    if data.is_empty() || data.starts_with("//") {
        None
    } else {
        Some(data)
    }
}

fn check_not_blank(path: &Path, text: &str) -> Result<()> {
    if text.trim().is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file is empty; expected one point 'x y z' per line",
        ));
    }
    Ok(())
}

/// `.xyz` / `.txt`: `x y z [more columns]` per line, metres.
fn read_xyz(path: &Path) -> Result<Vec<Vec3>> {
    let text = read_text(path)?;
    check_not_blank(path, &text)?;
    let mut points = Vec::new();
    for (line_no, line) in numbered_lines(&text) {
        if let Some(data) = strip_comment(line) {
            if let Some([x, y, z]) = text_point(path, line_no, data, "metres")? {
                points.push(Vec3::new(x, y, z));
            }
        }
    }
    Ok(points)
}

/// True for a 3DTK size header such as `360 x 225`.
fn is_uos_size_header(line: &str) -> bool {
    let mut parts = line.split('x').map(str::trim);
    matches!(
        (parts.next(), parts.next(), parts.next()),
        (Some(a), Some(b), None)
            if !a.is_empty() && !b.is_empty()
                && a.bytes().all(|c| c.is_ascii_digit())
                && b.bytes().all(|c| c.is_ascii_digit())
    )
}

/// 3DTK `.3d` ("uos" format): `x y z [reflectance …]` in centimetres, left-handed with x right,
/// y up, z forward. Converted to right-handed metres with x forward, y left, z up.
fn read_uos_3d(path: &Path) -> Result<Vec<Vec3>> {
    let text = read_text(path)?;
    check_not_blank(path, &text)?;
    let mut points = Vec::new();
    let mut first_data_line = true;
    for (line_no, line) in numbered_lines(&text) {
        let data = line.trim();
        if data.is_empty() {
            continue;
        }
        if std::mem::take(&mut first_data_line) && is_uos_size_header(data) {
            continue;
        }
        let Some([x_right, y_up, z_forward]) = text_point(path, line_no, data, "centimetres")?
        else {
            continue;
        };
        // 3DTK (left-handed: x right, y up, z forward) → sdem (x forward, y left, z up).
        points.push(Vec3::new(z_forward, -x_right, y_up) / 100.0);
    }
    Ok(points)
}

/// KITTI Velodyne `.bin`: little-endian `f32` `x y z intensity`, 16 bytes per point.
fn read_kitti_bin(path: &Path) -> Result<Vec<Vec3>> {
    let bytes = read_bytes(path)?;
    if bytes.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file is empty; a KITTI scan holds 16 bytes (x y z intensity as f32) per point",
        ));
    }
    if bytes.len() % 16 != 0 {
        let cut = bytes.len() / 16;
        return Err(Error::parse(
            path,
            None,
            format!(
                "{} bytes is not a multiple of 16 (x y z intensity as little-endian f32 per point): \
                 point {cut} (byte offset {}) is cut off after {} of its 16 bytes; the file is \
                 truncated or not a KITTI Velodyne scan",
                bytes.len(),
                cut * 16,
                bytes.len() % 16
            ),
        ));
    }
    let mut points = Vec::with_capacity(bytes.len() / 16);
    for (i, record) in bytes.chunks_exact(16).enumerate() {
        let mut xyz = [0f64; 3];
        for (value, chunk) in xyz.iter_mut().zip(record.chunks_exact(4)) {
            let mut raw = [0u8; 4];
            raw.copy_from_slice(chunk);
            *value = f64::from(f32::from_le_bytes(raw));
        }
        if xyz.iter().any(|v| v.is_nan()) {
            continue;
        }
        if xyz.iter().any(|v| v.is_infinite()) {
            return Err(Error::parse(
                path,
                None,
                format!(
                    "point {i} (byte offset {}) has an infinite coordinate",
                    i * 16
                ),
            ));
        }
        points.push(Vec3::new(xyz[0], xyz[1], xyz[2]));
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn write(dir: &Path, name: &str, content: &[u8]) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, content).unwrap();
        path
    }

    /// The error of reading `content` as `name`: must be a parse error naming the file and, when
    /// given, the line.
    fn expect_err(name: &str, content: &[u8], line: Option<usize>) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), name, content);
        let err = read_points(&path).expect_err(name);
        let msg = err.to_string();
        assert!(msg.contains(name), "{msg}");
        if let Some(line) = line {
            assert!(msg.contains(&format!("{name}:{line}:")), "{msg}");
        }
        msg
    }

    #[test]
    fn xyz_reads_spaces_commas_comments_and_extra_columns() {
        let dir = tempfile::tempdir().unwrap();
        let text = "# header\n\n1 2 3\n4.5,-5,6e-1,0.7\n\t7\t8\t9 # trailing comment\n//X,Y,Z\n";
        let path = write(dir.path(), "a.xyz", text.as_bytes());
        let points = read_points(&path).unwrap();
        assert_eq!(
            points,
            vec![
                Vec3::new(1.0, 2.0, 3.0),
                Vec3::new(4.5, -5.0, 0.6),
                Vec3::new(7.0, 8.0, 9.0)
            ]
        );
        let txt = write(dir.path(), "b.TXT", b"1 2 3\r\n4 5 6\r\n");
        assert_eq!(read_points(&txt).unwrap().len(), 2);
        // NaN is no return, dropped as the binary readers drop it; 3DTK's too.
        let nan = write(dir.path(), "n.xyz", b"1 2 3\n\n1 2 nan\nNaN 0 0\n4 5 6\n");
        assert_eq!(read_points(&nan).unwrap().len(), 2);
        let uos = write(dir.path(), "n.3d", b"100 200 300\n4 5 NaN\n");
        assert_eq!(read_points(&uos).unwrap(), vec![Vec3::new(3.0, -1.0, 2.0)]);
    }

    #[test]
    fn xyz_malformed() {
        expect_err("e.xyz", b"", None);
        expect_err("e.xyz", b"  \n\n", None);
        expect_err("c.xyz", b"# only a comment\n", None);
        expect_err("n.xyz", b"1 2 3\n1 2\n", Some(2));
        expect_err("n.xyz", b"1 2 3\n1 two 3\n", Some(2));
        expect_err("n.xyz", b"inf 2 3\n", Some(1));
        expect_err("n.xyz", b"1,,3\n", Some(1));
        expect_err("n.xyz", b"x y z\n1 2 3\n", Some(1));
    }

    #[test]
    fn unknown_extension_lists_the_supported_ones() {
        let msg = expect_err("cloud.obj", b"whatever", None);
        assert!(
            msg.contains(".ply") && msg.contains(".pcd") && msg.contains(".3d"),
            "{msg}"
        );
        let msg = expect_err("survey.E57", b"ASTM-E57", None);
        assert!(msg.contains("sdem import"), "{msg}");
        expect_err("noext", b"1 2 3", None);
    }

    #[test]
    fn missing_file_is_an_io_error() {
        let err = read_points(Path::new("/nonexistent/sdem/cloud.ply")).unwrap_err();
        assert!(matches!(err, Error::Io { .. }));
        assert!(err.to_string().contains("cloud.ply"));
    }

    #[test]
    fn uos_3d_converts_to_right_handed_metres() {
        let dir = tempfile::tempdir().unwrap();
        // x = 100 cm right, y = 50 cm up, z = 200 cm forward, plus a reflectance column.
        let path = write(
            dir.path(),
            "s.3d",
            b"360 x 225\n100 50 200 0.3\n-10.5 0 0\n",
        );
        let points = read_points(&path).unwrap();
        assert_eq!(points.len(), 2);
        assert!(
            (points[0] - Vec3::new(2.0, -1.0, 0.5)).norm() < 1e-12,
            "{:?}",
            points[0]
        );
        // Left (negative x in 3DTK) is +y here.
        assert!((points[1] - Vec3::new(0.0, 0.105, 0.0)).norm() < 1e-12);
        // Without the header line as well.
        let path = write(dir.path(), "t.3d", b"100 50 200\n");
        assert_eq!(read_points(&path).unwrap().len(), 1);
    }

    #[test]
    fn uos_3d_is_right_handed_after_conversion() {
        // In 3DTK's left-handed frame, right × up = forward. In ours, forward × left = up.
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "axes.3d", b"100 0 0\n0 100 0\n0 0 100\n");
        let p = read_points(&path).unwrap();
        let (right, up, forward) = (p[0], p[1], p[2]);
        assert!((forward - Vec3::x()).norm() < 1e-12);
        assert!((right + Vec3::y()).norm() < 1e-12);
        assert!((up - Vec3::z()).norm() < 1e-12);
        assert!((forward.cross(&(-right)) - up).norm() < 1e-12);
    }

    #[test]
    fn uos_3d_malformed() {
        expect_err("e.3d", b"", None);
        expect_err("h.3d", b"360 x 225\n", None);
        expect_err("b.3d", b"360 x 225\n1 2\n", Some(2));
        expect_err("b.3d", b"1 2 3\n360 x 225\n", Some(2));
        expect_err("b.3d", b"1 2 3\n4 5 -inf\n", Some(2));
        expect_err("b.3d", b"1 2 3\n4 5 six\n", Some(2));
    }

    fn kitti_bytes(points: &[[f32; 4]]) -> Vec<u8> {
        points
            .iter()
            .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
            .collect()
    }

    #[test]
    fn kitti_bin_reads_xyz_and_skips_nan() {
        let dir = tempfile::tempdir().unwrap();
        let bytes = kitti_bytes(&[
            [1.5, -2.25, 0.125, 0.5],
            [f32::NAN, 0.0, 0.0, 0.0],
            [10.0, 20.0, -1.0, 0.99],
        ]);
        let path = write(dir.path(), "000000.bin", &bytes);
        let points = read_points(&path).unwrap();
        assert_eq!(
            points,
            vec![Vec3::new(1.5, -2.25, 0.125), Vec3::new(10.0, 20.0, -1.0)]
        );
    }

    #[test]
    fn kitti_bin_malformed() {
        expect_err("e.bin", b"", None);
        let mut bytes = kitti_bytes(&[[1.0, 2.0, 3.0, 0.0], [4.0, 5.0, 6.0, 0.0]]);
        bytes.truncate(27);
        let msg = expect_err("t.bin", &bytes, None);
        assert!(msg.contains("multiple of 16"), "{msg}");
        let msg = expect_err(
            "i.bin",
            &kitti_bytes(&[[1.0, f32::INFINITY, 3.0, 0.0]]),
            None,
        );
        assert!(msg.contains("point 0"), "{msg}");
        expect_err("n.bin", &kitti_bytes(&[[f32::NAN, 2.0, 3.0, 0.0]]), None);
    }
}
