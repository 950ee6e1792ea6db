//! Where `sdem slam` writes: the names of its outputs, and the checks that keep it from
//! writing over what a user keeps in the output folder or names as another input or output.

use super::{Args, MAP_DIR, REPORT_FILE, STEPS_FILE};
use crate::output::{check_output_folder, create_folder};
use anyhow::{bail, Context, Result};
use std::path::Path;

/// The files `sdem slam` writes into its output folder, besides [`MAP_DIR`] and the pictures
/// ([`crate::cmd_view::MAP_PICTURE_FILES`]).
const OUTPUT_FILES: &[&str] = &[
    "poses.txt",
    "poses.tum",
    "map.ply",
    "map.sdemvox",
    "config.toml",
    REPORT_FILE,
    STEPS_FILE,
];

/// The names in `out` that `sdem slam` writes, the map folder last.
fn output_names() -> impl Iterator<Item = &'static str> {
    (OUTPUT_FILES.iter())
        .chain(crate::cmd_view::MAP_PICTURE_FILES)
        .copied()
        .chain([MAP_DIR])
}

/// Refuses a file given with `flag` that is one of the outputs in `out`: the run would write
/// over it, or read what it writes.
pub(super) fn check_beside_outputs(out: &Path, path: &Path, flag: &str) -> Result<()> {
    let (Some(name), Some(parent)) = (path.file_name(), path.parent()) else {
        return Ok(());
    };
    let parent = if parent.as_os_str().is_empty() {
        Path::new(".")
    } else {
        parent
    };
    let same_folder = match (std::fs::canonicalize(parent), std::fs::canonicalize(out)) {
        (Ok(a), Ok(b)) => a == b,
        _ => parent == out,
    };
    if same_folder && output_names().any(|o| name == o) {
        bail!(
            "{flag} {} is one of the files sdem slam writes in {}; name a file elsewhere",
            path.display(),
            out.display()
        );
    }
    Ok(())
}

/// The file in the output folder that a running `sdem slam` holds locked
/// ([`lock_out`]): it holds nothing, and an interrupted run's lock goes with its process.
pub(super) const LOCK_FILE: &str = ".sdem-slam.lock";

/// Takes the output folder for this run: an advisory lock on [`LOCK_FILE`], held until the
/// returned file is dropped (the process ends). A second `sdem slam` into the same folder with
/// `--force` or `--resume` replaced or continued the map while the first still wrote it: both
/// ended with status 0 and left a map whose manifest and node files belonged to different runs.
fn lock_out(out: &Path) -> Result<std::fs::File> {
    let path = out.join(LOCK_FILE);
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .with_context(|| format!("cannot open {}", path.display()))?;
    match file.try_lock() {
        Ok(()) => Ok(file),
        Err(std::fs::TryLockError::WouldBlock) => bail!(
            "another sdem slam is writing {} (it holds {}); wait for it to end, or choose \
             another --out",
            out.display(),
            LOCK_FILE
        ),
        Err(std::fs::TryLockError::Error(e)) => {
            Err(e).with_context(|| format!("cannot lock {}", path.display()))
        }
    }
}

/// Refuses to overwrite or resume the wrong map, or to write over files of the same names as
/// its outputs in a folder that holds no map; creates the output folder and takes it for this
/// run ([`lock_out`]: the returned file holds the lock); with `--force`, then takes the earlier
/// run's outputs away (its pictures and map nodes would otherwise stay beside the new run's).
pub(super) fn prepare_out(args: &Args, map_dir: &Path) -> Result<std::fs::File> {
    let out = &args.out;
    let has_map = map_dir.join(sdem_io::MAP_MANIFEST).exists();
    // A folder holding a map is continued (--resume) or replaced (--force) below; in one
    // without, no file of an output's name is written over unless --force.
    let names: Vec<&str> = if has_map {
        Vec::new()
    } else {
        output_names().collect()
    };
    if args.resume && !has_map {
        // A run stopped before its first save leaves its config and step log, not a map.
        let started = out.join(super::STEPS_FILE).exists() || out.join("config.toml").exists();
        bail!(
            "--resume: {} holds no saved map ({} is missing){}",
            out.display(),
            map_dir.join(sdem_io::MAP_MANIFEST).display(),
            if started {
                ": the run there stopped before its first save; start it again with --force \
                 (a map given with --map is read, never written)"
            } else {
                "; run without --resume"
            }
        );
    }
    check_output_folder(out, "--out", &names, args.force)?;
    if has_map && !args.resume && !args.force {
        bail!(
            "{} already holds a map; pass --resume to continue it or --force to replace it",
            out.display()
        );
    }
    create_folder(out)?;
    let lock = lock_out(out)?;
    // A killed run's half-written step log or report (`.steps.json.tmp-PID-N`); the map's own
    // are removed when the map is saved.
    sdem_io::remove_stale_temporaries(out);

    // What was checked above may have changed before the lock was taken.
    if map_dir.join(sdem_io::MAP_MANIFEST).exists() != has_map {
        bail!(
            "{} changed while this run started (another sdem slam?); run again",
            out.display()
        );
    }
    if args.force && !args.resume {
        if has_map {
            let foreign = sdem_io::foreign_in_map(map_dir);
            if !foreign.is_empty() {
                bail!(
                    "--force would remove {}, with {} that sdem did not write ({}); move {} out \
                     of {} first, or choose another --out",
                    map_dir.display(),
                    if foreign.len() == 1 {
                        "a file"
                    } else {
                        "files"
                    },
                    foreign
                        .iter()
                        .take(3)
                        .cloned()
                        .collect::<Vec<_>>()
                        .join(", "),
                    if foreign.len() == 1 { "it" } else { "them" },
                    map_dir.display()
                );
            }
        }
        remove_files(out, output_names(), "--force")?;
        if has_map {
            std::fs::remove_dir_all(map_dir)
                .with_context(|| format!("--force: cannot remove {}", map_dir.display()))?;
        }
    }
    Ok(lock)
}

/// Removes what a run writes only at its end (poses, cloud, voxel map, report, pictures) from a
/// folder whose saved map a resumed run has just taken on: an earlier run's would stay behind
/// if this one were killed too (`view map` drew a 20-node cloud with a 30-node trajectory). The
/// map, its config and the step log it goes on from stay.
pub(super) fn remove_final_outputs(out: &Path) -> Result<()> {
    let finals = (OUTPUT_FILES.iter())
        .filter(|&&name| name != STEPS_FILE && name != "config.toml")
        .chain(crate::cmd_view::MAP_PICTURE_FILES)
        .copied();
    remove_files(out, finals, "--resume")
}

/// Removes the files `names` in `out` that are there (a folder of such a name stays); an error
/// names the file and the `flag` that asked for it.
fn remove_files<'a>(out: &Path, names: impl Iterator<Item = &'a str>, flag: &str) -> Result<()> {
    for name in names {
        let path = out.join(name);
        if path.is_file() {
            std::fs::remove_file(&path)
                .with_context(|| format!("{flag}: cannot remove {}", path.display()))?;
        }
    }
    Ok(())
}
