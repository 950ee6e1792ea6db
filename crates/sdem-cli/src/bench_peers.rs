//! The peers of `sdem bench --suite`, run in the same process on the same pairs:
//! `../shared/peers/register_pair.py` (Open3D FPFH + RANSAC + ICP, KISS-Matcher + ICP,
//! small_gicp GICP from identity) on each pair written as PLY files, reference = target,
//! query = source, with the truth given so the script scores itself.
//!
//! Python starts slowly, so the peers get a subset of the pairs; when no Python environment or
//! no script is found the bench says so and goes on without them.

use anyhow::{bail, Context, Result};
use nalgebra::{Matrix3, Translation3, UnitQuaternion};
use sdem::geometry::{pose_error, Pose, PoseRecord, Vec3};
use sdem_sim::benchmark::{summarize, Stats};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The environment variable that names the peers' Python.
pub(crate) const PYTHON_ENV: &str = "SDEM_PEERS_PYTHON";
/// The peers' Python when [`PYTHON_ENV`] is not set (`scripts/peers.sh` makes it).
const DEFAULT_PYTHON: &str = "/tmp/peers-venv/bin/python";
/// The script in the peers' folder.
const SCRIPT: &str = "register_pair.py";

/// The methods run, in the order reported: `(register_pair.py's name, label, short label,
/// global)`. A global method needs no initial guess; small_gicp GICP starts from identity.
pub(crate) const METHODS: [(&str, &str, &str, bool); 3] = [
    (
        "o3d_fpfh_ransac_icp",
        "Open3D FPFH + RANSAC + ICP",
        "FPFH",
        true,
    ),
    ("kiss_matcher_icp", "KISS-Matcher + ICP", "KM", true),
    (
        "small_gicp_gicp",
        "small_gicp GICP from identity",
        "GICP",
        false,
    ),
];

/// The short label of `method` (register_pair.py's name).
pub(crate) fn short_label(method: &str) -> &str {
    METHODS
        .iter()
        .find(|m| m.0 == method)
        .map_or(method, |m| m.2)
}

/// The peers' Python and script, found.
pub(crate) struct Peers {
    python: PathBuf,
    script: PathBuf,
}

/// The default peers' folder: `../shared/peers` beside the repository.
pub(crate) fn default_folder() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/peers")
}

/// Finds the peers: `Ok(Ok(peers))`, or `Ok(Err(why))` when they are absent (the bench goes
/// on without them), or an error when `folder` was given and holds no script.
pub(crate) fn find(folder: Option<&Path>) -> Result<std::result::Result<Peers, String>> {
    let script = match folder {
        Some(dir) => {
            let script = dir.join(SCRIPT);
            if !script.is_file() {
                bail!(
                    "--peers {}: no {SCRIPT} there; the peers' folder is ../shared/peers",
                    dir.display()
                );
            }
            script
        }
        None => {
            let script = default_folder().join(SCRIPT);
            if !script.is_file() {
                return Ok(Err(format!(
                    "no peers' script at {} (--peers DIR names another folder)",
                    shown(&script)
                )));
            }
            script
        }
    };
    let python = match std::env::var_os(PYTHON_ENV) {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(DEFAULT_PYTHON),
    };
    if !python.is_file() {
        let from = if std::env::var_os(PYTHON_ENV).is_some() {
            format!("{PYTHON_ENV}={}", python.display())
        } else {
            format!("{DEFAULT_PYTHON} ({PYTHON_ENV} unset)")
        };
        return Ok(Err(format!(
            "no peers' Python: {from} does not exist (scripts/peers.sh makes /tmp/peers-venv)"
        )));
    }
    Ok(Ok(Peers { python, script }))
}

/// A path as the user would like to read it: canonical where it exists.
pub(crate) fn shown(path: &Path) -> String {
    path.canonicalize()
        .unwrap_or_else(|_| path.to_path_buf())
        .display()
        .to_string()
}

/// The peers' parameters (see `register_pair.py --help`), metres.
#[derive(Debug, Clone, Copy, Serialize)]
pub(crate) struct PeerSettings {
    /// Down-sampling voxel of the local methods and the final ICP.
    pub voxel: f64,
    /// Largest correspondence distance of the local methods.
    pub max_corr: f64,
    /// FPFH + RANSAC voxel.
    pub global_voxel: f64,
    /// KISS-Matcher voxel.
    pub km_voxel: f64,
    /// Timed runs per method; the median is reported (the first also imports the library).
    pub repeat: usize,
}

impl PeerSettings {
    /// For the tilting scanner's indoor scans (the settings of the peers' README).
    pub(crate) fn indoor() -> Self {
        Self {
            voxel: 0.05,
            max_corr: 0.25,
            global_voxel: 0.1,
            km_voxel: 0.2,
            repeat: 3,
        }
    }

    /// For LiDAR scans to 80–100 m: features on a coarse grid, the final ICP on a 10 cm one
    /// (on 25 cm every global method landed in the right basin yet 1–6 cm off on the simulated
    /// pairs: the grid, not the method).
    pub(crate) fn lidar() -> Self {
        Self {
            voxel: 0.1,
            max_corr: 1.0,
            global_voxel: 0.5,
            km_voxel: 0.5,
            repeat: 3,
        }
    }
}

/// One method on one pair.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct PeerResult {
    pub method: String,
    pub time_ms: Option<f64>,
    pub translation_error_m: Option<f64>,
    pub rotation_error_deg: Option<f64>,
    /// The estimated `T_target_source` = `reference_from_query`.
    pub estimate: Option<PoseRecord>,
    pub error: Option<String>,
}

/// Writes `points` as a binary PLY.
pub(crate) fn write_cloud(path: &Path, points: &[Vec3]) -> Result<()> {
    let finite: Vec<Vec3> = points
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .copied()
        .collect();
    sdem_io::write_points_ply(path, &finite)?;
    Ok(())
}

/// Writes `pose` as a 4×4 row-major matrix, one row a line.
pub(crate) fn write_transform(path: &Path, pose: &Pose) -> Result<()> {
    let m = pose.to_homogeneous();
    let mut text = String::new();
    for r in 0..4 {
        let row: Vec<String> = (0..4).map(|c| format!("{}", m[(r, c)])).collect();
        text.push_str(&row.join(" "));
        text.push('\n');
    }
    sdem_io::write_atomic(path, |w| w.write_all(text.as_bytes()))?;
    Ok(())
}

impl Peers {
    /// Runs every method of [`METHODS`] on the pair in `dir` (`reference.ply`, `query.ply`,
    /// `truth.txt`): one result per method, in that order. A failed run gives each method the
    /// error.
    pub(crate) fn run_pair(&self, dir: &Path, settings: &PeerSettings) -> Vec<PeerResult> {
        let names: Vec<&str> = METHODS.iter().map(|m| m.0).collect();
        self.run_methods(dir, settings, &names)
    }

    /// Runs the methods `names` (register_pair.py's) on the pair in `dir`, as
    /// [`Self::run_pair`]: one result per method, in that order.
    pub(crate) fn run_methods(
        &self,
        dir: &Path,
        settings: &PeerSettings,
        names: &[&str],
    ) -> Vec<PeerResult> {
        let output = Command::new(&self.python)
            .arg(&self.script)
            .arg(dir.join("query.ply"))
            .arg(dir.join("reference.ply"))
            .arg("--truth")
            .arg(dir.join("truth.txt"))
            .args(["--methods", &names.join(",")])
            .args(["--voxel", &settings.voxel.to_string()])
            .args(["--max-corr", &settings.max_corr.to_string()])
            .args(["--global-voxel", &settings.global_voxel.to_string()])
            .args(["--km-voxel", &settings.km_voxel.to_string()])
            .args(["--repeat", &settings.repeat.to_string()])
            .output()
            .with_context(|| format!("cannot run {}", self.python.display()));
        let failed = |why: String| {
            names
                .iter()
                .map(|name| PeerResult {
                    method: name.to_string(),
                    time_ms: None,
                    translation_error_m: None,
                    rotation_error_deg: None,
                    estimate: None,
                    error: Some(why.clone()),
                })
                .collect()
        };
        let output = match output {
            Ok(o) => o,
            Err(e) => return failed(format!("{e:#}")),
        };
        if !output.status.success() {
            let stderr = String::from_utf8_lossy(&output.stderr);
            let last = stderr.lines().last().unwrap_or("").to_string();
            return failed(format!("{SCRIPT} exited with {}: {last}", output.status));
        }
        let stdout = String::from_utf8_lossy(&output.stdout);
        let lines: Vec<serde_json::Value> = stdout
            .lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect();
        names
            .iter()
            .map(|name| {
                let line = lines.iter().find(|v| v["method"] == *name);
                match line {
                    None => PeerResult {
                        method: name.to_string(),
                        time_ms: None,
                        translation_error_m: None,
                        rotation_error_deg: None,
                        estimate: None,
                        error: Some(format!("{SCRIPT} printed no line for {name}")),
                    },
                    Some(v) => PeerResult {
                        method: name.to_string(),
                        time_ms: v["time_ms"].as_f64(),
                        translation_error_m: v["trans_err_m"].as_f64(),
                        rotation_error_deg: v["rot_err_deg"].as_f64(),
                        estimate: transform(&v["T"]).as_ref().map(PoseRecord::from),
                        error: v["error"].as_str().map(str::to_string),
                    },
                }
            })
            .collect()
    }
}

/// KISS-ICP's odometry over a sequence ([`Peers::run_odometry`]).
#[derive(Debug, Clone, Serialize)]
pub(crate) struct PeerOdometry {
    /// Absolute translation error, RMSE, both trajectories anchored at their first pose (evo
    /// APE without alignment), metres.
    pub ate_rmse_m: Option<f64>,
    /// Relative translation error between consecutive scans, RMSE, metres.
    pub rpe_translation_rmse_m: Option<f64>,
    /// … and rotation, degrees.
    pub rpe_rotation_rmse_deg: Option<f64>,
    /// Median time of a scan's registration (`register_frame`), ms.
    pub time_ms_median: Option<f64>,
    /// Its poses, one per scan (KITTI format), for the caller to score as it scores its own.
    #[serde(skip)]
    pub poses_file: Option<PathBuf>,
    /// Why it did not run, when it did not.
    pub error: Option<String>,
}

impl Peers {
    /// Runs KISS-ICP odometry (`odometry_seq.py`, beside the pairs' script) over the clouds in
    /// `scans` (`*.ply`, in name order) against the truth `truth` (KITTI poses), with the
    /// sensor's `max_range_m`.
    pub(crate) fn run_odometry(
        &self,
        scans: &Path,
        truth: &Path,
        max_range_m: f64,
    ) -> PeerOdometry {
        let failed = |why: String| PeerOdometry {
            ate_rmse_m: None,
            rpe_translation_rmse_m: None,
            rpe_rotation_rmse_deg: None,
            time_ms_median: None,
            poses_file: None,
            error: Some(why),
        };
        let script = self.script.with_file_name("odometry_seq.py");
        let output = Command::new(&self.python)
            .arg(&script)
            .arg(scans)
            .arg("--gt")
            .arg(truth)
            .args(["--methods", "kiss_icp"])
            .args(["--max-range", &max_range_m.to_string()])
            .arg("--out")
            .arg(scans.join("peer_results"))
            .output();
        let output = match output {
            Ok(o) => o,
            Err(e) => return failed(format!("cannot run {}: {e}", self.python.display())),
        };
        if !output.status.success() {
            let stderr = String::from_utf8_lossy(&output.stderr);
            let last = stderr.lines().last().unwrap_or("").to_string();
            return failed(format!(
                "odometry_seq.py exited with {}: {last}",
                output.status
            ));
        }
        let stdout = String::from_utf8_lossy(&output.stdout);
        let Some(v) = (stdout.lines())
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .find(|v| v["method"] == "kiss_icp")
        else {
            return failed("odometry_seq.py printed no line for kiss_icp".into());
        };
        PeerOdometry {
            ate_rmse_m: v["ape_trans_rmse_m"].as_f64(),
            rpe_translation_rmse_m: v["rpe_trans_rmse_m"].as_f64(),
            rpe_rotation_rmse_deg: v["rpe_rot_rmse_deg"].as_f64(),
            time_ms_median: v["per_scan_ms_median"].as_f64(),
            poses_file: v["poses_file"].as_str().map(PathBuf::from),
            error: v["error"].as_str().map(str::to_string),
        }
    }
}

/// A 4×4 matrix as JSON rows (register_pair.py's `T`, rounded to 6 decimals) as a pose: the
/// rotation the nearest to its 3×3 block.
fn transform(value: &serde_json::Value) -> Option<Pose> {
    let rows = value.as_array()?;
    let mut m = Matrix3::zeros();
    let mut t = Vec3::zeros();
    for r in 0..3 {
        let row = rows.get(r)?.as_array()?;
        for c in 0..3 {
            m[(r, c)] = row.get(c)?.as_f64()?;
        }
        t[r] = row.get(3)?.as_f64()?;
    }
    if !(m.iter().all(|v| v.is_finite()) && t.iter().all(|v| v.is_finite())) {
        return None;
    }
    let rotation = UnitQuaternion::from_matrix(&m);
    Some(Pose::from_parts(Translation3::from(t), rotation))
}

/// One method over the subset.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct MethodReport {
    pub method: String,
    pub label: String,
    /// Needs no initial guess.
    pub global: bool,
    pub pairs: usize,
    /// Pairs where the method ran and returned a pose.
    pub ran: usize,
    pub succeeded: usize,
    pub success_rate: f64,
    pub translation_error_mm: Stats,
    pub rotation_error_deg: Stats,
    pub time_ms: Stats,
    /// The first error, when some runs failed (a library that does not import, say).
    pub first_error: Option<String>,
    /// Pairs where this method's pose and sdem's lie within the success thresholds of each
    /// other: where the truth itself is off (KITTI's first frames), agreement still shows.
    pub agrees_with_sdem: usize,
    /// sdem's median time on the same pairs over this method's.
    pub sdem_time_ratio: Option<f64>,
}

/// Sums up `results[pair][method]` per method, scoring with the thresholds; `sdem_median_ms`
/// is sdem's median time on the same pairs and `sdem_estimates[pair]` its poses.
pub(crate) fn summarize_methods(
    results: &[Vec<PeerResult>],
    sdem_estimates: &[Option<Pose>],
    max_translation_m: f64,
    max_rotation_deg: f64,
    sdem_median_ms: f64,
) -> Vec<MethodReport> {
    METHODS
        .iter()
        .enumerate()
        .map(|(m, &(method, label, _, global))| {
            let rows: Vec<&PeerResult> = results.iter().filter_map(|r| r.get(m)).collect();
            let ok: Vec<&&PeerResult> = rows.iter().filter(|r| r.error.is_none()).collect();
            let translation: Vec<f64> = rows
                .iter()
                .map(|r| r.translation_error_m.map_or(f64::NAN, |t| t * 1e3))
                .collect();
            let rotation: Vec<f64> = rows
                .iter()
                .map(|r| r.rotation_error_deg.unwrap_or(f64::NAN))
                .collect();
            let times: Vec<f64> = ok.iter().filter_map(|r| r.time_ms).collect();
            let succeeded = ok
                .iter()
                .filter(|r| {
                    r.translation_error_m
                        .is_some_and(|t| t <= max_translation_m)
                        && r.rotation_error_deg.is_some_and(|d| d <= max_rotation_deg)
                })
                .count();
            let time_ms = summarize(&times);
            let agrees_with_sdem = results
                .iter()
                .zip(sdem_estimates)
                .filter(|(r, sdem)| {
                    let peer = r.get(m).and_then(|p| p.estimate.as_ref()).map(Pose::from);
                    let (Some(peer), Some(sdem)) = (peer, sdem) else {
                        return false;
                    };
                    let (t, d) = pose_error(&peer, sdem);
                    t <= max_translation_m && d.to_degrees() <= max_rotation_deg
                })
                .count();
            MethodReport {
                method: method.to_string(),
                label: label.to_string(),
                global,
                pairs: rows.len(),
                ran: ok.len(),
                succeeded,
                success_rate: if rows.is_empty() {
                    0.0
                } else {
                    succeeded as f64 / rows.len() as f64
                },
                translation_error_mm: summarize(&translation),
                rotation_error_deg: summarize(&rotation),
                sdem_time_ratio: (time_ms.count > 0).then(|| sdem_median_ms / time_ms.median),
                time_ms,
                first_error: rows.iter().find_map(|r| r.error.clone()),
                agrees_with_sdem,
            }
        })
        .collect()
}
