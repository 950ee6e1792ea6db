//! Printing helpers shared by the commands.

use anyhow::{Context, Result};
use sdem::geometry::{Pose, PoseRecord};
use serde::Serialize;

/// Prints one JSON object on stdout.
pub fn print_json<T: Serialize>(value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value).context("cannot encode the result as JSON")?;
    println!("{text}");
    Ok(())
}

/// A pose as one human-readable line: centimetres and degrees.
pub fn pose_line(pose: &Pose) -> String {
    let r = PoseRecord::from(pose);
    format!(
        "x {:7.2} cm  y {:7.2} cm  z {:7.2} cm  roll {:6.2}°  pitch {:6.2}°  yaw {:7.2}°",
        r.x * 100.0,
        r.y * 100.0,
        r.z * 100.0,
        r.roll_deg,
        r.pitch_deg,
        r.yaw_deg
    )
}

/// Milliseconds elapsed since `start`.
pub fn elapsed_ms(start: std::time::Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}
