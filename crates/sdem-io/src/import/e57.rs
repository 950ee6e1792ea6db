//! E57 surveys (one `.e57` file of several scans, [`import_e57`]).
//!
//! Each scan of the survey ([`crate::read_e57`]: its points in its own frame, invalid points
//! dropped) becomes `scans/000000.ply`, … (binary PLY, in the file's order; `first` and `count`
//! select by that order, from 0), read and written one at a time so that a survey larger than
//! memory imports. A scan with no valid point is skipped and the summary says so.
//!
//! A registered pose is a surveyor's (or a robot's) estimate, not ground truth: when every
//! imported scan has one, the poses become `odometry.txt`, a prior of which sdem uses only the
//! motion between consecutive scans, and their roll, pitch and yaw become `attitude.csv` (a
//! terrestrial scanner levels itself, so the survey's frame is gravity-aligned). The translations
//! are re-based on the first imported scan's (georeferenced surveys sit hundreds of kilometres
//! from their origin); rotations are kept, so the attitude keeps its roll and pitch. When some
//! scan has no pose, neither file is written (sdem then searches each scan's attitude) and the
//! summary says why. Nothing becomes `poses_truth.txt`.

use super::{check_out, scan_name, write_or_roll_back, ImportFormat, ImportOptions, ImportSummary};
use crate::dataset::ODOMETRY_FILE;
use crate::error::{Error, Result};
use crate::{
    for_each_e57_scan, write_attitude_csv, write_points_ply, write_poses, E57Scan, ATTITUDE_FILE,
    SCANS_DIR,
};
use nalgebra::Translation3;
use sdem::geometry::{attitude_of, Pose};
use std::path::{Path, PathBuf};

/// Imports the E57 survey `source` into the dataset folder `out` (see the module documentation).
///
/// # Errors
/// [`Error::Invalid`] when `out` already holds a dataset, the selection is empty or every
/// selected scan is empty; the errors of [`crate::read_e57`] for a malformed survey; on any
/// error, what was written is removed.
pub fn import_e57(source: &Path, out: &Path, options: &ImportOptions) -> Result<ImportSummary> {
    check_out(out)?;
    if let Some(frames) = &options.frames_dir {
        return Err(Error::Invalid(format!(
            "a frames folder ({}) is for 3DTK imports only; {} is an E57 survey",
            frames.display(),
            source.display()
        )));
    }
    // The survey's size from its metadata alone, then one scan at a time.
    let total = for_each_e57_scan(source, |_| false, |_, _| Ok(()))?;
    let selected = selection(total, options, source)?;
    let mut summary = ImportSummary::empty::<()>(ImportFormat::E57, source, out, &[]);
    let mut notes = Vec::new();
    let mut poses: Vec<Option<Pose>> = Vec::new();
    write_or_roll_back(out, || {
        let wanted = |index| selected.contains(&index);
        for_each_e57_scan(source, wanted, |index, scan| {
            if scan.points_in_sensor.is_empty() {
                notes.push(format!(
                    "scan {index}{} has no valid point ({} invalid); skipped",
                    label(&scan),
                    scan.dropped
                ));
                return Ok(());
            }
            let name = scan_name(poses.len(), "ply");
            write_points_ply(&out.join(SCANS_DIR).join(name), &scan.points_in_sensor)?;
            summary.points_per_scan.push(scan.points_in_sensor.len());
            summary.dropped_invalid += scan.dropped;
            summary
                .source_scans
                .push(PathBuf::from(format!("{}#{index}", source.display())));
            poses.push(scan.world_from_sensor);
            Ok(())
        })?;
        if poses.is_empty() {
            return Err(Error::Invalid(format!(
                "no selected scan of {} has a valid point; there is nothing to import",
                source.display()
            )));
        }
        summary.written.push(format!("{SCANS_DIR}/"));
        write_priors(out, &poses, &mut summary.written, &mut notes)
    })?;
    summary.scans = poses.len();
    if poses.len() < total {
        notes.push(format!(
            "imported {} of the survey's {total} scans",
            poses.len()
        ));
    }
    summary.notes = notes;
    Ok(summary)
}

/// Writes `odometry.txt` and `attitude.csv` from the scans' registered poses when every scan
/// has one; otherwise says why not in `notes`.
fn write_priors(
    out: &Path,
    poses: &[Option<Pose>],
    written: &mut Vec<String>,
    notes: &mut Vec<String>,
) -> Result<()> {
    let Some(poses) = poses.iter().copied().collect::<Option<Vec<Pose>>>() else {
        let without = poses.iter().filter(|p| p.is_none()).count();
        notes.push(format!(
            "{without} of {} scans have no registered pose, so no odometry.txt or attitude.csv \
             was written (sdem searches each scan's attitude)",
            poses.len()
        ));
        return Ok(());
    };
    let odometry = rebased(&poses);
    write_poses(&out.join(ODOMETRY_FILE), &odometry)?;
    let attitudes: Vec<_> = odometry.iter().map(attitude_of).collect();
    write_attitude_csv(&out.join(ATTITUDE_FILE), &attitudes)?;
    written.push(ODOMETRY_FILE.to_string());
    written.push(ATTITUDE_FILE.to_string());
    Ok(())
}

/// The scan indices `options.first`, `options.every` and `options.count` select from a survey
/// of `total`.
fn selection(total: usize, options: &ImportOptions, source: &Path) -> Result<Vec<usize>> {
    let every = options.stride()?;
    let available: Vec<usize> = (options.first.min(total)..total).step_by(every).collect();
    let count = options.count.unwrap_or(available.len());
    if available.is_empty() || count == 0 || count > available.len() {
        let asked = match options.count {
            Some(count) => format!("{count} from scan {}", options.first),
            None => format!("scans from {} on", options.first),
        };
        return Err(Error::Invalid(format!(
            "{} holds {total} scans (numbered from 0), and the import asks for {asked}{}: \
             beyond them, or none",
            source.display(),
            super::every_text(every),
        )));
    }
    Ok(available.into_iter().take(count).collect())
}

/// The poses with the translation re-based on the first one's; rotations unchanged.
fn rebased(poses: &[Pose]) -> Vec<Pose> {
    let origin = poses
        .first()
        .map_or_else(Default::default, |p| p.translation.vector);
    poses
        .iter()
        .map(|p| {
            Pose::from_parts(
                Translation3::from(p.translation.vector - origin),
                p.rotation,
            )
        })
        .collect()
}

/// ` ('name')` for a scan with a name.
fn label(scan: &E57Scan) -> String {
    scan.name
        .as_ref()
        .map_or(String::new(), |n| format!(" ('{n}')"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ::e57::{Record, RecordDataType, RecordName, RecordValue};
    use sdem::geometry::Vec3;

    /// A survey of three scans (the `e57` crate's writer): scan 0 posed at (1000, 2000, 5) and
    /// turned 90°, scan 1 whose points are all invalid, scan 2 with `pose2` or none.
    fn survey(path: &Path, pose2: bool) {
        let mut writer = ::e57::E57Writer::from_file(path, "{survey}").unwrap();
        let prototype = || {
            let coordinate = |name| Record {
                name,
                data_type: RecordDataType::F64,
            };
            vec![
                coordinate(RecordName::CartesianX),
                coordinate(RecordName::CartesianY),
                coordinate(RecordName::CartesianZ),
                Record {
                    name: RecordName::CartesianInvalidState,
                    data_type: RecordDataType::Integer { min: 0, max: 2 },
                },
            ]
        };
        let half = 0.5f64.sqrt();
        let turned = ::e57::Transform {
            rotation: ::e57::Quaternion {
                w: half,
                x: 0.0,
                y: 0.0,
                z: half,
            },
            translation: ::e57::Translation {
                x: 1000.0,
                y: 2000.0,
                z: 5.0,
            },
        };
        let shifted = ::e57::Transform {
            rotation: ::e57::Quaternion {
                w: 1.0,
                x: 0.0,
                y: 0.0,
                z: 0.0,
            },
            translation: ::e57::Translation {
                x: 1001.0,
                y: 2000.0,
                z: 5.0,
            },
        };
        for (i, (transform, state)) in [
            (Some(turned), 0),
            (Some(shifted.clone()), 2),
            (pose2.then_some(shifted), 0),
        ]
        .into_iter()
        .enumerate()
        {
            let mut cloud = writer
                .add_pointcloud(&format!("{{scan{i}}}"), prototype())
                .unwrap();
            cloud.set_transform(transform);
            for k in 0..4 {
                let mut values = [1.0 + k as f64, -0.5, 0.25]
                    .map(RecordValue::Double)
                    .to_vec();
                values.push(RecordValue::Integer(state));
                cloud.add_point(values).unwrap();
            }
            cloud.finalize().unwrap();
        }
        writer.finalize().unwrap();
    }

    #[test]
    fn scans_without_points_are_skipped_and_partial_poses_write_no_prior() {
        let dir = tempfile::tempdir().unwrap();
        let source = dir.path().join("survey.e57");
        survey(&source, false);
        let out = dir.path().join("ds");
        let summary = import_e57(&source, &out, &ImportOptions::default()).unwrap();
        assert_eq!(summary.scans, 2);
        assert_eq!(summary.points_per_scan, vec![4, 4]);
        assert_eq!(summary.dropped_invalid, 0);
        assert!(summary
            .notes
            .iter()
            .any(|n| n.contains("scan 1") && n.contains("skipped")));
        assert!(summary
            .notes
            .iter()
            .any(|n| n.contains("1 of 2 scans have no registered pose")));
        assert!(!out.join(ODOMETRY_FILE).exists() && !out.join(ATTITUDE_FILE).exists());
        let points = crate::read_points(&out.join("scans/000001.ply")).unwrap();
        assert_eq!(
            points[3],
            Vec3::new(4.0, -0.5, 0.25),
            "its own frame, no pose applied"
        );
    }

    #[test]
    fn registered_poses_become_odometry_and_attitude_rebased_on_the_first() {
        let dir = tempfile::tempdir().unwrap();
        let source = dir.path().join("survey.e57");
        survey(&source, true);
        let out = dir.path().join("ds");
        let summary = import_e57(&source, &out, &ImportOptions::default()).unwrap();
        assert_eq!(summary.scans, 2);
        let odometry = crate::read_kitti_poses(&out.join(ODOMETRY_FILE)).unwrap();
        assert!(odometry[0].translation.vector.norm() < 1e-12);
        assert!((odometry[1].translation.vector - Vec3::new(1.0, 0.0, 0.0)).norm() < 1e-9);
        let attitude = crate::read_attitude_csv(&out.join(ATTITUDE_FILE)).unwrap();
        assert!((attitude[0].yaw.to_degrees() - 90.0).abs() < 1e-9);
        assert!(!out.join(crate::TRUTH_FILE).exists());
        // A selection out of range is refused before anything is written.
        let options = ImportOptions {
            first: 2,
            count: Some(2),
            every: None,
            frames_dir: None,
        };
        let other = dir.path().join("other");
        let err = import_e57(&source, &other, &options).unwrap_err();
        assert!(err.to_string().contains("holds 3 scans"), "{err}");
        assert!(!other.exists());
        // A stride picks scans by their position in the survey.
        let every = |first, every, count| ImportOptions {
            first,
            count,
            every: Some(every),
            frames_dir: None,
        };
        assert_eq!(selection(3, &every(0, 2, None), &source).unwrap(), [0, 2]);
        assert_eq!(selection(3, &every(1, 2, None), &source).unwrap(), [1]);
        let err = selection(3, &every(0, 2, Some(3)), &source).unwrap_err();
        assert!(err.to_string().contains("with a stride of 2"), "{err}");
    }
}
