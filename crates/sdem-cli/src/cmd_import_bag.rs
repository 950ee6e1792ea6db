//! The ROS 2 bag branch of `sdem import`: its flags, the import with a progress bar, and the
//! summary.

use crate::output::print_json;
use crate::parse::{positive_degrees, positive_metres, positive_seconds};
use anyhow::Result;
use sdem_io::rosbag::{import_rosbag, BagImportOptions, BagImportSummary, StopPolicy, StopRules};
use std::path::Path;
use std::time::Instant;

/// The flags of `sdem import` for ROS 2 bags.
#[derive(clap::Args, Default)]
#[command(next_help_heading = "ROS 2 bags")]
pub struct BagArgs {
    /// The scan topic: sensor_msgs/msg/PointCloud2, or sensor_msgs/msg/LaserScan of a tilting
    /// laser [default: the only topic of either type].
    #[arg(long, value_name = "TOPIC")]
    scan_topic: Option<String>,
    /// The IMU topic (sensor_msgs/msg/Imu) whose orientation gives the attitude [default: the
    /// only one].
    #[arg(long, value_name = "TOPIC")]
    imu_topic: Option<String>,
    /// The odometry topic (nav_msgs/msg/Odometry) [default: the only one].
    #[arg(long, value_name = "TOPIC")]
    odom_topic: Option<String>,
    /// A tilting laser's sensor_msgs/msg/JointState topic [default: the only one; /tf is used
    /// instead when it moves the laser's frame].
    #[arg(long, value_name = "TOPIC")]
    joint_topic: Option<String>,
    /// The laser's tilt joint [default: the joint with "tilt" in its name, or the only one].
    #[arg(long, value_name = "NAME")]
    tilt_joint: Option<String>,
    /// A positive joint angle tilts the scan plane up [default: down, as for a joint about +y].
    #[arg(long)]
    tilt_positive_up: bool,
    /// Leave the IMU out: no attitude.csv (sdem then searches the attitude).
    #[arg(long)]
    no_imu: bool,
    /// Leave the odometry out: no odometry.txt and no motion compensation of sweeps.
    #[arg(long)]
    no_odom: bool,
    /// How scans become stops [default: auto: every scan when they come at most once a second
    /// or are a laser's sweeps, else travelled].
    #[arg(long, value_enum)]
    stops: Option<Stops>,
    /// With travelled stops: the distance between stops, metres [default: 1].
    #[arg(long, value_name = "M", allow_hyphen_values = true, value_parser = positive_metres)]
    stop_distance: Option<f64>,
    /// With travelled stops: the angle turned between stops, degrees [default: 10].
    #[arg(long, value_name = "DEG", allow_hyphen_values = true, value_parser = positive_degrees)]
    stop_angle: Option<f64>,
    /// With travelled stops and no odometry: the time between stops, seconds [default: 1].
    #[arg(long, value_name = "S", allow_hyphen_values = true, value_parser = positive_seconds)]
    stop_interval: Option<f64>,
    /// The least tilt a laser's sweep spans to make a scan, degrees [default: 20].
    #[arg(long, value_name = "DEG", allow_hyphen_values = true, value_parser = positive_degrees)]
    min_sweep: Option<f64>,
    /// Use everything readable before damage (a bag cut short), and leave out the messages that
    /// do not decode and the scans without an attitude or odometry reading; the summary lists
    /// what was left out.
    #[arg(long)]
    salvage: bool,
}

/// The `--stops` values.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Stops {
    /// Every scan when they come at most once a second or are a laser's sweeps, else travelled.
    Auto,
    /// Every scan is a stop.
    EachScan,
    /// A stop per --stop-distance or --stop-angle travelled (by odometry), or per
    /// --stop-interval without odometry.
    Travelled,
}

impl BagArgs {
    /// The flags given, by name, for refusing them on a source that is not a bag.
    pub fn given(&self) -> Vec<&'static str> {
        let flags = [
            ("--scan-topic", self.scan_topic.is_some()),
            ("--imu-topic", self.imu_topic.is_some()),
            ("--odom-topic", self.odom_topic.is_some()),
            ("--joint-topic", self.joint_topic.is_some()),
            ("--tilt-joint", self.tilt_joint.is_some()),
            ("--tilt-positive-up", self.tilt_positive_up),
            ("--no-imu", self.no_imu),
            ("--no-odom", self.no_odom),
            ("--stops", self.stops.is_some()),
            ("--stop-distance", self.stop_distance.is_some()),
            ("--stop-angle", self.stop_angle.is_some()),
            ("--stop-interval", self.stop_interval.is_some()),
            ("--min-sweep", self.min_sweep.is_some()),
            ("--salvage", self.salvage),
        ];
        flags.iter().filter(|(_, g)| *g).map(|(f, _)| *f).collect()
    }

    /// Refuses (a usage error, before anything is read) flags that contradict each other.
    pub fn check(&self) -> Result<()> {
        for (off, off_given, topic, topic_given) in [
            (
                "--no-imu",
                self.no_imu,
                "--imu-topic",
                self.imu_topic.is_some(),
            ),
            (
                "--no-odom",
                self.no_odom,
                "--odom-topic",
                self.odom_topic.is_some(),
            ),
        ] {
            if off_given && topic_given {
                return Err(crate::parse::usage_error(
                    "import",
                    format!("{off} and {topic} contradict each other; give one"),
                ));
            }
        }
        Ok(())
    }

    fn options(&self) -> BagImportOptions {
        let defaults = BagImportOptions::default();
        let rules = StopRules::default();
        BagImportOptions {
            scan_topic: self.scan_topic.clone(),
            imu_topic: self.imu_topic.clone(),
            odom_topic: self.odom_topic.clone(),
            joint_topic: self.joint_topic.clone(),
            tilt_joint: self.tilt_joint.clone(),
            tilt_positive_up: self.tilt_positive_up,
            no_imu: self.no_imu,
            no_odometry: self.no_odom,
            stops: StopRules {
                policy: match self.stops {
                    None | Some(Stops::Auto) => StopPolicy::Auto,
                    Some(Stops::EachScan) => StopPolicy::EachScan,
                    Some(Stops::Travelled) => StopPolicy::Travelled,
                },
                distance_m: self.stop_distance.unwrap_or(rules.distance_m),
                angle_deg: self.stop_angle.unwrap_or(rules.angle_deg),
                interval_s: self.stop_interval.unwrap_or(rules.interval_s),
            },
            min_sweep_deg: self.min_sweep.unwrap_or(defaults.min_sweep_deg),
            salvage: self.salvage,
        }
    }
}

/// Imports the bag `source` into `out` and prints the summary.
pub fn run(source: &Path, out: &Path, args: &BagArgs, json: bool) -> Result<()> {
    let start = Instant::now();
    let bar = crate::progress::bar(1, json, "reading");
    let summary = import_rosbag(source, out, &args.options(), &mut |p| {
        bar.set_length(p.total.max(1));
        bar.set_message(p.phase);
        bar.set_position(p.done);
    });
    bar.finish_and_clear();
    let summary = summary?;
    let seconds = start.elapsed().as_secs_f64();
    if json {
        let mut value = serde_json::to_value(&summary)?;
        value["time_ms"] = serde_json::json!(seconds * 1e3);
        return print_json(&value);
    }
    print_text(&summary, seconds);
    Ok(())
}

fn print_text(s: &BagImportSummary, seconds: f64) {
    println!(
        "imported {} stops from {} ({}) to {} in {seconds:.1} s",
        s.stops,
        s.source.display(),
        s.storage.name(),
        s.out.display()
    );
    println!(
        "  scans: {} ({}), frame {}; {} in the bag, stops: {}",
        s.scan_topic.topic, s.scan_topic.why, s.sensor_frame, s.scans_in_bag, s.stop_rule
    );
    if let Some(tilt) = &s.tilt {
        println!("  tilt: {tilt}");
    }
    let n = &s.points_per_scan;
    println!(
        "  points: {}..{} per scan",
        n.iter().min().unwrap_or(&0),
        n.iter().max().unwrap_or(&0)
    );
    if s.motion_compensated_sweeps > 0 {
        println!(
            "  motion compensated: {} sweeps, by up to {:.3} m",
            s.motion_compensated_sweeps, s.largest_compensation_m
        );
    }
    let sigma = match s.attitude_sigma_deg {
        Some([rp, yaw]) => {
            format!("; σ {rp:.2}° roll/pitch, {yaw:.2}° heading (the IMU's covariance)")
        }
        None => String::new(),
    };
    println!("  attitude: {}{sigma}", s.attitude);
    match &s.odom_topic {
        Some(o) => println!("  odometry: {} ({})", o.topic, o.why),
        None => println!("  odometry: none (no odometry.txt)"),
    }
    println!("  mounting: {}", s.mounting);
    if let Some(damage) = &s.damage {
        println!("  DAMAGED, salvaged: {}", damage.describe());
    }
    for line in &s.left_out {
        println!("  left out: {line}");
    }
    println!("  wrote {}", s.written.join(", "));
}
