//! A tilting laser's topic made into scans: where the tilt comes from (the laser's frame
//! moving on `/tf`, or a joint of a `JointState` topic), the sweeps, and the sensor model.

use super::collect::{Collected, Kept};
use super::messages::{LaserScan, MessageKind};
use super::plan::{mounting, BagImportOptions, Candidate, Plan};
use super::select::{self, Chosen};
use super::series::{blend_f64, blend_pose, OutOfSpan, Series};
use super::sweeps::{assemble, SweepRules, TiltSource};
use super::tf::{frame_name, TfTree};
use crate::error::{Error, Result};
use sdem::geometry::Pose;
use sdem::sensor::SensorConfig;

/// A pause longer than this between two lines ends a sweep, seconds.
const MAX_LINE_GAP_S: f64 = 1.0;

/// The sweeps of the laser topic `scan`, with the odometry (`odom_from_base` and the base
/// frame) taking the motion during each sweep out.
pub(super) fn plan_sweeps(
    collected: &Collected,
    tree: &TfTree,
    odometry: Option<(&Series<Pose>, &str)>,
    scan: Chosen,
    options: &BagImportOptions,
) -> Result<Plan> {
    let mut lines: Vec<Kept<LaserScan>> = collected
        .laser
        .get(&scan.topic)
        .cloned()
        .unwrap_or_default();
    lines.sort_by_key(|l| l.stamp_ns);
    let laser_frame = lines
        .first()
        .map(|l| frame_name(&l.message.header.frame_id).to_string())
        .unwrap_or_default();
    let (source, sensor_frame, tilt) = tilt_source(collected, tree, &scan, &laser_frame, options)?;
    let base_from_sensor = odometry.map(|(_, base)| mounting(tree, base, &sensor_frame).0);
    let odom_at = |t: i64| -> std::result::Result<Pose, OutOfSpan> {
        match (odometry, base_from_sensor) {
            (Some((series, _)), Some(b)) => Ok(series.at(t, blend_pose)? * b),
            _ => Err(OutOfSpan::Empty),
        }
    };
    let odom: Option<&dyn Fn(i64) -> std::result::Result<Pose, OutOfSpan>> =
        odometry.map(|_| &odom_at as _);
    let mut left_out = Vec::new();
    if options.salvage {
        let before = lines.len();
        lines.retain(|l| {
            let tilt_known = match &source {
                TiltSource::Joint { angle, .. } => angle.at(l.stamp_ns, blend_f64).is_ok(),
                TiltSource::Tf { tree, laser_frame } => {
                    tree.moving_at(laser_frame, l.stamp_ns).is_ok()
                }
            };
            tilt_known && odom.is_none_or(|o| o(l.stamp_ns).is_ok())
        });
        if lines.len() < before {
            left_out.push(format!(
                "{} of {before} lines of {}: their tilt or odometry is unknown at their stamps",
                before - lines.len(),
                scan.topic
            ));
        }
    }
    let rules = SweepRules {
        min_span_deg: options.min_sweep_deg,
        max_line_gap_s: MAX_LINE_GAP_S,
    };
    let sweeps = assemble(&lines, &source, &rules, odom).map_err(|(i, why)| {
        let line = &lines[i];
        Error::parse(
            &line.origin.file,
            None,
            format!(
                "{} #{} (stamp {:.3} s): the laser's tilt or the odometry is unknown there: \
                 {why}; --salvage leaves such lines out",
                scan.topic,
                line.origin.index,
                line.stamp_ns as f64 * 1e-9
            ),
        )
    })?;
    if sweeps.is_empty() {
        return Err(Error::Invalid(format!(
            "{}: no sweep spans {}° of tilt ({} lines, {tilt}); is the laser tilting? \
             --min-sweep sets the least span",
            scan.topic,
            options.min_sweep_deg,
            lines.len()
        )));
    }
    let laser = sensor_model(&lines, &sweeps, &mut left_out);
    let candidates = sweeps
        .into_iter()
        .map(|s| Candidate {
            stamp_ns: s.stamp_ns,
            origin: s.origin.clone(),
            sweep: Some(s),
        })
        .collect();
    Ok(Plan {
        scan,
        sensor_frame,
        candidates,
        tilt: Some(tilt),
        laser,
        left_out,
    })
}

/// Where the tilt comes from, the sensor frame, and both in words.
fn tilt_source<'a>(
    collected: &Collected,
    tree: &'a TfTree,
    scan: &Chosen,
    laser_frame: &str,
    options: &BagImportOptions,
) -> Result<(TiltSource<'a>, String, String)> {
    if options.joint_topic.is_none() {
        if let Some(parent) = tree.moving_parent(laser_frame) {
            let words = format!("/tf moves {laser_frame} in {parent}: the scans are in {parent}");
            let source = TiltSource::Tf {
                tree,
                laser_frame: laser_frame.to_string(),
            };
            return Ok((source, parent.to_string(), words));
        }
    }
    let joint_topic = select::optional_topic(
        collected,
        MessageKind::JointState,
        options.joint_topic.as_deref(),
        "--joint-topic",
    )?
    .ok_or_else(|| {
        Error::Invalid(format!(
            "{} holds the lines of a 2D laser, but the bag says nothing of its tilt: no /tf \
             transform moves its frame {laser_frame} and there is no sensor_msgs/msg/JointState \
             topic; record the tilt joint's states or the laser's /tf",
            scan.topic
        ))
    })?;
    let messages = collected
        .joints
        .get(&joint_topic.topic)
        .map_or(&[][..], Vec::as_slice);
    let names = messages
        .first()
        .map_or(&[][..], |m| m.message.name.as_slice());
    let joint = select::tilt_joint(&joint_topic.topic, names, options.tilt_joint.as_deref())?;
    let samples = messages
        .iter()
        .filter_map(|m| {
            let i = m.message.name.iter().position(|n| *n == joint)?;
            let angle = *m.message.position.get(i)?;
            angle.is_finite().then_some((m.stamp_ns, angle))
        })
        .collect();
    let up_sign = if options.tilt_positive_up { 1.0 } else { -1.0 };
    let words = format!(
        "joint {joint} of {}, a positive angle tilting the scan plane {}",
        joint_topic.topic,
        if options.tilt_positive_up {
            "up (--tilt-positive-up)"
        } else {
            "down (a joint about +y)"
        }
    );
    let source = TiltSource::Joint {
        angle: Series::new(samples),
        up_sign,
    };
    Ok((source, laser_frame.to_string(), words))
}

/// The sensor model of the laser (pan from its lines, tilt from the sweeps), or `None` with a
/// note when it does not fit sdem's model.
fn sensor_model(
    lines: &[Kept<LaserScan>],
    sweeps: &[super::sweeps::SweepScan],
    notes: &mut Vec<String>,
) -> Option<SensorConfig> {
    let first = &lines.first()?.message;
    let pan_step = f64::from(first.angle_increment).to_degrees().abs();
    let pan_min = f64::from(first.angle_min).to_degrees();
    let count = first.ranges.len().max(1);
    let tilt_lo = sweeps.iter().map(|s| s.tilt_deg.0).fold(f64::MAX, f64::min);
    let tilt_hi = sweeps.iter().map(|s| s.tilt_deg.1).fold(f64::MIN, f64::max);
    let lines_per_sweep = sweeps.iter().map(|s| s.lines).max().unwrap_or(2).max(2);
    let sensor = SensorConfig {
        tilt_min_deg: tilt_lo,
        tilt_max_deg: tilt_hi,
        tilt_step_deg: (tilt_hi - tilt_lo) / (lines_per_sweep - 1) as f64,
        pan_min_deg: pan_min,
        pan_max_deg: pan_min + (count - 1) as f64 * pan_step,
        pan_step_deg: pan_step,
        max_range_m: f64::from(first.range_max),
        min_range_m: f64::from(first.range_min).max(0.0),
        ..SensorConfig::default()
    };
    match sensor.validate() {
        Ok(()) => Some(sensor),
        Err(e) => {
            notes.push(format!(
                "no sensor.toml: the laser does not fit sdem's sensor model ({e})"
            ));
            None
        }
    }
}
