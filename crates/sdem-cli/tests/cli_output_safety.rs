//! Nothing a user saved is lost by a command run twice or pointed at the wrong place, and bad
//! options are refused before the work starts: `demo`, `simulate`, `view` and `bench --suite
//! scale` refuse to write over an existing file unless `--force`; an `--out` that is a file (or
//! a folder where a file is wanted) is named as such; an OS error is said once; `demo --stops`,
//! `bench --pairs`/`--step` and `view cost --step`/`--extent` are usage errors, checked up front.
//!
//! Each refusal exits before any simulation or localization, so these tests are quick.

mod common;

use common::{run_err, run_ok, usage_error};
use std::path::Path;
use tempfile::TempDir;

fn s(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}

/// What a user saved: a file whose content a test checks is kept.
const MINE: &str = "mine, not sdem's";

fn save_mine(path: &Path) {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    std::fs::write(path, MINE).unwrap();
}

fn assert_kept(path: &Path) {
    assert_eq!(
        std::fs::read_to_string(path).unwrap(),
        MINE,
        "{} was overwritten",
        path.display()
    );
}

/// A scan file of 200 points on a wavy ellipse, which `view panorama` draws.
fn scan_file(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("scan.xyz");
    std::fs::write(&path, common::wavy_ellipse_xyz()).unwrap();
    path
}

#[test]
fn demo_refuses_a_folder_holding_a_file_it_writes_unless_forced() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("mine");
    for name in [
        "plan.png",
        "poses.txt",
        "map.ply",
        "viewer.html",
        "report.json",
    ] {
        let _ = std::fs::remove_dir_all(&out);
        save_mine(&out.join(name));
        let e = run_err(dir.path(), &["demo", "--out", s(&out), "--stops", "2"]);
        assert!(
            e.contains(name) && e.contains("--force") && e.contains(s(&out)),
            "{e}"
        );
        assert_kept(&out.join(name));
    }
    // A `sdem slam` output folder (its saved map) is refused too.
    let slam_out = dir.path().join("slam-out");
    std::fs::create_dir_all(slam_out.join("map")).unwrap();
    let e = run_err(dir.path(), &["demo", "--out", s(&slam_out)]);
    assert!(e.contains("map/") && e.contains("--force"), "{e}");
    assert_eq!(std::fs::read_dir(&slam_out).unwrap().count(), 1);

    // --force replaces the demo's files and leaves the others.
    save_mine(&out.join("notes.md"));
    run_ok(
        dir.path(),
        &[
            "demo",
            "--out",
            s(&out),
            "--stops",
            "2",
            "--force",
            "--json",
        ],
    );
    assert_ne!(
        std::fs::read(out.join("report.json")).unwrap(),
        MINE.as_bytes()
    );
    assert_kept(&out.join("notes.md"));
}

/// Without `--out` the demo writes its own folder, `sdem-demo`, and each run replaces the
/// last one's outputs there: the README's first command can be run again.
#[test]
fn demo_without_out_replaces_its_own_folder() {
    let dir = TempDir::new().unwrap();
    for _ in 0..2 {
        run_ok(dir.path(), &["demo", "--stops", "2", "--json"]);
    }
    assert!(dir.path().join("sdem-demo/report.json").exists());
}

#[test]
fn demo_says_an_out_that_is_a_file_is_not_a_folder() {
    let dir = TempDir::new().unwrap();
    let file = dir.path().join("file_out");
    save_mine(&file);
    let e = run_err(dir.path(), &["demo", "--out", s(&file)]);
    assert!(e.contains("is a file, not a folder"), "{e}");
    assert!(!e.contains("os error"), "{e}");
    assert_kept(&file);
}

#[test]
fn simulate_refuses_a_folder_holding_dataset_files_without_scans() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("mine");
    for name in [
        "attitude.csv",
        "poses_truth.txt",
        "sensor.toml",
        "odometry.txt",
    ] {
        let _ = std::fs::remove_dir_all(&out);
        save_mine(&out.join(name));
        let e = run_err(dir.path(), &["simulate", "--out", s(&out), "--stops", "2"]);
        assert!(e.contains(name) && e.contains("--force"), "{e}");
        assert_kept(&out.join(name));
        assert!(
            !out.join("scans").exists(),
            "a refused simulate wrote scans/"
        );
    }
    // --force still replaces the dataset's files, and nothing else.
    save_mine(&out.join("notes.md"));
    run_ok(
        dir.path(),
        &["simulate", "--out", s(&out), "--stops", "2", "--force"],
    );
    assert_ne!(
        std::fs::read(out.join("odometry.txt")).unwrap(),
        MINE.as_bytes()
    );
    assert_kept(&out.join("notes.md"));

    let file = dir.path().join("file_out");
    save_mine(&file);
    let e = run_err(dir.path(), &["simulate", "--out", s(&file)]);
    assert!(e.contains("is a file, not a folder"), "{e}");
}

#[test]
fn view_refuses_an_existing_out_file_before_the_work_unless_forced() {
    let dir = TempDir::new().unwrap();
    let png = dir.path().join("picture.png");
    save_mine(&png);
    // The input does not exist: the --out check comes first, before any reading.
    let commands: [&[&str]; 3] = [
        &["view", "panorama", "nowhere"],
        &["view", "slice", "nowhere"],
        &[
            "view",
            "cost",
            "nowhere",
            "--reference",
            "0",
            "--query",
            "1",
        ],
    ];
    for command in commands {
        let args = [command, &["--out", s(&png)]].concat();
        let e = run_err(dir.path(), &args);
        assert!(
            e.contains("already exists") && e.contains("--force") && e.contains(s(&png)),
            "{args:?}: {e}"
        );
        assert_kept(&png);
    }
    // A folder given as the file.
    let e = run_err(dir.path(), &["view", "panorama", "nowhere", "--out", "."]);
    assert!(e.contains("is a folder, not a file"), "{e}");

    // --force writes over it.
    let scan = scan_file(dir.path());
    run_ok(
        dir.path(),
        &["view", "panorama", s(&scan), "--out", s(&png), "--force"],
    );
    assert_ne!(std::fs::read(&png).unwrap(), MINE.as_bytes());
}

#[test]
fn bench_scale_refuses_an_existing_plot_before_the_work() {
    let dir = TempDir::new().unwrap();
    let plot = dir.path().join("scale.png");
    save_mine(&plot);
    let args = [
        "bench",
        "--suite",
        "scale",
        "--route",
        "room-laps",
        "--sizes",
        "12",
        "--plot",
        s(&plot),
    ];
    let e = run_err(dir.path(), &args);
    assert!(
        e.contains("--plot") && e.contains("already exists") && e.contains("--force"),
        "{e}"
    );
    assert_kept(&plot);
    // The default plot, in the current folder, is kept as well.
    let e = run_err(dir.path(), &args[..7]);
    assert!(e.contains("scale.png") && e.contains("--force"), "{e}");
    assert_kept(&plot);
}

/// No file can be made in /proc (Linux): the write fails with the OS's "No such file".
#[cfg(target_os = "linux")]
#[test]
fn an_os_error_is_said_once() {
    let dir = TempDir::new().unwrap();
    let scan = scan_file(dir.path());
    let out = "/proc/sdem-no-such-picture.png";
    let e = run_err(dir.path(), &["view", "panorama", s(&scan), "--out", out]);
    assert_eq!(e.matches("os error").count(), 1, "{e}");
    assert!(e.contains("sdem-no-such-picture"), "{e}");
}

#[test]
fn a_file_where_a_folder_should_be_is_named() {
    let dir = TempDir::new().unwrap();
    let file = dir.path().join("file_out");
    save_mine(&file);
    let inside = file.join("p.png");
    let e = run_err(
        dir.path(),
        &["view", "panorama", "nowhere", "--out", s(&inside)],
    );
    assert!(
        e.contains("is a file, not a folder") && e.contains(s(&file)),
        "{e}"
    );
    let e = run_err(dir.path(), &["demo", "--out", s(&file.join("sub"))]);
    assert!(
        e.contains("is a file, not a folder") && !e.contains("File exists"),
        "{e}"
    );
    assert_kept(&file);
}

#[test]
fn demo_checks_stops_up_front() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("demo");
    for stops in ["0", "1", "41", "-2", "x"] {
        // A usage error: nothing on stdout (part 1 is not printed first).
        let e = usage_error(
            dir.path(),
            &["demo", "--out", s(&out), "--stops", stops],
            &[
                &format!("'{stops}' for '--stops"),
                "2..=40",
                "route holds 40",
            ],
        );
        assert!(!e.contains("collapsed_building_stops"), "{e}");
        assert!(!out.exists(), "a refused demo wrote {}", out.display());
    }
}

#[test]
fn bench_checks_pairs_and_step_before_measuring() {
    let dir = TempDir::new().unwrap();
    for (args, wanted) in [
        (
            ["bench", "--quick", "--pairs", "0"],
            ["'0' for '--pairs", "≥ 1"],
        ),
        (
            ["bench", "--faults", "--pairs", "0"],
            ["'0' for '--pairs", "≥ 1"],
        ),
        (
            ["bench", "--quick", "--step", "0"],
            ["'0' for '--step", "positive"],
        ),
    ] {
        // No progress line: nothing was measured before the refusal.
        let e = usage_error(dir.path(), &args, &wanted);
        assert!(!e.contains("exact search"), "{args:?}: {e}");
    }
}

#[test]
fn view_cost_refuses_a_step_leaving_too_few_samples() {
    let dir = TempDir::new().unwrap();
    let base = [
        "view",
        "cost",
        "nowhere",
        "--reference",
        "0",
        "--query",
        "1",
        "--out",
        "c.png",
    ];
    for (extra, flag) in [
        ("--step=1e9", "--step"),
        ("--extent=1e-9", "--extent"),
        ("--step=0.7", "--step"),
        ("--step=0", "--step"),
        ("--extent=-1", "--extent"),
    ] {
        let args = [&base[..], &[extra]].concat();
        // Refused before the dataset is read, with the flag named.
        let e = usage_error(dir.path(), &args, &[flag]);
        assert!(!e.contains("nowhere"), "{args:?}: {e}");
    }
    usage_error(
        dir.path(),
        &[&base[..], &["--step", "1e9"]].concat(),
        &[
            "--step 1e9 m",
            "1 sample",
            "3 to 401",
            "Usage: sdem view cost",
        ],
    );
    assert!(!dir.path().join("c.png").exists());
}

/// A standard output that cannot be written (`sdem … | head` closing the pipe, `> /dev/full`)
/// ended every command in a panic (status 101); a closed pipe now ends quietly as `SIGPIPE`
/// would (141), a full device with one line (status 1).
#[test]
fn a_closed_or_full_standard_output_ends_without_a_panic() {
    let dir = TempDir::new().unwrap();
    let simulate = |out: &str, stdout: std::process::Stdio| {
        std::process::Command::new(env!("CARGO_BIN_EXE_sdem"))
            .current_dir(dir.path())
            .args(["simulate", "--out", out, "--stops", "2"])
            .stdout(stdout)
            .stderr(std::process::Stdio::piped())
            .output()
            .unwrap()
    };
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let closed = simulate("a", writer.into());
    let stderr = String::from_utf8_lossy(&closed.stderr);
    assert_eq!(closed.status.code(), Some(141), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    if let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") {
        let out = simulate("b", full.into());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(
            stderr.contains("cannot write to the standard output") && !stderr.contains("panicked"),
            "{stderr}"
        );
    }
}

/// A path that is not valid UTF-8 cannot be written into sdem's JSON: `export --mcap` to one
/// panicked after writing the file, `import --json` failed with the dataset written. Refused as
/// a usage error before anything is read or written.
#[cfg(unix)]
#[test]
fn a_non_utf8_path_is_a_usage_error_before_anything_is_written() {
    use std::os::unix::ffi::OsStrExt;
    let dir = TempDir::new().unwrap();
    let name = std::ffi::OsStr::from_bytes(b"d\xff");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sdem"))
        .current_dir(dir.path())
        .args(["simulate", "--stops", "2", "--out"])
        .arg(name)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("not valid UTF-8"), "{stderr}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}
