//! Dataset folders (DESIGN.md, "Dataset folder"): `scans/`, optional `sweeps/`, optional
//! `attitude.csv`, optional `odometry.txt` and `poses_truth.txt` (+ `.tum`), optional
//! `sensor.toml`.

use super::{
    read_attitude_readings, read_kitti_poses, read_sensor_file, read_sweep, write_attitude_csv,
    write_points_ply, write_poses, write_sensor_toml, write_sweep, POINT_EXTENSIONS,
};
use crate::error::{Error, Result};
use sdem::geometry::{Attitude, AttitudeSigma, Pose, Vec3};
use sdem::sensor::{SensorConfig, Sweep};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

mod listing;

pub use listing::scans_numbered;
use listing::{point_files, ScanListing};

/// The folder of point clouds, one file per stop.
pub const SCANS_DIR: &str = "scans";
/// The optional folder of raw sweeps, `NNNNNN.sweep` beside `scans/NNNNNN.*`.
pub const SWEEPS_DIR: &str = "sweeps";
/// The optional attitude file (the gyro/compass reading per scan).
pub const ATTITUDE_FILE: &str = "attitude.csv";
/// The optional dead-reckoned `world_from_sensor` poses (KITTI; a `.tum` twin is written beside
/// it). Only the relative motion between consecutive scans is meant to be used.
pub const ODOMETRY_FILE: &str = "odometry.txt";
/// The optional slam6D result of an imported 3DTK folder (KITTI; a `.tum` twin beside it): a
/// reference for comparison, not ground truth.
pub const SLAM6D_FILE: &str = "poses_slam6d.txt";
/// The optional ground-truth poses (KITTI; a `.tum` twin is written beside it).
pub const TRUTH_FILE: &str = "poses_truth.txt";
/// The optional sensor model.
pub const SENSOR_FILE: &str = "sensor.toml";

/// A dataset folder, opened: the scan files (not yet read) and, when the folder has them, the
/// attitude, odometry and true pose of each scan and the sensor model.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The dataset folder.
    pub root: PathBuf,
    /// One point-cloud file per stop, in `scans/`, in the natural order of their file names
    /// (`scan2` before `scan10`).
    pub scan_paths: Vec<PathBuf>,
    /// The gyro/compass attitude of each scan, from `attitude.csv`, when present (one per scan),
    /// each with its standard deviations ([`Attitude::sigma`]): the row's own when the file
    /// has σ columns, else [`Dataset::attitude_sigma`].
    ///
    /// Without it there is no attitude measurement: the attitude is unknown, and
    /// `sdem::localize` searches it (a [`sdem::Scan`] built with `None`); the SLAM loop takes
    /// the previous scan's estimated attitude as the prior of the next one and searches heading
    /// wider, since no compass bounds it.
    pub attitudes: Option<Vec<Attitude>>,
    /// The standard deviations of the attitude readings that `sensor.toml` states, or
    /// [`AttitudeSigma::default`] (0.5° roll/pitch, 3.5° heading) when it states none. Rows of
    /// `attitude.csv` with σ columns carry their own.
    pub attitude_sigma: AttitudeSigma,
    /// Where the readings' standard deviations come from.
    pub attitude_sigma_from: SigmaSource,
    /// The robot's dead-reckoned `world_from_sensor` of each scan, from `odometry.txt`, when
    /// present (one per scan). Odometry drifts: only the relative motion between consecutive
    /// scans, `odometry[i - 1].inverse() * odometry[i]`, is meant to be used, as a prior.
    pub odometry: Option<Vec<Pose>>,
    /// The true `world_from_sensor` of each scan, from `poses_truth.txt`, when present.
    pub truth: Option<Vec<Pose>>,
    /// The sensor model from `sensor.toml`, when present.
    pub sensor: Option<SensorConfig>,
}

/// Where the standard deviations of a dataset's attitude readings come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SigmaSource {
    /// Neither file states them: [`AttitudeSigma::default`].
    Default,
    /// `sensor.toml`'s `attitude_sigma_roll_pitch_deg` / `attitude_sigma_yaw_deg`.
    SensorToml,
    /// `attitude.csv`'s per-row σ columns.
    AttitudeCsv,
}

impl SigmaSource {
    /// The source in words, for messages: `the default`, `sensor.toml`, `attitude.csv`.
    pub fn describe(self) -> &'static str {
        match self {
            SigmaSource::Default => "the default",
            SigmaSource::SensorToml => SENSOR_FILE,
            SigmaSource::AttitudeCsv => ATTITUDE_FILE,
        }
    }
}

impl Dataset {
    /// Opens a dataset folder: lists `scans/` and reads `attitude.csv`, `odometry.txt`,
    /// `poses_truth.txt` and `sensor.toml` when present. Point clouds are read later, one at a
    /// time, by [`Dataset::load_scan`].
    ///
    /// In `scans/`, files with a point-cloud extension ([`POINT_EXTENSIONS`]) are the scans, in
    /// the natural order of their names (`scan2` before `scan10`, runs of digits compared by
    /// value); hidden files and other files are ignored. Errors: no `scans/` folder, no scan in
    /// it, two scans with the same name stem (`000001.ply` and `000001.pcd`), a row count in
    /// `attitude.csv`, `odometry.txt` or `poses_truth.txt` different from the scan count (the
    /// message names the file, both counts, and the visible entries of `scans/` that were not
    /// taken as scans: another extension, a folder, a link to a missing file), and any error
    /// reading those files.
    ///
    /// # Example
    /// ```
    /// # let dir = std::env::temp_dir().join(format!("sdem-doc-dataset-{}", std::process::id()));
    /// use sdem::geometry::{Attitude, Vec3};
    /// let scans = vec![(vec![Vec3::new(1.0, 0.0, 0.0)], Attitude::default())];
    /// sdem_io::write_dataset(&dir, &Default::default(), &scans, None, None, None).unwrap();
    /// let dataset = sdem_io::Dataset::open(&dir).unwrap();
    /// assert_eq!(dataset.len(), 1);
    /// assert_eq!(dataset.load_scan(0).unwrap(), scans[0].0);
    /// # std::fs::remove_dir_all(&dir).unwrap();
    /// ```
    pub fn open(root: &Path) -> Result<Dataset> {
        let scans_dir = root.join(SCANS_DIR);
        if !scans_dir.is_dir() {
            let what = if root.is_dir() {
                "has no scans/ folder"
            } else {
                "is not a folder"
            };
            return Err(Error::Invalid(format!(
                "{} {what}; a dataset needs {} holding one point-cloud file per stop (.{})",
                root.display(),
                scans_dir.display(),
                POINT_EXTENSIONS.join(", .")
            )));
        }
        let listing = point_files(&scans_dir)?;
        let scan_paths = &listing.scans;
        if scan_paths.is_empty() {
            return Err(Error::Invalid(format!(
                "{} holds no point-cloud file; put one file per stop there (.{}){}",
                scans_dir.display(),
                POINT_EXTENSIONS.join(", ."),
                listing.skipped_note()
            )));
        }
        let mut stems: HashMap<&std::ffi::OsStr, &Path> = HashMap::new();
        for path in scan_paths {
            if let Some(stem) = path.file_stem() {
                if let Some(other) = stems.insert(stem, path) {
                    return Err(Error::Invalid(format!(
                        "{} and {} are two scans of the same stop; keep one",
                        other.display(),
                        path.display()
                    )));
                }
            }
        }

        // sensor.toml first: its σ is the default of attitude.csv's readings.
        let sensor_path = root.join(SENSOR_FILE);
        let sensor_file = if sensor_path.exists() {
            Some(read_sensor_file(&sensor_path)?)
        } else {
            None
        };
        let toml_sigma = sensor_file.as_ref().and_then(|f| f.attitude_sigma);
        let attitude_sigma = toml_sigma.unwrap_or_default();
        let mut attitude_sigma_from = if toml_sigma.is_some() {
            SigmaSource::SensorToml
        } else {
            SigmaSource::Default
        };
        let sensor = sensor_file.map(|f| f.sensor);

        let attitude_path = root.join(ATTITUDE_FILE);
        let attitudes = if attitude_path.exists() {
            let readings = read_attitude_readings(&attitude_path, attitude_sigma)?;
            if readings.attitudes.len() != scan_paths.len() {
                return Err(Error::Invalid(format!(
                    "{} has {} but {} holds {} scans; they must match one to one{}",
                    attitude_path.display(),
                    match readings.attitudes.len() {
                        1 => "1 row".to_string(),
                        n => format!("{n} rows"),
                    },
                    scans_dir.display(),
                    scan_paths.len(),
                    listing.skipped_note()
                )));
            }
            if readings.sigma_per_row {
                attitude_sigma_from = SigmaSource::AttitudeCsv;
            }
            Some(readings.attitudes)
        } else {
            None
        };
        let odometry = read_poses_if_present(&root.join(ODOMETRY_FILE), &scans_dir, &listing)?;
        let truth = read_poses_if_present(&root.join(TRUTH_FILE), &scans_dir, &listing)?;

        Ok(Dataset {
            root: root.to_path_buf(),
            scan_paths: listing.scans,
            attitudes,
            odometry,
            truth,
            sensor,
            attitude_sigma,
            attitude_sigma_from,
        })
    }

    /// The gyro/compass attitude of scan `index` with its σ, or `None` when the dataset has no
    /// `attitude.csv` (the attitude is unknown) or `index` is out of range.
    pub fn attitude(&self, index: usize) -> Option<Attitude> {
        self.attitudes.as_ref().and_then(|a| a.get(index).copied())
    }

    /// The gyro/compass attitude of scan `index`, or the level attitude (roll = pitch = yaw = 0,
    /// with [`Dataset::attitude_sigma`]) when the dataset has no `attitude.csv`. `None` when
    /// `index` is out of range.
    pub fn attitude_or_level(&self, index: usize) -> Option<Attitude> {
        if index >= self.len() {
            return None;
        }
        Some(self.attitude(index).unwrap_or(Attitude {
            sigma: self.attitude_sigma,
            ..Attitude::default()
        }))
    }

    /// The number of scans.
    pub fn len(&self) -> usize {
        self.scan_paths.len()
    }

    /// True when the dataset has no scans (an opened dataset always has at least one).
    pub fn is_empty(&self) -> bool {
        self.scan_paths.is_empty()
    }

    fn check_index(&self, index: usize) -> Result<&PathBuf> {
        self.scan_paths.get(index).ok_or_else(|| {
            Error::Invalid(format!(
                "scan index {index} is out of range: {} has {}",
                self.root.display(),
                scans_numbered(self.len())
            ))
        })
    }

    /// Reads scan `index` (0-based): its points in the sensor frame, metres.
    pub fn load_scan(&self, index: usize) -> Result<Vec<Vec3>> {
        // With a sensor model, a scan far beyond the sensor's reach is in another unit.
        let reach = self.sensor.as_ref().map(|s| s.max_range_m);
        crate::points::read_points_within(self.check_index(index)?, reach)
    }

    /// The raw sweep of scan `index` from `sweeps/STEM.sweep`, where `STEM` is the scan file's
    /// name without extension; `None` when the dataset has no such file.
    pub fn load_sweep(&self, index: usize) -> Result<Option<Sweep>> {
        let scan = self.check_index(index)?;
        let Some(stem) = scan.file_stem() else {
            return Ok(None);
        };
        let mut name = stem.to_os_string();
        name.push(".sweep");
        let path = self.root.join(SWEEPS_DIR).join(name);
        if path.is_file() {
            read_sweep(&path).map(Some)
        } else {
            Ok(None)
        }
    }
}

/// Reads a KITTI pose file of the dataset when it exists, checking one pose per scan.
fn read_poses_if_present(
    path: &Path,
    scans_dir: &Path,
    listing: &ScanListing,
) -> Result<Option<Vec<Pose>>> {
    if !path.exists() {
        return Ok(None);
    }
    let poses = read_kitti_poses(path)?;
    if poses.len() != listing.scans.len() {
        return Err(Error::Invalid(format!(
            "{} has {} poses but {} holds {} scans; they must match one to one{}",
            path.display(),
            poses.len(),
            scans_dir.display(),
            listing.scans.len(),
            listing.skipped_note()
        )));
    }
    Ok(Some(poses))
}

/// Refuses to write into a folder whose existing files would silently become part of the new
/// dataset: point-cloud or sweep files that this write does not replace.
fn check_no_stale(folder: &Path, keep: &[String], what: &str) -> Result<()> {
    if !folder.is_dir() {
        return Ok(());
    }
    for path in point_files(folder)?.scans {
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        if !keep.iter().any(|k| k == name) {
            return Err(Error::Invalid(format!(
                "{} already exists and is not part of the dataset being written ({what}); write \
                 into an empty folder or remove it",
                path.display()
            )));
        }
    }
    Ok(())
}

/// Refuses to write a dataset without the optional pose file `name` while an old one is left in
/// `root`: it would silently become part of the new dataset.
pub(crate) fn check_no_stale_file(root: &Path, name: &str, what: &str) -> Result<()> {
    let path = root.join(name);
    if path.exists() {
        return Err(Error::Invalid(format!(
            "cannot write dataset {}: {} is left from an earlier dataset and this one has no \
             {what}; remove it or write into an empty folder",
            root.display(),
            path.display()
        )));
    }
    Ok(())
}

/// Checks that an optional per-scan list has one entry per scan.
fn check_count(root: &Path, what: &str, count: Option<usize>, scans: usize) -> Result<()> {
    match count {
        Some(n) if n != scans => Err(Error::Invalid(format!(
            "cannot write dataset {}: {n} {what} for {scans} scans; they must match one to one",
            root.display()
        ))),
        _ => Ok(()),
    }
}

/// Writes a dataset folder: `scans/000000.ply`, … (binary PLY), `attitude.csv`, `sensor.toml`,
/// and when given `sweeps/000000.sweep`, …, `poses_truth.txt` with `poses_truth.tum` and
/// `odometry.txt` with `odometry.tum`. Folders are created as needed and every file is written
/// atomically.
///
/// # Arguments
/// * `root` — the dataset folder (created if missing).
/// * `sensor` — the sensor model, written as `sensor.toml`.
/// * `scans` — per stop, the points in the sensor frame (metres) and the measured attitude.
/// * `sweeps` — optional raw sweeps, one per scan.
/// * `truth` — optional true `world_from_sensor` poses, one per scan.
/// * `odometry` — optional dead-reckoned `world_from_sensor` poses, one per scan.
///
/// Errors: no scans; `sweeps`, `truth` or `odometry` of another length than `scans`; an empty or
/// non-finite scan or attitude; and, to keep an old dataset's files from mixing into the new one,
/// a point-cloud file in `scans/` (or a sweep in `sweeps/`) that this write would not replace, or
/// a `poses_truth.txt` (`odometry.txt`) left over when `truth` (`odometry`) is `None` — all
/// checked before anything is written.
pub fn write_dataset(
    root: &Path,
    sensor: &SensorConfig,
    scans: &[(Vec<Vec3>, Attitude)],
    sweeps: Option<&[Sweep]>,
    truth: Option<&[Pose]>,
    odometry: Option<&[Pose]>,
) -> Result<()> {
    if !scans.is_empty() {
        check_count(root, "sweeps", sweeps.map(<[_]>::len), scans.len())?;
    }
    let plan = DatasetPlan {
        scans: scans.len(),
        with_sweeps: sweeps.is_some(),
        truth,
        odometry,
    };
    write_dataset_streamed(root, sensor, &plan, |i| {
        Ok(StreamedScan {
            points: std::borrow::Cow::Borrowed(&scans[i].0),
            attitude: scans[i].1,
            sweep: sweeps.map(|s| std::borrow::Cow::Borrowed(&s[i])),
        })
    })
}

/// What [`write_dataset_streamed`] writes besides the scans: how many, whether raw sweeps
/// come with them, and the pose files.
#[derive(Debug, Clone, Copy)]
pub struct DatasetPlan<'a> {
    /// The number of scans.
    pub scans: usize,
    /// Whether each scan comes with its raw sweep (`sweeps/`).
    pub with_sweeps: bool,
    /// True `world_from_sensor` poses, one per scan.
    pub truth: Option<&'a [Pose]>,
    /// Dead-reckoned `world_from_sensor` poses, one per scan.
    pub odometry: Option<&'a [Pose]>,
}

/// One scan handed to [`write_dataset_streamed`].
#[derive(Debug, Clone)]
pub struct StreamedScan<'a> {
    /// The points in the sensor frame, metres.
    pub points: std::borrow::Cow<'a, [Vec3]>,
    /// The measured attitude.
    pub attitude: Attitude,
    /// The raw sweep, when the plan has sweeps.
    pub sweep: Option<std::borrow::Cow<'a, Sweep>>,
}

/// [`write_dataset`] for runs too long to hold in memory: scan `i` comes from `scan_at(i)`, in
/// order, and is written before the next is asked for. The same files, checks and errors as
/// [`write_dataset`], and a scan without its sweep where the plan has sweeps is an error.
///
/// # Example
/// ```
/// use sdem::geometry::{Attitude, Vec3};
/// use sdem_io::{write_dataset_streamed, DatasetPlan, StreamedScan};
/// let dir = tempfile::tempdir().unwrap();
/// let plan = DatasetPlan { scans: 3, with_sweeps: false, truth: None, odometry: None };
/// write_dataset_streamed(dir.path(), &Default::default(), &plan, |i| {
///     let points = vec![Vec3::new(1.0 + i as f64, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0)];
///     Ok(StreamedScan { points: points.into(), attitude: Attitude::default(), sweep: None })
/// })?;
/// assert_eq!(sdem_io::Dataset::open(dir.path())?.len(), 3);
/// # Ok::<(), sdem_io::Error>(())
/// ```
pub fn write_dataset_streamed<'s>(
    root: &Path,
    sensor: &SensorConfig,
    plan: &DatasetPlan,
    mut scan_at: impl FnMut(usize) -> Result<StreamedScan<'s>>,
) -> Result<()> {
    let count = plan.scans;
    if count == 0 {
        return Err(Error::Invalid(format!(
            "cannot write dataset {}: there are no scans",
            root.display()
        )));
    }
    check_count(root, "truth poses", plan.truth.map(<[_]>::len), count)?;
    check_count(root, "odometry poses", plan.odometry.map(<[_]>::len), count)?;
    sensor.validate()?;

    let scans_dir = root.join(SCANS_DIR);
    let sweeps_dir = root.join(SWEEPS_DIR);
    let names =
        |ext: &str| -> Vec<String> { (0..count).map(|i| format!("{i:06}.{ext}")).collect() };
    let scan_names = names("ply");
    let sweep_names = if plan.with_sweeps {
        names("sweep")
    } else {
        Vec::new()
    };
    check_no_stale(&scans_dir, &scan_names, "a scan")?;
    check_no_stale(&sweeps_dir, &sweep_names, "a raw sweep")?;
    if plan.truth.is_none() {
        check_no_stale_file(root, TRUTH_FILE, "truth")?;
    }
    if plan.odometry.is_none() {
        check_no_stale_file(root, ODOMETRY_FILE, "odometry")?;
    }

    std::fs::create_dir_all(&scans_dir).map_err(|e| Error::io(&scans_dir, e))?;
    if plan.with_sweeps {
        std::fs::create_dir_all(&sweeps_dir).map_err(|e| Error::io(&sweeps_dir, e))?;
    }
    let mut attitudes = Vec::with_capacity(count);
    for (i, name) in scan_names.iter().enumerate() {
        let scan = scan_at(i)?;
        write_points_ply(&scans_dir.join(name), &scan.points)?;
        match (&scan.sweep, plan.with_sweeps) {
            (Some(sweep), true) => write_sweep(&sweeps_dir.join(&sweep_names[i]), sweep)?,
            (None, true) => {
                return Err(Error::Invalid(format!(
                    "cannot write dataset {}: scan {i} comes without its raw sweep",
                    root.display()
                )))
            }
            (_, false) => {}
        }
        attitudes.push(scan.attitude);
    }
    write_attitude_csv(&root.join(ATTITUDE_FILE), &attitudes)?;
    if let Some(truth) = plan.truth {
        write_poses(&root.join(TRUTH_FILE), truth)?;
    }
    if let Some(odometry) = plan.odometry {
        write_poses(&root.join(ODOMETRY_FILE), odometry)?;
    }
    write_sensor_toml(&root.join(SENSOR_FILE), sensor)
}

/// The files and folders of a dataset folder that sdem writes (`scans/`, `sweeps/`,
/// `attitude.csv`, the pose files with their `.tum` twins, `sensor.toml`).
pub const DATASET_ENTRIES: &[&str] = &[
    SCANS_DIR,
    SWEEPS_DIR,
    ATTITUDE_FILE,
    TRUTH_FILE,
    "poses_truth.tum",
    ODOMETRY_FILE,
    "odometry.tum",
    SLAM6D_FILE,
    "poses_slam6d.tum",
    SENSOR_FILE,
];

/// Removes from `root` the dataset entries listed in [`DATASET_ENTRIES`] (and nothing else), so
/// that a new dataset can be written there without mixing with the old one. Entries that do not
/// exist are skipped; a missing `root` is fine.
///
/// # Errors
/// [`Error::Invalid`], before anything is removed, when `scans/` or `sweeps/` holds a file sdem
/// does not write there (one not numbered like `000012.ply`): it is the user's, and would go
/// with the folder.
///
/// # Example
/// ```
/// # let dir = std::env::temp_dir().join(format!("sdem-doc-clear-{}", std::process::id()));
/// use sdem::geometry::{Attitude, Vec3};
/// let scans = vec![(vec![Vec3::new(1.0, 0.0, 0.0)], Attitude::default())];
/// sdem_io::write_dataset(&dir, &Default::default(), &scans, None, None, None).unwrap();
/// std::fs::write(dir.join("notes.md"), "mine").unwrap();
/// sdem_io::clear_dataset(&dir).unwrap();
/// assert!(!dir.join("scans").exists() && dir.join("notes.md").exists());
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn clear_dataset(root: &Path) -> Result<()> {
    for folder in [SCANS_DIR, SWEEPS_DIR] {
        let Ok(entries) = std::fs::read_dir(root.join(folder)) else {
            continue;
        };
        let mut foreign: Vec<String> = (entries.flatten())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|name| !crate::numbered_file(name, None))
            .collect();
        if !foreign.is_empty() {
            foreign.sort();
            let shown: Vec<String> = (foreign.iter().take(3))
                .map(|n| format!("{folder}/{n}"))
                .collect();
            return Err(Error::Invalid(format!(
                "{} holds {} that sdem did not write ({}{}); replacing the dataset would remove \
                 {}: move {} out of {folder}/ first, or choose another folder",
                root.display(),
                if foreign.len() == 1 {
                    "a file"
                } else {
                    "files"
                },
                shown.join(", "),
                if foreign.len() > 3 { ", …" } else { "" },
                if foreign.len() == 1 { "it" } else { "them" },
                if foreign.len() == 1 { "it" } else { "them" },
            )));
        }
    }
    for name in DATASET_ENTRIES {
        let path = root.join(name);
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        let removed = if meta.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        removed.map_err(|e| Error::io(&path, e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use sdem::geometry::{pose_error, pose_from_parts};
    use sdem::sensor::SweepLine;

    fn scans(n: usize) -> Vec<(Vec<Vec3>, Attitude)> {
        (0..n)
            .map(|i| {
                let points = (0..10)
                    .map(|k| Vec3::new(k as f64 * 0.5, i as f64, 1.0 - k as f64 * 0.125))
                    .collect();
                (
                    points,
                    Attitude::from_degrees(0.5 * i as f64, -1.0, 10.0 * i as f64),
                )
            })
            .collect()
    }

    fn sweep() -> Sweep {
        Sweep {
            pan_min_deg: -90.0,
            pan_step_deg: 90.0,
            lift_slide_m: 0.3,
            lines: vec![SweepLine {
                tilt_deg: 0.0,
                attitude: Attitude::default(),
                ranges: vec![1.0, f32::NAN, 2.0],
            }],
        }
    }

    /// A scan whose median range is many times the sensor's reach (sensor.toml) is refused as
    /// another unit, naming the file, though it passes the readers' 1 km check (these points,
    /// scaled by 100, lie 270 m away); without a sensor model it is read.
    #[test]
    fn a_scan_far_beyond_the_sensors_reach_is_refused_as_millimetres() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("run");
        let in_mm: Vec<(Vec<Vec3>, Attitude)> = scans(2)
            .into_iter()
            .map(|(points, a)| (points.iter().map(|p| p * 100.0).collect(), a))
            .collect();
        let sensor = SensorConfig::default();
        write_dataset(&root, &sensor, &in_mm, None, None, None).unwrap();
        let e = Dataset::open(&root)
            .unwrap()
            .load_scan(1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("000001.ply") && e.contains("millimetres"), "{e}");
        std::fs::remove_file(root.join(SENSOR_FILE)).unwrap();
        assert_eq!(
            Dataset::open(&root).unwrap().load_scan(1).unwrap().len(),
            10
        );
    }

    #[test]
    fn write_then_open_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("run");
        let scans = scans(3);
        let truth: Vec<Pose> = (0..3)
            .map(|i| pose_from_parts(Vec3::new(i as f64, 0.1, 0.0), scans[i].1))
            .collect();
        let sweeps = vec![sweep(); 3];
        let sensor = SensorConfig {
            trusted_range_m: Some(3.0),
            ..Default::default()
        };
        let odometry: Vec<Pose> = truth
            .iter()
            .map(|t| Pose::translation(0.01, 0.0, 0.0) * t)
            .collect();
        write_dataset(
            &root,
            &sensor,
            &scans,
            Some(&sweeps),
            Some(&truth),
            Some(&odometry),
        )
        .unwrap();
        assert!(root.join("poses_truth.tum").is_file());
        assert!(root.join("odometry.tum").is_file());

        let dataset = Dataset::open(&root).unwrap();
        assert_eq!(dataset.len(), 3);
        assert!(!dataset.is_empty());
        assert_eq!(dataset.scan_paths[2], root.join("scans/000002.ply"));
        assert_eq!(dataset.sensor, Some(sensor.clone()));
        for (i, (points, attitude)) in scans.iter().enumerate() {
            assert_eq!(&dataset.load_scan(i).unwrap(), points);
            let a = dataset.attitudes.as_ref().unwrap()[i];
            assert_eq!(dataset.attitude_or_level(i), Some(a));
            assert!((a.yaw - attitude.yaw).abs() < 1e-12 && (a.roll - attitude.roll).abs() < 1e-12);
            let (dt, dr) = pose_error(&truth[i], &dataset.truth.as_ref().unwrap()[i]);
            assert!(dt < 1e-9 && dr < 1e-9);
            let (dt, dr) = pose_error(&odometry[i], &dataset.odometry.as_ref().unwrap()[i]);
            assert!(dt < 1e-9 && dr < 1e-9);
            assert_eq!(dataset.load_sweep(i).unwrap().unwrap().lines.len(), 1);
        }

        // Writing again over the same dataset is fine; a smaller one without truth is refused
        // (stale scans and truth), before anything is written.
        write_dataset(
            &root,
            &sensor,
            &scans,
            Some(&sweeps),
            Some(&truth),
            Some(&odometry),
        )
        .unwrap();
        let err = write_dataset(&root, &sensor, &scans[..2], None, None, None).unwrap_err();
        assert!(err.to_string().contains("000002.ply"), "{err}");
        assert_eq!(Dataset::open(&root).unwrap().len(), 3);
        // Same scans, truth, no odometry: the old odometry.txt is refused.
        let err = write_dataset(&root, &sensor, &scans, Some(&sweeps), Some(&truth), None)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("odometry.txt") && err.contains("odometry"),
            "{err}"
        );
        let err = write_dataset(&root, &sensor, &scans, Some(&sweeps), None, Some(&odometry))
            .unwrap_err()
            .to_string();
        assert!(err.contains("poses_truth.txt"), "{err}");

        // clear_dataset removes every dataset entry and nothing else; a file of the user's in
        // scans/ makes it refuse, naming it, before anything is removed.
        std::fs::write(root.join("notes.md"), "mine").unwrap();
        std::fs::write(root.join("scans/mine.txt"), "mine").unwrap();
        std::fs::write(root.join("scans/.000001.ply.tmp-1-0"), "crashed").unwrap();
        let err = clear_dataset(&root).unwrap_err().to_string();
        assert!(
            err.contains("scans/mine.txt") && err.contains("move it out"),
            "{err}"
        );
        assert!(root.join("scans/000002.ply").is_file() && root.join(ATTITUDE_FILE).is_file());
        std::fs::remove_file(root.join("scans/mine.txt")).unwrap();
        clear_dataset(&root).unwrap();
        let left: Vec<_> = std::fs::read_dir(&root)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        assert_eq!(left, vec!["notes.md".to_string()]);
        write_dataset(&root, &sensor, &scans[..2], None, None, None).unwrap();
        let dataset = Dataset::open(&root).unwrap();
        assert!(dataset.odometry.is_none() && dataset.truth.is_none());
    }

    #[test]
    fn open_ignores_hidden_and_foreign_files_and_sorts() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        std::fs::create_dir(root.join("scans")).unwrap();
        std::fs::write(root.join("scans/b.xyz"), "1 2 3\n").unwrap();
        std::fs::write(root.join("scans/a.xyz"), "4 5 6\n").unwrap();
        std::fs::write(root.join("scans/.a.xyz.tmp-1-0"), "junk").unwrap();
        std::fs::write(root.join("scans/.hidden.ply"), "junk").unwrap();
        std::fs::write(root.join("scans/README.md"), "notes").unwrap();
        std::fs::create_dir(root.join("scans/sub.ply")).unwrap();
        std::fs::write(
            root.join("attitude.csv"),
            "index,roll_deg,pitch_deg,yaw_deg\n0,0,0,0\n1,0,0,90\n",
        )
        .unwrap();
        let dataset = Dataset::open(root).unwrap();
        assert_eq!(
            dataset.scan_paths,
            vec![root.join("scans/a.xyz"), root.join("scans/b.xyz")]
        );
        assert_eq!(
            dataset.load_scan(0).unwrap(),
            vec![Vec3::new(4.0, 5.0, 6.0)]
        );
        assert!(dataset.truth.is_none() && dataset.sensor.is_none());
        assert!(dataset.load_sweep(0).unwrap().is_none());
    }

    /// Scans named without zero padding pair with the rows in the order of their numbers:
    /// `scan2` is the third scan, not the twelfth.
    #[test]
    fn open_sorts_unpadded_scan_names_by_number() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        std::fs::create_dir(root.join("scans")).unwrap();
        for i in 0..12 {
            std::fs::write(
                root.join(format!("scans/scan{i}.xyz")),
                format!("{i} 0 0\n"),
            )
            .unwrap();
        }
        let dataset = Dataset::open(root).unwrap();
        let names: Vec<_> = dataset
            .scan_paths
            .iter()
            .map(|p| p.file_name().unwrap().to_str().unwrap().to_string())
            .collect();
        let want: Vec<_> = (0..12).map(|i| format!("scan{i}.xyz")).collect();
        assert_eq!(names, want);
        assert_eq!(
            dataset.load_scan(2).unwrap(),
            vec![Vec3::new(2.0, 0.0, 0.0)]
        );
    }

    /// A file that looks like a scan but is not taken as one is named when the row counts do not
    /// match, so the user sees why.
    #[test]
    fn count_mismatch_names_the_skipped_files() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        std::fs::create_dir(root.join("scans")).unwrap();
        std::fs::write(root.join("scans/000000.xyz"), "1 2 3\n").unwrap();
        std::fs::write(root.join("scans/000001.foo"), "1 2 3\n").unwrap();
        std::fs::write(root.join("scans/000002.xyz"), "1 2 3\n").unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(root.join("gone.ply"), root.join("scans/000003.ply")).unwrap();
        write_attitude_csv(&root.join("attitude.csv"), &[Attitude::default(); 4]).unwrap();
        let err = Dataset::open(root).unwrap_err().to_string();
        assert!(
            err.contains("4 rows") && err.contains("000001.foo (not a point-cloud extension)"),
            "{err}"
        );
        #[cfg(unix)]
        assert!(
            err.contains("000003.ply (a link to a missing file)"),
            "{err}"
        );
        std::fs::remove_file(root.join("attitude.csv")).unwrap();
        crate::write_kitti_poses(&root.join("poses_truth.txt"), &[Pose::identity(); 4]).unwrap();
        let err = Dataset::open(root).unwrap_err().to_string();
        assert!(
            err.contains("4 poses") && err.contains("000001.foo"),
            "{err}"
        );
    }

    /// The readings' σ: per row from attitude.csv's columns, else sensor.toml's, else the
    /// defaults; without attitude.csv the attitude is unknown.
    #[test]
    fn attitude_sigma_from_each_source() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        std::fs::create_dir(root.join("scans")).unwrap();
        for name in ["a.xyz", "b.xyz"] {
            std::fs::write(root.join("scans").join(name), "1 2 3\n").unwrap();
        }
        let yaw_sigma_deg = |d: &Dataset, i: usize| d.attitude(i).unwrap().sigma.yaw.to_degrees();
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;

        // No attitude.csv, no sensor.toml: unknown attitude, default σ.
        let d = Dataset::open(root).unwrap();
        assert_eq!(d.attitude(0), None);
        assert_eq!(d.attitude_sigma, AttitudeSigma::default());
        assert_eq!(d.attitude_sigma_from, SigmaSource::Default);
        assert_eq!(d.attitude_or_level(1), Some(Attitude::default()));

        // sensor.toml's σ: the dataset's, and the level attitude's when there are no readings.
        std::fs::write(root.join("sensor.toml"), "attitude_sigma_yaw_deg = 20\n").unwrap();
        let d = Dataset::open(root).unwrap();
        assert_eq!(d.attitude_sigma_from, SigmaSource::SensorToml);
        assert!(close(d.attitude_sigma.yaw.to_degrees(), 20.0));
        assert!(close(
            d.attitude_or_level(0).unwrap().sigma.yaw.to_degrees(),
            20.0
        ));
        assert_eq!(d.attitude(0), None);

        // Readings without σ columns take sensor.toml's.
        let csv = root.join("attitude.csv");
        std::fs::write(
            &csv,
            "index,roll_deg,pitch_deg,yaw_deg\n0,0,0,0\n1,0,0,90\n",
        )
        .unwrap();
        let d = Dataset::open(root).unwrap();
        assert!(close(yaw_sigma_deg(&d, 1), 20.0));
        assert_eq!(d.attitude_sigma_from, SigmaSource::SensorToml);

        // Per-row σ wins over sensor.toml's.
        std::fs::write(
            &csv,
            "index,roll_deg,pitch_deg,yaw_deg,roll_pitch_sigma_deg,yaw_sigma_deg\n\
             0,0,0,0,0.5,2\n1,0,0,90,0.5,45\n",
        )
        .unwrap();
        let d = Dataset::open(root).unwrap();
        assert!(close(yaw_sigma_deg(&d, 0), 2.0) && close(yaw_sigma_deg(&d, 1), 45.0));
        assert_eq!(d.attitude_sigma_from, SigmaSource::AttitudeCsv);
        assert_eq!(d.attitude_sigma_from.describe(), "attitude.csv");

        // An invalid σ in sensor.toml is an error naming it, even with σ columns in the csv.
        std::fs::write(root.join("sensor.toml"), "attitude_sigma_yaw_deg = -1\n").unwrap();
        let err = Dataset::open(root).unwrap_err().to_string();
        assert!(
            err.contains("sensor.toml:1:") && err.contains("attitude_sigma_yaw_deg"),
            "{err}"
        );
    }

    #[test]
    fn open_errors() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("ds");

        // Not a folder / no scans folder.
        let err = Dataset::open(&root).unwrap_err().to_string();
        assert!(err.contains("ds") && err.contains("scans"), "{err}");
        std::fs::create_dir(&root).unwrap();
        let err = Dataset::open(&root).unwrap_err().to_string();
        assert!(
            err.contains("scans") && err.contains("one point-cloud file per stop"),
            "{err}"
        );

        // Empty scans folder.
        std::fs::create_dir(root.join("scans")).unwrap();
        let err = Dataset::open(&root).unwrap_err().to_string();
        assert!(err.contains("no point-cloud file"), "{err}");

        // No attitude.csv: fine, the attitude is unknown (level when asked for).
        write_points_ply(&root.join("scans/000000.ply"), &scans(1)[0].0).unwrap();
        write_points_ply(&root.join("scans/000001.ply"), &scans(1)[0].0).unwrap();
        let dataset = Dataset::open(&root).unwrap();
        assert!(dataset.attitudes.is_none() && dataset.odometry.is_none());
        assert_eq!(dataset.attitude_or_level(1), Some(Attitude::default()));
        assert_eq!(dataset.attitude_or_level(2), None);

        // Count mismatch names both counts and both paths.
        write_attitude_csv(&root.join("attitude.csv"), &[Attitude::default()]).unwrap();
        let err = Dataset::open(&root).unwrap_err().to_string();
        assert!(
            err.contains("1 row ")
                && err.contains("2 scans")
                && err.contains("attitude.csv")
                && err.contains("scans"),
            "{err}"
        );
        write_attitude_csv(&root.join("attitude.csv"), &[Attitude::default(); 2]).unwrap();
        Dataset::open(&root).unwrap();

        // Truth count mismatch.
        crate::write_kitti_poses(&root.join("poses_truth.txt"), &[Pose::identity(); 3]).unwrap();
        let err = Dataset::open(&root).unwrap_err().to_string();
        assert!(
            err.contains("3 poses") && err.contains("2 scans") && err.contains("poses_truth.txt"),
            "{err}"
        );
        std::fs::remove_file(root.join("poses_truth.txt")).unwrap();

        // Odometry count mismatch, and a malformed odometry line.
        crate::write_kitti_poses(&root.join("odometry.txt"), &[Pose::identity(); 1]).unwrap();
        let err = Dataset::open(&root).unwrap_err().to_string();
        assert!(
            err.contains("1 poses") && err.contains("2 scans") && err.contains("odometry.txt"),
            "{err}"
        );
        std::fs::write(
            root.join("odometry.txt"),
            "1 0 0 0 0 1 0 0 0 0 1 0
1 2 3
",
        )
        .unwrap();
        let err = Dataset::open(&root).unwrap_err().to_string();
        assert!(err.contains("odometry.txt:2"), "{err}");
        crate::write_kitti_poses(&root.join("odometry.txt"), &[Pose::identity(); 2]).unwrap();
        assert_eq!(Dataset::open(&root).unwrap().odometry.unwrap().len(), 2);
        std::fs::remove_file(root.join("odometry.txt")).unwrap();

        // A broken sensor.toml.
        std::fs::write(root.join("sensor.toml"), "bogus = 1\n").unwrap();
        let err = Dataset::open(&root).unwrap_err().to_string();
        assert!(err.contains("sensor.toml:1"), "{err}");
        std::fs::remove_file(root.join("sensor.toml")).unwrap();

        // Out-of-range index.
        let dataset = Dataset::open(&root).unwrap();
        let err = dataset.load_scan(2).unwrap_err();
        assert!(matches!(err, Error::Invalid(_)));
        assert!(
            err.to_string().contains("has 2 scans, numbered 0 to 1"),
            "{err}"
        );
        assert!(dataset.load_sweep(7).is_err());

        // Two files for the same stop.
        std::fs::write(root.join("scans/000001.xyz"), "1 2 3\n").unwrap();
        let err = Dataset::open(&root).unwrap_err().to_string();
        assert!(
            err.contains("000001.ply") && err.contains("000001.xyz"),
            "{err}"
        );
    }

    #[test]
    fn write_dataset_checks_lengths() {
        let dir = tempfile::tempdir().unwrap();
        let sensor = SensorConfig::default();
        let s = scans(2);
        assert!(write_dataset(dir.path(), &sensor, &[], None, None, None).is_err());
        assert!(write_dataset(dir.path(), &sensor, &s, Some(&[sweep()]), None, None).is_err());
        let one = [Pose::identity()];
        assert!(write_dataset(dir.path(), &sensor, &s, None, Some(&one), None).is_err());
        let err = write_dataset(dir.path(), &sensor, &s, None, None, Some(&one)).unwrap_err();
        assert!(
            err.to_string().contains("1 odometry poses for 2 scans"),
            "{err}"
        );
        assert!(!dir.path().join("scans").exists());
    }
}
