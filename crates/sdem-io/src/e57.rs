//! ASTM E57 surveys (`.e57`), read and written with the `e57` crate.
//!
//! An E57 file holds a survey: any number of scans ("data3D" point clouds), each with its points
//! in its own frame (Cartesian, or spherical range/azimuth/elevation) and, when registered, a
//! pose that maps that frame into the file's. sdem reads every scan in its own frame (the pose is
//! not applied to the points) with its pose as `world_from_sensor`
//! ([`read_e57`]), and writes scans with poses the same way ([`write_e57`]).
//!
//! Reading keeps each point whose Cartesian coordinates are valid (`cartesianInvalidState` 0),
//! or whose spherical coordinates are (converted to Cartesian by `e57`); a direction without a
//! range, an invalid point and a point at exactly (0, 0, 0) (some scanners write no return so)
//! are dropped and counted. Intensity and colour are ignored. E57 stores metres; each scan is
//! checked as [`crate::read_points`] checks a scan (coordinates within `f32`, half of the points
//! within [`crate::MAX_MEDIAN_RANGE_M`] of the scanner). A pose's quaternion is normalized, and
//! one that is zero or not finite is an error naming the scan.

use super::{fmt_point, write_atomic};
use crate::error::{one_line, Error, Result};
use nalgebra::{Quaternion, Translation3, UnitQuaternion};
use sdem::geometry::{Pose, Vec3};
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom};
use std::path::Path;

/// One scan of an E57 survey, as read.
#[derive(Debug, Clone, PartialEq)]
pub struct E57Scan {
    /// The scan's name in the file, when it has one.
    pub name: Option<String>,
    /// The points kept, in the scan's own (sensor) frame, metres.
    pub points_in_sensor: Vec<Vec3>,
    /// The scan's registered pose (its frame in the file's), when the file has one.
    pub world_from_sensor: Option<Pose>,
    /// The points dropped: invalid, a direction without a range, or at the origin.
    pub dropped: usize,
}

/// One scan to write into an E57 survey.
#[derive(Debug, Clone, Copy)]
pub struct E57ScanOut<'a> {
    /// The scan's name in the file.
    pub name: &'a str,
    /// The points, in the scan's own (sensor) frame, metres.
    pub points_in_sensor: &'a [[f32; 3]],
    /// The scan's pose in the survey's frame.
    pub world_from_sensor: &'a Pose,
}

/// Reads every scan of an E57 survey, in the order of the file (see the module documentation).
/// For surveys too large to hold at once, [`for_each_e57_scan`] reads one scan at a time.
///
/// # Errors
/// [`Error::Io`] when the file cannot be read; [`Error::Parse`] naming the file (and the scan)
/// when it is not an E57 file, is truncated or damaged (its pages carry checksums), holds no
/// scan, or a scan's pose is not a rotation.
pub fn read_e57(path: &Path) -> Result<Vec<E57Scan>> {
    let mut scans = Vec::new();
    for_each_e57_scan(
        path,
        |_| true,
        |_, scan| {
            scans.push(scan);
            Ok(())
        },
    )?;
    Ok(scans)
}

/// Reads the scans of an E57 survey one at a time, in the order of the file: `visit(index,
/// scan)` gets each scan for which `wanted(index)` is true (the others' points are not decoded),
/// so only one scan is in memory at a time. Returns the number of scans in the survey.
///
/// # Errors
/// As [`read_e57`], and whatever `visit` returns.
pub fn for_each_e57_scan(
    path: &Path,
    wanted: impl Fn(usize) -> bool,
    mut visit: impl FnMut(usize, E57Scan) -> Result<()>,
) -> Result<usize> {
    let err = |message: String| Error::parse(path, None, message);
    let mut file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut magic = Vec::with_capacity(8);
    (&mut file)
        .take(8)
        .read_to_end(&mut magic)
        .map_err(|e| Error::io(path, e))?;
    if magic.is_empty() {
        return Err(err(
            "the file is empty; expected an E57 header starting with 'ASTM-E57'".into(),
        ));
    }
    if magic != b"ASTM-E57" {
        let start = String::from_utf8_lossy(&magic).into_owned();
        return Err(err(format!(
            "the file starts with {start:?}, not the E57 magic 'ASTM-E57'; it is not an E57 file"
        )));
    }
    file.seek(SeekFrom::Start(0))
        .map_err(|e| Error::io(path, e))?;
    let mut reader = ::e57::E57Reader::new(BufReader::new(file))
        .map_err(|e| err(format!("not a readable E57 file: {}", one_line(&e))))?;
    let clouds = reader.pointclouds();
    if clouds.is_empty() {
        return Err(err(
            "the survey holds no scans (its data3D list is empty); there is nothing to import"
                .into(),
        ));
    }
    for (index, cloud) in clouds.iter().enumerate() {
        if !wanted(index) {
            continue;
        }
        let name = cloud
            .name
            .as_ref()
            .map_or(String::new(), |n| format!(" ('{n}')"));
        let scan = read_scan(&mut reader, cloud)
            .map_err(|message| err(format!("scan {index}{name}: {message}")))?;
        if !scan.points_in_sensor.is_empty() {
            // As every scan: metres in the sensor frame (see `read_points`).
            crate::points::check_magnitudes(path, &scan.points_in_sensor, None).map_err(
                |e| match e {
                    Error::Parse { message, .. } => err(format!("scan {index}{name}: {message}")),
                    other => other,
                },
            )?;
        }
        visit(index, scan)?;
    }
    Ok(clouds.len())
}

/// Reads one scan's points and pose; the error says what is wrong with it.
fn read_scan<T: std::io::Read + std::io::Seek>(
    reader: &mut ::e57::E57Reader<T>,
    cloud: &::e57::PointCloud,
) -> std::result::Result<E57Scan, String> {
    let world_from_sensor = cloud.transform.as_ref().map(pose_of).transpose()?;
    let mut iter = reader
        .pointcloud_simple(cloud)
        .map_err(|e| format!("cannot read its points: {}", one_line(&e)))?;
    iter.apply_pose(false);
    iter.spherical_to_cartesian(true);
    let mut points = Vec::new();
    let mut dropped = 0;
    for (i, point) in iter.enumerate() {
        let point = point.map_err(|e| format!("point {i} cannot be read: {}", one_line(&e)))?;
        match point.cartesian {
            ::e57::CartesianCoordinate::Valid { x, y, z }
                if [x, y, z].iter().all(|v| v.is_finite()) && (x, y, z) != (0.0, 0.0, 0.0) =>
            {
                points.push(Vec3::new(x, y, z));
            }
            ::e57::CartesianCoordinate::Valid { x, y, z }
                if [x, y, z].iter().any(|v| v.is_infinite()) =>
            {
                return Err(format!(
                    "point {i} is {}; coordinates must be finite",
                    fmt_point([x, y, z])
                ));
            }
            _ => dropped += 1,
        }
    }
    Ok(E57Scan {
        name: cloud.name.clone(),
        points_in_sensor: points,
        world_from_sensor,
        dropped,
    })
}

/// An E57 transform as a pose; the quaternion is normalized.
fn pose_of(transform: &::e57::Transform) -> std::result::Result<Pose, String> {
    let (q, t) = (&transform.rotation, &transform.translation);
    let values = [q.w, q.x, q.y, q.z, t.x, t.y, t.z];
    let norm = (q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z).sqrt();
    if !values.iter().all(|v| v.is_finite()) || norm <= 1e-6 {
        return Err(format!(
            "its pose (quaternion w {} x {} y {} z {}, translation {} {} {}) is not a rigid \
             transform",
            q.w, q.x, q.y, q.z, t.x, t.y, t.z
        ));
    }
    let rotation = UnitQuaternion::from_quaternion(Quaternion::new(q.w, q.x, q.y, q.z));
    Ok(Pose::from_parts(Translation3::new(t.x, t.y, t.z), rotation))
}

/// Writes an E57 survey of `scans` (through [`write_atomic`]): each scan's points as 32-bit
/// floats in its own frame, with its pose, named `name`. The file's GUID is derived from the
/// content (CRC-32s of the points, poses and names), so the same scans give the same file.
///
/// # Example
/// ```
/// use sdem::geometry::Pose;
/// let dir = tempfile::tempdir()?;
/// let path = dir.path().join("survey.e57");
/// let points = [[1.0f32, 0.0, 0.5], [0.0, 2.0, -0.25]];
/// let pose = Pose::translation(3.0, 0.0, 0.0);
/// let scan = sdem_io::E57ScanOut { name: "a", points_in_sensor: &points, world_from_sensor: &pose };
/// sdem_io::write_e57(&path, &[scan])?;
/// let back = sdem_io::read_e57(&path)?;
/// assert_eq!(back[0].points_in_sensor.len(), 2);
/// assert_eq!(back[0].world_from_sensor, Some(pose));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// [`Error::Invalid`] for no scan, a scan without points, or a non-finite coordinate or pose;
/// [`Error::Io`] when the file cannot be written.
pub fn write_e57(path: &Path, scans: &[E57ScanOut]) -> Result<()> {
    let refuse =
        |why: String| Error::Invalid(format!("refusing to write {}: {why}", path.display()));
    if scans.is_empty() {
        return Err(refuse("there are no scans".into()));
    }
    for (i, scan) in scans.iter().enumerate() {
        if scan.points_in_sensor.is_empty() {
            return Err(refuse(format!("scan {i} ('{}') has no points", scan.name)));
        }
        if let Some(p) = scan
            .points_in_sensor
            .iter()
            .find(|p| !p.iter().all(|v| v.is_finite()))
        {
            return Err(refuse(format!(
                "scan {i} has a point {p:?}; coordinates must be finite"
            )));
        }
    }
    for (i, scan) in scans.iter().enumerate() {
        let pose = scan.world_from_sensor.to_homogeneous();
        if !pose.iter().all(|v| v.is_finite()) {
            return Err(refuse(format!("scan {i}'s pose is not finite")));
        }
    }
    let bytes = encode(scans, &content_guid(scans)).map_err(|e| refuse(one_line(&e)))?;
    write_atomic(path, |w| w.write_all(&bytes))
}

/// The whole E57 file, in memory (the writer seeks back to fill in its header).
fn encode(scans: &[E57ScanOut], guid: &str) -> ::e57::Result<Vec<u8>> {
    let mut out = Cursor::new(Vec::new());
    let mut writer = ::e57::E57Writer::new(&mut out, guid)?;
    for (i, scan) in scans.iter().enumerate() {
        let prototype = vec![
            ::e57::Record::CARTESIAN_X_F32,
            ::e57::Record::CARTESIAN_Y_F32,
            ::e57::Record::CARTESIAN_Z_F32,
        ];
        let mut cloud = writer.add_pointcloud(&format!("{guid}-scan-{i}"), prototype)?;
        cloud.set_name(Some(scan.name.to_string()));
        cloud.set_transform(Some(transform_of(scan.world_from_sensor)));
        for p in scan.points_in_sensor {
            cloud.add_point(p.iter().map(|&v| ::e57::RecordValue::Single(v)).collect())?;
        }
        cloud.finalize()?;
    }
    writer.finalize()?;
    drop(writer);
    Ok(out.into_inner())
}

/// A GUID-shaped id (`{8-4-4-4-12}` hex digits) made of CRC-32s of the scans' points, poses,
/// names and count.
fn content_guid(scans: &[E57ScanOut]) -> String {
    let mut points = crc32fast::Hasher::new();
    let mut poses = crc32fast::Hasher::new();
    let mut names = crc32fast::Hasher::new();
    for scan in scans {
        scan.points_in_sensor
            .iter()
            .flatten()
            .for_each(|v| points.update(&v.to_le_bytes()));
        let pose = scan.world_from_sensor.to_homogeneous();
        pose.iter().for_each(|v| poses.update(&v.to_le_bytes()));
        names.update(scan.name.as_bytes());
        names.update(&[0]);
    }
    let (a, b, c) = (points.finalize(), poses.finalize(), names.finalize());
    let d = crc32fast::hash(&(scans.len() as u64).to_le_bytes());
    format!(
        "{{{a:08X}-{:04X}-{:04X}-{:04X}-{:04X}{d:08X}}}",
        b >> 16,
        b & 0xFFFF,
        c >> 16,
        c & 0xFFFF
    )
}

/// A pose as an E57 transform (the quaternion with w ≥ 0, as E57 asks).
fn transform_of(pose: &Pose) -> ::e57::Transform {
    let q = pose.rotation.quaternion();
    let sign = if q.w < 0.0 { -1.0 } else { 1.0 };
    let t = pose.translation.vector;
    ::e57::Transform {
        rotation: ::e57::Quaternion {
            w: sign * q.w,
            x: sign * q.i,
            y: sign * q.j,
            z: sign * q.k,
        },
        translation: ::e57::Translation {
            x: t.x,
            y: t.y,
            z: t.z,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ::e57::{Record, RecordDataType, RecordName, RecordValue};

    fn record(name: RecordName, data_type: RecordDataType) -> Record {
        Record { name, data_type }
    }

    /// An E57 file of one spherical scan (range, azimuth, elevation, invalid state; the e57
    /// crate's writer): three valid points, one direction without a range (state 1) and one
    /// invalid point (state 2); or, with `clouds` false, of no scan at all.
    fn spherical_file(clouds: bool) -> Vec<u8> {
        let mut out = Cursor::new(Vec::new());
        let mut writer = ::e57::E57Writer::new(&mut out, "{test}").unwrap();
        if clouds {
            let prototype = vec![
                record(RecordName::SphericalRange, RecordDataType::F64),
                record(RecordName::SphericalAzimuth, RecordDataType::F64),
                record(RecordName::SphericalElevation, RecordDataType::F64),
                record(
                    RecordName::SphericalInvalidState,
                    RecordDataType::Integer { min: 0, max: 2 },
                ),
            ];
            let mut cloud = writer.add_pointcloud("{cloud}", prototype).unwrap();
            let half_pi = std::f64::consts::FRAC_PI_2;
            for (r, az, el, state) in [
                (2.0, 0.0, 0.0, 0),
                (3.0, half_pi, 0.0, 0),
                (1.5, 0.0, half_pi / 3.0, 0),
                (0.0, 1.0, 0.2, 1),
                (7.0, 2.0, 0.1, 2),
            ] {
                let values = [r, az, el].map(RecordValue::Double);
                let mut values = values.to_vec();
                values.push(RecordValue::Integer(state));
                cloud.add_point(values).unwrap();
            }
            cloud.finalize().unwrap();
        }
        writer.finalize().unwrap();
        drop(writer);
        out.into_inner()
    }

    fn read(bytes: &[u8]) -> Result<Vec<E57Scan>> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("survey.e57");
        std::fs::write(&path, bytes).unwrap();
        read_e57(&path)
    }

    fn expect_err(bytes: &[u8]) -> String {
        let msg = read(bytes).unwrap_err().to_string();
        assert!(msg.contains("survey.e57"), "{msg}");
        msg
    }

    #[test]
    fn spherical_scans_become_cartesian_and_directions_are_dropped() {
        let scans = read(&spherical_file(true)).unwrap();
        assert_eq!(scans.len(), 1);
        assert_eq!(scans[0].world_from_sensor, None);
        assert_eq!(scans[0].dropped, 2);
        let expected = [
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 0.0),
            Vec3::new(1.5 * 0.75f64.sqrt(), 0.0, 0.75),
        ];
        assert_eq!(scans[0].points_in_sensor.len(), 3);
        for (p, q) in scans[0].points_in_sensor.iter().zip(expected) {
            assert!((p - q).norm() < 1e-12, "{p:?} vs {q:?}");
        }
    }

    #[test]
    fn written_scans_read_back_with_their_poses() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.e57");
        let a = [[1.0f32, 2.0, 0.5], [-3.0, 0.25, 1.5]];
        let b = [[0.125f32, -1.0, 2.0]];
        let pose_a = sdem::geometry::pose_from_parts(
            Vec3::new(4.0, -1.0, 0.25),
            sdem::geometry::Attitude::from_degrees(1.0, -2.0, 200.0),
        );
        let pose_b = Pose::translation(0.5, 0.0, 0.0);
        let scans = [
            E57ScanOut {
                name: "scan 000000",
                points_in_sensor: &a,
                world_from_sensor: &pose_a,
            },
            E57ScanOut {
                name: "scan 000003",
                points_in_sensor: &b,
                world_from_sensor: &pose_b,
            },
        ];
        write_e57(&path, &scans).unwrap();
        let first = std::fs::read(&path).unwrap();
        let back = read_e57(&path).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[1].name.as_deref(), Some("scan 000003"));
        let as_f64 = |p: &[f32; 3]| Vec3::new(p[0].into(), p[1].into(), p[2].into());
        assert_eq!(
            back[0].points_in_sensor,
            a.iter().map(as_f64).collect::<Vec<_>>()
        );
        let pose = back[0].world_from_sensor.unwrap();
        assert!((pose.to_homogeneous() - pose_a.to_homogeneous()).amax() < 1e-12);
        // The same scans give the same file.
        write_e57(&path, &scans).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), first);
        assert!(write_e57(&path, &[]).is_err());
    }

    #[test]
    fn malformed_surveys() {
        assert!(expect_err(b"").contains("empty"));
        assert!(expect_err(b"PK\x03\x04 not a survey").contains("'ASTM-E57'"));
        let good = spherical_file(true);
        let msg = expect_err(&good[..good.len() - 100]);
        assert!(msg.contains("truncated"), "{msg}");
        let msg = expect_err(&spherical_file(false));
        assert!(msg.contains("no scans"), "{msg}");
        let mut damaged = good.clone();
        damaged[600] ^= 0x40;
        let msg = expect_err(&damaged);
        assert!(msg.contains("E57"), "{msg}");
    }
}
