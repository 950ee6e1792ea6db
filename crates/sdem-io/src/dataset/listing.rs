//! Which files of a dataset's `scans/` are its scans, and in which order: the visible files
//! with a point-cloud extension, in the natural order of their names; the entries left out are
//! kept to be named when the per-scan files' row counts do not match; and the scans' count in
//! words, for an index out of range.

use crate::error::{Error, Result};
use crate::{PointFormat, POINT_EXTENSIONS};
use std::cmp::Ordering;
use std::path::{Path, PathBuf};

fn is_hidden(path: &Path) -> bool {
    path.file_name()
        .is_none_or(|n| n.to_string_lossy().starts_with('.'))
}

/// Compares two names in natural order: runs of ASCII digits by their value, the rest by
/// character, so that `scan2` comes before `scan10`. Scan names are often not zero-padded, and a
/// plain text sort (`scan1`, `scan10`, `scan2`) would pair the scans with the wrong rows of
/// `attitude.csv` and the pose files without a word. Zero-padded names keep their order; names
/// equal in value (`scan01`, `scan1`) fall back to plain text, so the order is total.
fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut x, mut y) = (a.as_bytes(), b.as_bytes());
    loop {
        match (x.first(), y.first()) {
            (None, None) => return a.cmp(b),
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(c), Some(d)) if c.is_ascii_digit() && d.is_ascii_digit() => {
                let run = |s: &[u8]| s.iter().take_while(|c| c.is_ascii_digit()).count();
                let (dx, rest_x) = x.split_at(run(x));
                let (dy, rest_y) = y.split_at(run(y));
                // Leading zeros aside, a longer run is a larger number, without overflow.
                let trim = |s: &[u8]| s.iter().take_while(|&&c| c == b'0').count();
                let (vx, vy) = (&dx[trim(dx)..], &dy[trim(dy)..]);
                let order = vx.len().cmp(&vy.len()).then_with(|| vx.cmp(vy));
                if order != Ordering::Equal {
                    return order;
                }
                (x, y) = (rest_x, rest_y);
            }
            (Some(c), Some(d)) => {
                if c != d {
                    return c.cmp(d);
                }
                (x, y) = (&x[1..], &y[1..]);
            }
        }
    }
}

/// What [`point_files`] found in a folder: the scans, and the visible entries it did not take,
/// each as `NAME (why)`, for the messages that a skipped file would otherwise leave unexplained.
pub(super) struct ScanListing {
    pub scans: Vec<PathBuf>,
    skipped: Vec<String>,
}

impl ScanListing {
    /// The skipped entries for a count-mismatch message, or nothing when there are none.
    pub fn skipped_note(&self) -> String {
        const SHOWN: usize = 5;
        if self.skipped.is_empty() {
            return String::new();
        }
        let mut names = self.skipped[..self.skipped.len().min(SHOWN)].join(", ");
        if self.skipped.len() > SHOWN {
            names.push_str(&format!(", and {} more", self.skipped.len() - SHOWN));
        }
        format!(
            "; not counted as scans: {names}; rename or restore them (a scan has one of the \
             extensions .{}), or remove them",
            POINT_EXTENSIONS.join(", .")
        )
    }
}

/// The visible regular files of `folder` that have a point-cloud extension, in the natural
/// order of their names ([`natural_cmp`]), and the visible entries left out.
pub(super) fn point_files(folder: &Path) -> Result<ScanListing> {
    let entries = std::fs::read_dir(folder).map_err(|e| Error::io(folder, e))?;
    let mut scans = Vec::new();
    let mut skipped = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| Error::io(folder, e))?.path();
        if is_hidden(&path) {
            continue;
        }
        let why = if path.file_name().is_some_and(|n| n.to_str().is_none()) {
            // The scan's file name goes into report.json and the map, which hold UTF-8 only.
            "a name that is not UTF-8"
        } else if path.is_file() {
            if PointFormat::from_path(&path).is_some() {
                scans.push(path);
                continue;
            }
            "not a point-cloud extension"
        } else if path.is_dir() {
            "a folder"
        } else if path.is_symlink() {
            "a link to a missing file"
        } else {
            "not a regular file"
        };
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        skipped.push(format!("{name} ({why})"));
    }
    let name = |p: &PathBuf| {
        p.file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned()
    };
    scans.sort_by(|a, b| natural_cmp(&name(a), &name(b)));
    skipped.sort_by(|a, b| natural_cmp(a, b));
    Ok(ScanListing { scans, skipped })
}

/// A dataset's scans in words, for an index out of range: `1 scan, numbered 0`, `40 scans,
/// numbered 0 to 39`.
pub fn scans_numbered(count: usize) -> String {
    match count {
        0 => "no scan".to_string(),
        1 => "1 scan, numbered 0".to_string(),
        n => format!("{n} scans, numbered 0 to {}", n - 1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_cmp_orders_digit_runs_by_value() {
        let mut names = vec![
            "scan10", "scan2", "scan0", "scan11", "scan1", "scan01", "b", "a10b", "a9c", "a",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            ["a", "a9c", "a10b", "b", "scan0", "scan01", "scan1", "scan2", "scan10", "scan11"]
        );
        // Zero-padded names keep their plain order; digit runs longer than any integer compare.
        assert_eq!(natural_cmp("000009", "000010"), Ordering::Less);
        let huge = "9".repeat(40);
        assert_eq!(natural_cmp(&huge, &format!("1{huge}")), Ordering::Less);
        assert_eq!(natural_cmp("x", "x"), Ordering::Equal);
    }
}
