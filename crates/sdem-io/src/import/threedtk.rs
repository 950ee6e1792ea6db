//! 3DTK folders (`scanNNN.3d` + `scanNNN.pose`, [`import_3dtk`]).
//!
//! 3DTK's frame is **left-handed**: x right, y up, z forward, centimetres. A point maps to sdem's
//! frame (x forward, y left, z up, metres) by the fixed axis map `C`:
//! `p_sdem = C · p_3dtk / 100` with `C · (x, y, z) = (z, −x, y)`. `C` has determinant −1 (a
//! reflection), so a rigid transform `M = [R | t]` between two 3DTK frames becomes
//! `C · M · C⁻¹ = [C R Cᵀ | C t / 100]` between the matching sdem frames, again a proper rotation.
//! A rotation by θ about 3DTK's y (up) axis becomes a yaw of **−θ** about sdem's z: 3DTK's angles
//! turn the left-handed way.
//!
//! - **Scans**: each `scanNNN.3d` is read with [`crate::read_points`] (which already applies
//!   `C` and the centimetres), and written as `scans/000000.ply`, … (binary PLY, numbered from 0
//!   in the order of `NNN`). Returns at a scan's "no return" range (where 0.5 % of its points or
//!   more pile up within 2 cm at the far end of its ranges: 32.76 m on 3DTK's example scans;
//!   [`no_return_range`]) and beyond are no surface and are dropped, and so are returns
//!   nearer than [`UOS_MIN_RANGE_M`] (0.2 m; the robot itself and invalid returns); the summary
//!   counts both. Every other return is kept, however far.
//! - **`scanNNN.pose`** (two lines: `x y z` in cm, then `θx θy θz` in degrees, with
//!   `world_from_scan = [Rx(θx)·Ry(θy)·Rz(θz) | t]` in 3DTK's frame, see [`read_uos_pose`]) is
//!   the robot's initial estimate, i.e. its odometry. It is converted as above and written as
//!   `odometry.txt`, and the roll, pitch and yaw of the converted rotation (sdem's
//!   `R = Rz·Ry·Rx`) as `attitude.csv`, since 3DTK data has no separate gyro/compass reading.
//! - **`sensor.toml`**: the scanner's beam and line steps measured from the scans' point order
//!   ([`measure_line_scanner`]; the median over the scans; the line step a tilt step where the
//!   lines lie near the horizontal, as a nodding scanner's, a pan step where they stand, as a
//!   turning scanner's), the extents of the
//!   returns' directions and ranges, and an assumed 1 cm range noise ([`measured_sensor`]), so
//!   that `sdem slam` matches its S-DEM to the scanner that took the scans. Where no scan shows
//!   a scanner's lines (points merged or reordered), none is written and the summary says so:
//!   `sdem slam` then chooses its grid from the first scan.
//!   A `.pose` must exist for every imported `.3d`.
//! - **`scanNNN.frames`** (slam6D's output; one line per registration step, a 4×4 matrix in
//!   OpenGL column-major order in cm, then a flag), when a frames folder is given or found
//!   (`slam6d_frames_2009/`, or `.frames` files beside the scans): the **last** line of each,
//!   slam6D's final registration, is converted as above and written as `poses_slam6d.txt`. It is
//!   a reference to compare with, not ground truth, so it never becomes `poses_truth.txt`.
//!
//! 3DTK's poses are in 3DTK's world frame, the frame of its scan 0, and are kept there (not
//! re-based on the first imported scan) so that the attitude keeps its roll and pitch.

use super::line_scanner::{measure_line_scanner, measured_sensor, no_return_range, Extents};
use super::{
    check_out, check_source, numbered_files, scan_name, select, write_or_roll_back, ImportFormat,
    ImportOptions, ImportSummary,
};
use crate::dataset::{ODOMETRY_FILE, SLAM6D_FILE};
use crate::error::{Error, Result};
use crate::poses::to_rotation;
use crate::{
    fmt_msg, numbered_lines, parse_finite, read_points, read_text, write_attitude_csv,
    write_points_ply, write_poses, write_sensor_toml, ATTITUDE_FILE, SCANS_DIR, SENSOR_FILE,
};
use nalgebra::{Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3};
use sdem::geometry::{attitude_of, Attitude, Pose, Vec3};
use std::path::Path;

/// The range (metres) within which the benches re-view 3DTK's example scans (`sdem bench
/// --suite real-geometry`, `examples/real_unlevelled`): their surfaces but the corridor's far
/// end, whose returns 30–32.4 m away disagree between scans by metres. The import keeps every
/// return short of each scan's own "no return" range.
pub const UOS_MAX_RANGE_M: f64 = 30.0;

/// 3DTK points nearer than this (metres) are dropped on import: returns from the robot itself and
/// invalid ones.
pub const UOS_MIN_RANGE_M: f64 = 0.2;

/// The largest translation, metres from 3DTK's origin, that a `.pose` or `.frames` may hold: a
/// robot's survey spans kilometres, not a thousand; beyond this the value is damaged (a `1e300`
/// would become an odometry step of 1e298 m that every later stage trusts) or not centimetres.
const MAX_UOS_TRANSLATION_M: f64 = 1e6;

/// The largest angle, degrees, that a `.pose` may hold: a thousand turns leaves room for an
/// unwrapped heading; beyond it the value is damaged or not in degrees, and its sine and cosine
/// carry no meaning.
const MAX_UOS_ANGLE_DEG: f64 = 360_000.0;

/// Refuses a translation component (`cm`) beyond [`MAX_UOS_TRANSLATION_M`]; `what` names it.
fn check_uos_translation(path: &Path, line_no: usize, cm: f64, what: &str) -> Result<()> {
    if (cm / 100.0).abs() > MAX_UOS_TRANSLATION_M {
        return Err(Error::parse(
            path,
            Some(line_no),
            format!(
                "{what} is {} cm, {} m from 3DTK's origin; a position lies within \
                 ±{MAX_UOS_TRANSLATION_M:e} m, so the file is damaged or not in centimetres",
                fmt_msg(cm),
                fmt_msg(cm / 100.0)
            ),
        ));
    }
    Ok(())
}

/// The folder name under which the 3DTK example data keeps slam6D's `.frames` files.
const DEFAULT_FRAMES_DIR: &str = "slam6d_frames_2009";

// ---------------------------------------------------------------------------------------------
// Frames and poses
// ---------------------------------------------------------------------------------------------

/// `C`: 3DTK axes (x right, y up, z forward) to sdem's (x forward, y left, z up); a reflection.
fn sdem_from_uos() -> Matrix3<f64> {
    Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
}

/// Converts a 3DTK `world_from_scan` (4×4, left-handed frames, centimetres) into sdem's
/// `world_from_sensor` (right-handed, metres): `C · M · C⁻¹`, translation divided by 100.
///
/// # Errors
/// A message when the 3×3 block is not a rotation (to within 1e-3) or the bottom row is not
/// `0 0 0 1`.
///
/// # Example
/// ```
/// use nalgebra::Matrix4;
/// // 3DTK: 150 cm forward (z) and 20 cm to the right (x).
/// let m = Matrix4::new_translation(&nalgebra::Vector3::new(20.0, 0.0, 150.0));
/// let pose = sdem_io::uos_matrix_to_world_from_sensor(&m).unwrap();
/// let t = pose.translation.vector;
/// assert!((t - nalgebra::Vector3::new(1.5, -0.2, 0.0)).norm() < 1e-12);
/// ```
pub fn uos_matrix_to_world_from_sensor(m: &Matrix4<f64>) -> std::result::Result<Pose, String> {
    let bottom = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
    if (bottom[0].abs() + bottom[1].abs() + bottom[2].abs() + (bottom[3] - 1.0).abs()) > 1e-6 {
        return Err(format!(
            "the bottom row is {bottom:?}, not [0, 0, 0, 1]; not a rigid transform"
        ));
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let rotation = to_rotation(&r)?;
    let c = sdem_from_uos();
    let r_sdem = to_rotation(&(c * rotation.matrix() * c.transpose()))?;
    let t: Vector3<f64> = m.fixed_view::<3, 1>(0, 3).into_owned();
    let t_sdem = c * t / 100.0;
    Ok(Pose::from_parts(
        Translation3::from(t_sdem),
        UnitQuaternion::from_rotation_matrix(&r_sdem),
    ))
}

/// Converts a 3DTK pose (translation in cm; `θx θy θz` in degrees, `R = Rx(θx)·Ry(θy)·Rz(θz)`,
/// as 3DTK's `EulerToMatrix4` builds it) into sdem's `world_from_sensor`.
///
/// # Example
/// ```
/// // 3DTK turns +90° about its up axis (y): its forward (z) becomes its right (x), which is
/// // sdem's −y, so the sdem yaw is −90°.
/// let pose = sdem_io::uos_pose_to_world_from_sensor([0.0; 3], [0.0, 90.0, 0.0]);
/// let yaw = sdem::geometry::attitude_of(&pose).yaw.to_degrees();
/// assert!((yaw + 90.0).abs() < 1e-9);
/// ```
pub fn uos_pose_to_world_from_sensor(translation_cm: [f64; 3], angles_deg: [f64; 3]) -> Pose {
    let [ax, ay, az] = angles_deg.map(f64::to_radians);
    let r = Rotation3::from_axis_angle(&Vector3::x_axis(), ax)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), ay)
        * Rotation3::from_axis_angle(&Vector3::z_axis(), az);
    let mut m = r.to_homogeneous();
    m[(0, 3)] = translation_cm[0];
    m[(1, 3)] = translation_cm[1];
    m[(2, 3)] = translation_cm[2];
    uos_matrix_to_world_from_sensor(&m).expect("a product of rotations is a rotation")
}

/// Reads a 3DTK `.pose` file (two lines: `x y z` in cm, then `θx θy θz` in degrees; blank lines
/// ignored) as sdem's `world_from_sensor` ([`uos_pose_to_world_from_sensor`]).
///
/// # Errors
/// [`Error::Parse`] naming the file and line for a line without exactly 3 numbers, a non-number,
/// a non-finite value, a translation beyond ±1e6 m or an angle beyond ±360 000° (a thousand
/// turns), and for a file with other than 2 such lines.
pub fn read_uos_pose(path: &Path) -> Result<Pose> {
    let text = read_text(path)?;
    let mut rows: Vec<[f64; 3]> = Vec::new();
    for (line_no, line) in numbered_lines(&text) {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.is_empty() {
            continue;
        }
        let what = ["translation (x y z, cm)", "rotation (θx θy θz, degrees)"];
        if rows.len() == 2 {
            return Err(Error::parse(
                path,
                Some(line_no),
                "a 3DTK .pose has two lines, 'x y z' (cm) then 'θx θy θz' (degrees); this is a third",
            ));
        }
        let what = what[rows.len()];
        if tokens.len() != 3 {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!("expected 3 numbers, the {what}; found {}", tokens.len()),
            ));
        }
        let mut row = [0.0; 3];
        for (k, (slot, token)) in row.iter_mut().zip(&tokens).enumerate() {
            let name = format!("value {} of the {what}", k + 1);
            *slot = parse_finite(path, line_no, token, &name)?;
            if rows.is_empty() {
                check_uos_translation(path, line_no, *slot, &name)?;
            } else if slot.abs() > MAX_UOS_ANGLE_DEG {
                return Err(Error::parse(
                    path,
                    Some(line_no),
                    format!(
                        "{name} is {}°, more than a thousand turns; the file is damaged or not in \
                         degrees",
                        fmt_msg(*slot)
                    ),
                ));
            }
        }
        rows.push(row);
    }
    match rows.as_slice() {
        [t, r] => Ok(uos_pose_to_world_from_sensor(*t, *r)),
        _ => Err(Error::parse(
            path,
            None,
            format!(
                "{} line(s) of numbers; a 3DTK .pose has two, 'x y z' (cm) then 'θx θy θz' (degrees)",
                rows.len()
            ),
        )),
    }
}

/// Reads a slam6D `.frames` file and returns its **last** line (slam6D's final registration)
/// as sdem's `world_from_sensor`. Each non-blank line holds 16 numbers, a 4×4 matrix in OpenGL
/// column-major order (elements 12–14 the translation, cm), and optionally a 17th, a flag; every
/// line is checked.
///
/// # Errors
/// [`Error::Parse`] naming the file and line: a wrong number count, a non-number, a non-finite
/// value, a translation beyond ±1e6 m, or a matrix that is not a rigid transform; a file without
/// lines.
pub fn read_uos_frames_last(path: &Path) -> Result<Pose> {
    let text = read_text(path)?;
    let mut last = None;
    for (line_no, line) in numbered_lines(&text) {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.is_empty() {
            continue;
        }
        if tokens.len() != 16 && tokens.len() != 17 {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "{} numbers on this line; a .frames line is a 4×4 matrix in column-major order \
                     (16 numbers) and a flag",
                    tokens.len()
                ),
            ));
        }
        let mut v = [0f64; 16];
        for (k, (slot, token)) in v.iter_mut().zip(&tokens).enumerate() {
            *slot = parse_finite(path, line_no, token, &format!("value {}", k + 1))?;
            if (12..15).contains(&k) {
                check_uos_translation(path, line_no, *slot, &format!("value {}", k + 1))?;
            }
        }
        let m = Matrix4::from_column_slice(&v);
        let pose = uos_matrix_to_world_from_sensor(&m)
            .map_err(|why| Error::parse(path, Some(line_no), format!("the matrix: {why}")))?;
        last = Some(pose);
    }
    last.ok_or_else(|| {
        Error::parse(
            path,
            None,
            "the file holds no frames; expected lines of 16 numbers (a column-major 4×4) and a flag",
        )
    })
}

/// Keeps the points with `UOS_MIN_RANGE_M ≤ |p|` and, where the scan has a "no return" range
/// (`no_return_from`), `|p| < no_return_from`; returns them with the number dropped at the
/// "no return" range and the number dropped as too near.
fn filter_uos_points(points: Vec<Vec3>, no_return_from: Option<f64>) -> (Vec<Vec3>, usize, usize) {
    let (mut far, mut near) = (0, 0);
    let kept = points
        .into_iter()
        .filter(|p| {
            let r = p.norm();
            if no_return_from.is_some_and(|from| r >= from) {
                far += 1;
                false
            } else if r < UOS_MIN_RANGE_M {
                near += 1;
                false
            } else {
                true
            }
        })
        .collect();
    (kept, far, near)
}

/// Refuses a gap in the numbers of the selected scans (`scan000`, `scan002` without `scan001`):
/// the import numbers the dataset's scans from 0 without gaps, so a lost or deleted scan would
/// silently join its neighbours as consecutive stops, and the user would never learn that the
/// motion between them spans two. `--first` and `--count` choose where a selection starts and
/// ends, so only a gap inside it is an error; with `--every K` the selected numbers lie `every`
/// apart, and a missing one among them is the gap.
fn check_no_gap(scans: &[(usize, std::path::PathBuf)], every: usize) -> Result<()> {
    for pair in scans.windows(2) {
        let [(before, before_path), (after, after_path)] = pair else {
            continue;
        };
        if *after == before + every {
            continue;
        }
        // The missing file, with the digits of its neighbour (`scan001.3d`, not `scan1.3d`).
        let digits = before_path
            .file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| s.strip_prefix("scan"))
            .map_or(0, str::len);
        let missing = before_path.with_file_name(format!("scan{:0digits$}.3d", before + every));
        let gap = (after - before) / every - 1;
        return Err(Error::Invalid(format!(
            "{} is missing ({gap} scan(s) missing between {} and {}): the import would number the \
             scans on either side of the gap as consecutive stops; restore it, or import each \
             side on its own with --first and --count",
            missing.display(),
            before_path.display(),
            after_path.display()
        )));
    }
    Ok(())
}

/// Imports a 3DTK folder into the dataset folder `out` (see the module documentation for the
/// frames and the files written): `scans/NNNNNN.ply`, `odometry.txt` (+ `.tum`),
/// `attitude.csv`, and `poses_slam6d.txt` (+ `.tum`) when `.frames` files are found.
///
/// Everything but the point clouds is read and checked before anything is written; an error
/// while writing removes what was written.
///
/// # Errors
/// `source` missing or without `scanNNN.3d`; a gap in the numbers of the selected scans (naming
/// the first missing file); a `.pose` (or, with a frames folder, a `.frames`)
/// missing for a selected scan; a malformed `.pose`, `.frames` or `.3d` (naming the file and
/// line); a scan left without points by the range filter; `out` holding a dataset entry
/// ([`DATASET_ENTRIES`](crate::DATASET_ENTRIES)).
pub fn import_3dtk(source: &Path, out: &Path, options: &ImportOptions) -> Result<ImportSummary> {
    check_source(source)?;
    let scans = select(
        numbered_files(source, "scan", "3d")?,
        options,
        source,
        "3DTK scanNNN.3d files",
    )?;
    check_no_gap(&scans, options.stride()?)?;
    let mut odometry = Vec::with_capacity(scans.len());
    for (_, scan) in &scans {
        let pose_path = scan.with_extension("pose");
        if !pose_path.is_file() {
            return Err(Error::Invalid(format!(
                "{} is missing; 3DTK needs a .pose (x y z in cm, then θx θy θz in degrees) beside \
                 each scan, here for {}",
                pose_path.display(),
                scan.display()
            )));
        }
        odometry.push(read_uos_pose(&pose_path)?);
    }
    let frames_dir = match &options.frames_dir {
        Some(dir) if dir.is_dir() => Some(dir.clone()),
        Some(dir) => {
            return Err(Error::Invalid(format!(
                "the frames folder {} does not exist",
                dir.display()
            )))
        }
        None if source.join(DEFAULT_FRAMES_DIR).is_dir() => Some(source.join(DEFAULT_FRAMES_DIR)),
        None if !numbered_files(source, "scan", "frames")?.is_empty() => Some(source.to_path_buf()),
        None => None,
    };
    let slam6d = match &frames_dir {
        Some(dir) => {
            let mut poses = Vec::with_capacity(scans.len());
            for (_, scan) in &scans {
                let name = scan.with_extension("frames");
                let path = dir.join(name.file_name().unwrap_or_default());
                if !path.is_file() {
                    return Err(Error::Invalid(format!(
                        "{} is missing; the frames folder {} needs one .frames per imported scan, \
                         here for {}",
                        path.display(),
                        dir.display(),
                        scan.display()
                    )));
                }
                poses.push(read_uos_frames_last(&path)?);
            }
            Some(poses)
        }
        None => None,
    };
    check_out(out)?;

    let attitudes: Vec<Attitude> = odometry.iter().map(attitude_of).collect();
    let mut summary = ImportSummary::empty(ImportFormat::Uos3dtk, source, out, &scans);
    write_or_roll_back(out, || {
        let (mut steps, mut extents) = (Vec::new(), Extents::new());
        for (index, (_, scan)) in scans.iter().enumerate() {
            let raw = read_points(scan)?;
            steps.extend(measure_line_scanner(&raw));
            let no_return_from = no_return_range(&raw);
            let (points, far, near) = filter_uos_points(raw, no_return_from);
            if points.is_empty() {
                return Err(Error::parse(
                    scan,
                    None,
                    format!(
                        "no point lies {UOS_MIN_RANGE_M} m or more from the sensor short of its \
                         \"no return\" range; nothing is left to import"
                    ),
                ));
            }
            extents.add(&points);
            write_points_ply(&out.join(SCANS_DIR).join(scan_name(index, "ply")), &points)?;
            summary.points_per_scan.push(points.len());
            summary.dropped_far += far;
            summary.dropped_near += near;
            summary.no_return_from_m = match (summary.no_return_from_m, no_return_from) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            };
        }
        summary
            .written
            .push(format!("{SCANS_DIR}/ ({} .ply)", scans.len()));
        write_poses(&out.join(ODOMETRY_FILE), &odometry)?;
        summary.written.push(ODOMETRY_FILE.into());
        write_attitude_csv(&out.join(ATTITUDE_FILE), &attitudes)?;
        summary.written.push(ATTITUDE_FILE.into());
        match measured_sensor(&steps, &extents, UOS_MIN_RANGE_M) {
            Ok(sensor) => {
                summary.notes.push(format!(
                    "{SENSOR_FILE}: beams {}° apart, lines {}° apart, measured from the point \
                     order of {} of the {} scans",
                    sensor.pan_step_deg,
                    sensor.tilt_step_deg,
                    steps.len(),
                    scans.len()
                ));
                write_sensor_toml(&out.join(SENSOR_FILE), &sensor)?;
                summary.written.push(SENSOR_FILE.into());
            }
            Err(why) => summary.notes.push(format!(
                "no {SENSOR_FILE} written: {why}; sdem slam chooses its grid from the first scan \
                 (write a {SENSOR_FILE} with the scanner's steps to match it)"
            )),
        }
        if let Some(slam6d) = &slam6d {
            write_poses(&out.join(SLAM6D_FILE), slam6d)?;
            summary.written.push(SLAM6D_FILE.into());
        }
        Ok(())
    })?;
    Ok(summary)
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::import_dataset;
    use crate::import::test_files::write;
    use crate::{read_kitti_poses, Dataset};
    use std::path::PathBuf;

    /// The 3DTK → sdem point map, as the `.3d` reader applies it.
    fn sdem_point(uos_cm: [f64; 3]) -> Vec3 {
        Vec3::new(uos_cm[2], -uos_cm[0], uos_cm[1]) / 100.0
    }

    /// The pose conversion agrees with converting points: for a 3DTK transform M and a point p,
    /// `convert(M) · convert(p) = convert(M · p)`.
    #[test]
    fn pose_conversion_commutes_with_point_conversion() {
        let t = [-3.1, -7.5, 156.9];
        let angles = [1.36, -30.0, -0.56];
        let pose = uos_pose_to_world_from_sensor(t, angles);
        let [ax, ay, az] = angles.map(f64::to_radians);
        let r = Rotation3::from_axis_angle(&Vector3::x_axis(), ax)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), ay)
            * Rotation3::from_axis_angle(&Vector3::z_axis(), az);
        for p in [[100.0, 0.0, 0.0], [0.0, 50.0, 0.0], [10.0, -20.0, 300.0]] {
            let p_uos = Vector3::from(p);
            let world_uos = r * p_uos + Vector3::from(t);
            let expected = sdem_point([world_uos.x, world_uos.y, world_uos.z]);
            let got = pose * nalgebra::Point3::from(sdem_point(p));
            assert!(
                (got.coords - expected).norm() < 1e-12,
                "{got:?} {expected:?}"
            );
        }
    }

    /// A rotation about 3DTK's up axis (y) is a yaw in sdem with the sign flipped: a 3DTK point
    /// to the right (x > 0) ends up at negative y.
    #[test]
    fn yaw_sign_about_the_uos_up_axis() {
        let pose = uos_pose_to_world_from_sensor([0.0, 0.0, 0.0], [0.0, 30.0, 0.0]);
        let a = attitude_of(&pose);
        assert!((a.yaw.to_degrees() + 30.0).abs() < 1e-9, "{a:?}");
        assert!(a.roll.abs() < 1e-12 && a.pitch.abs() < 1e-12);
        // The sensor's forward axis, turned towards 3DTK's right (+x), points to sdem's −y.
        let forward = pose.rotation * Vec3::x();
        assert!(forward.y < 0.0 && forward.x > 0.0, "{forward:?}");
        // A point 1 m forward of a sensor turned 90° the 3DTK way (+θy) lies at 3DTK x = +100 cm
        // (right), i.e. sdem y = −1 m.
        let pose = uos_pose_to_world_from_sensor([0.0, 0.0, 0.0], [0.0, 90.0, 0.0]);
        let p = pose * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!(
            (p.coords - Vec3::new(0.0, -1.0, 0.0)).norm() < 1e-12,
            "{p:?}"
        );
        // Translation: 3DTK (x right, y up, z forward) cm → (z, −x, y) m.
        let pose = uos_pose_to_world_from_sensor([20.0, -5.0, 150.0], [0.0; 3]);
        let t = pose.translation.vector;
        assert!((t - Vec3::new(1.5, -0.2, -0.05)).norm() < 1e-12, "{t:?}");
    }

    /// Rotations about 3DTK's x (right) and z (forward) axes: pitch and roll, signs flipped too.
    #[test]
    fn roll_and_pitch_signs() {
        // θx about 3DTK's right axis: a pitch about sdem's −y... C·Rx(θ)·Cᵀ = R(−y, −θ) = Ry(θ).
        let pose = uos_pose_to_world_from_sensor([0.0; 3], [10.0, 0.0, 0.0]);
        let a = attitude_of(&pose);
        assert!((a.pitch.to_degrees() - 10.0).abs() < 1e-9, "{a:?}");
        // Positive θx tilts 3DTK's forward (z) down (−y): sdem's forward gets z < 0, which is a
        // positive pitch in sdem (Ry(+) turns x towards −z).
        let forward = pose.rotation * Vec3::x();
        assert!(forward.z < 0.0, "{forward:?}");
        // θz about 3DTK's forward axis: C·Rz(θ)·Cᵀ = R(x, −θ), a roll of −θ.
        let pose = uos_pose_to_world_from_sensor([0.0; 3], [0.0, 0.0, 10.0]);
        let a = attitude_of(&pose);
        assert!((a.roll.to_degrees() + 10.0).abs() < 1e-9, "{a:?}");
    }

    #[test]
    fn read_pose_and_its_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(dir.path(), "a.pose", "10 20 300\n0 45 0\n\n");
        let pose = read_uos_pose(&p).unwrap();
        assert!((pose.translation.vector - Vec3::new(3.0, -0.1, 0.2)).norm() < 1e-12);
        assert!((attitude_of(&pose).yaw.to_degrees() + 45.0).abs() < 1e-9);
        let cases = [
            ("b.pose", "1 2\n0 0 0\n", "b.pose:1"),
            ("c.pose", "1 2 3\n0 x 0\n", "c.pose:2"),
            ("d.pose", "1 2 3\n0 0 nan\n", "d.pose:2"),
            ("e.pose", "1 2 3\n", "e.pose: 1 line"),
            ("f.pose", "1 2 3\n0 0 0\n1 1 1\n", "f.pose:3"),
            ("g.pose", "", "g.pose: 0 line"),
        ];
        for (name, text, want) in cases {
            let err = read_uos_pose(&write(dir.path(), name, text))
                .unwrap_err()
                .to_string();
            assert!(err.contains(want), "{name}: {err}");
        }
    }

    #[test]
    fn absurd_pose_values_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let cases = [
            ("t.pose", "1e300 0 0\n0 0 0\n", "t.pose:1", "1.000e300 cm"),
            (
                "u.pose",
                "0 -2e8 0\n0 0 0\n",
                "u.pose:1",
                "value 2 of the translation",
            ),
            ("a.pose", "0 0 0\n0 1e300 0\n", "a.pose:2", "1.000e300°"),
            (
                "f.frames",
                "1 0 0 0 0 1 0 0 0 0 1 0 0 1e300 0 1 2\n",
                "f.frames:1",
                "value 14",
            ),
        ];
        for (name, text, place, what) in cases {
            let path = write(dir.path(), name, text);
            let err = if name.ends_with(".pose") {
                read_uos_pose(&path).unwrap_err()
            } else {
                read_uos_frames_last(&path).unwrap_err()
            };
            let err = err.to_string();
            assert!(err.contains(place) && err.contains(what), "{name}: {err}");
            assert!(err.len() < 400, "{name}: {err}");
        }
        // A long survey and an unwrapped heading are still poses.
        let ok = write(dir.path(), "ok.pose", "5e7 0 -3e7\n0 -7200 0\n");
        read_uos_pose(&ok).unwrap();
    }

    fn frames_line(m: &Matrix4<f64>, flag: u32) -> String {
        let mut v: Vec<String> = m.as_slice().iter().map(|x| format!("{x}")).collect();
        v.push(flag.to_string());
        v.join(" ")
    }

    #[test]
    fn frames_last_line_column_major() {
        let dir = tempfile::tempdir().unwrap();
        // Last line: a 90° 3DTK yaw and a translation of 100 cm right, 300 cm forward.
        let mut m =
            Rotation3::from_axis_angle(&Vector3::y_axis(), 90f64.to_radians()).to_homogeneous();
        m[(0, 3)] = 100.0;
        m[(2, 3)] = 300.0;
        let text = format!(
            "{}\n{}\n",
            frames_line(&Matrix4::identity(), 2),
            frames_line(&m, 1)
        );
        // The translation is at elements 12..14 of the line (column-major).
        let values: Vec<&str> = text.lines().nth(1).unwrap().split(' ').collect();
        assert_eq!((values[12], values[14]), ("100", "300"));
        let pose = read_uos_frames_last(&write(dir.path(), "s.frames", &text)).unwrap();
        assert!((pose.translation.vector - Vec3::new(3.0, -1.0, 0.0)).norm() < 1e-12);
        assert!((attitude_of(&pose).yaw.to_degrees() + 90.0).abs() < 1e-9);

        let bad = [
            ("a.frames", "1 0 0\n", "a.frames:1"),
            (
                "b.frames",
                "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2\n2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2\n",
                "b.frames:2",
            ),
            (
                "c.frames",
                "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 x\n",
                "c.frames:1",
            ),
            (
                "d.frames",
                "1 0 0 5 0 1 0 0 0 0 1 0 0 0 0 1 2\n",
                "d.frames:1",
            ),
            ("e.frames", "\n", "e.frames"),
        ];
        for (name, text, want) in bad {
            let err = read_uos_frames_last(&write(dir.path(), name, text))
                .unwrap_err()
                .to_string();
            assert!(err.contains(want) && err.contains(name), "{name}: {err}");
        }
    }

    /// A tiny 3DTK folder: `n` scans, each with points in cm (one far sentinel, one near).
    fn uos_folder(dir: &Path, n: usize) -> PathBuf {
        let source = dir.join("uos");
        for i in 0..n {
            write(
                &source,
                &format!("scan{i:03}.3d"),
                "100 0 200\n-50 20 300\n0 0 3276\n1 1 5\n0 -30 150\n",
            );
            write(
                &source,
                &format!("scan{i:03}.pose"),
                &format!("0 0 {}\n0 {} 0\n", 150 * i, 5 * i),
            );
        }
        source
    }

    #[test]
    fn import_3dtk_writes_a_dataset() {
        let dir = tempfile::tempdir().unwrap();
        let source = uos_folder(dir.path(), 3);
        let frames = dir.path().join("frames");
        for i in 0..3 {
            let mut m = Matrix4::identity();
            m[(2, 3)] = 150.0 * i as f64 + 1.0;
            write(
                &frames,
                &format!("scan{i:03}.frames"),
                &format!(
                    "{}\n{}\n",
                    frames_line(&Matrix4::identity(), 0),
                    frames_line(&m, 1)
                ),
            );
        }
        let out = dir.path().join("ds");
        let options = ImportOptions {
            first: 1,
            count: Some(2),
            every: None,
            frames_dir: Some(frames),
        };
        let summary = import_dataset(&source, &out, None, &options).unwrap();
        assert_eq!(summary.format, ImportFormat::Uos3dtk);
        assert_eq!(summary.scans, 2);
        assert_eq!(summary.points_per_scan, vec![3, 3]);
        assert_eq!((summary.dropped_far, summary.dropped_near), (2, 2));
        assert!(summary.source_scans[0].ends_with("scan001.3d"));
        let dataset = Dataset::open(&out).unwrap();
        assert_eq!(dataset.len(), 2);
        assert_eq!(dataset.load_scan(0).unwrap()[0], Vec3::new(2.0, -1.0, 0.0));
        let odometry = dataset.odometry.unwrap();
        assert!((odometry[1].translation.vector - Vec3::new(3.0, 0.0, 0.0)).norm() < 1e-12);
        let attitudes = dataset.attitudes.unwrap();
        assert!((attitudes[1].yaw.to_degrees() + 10.0).abs() < 1e-9);
        assert!(dataset.truth.is_none());
        let slam6d = read_kitti_poses(&out.join(SLAM6D_FILE)).unwrap();
        assert!((slam6d[1].translation.vector.x - 3.01).abs() < 1e-12);
        assert!(out.join("poses_slam6d.tum").is_file() && out.join("odometry.tum").is_file());

        // Again into the same folder: refused, nothing changed.
        let err = import_3dtk(&source, &out, &ImportOptions::default())
            .unwrap_err()
            .to_string();
        assert!(err.contains("already exists"), "{err}");
        assert_eq!(Dataset::open(&out).unwrap().len(), 2);
    }

    /// A scan file of a line scanner in 3DTK's frame and centimetres, with `far` returns at
    /// 45–60 m (a real far wall) and, when `no_return`, every 40th beam at 327.67 m (a
    /// scanner's "no return" range).
    fn uos_line_scan(
        beam_step_deg: f64,
        line_step_deg: f64,
        far: usize,
        no_return: bool,
    ) -> String {
        let lines = (60.0 / line_step_deg) as usize;
        let beams = (180.0 / beam_step_deg) as usize + 1;
        let scan = crate::import::line_scanner::tests::line_scan(
            Vec3::y(),
            -30.0,
            line_step_deg,
            lines,
            beam_step_deg,
            beams,
            crate::import::line_scanner::tests::room,
        );
        let mut text = String::new();
        for (i, p) in scan.iter().enumerate() {
            let p = if i < far {
                p.normalize() * (45.0 + 0.05 * i as f64)
            } else if no_return && i % 40 == 7 {
                p.normalize() * 327.67
            } else {
                *p
            };
            // sdem (x forward, y left, z up, m) → 3DTK (x right, y up, z forward, cm).
            text += &format!("{} {} {}\n", -p.y * 100.0, p.z * 100.0, p.x * 100.0);
        }
        text
    }

    #[test]
    fn the_sensor_written_is_the_scanner_measured_and_far_returns_are_kept() {
        let dir = tempfile::tempdir().unwrap();
        let source = uos_folder(dir.path(), 2);
        // A scanner of 1° beams and 0.75° lines that reports "no return" at 327.67 m and sees
        // a wall 45–60 m away.
        for i in 0..2 {
            write(
                &source,
                &format!("scan{i:03}.3d"),
                &uos_line_scan(1.0, 0.75, 300, true),
            );
        }
        let out = dir.path().join("ds");
        let summary = import_3dtk(&source, &out, &ImportOptions::default()).unwrap();
        let sensor = crate::read_sensor_toml(&out.join(SENSOR_FILE)).unwrap();
        assert_eq!((sensor.pan_step_deg, sensor.tilt_step_deg), (1.0, 0.75));
        assert_eq!(sensor.matched_sdem_resolution_deg(), 1.0);
        // Nodded about the left axis, a line at +θ looks θ down.
        assert_eq!((sensor.tilt_min_deg, sensor.tilt_max_deg), (-29.25, 30.0));
        assert_eq!((sensor.pan_min_deg, sensor.pan_max_deg), (-90.0, 90.0));
        // The far wall is kept (the sensor's range reaches it); the "no return" beams are not.
        assert_eq!(sensor.max_range_m, 60.0);
        let beams = 181 * 80;
        let no_return = (0..beams).filter(|i| *i >= 300 && i % 40 == 7).count();
        assert_eq!(summary.dropped_far, 2 * no_return, "{summary:?}");
        assert_eq!(summary.points_per_scan, vec![beams - no_return; 2]);
        assert!(
            summary
                .no_return_from_m
                .is_some_and(|r| (327.6..327.67).contains(&r)),
            "{summary:?}"
        );
        assert!(summary.notes[0].contains("measured"), "{:?}", summary.notes);

        // Points in no scanner's order: no sensor.toml, and the note says why.
        let dir = tempfile::tempdir().unwrap();
        let source = uos_folder(dir.path(), 2);
        let in_order = uos_line_scan(0.5, 0.5, 0, false);
        let lines: Vec<&str> = in_order.lines().collect();
        let shuffled: String = (0..lines.len())
            .map(|i| format!("{}\n", lines[(i * 7919) % lines.len()]))
            .collect();
        for i in 0..2 {
            write(&source, &format!("scan{i:03}.3d"), &shuffled);
        }
        let out = dir.path().join("ds");
        let summary = import_3dtk(&source, &out, &ImportOptions::default()).unwrap();
        assert!(!out.join(SENSOR_FILE).exists());
        assert!(!summary.written.iter().any(|w| w == SENSOR_FILE));
        assert!(
            summary.notes[0].contains("no sensor.toml"),
            "{:?}",
            summary.notes
        );
        assert_eq!((summary.dropped_far, summary.no_return_from_m), (0, None));
    }

    /// 3DTK's example scans, where they lie beside the repository: 0.5° beams, 0.517° lines.
    #[test]
    fn the_example_scans_show_their_scanners_steps() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/3dtk-dat/scan000.3d");
        if !path.is_file() {
            eprintln!("skipped: no {} beside the repository", path.display());
            return;
        }
        let points = read_points(&path).unwrap();
        let steps = measure_line_scanner(&points).unwrap();
        assert!((steps.beam_step_deg - 0.5).abs() < 1e-3, "{steps:?}");
        assert!((steps.line_step_deg - 0.517).abs() < 1e-3, "{steps:?}");
        assert_eq!(steps.lines, 226);
        let from = no_return_range(&points).unwrap();
        assert!((32.74..32.76).contains(&from), "{from}");
    }

    #[test]
    fn import_3dtk_errors() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("ds");
        let opts = ImportOptions::default();
        let err = import_3dtk(&dir.path().join("none"), &out, &opts)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("none") && err.contains("does not exist"),
            "{err}"
        );
        let empty = dir.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        let err = import_3dtk(&empty, &out, &opts).unwrap_err().to_string();
        assert!(err.contains("no scans"), "{err}");
        let err = ImportFormat::detect(&empty).unwrap_err().to_string();
        assert!(err.contains("neither"), "{err}");

        let source = uos_folder(dir.path(), 2);
        std::fs::remove_file(source.join("scan001.pose")).unwrap();
        let err = import_3dtk(&source, &out, &opts).unwrap_err().to_string();
        assert!(err.contains("scan001.pose is missing"), "{err}");
        write(&source, "scan001.pose", "0 0 0\n0 0\n");
        let err = import_3dtk(&source, &out, &opts).unwrap_err().to_string();
        assert!(err.contains("scan001.pose:2"), "{err}");
        write(&source, "scan001.pose", "0 0 0\n0 0 0\n");

        // A frames folder missing one scan's file.
        let frames = dir.path().join("frames");
        write(
            &frames,
            "scan000.frames",
            "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 0\n",
        );
        let with_frames = ImportOptions {
            frames_dir: Some(frames.clone()),
            ..Default::default()
        };
        let err = import_3dtk(&source, &out, &with_frames)
            .unwrap_err()
            .to_string();
        assert!(err.contains("scan001.frames is missing"), "{err}");
        write(
            &frames,
            "scan001.frames",
            "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 0\n1 2\n",
        );
        let err = import_3dtk(&source, &out, &with_frames)
            .unwrap_err()
            .to_string();
        assert!(err.contains("scan001.frames:2"), "{err}");

        // Selection errors.
        let err = import_3dtk(
            &source,
            &out,
            &ImportOptions {
                first: 5,
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("no scan numbered 5"), "{err}");
        let err = import_3dtk(
            &source,
            &out,
            &ImportOptions {
                count: Some(3),
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("3 scans asked"), "{err}");

        // A malformed .3d is found while writing: what was written is removed.
        write(&source, "scan001.3d", "1 2 3\n1 2\n");
        let err = import_3dtk(&source, &out, &opts).unwrap_err().to_string();
        assert!(err.contains("scan001.3d:2"), "{err}");
        assert!(!out.exists(), "a failed import left {}", out.display());
        // A scan with only filtered points.
        write(&source, "scan001.3d", "1 2 3\n0 0 5000\n");
        let err = import_3dtk(&source, &out, &opts).unwrap_err().to_string();
        assert!(
            err.contains("scan001.3d") && err.contains("no point"),
            "{err}"
        );
        assert!(!out.exists());
        assert!(nothing_left(dir.path()));
    }

    #[test]
    fn a_gap_in_the_scan_numbers_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let source = uos_folder(dir.path(), 4);
        std::fs::remove_file(source.join("scan001.3d")).unwrap();
        std::fs::remove_file(source.join("scan002.3d")).unwrap();
        let out = dir.path().join("ds");
        let err = import_3dtk(&source, &out, &ImportOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("scan001.3d is missing")
                && err.contains("2 scan(s) missing")
                && err.contains("scan003.3d")
                && err.contains("--first"),
            "{err}"
        );
        assert!(!out.exists());
        // A selection on one side of the gap is imported.
        let options = ImportOptions {
            first: 3,
            ..Default::default()
        };
        assert_eq!(import_3dtk(&source, &out, &options).unwrap().scans, 1);
    }

    #[test]
    fn every_kth_scan_is_imported_and_a_missing_one_among_them_named() {
        let dir = tempfile::tempdir().unwrap();
        let source = uos_folder(dir.path(), 7);
        // scan003 missing does not matter to every second scan from 0, and is a gap from 1.
        std::fs::remove_file(source.join("scan003.3d")).unwrap();
        let every = |first| ImportOptions {
            first,
            every: Some(2),
            ..Default::default()
        };
        let out = dir.path().join("even");
        let summary = import_3dtk(&source, &out, &every(0)).unwrap();
        assert_eq!(summary.scans, 4);
        assert!(summary.source_scans[3].ends_with("scan006.3d"));
        // Its odometry is each scan's own pose: 3 m from scan 0 to scan 2 (1.5 m a scan).
        let odometry = crate::read_kitti_poses(&out.join(crate::ODOMETRY_FILE)).unwrap();
        assert!((odometry[1].translation.vector.norm() - 3.0).abs() < 1e-9);
        let err = import_3dtk(&source, &dir.path().join("odd"), &every(1))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("scan003.3d is missing") && err.contains("scan005.3d"),
            "{err}"
        );
    }

    /// No temporary file is left anywhere under `dir`.
    fn nothing_left(dir: &Path) -> bool {
        std::fs::read_dir(dir).unwrap().all(|e| {
            let e = e.unwrap();
            let name = e.file_name().into_string().unwrap();
            !name.contains(".tmp-") && (!e.path().is_dir() || nothing_left(&e.path()))
        })
    }
}
