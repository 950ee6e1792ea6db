//! E57 surveys (one `.e57` file of several scans, [`import_e57`]).
//!
//! Each scan of the survey ([`crate::read_e57`]: its points in its own frame, invalid points
//! dropped) becomes `scans/000000.ply`, … (binary PLY, in the file's order; `first` and `count`
//! select by that order, from 0). A scan with no valid point is skipped and the summary says so.
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
    read_e57, write_attitude_csv, write_points_ply, write_poses, E57Scan, ATTITUDE_FILE, SCANS_DIR,
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
    let all = read_e57(source)?;
    let total = all.len();
    let selected = select_scans(all, options, source)?;
    let mut notes = Vec::new();
    let mut kept: Vec<(usize, E57Scan)> = Vec::new();
    for (index, scan) in selected {
        if scan.points_in_sensor.is_empty() {
            notes.push(format!(
                "scan {index}{} has no valid point ({} invalid); skipped",
                label(&scan),
                scan.dropped
            ));
        } else {
            kept.push((index, scan));
        }
    }
    if kept.is_empty() {
        return Err(Error::Invalid(format!(
            "no selected scan of {} has a valid point; there is nothing to import",
            source.display()
        )));
    }
    let listed: Vec<(usize, PathBuf)> = kept
        .iter()
        .map(|(index, _)| {
            (
                *index,
                PathBuf::from(format!("{}#{index}", source.display())),
            )
        })
        .collect();
    let mut summary = ImportSummary::empty(ImportFormat::E57, source, out, &listed);
    summary.dropped_invalid = kept.iter().map(|(_, s)| s.dropped).sum();
    write_or_roll_back(out, || {
        for (i, (_, scan)) in kept.iter().enumerate() {
            write_points_ply(
                &out.join(SCANS_DIR).join(scan_name(i, "ply")),
                &scan.points_in_sensor,
            )?;
            summary.points_per_scan.push(scan.points_in_sensor.len());
        }
        summary.written.push(format!("{SCANS_DIR}/"));
        let poses: Option<Vec<Pose>> = kept.iter().map(|(_, s)| s.world_from_sensor).collect();
        match poses {
            Some(poses) => {
                let odometry = rebased(&poses);
                write_poses(&out.join(ODOMETRY_FILE), &odometry)?;
                let attitudes: Vec<_> = odometry.iter().map(attitude_of).collect();
                write_attitude_csv(&out.join(ATTITUDE_FILE), &attitudes)?;
                summary.written.push(ODOMETRY_FILE.to_string());
                summary.written.push(ATTITUDE_FILE.to_string());
            }
            None => {
                let without = kept
                    .iter()
                    .filter(|(_, s)| s.world_from_sensor.is_none())
                    .count();
                notes.push(format!(
                    "{without} of {} scans have no registered pose, so no odometry.txt or \
                     attitude.csv was written (sdem searches each scan's attitude)",
                    kept.len()
                ));
            }
        }
        Ok(())
    })?;
    if kept.len() < total {
        notes.push(format!(
            "imported {} of the survey's {total} scans",
            kept.len()
        ));
    }
    summary.notes = notes;
    Ok(summary)
}

/// The scans `options.first` and `options.count` select, with their index in the file.
fn select_scans(
    all: Vec<E57Scan>,
    options: &ImportOptions,
    source: &Path,
) -> Result<Vec<(usize, E57Scan)>> {
    let total = all.len();
    let count = options.count.unwrap_or(total.saturating_sub(options.first));
    if options.first >= total || count == 0 || options.first + count > total {
        return Err(Error::Invalid(format!(
            "{} holds {total} scans (numbered from 0); scans {}..{} were asked",
            source.display(),
            options.first,
            options.first + count
        )));
    }
    Ok(all
        .into_iter()
        .enumerate()
        .skip(options.first)
        .take(count)
        .collect())
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
