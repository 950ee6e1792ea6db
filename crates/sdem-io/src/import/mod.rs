//! Importing other datasets into sdem's dataset layout: 3DTK folders, KITTI odometry sequences
//! and E57 surveys.
//!
//! Each format has its own file, with its frames and the files it writes: `threedtk.rs`
//! (3DTK folders: `.3d` scans, `.pose` and `.frames` files), `kitti.rs` (KITTI odometry
//! sequences: Velodyne `.bin` scans, `calib.txt`, `poses.txt`) and `e57.rs` (E57 surveys: one
//! file of scans with registered poses). What they share lives here:
//! the options and summary of an import, format detection, and the folder helpers (finding
//! numbered scan files, selecting them, refusing a folder that holds a dataset, rolling back a
//! failed write).

use super::{clear_dataset, DATASET_ENTRIES, SCANS_DIR};
use crate::error::{Error, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};

mod e57;
mod kitti;
mod line_scanner;
mod threedtk;

pub use self::e57::import_e57;
pub use kitti::{import_kitti, kitti_velodyne_poses, parse_kitti_calib_tr, read_kitti_calib_tr};
pub use threedtk::{
    import_3dtk, read_uos_frames_last, read_uos_pose, uos_matrix_to_world_from_sensor,
    uos_pose_to_world_from_sensor, UOS_MAX_RANGE_M, UOS_MIN_RANGE_M,
};

/// What kind of folder is imported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ImportFormat {
    /// A 3DTK folder: `scanNNN.3d` with `scanNNN.pose`, optionally `.frames`.
    #[serde(rename = "3dtk")]
    Uos3dtk,
    /// A KITTI odometry sequence: `velodyne/NNNNNN.bin`, optionally `poses.txt` + `calib.txt`.
    #[serde(rename = "kitti")]
    Kitti,
    /// An E57 survey: one `.e57` file of scans, each with its registered pose when it has one.
    #[serde(rename = "e57")]
    E57,
}

impl ImportFormat {
    /// Guesses the format of `source` from its content: a file `*.e57` is an E57 survey, a
    /// folder with `velodyne/` KITTI, one with `scanNNN.3d` files 3DTK.
    ///
    /// # Errors
    /// [`Error::Invalid`] when `source` is neither an `.e57` file nor a folder, or looks like
    /// none of them.
    pub fn detect(source: &Path) -> Result<ImportFormat> {
        let e57 = source
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("e57"));
        if e57 && source.is_file() {
            return Ok(ImportFormat::E57);
        }
        check_source(source)?;
        if is_kitti_sequence(source) {
            return Ok(ImportFormat::Kitti);
        }
        if is_3dtk_folder(source)? {
            return Ok(ImportFormat::Uos3dtk);
        }
        Err(Error::Invalid(format!(
            "{} is neither a 3DTK folder (scanNNN.3d + scanNNN.pose), a KITTI sequence \
             (velodyne/NNNNNN.bin) nor a ROS 2 bag folder (metadata.yaml, .mcap or .db3 \
             files); import also reads an .e57 file or one bag file. Name the format with \
             --format or check the folder",
            source.display()
        )))
    }
}

/// Whether `folder` is a KITTI sequence: it has `velodyne/`.
fn is_kitti_sequence(folder: &Path) -> bool {
    folder.join("velodyne").is_dir()
}

/// Whether `folder` is a 3DTK folder: it has `scanNNN.3d` files.
fn is_3dtk_folder(folder: &Path) -> Result<bool> {
    Ok(!numbered_files(folder, "scan", "3d")?.is_empty())
}

/// Whether `folder` holds the scans of a KITTI sequence or a 3DTK folder ([`ImportFormat::detect`]'s
/// rules): a folder that also holds bag files is still not a bag.
pub(crate) fn holds_scans(folder: &Path) -> bool {
    is_kitti_sequence(folder) || is_3dtk_folder(folder).unwrap_or(false)
}

/// Which scans to import and where extra inputs are.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ImportOptions {
    /// The first scan number to import (the `NNN` of the file names); scans with a smaller
    /// number are skipped.
    pub first: usize,
    /// How many scans to import from `first` on (in the order of their numbers); `None` for all.
    pub count: Option<usize>,
    /// Import every this many-th scan number from the first at or after `first` on (`None`:
    /// every scan; E57: every this many-th scan of the survey), `count` of them:
    /// a 10 Hz LiDAR recording thinned as a vehicle that stops to scan, or drops frames,
    /// would take it. The dataset's scans are renumbered from 0 and its pose files hold the
    /// imported scans' poses alone.
    pub every: Option<usize>,
    /// 3DTK only: the folder of slam6D's `scanNNN.frames`. `None` looks for
    /// `SOURCE/slam6d_frames_2009/`, then for `.frames` files in `SOURCE`.
    pub frames_dir: Option<PathBuf>,
}

/// What an import read and wrote.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImportSummary {
    /// The format imported.
    pub format: ImportFormat,
    /// The source folder.
    pub source: PathBuf,
    /// The dataset folder written.
    pub out: PathBuf,
    /// The number of scans imported.
    pub scans: usize,
    /// The source file of each imported scan, in dataset order.
    pub source_scans: Vec<PathBuf>,
    /// The points kept in each scan.
    pub points_per_scan: Vec<usize>,
    /// Points dropped at the scanner's "no return" range (3DTK), over all scans.
    pub dropped_far: usize,
    /// 3DTK: the range from which a scan's returns were taken for "no return" (the least over
    /// the scans), metres; `None` where no scan has one and every return was kept.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub no_return_from_m: Option<f64>,
    /// Points dropped as nearer than [`UOS_MIN_RANGE_M`] (3DTK), over all scans.
    pub dropped_near: usize,
    /// Points dropped as invalid (E57: no return, a direction without a range), over all scans.
    pub dropped_invalid: usize,
    /// The files written, relative to `out` (`scans/` stands for the scan files).
    pub written: Vec<String>,
    /// What a user should know about the import (scans skipped, files not written, and why).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl ImportSummary {
    /// The summary before any scan is written: what is imported from where, nothing counted yet.
    fn empty<T>(format: ImportFormat, source: &Path, out: &Path, scans: &[(T, PathBuf)]) -> Self {
        Self {
            format,
            source: source.to_path_buf(),
            out: out.to_path_buf(),
            scans: scans.len(),
            source_scans: scans.iter().map(|(_, p)| p.clone()).collect(),
            points_per_scan: Vec::with_capacity(scans.len()),
            dropped_far: 0,
            no_return_from_m: None,
            dropped_near: 0,
            dropped_invalid: 0,
            written: Vec::new(),
            notes: Vec::new(),
        }
    }
}

/// Imports `source` into the dataset folder `out`, guessing the format when `format` is `None`
/// ([`ImportFormat::detect`]). See [`import_3dtk`] and [`import_kitti`].
pub fn import_dataset(
    source: &Path,
    out: &Path,
    format: Option<ImportFormat>,
    options: &ImportOptions,
) -> Result<ImportSummary> {
    let format = match format {
        Some(f) => f,
        None => ImportFormat::detect(source)?,
    };
    match format {
        ImportFormat::Uos3dtk => import_3dtk(source, out, options),
        ImportFormat::Kitti => {
            if let Some(frames) = &options.frames_dir {
                return Err(Error::Invalid(format!(
                    "a frames folder ({}) is for 3DTK imports only; {} is a KITTI sequence",
                    frames.display(),
                    source.display()
                )));
            }
            import_kitti(source, out, options)
        }
        ImportFormat::E57 => import_e57(source, out, options),
    }
}

// ---------------------------------------------------------------------------------------------
// Folders
// ---------------------------------------------------------------------------------------------

fn check_source(source: &Path) -> Result<()> {
    if source.is_dir() {
        Ok(())
    } else if source.exists() {
        Err(Error::Invalid(format!(
            "{} is not a folder; import reads a 3DTK folder, a KITTI sequence folder, an .e57 \
             file or a ROS 2 bag (a rosbag2 folder, or an .mcap or .db3 file)",
            source.display()
        )))
    } else {
        Err(Error::Invalid(format!(
            "{} does not exist; import reads a 3DTK folder, a KITTI sequence folder, an .e57 \
             file or a ROS 2 bag (a rosbag2 folder, or an .mcap or .db3 file)",
            source.display()
        )))
    }
}

/// The visible files of `folder` named `PREFIX` + digits + `.EXT`, as `(number, path)` sorted
/// by number.
fn numbered_files(folder: &Path, prefix: &str, ext: &str) -> Result<Vec<(usize, PathBuf)>> {
    let entries = std::fs::read_dir(folder).map_err(|e| Error::io(folder, e))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| Error::io(folder, e))?.path();
        let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
            continue;
        };
        let Some(digits) = name
            .strip_prefix(prefix)
            .and_then(|n| n.strip_suffix(ext))
            .and_then(|n| n.strip_suffix('.'))
        else {
            continue;
        };
        if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) || !path.is_file() {
            continue;
        }
        if let Ok(number) = digits.parse::<usize>() {
            files.push((number, path));
        }
    }
    files.sort();
    Ok(files)
}

/// Applies `first` and `count` to the numbered scan files.
fn select(
    files: Vec<(usize, PathBuf)>,
    options: &ImportOptions,
    folder: &Path,
    what: &str,
) -> Result<Vec<(usize, PathBuf)>> {
    if files.is_empty() {
        return Err(Error::Invalid(format!(
            "{} holds no scans ({what})",
            folder.display()
        )));
    }
    // Every Kth scan number from the first one at or after `first` (a file missing at a
    // selected number is not replaced by its neighbour).
    let every = options.stride()?;
    let start = files
        .iter()
        .map(|(n, _)| *n)
        .filter(|n| *n >= options.first)
        .min();
    let available: Vec<_> = files
        .into_iter()
        .filter(|(n, _)| start.is_some_and(|s| *n >= s && (*n - s) % every == 0))
        .collect();
    let selected: Vec<_> = match options.count {
        Some(0) => {
            return Err(Error::Invalid(
                "the scan count is 0; import at least one scan".into(),
            ))
        }
        Some(count) if count > available.len() => {
            return Err(Error::Invalid(format!(
                "{count} scans asked from number {} on{}, but {} holds {} ({what})",
                options.first,
                every_text(every),
                folder.display(),
                available.len()
            )))
        }
        Some(count) => available.into_iter().take(count).collect(),
        None => available,
    };
    if selected.is_empty() {
        return Err(Error::Invalid(format!(
            "{} holds no scan numbered {} or more ({what})",
            folder.display(),
            options.first
        )));
    }
    Ok(selected)
}

impl ImportOptions {
    /// The stride [`Self::every`] asks for: 1 when it is `None`.
    ///
    /// # Errors
    /// [`Error::Invalid`] when it is `Some(0)`.
    pub fn stride(&self) -> Result<usize> {
        match self.every {
            None => Ok(1),
            Some(0) => Err(Error::Invalid(
                "every 0th scan imports nothing; give a stride of at least 1".into(),
            )),
            Some(n) => Ok(n),
        }
    }
}

/// " with a stride of N" for a stride above 1, for messages.
pub(crate) fn every_text(every: usize) -> String {
    match every {
        1 => String::new(),
        n => format!(" with a stride of {n}"),
    }
}

/// Refuses to import into a folder that holds a dataset entry.
pub(crate) fn check_out(out: &Path) -> Result<()> {
    if out.exists() && !out.is_dir() {
        return Err(Error::Invalid(format!(
            "{} is not a folder; import writes a dataset folder",
            out.display()
        )));
    }
    for name in DATASET_ENTRIES {
        let path = out.join(name);
        if path.exists() {
            return Err(Error::Invalid(format!(
                "{} already exists; import writes into a folder without a dataset (remove it first)",
                path.display()
            )));
        }
    }
    Ok(())
}

/// Runs the writing part of an import; on error removes what it wrote (the folder held no
/// dataset entry before, see [`check_out`]).
pub(crate) fn write_or_roll_back(out: &Path, write: impl FnOnce() -> Result<()>) -> Result<()> {
    let created = !out.exists();
    let result = std::fs::create_dir_all(out.join(SCANS_DIR))
        .map_err(|e| Error::io(out.join(SCANS_DIR), e))
        .and_then(|()| write());
    if result.is_err() {
        let _ = clear_dataset(out);
        if created {
            let _ = std::fs::remove_dir(out);
        }
    }
    result
}

fn scan_name(index: usize, ext: &str) -> String {
    format!("{index:06}.{ext}")
}

#[cfg(test)]
mod test_files {
    use std::path::{Path, PathBuf};

    pub(super) fn write(dir: &Path, name: &str, content: &str) -> PathBuf {
        let path = dir.join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).unwrap();
        }
        std::fs::write(&path, content).unwrap();
        path
    }
}
