//! What `sdem slam` and `sdem export` may write over, and which files they check before the
//! work: a folder of the user's files, slam's own outputs named as `--mcap` or `--compare`, a
//! map resumed with another dataset, what `--force` leaves of an earlier run, an existing E57,
//! scans replaced after mapping.

mod common;

use common::{run_err, run_ok, usage_error};
use std::path::Path;
use tempfile::TempDir;

fn simulate(dir: &Path, out: &str, seed: &str) {
    run_ok(
        dir,
        &["simulate", "--out", out, "--stops", "3", "--seed", seed],
    );
}

#[test]
fn a_folder_of_the_users_files_without_a_map_is_not_written_over() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("poses.txt"), "precious").unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let e = run_err(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures"],
    );
    assert!(e.contains("poses.txt") && e.contains("--force"), "{e}");
    assert_eq!(
        std::fs::read_to_string(out.join("poses.txt")).unwrap(),
        "precious"
    );
    // A folder whose files have other names is written into; they stay.
    std::fs::remove_file(out.join("poses.txt")).unwrap();
    run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures"],
    );
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
    // A file as --out is named as such.
    let e = run_err(
        dir.path(),
        &["slam", "data", "--out", "out/notes.txt", "--no-pictures"],
    );
    assert!(e.contains("is a file"), "{e}");
}

#[test]
fn outputs_named_as_inputs_or_extra_outputs_are_refused_before_the_run() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    let e = run_err(
        dir.path(),
        &["slam", "data", "--out", "out", "--mcap", "out/poses.txt"],
    );
    assert!(e.contains("--mcap") && e.contains("poses.txt"), "{e}");
    // A --compare file is read before the run: missing, or too short, it stops the run
    // before any output is written.
    let e = run_err(
        dir.path(),
        &["slam", "data", "--out", "out", "--compare", "out/poses.txt"],
    );
    assert!(e.contains("--compare"), "{e}");
    std::fs::write(dir.path().join("short.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n").unwrap();
    let e = run_err(
        dir.path(),
        &["slam", "data", "--out", "out", "--compare", "short.txt"],
    );
    assert!(e.contains("1 poses") && e.contains("3 scans"), "{e}");
    usage_error(
        dir.path(),
        &["slam", "data", "--out", "out", "--max-scans", "0"],
        &["'0' for '--max-scans", "≥ 1", "0 maps nothing"],
    );
    assert!(!dir.path().join("out").exists());
    // An earlier run's poses in the output folder are compared as they were, not as this
    // run rewrites them.
    run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures"],
    );
    let text = run_ok(
        dir.path(),
        &[
            "slam",
            "data",
            "--out",
            "out",
            "--force",
            "--no-pictures",
            "--compare",
            "out/poses.txt",
        ],
    );
    assert!(text.contains("poses.txt"), "{text}");
}

#[test]
fn a_map_is_resumed_only_with_its_own_dataset_and_names_it_by_its_whole_path() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    simulate(dir.path(), "other", "2");
    run_ok(
        dir.path(),
        &[
            "slam",
            "data",
            "--out",
            "out",
            "--max-scans",
            "2",
            "--no-pictures",
        ],
    );
    let e = run_err(
        dir.path(),
        &["slam", "other", "--out", "out", "--resume", "--no-pictures"],
    );
    assert!(e.contains("was made from") && e.contains("other"), "{e}");
    // The map names its dataset by its whole path, so it resumes (and exports) from any
    // folder.
    let manifest =
        std::fs::read_to_string(dir.path().join("out/map").join(sdem_io::MAP_MANIFEST)).unwrap();
    let whole = std::fs::canonicalize(dir.path().join("data")).unwrap();
    assert!(manifest.contains(&*whole.to_string_lossy()), "{manifest}");
    let elsewhere = dir.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    run_ok(
        &elsewhere,
        &[
            "slam",
            "../data",
            "--out",
            "../out",
            "--resume",
            "--no-pictures",
        ],
    );
}

#[test]
fn force_takes_away_the_earlier_runs_pictures_and_map_nodes() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    run_ok(dir.path(), &["slam", "data", "--out", "out"]);
    let out = dir.path().join("out");
    assert!(out.join("plan.png").exists() && out.join("map/nodes/000002.pts").exists());
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    run_ok(
        dir.path(),
        &[
            "slam",
            "data",
            "--out",
            "out",
            "--force",
            "--no-pictures",
            "--max-scans",
            "2",
        ],
    );
    assert!(!out.join("plan.png").exists() && !out.join("viewer.html").exists());
    assert!(!out.join("map/nodes/000002.pts").exists());
    assert!(out.join("map/nodes/000001.pts").exists() && out.join("poses.txt").exists());
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
}

#[test]
fn export_reads_the_maps_dataset_from_any_folder_and_keeps_an_existing_e57() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures"],
    );
    let elsewhere = dir.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    // Another dataset under the same relative name, where the export runs.
    simulate(&elsewhere, "data", "9");
    let exported = common::run_json(
        &elsewhere,
        &["export", "../out", "--e57", "a.e57", "--json"],
    );
    assert_eq!(exported["e57"]["points_from"], "dataset", "{exported}");
    let here = common::run_json(dir.path(), &["export", "out", "--e57", "b.e57", "--json"]);
    assert_eq!(
        exported["e57"]["points"], here["e57"]["points"],
        "{exported} {here}"
    );
    let e = run_err(dir.path(), &["export", "out", "--e57", "b.e57"]);
    assert!(e.contains("--force"), "{e}");
    run_ok(dir.path(), &["export", "out", "--e57", "b.e57", "--force"]);
}

/// A dataset whose scans were replaced after mapping (simulated again with another seed) would
/// have put other scans at the map's poses: the export writes the nodes' points instead and says
/// which scan changed.
#[test]
fn export_does_not_pair_the_maps_poses_with_scans_replaced_after_mapping() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "3");
    run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures"],
    );
    let same = common::run_json(dir.path(), &["export", "out", "--e57", "a.e57", "--json"]);
    assert_eq!(same["e57"]["points_from"], "dataset", "{same}");
    run_ok(
        dir.path(),
        &[
            "simulate", "--out", "data", "--stops", "3", "--seed", "4", "--force",
        ],
    );
    let changed = common::run_json(dir.path(), &["export", "out", "--e57", "b.e57", "--json"]);
    assert_eq!(changed["e57"]["points_from"], "nodes", "{changed}");
    let note = changed["e57"]["note"].as_str().unwrap();
    assert!(
        note.contains("scan 0 ") && note.contains("changed after mapping"),
        "{note}"
    );
}

/// sdem's MCAP map holds its scans in the map's frame: imported back as scans in their
/// sensor's frame, every stop seemed to stand at the origin and the map came out wrong with no
/// doubt. The import refuses clouds in a frame that `/tf` moves another frame in.
#[test]
fn clouds_in_a_world_frame_are_not_imported_as_a_sensors_scans() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures"],
    );
    run_ok(dir.path(), &["export", "out", "--mcap", "map.mcap"]);
    let e = run_err(
        dir.path(),
        &[
            "import",
            "map.mcap",
            "--out",
            "again",
            "--scan-topic",
            "/sdem/scans",
        ],
    );
    assert!(
        e.contains("frame map") && e.contains("/tf moves base_link"),
        "{e}"
    );
}

/// A second `sdem slam` into a folder another one is writing, with `--force` or `--resume`,
/// replaced or continued the map under it: both ended with status 0 and the map was left with
/// one run's manifest and the other's node files. The folder's lock (held here as a running
/// slam holds it) refuses it before anything is touched; once released, the run goes on.
#[test]
fn a_folder_another_slam_is_writing_is_refused() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures"],
    );
    let manifest = std::fs::read(dir.path().join("out/map/map.json")).unwrap();
    let lock = std::fs::File::create(dir.path().join("out/.sdem-slam.lock")).unwrap();
    lock.try_lock().unwrap();
    for flag in ["--force", "--resume"] {
        let e = run_err(
            dir.path(),
            &["slam", "data", "--out", "out", "--no-pictures", flag],
        );
        assert!(e.contains("another sdem slam is writing"), "{flag}: {e}");
    }
    assert_eq!(
        std::fs::read(dir.path().join("out/map/map.json")).unwrap(),
        manifest
    );
    drop(lock);
    run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures", "--force"],
    );
}

/// A run killed before its first save leaves its config and step log but no map: `--resume`
/// said "already holds config.toml … --force" as if the folder were a user's; it now says the
/// run stopped before its first save. A killed run's temporary step log in the folder is
/// removed by the next run (the map's own were already).
#[test]
fn a_run_stopped_before_its_first_save_is_said_so_and_its_temporaries_go() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("config.toml"), "").unwrap();
    std::fs::write(out.join("steps.json"), "[]").unwrap();
    let e = run_err(dir.path(), &["slam", "data", "--out", "out", "--resume"]);
    assert!(
        e.contains("stopped before its first save") && e.contains("--force"),
        "{e}"
    );
    let stale = out.join(".steps.json.tmp-4000000000-0"); // no such process
    std::fs::write(&stale, "[").unwrap();
    run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures", "--force"],
    );
    assert!(!stale.exists());
}

/// A resumed run that stops (killed, or at a bad scan) left the earlier run's poses, cloud and
/// report beside its longer map (`view map` drew the old cloud with the new trajectory): they
/// are taken away once the resume has taken the map on, and the next good run writes them.
#[test]
fn a_resumed_run_that_stops_leaves_no_earlier_outputs_beside_its_map() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    let args = ["slam", "data", "--out", "out", "--no-pictures"];
    run_ok(dir.path(), &[&args[..], &["--max-scans", "2"]].concat());
    let out = dir.path().join("out");
    assert!(out.join("poses.txt").is_file() && out.join("report.json").is_file());
    let scan = dir.path().join("data/scans/000002.ply");
    let good = std::fs::read(&scan).unwrap();
    std::fs::write(&scan, &good[..good.len() / 2]).unwrap();
    let e = run_err(dir.path(), &[&args[..], &["--resume"]].concat());
    assert!(e.contains("000002.ply"), "{e}");
    for name in ["poses.txt", "poses.tum", "map.ply", "report.json"] {
        assert!(
            !out.join(name).exists(),
            "{name} of the 2-scan run is still there"
        );
    }
    assert!(out.join("map/map.json").is_file() && out.join("steps.json").is_file());
    std::fs::write(&scan, &good).unwrap();
    run_ok(dir.path(), &[&args[..], &["--resume"]].concat());
    assert_eq!(common::lines(&out.join("poses.txt")), 3);
}

/// A step log deleted or damaged before a resume: the run went on and its report listed fewer
/// steps than scans without a word (a damaged one was refused, with no hint). It goes on from
/// the whole map either way and says what the report will lack.
#[test]
fn a_lost_step_log_is_said_so_when_the_run_resumes() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    let args = ["slam", "data", "--out", "out", "--no-pictures"];
    let out = dir.path().join("out");
    for damage in ["delete", "truncate"] {
        run_ok(
            dir.path(),
            &[&args[..], &["--max-scans", "2", "--force"]].concat(),
        );
        let log = out.join("steps.json");
        match damage {
            "delete" => std::fs::remove_file(&log).unwrap(),
            _ => std::fs::write(&log, "[{\"scan_index\": 0").unwrap(),
        }
        let resumed = common::run(dir.path(), &[&args[..], &["--resume"]].concat());
        assert_eq!(resumed.code, Some(0), "{damage}: {}", resumed.stderr);
        assert!(
            resumed.stderr.contains("warning") && resumed.stderr.contains("only 0 of their steps"),
            "{damage}: {}",
            resumed.stderr
        );
        assert_eq!(common::lines(&out.join("poses.txt")), 3);
    }
}

/// A saved map with a node file gone: every command that reads it said only the file and the
/// system's words; each now says the map is damaged and what to do, before the cause.
#[test]
fn a_damaged_map_is_said_so_by_every_command_that_reads_it() {
    let dir = TempDir::new().unwrap();
    simulate(dir.path(), "data", "1");
    run_ok(
        dir.path(),
        &["slam", "data", "--out", "out", "--no-pictures"],
    );
    std::fs::remove_file(dir.path().join("out/map/nodes/000001.pts")).unwrap();
    let scan = "data/scans/000000.ply";
    for args in [
        &["localize", "--map", "out", scan][..],
        &["view", "map", "out", "--out-dir", "pictures"][..],
        &["export", "out", "--e57", "x.e57"][..],
        &["slam", "data", "--out", "out", "--resume"][..],
    ] {
        let e = run_err(dir.path(), args);
        assert!(
            e.contains("is damaged") && e.contains("--force") && e.contains("000001.pts"),
            "{args:?}: {e}"
        );
    }
}
