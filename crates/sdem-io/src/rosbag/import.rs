//! `sdem import BAG`: a ROS 2 bag made into a dataset folder: one scan per stop in the
//! sensor frame, the attitude of the sensor at each stop (`attitude.csv`), the odometry's pose
//! of the sensor at each stop (`odometry.txt`).

use super::collect::{collect, CloudEntry, Collected, Kept};
use super::messages::{self, rotation_of, MessageKind};
use super::plan::{mounting, BagImportOptions, Candidate, Plan};
use super::pointcloud::CloudLayout;
use super::select::{self, Chosen};
use super::series::{blend_pose, OutOfSpan, Series};
use super::stops;
use super::storage::{Bag, BagMessage, Damage, Storage};
use super::tf::{frame_name, TfTree};
use crate::error::{Error, Result};
use crate::import::{check_out, write_or_roll_back};
use crate::{write_attitude_csv, write_points_ply, write_poses, write_sensor_toml};
use crate::{ATTITUDE_FILE, ODOMETRY_FILE, SCANS_DIR, SENSOR_FILE};
use sdem::geometry::{Attitude, Pose, Vec3};
use sdem::sensor::SensorConfig;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// How far an import has come, for a progress bar.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImportProgress {
    /// `reading` (the first pass), `writing` (the second pass, the scans' points).
    pub phase: &'static str,
    /// Bytes of the bag read in this phase.
    pub done: u64,
    /// The bag's size, bytes.
    pub total: u64,
}

/// What a bag import read and wrote.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BagImportSummary {
    /// The bag.
    pub source: PathBuf,
    /// The dataset folder written.
    pub out: PathBuf,
    /// The bag's storage.
    pub storage: Storage,
    /// The scan topic and why.
    pub scan_topic: Chosen,
    /// The frame the scans are in (the sensor frame).
    pub sensor_frame: String,
    /// The IMU topic, when one was used.
    pub imu_topic: Option<Chosen>,
    /// The odometry topic, when one was used.
    pub odom_topic: Option<Chosen>,
    /// Where a tilting laser's tilt came from, in words.
    pub tilt: Option<String>,
    /// Scans on the topic (clouds, or sweeps assembled from the laser's lines).
    pub scans_in_bag: usize,
    /// Stops written.
    pub stops: usize,
    /// How the stops were chosen, in words.
    pub stop_rule: String,
    /// The bag stamp of each stop, seconds.
    pub stop_stamps_s: Vec<f64>,
    /// The points of each stop.
    pub points_per_scan: Vec<usize>,
    /// The sensor's mounting on the robot (`base_from_sensor`), in words.
    pub mounting: String,
    /// How the IMU's orientation was turned into the sensor's attitude, in words.
    pub attitude: String,
    /// The standard deviations of roll/pitch and heading (degrees) the IMU's covariance
    /// states, written into attitude.csv; `None` when it states none.
    pub attitude_sigma_deg: Option<[f64; 2]>,
    /// Sweeps whose lines were moved to undo the robot's motion during the sweep.
    pub motion_compensated_sweeps: usize,
    /// The largest such correction, metres.
    pub largest_compensation_m: f64,
    /// Where the bag is damaged, when it is (imported with `--salvage`).
    pub damage: Option<Damage>,
    /// What was left out, in words (undecodable messages, scans without attitude, …).
    pub left_out: Vec<String>,
    /// The files written, relative to `out` (`scans/` stands for the scan files).
    pub written: Vec<String>,
}

/// The odometry of the sensor over time.
struct OdometryTrack {
    chosen: Chosen,
    odom_from_base: Series<Pose>,
    base_frame: String,
}

/// Imports the ROS 2 bag `source` (a rosbag2 folder or one `.mcap`/`.db3` file) into the
/// dataset folder `out`; see the module documentation of [`crate::rosbag`].
///
/// # Errors
/// A bag that cannot be opened or read, damage (without `salvage`), topics that cannot be
/// chosen, scans without readable points, an IMU or odometry that does not cover a scan's
/// stamp (without `salvage`), and any error writing the dataset (which is then removed).
pub fn import_rosbag(
    source: &Path,
    out: &Path,
    options: &BagImportOptions,
    progress: &mut dyn FnMut(ImportProgress),
) -> Result<BagImportSummary> {
    check_options(options)?;
    let bag = Bag::open(source)?;
    check_out(out)?;
    let total = bag.size_bytes();
    let mut collected = collect(&bag, options.salvage, &mut |done| {
        progress(ImportProgress {
            phase: "reading",
            done,
            total,
        })
    })?;
    check_damage(&collected, options)?;
    let tree = TfTree::new(
        &collected.tf_static,
        std::mem::take(&mut collected.tf_moving),
    );
    let odometry = odometry_track(&collected, options)?;
    let plan = plan_scans(&collected, &tree, odometry.as_ref(), options)?;
    let base_frame = odometry
        .as_ref()
        .map_or("base_link", |o| o.base_frame.as_str());
    let (base_from_sensor, mounting) = mounting(&tree, base_frame, &plan.sensor_frame);
    let odom_at = |t: i64| -> std::result::Result<Pose, OutOfSpan> {
        let track = odometry.as_ref().ok_or(OutOfSpan::Empty)?;
        Ok(track.odom_from_base.at(t, blend_pose)? * base_from_sensor)
    };
    let imu = imu_track(&collected, &tree, &plan.sensor_frame, options)?;
    let stamps: Vec<i64> = plan.candidates.iter().map(|c| c.stamp_ns).collect();
    let (policy, stop_rule) = stops::resolve(options.stops.policy, &stamps, plan.laser.is_some());
    let chosen = stops::choose(
        &stamps,
        policy,
        &options.stops,
        odometry.as_ref().map(|_| &odom_at as &dyn Fn(i64) -> _),
    );
    let mut left_out = plan.left_out;
    let stops = readings_at_stops(
        &plan.candidates,
        &chosen,
        &plan.scan,
        &imu,
        &odometry,
        &odom_at,
        options,
        &mut left_out,
    )?;
    if stops.is_empty() {
        return Err(Error::Invalid(format!(
            "no scan of {} can be imported ({}); nothing was written",
            plan.scan.topic,
            left_out.join("; ")
        )));
    }
    let mut summary = BagImportSummary {
        source: source.to_path_buf(),
        out: out.to_path_buf(),
        storage: bag.storage,
        scan_topic: plan.scan.clone(),
        sensor_frame: plan.sensor_frame.clone(),
        imu_topic: imu.as_ref().map(|i| i.chosen.clone()),
        odom_topic: odometry.as_ref().map(|o| o.chosen.clone()),
        tilt: plan.tilt.clone(),
        scans_in_bag: plan.candidates.len(),
        stops: stops.len(),
        stop_rule,
        stop_stamps_s: stops.iter().map(|s| s.stamp_ns as f64 * 1e-9).collect(),
        points_per_scan: Vec::new(),
        mounting,
        attitude: imu.as_ref().map_or_else(
            || "none: no attitude.csv (sdem searches the attitude)".to_string(),
            |i| i.describe.clone(),
        ),
        attitude_sigma_deg: imu.as_ref().and_then(|i| i.sigma_deg),
        motion_compensated_sweeps: 0,
        largest_compensation_m: 0.0,
        damage: collected.damage.clone(),
        left_out,
        written: Vec::new(),
    };
    write_or_roll_back(out, || {
        write_scans(
            &bag,
            out,
            &plan.scan.topic,
            &plan.candidates,
            &stops,
            &mut summary,
            &mut |done| {
                progress(ImportProgress {
                    phase: "writing",
                    done,
                    total,
                })
            },
        )?;
        write_readings(out, &stops, imu.as_ref(), plan.laser.as_ref(), &mut summary)
    })?;
    Ok(summary)
}

fn check_options(options: &BagImportOptions) -> Result<()> {
    let rules = &options.stops;
    let positive = [
        ("--stop-distance", rules.distance_m),
        ("--stop-angle", rules.angle_deg),
        ("--stop-interval", rules.interval_s),
        ("--min-sweep", options.min_sweep_deg),
    ];
    for (flag, value) in positive {
        if !(value.is_finite() && value > 0.0) {
            return Err(Error::Invalid(format!(
                "{flag} {value} must be a positive number"
            )));
        }
    }
    Ok(())
}

/// Refuses a damaged bag unless `salvage`.
fn check_damage(collected: &Collected, options: &BagImportOptions) -> Result<()> {
    let Some(damage) = &collected.damage else {
        return Ok(());
    };
    if !options.salvage {
        return Err(Error::Invalid(format!(
            "{}; pass --salvage to import everything read before the damage (a bag whose \
             recording was killed may also be mended with `ros2 bag reindex`)",
            damage.describe()
        )));
    }
    Ok(())
}

/// The odometry topic's poses, unless left out.
fn odometry_track(
    collected: &Collected,
    options: &BagImportOptions,
) -> Result<Option<OdometryTrack>> {
    if options.no_odometry {
        return Ok(None);
    }
    let Some(chosen) = select::optional_topic(
        collected,
        MessageKind::Odometry,
        options.odom_topic.as_deref(),
        "--odom-topic",
    )?
    else {
        return Ok(None);
    };
    let messages = collected
        .odometry
        .get(&chosen.topic)
        .map_or(&[][..], Vec::as_slice);
    let mut samples = Vec::with_capacity(messages.len());
    for m in messages {
        match messages::pose_of(m.message.position, m.message.orientation) {
            Some(pose) => samples.push((m.stamp_ns, pose)),
            None if options.salvage => {}
            None => {
                return Err(Error::parse(
                    &m.origin.file,
                    None,
                    format!(
                        "{} message #{}: its pose is not finite or its orientation not a unit \
                         quaternion; --salvage skips such messages, --no-odom leaves odometry out",
                        chosen.topic, m.origin.index
                    ),
                ))
            }
        }
    }
    let base_frame = messages
        .first()
        .map(|m| frame_name(&m.message.child_frame_id).to_string())
        .filter(|f| !f.is_empty())
        .unwrap_or_else(|| "base_link".to_string());
    Ok(Some(OdometryTrack {
        chosen,
        odom_from_base: Series::new(samples),
        base_frame,
    }))
}

/// The scans of the chosen topic: clouds as they are, a laser's lines assembled into sweeps.
fn plan_scans(
    collected: &Collected,
    tree: &TfTree,
    odometry: Option<&OdometryTrack>,
    options: &BagImportOptions,
) -> Result<Plan> {
    let scan = select::scan_topic(collected, options.scan_topic.as_deref())?;
    if scan.kind == MessageKind::PointCloud2 {
        let entries = collected
            .clouds
            .get(&scan.topic)
            .map_or(&[][..], Vec::as_slice);
        return plan_clouds(scan, entries, tree, options);
    }
    super::laser::plan_sweeps(
        collected,
        tree,
        odometry.map(|o| (&o.odom_from_base, o.base_frame.as_str())),
        scan,
        options,
    )
}

fn plan_clouds(
    scan: Chosen,
    entries: &[CloudEntry],
    tree: &TfTree,
    options: &BagImportOptions,
) -> Result<Plan> {
    let mut candidates = Vec::new();
    let mut left_out = Vec::new();
    for entry in entries {
        match &entry.returns {
            Ok(0) => left_out.push(format!(
                "{} #{}: no point with a return",
                scan.topic, entry.origin.index
            )),
            Ok(_) => candidates.push(Candidate {
                stamp_ns: entry.stamp_ns,
                origin: entry.origin.clone(),
                sweep: None,
            }),
            Err(why) if options.salvage => {
                left_out.push(format!("{} #{}: {why}", scan.topic, entry.origin.index));
            }
            Err(why) => {
                return Err(Error::parse(
                    &entry.origin.file,
                    None,
                    format!(
                        "{} message #{}: {why}; --salvage leaves such clouds out",
                        scan.topic, entry.origin.index
                    ),
                ))
            }
        }
    }
    candidates.sort_by_key(|c| c.stamp_ns);
    let sensor_frame = entries
        .first()
        .map(|e| frame_name(&e.frame_id).to_string())
        .unwrap_or_default();
    // Clouds in a world frame (a map sdem or another tool exported, already aligned): taken as
    // scans in their sensor's frame, every stop would seem to stand at the origin, and the map
    // would be wrong with no doubt.
    if let (Some(first), Some(moved)) = (entries.first(), tree.world_frame_moving(&sensor_frame)) {
        return Err(Error::parse(
            &first.origin.file,
            None,
            format!(
                "{} is in frame {sensor_frame}, in which /tf moves {moved}: its points are in a \
                 world frame (an aligned map's), not in their sensor's; sdem imports scans as \
                 the sensor took them (for a map sdem exported, draw its slam output folder \
                 with sdem view map, or open the MCAP itself in Foxglove)",
                scan.topic
            ),
        ));
    }
    if let Some(other) = entries
        .iter()
        .find(|e| frame_name(&e.frame_id) != sensor_frame)
    {
        left_out.push(format!(
            "note: {} #{} is in frame {}, the first cloud in {sensor_frame}; every cloud is \
             taken as in the sensor frame",
            scan.topic, other.origin.index, other.frame_id
        ));
    }
    Ok(Plan {
        scan,
        sensor_frame,
        candidates,
        tilt: None,
        laser: None,
        left_out,
    })
}

/// The IMU's orientation over time turned into the sensor's attitude.
pub(super) struct ImuTrack {
    chosen: Chosen,
    /// `world_from_imu` over time (rotation only).
    world_from_imu: Series<Pose>,
    imu_from_sensor: Pose,
    sigma_deg: Option<[f64; 2]>,
    describe: String,
}

impl ImuTrack {
    fn attitude_at(&self, stamp: i64) -> std::result::Result<Attitude, OutOfSpan> {
        let world_from_sensor = self.world_from_imu.at(stamp, blend_pose)? * self.imu_from_sensor;
        let attitude = Attitude::from_quaternion(&world_from_sensor.rotation);
        Ok(match self.sigma_deg {
            Some([rp, yaw]) => attitude.with_sigma_deg(rp, yaw),
            None => attitude,
        })
    }
}

/// The IMU topic's orientations, unless left out or without orientation.
fn imu_track(
    collected: &Collected,
    tree: &TfTree,
    sensor_frame: &str,
    options: &BagImportOptions,
) -> Result<Option<ImuTrack>> {
    if options.no_imu {
        return Ok(None);
    }
    let Some(chosen) = select::optional_topic(
        collected,
        MessageKind::Imu,
        options.imu_topic.as_deref(),
        "--imu-topic",
    )?
    else {
        return Ok(None);
    };
    let messages = collected
        .imu
        .get(&chosen.topic)
        .map_or(&[][..], Vec::as_slice);
    let with_orientation: Vec<&Kept<messages::Imu>> = messages
        .iter()
        .filter(|m| m.message.orientation_covariance[0] != -1.0)
        .collect();
    let samples: Vec<(i64, Pose)> = with_orientation
        .iter()
        .filter_map(|m| {
            rotation_of(m.message.orientation)
                .map(|q| (m.stamp_ns, Pose::from_parts(Default::default(), q)))
        })
        .collect();
    if samples.is_empty() {
        return Err(Error::Invalid(format!(
            "{} gives no orientation (orientation_covariance[0] = -1 or a zero quaternion in \
             every message); name an IMU topic with orientation (--imu-topic) or leave the \
             attitude out with --no-imu",
            chosen.topic
        )));
    }
    let imu_frame = with_orientation
        .first()
        .map(|m| frame_name(&m.message.header.frame_id).to_string())
        .unwrap_or_default();
    let (imu_from_sensor, describe) = match tree.fixed_transform(&imu_frame, sensor_frame) {
        Some(pose) if imu_frame == sensor_frame => (
            pose,
            format!(
                "{}'s orientation of {imu_frame}, the clouds' own frame",
                chosen.topic
            ),
        ),
        Some(pose) => (
            pose,
            format!(
                "{}'s orientation of {imu_frame}, turned into {sensor_frame} through /tf_static",
                chosen.topic
            ),
        ),
        None => (
            Pose::identity(),
            format!(
                "{}'s orientation of {imu_frame}, taken as {sensor_frame}'s: no /tf_static \
                 transform joins them (identity)",
                chosen.topic
            ),
        ),
    };
    Ok(Some(ImuTrack {
        sigma_deg: sigma_of(&with_orientation),
        chosen,
        world_from_imu: Series::new(samples),
        imu_from_sensor,
        describe,
    }))
}

/// The median σ of roll/pitch and heading, degrees, that the IMU's covariance states (the
/// larger of x and y for roll/pitch, z for the heading), bounded to what `attitude.csv`
/// holds; `None` when it states none (zeros, "unknown").
fn sigma_of(messages: &[&Kept<messages::Imu>]) -> Option<[f64; 2]> {
    let mut rp = Vec::new();
    let mut yaw = Vec::new();
    for m in messages {
        let c = m.message.orientation_covariance;
        if c[0] > 0.0 && c[4] > 0.0 && c[8] > 0.0 && c.iter().all(|v| v.is_finite()) {
            rp.push(c[0].max(c[4]).sqrt().to_degrees());
            yaw.push(c[8].sqrt().to_degrees());
        }
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (!rp.is_empty()).then(|| {
        [
            median(rp).clamp(1e-3, crate::MAX_ATTITUDE_SIGMA_ROLL_PITCH_DEG),
            median(yaw).clamp(1e-3, crate::MAX_ATTITUDE_SIGMA_YAW_DEG),
        ]
    })
}

/// A stop with its readings.
struct Stop {
    candidate: usize,
    stamp_ns: i64,
    attitude: Option<Attitude>,
    odom_from_sensor: Option<Pose>,
}

/// The attitude and odometry at each chosen scan; a scan they do not cover is an error, or
/// with `salvage` left out.
#[allow(clippy::too_many_arguments)]
fn readings_at_stops(
    candidates: &[Candidate],
    chosen: &[usize],
    scan: &Chosen,
    imu: &Option<ImuTrack>,
    odometry: &Option<OdometryTrack>,
    odom_at: &dyn Fn(i64) -> std::result::Result<Pose, OutOfSpan>,
    options: &BagImportOptions,
    left_out: &mut Vec<String>,
) -> Result<Vec<Stop>> {
    let mut stops = Vec::new();
    for &i in chosen {
        let c = &candidates[i];
        let attitude = imu
            .as_ref()
            .map(|t| (t.attitude_at(c.stamp_ns), &t.chosen, "--no-imu"));
        let odometry_reading = odometry
            .as_ref()
            .map(|t| (odom_at(c.stamp_ns), &t.chosen, "--no-odom"));
        let problem = [
            attitude
                .as_ref()
                .and_then(|(r, topic, flag)| r.as_ref().err().map(|e| (e, *topic, *flag))),
            odometry_reading
                .as_ref()
                .and_then(|(r, topic, flag)| r.as_ref().err().map(|e| (e, *topic, *flag))),
        ]
        .into_iter()
        .flatten()
        .next();
        if let Some((why, topic, flag)) = problem {
            let what = format!(
                "{} #{} (stamp {:.3} s) has no reading on {}: {why}",
                scan.topic,
                c.origin.index,
                c.stamp_ns as f64 * 1e-9,
                topic.topic
            );
            if options.salvage {
                left_out.push(what);
                continue;
            }
            return Err(Error::parse(
                &c.origin.file,
                None,
                format!(
                    "{what}; --salvage imports only the scans it covers, {flag} leaves {} out",
                    topic.topic
                ),
            ));
        }
        stops.push(Stop {
            candidate: i,
            stamp_ns: c.stamp_ns,
            attitude: attitude.and_then(|(r, _, _)| r.ok()),
            odom_from_sensor: odometry_reading.and_then(|(r, _, _)| r.ok()),
        });
    }
    Ok(stops)
}

/// Writes `scans/NNNNNN.ply`: clouds read again from the bag (the second pass), sweeps from
/// memory.
#[allow(clippy::too_many_arguments)]
fn write_scans(
    bag: &Bag,
    out: &Path,
    topic: &str,
    candidates: &[Candidate],
    stops: &[Stop],
    summary: &mut BagImportSummary,
    progress: &mut dyn FnMut(u64),
) -> Result<()> {
    let scans_dir = out.join(SCANS_DIR);
    let name = |stop: usize| scans_dir.join(format!("{stop:06}.ply"));
    let mut points_per_scan = vec![0usize; stops.len()];
    let mut wanted: HashMap<u64, usize> = HashMap::new();
    for (stop, s) in stops.iter().enumerate() {
        let c = &candidates[s.candidate];
        match &c.sweep {
            Some(sweep) => {
                write_points_ply(&name(stop), &sweep.points)?;
                points_per_scan[stop] = sweep.points.len();
                if sweep.compensation_m > 0.0 {
                    summary.motion_compensated_sweeps += 1;
                    summary.largest_compensation_m =
                        summary.largest_compensation_m.max(sweep.compensation_m);
                }
            }
            None => {
                wanted.insert(c.origin.index, stop);
            }
        }
    }
    if !wanted.is_empty() {
        // Damage was reported by the first pass (and accepted with --salvage).
        let _damage = bag.read(
            &mut |m: &BagMessage| {
                if m.topic != topic {
                    return Ok(());
                }
                let Some(&stop) = wanted.get(&m.index) else {
                    return Ok(());
                };
                let points = cloud_points(m)?;
                write_points_ply(&name(stop), &points)?;
                points_per_scan[stop] = points.len();
                wanted.remove(&m.index);
                Ok(())
            },
            progress,
        )?;
        if let Some((index, _)) = wanted.iter().next() {
            return Err(Error::Invalid(format!(
                "{topic} #{index} was readable in the first pass over {} but not in the second; \
                 is the bag being written to?",
                bag.path.display()
            )));
        }
    }
    summary.points_per_scan = points_per_scan;
    summary.written.push(format!("{SCANS_DIR}/"));
    Ok(())
}

fn cloud_points(m: &BagMessage) -> Result<Vec<Vec3>> {
    let fail = |why: String| {
        Error::parse(
            m.file,
            None,
            format!("{} message #{}: {why}", m.topic, m.index),
        )
    };
    let cloud = messages::point_cloud2(m.data).map_err(|e| fail(e.to_string()))?;
    let layout = CloudLayout::of(&cloud).map_err(fail)?;
    Ok(layout.points(&cloud).points)
}

/// Writes `attitude.csv`, `odometry.txt` (+ `.tum`) and, for a laser, `sensor.toml`.
fn write_readings(
    out: &Path,
    stops: &[Stop],
    imu: Option<&ImuTrack>,
    laser: Option<&SensorConfig>,
    summary: &mut BagImportSummary,
) -> Result<()> {
    if imu.is_some() {
        let attitudes: Vec<Attitude> = stops.iter().filter_map(|s| s.attitude).collect();
        write_attitude_csv(&out.join(ATTITUDE_FILE), &attitudes)?;
        summary.written.push(ATTITUDE_FILE.to_string());
    }
    let odometry: Vec<Pose> = stops.iter().filter_map(|s| s.odom_from_sensor).collect();
    if !odometry.is_empty() {
        write_poses(&out.join(ODOMETRY_FILE), &odometry)?;
        summary.written.push(ODOMETRY_FILE.to_string());
        summary.written.push("odometry.tum".to_string());
    }
    if let Some(sensor) = laser {
        write_sensor_toml(&out.join(SENSOR_FILE), sensor)?;
        summary.written.push(SENSOR_FILE.to_string());
    }
    Ok(())
}
