//! Printing helpers shared by the commands, and how a command that printed results ended.

use anyhow::{bail, Context, Result};
use sdem::geometry::{Pose, PoseRecord};
use sdem::Doubt;
use serde::Serialize;
use serde_json::Value;
use std::path::Path;

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

/// The first of `dir` and the folders above it that exists but is not a folder (a file in the
/// way of creating `dir`), if any.
pub fn file_in_the_way(dir: &Path) -> Option<&Path> {
    dir.ancestors()
        .filter(|p| !p.as_os_str().is_empty())
        .find(|p| p.exists() && !p.is_dir())
}

/// Creates the folder `dir` and those above it; when a file stands in the way, says so (rather
/// than the operating system's "File exists").
pub fn create_folder(dir: &Path) -> Result<()> {
    if let Some(file) = file_in_the_way(dir) {
        bail!(
            "cannot create the folder {}: {} is a file, not a folder",
            dir.display(),
            file.display()
        );
    }
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))
}

/// Checks, before any work, that the folder `dir` given by the flag `flag` can take a
/// command's outputs: it is not a file (nor below one), and unless `force` it holds none of
/// `names` (files or folders the command writes), so that nothing a user saved is overwritten.
/// The error names the first such entry and how to go on.
pub fn check_output_folder(dir: &Path, flag: &str, names: &[&str], force: bool) -> Result<()> {
    if let Some(file) = file_in_the_way(dir) {
        bail!(
            "{flag} {}: {} is a file, not a folder; {flag} names the folder the outputs go \
             into: choose a folder (a missing one is created)",
            dir.display(),
            file.display()
        );
    }
    if force {
        return Ok(());
    }
    if let Some(name) = names.iter().find(|name| exists(&dir.join(name))) {
        bail!(
            "{flag} {} already holds {name}, which this command would overwrite; pass --force \
             to replace it, or choose another {flag}",
            dir.display()
        );
    }
    Ok(())
}

/// Checks, before any work, that the file `path` given by the flag `flag` can be written: it is
/// not a folder, no file stands where its folder would be, and unless `force` it does not
/// exist yet, so that nothing a user saved is overwritten.
pub fn check_output_file(path: &Path, flag: &str, force: bool) -> Result<()> {
    if path.is_dir() {
        bail!(
            "{flag} {} is a folder, not a file: name the file to write in it",
            path.display()
        );
    }
    if let Some(file) = path.parent().and_then(file_in_the_way) {
        bail!(
            "{flag} {}: {} is a file, not a folder: choose a path in a folder",
            path.display(),
            file.display()
        );
    }
    if !force && exists(path) {
        bail!(
            "{flag} {} already exists; pass --force to replace it, or choose another {flag}",
            path.display()
        );
    }
    Ok(())
}

/// Whether anything (a file, a folder, even a dangling link) is at `path`.
fn exists(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok()
}

/// An error as one line: its message, then each cause not already part of the message above it
/// (`sdem_io`'s errors say their OS error in their own message and carry it as their source
/// too), joined by ": ".
pub fn error_line(error: &anyhow::Error) -> String {
    let mut line = String::new();
    let mut above = String::new();
    for (i, cause) in error.chain().enumerate() {
        let text = cause.to_string();
        if i == 0 {
            line.clone_from(&text);
        } else if !above.contains(&text) {
            line.push_str(": ");
            line.push_str(&text);
        }
        above = text;
    }
    line
}

/// The saved map in `folder`, read: an error reading a map whose manifest is there says the map
/// is damaged and what to do, before the cause (a deleted node file, a truncated manifest).
pub fn load_saved_map(folder: &Path) -> Result<sdem_io::SavedMap> {
    let loaded = sdem_io::load_map(folder);
    if !folder.join(sdem_io::MAP_MANIFEST).is_file() {
        // Not a saved map at all: the reader's own words say so.
        return Ok(loaded?);
    }
    loaded.with_context(|| {
        format!(
            "the saved map {} is damaged (restore the folder from a copy, or map again with \
             sdem slam --force)",
            folder.display()
        )
    })
}

/// The exit status after a closed standard output: a process killed by `SIGPIPE` reports 128 + 13
/// to its shell, as `sdem … | head` would without this.
pub const EXIT_CLOSED_PIPE: i32 = 141;

/// Makes a standard output that cannot be written end the process with a word instead of a
/// panic: `println!` panics when the reader is gone (`sdem info BAG | head -3`, status 101 and a
/// backtrace hint) or the device is full (`> /dev/full`). A closed pipe ends quietly with
/// [`EXIT_CLOSED_PIPE`] (the reader has what it wanted, as with other tools); any other write
/// error prints one line and ends with status 1. Whatever a command wrote to files is whole: they
/// are written to a temporary and renamed (a later run removes a temporary left behind).
pub fn end_quietly_when_stdout_fails() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = (payload.downcast_ref::<String>().map(String::as_str))
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if let Some(reason) = message.strip_prefix("failed printing to stdout: ") {
            // EPIPE (32) on Unix, ERROR_NO_DATA (232) on Windows.
            if ["os error 32)", "os error 232)"]
                .iter()
                .any(|e| reason.ends_with(e))
            {
                std::process::exit(EXIT_CLOSED_PIPE);
            }
            // Not eprintln!: with stderr unwritable too it would panic inside the hook (abort).
            use std::io::Write;
            let _ = writeln!(
                std::io::stderr(),
                "sdem: error: cannot write to the standard output: {reason}"
            );
            std::process::exit(1);
        }
        default(info);
    }));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An `sdem_io` I/O error says its OS error in its message and carries it as its source:
    /// the line says it once, and keeps every context above it.
    #[test]
    fn error_line_says_each_cause_once() {
        let os = std::io::Error::from(std::io::ErrorKind::NotFound);
        let os_text = os.to_string();
        let io = sdem_io::Error::io("/proc/x.png", os);
        let error = anyhow::Error::new(io).context("cannot write the picture");
        let line = error_line(&error);
        assert_eq!(line.matches(&os_text).count(), 1, "{line}");
        assert!(
            line.starts_with("cannot write the picture: /proc/x.png: "),
            "{line}"
        );
        // A cause that adds something is kept.
        let error = anyhow::anyhow!("unknown route").context("--route");
        assert_eq!(error_line(&error), "--route: unknown route");
    }
}
