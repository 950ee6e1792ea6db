//! KITTI odometry sequences (`velodyne/NNNNNN.bin`, `poses.txt`, `calib.txt`, [`import_kitti`]).
//!
//! The Velodyne frame is already sdem's (x forward, y left, z up, metres): the selected `.bin`
//! files are checked and copied unchanged to `scans/000000.bin`, …. KITTI's `poses.txt` holds the
//! poses `P_i` of the left camera (x right, y down, z forward), so the Velodyne poses are
//! `T_velo_i = Tr⁻¹ · P_i · Tr` with `Tr` the `Tr:` line of `calib.txt` (velodyne → camera), then
//! re-based so that the first imported scan is the identity (DESIGN.md: the world origin is the
//! first scan's sensor), and written as `poses_truth.txt` (KITTI's GPS/INS ground truth). KITTI
//! has no gyro/compass reading here, so no `attitude.csv` is written. Without `poses.txt` (the
//! test sequences 11–21) the scans are imported without truth.

use super::{
    check_out, check_source, numbered_files, scan_name, select, write_or_roll_back, ImportFormat,
    ImportOptions, ImportSummary,
};
use crate::dataset::check_no_stale_file;
use crate::error::{Error, Result};
use crate::poses::parse_row_major_pose;
use crate::{
    numbered_lines, read_bytes, read_kitti_poses, read_points, read_text, write_atomic,
    write_poses, SCANS_DIR, TRUTH_FILE,
};
use sdem::geometry::Pose;
use std::path::Path;

/// Parses the `Tr:` line of a KITTI `calib.txt` (the row-major 3×4 `camera_from_velodyne`;
/// `Tr_velo_to_cam:` is accepted too) from `text`, which was read from `path`.
///
/// # Errors
/// [`Error::Parse`] naming the line for a wrong number count, a non-number or a non-rotation;
/// naming the file when there is no such line.
pub fn parse_kitti_calib_tr(path: &Path, text: &str) -> Result<Pose> {
    for (line_no, line) in numbered_lines(text) {
        let Some((key, rest)) = line.split_once(':') else {
            continue;
        };
        if !matches!(key.trim(), "Tr" | "Tr_velo_to_cam") {
            continue;
        }
        let tokens: Vec<&str> = rest.split_whitespace().collect();
        if tokens.len() != 12 {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!(
                    "{} numbers after '{}:'; Tr is 12 numbers, the row-major 3×4 [R | t] from \
                     velodyne to camera",
                    tokens.len(),
                    key.trim()
                ),
            ));
        }
        return parse_row_major_pose(path, line_no, &tokens, "Tr");
    }
    Err(Error::parse(
        path,
        None,
        "no 'Tr:' line (the velodyne-to-camera transform, 12 numbers); KITTI odometry's \
         calib.txt has one",
    ))
}

/// Reads the `Tr:` line of a KITTI `calib.txt` ([`parse_kitti_calib_tr`]).
pub fn read_kitti_calib_tr(path: &Path) -> Result<Pose> {
    let text = read_text(path)?;
    parse_kitti_calib_tr(path, &text)
}

/// KITTI camera poses to Velodyne poses re-based on the first: with
/// `T_velo_i = Tr⁻¹ · P_i · Tr`, returns `T_velo_0⁻¹ · T_velo_i` for each `i`, so the first
/// is the identity.
///
/// # Arguments
/// * `camera_poses` — `P_i`, the left camera's pose in `poses.txt` (camera 0 of frame 0 as world).
/// * `camera_from_velodyne` — `Tr` from `calib.txt`.
///
/// # Example
/// ```
/// use sdem::geometry::Pose;
/// // Camera axes: x right, y down, z forward. A camera that moved 1 m forward (its z)...
/// let tr = Pose::from_parts(
///     nalgebra::Translation3::identity(),
///     nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(
///         nalgebra::Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0),
///     )),
/// );
/// let cams = [Pose::identity(), Pose::translation(0.0, 0.0, 1.0)];
/// let velo = sdem_io::kitti_velodyne_poses(&cams, &tr);
/// // ...moved 1 m along the Velodyne's x (forward).
/// assert!((velo[1].translation.vector - nalgebra::Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
/// ```
pub fn kitti_velodyne_poses(camera_poses: &[Pose], camera_from_velodyne: &Pose) -> Vec<Pose> {
    let tr = camera_from_velodyne;
    let velo: Vec<Pose> = camera_poses.iter().map(|p| tr.inverse() * p * tr).collect();
    let Some(first) = velo.first() else {
        return Vec::new();
    };
    let first_inv = first.inverse();
    let mut rebased: Vec<Pose> = velo.iter().map(|v| first_inv * v).collect();
    // Exactly the identity, not the identity up to round-off.
    rebased[0] = Pose::identity();
    rebased
}

/// Imports a KITTI odometry sequence folder into the dataset folder `out` (see the module
/// documentation): `scans/NNNNNN.bin` copied unchanged and, when `poses.txt` is present,
/// `poses_truth.txt` (+ `.tum`) with the Velodyne poses re-based on the first imported scan. No
/// `attitude.csv` is written.
///
/// Poses and calibration are read and checked before anything is written; an error while
/// writing removes what was written.
///
/// # Errors
/// `source` missing or without `velodyne/NNNNNN.bin`; `poses.txt` present but `calib.txt`
/// missing; a malformed `poses.txt` or `calib.txt` (naming the file and line); fewer poses than
/// a selected scan's number needs; a malformed `.bin`; `out` holding a dataset entry.
pub fn import_kitti(source: &Path, out: &Path, options: &ImportOptions) -> Result<ImportSummary> {
    check_source(source)?;
    let velodyne = source.join("velodyne");
    if !velodyne.is_dir() {
        return Err(Error::Invalid(format!(
            "{} has no velodyne/ folder; a KITTI sequence holds velodyne/NNNNNN.bin",
            source.display()
        )));
    }
    let scans = select(
        numbered_files(&velodyne, "", "bin")?,
        options,
        &velodyne,
        "KITTI NNNNNN.bin files",
    )?;
    let poses_path = source.join("poses.txt");
    let truth = if poses_path.is_file() {
        let calib_path = source.join("calib.txt");
        if !calib_path.is_file() {
            return Err(Error::Invalid(format!(
                "{} is missing; it holds Tr, which turns the camera poses of {} into Velodyne poses",
                calib_path.display(),
                poses_path.display()
            )));
        }
        let tr = read_kitti_calib_tr(&calib_path)?;
        let camera_poses = read_kitti_poses(&poses_path)?;
        let mut selected = Vec::with_capacity(scans.len());
        for (number, scan) in &scans {
            let pose = camera_poses.get(*number).ok_or_else(|| {
                Error::Invalid(format!(
                    "{} has {} poses but {} needs pose {} (line {})",
                    poses_path.display(),
                    camera_poses.len(),
                    scan.display(),
                    number,
                    number + 1
                ))
            })?;
            selected.push(*pose);
        }
        Some(kitti_velodyne_poses(&selected, &tr))
    } else {
        None
    };
    check_out(out)?;
    if truth.is_none() {
        check_no_stale_file(out, TRUTH_FILE, "truth")?;
    }

    let mut summary = ImportSummary::empty(ImportFormat::Kitti, source, out, &scans);
    write_or_roll_back(out, || {
        for (index, (_, scan)) in scans.iter().enumerate() {
            let points = read_points(scan)?.len();
            let bytes = read_bytes(scan)?;
            let target = out.join(SCANS_DIR).join(scan_name(index, "bin"));
            write_atomic(&target, |w| w.write_all(&bytes))?;
            summary.points_per_scan.push(points);
        }
        summary
            .written
            .push(format!("{SCANS_DIR}/ ({} .bin)", scans.len()));
        if let Some(truth) = &truth {
            write_poses(&out.join(TRUTH_FILE), truth)?;
            summary.written.push(TRUTH_FILE.into());
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
    use crate::Dataset;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use sdem::geometry::{attitude_of, pose_error, Vec3};
    use std::path::PathBuf;

    #[test]
    fn kitti_calib_and_velodyne_poses() {
        let dir = tempfile::tempdir().unwrap();
        // Tr: velodyne (x fwd, y left, z up) → camera (x right, y down, z fwd), plus an offset.
        let calib = "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n\
                     Tr: 0 -1 0 0.1 0 0 -1 -0.05 1 0 0 -0.3\n";
        let path = write(dir.path(), "calib.txt", calib);
        let tr = read_kitti_calib_tr(&path).unwrap();
        assert!((tr * nalgebra::Point3::new(1.0, 0.0, 0.0)).coords.z > 0.0);
        // The camera moves 1 m forward per frame and turns 10° left (about its −y, i.e. up).
        let step = Pose::from_parts(
            Translation3::new(0.0, 0.0, 1.0),
            UnitQuaternion::from_axis_angle(&-Vector3::y_axis(), 10f64.to_radians()),
        );
        let cams: Vec<Pose> = (0..4)
            .scan(Pose::identity(), |p, _| {
                let now = *p;
                *p *= step;
                Some(now)
            })
            .collect();
        let velo = kitti_velodyne_poses(&cams[1..], &tr);
        assert_eq!(velo.len(), 3);
        let (dt, dr) = pose_error(&Pose::identity(), &velo[0]);
        assert!(dt < 1e-12 && dr < 1e-12);
        // In the Velodyne frame each step turns +10° (yaw, left) and goes forward.
        let rel = velo[0].inverse() * velo[1];
        assert!((attitude_of(&rel).yaw.to_degrees() - 10.0).abs() < 1e-9);
        assert!(rel.translation.vector.x > 0.9);

        for (name, text, want) in [
            ("c1.txt", "P0: 1 0 0\n", "c1.txt: no 'Tr:'"),
            ("c2.txt", "P0: 1\nTr: 1 0 0 0 0 1 0 0 0 0 1\n", "c2.txt:2"),
            ("c3.txt", "Tr: 1 0 0 0 0 1 0 0 0 0 1 z\n", "c3.txt:1"),
            ("c4.txt", "Tr: 2 0 0 0 0 1 0 0 0 0 1 0\n", "c4.txt:1"),
        ] {
            let err = read_kitti_calib_tr(&write(dir.path(), name, text))
                .unwrap_err()
                .to_string();
            assert!(err.contains(want), "{name}: {err}");
        }
    }

    fn kitti_folder(dir: &Path, n: usize) -> PathBuf {
        let source = dir.join("kitti");
        std::fs::create_dir_all(source.join("velodyne")).unwrap();
        for i in 0..n {
            let bytes: Vec<u8> = [[1.0f32 + i as f32, 2.0, 3.0, 0.5], [4.0, 5.0, 6.0, 0.1]]
                .iter()
                .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
                .collect();
            std::fs::write(source.join(format!("velodyne/{i:06}.bin")), bytes).unwrap();
        }
        // Camera 0 moves 0.8 m forward (its z) per frame.
        let poses: String = (0..n)
            .map(|i| format!("1 0 0 0 0 1 0 0 0 0 1 {}\n", 0.8 * i as f64))
            .collect();
        write(&source, "poses.txt", &poses);
        write(
            &source,
            "calib.txt",
            "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: 0 -1 0 0 0 0 -1 0 1 0 0 -0.27\n",
        );
        source
    }

    #[test]
    fn import_kitti_writes_a_dataset() {
        let dir = tempfile::tempdir().unwrap();
        let source = kitti_folder(dir.path(), 5);
        let out = dir.path().join("ds");
        let options = ImportOptions {
            first: 2,
            count: Some(2),
            every: None,
            frames_dir: None,
        };
        let summary = import_dataset(&source, &out, None, &options).unwrap();
        assert_eq!(summary.format, ImportFormat::Kitti);
        assert_eq!(summary.points_per_scan, vec![2, 2]);
        let dataset = Dataset::open(&out).unwrap();
        assert!(dataset.attitudes.is_none() && dataset.odometry.is_none());
        assert_eq!(dataset.scan_paths[0], out.join("scans/000000.bin"));
        assert_eq!(
            std::fs::read(&dataset.scan_paths[1]).unwrap(),
            std::fs::read(source.join("velodyne/000003.bin")).unwrap()
        );
        let truth = dataset.truth.unwrap();
        let (dt, dr) = pose_error(&Pose::identity(), &truth[0]);
        assert!(dt < 1e-12 && dr < 1e-12);
        assert!((truth[1].translation.vector - Vec3::new(0.8, 0.0, 0.0)).norm() < 1e-9);

        // Every second frame from frame 1 on: frames 1 and 3, the truth 1.6 m apart.
        let thinned = dir.path().join("thinned");
        let every = ImportOptions {
            first: 1,
            every: Some(2),
            ..Default::default()
        };
        let summary = import_dataset(&source, &thinned, None, &every).unwrap();
        assert_eq!(summary.scans, 2);
        assert!(summary.source_scans[1].ends_with("000003.bin"));
        let truth = Dataset::open(&thinned).unwrap().truth.unwrap();
        assert!((truth[1].translation.vector - Vec3::new(1.6, 0.0, 0.0)).norm() < 1e-9);
        // Three of them are more than the folder holds; a stride of 0 is refused.
        for (options, want) in [
            (
                ImportOptions {
                    count: Some(3),
                    ..every.clone()
                },
                "3 scans asked from number 1 on with a stride of 2",
            ),
            (
                ImportOptions {
                    every: Some(0),
                    ..Default::default()
                },
                "at least 1",
            ),
        ] {
            let err = import_dataset(&source, &dir.path().join("no"), None, &options)
                .unwrap_err()
                .to_string();
            assert!(err.contains(want), "{err}");
        }

        // Without poses.txt: no truth.
        let out2 = dir.path().join("ds2");
        std::fs::remove_file(source.join("poses.txt")).unwrap();
        import_kitti(&source, &out2, &ImportOptions::default()).unwrap();
        let dataset = Dataset::open(&out2).unwrap();
        assert_eq!(dataset.len(), 5);
        assert!(dataset.truth.is_none());
    }

    #[test]
    fn import_kitti_errors() {
        let dir = tempfile::tempdir().unwrap();
        let source = kitti_folder(dir.path(), 3);
        let out = dir.path().join("ds");
        let opts = ImportOptions::default();
        let err = import_dataset(
            &source,
            &out,
            None,
            &ImportOptions {
                frames_dir: Some(dir.path().into()),
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("3DTK imports only"), "{err}");
        write(&source, "poses.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0\n");
        let err = import_kitti(&source, &out, &opts).unwrap_err().to_string();
        assert!(err.contains("poses.txt:2"), "{err}");
        write(&source, "poses.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
        let err = import_kitti(&source, &out, &opts).unwrap_err().to_string();
        assert!(
            err.contains("1 poses") && err.contains("000001.bin"),
            "{err}"
        );
        write(&source, "poses.txt", &"1 0 0 0 0 1 0 0 0 0 1 0\n".repeat(3));
        write(&source, "calib.txt", "Tr: 1 0 0\n");
        let err = import_kitti(&source, &out, &opts).unwrap_err().to_string();
        assert!(err.contains("calib.txt:1"), "{err}");
        std::fs::remove_file(source.join("calib.txt")).unwrap();
        let err = import_kitti(&source, &out, &opts).unwrap_err().to_string();
        assert!(err.contains("calib.txt is missing"), "{err}");
        write(&source, "calib.txt", "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n");
        std::fs::write(source.join("velodyne/000002.bin"), [0u8; 7]).unwrap();
        let err = import_kitti(&source, &out, &opts).unwrap_err().to_string();
        assert!(err.contains("000002.bin"), "{err}");
        assert!(!out.exists());
        for i in 0..3 {
            std::fs::remove_file(source.join(format!("velodyne/{i:06}.bin"))).unwrap();
        }
        let err = import_kitti(&source, &out, &opts).unwrap_err().to_string();
        assert!(err.contains("no scans"), "{err}");
    }
}
