//! Issue 21, items 1 and 4 at the command line: the attitude is a measurement with a standard
//! deviation. `sdem localize` and `sdem slam` take it from attitude.csv's σ columns, else
//! sensor.toml's `attitude_sigma_*_deg`, else the defaults, or from `--attitude-sigma-deg`;
//! the heading is searched over 3σ of the two readings' difference, and the output says what
//! was assumed, in words and in the JSON. A bad σ is a one-line error naming where it is.

mod common;

use common::{doubt_kinds, run, run_err, run_json, run_ok};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn s(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}

/// `sdem simulate --stops 2` in `dir/ds`.
fn simulated(dir: &Path) -> PathBuf {
    let ds = dir.join("ds");
    run_ok(
        dir,
        &["simulate", "--out", s(&ds), "--stops", "2", "--seed", "1"],
    );
    ds
}

/// A quick localization of scan 1 against scan 0: a small window around the true step.
const QUICK: [&str; 5] = [
    "--window",
    "0.25:0.45,-0.1:0.1,-0.05:0.05",
    "--step",
    "0.02",
    "--no-runner-up",
];

fn localize_args<'a>(ds: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["localize", s(ds), "--reference", "0", "--query", "1"];
    args.extend_from_slice(&QUICK);
    args.extend_from_slice(extra);
    args
}

/// `localize --json` (status 0, or 3 with `--accept-doubtful` added).
fn localize(dir: &Path, ds: &Path, extra: &[&str]) -> Value {
    let mut args = localize_args(ds, extra);
    args.extend_from_slice(&["--accept-doubtful", "--json"]);
    run_json(dir, &args)
}

/// Writes `sensor.toml` as the simulator wrote it with `top` put first (keys outside any table).
fn sensor_toml_with(ds: &Path, top: &str) {
    let path = ds.join("sensor.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let text = text.replace(&format!("{top}\n"), "");
    std::fs::write(&path, format!("{top}\n{text}")).unwrap();
}

fn num(value: &Value, key: &str) -> f64 {
    value[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} in {value}"))
}

/// Each source of σ reaches the search: the heading range is 3σ of the two readings'
/// difference, the JSON names the source and the text says it in words.
#[test]
fn sigma_from_each_source_sets_the_heading_searched() {
    let dir = tempfile::tempdir().unwrap();
    let ds = simulated(dir.path());
    let expect = |result: &Value, from: &str, heading: f64| {
        let a = &result["attitude"];
        assert_eq!(a["source"], "readings", "{a}");
        assert_eq!(a["sigma_from"], from, "{a}");
        assert!(
            (num(a, "heading_searched_deg") - heading).abs() < 1e-6,
            "{heading}: {a}"
        );
        assert_eq!(a["roll_pitch_searched"], false, "{a}");
        for scan in ["reference", "query"] {
            for key in [
                "roll_deg",
                "pitch_deg",
                "yaw_deg",
                "sigma_roll_pitch_deg",
                "sigma_yaw_deg",
            ] {
                num(&a[scan], key);
            }
        }
    };

    // The defaults: 3.5° each, ±3·√2·3.5°.
    let default = localize(dir.path(), &ds, &[]);
    expect(&default, "the default", 3.0 * 2f64.sqrt() * 3.5);
    let text = run(dir.path(), &localize_args(&ds, &[])).stdout;
    assert!(
        text.contains("attitude: from attitude.csv, compass σ 3.5°, roll/pitch σ 0.5° (the default): heading searched ±14.85°"),
        "{text}"
    );

    // sensor.toml's σ: a narrower heading search, fewer candidates.
    sensor_toml_with(&ds, "attitude_sigma_yaw_deg = 1.0");
    let narrow = localize(dir.path(), &ds, &[]);
    expect(&narrow, "sensor.toml", 3.0 * 2f64.sqrt());
    assert!(
        num(&narrow, "candidates_total") < num(&default, "candidates_total"),
        "{narrow}\n{default}"
    );
    assert!((num(&narrow["attitude"]["query"], "sigma_yaw_deg") - 1.0).abs() < 1e-12);

    // attitude.csv's own σ per row wins over sensor.toml's.
    let csv = ds.join("attitude.csv");
    let old = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<String> = old
        .lines()
        .skip(1)
        .zip(["2", "20"])
        .map(|(row, yaw_sigma)| format!("{row},0.5,{yaw_sigma}"))
        .collect();
    std::fs::write(
        &csv,
        format!(
            "{}\n{}\n",
            sdem_io::ATTITUDE_HEADER_WITH_SIGMA,
            rows.join("\n")
        ),
    )
    .unwrap();
    let per_row = localize(dir.path(), &ds, &[]);
    expect(&per_row, "attitude.csv", 3.0 * 2f64.hypot(20.0));
    let text = run(dir.path(), &localize_args(&ds, &[])).stdout;
    assert!(text.contains("compass σ 2° and 20°"), "{text}");

    // The command line's σ wins over both; a σ of 60° reaches a full turn.
    let flag = localize(dir.path(), &ds, &["--attitude-sigma-deg", "0.5,5"]);
    expect(&flag, "--attitude-sigma-deg", 3.0 * 2f64.sqrt() * 5.0);
    let full = localize(dir.path(), &ds, &["--attitude-sigma-deg", "0.5,60"]);
    expect(&full, "--attitude-sigma-deg", 180.0);
    let text = run(
        dir.path(),
        &localize_args(&ds, &["--attitude-sigma-deg", "0.5,60"]),
    )
    .stdout;
    assert!(text.contains("heading searched over a full turn"), "{text}");

    // --heading-window overrides the σ's range.
    let window = localize(dir.path(), &ds, &["--heading-window", "3"]);
    assert_eq!(window["attitude"]["heading_searched_deg"], 3.0, "{window}");
    assert_eq!(
        window["attitude"]["heading_searched_from"],
        "heading_window"
    );
    let text = run(dir.path(), &localize_args(&ds, &["--heading-window", "0"])).stdout;
    assert!(
        text.contains("heading taken from the compass (--heading-window 0)"),
        "{text}"
    );
}

/// The roll/pitch σ reaches the library's check of the match against the readings: the
/// simulated gyro errs by about 0.05°, so a σ of 0.001° makes the match's tilt a doubt
/// (`attitude_corrected`, status 3), and the default σ does not.
#[test]
fn a_tight_roll_pitch_sigma_makes_the_tilt_a_doubt() {
    let dir = tempfile::tempdir().unwrap();
    let ds = simulated(dir.path());
    let mut args = localize_args(&ds, &["--heading-window", "0", "--json"]);
    let trusted = run(dir.path(), &args);
    assert_eq!(
        trusted.code,
        Some(0),
        "{}{}",
        trusted.stdout,
        trusted.stderr
    );
    args.extend_from_slice(&["--attitude-sigma-deg", "0.001,3.5"]);
    let r = run(dir.path(), &args);
    assert_eq!(r.code, Some(3), "{}{}", r.stdout, r.stderr);
    let result = r.json();
    assert!(
        doubt_kinds(&result).contains(&"attitude_corrected".to_string()),
        "{result}"
    );
}

/// A bad σ, in sensor.toml, attitude.csv or on the command line: one line on stderr naming the
/// file and line or the flag, and what is wrong (status 1).
#[test]
fn a_bad_sigma_is_a_one_line_error_naming_where() {
    let dir = tempfile::tempdir().unwrap();
    let ds = simulated(dir.path());
    let args = localize_args(&ds, &[]);
    let original = std::fs::read_to_string(ds.join("sensor.toml")).unwrap();
    for (top, why) in [
        ("attitude_sigma_yaw_deg = -3.5", "positive"),
        ("attitude_sigma_yaw_deg = 0", "zero"),
        ("attitude_sigma_roll_pitch_deg = nan", "positive"),
        (
            "attitude_sigma_roll_pitch_deg = \"half a degree\"",
            "degrees",
        ),
        ("attitude_sigma_yaw_deg = 400", "more than 180"),
    ] {
        std::fs::write(ds.join("sensor.toml"), format!("{top}\n{original}")).unwrap();
        let m = run_err(dir.path(), &args);
        let key = top.split(' ').next().unwrap();
        assert!(
            m.contains("sensor.toml:1:") && m.contains(key) && m.contains(why),
            "{top}: {m}"
        );
    }
    // Appended at the end, the key falls into [lift]: the error says where it belongs.
    std::fs::write(
        ds.join("sensor.toml"),
        format!("{original}attitude_sigma_yaw_deg = 20\n"),
    )
    .unwrap();
    let m = run_err(dir.path(), &args);
    assert!(
        m.contains("inside [lift]") && m.contains("top of the file"),
        "{m}"
    );
    std::fs::write(ds.join("sensor.toml"), &original).unwrap();

    // A malformed σ is a usage error (exit status 2) naming the flag.
    for value in ["-1,3", "0.5,0", "nan,3", "a,b", "1", "1,2,3", "0.5,200"] {
        let r = run(
            dir.path(),
            &localize_args(&ds, &["--attitude-sigma-deg", value]),
        );
        assert_eq!(r.code, Some(2), "{value}: {}", r.stderr);
        assert!(
            r.stderr.contains("--attitude-sigma-deg"),
            "{value}: {}",
            r.stderr
        );
    }

    // --assume-level with readings: they are used, the flag is refused.
    let m = run_err(dir.path(), &localize_args(&ds, &["--assume-level"]));
    assert!(
        m.contains("--assume-level") && m.contains("attitude.csv"),
        "{m}"
    );

    // With --map, the σ describes --attitude and needs it: a usage error.
    common::usage_error(
        dir.path(),
        &[
            "localize",
            "--map",
            s(&dir.path().join("nowhere")),
            "--scan",
            "x.ply",
            "--attitude-sigma-deg",
            "0.5,3",
        ],
        &["--attitude-sigma-deg", "--attitude R,P,Y"],
    );
}

/// `sdem slam` passes each reading with its σ to the loop and reports where it came from;
/// `--attitude-sigma-deg` needs attitude.csv.
#[test]
fn slam_reports_the_readings_sigma() {
    let dir = tempfile::tempdir().unwrap();
    let ds = simulated(dir.path());
    sensor_toml_with(&ds, "attitude_sigma_yaw_deg = 2.0");
    let out = dir.path().join("out");
    let args = ["slam", s(&ds), "--out", s(&out), "--no-pictures"];
    let text = run_ok(dir.path(), &args);
    assert!(
        text.contains("attitude: from attitude.csv, compass σ 2°, roll/pitch σ 0.5° (sensor.toml)"),
        "{text}"
    );
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let a = &report["attitude"];
    assert_eq!(a["source"], "readings", "{a}");
    assert_eq!(a["sigma_from"], "sensor.toml", "{a}");
    assert_eq!(a["sigma_yaw_deg"], 2.0, "{a}");

    let json = run_json(
        dir.path(),
        &[
            &args[..],
            &["--force", "--json", "--attitude-sigma-deg", "1,10"],
        ]
        .concat(),
    );
    assert_eq!(
        json["attitude"]["sigma_from"], "--attitude-sigma-deg",
        "{json}"
    );
    assert_eq!(json["attitude"]["sigma_yaw_deg"], 10.0, "{json}");

    std::fs::remove_file(ds.join("attitude.csv")).unwrap();
    let m = run_err(
        dir.path(),
        &[&args[..], &["--force", "--attitude-sigma-deg", "1,10"]].concat(),
    );
    assert!(
        m.contains("--attitude-sigma-deg") && m.contains("no attitude.csv"),
        "{m}"
    );
    let json = run_json(dir.path(), &[&args[..], &["--force", "--json"]].concat());
    assert_eq!(json["attitude"]["source"], "unknown", "{json}");
}
