//! # sdem-io — files for sdem
//!
//! Point clouds, attitude and pose files, the sensor model, raw sweeps, voxel maps, saved maps
//! and dataset folders.
//!
//! Of sdem's libraries this is the one that touches the file system (the algorithms in `sdem`
//! take and return plain values). Every reader returns [`Error::Parse`] naming the file and, for text, the 1-based line
//! when the content is malformed, and [`Error::Io`] when the operating system fails; no input makes
//! a reader panic or return a silently wrong value (non-finite coordinates and angles are errors,
//! counts declared in headers are checked against the file's size before anything is allocated).
//! Every writer goes through [`write_atomic`], so a crash never leaves a half-written file.
//!
//! Units: metres and radians in memory, degrees in files.
//!
//! # Example
//! A scan written as PLY and read back, as `sdem` reads every scan of a dataset.
//! ```
//! use sdem::geometry::Vec3;
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("scan.ply");
//! let points = vec![Vec3::new(1.0, 0.0, 0.5), Vec3::new(0.0, 2.0, -0.25)];
//! sdem_io::write_points_ply(&path, &points)?;
//! assert_eq!(sdem_io::read_points(&path)?, points);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Point clouds ([`read_points`], [`write_points_ply`])
//!
//! | extension | format |
//! |---|---|
//! | `.ply` | PLY, `ascii`, `binary_little_endian` or `binary_big_endian`; element `vertex` with properties `x`, `y`, `z` stored as `float` or `double`; other properties and elements are ignored; vertices with a NaN coordinate are skipped (no return) |
//! | `.pcd` | PCL PCD, `DATA ascii`, `binary` (little-endian) or `binary_compressed` (LZF, as PCL and Open3D write it); fields `x`, `y`, `z` of `TYPE F`, `SIZE 4` or `8`, `COUNT 1`, in any order among other fields of any type and count, which are ignored; organized clouds (`HEIGHT` > 1) row after row; points with a NaN coordinate are skipped. A `VIEWPOINT` (the sensor's pose in the points' frame) takes the points into the sensor's frame |
//! | `.xyz`, `.txt` | text, one point per line: `x y z` separated by spaces, tabs or commas; further columns ignored; blank lines and everything after `#` (or a line starting with `//`) ignored |
//! | `.bin` | KITTI Velodyne: little-endian `f32` records `x y z intensity`, 16 bytes per point, no header |
//! | `.3d` | 3DTK "uos": text `x y z` in **centimetres**, left-handed with x right, y up, z forward; converted to metres with x forward, y left, z up: `(z, −x, y) / 100`. An optional first line like `360 x 225` is skipped; further columns ignored |
//! | `.las`, `.laz` | ASPRS LAS 1.0–1.4, any point format, uncompressed or LASzip-compressed (`las` and `laz` crates); the header's scale and offset applied; other attributes ignored |
//! | `.sweep` | a raw tilting-LRF sweep (below), turned into points with [`Sweep::points_in_sensor`] |
//!
//! A cloud with no points is an error on reading and on writing: sdem cannot use an empty scan.
//! Infinite coordinates are always an error. A point with a NaN coordinate is skipped in every
//! format: sensors write NaN for "no return". In the text formats (`.xyz`, `.txt`, `.3d`) a field
//! that is no number at all is an error naming the line.
//! Scans are metres in the sensor frame: a coordinate beyond the range of `f32` (in which sdem
//! keeps points) is an error, and so is a scan of which half the points lie farther than
//! [`MAX_MEDIAN_RANGE_M`] (1 km) from the sensor — millimetres, or world coordinates.
//!
//! # `attitude.csv` ([`read_attitude_csv`], [`write_attitude_csv`])
//!
//! ```text
//! index,roll_deg,pitch_deg,yaw_deg
//! 0,0.5,-1.25,90
//! 1,0.25,-1,92.5
//! ```
//! The header exactly as shown, then one row per scan with `index` counting 0, 1, 2, … in order.
//! Angles in degrees, `R = Rz(yaw) · Ry(pitch) · Rx(roll)`. Blank lines are ignored. A roll or
//! pitch beyond ±[`MAX_TILT_READING_DEG`] (360°) is not a reading in degrees and is an error;
//! a yaw may be unwrapped (a gyro heading), up to ±[`MAX_YAW_READING_DEG`] (1e6°, some 2,800
//! turns). `sdem localize --attitude` holds its reading to the same bounds
//! ([`attitude_reading_problem`]).
//!
//! Each reading may carry its own standard deviations (a compass that is good in the open and
//! poor near steel), in two more columns, degrees, with the header
//! [`ATTITUDE_HEADER_WITH_SIGMA`]:
//! ```text
//! index,roll_deg,pitch_deg,yaw_deg,roll_pitch_sigma_deg,yaw_sigma_deg
//! 0,0.5,-1.25,90,0.5,3.5
//! 1,0.25,-1,92.5,0.5,20
//! ```
//! Then every row has all six fields, each σ positive, roll/pitch σ at most 90°, yaw σ at most
//! 180°. Without them (the four-column header) every reading takes the σ of `sensor.toml`, or
//! the defaults (0.5° roll/pitch, 3.5° yaw) ([`read_attitude_readings`]).
//!
//! # Pose files ([`read_kitti_poses`], [`read_tum_poses`], [`write_poses`])
//!
//! KITTI: one pose per line, 12 numbers, the row-major 3×4 matrix `[R | t]` of
//! `world_from_sensor`. On reading, `R` must be a rotation to within 1e-3 (determinant and `RᵀR`)
//! and is re-orthonormalized. TUM: one pose per line, `timestamp x y z qx qy qz qw`; sdem writes
//! the scan index as the timestamp. [`write_poses`] writes a KITTI file and, beside it, the same
//! poses as TUM with the extension `.tum`, so `evo_ape` / `evo_rpe` read either.
//!
//! # `sensor.toml` ([`read_sensor_file`], [`write_sensor_file`]; [`read_sensor_toml`], [`write_sensor_toml`])
//!
//! The fields of [`SensorConfig`] (unknown keys are errors, missing keys take the defaults), then
//! [`SensorConfig::validate`]. An empty file is an error (a truncated one: remove the file to use
//! the defaults). At the top (before any `[table]`), two optional keys state how far the
//! gyro/compass readings of `attitude.csv` can be off, as standard deviations in degrees
//! ([`sdem::geometry::AttitudeSigma`]): `attitude_sigma_roll_pitch_deg` (default 0.5) and
//! `attitude_sigma_yaw_deg` (default 3.5; 180 says the compass tells nothing). Each must be
//! positive, roll/pitch at most 90, yaw at most 180. `sdem::localize` searches the heading over
//! 3σ of the two readings' difference, and flags a match that tilts the scans beyond 3σ of roll
//! and pitch. They are not the simulator's `tilt_sensor_noise_deg` and `compass_noise_deg`
//! (the noise it adds), which a real compass near steel exceeds.
//!
//! # Raw sweeps: the `.sweep` format, version 1 ([`read_sweep`], [`write_sweep`])
//!
//! What a tilting 2D laser range finder produces at one stop, before it becomes points: for each
//! scan line the tilt of the scan plane, the gyro/compass attitude while the line was taken, and
//! the ranges over pan. UTF-8 text; lines end with `\n` (`\r\n` is accepted); values are separated
//! by spaces or tabs. Blank lines and lines whose first non-blank character is `#` are ignored
//! anywhere. The other lines are, in this order:
//!
//! 1. `sdem-sweep 1` — the magic word and the format version (only version 1 exists).
//! 2. `pan_deg PAN_MIN PAN_STEP PAN_COUNT` — every scan line holds `PAN_COUNT` (≥ 1) beams;
//!    beam `k` (0-based) is at pan angle `PAN_MIN + k · PAN_STEP` degrees, counter-clockwise
//!    from forward inside the scan plane. `PAN_STEP` > 0, and every beam's pan angle lies within
//!    ±360°.
//! 3. `lift_slide_m U` — the lift's slide `u` during the sweep, metres (see
//!    [`sdem::sensor::LiftConfig`]), within ±[`MAX_LIFT_SLIDE_M`] (100 m).
//! 4. `lines N` — the number of scan lines that follow (≥ 1).
//! 5. `N` data lines, in the order they were taken, each with `4 + PAN_COUNT` values:
//!    `TILT_DEG ROLL_DEG PITCH_DEG YAW_DEG R_0 R_1 … R_(PAN_COUNT−1)`.
//!    `TILT_DEG` is the tilt of the scan plane, degrees, positive up (beam direction
//!    `(cos θ cos φ, sin φ, sin θ cos φ)` in the sensor frame, see [`sdem::sensor`]).
//!    `ROLL_DEG PITCH_DEG YAW_DEG` is the gyro/compass reading, degrees.
//!    `R_k` is the range of beam `k` in metres, or `nan` where the beam had no return.
//!
//! Nothing but blank and comment lines may follow the last data line, and the last line ends with
//! its line break (a file without one is truncated). All angles and `U` must be finite, roll and
//! pitch within ±[`MAX_TILT_READING_DEG`]; a range must be `nan` or a finite number ≥ 0, and half
//! of the returns must lie within [`MAX_MEDIAN_RANGE_M`] (else the ranges are not in metres).
//! Ranges are 32-bit floats; the writer prints the shortest decimal that reads back to the same
//! `f32`, so a sweep round-trips exactly.
//! Example (the paper's sensor: pan −90°…90° in 1° steps, 86 tilt lines; ranges shortened):
//!
//! ```text
//! sdem-sweep 1
//! pan_deg -90 1 181
//! lift_slide_m 0.55
//! lines 86
//! # tilt_deg roll_deg pitch_deg yaw_deg then 181 ranges in metres (nan = no return)
//! -45 0.01 -0.02 0.1 1.2345 nan 1.25 …
//! -44 0.01 -0.02 0.1 1.2411 1.2398 nan …
//! ```
//!
//! # Voxel maps: the `.sdemvox` format, version 1 ([`read_voxel_map`], [`write_voxel_map`])
//!
//! A [`sdem::voxel::VoxelMap`]: the occupancy log-odds of every known voxel, with the
//! configuration that made them. Binary, little-endian, no padding:
//!
//! | offset | type | content |
//! |---|---|---|
//! | 0 | 8 bytes | the magic `sdem-vox` (ASCII) |
//! | 8 | `u32` | the format version, 1 |
//! | 12 | 6 × `f64` | the [`sdem::voxel::VoxelConfig`]: `voxel_m`, `hit_log_odds`, `miss_log_odds`, `min_log_odds`, `max_log_odds`, `max_range_m` |
//! | 60 | `u64` | `N`, the number of voxel records |
//! | 68 | `N` × 16 bytes | records `i32 i, i32 j, i32 k, f32 log_odds`, sorted by `(i, j, k)`, no key twice |
//! | 68 + 16 `N` | `u32` | CRC-32 (IEEE, as zlib, PNG and gzip compute it) of every byte before it |
//!
//! Voxel `[i, j, k]` is the cube `[i·s, (i+1)·s) × [j·s, (j+1)·s) × [k·s, (k+1)·s)` in the world
//! frame, `s = voxel_m` metres; a log-odds above 0 is occupied, at or below 0 free; voxels not
//! listed are unknown. A reader checks, in this order: the magic, the version (a newer one is
//! reported as such), that the file is exactly `72 + 16 N` bytes, the checksum, the
//! configuration, then that each record's log-odds is finite and within
//! `[min_log_odds, max_log_odds]`, its key within ±10⁹ and after the previous record's key (an
//! error names the record and its byte offset).
//! The checksum is CRC-32 rather than a hash: it catches every burst error up to 32 bits and
//! every 1- to 3-bit error in files far larger than a map, any zlib can check it, and a map file
//! needs protection from damage, not from forgery.
//!
//! # Dataset folders ([`Dataset`], [`write_dataset`], [`clear_dataset`])
//!
//! ```text
//! DATASET/
//!   scans/000000.ply     one point cloud per stop, sensor frame, metres (any format above)
//!   sweeps/000000.sweep  optional: the raw sweep of each stop (the simulator writes them)
//!   attitude.csv         optional: the gyro/compass reading, one row per scan
//!   odometry.txt         optional: dead-reckoned world_from_sensor poses, KITTI (+ odometry.tum)
//!   poses_truth.txt      optional: true world_from_sensor poses, KITTI (+ poses_truth.tum)
//!   poses_slam6d.txt     optional: slam6D's registration of an imported 3DTK folder, KITTI
//!   sensor.toml          optional: the sensor model and the attitude readings' σ
//! ```
//!
//! Every optional per-scan file, when present, has exactly one row (pose) per scan, in the order
//! of the scan files' names, compared naturally (`scan2` before `scan10`; runs of digits by
//! value); a different count is an error naming the file, both counts, and the files in `scans/`
//! that were not taken as scans.
//!
//! - **`attitude.csv` absent**: the robot had no gyro/compass (KITTI), so there is no attitude
//!   measurement ([`Dataset::attitude`] is `None`). `sdem localize` then searches the rotation
//!   (`sdem::localize` with scans of unknown attitude; `--assume-level` takes both as level
//!   instead); the SLAM loop takes the previous scan's estimated attitude as the prior of the
//!   next one and searches heading wider, since no compass bounds it.
//! - **The readings' uncertainty**: each reading has standard deviations
//!   ([`sdem::geometry::Attitude::sigma`]), from `attitude.csv`'s σ columns, else from
//!   `sensor.toml`, else the defaults ([`Dataset::attitude_sigma`], [`Dataset::attitude_sigma_from`]).
//! - **`odometry.txt`**: the robot's dead-reckoned `world_from_sensor` of each scan, in the KITTI
//!   pose format above ([`read_kitti_poses`]). Dead reckoning drifts without bound, so only the
//!   relative motion between consecutive scans, `odometry[i-1]⁻¹ · odometry[i]`, is used (as the
//!   prior of a search window), never the absolute poses. `sdem simulate` writes it with noise
//!   proportional to each step (`sdem_sim::odometry`); `sdem import` writes 3DTK's `.pose` files
//!   there.
//! - **`poses_truth.txt`**: ground truth, used only to report errors. An imported reference that
//!   is not ground truth (slam6D's ICP result) goes to `poses_slam6d.txt` instead.
//!
//! # Importing other datasets ([`import_dataset`], [`import_3dtk`], [`import_kitti`])
//!
//! `sdem import` turns another dataset into the layout above:
//!
//! - **3DTK** (`scanNNN.3d` + `scanNNN.pose`, optionally slam6D's `scanNNN.frames`): scans
//!   converted to sdem's frame as for `.3d` above and written as `scans/NNNNNN.ply`, without the
//!   returns at the scanner's "no return" range (where they pile up at the far end: ~32.76 m on
//!   3DTK's example scans) or nearer than 0.2 m (the robot itself); the scanner's beam and line
//!   steps, measured from the scans' point order, become `sensor.toml`. 3DTK's frame is left-handed, so a pose `M` becomes `C · M · C⁻¹` with the
//!   axis map `C · (x, y, z) = (z, −x, y)` (a reflection) and the translation in metres; a turn
//!   by θ about 3DTK's up axis is a yaw of −θ. The `.pose` files (the robot's initial estimate)
//!   become `odometry.txt` and, through their roll/pitch/yaw, `attitude.csv`; the last line of
//!   each `.frames` becomes `poses_slam6d.txt` — a reference, not ground truth.
//! - **KITTI odometry** (`velodyne/NNNNNN.bin`, `poses.txt`, `calib.txt`): the `.bin` scans are
//!   copied unchanged (the Velodyne frame is sdem's), the camera poses become Velodyne poses
//!   `Tr⁻¹ · P_i · Tr` re-based on the first imported scan in `poses_truth.txt`, and no
//!   `attitude.csv` is written (no gyro/compass).
//! - **E57 surveys** (one `.e57` file, [`import_e57`]): every scan ([`read_e57`]: Cartesian or
//!   spherical, invalid points dropped) in its own frame as `scans/NNNNNN.ply`; the registered
//!   poses, when every scan has one, become `odometry.txt` (translations re-based on the first
//!   scan) and their roll, pitch and yaw `attitude.csv` — a prior, never `poses_truth.txt`.
//!   [`write_e57`] writes scans with poses the same way (`sdem export MAP --e57`).
//!
//! Scans are renumbered from `000000` in the order of their source numbers (E57: of the file).
//!
//! # ROS 2 bags ([`rosbag`]) and MCAP output ([`write_map_mcap`])
//!
//! [`rosbag::import_rosbag`] makes a dataset folder of a ROS 2 bag (rosbag2 MCAP or SQLite3
//! storage, or one `.mcap` file): scans from `PointCloud2` or a tilting laser's `LaserScan`
//! lines, `attitude.csv` from an `Imu`, `odometry.txt` from an `Odometry` topic, all at each
//! scan's stamp and in the sensor frame through `/tf_static`; [`rosbag::bag_info`] says what a
//! bag holds. [`write_map_mcap`] writes a mapped run as MCAP with ROS 2 schemas for Foxglove and
//! RViz. The module documentations give the details.

pub use crate::error::{Error, Result};
use sdem::geometry::Vec3;
use sdem::sensor::{SensorConfig, Sweep};
use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

mod attitude;
mod dataset;
mod e57;
mod error;
mod import;
mod las;
mod map_store;
mod mapfile;
mod mcap_out;
mod pcd;
mod ply;
mod points;
mod poses;
pub mod rosbag;
mod sensor_file;
mod sweep;
mod voxels;

pub use self::e57::{for_each_e57_scan, read_e57, write_e57, E57Scan, E57ScanOut};
pub use attitude::{
    attitude_reading_problem, read_attitude_csv, read_attitude_readings, write_attitude_csv,
    AttitudeReadings, ATTITUDE_HEADER, ATTITUDE_HEADER_WITH_SIGMA, MAX_TILT_READING_DEG,
    MAX_YAW_READING_DEG,
};
pub use dataset::{
    clear_dataset, scans_numbered, write_dataset, write_dataset_streamed, Dataset, DatasetPlan,
    SigmaSource, StreamedScan, ATTITUDE_FILE, DATASET_ENTRIES, ODOMETRY_FILE, SCANS_DIR,
    SENSOR_FILE, SLAM6D_FILE, SWEEPS_DIR, TRUTH_FILE,
};
pub use import::{
    import_3dtk, import_dataset, import_e57, import_kitti, kitti_velodyne_poses,
    parse_kitti_calib_tr, read_kitti_calib_tr, read_uos_frames_last, read_uos_pose,
    uos_matrix_to_world_from_sensor, uos_pose_to_world_from_sensor, ImportFormat, ImportOptions,
    ImportSummary, UOS_MAX_RANGE_M, UOS_MIN_RANGE_M,
};
pub use map_store::MapFolder;
pub use mapfile::{
    foreign_in_map, load_map, save_map, saved_map_folder, NodeFiles, SavedMap, MAP_FORMAT,
    MAP_MANIFEST, MAP_VERSION,
};
pub use mcap_out::{
    point_cloud2_message, write_map_mcap, MapScene, McapSummary, MAP_FRAME, ROBOT_FRAME,
};
pub use ply::write_points_ply;
pub use points::{read_points, PointFormat, MAX_MEDIAN_RANGE_M, POINT_EXTENSIONS};
pub use poses::{
    read_kitti_poses, read_tum_poses, write_kitti_poses, write_poses, write_tum_poses,
};
pub use sensor_file::{
    attitude_sigma_from_degrees, read_sensor_file, write_sensor_file, SensorFile,
    ATTITUDE_SIGMA_ROLL_PITCH_KEY, ATTITUDE_SIGMA_YAW_KEY, MAX_ATTITUDE_SIGMA_ROLL_PITCH_DEG,
    MAX_ATTITUDE_SIGMA_YAW_DEG,
};
pub use sweep::{read_sweep, write_sweep, MAX_LIFT_SLIDE_M, SWEEP_MAGIC, SWEEP_VERSION};
pub use voxels::{read_voxel_map, write_voxel_map, VOXEL_EXTENSION, VOXEL_MAGIC, VOXEL_VERSION};

/// What [`write_atomic`]'s temporary files carry between the target's name and the process id.
const TEMPORARY_MARK: &str = ".tmp-";

/// The name of the file `name` stands for: itself, or the target of a temporary file
/// [`write_atomic`] left (`.NAME.tmp-PID-N`, a crash mid-save).
pub(crate) fn unwrapped_temporary(name: &str) -> &str {
    name.strip_prefix('.')
        .and_then(|n| n.rsplit_once(TEMPORARY_MARK))
        .map_or(name, |(file, _)| file)
}

/// Whether `name` (or the file a temporary one stands for) is numbered as sdem numbers the
/// files it writes by scan or node: six digits, then `.ext` (any extension when `None`).
pub(crate) fn numbered_file(name: &str, ext: Option<&str>) -> bool {
    unwrapped_temporary(name)
        .split_once('.')
        .is_some_and(|(stem, e)| {
            stem.len() == 6
                && stem.bytes().all(|b| b.is_ascii_digit())
                && ext.map_or(!e.is_empty(), |ext| e == ext)
        })
}

/// Writes a file atomically: `write` fills a temporary file in the same folder (named
/// `.NAME.tmp-PID-N`), which is flushed, synced to disk and then renamed over `path`. A crash or
/// an error leaves either the old file or the new one, never a half-written one; on error the
/// temporary file is removed.
///
/// # Arguments
/// * `path` — the file to create or replace; its folder must exist.
/// * `write` — writes the content; it gets a buffered writer.
///
/// # Example
/// ```
/// let dir = std::env::temp_dir().join(format!("sdem-doc-atomic-{}", std::process::id()));
/// std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("hello.txt");
/// sdem_io::write_atomic(&path, |w| w.write_all(b"hello\n")).unwrap();
/// assert_eq!(std::fs::read_to_string(&path).unwrap(), "hello\n");
/// std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let file_name = path.file_name().ok_or_else(|| {
        Error::Invalid(format!(
            "cannot write to {}: the path does not name a file",
            path.display()
        ))
    })?;
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut tmp_name = OsString::from(".");
    tmp_name.push(file_name);
    tmp_name.push(format!(
        "{TEMPORARY_MARK}{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let tmp_path = folder.join(tmp_name);

    let result = (|| -> std::io::Result<()> {
        let file = std::fs::File::create(&tmp_path)?;
        let mut out = std::io::BufWriter::new(file);
        write(&mut out)?;
        out.flush()?;
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        drop(file);
        std::fs::rename(&tmp_path, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp_path);
        return Err(Error::io(path, e));
    }
    // Make the rename itself durable where the platform allows syncing a folder.
    #[cfg(unix)]
    if let Ok(dir) = std::fs::File::open(&folder) {
        let _ = dir.sync_all();
    }
    Ok(())
}

/// Removes the temporary files (`.NAME.tmp-PID-N`, as [`write_atomic`] names them) that a
/// process killed mid-save left in `folder`: those of other processes that are no longer running (on Linux; on
/// other systems, those of every other process). Best effort: a file that cannot be removed is
/// left, as it does no harm but take room.
pub fn remove_stale_temporaries(folder: &Path) {
    let Ok(entries) = std::fs::read_dir(folder) else {
        return;
    };
    let own = std::process::id();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let Some(pid) = name
            .strip_prefix('.')
            .and_then(|n| n.rsplit_once(TEMPORARY_MARK))
            .and_then(|(_, tail)| tail.split_once('-'))
            .and_then(|(pid, _)| pid.parse::<u32>().ok())
        else {
            continue;
        };
        let alive = pid == own
            || (cfg!(target_os = "linux") && Path::new("/proc").join(pid.to_string()).exists());
        if !alive {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// Reads a whole file, mapping OS errors to [`Error::Io`].
fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

/// Reads a whole file as UTF-8 text (a leading byte-order mark is dropped). Invalid UTF-8 is a
/// parse error naming the line where it starts.
fn read_text(path: &Path) -> Result<String> {
    let bytes = read_bytes(path)?;
    text_from_bytes(path, bytes, 0)
}

/// Turns `bytes` into text; `first_line` is the number of lines before `bytes` in the file.
fn text_from_bytes(path: &Path, mut bytes: Vec<u8>, first_line: usize) -> Result<String> {
    if bytes.starts_with(&[0xEF, 0xBB, 0xBF]) {
        bytes.drain(..3);
    }
    String::from_utf8(bytes).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        let bad = e.as_bytes();
        let line = first_line + 1 + bad.get(..valid).map_or(0, count_newlines);
        Error::parse(
            path,
            Some(line),
            "not UTF-8 text; the file is binary or in another encoding",
        )
    })
}

fn count_newlines(bytes: &[u8]) -> usize {
    bytes.iter().filter(|&&b| b == b'\n').count()
}

/// The line of `bytes` that starts at byte `start`, with its `\n` (to the end of `bytes` when
/// there is none), and the offset just past it: a header's next line, read without decoding
/// the binary data after the header.
fn line_from(bytes: &[u8], start: usize) -> (&[u8], usize) {
    let rest = bytes.get(start..).unwrap_or_default();
    let len = rest
        .iter()
        .position(|&b| b == b'\n')
        .map_or(rest.len(), |i| i + 1);
    (rest.get(..len).unwrap_or_default(), start + len)
}

/// Numbered lines of a text: `(1-based line number, line without its line ending)`.
fn numbered_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().map(|(i, l)| (i + 1, l))
}

/// Parses a finite `f64`; `what` names the value in the error message.
fn parse_finite(path: &Path, line: usize, token: &str, what: &str) -> Result<f64> {
    match token.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(v) => Err(Error::parse(
            path,
            Some(line),
            format!("{what} is {v}; it must be a finite number"),
        )),
        Err(_) => Err(Error::parse(
            path,
            Some(line),
            format!("{what} '{token}' is not a number"),
        )),
    }
}

/// Parses a non-negative integer count; `what` names the value in the error message.
fn parse_count(path: &Path, line: usize, token: &str, what: &str) -> Result<usize> {
    token.parse::<usize>().map_err(|_| {
        Error::parse(
            path,
            Some(line),
            format!("{what} '{token}' is not a non-negative whole number"),
        )
    })
}

/// Formats an `f64` so that it reads back bit-for-bit, in plain notation for ordinary magnitudes
/// and in scientific notation for tiny or huge ones (Rust's `{}` never uses an exponent).
fn fmt_f64(value: f64) -> String {
    let magnitude = value.abs();
    if value == 0.0 || (1e-5..1e16).contains(&magnitude) || !value.is_finite() {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}

/// Formats a number for an error message: as `{}` for ordinary magnitudes, with an exponent
/// (`1.000e300`) from 1e6 up and below 1e-4, since `{}` spells out every digit and a damaged
/// file's 1e300 would fill the terminal with a 301-digit number nobody can read. An `f32` keeps
/// its own shortest form (`0.1`, not `0.10000000149011612`).
fn fmt_msg<T: Into<f64> + Copy + std::fmt::Display>(value: T) -> String {
    let wide: f64 = value.into();
    let magnitude = wide.abs();
    if wide == 0.0 || (1e-4..1e6).contains(&magnitude) || !wide.is_finite() {
        format!("{value}")
    } else {
        format!("{wide:.3e}")
    }
}

/// A point for an error message, `(x, y, z)`, each coordinate by [`fmt_msg`].
fn fmt_point(xyz: [f64; 3]) -> String {
    let [x, y, z] = xyz.map(fmt_msg);
    format!("({x}, {y}, {z})")
}

/// Checks that every point is finite and representable as `f32` before writing.
fn check_points_writable(path: &Path, points: &[Vec3]) -> Result<()> {
    if points.is_empty() {
        return Err(Error::Invalid(format!(
            "refusing to write {}: the point cloud is empty (sdem cannot use an empty scan)",
            path.display()
        )));
    }
    for (i, p) in points.iter().enumerate() {
        if !(p.iter().all(|v| v.is_finite() && (*v as f32).is_finite())) {
            return Err(Error::Invalid(format!(
                "refusing to write {}: point {i} is {}; coordinates must be finite and fit in f32",
                path.display(),
                fmt_point([p.x, p.y, p.z])
            )));
        }
    }
    Ok(())
}

/// Turns a sweep file into points in the sensor frame (used by [`read_points`]).
fn sweep_points(path: &Path) -> Result<Vec<Vec3>> {
    let sweep: Sweep = read_sweep(path)?;
    let points = sweep.points_in_sensor();
    if points.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the sweep has no returns (every range is nan or 0), so it gives no points",
        ));
    }
    Ok(points)
}

/// Writes `sensor.toml` with the sensor model alone (no attitude σ; see [`write_sensor_file`]):
/// the configuration is validated first, so sdem never writes a file it would refuse to read.
///
/// # Example
/// ```
/// # let dir = std::env::temp_dir().join(format!("sdem-doc-toml-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// let path = dir.join("sensor.toml");
/// let config = sdem::sensor::SensorConfig::default();
/// sdem_io::write_sensor_toml(&path, &config).unwrap();
/// assert_eq!(sdem_io::read_sensor_toml(&path).unwrap(), config);
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn write_sensor_toml(path: &Path, config: &SensorConfig) -> Result<()> {
    write_sensor_file(
        path,
        &SensorFile {
            sensor: config.clone(),
            attitude_sigma: None,
        },
    )
}

/// Reads `sensor.toml` into a validated [`SensorConfig`] (the sensor model alone; the attitude
/// readings' standard deviations, which the file may state too, are checked and left out: see
/// [`read_sensor_file`] for both). Unknown keys, wrong types and invalid values are parse errors
/// naming the file and the line (for an invalid value, the line of the key the message names,
/// where the file sets it). An empty file is an error too: it is a truncated one (sdem writes
/// every key); remove the file to use the defaults.
pub fn read_sensor_toml(path: &Path) -> Result<SensorConfig> {
    read_sensor_file(path).map(|file| file.sensor)
}

/// Reads the configuration file of `sdem slam --config FILE`: the fields of
/// [`sdem::slam::SlamOptions`] as `sdem slam` writes them into `config.toml` (unknown keys are
/// errors, missing keys take the defaults), then [`sdem::slam::SlamOptions::validate`]. Errors
/// name the file and the line (for an invalid value, the line of the key the message names,
/// where the file sets it), on one line.
pub fn read_slam_config(path: &Path) -> Result<sdem::slam::SlamOptions> {
    let text = read_text(path)?;
    let config: sdem::slam::SlamOptions = parse_toml(
        path,
        &text,
        "the keys are those of the config.toml that sdem slam writes",
    )?;
    at_named_key(path, &text, config.validate())?;
    Ok(config)
}

/// A configuration's validation error as a parse error of `path` at the line of `text` that
/// sets the key the message names (the whole file where none does).
fn at_named_key(path: &Path, text: &str, validated: sdem::Result<()>) -> Result<()> {
    validated.map_err(|e| {
        let message = e.to_string();
        Error::parse(path, line_of_named_key(text, &message), message)
    })
}

/// Parses TOML `text` read from `path`; an error names the file and line on one line (TOML's own
/// message shows the line over several), with `keys` saying what the keys are.
fn parse_toml<T: serde::de::DeserializeOwned>(path: &Path, text: &str, keys: &str) -> Result<T> {
    toml::from_str(text).map_err(|e| toml_error(path, text, e, keys))
}

/// A TOML error in `text` read from `path` as a parse error naming the file and line on one
/// line, with `keys` saying what the keys are.
fn toml_error(path: &Path, text: &str, e: toml::de::Error, keys: &str) -> Error {
    let line = e.span().map(|span| {
        1 + text
            .get(..span.start)
            .map_or(0, |t| count_newlines(t.as_bytes()))
    });
    let message = e.message().split_whitespace().collect::<Vec<_>>().join(" ");
    Error::parse(path, line, format!("{message} ({keys})"))
}

/// The 1-based line of the first `KEY = value` line of a TOML text whose `KEY` the message
/// names (as a whole word).
fn line_of_named_key(text: &str, message: &str) -> Option<usize> {
    let names = |key: &str| {
        message.match_indices(key).any(|(at, _)| {
            let word = |c: char| c.is_alphanumeric() || c == '_';
            let before = message.get(..at).and_then(|m| m.chars().next_back());
            let after = message.get(at + key.len()..).and_then(|m| m.chars().next());
            !before.is_some_and(word) && !after.is_some_and(word)
        })
    };
    numbered_lines(text).find_map(|(line_no, line)| {
        let (key, _) = line.split_once('=')?;
        let key = key.trim();
        (!key.is_empty() && !key.starts_with('#') && names(key)).then_some(line_no)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_atomic_replaces_and_cleans_up() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_atomic(&path, |w| w.write_all(b"one")).unwrap();
        write_atomic(&path, |w| w.write_all(b"two")).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "two");
        // A failing writer leaves the old file and no temporary file.
        let err = write_atomic(&path, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk on fire"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("a.txt"), "{err}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "two");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![OsString::from("a.txt")]);
        // A missing folder is an I/O error naming the target.
        let err = write_atomic(&dir.path().join("nope/b.txt"), |w| w.write_all(b"x")).unwrap_err();
        assert!(matches!(err, Error::Io { .. }) && err.to_string().contains("b.txt"));
    }

    #[test]
    fn fmt_f64_round_trips() {
        for v in [
            0.0,
            -0.0,
            1.0,
            -2.5,
            0.1,
            1e-17,
            5.551115e-17,
            1e300,
            123456.789,
            -1e-5,
        ] {
            let s = fmt_f64(v);
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), v.to_bits(), "{s}");
        }
        assert_eq!(fmt_f64(0.5), "0.5");
        assert_eq!(fmt_f64(1e-17), "1e-17");
    }

    #[test]
    fn messages_print_huge_numbers_compactly() {
        assert_eq!(fmt_msg(1e300), "1.000e300");
        assert_eq!(fmt_msg(-3e38f32), "-3.000e38");
        assert_eq!(fmt_msg(0.1f32), "0.1");
        assert_eq!(fmt_msg(-2.5), "-2.5");
        assert_eq!(fmt_msg(999_999.5), "999999.5");
        assert_eq!(fmt_msg(f64::INFINITY), "inf");
        assert_eq!(
            fmt_point([1e300, 0.0, -1e-300]),
            "(1.000e300, 0, -1.000e-300)"
        );
        // A point of 1e300 (beyond f32) and one of 3e38 (in f32, but kilometres away): both
        // messages stay short and show the number.
        let dir = tempfile::tempdir().unwrap();
        for (text, want) in [("1e300 0 0\n", "1.000e300"), ("3e38 0 0\n", "3.000e38")] {
            let path = dir.path().join("far.xyz");
            std::fs::write(&path, text).unwrap();
            let msg = read_points(&path).unwrap_err().to_string();
            assert!(msg.contains(want) && msg.len() < 400, "{msg}");
        }
    }

    #[test]
    fn invalid_utf8_names_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.xyz");
        std::fs::write(&path, b"1 2 3\n4 5 \xff\n").unwrap();
        let err = read_text(&path).unwrap_err();
        assert!(err.to_string().contains("bad.xyz:2:"), "{err}");
    }

    #[test]
    fn sensor_toml_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sensor.toml");
        let config = SensorConfig {
            trusted_range_m: Some(3.0),
            max_range_m: 7.5,
            ..Default::default()
        };
        write_sensor_toml(&path, &config).unwrap();
        assert_eq!(read_sensor_toml(&path).unwrap(), config);
        // Defaults fill missing keys.
        std::fs::write(&path, "max_range_m = 6.0\n").unwrap();
        let partial = read_sensor_toml(&path).unwrap();
        assert_eq!(partial.max_range_m, 6.0);
        assert_eq!(partial.pan_step_deg, SensorConfig::default().pan_step_deg);
    }

    #[test]
    fn sensor_toml_errors_name_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sensor.toml");
        let cases: &[(&str, Option<&str>)] = &[
            ("tilt_min_deg = -45.0\nmax_rnage_m = 8.0\n", Some(":2:")),
            ("max_range_m = \"far\"\n", Some(":1:")),
            ("max_range_m = 8.0\n[lift\n", Some(":2:")),
            ("pan_step_deg = 0.0\n", None),
            ("min_range_m = nan\n", None),
            ("[lift]\nlink_length_m = -1.0\n", None),
        ];
        for (text, line) in cases {
            std::fs::write(&path, text).unwrap();
            let err = read_sensor_toml(&path).unwrap_err();
            let msg = err.to_string();
            assert!(matches!(err, Error::Parse { .. }), "{msg}");
            assert!(msg.contains("sensor.toml"), "{msg}");
            if let Some(line) = line {
                assert!(msg.contains(line), "{text:?} -> {msg}");
            }
        }
        let invalid = SensorConfig {
            pan_step_deg: -1.0,
            ..Default::default()
        };
        assert!(write_sensor_toml(&path, &invalid).is_err());
        let err = read_sensor_toml(&dir.path().join("missing.toml")).unwrap_err();
        assert!(matches!(err, Error::Io { .. }));
    }
}
