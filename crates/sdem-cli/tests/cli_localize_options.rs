//! `sdem localize`'s search options: a number out of its range is a usage error like a malformed
//! `--window` (exit status 2, clap's message naming the flag and the range it allows), refused
//! before any file is read.

mod common;

use common::{run, usage_error};
use std::path::Path;

fn s(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}

/// A dataset of two stops simulated in `dir` (seed 1), as `sdem simulate` writes it.
fn two_stops(dir: &Path) -> std::path::PathBuf {
    let ds = dir.join("ds");
    let sim = ["simulate", "--out", s(&ds), "--stops", "2", "--seed", "1"];
    assert_eq!(run(dir, &sim).code, Some(0));
    ds
}

#[test]
fn localize_numbers_out_of_range_are_usage_errors_naming_flag_and_range() {
    let dir = tempfile::tempdir().unwrap();
    // Not a dataset: every refusal comes before it is opened.
    let ds = dir.path().join("nowhere");
    let pair = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    for (flag, value, range) in [
        ("--step", "0", "positive number of metres"),
        ("--step", "-0.01", "positive number of metres"),
        ("--step", "nan", "positive number of metres"),
        ("--resolution", "0", "(0, 45]"),
        ("--resolution", "-1", "(0, 45]"),
        ("--heading-window", "200", "[0, 180]"),
        ("--heading-window", "-5", "[0, 180]"),
        ("--heading-step", "0", "positive number of degrees"),
        ("--prior", "0.1,0.2,0", "x,y,z,sigma"),
        ("--prior", "a,b,c,d", "x,y,z,sigma"),
        ("--prior", "0.1,0.2,0,0", "positive"),
        ("--prior", "0.1,0.2,0,-1", "positive"),
        ("--attitude-sigma-deg", "0,3", "σ"),
        ("--min-overlap", "1.5", "from 0 to 1"),
        ("--min-overlap", "-0.1", "from 0 to 1"),
    ] {
        let args = [&pair[..], &[flag, value]].concat();
        let e = usage_error(dir.path(), &args, &[flag, range]);
        assert!(!e.contains("nowhere"), "{args:?}: {e}");
    }
    // With --map, its own numbers: the prediction, the place and the attitude reading.
    let map = ["localize", "--map", "nomap", "scan.ply"];
    for (flag, value, range) in [
        ("--prior", "1,2,0,0", "positive"),
        ("--near", "1,2", "x,y,z"),
        ("--near", "1,inf,0", "x,y,z"),
        ("--attitude", "0,nan,0", "roll,pitch,yaw"),
    ] {
        let args = [&map[..], &[flag, value]].concat();
        let e = usage_error(dir.path(), &args, &[flag, range]);
        assert!(!e.contains("nomap"), "{args:?}: {e}");
    }
}

/// Flags of one mode given in the other are usage errors (exit status 2) before anything is
/// read: --near, --attitude and --scan are for --map, and --map needs its scan; `sdem export`
/// needs a format to write.
#[test]
fn flags_of_the_other_mode_are_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let pair = ["localize", "nowhere", "--reference", "0", "--query", "1"];
    for (flag, value) in [("--near", "1,2,3"), ("--attitude", "1,2,3")] {
        let args = [&pair[..], &[flag, value]].concat();
        let e = usage_error(dir.path(), &args, &[flag, "--map DIR SCAN"]);
        assert!(!e.contains("nowhere"), "{args:?}: {e}");
    }
    usage_error(
        dir.path(),
        &["localize", "--map", "nomap"],
        &["--map needs the scan"],
    );
    usage_error(dir.path(), &["export", "nomap"], &["--mcap", "--e57"]);
}

#[test]
fn localize_refuses_a_step_larger_than_the_window_naming_both() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("nowhere");
    let pair = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    // The default window (the paper's: 1 m along x at most).
    let e = usage_error(
        dir.path(),
        &[&pair[..], &["--step", "1e9"]].concat(),
        &["--step 1e9 m", "1 m", "--window"],
    );
    assert!(!e.contains("nowhere"), "{e}");
    let window = ["--window", "-0.1:0.1,-0.05:0.05,0:0"];
    usage_error(
        dir.path(),
        &[&pair[..], &window, &["--step", "0.5"]].concat(),
        &["--step 0.5 m", "0.2 m", "--window -0.1:0.1,-0.05:0.05,0:0"],
    );
    // A step as large as the window's longest side leaves two candidates on it: searched
    // (here the missing dataset is the error).
    let r = run(
        dir.path(),
        &[&pair[..], &window, &["--step", "0.2"]].concat(),
    );
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    assert!(r.stderr.contains("nowhere"), "{}", r.stderr);
}

#[test]
fn localize_refuses_a_prior_or_place_beyond_a_million_metres() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("nowhere");
    let pair = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    for prior in ["1e9,0,0,0.1", "0,0,-2e6,0.1", "0,1e300,0,0.1"] {
        let e = usage_error(
            dir.path(),
            &[&pair[..], &["--prior", prior]].concat(),
            &["--prior", "1e6 m"],
        );
        assert!(!e.contains("no candidate"), "{e}");
    }
    let map = ["localize", "--map", "nomap", "scan.ply"];
    usage_error(
        dir.path(),
        &[&map[..], &["--prior", "1e9,0,0,1"]].concat(),
        &["--prior", "1e6 m"],
    );
    usage_error(
        dir.path(),
        &[&map[..], &["--near", "0,1e9,0"]].concat(),
        &["--near", "1e6 m"],
    );
}

#[test]
fn localize_refuses_an_exhaustive_search_beyond_its_candidate_limit() {
    let dir = tempfile::tempdir().unwrap();
    let ds = two_stops(dir.path());
    let pair = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    // ±2 m at 1 cm with ±2° of heading: 401 × 401 × 21 positions, many headings. Refused
    // before any is scored, naming the count, the limit and the flags that shrink it.
    let big = [
        "--exhaustive",
        "--window",
        "-2:2,-2:2,-0.1:0.1",
        "--heading-window",
        "2",
    ];
    usage_error(
        dir.path(),
        &[&pair[..], &big].concat(),
        &[
            "401 × 401 × 21 positions",
            "limit of 4000000",
            "--window",
            "--step",
            "--exhaustive",
            "--max-candidates",
        ],
    );
    // The limit is the user's to move; it limits only the exhaustive search.
    usage_error(
        dir.path(),
        &[&pair[..], &big, &["--max-candidates", "1000000"]].concat(),
        &["limit of 1000000"],
    );
    usage_error(
        dir.path(),
        &[&pair[..], &["--max-candidates", "1000000"]].concat(),
        &["--max-candidates", "--exhaustive"],
    );
    // With --search exhaustive and no attitude (roll, pitch and every heading searched).
    std::fs::remove_file(ds.join("attitude.csv")).unwrap();
    let args = [
        &pair[..],
        &["--search", "exhaustive", "--window", "-1:1,-1:1,-0.1:0.1"],
    ]
    .concat();
    usage_error(
        dir.path(),
        &args,
        &["candidates", "limit of 4000000", "--search exhaustive"],
    );
}

/// A `--prior` that claims a millimetre and lies 34 cm from where the scans put the query holds
/// the pose, which is then doubtful (exit 3) with `prior_conflict`, said in words; a prior at
/// the scans' pose leaves it trusted.
#[test]
fn a_prior_that_overrules_the_scans_is_doubtful() {
    let dir = tempfile::tempdir().unwrap();
    let ds = two_stops(dir.path());
    let pair = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    let wrong = run(
        dir.path(),
        &[&pair[..], &["--prior", "0,0,0,0.001"]].concat(),
    );
    assert_eq!(wrong.code, Some(3), "{}\n{}", wrong.stdout, wrong.stderr);
    assert!(
        wrong.stdout.contains("the prediction, not the scans"),
        "{}",
        wrong.stdout
    );
    let json = run(
        dir.path(),
        &[&pair[..], &["--prior", "0,0,0,0.001", "--json"]].concat(),
    );
    assert!(
        json.stdout.contains("\"prior_conflict\""),
        "{}",
        json.stdout
    );
    let right = run(
        dir.path(),
        &[&pair[..], &["--prior", "0.337,0,0,0.001"]].concat(),
    );
    assert_eq!(right.code, Some(0), "{}\n{}", right.stdout, right.stderr);
}

/// `--min-overlap` is the floor on the share of the query's compared cells a candidate must
/// share: raised to 99 %, only candidates sharing that much count, and the grid's best among
/// them lies 10.4 cm from the truth (which shares less), turned 0.6°; the refinement takes it
/// back to the truth (a move plausible at that turn), and the pose is trusted there. At the
/// default the same pair is trusted with less in common.
#[test]
fn the_least_overlap_can_be_set_and_the_search_obeys_it() {
    let dir = tempfile::tempdir().unwrap();
    let ds = two_stops(dir.path());
    let pair = [
        "localize",
        s(&ds),
        "--reference",
        "0",
        "--query",
        "1",
        "--json",
    ];
    let overlap = |args: &[&str]| {
        let out = run(dir.path(), args);
        let v = out.json();
        let fraction = v["diagnostics"]["overlap_fraction"].as_f64().unwrap();
        let error = v["error_m"].as_f64().unwrap();
        (out.code, fraction, error)
    };
    let (code, default, error) = overlap(&pair);
    assert_eq!(code, Some(0));
    assert!(default < 0.99 && error < 0.002, "{default} {error}");
    let (code, raised, error) = overlap(&[&pair[..], &["--min-overlap", "0.99"]].concat());
    assert!(raised >= 0.99, "{raised}");
    assert_eq!(code, Some(0));
    assert!(error < 0.002, "{error} m from the truth");
}

/// Without `--resolution` a dataset's scans are built on the grid `sdem slam` builds for it:
/// matched to the scanner's step in its `sensor.toml` (here a pan step of 2°: 2° cells), and
/// without one to the reference scan's sampling (the paper's sweep: 1°; `settings`
/// `matched_grid`); `--resolution` overrides either. The JSON says which was used.
#[test]
fn the_grid_follows_the_datasets_sensor_unless_a_resolution_is_given() {
    let dir = tempfile::tempdir().unwrap();
    let ds = two_stops(dir.path());
    let pair = ["localize", s(&ds), "--reference", "0", "--query", "1"];
    let settings = |extra: &[&str]| {
        let args = [&pair[..], extra, &["--json"]].concat();
        let v = run(dir.path(), &args).json();
        assert!(v["error_m"].as_f64().unwrap() < 0.01, "{v}");
        (v["resolution_deg"].as_f64().unwrap(), v["settings"].clone())
    };
    let resolution = |extra: &[&str]| settings(extra).0;
    // `sdem simulate` writes the paper's SICK: 1° steps.
    assert_eq!(resolution(&[]), 1.0);
    let sensor = ds.join("sensor.toml");
    let text = std::fs::read_to_string(&sensor).unwrap();
    assert!(text.contains("pan_step_deg = 1.0"), "{text}");
    std::fs::write(
        &sensor,
        text.replace("pan_step_deg = 1.0", "pan_step_deg = 2.0"),
    )
    .unwrap();
    assert_eq!(resolution(&[]), 2.0);
    assert_eq!(resolution(&["--resolution", "1.5"]), 1.5);
    std::fs::remove_file(&sensor).unwrap();
    assert_eq!(settings(&[]), (1.0, "matched_grid".into()));
    // A --step leaves the grid matched to the scan.
    assert_eq!(settings(&["--step", "0.02"]), (1.0, "matched_grid".into()));
}
