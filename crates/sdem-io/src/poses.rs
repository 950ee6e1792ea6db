//! Pose files: KITTI (row-major 3×4 `[R | t]` per line) and TUM (`t x y z qx qy qz qw`).

use super::{fmt_f64, fmt_msg, numbered_lines, parse_finite, read_text, write_atomic};
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion};
use sdem::geometry::Pose;
use std::path::Path;

/// How far from a rotation a 3×3 block read from a file (KITTI poses and calibration, 3DTK
/// poses and frames) may be before it is rejected (determinant and the entries of `RᵀR − I`).
/// KITTI's own files carry 7 significant digits, ~1e-6 off.
const ROTATION_TOLERANCE: f64 = 1e-3;

/// How far from 1 a TUM quaternion's norm may be before it is rejected.
const QUATERNION_TOLERANCE: f64 = 1e-3;

fn check_poses_writable(path: &Path, poses: &[Pose]) -> Result<()> {
    for (i, pose) in poses.iter().enumerate() {
        let finite = pose.translation.vector.iter().all(|v| v.is_finite())
            && pose.rotation.coords.iter().all(|v| v.is_finite());
        if !finite {
            return Err(Error::Invalid(format!(
                "refusing to write {}: pose {i} has a non-finite value",
                path.display()
            )));
        }
    }
    Ok(())
}

/// Writes poses in the KITTI format: one line per pose, the 12 numbers of the row-major 3×4
/// matrix `[R | t]` of `world_from_sensor`, written so that they read back bit-for-bit.
/// See [`write_poses`] for the KITTI + TUM pair that DESIGN.md asks for.
pub fn write_kitti_poses(path: &Path, world_from_sensor: &[Pose]) -> Result<()> {
    check_poses_writable(path, world_from_sensor)?;
    write_atomic(path, |w| {
        for pose in world_from_sensor {
            let m = pose.to_homogeneous();
            let mut values = Vec::with_capacity(12);
            for row in 0..3 {
                for col in 0..4 {
                    values.push(fmt_f64(m[(row, col)]));
                }
            }
            writeln!(w, "{}", values.join(" "))?;
        }
        Ok(())
    })
}

/// Reads a KITTI pose file: one `world_from_sensor` per line as 12 numbers (row-major 3×4
/// `[R | t]`). Blank lines are skipped. Each `R` must be a rotation to within 1e-3 (determinant
/// and `RᵀR`) and is re-orthonormalized; a wrong number count, a non-number, a non-finite value
/// or a non-rotation is an error naming the line. A file without poses is an error.
pub fn read_kitti_poses(path: &Path) -> Result<Vec<Pose>> {
    let text = read_text(path)?;
    let mut poses = Vec::new();
    for (line_no, line) in numbered_lines(&text) {
        if line.trim().is_empty() {
            continue;
        }
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.len() != 12 {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "{} numbers on this line; a KITTI pose is 12 numbers, the row-major 3×4 [R | t]",
                    tokens.len()
                ),
            ));
        }
        poses.push(parse_row_major_pose(path, line_no, &tokens, "")?);
    }
    if poses.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file holds no poses; expected one line of 12 numbers per pose",
        ));
    }
    Ok(poses)
}

/// Parses 12 tokens at `line_no` of `path` as a row-major 3×4 `[R | t]`, checking that the
/// numbers are finite and that `R` is a rotation (to within [`ROTATION_TOLERANCE`], then
/// re-orthonormalized). `what` names the matrix in messages (`"Tr"`, or `""` for a pose line).
pub(super) fn parse_row_major_pose(
    path: &Path,
    line_no: usize,
    tokens: &[&str],
    what: &str,
) -> Result<Pose> {
    let of = if what.is_empty() {
        String::new()
    } else {
        format!(" of {what}")
    };
    let mut v = [0f64; 12];
    for (k, (slot, token)) in v.iter_mut().zip(tokens).enumerate() {
        *slot = parse_finite(path, line_no, token, &format!("value {}{of}", k + 1))?;
    }
    let r = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
    let rotation = to_rotation(&r).map_err(|why| {
        Error::parse(
            path,
            Some(line_no),
            format!("the 3×3 block{of} is not a rotation: {why}"),
        )
    })?;
    Ok(Pose::from_parts(
        Translation3::new(v[3], v[7], v[11]),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}

/// Checks that `r` is near a rotation (determinant and `RᵀR − I` within [`ROTATION_TOLERANCE`])
/// and returns the nearest one (polar decomposition).
pub(super) fn to_rotation(r: &Matrix3<f64>) -> std::result::Result<Rotation3<f64>, String> {
    let det = r.determinant();
    if !det.is_finite() || (det - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(format!("its determinant is {}, not 1", fmt_msg(det)));
    }
    let off = (r.transpose() * r - Matrix3::identity()).abs().max();
    if off > ROTATION_TOLERANCE {
        return Err(format!(
            "RᵀR differs from the identity by up to {}",
            fmt_msg(off)
        ));
    }
    let svd = r.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err("its singular value decomposition failed".into());
    };
    let mut nearest = u * v_t;
    if nearest.determinant() < 0.0 {
        // Cannot happen when det(r) ≈ 1, kept for safety.
        return Err("it is a reflection".into());
    }
    // One Newton step of the polar iteration removes SVD round-off.
    nearest = 0.5 * (nearest + nearest.transpose().try_inverse().unwrap_or(nearest));
    Ok(Rotation3::from_matrix_unchecked(nearest))
}

/// Writes poses in the TUM format, `index x y z qx qy qz qw` per line, with the scan index as
/// the timestamp (evo reads it as seconds).
pub fn write_tum_poses(path: &Path, world_from_sensor: &[Pose]) -> Result<()> {
    check_poses_writable(path, world_from_sensor)?;
    write_atomic(path, |w| {
        for (index, pose) in world_from_sensor.iter().enumerate() {
            let t = pose.translation.vector;
            let q = pose.rotation.coords; // x, y, z, w
            writeln!(
                w,
                "{index} {} {} {} {} {} {} {}",
                fmt_f64(t.x),
                fmt_f64(t.y),
                fmt_f64(t.z),
                fmt_f64(q.x),
                fmt_f64(q.y),
                fmt_f64(q.z),
                fmt_f64(q.w)
            )?;
        }
        Ok(())
    })
}

/// Reads a TUM pose file: `timestamp x y z qx qy qz qw` per line; blank lines and lines starting
/// with `#` are skipped. Returns `(timestamp, world_from_sensor)` pairs in file order. The
/// quaternion's norm must be within 1e-3 of 1 (it is then normalized); a wrong number count, a
/// non-number or a non-finite value is an error naming the line. A file without poses is an
/// error.
pub fn read_tum_poses(path: &Path) -> Result<Vec<(f64, Pose)>> {
    let text = read_text(path)?;
    let mut poses = Vec::new();
    for (line_no, line) in numbered_lines(&text) {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let tokens: Vec<&str> = line.split_whitespace().collect();
        let [t, x, y, z, qx, qy, qz, qw] = tokens.as_slice() else {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "{} numbers on this line; a TUM pose is 8: timestamp x y z qx qy qz qw",
                    tokens.len()
                ),
            ));
        };
        let num = |token: &str, what: &str| parse_finite(path, line_no, token, what);
        let timestamp = num(t, "timestamp")?;
        let translation = Translation3::new(num(x, "x")?, num(y, "y")?, num(z, "z")?);
        let q = Quaternion::new(
            num(qw, "qw")?,
            num(qx, "qx")?,
            num(qy, "qy")?,
            num(qz, "qz")?,
        );
        let norm = q.norm();
        if (norm - 1.0).abs() > QUATERNION_TOLERANCE {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "the quaternion's norm is {}, not 1; it is not a rotation",
                    fmt_msg(norm)
                ),
            ));
        }
        poses.push((
            timestamp,
            Pose::from_parts(translation, UnitQuaternion::from_quaternion(q)),
        ));
    }
    if poses.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file holds no poses; expected lines 'timestamp x y z qx qy qz qw'",
        ));
    }
    Ok(poses)
}

/// Writes the KITTI file `kitti_path` and, beside it, the same poses as TUM with the extension
/// `.tum` (DESIGN.md: evo reads both).
///
/// # Example
/// ```
/// # let dir = std::env::temp_dir().join(format!("sdem-doc-poses-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// use sdem::geometry::{pose_from_parts, Attitude, Vec3};
/// let poses = vec![pose_from_parts(Vec3::new(1.0, 2.0, 0.1), Attitude::from_degrees(1.0, 2.0, 30.0))];
/// sdem_io::write_poses(&dir.join("poses.txt"), &poses).unwrap();
/// assert_eq!(sdem_io::read_kitti_poses(&dir.join("poses.txt")).unwrap().len(), 1);
/// assert_eq!(sdem_io::read_tum_poses(&dir.join("poses.tum")).unwrap().len(), 1);
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn write_poses(kitti_path: &Path, world_from_sensor: &[Pose]) -> Result<()> {
    if kitti_path.extension().is_some_and(|e| e == "tum") {
        return Err(Error::Invalid(format!(
            "{}: the KITTI pose file must not have the extension .tum, which its TUM twin takes",
            kitti_path.display()
        )));
    }
    write_kitti_poses(kitti_path, world_from_sensor)?;
    write_tum_poses(&kitti_path.with_extension("tum"), world_from_sensor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sdem::geometry::{pose_error, pose_from_parts, Attitude, Vec3};
    use std::path::PathBuf;

    fn sample_poses() -> Vec<Pose> {
        (0..20)
            .map(|i| {
                let t = i as f64;
                pose_from_parts(
                    Vec3::new(0.3 * t, -1.7 + 0.01 * t, 1e-7 * t),
                    Attitude::from_degrees(3.0 * t.sin(), -8.0 + t, 170.0 - 17.0 * t),
                )
            })
            .collect()
    }

    fn assert_same(a: &[Pose], b: &[Pose]) {
        assert_eq!(a.len(), b.len());
        for (p, q) in a.iter().zip(b) {
            let (dt, dr) = pose_error(p, q);
            assert!(dt < 1e-9 && dr < 1e-9, "{dt} {dr}");
        }
    }

    fn write(dir: &Path, name: &str, content: &str) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, content).unwrap();
        path
    }

    #[test]
    fn kitti_and_tum_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let poses = sample_poses();
        let kitti = dir.path().join("poses.txt");
        write_poses(&kitti, &poses).unwrap();
        assert_same(&poses, &read_kitti_poses(&kitti).unwrap());
        let tum = read_tum_poses(&dir.path().join("poses.tum")).unwrap();
        assert_eq!(
            tum.iter().map(|(t, _)| *t).collect::<Vec<_>>(),
            (0..20).map(f64::from).collect::<Vec<_>>()
        );
        let tum: Vec<Pose> = tum.into_iter().map(|(_, p)| p).collect();
        assert_same(&poses, &tum);
        assert!(write_poses(&dir.path().join("x.tum"), &poses).is_err());
    }

    #[test]
    fn reads_real_kitti_precision_and_reorthonormalizes() {
        let dir = tempfile::tempdir().unwrap();
        // Two lines of KITTI odometry sequence 00 ground truth (7 significant digits).
        let path = write(
            dir.path(),
            "00.txt",
            "1.000000e+00 9.043680e-12 2.326809e-11 5.551115e-17 9.043683e-12 1.000000e+00 2.392370e-10 3.330669e-16 2.326810e-11 2.392370e-10 9.999999e-01 -4.440892e-16\n\
             9.999978e-01 5.272628e-04 -2.066935e-03 -4.690294e-02 -5.296506e-04 9.999992e-01 -1.154865e-03 -2.839928e-02 2.066324e-03 1.155958e-03 9.999971e-01 8.586941e-01\n\n",
        );
        let poses = read_kitti_poses(&path).unwrap();
        assert_eq!(poses.len(), 2);
        let r = poses[1].rotation.to_rotation_matrix().into_inner();
        assert!((r.transpose() * r - Matrix3::identity()).abs().max() < 1e-12);
        assert!((poses[1].translation.vector.z - 0.8586941).abs() < 1e-12);
    }

    fn expect_err(name: &str, content: &str, line: Option<usize>, tum: bool) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), name, content);
        let err = if tum {
            read_tum_poses(&path).map(|_| ()).unwrap_err()
        } else {
            read_kitti_poses(&path).map(|_| ()).unwrap_err()
        };
        let msg = err.to_string();
        assert!(matches!(err, Error::Parse { .. }), "{msg}");
        assert!(msg.contains(name), "{msg}");
        if let Some(line) = line {
            assert!(msg.contains(&format!("{name}:{line}:")), "{msg}");
        }
        msg
    }

    #[test]
    fn malformed_kitti() {
        let id = "1 0 0 0 0 1 0 0 0 0 1 0\n";
        expect_err("k.txt", "", None, false);
        expect_err("k.txt", "\n\n", None, false);
        expect_err(
            "k.txt",
            &format!("{id}1 0 0 0 0 1 0 0 0 0 1\n"),
            Some(2),
            false,
        );
        expect_err(
            "k.txt",
            &format!("{id}1 0 0 0 0 1 0 0 0 0 1 0 0\n"),
            Some(2),
            false,
        );
        expect_err(
            "k.txt",
            &format!("{id}1 0 0 x 0 1 0 0 0 0 1 0\n"),
            Some(2),
            false,
        );
        expect_err(
            "k.txt",
            &format!("{id}1 0 0 nan 0 1 0 0 0 0 1 0\n"),
            Some(2),
            false,
        );
        expect_err(
            "k.txt",
            &format!("{id}1 0 0 0 0 1 0 inf 0 0 1 0\n"),
            Some(2),
            false,
        );
        // Scaled, sheared and reflected blocks are not rotations.
        let msg = expect_err(
            "k.txt",
            &format!("{id}2 0 0 0 0 1 0 0 0 0 1 0\n"),
            Some(2),
            false,
        );
        assert!(msg.contains("rotation"), "{msg}");
        expect_err(
            "k.txt",
            &format!("{id}1 0.1 0 0 0 1 0 0 0 0 1 0\n"),
            Some(2),
            false,
        );
        expect_err(
            "k.txt",
            &format!("{id}-1 0 0 0 0 1 0 0 0 0 1 0\n"),
            Some(2),
            false,
        );
        expect_err(
            "k.txt",
            &format!("{id}0 0 0 0 0 0 0 0 0 0 0 0\n"),
            Some(2),
            false,
        );
    }

    #[test]
    fn malformed_tum() {
        let ok = "0 1 2 3 0 0 0 1\n";
        expect_err("p.tum", "", None, true);
        expect_err("p.tum", "# only a comment\n", None, true);
        expect_err("p.tum", &format!("{ok}1 1 2 3 0 0 0\n"), Some(2), true);
        expect_err("p.tum", &format!("{ok}1 1 2 3 0 0 0 1 9\n"), Some(2), true);
        expect_err("p.tum", &format!("{ok}1 1 two 3 0 0 0 1\n"), Some(2), true);
        expect_err("p.tum", &format!("{ok}1 1 2 3 0 0 0 nan\n"), Some(2), true);
        expect_err("p.tum", &format!("{ok}1 1 2 3 0 0 0 2\n"), Some(2), true);
        expect_err("p.tum", &format!("{ok}1 1 2 3 0 0 0 0\n"), Some(2), true);
    }

    #[test]
    fn writers_reject_non_finite_poses() {
        let dir = tempfile::tempdir().unwrap();
        let bad = pose_from_parts(Vec3::new(f64::NAN, 0.0, 0.0), Attitude::default());
        assert!(matches!(
            write_kitti_poses(&dir.path().join("a.txt"), &[bad]),
            Err(Error::Invalid(_))
        ));
        assert!(matches!(
            write_tum_poses(&dir.path().join("a.tum"), &[bad]),
            Err(Error::Invalid(_))
        ));
    }
}
