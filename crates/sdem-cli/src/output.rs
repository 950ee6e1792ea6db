//! Printing helpers shared by the commands, and how a command that printed results ended.

use anyhow::{Context, Result};
use sdem::geometry::{Pose, PoseRecord};
use sdem::Doubt;
use serde::Serialize;
use serde_json::Value;

/// How a command that ran to its end came out; `main` turns it into the exit status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Done, and every result is trusted (or the command makes no claim to trust): status 0.
    Done,
    /// Done, but a result has doubts: it was printed as a best guess, labelled: status 3.
    DoneWithDoubts,
}

impl Outcome {
    /// The outcome of results that are all `trusted` or not; with `accept_doubtful` (the
    /// caller asked for the best guess) a doubtful result still ends as [`Outcome::Done`].
    pub fn of(trusted: bool, accept_doubtful: bool) -> Self {
        if trusted || accept_doubtful {
            Outcome::Done
        } else {
            Outcome::DoneWithDoubts
        }
    }
}

/// The label of a pose line: `estimate` for a trusted result, `best guess (doubtful)` for one
/// with doubts.
pub fn estimate_label(trusted: bool) -> &'static str {
    if trusted {
        "estimate"
    } else {
        "best guess (doubtful)"
    }
}

/// One doubt as JSON: its `kind` and figures (as the library serializes it) and a `message`
/// in words (its `Display`).
pub fn doubt_json(doubt: &Doubt) -> Value {
    let mut value = serde_json::to_value(doubt).unwrap_or_else(|_| {
        // A doubt's fields are numbers and strings; this cannot fail, but never lose the kind.
        serde_json::json!({ "kind": doubt.kind() })
    });
    if let Some(object) = value.as_object_mut() {
        object.insert("message".into(), Value::String(doubt.to_string()));
    }
    value
}

/// Every doubt as JSON, with its message (see [`doubt_json`]).
pub fn doubts_json(doubts: &[Doubt]) -> Vec<Value> {
    doubts.iter().map(doubt_json).collect()
}

/// `value` (a serialized result) with its `doubts` field replaced by `doubts` with their
/// messages.
pub fn with_doubt_messages(mut value: Value, doubts: &[Doubt]) -> Value {
    if let Some(object) = value.as_object_mut() {
        object.insert("doubts".into(), Value::Array(doubts_json(doubts)));
    }
    value
}

/// Prints each doubt as a line `DOUBT: <message>`, indented by `indent`.
pub fn print_doubts(indent: &str, doubts: &[Doubt]) {
    for doubt in doubts {
        println!("{indent}DOUBT: {doubt}");
    }
}

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

/// Degrees as short text, at most two decimals: `3.5`, `14.85`, `20`.
pub fn degrees(value: f64) -> String {
    let text = format!("{value:.2}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Milliseconds elapsed since `start`.
pub fn elapsed_ms(start: std::time::Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}
