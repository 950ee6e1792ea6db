//! Helpers shared by the integration tests: run the real `sdem` binary in a folder and check
//! how it ended. (Each test file uses only some of them.)
#![allow(dead_code)]

use assert_cmd::Command;
use serde_json::Value;
use std::path::Path;

/// A scan of 200 points on a wavy ellipse (3 m by 2 m, ±0.5 m in height) as `.xyz` text: a
/// valid scan that tests copy and damage.
pub fn wavy_ellipse_xyz() -> String {
    (0..200)
        .map(|i| {
            let a = f64::from(i) * 0.0314;
            format!(
                "{} {} {}\n",
                3.0 * a.cos(),
                2.0 * a.sin(),
                0.5 * (3.0 * a).sin()
            )
        })
        .collect()
}

/// The `sdem` binary, run in `dir`.
pub fn sdem(dir: &Path) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_sdem"));
    cmd.current_dir(dir);
    cmd
}

/// What a finished command left behind.
pub struct Run {
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
}

impl Run {
    /// Its stdout as one JSON object, whatever its exit status (a result with doubts exits 3
    /// and still prints it; [`run_json`] demands 0).
    pub fn json(&self) -> Value {
        let value: Value = serde_json::from_str(&self.stdout).unwrap_or_else(|e| {
            panic!(
                "stdout is not exactly one JSON value ({e}):\n{}\n{}",
                self.stdout, self.stderr
            )
        });
        assert!(value.is_object(), "not an object: {value}");
        value
    }
}

pub fn run(dir: &Path, args: &[&str]) -> Run {
    let out = sdem(dir).args(args).output().expect("cannot run sdem");
    Run {
        code: out.status.code(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Runs `args`, expects success and returns stdout.
pub fn run_ok(dir: &Path, args: &[&str]) -> String {
    let r = run(dir, args);
    assert_eq!(
        r.code,
        Some(0),
        "sdem {args:?} failed\nstdout:\n{}\nstderr:\n{}",
        r.stdout,
        r.stderr
    );
    assert!(
        !r.stderr.contains("panicked"),
        "sdem {args:?}: {}",
        r.stderr
    );
    r.stdout
}

/// Runs `args --json`-style: expects success and exactly one JSON object on stdout.
pub fn run_json(dir: &Path, args: &[&str]) -> Value {
    let stdout = run_ok(dir, args);
    let value: Value = serde_json::from_str(&stdout).unwrap_or_else(|e| {
        panic!("sdem {args:?}: stdout is not exactly one JSON value ({e}):\n{stdout}")
    });
    assert!(value.is_object(), "sdem {args:?}: not an object: {value}");
    value
}

/// Runs `args`, expects a failure of the sdem's own (exit code 1, no panic, nothing on stdout,
/// exactly one non-empty stderr line) and returns that line.
pub fn run_err(dir: &Path, args: &[&str]) -> String {
    let r = run(dir, args);
    assert!(
        r.code.is_some_and(|c| c != 0),
        "sdem {args:?} should fail, got {:?}\nstdout:\n{}",
        r.code,
        r.stdout
    );
    assert_eq!(r.code, Some(1), "sdem {args:?}: stderr:\n{}", r.stderr);
    assert!(
        !r.stderr.contains("panicked"),
        "sdem {args:?} panicked:\n{}",
        r.stderr
    );
    assert!(
        r.stdout.trim().is_empty(),
        "sdem {args:?} failed but printed on stdout:\n{}",
        r.stdout
    );
    let lines: Vec<&str> = r.stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(
        lines.len(),
        1,
        "sdem {args:?}: expected a one-line error, got:\n{}",
        r.stderr
    );
    lines[0].to_string()
}

/// Runs `args`, expects a usage error (exit code 2, clap's message, no panic, nothing on
/// stdout) whose stderr contains every one of `wanted`, and returns stderr.
pub fn usage_error(dir: &Path, args: &[&str], wanted: &[&str]) -> String {
    let r = run(dir, args);
    assert_eq!(r.code, Some(2), "sdem {args:?}: {}", r.stderr);
    assert!(
        !r.stderr.contains("panicked"),
        "sdem {args:?}: {}",
        r.stderr
    );
    assert!(r.stdout.trim().is_empty(), "sdem {args:?}: {}", r.stdout);
    assert!(
        r.stderr.starts_with("error: "),
        "sdem {args:?}: {}",
        r.stderr
    );
    for w in wanted {
        assert!(
            r.stderr.contains(w),
            "sdem {args:?}: {:?} lacks {w:?}",
            r.stderr
        );
    }
    r.stderr
}

/// Runs `args`, expects exit code 1 and no panic, and returns stderr (whatever its length).
pub fn fails(dir: &Path, args: &[&str]) -> String {
    let r = run(dir, args);
    assert_eq!(r.code, Some(1), "sdem {args:?}: {}", r.stderr);
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    r.stderr
}

/// Checks the `doubts` of a result: each an object with its `kind` and a `message` in words.
/// Returns the kinds.
pub fn doubt_kinds(result: &Value) -> Vec<String> {
    let doubts = result["doubts"]
        .as_array()
        .unwrap_or_else(|| panic!("no doubts array in {result}"));
    doubts
        .iter()
        .map(|d| {
            let message = d["message"].as_str().unwrap_or_default();
            assert!(message.len() > 20, "a doubt without its message: {d}");
            d["kind"]
                .as_str()
                .unwrap_or_else(|| panic!("{d}"))
                .to_string()
        })
        .collect()
}

/// The Python that has the packages of `scripts/test-requirements.txt` (pye57, laspy, …), from
/// `SDEM_TEST_PYTHON`. Without it the test fails saying how to make one: it is never skipped.
pub fn test_python() -> std::path::PathBuf {
    match std::env::var_os("SDEM_TEST_PYTHON") {
        Some(python) if !python.is_empty() => std::path::PathBuf::from(python),
        _ => panic!(
            "SDEM_TEST_PYTHON is not set: this test writes its input with pye57 or laspy. Run \
             scripts/test (it makes target/test-venv from scripts/test-requirements.txt and sets \
             it), or make one: python3 -m venv target/test-venv && target/test-venv/bin/pip \
             install -r scripts/test-requirements.txt, then SDEM_TEST_PYTHON=$PWD/target/\
             test-venv/bin/python cargo test"
        ),
    }
}

/// Runs the Python `script` with `args` in `dir`; panics with its output when it fails.
pub fn run_python(dir: &Path, script: &str, args: &[&str]) {
    let python = test_python();
    let out = std::process::Command::new(&python)
        .current_dir(dir)
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run SDEM_TEST_PYTHON={}: {e}", python.display()));
    assert!(
        out.status.success(),
        "the Python script failed ({}):\n{}\n{}",
        python.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The number of lines of a text file (a KITTI pose file's poses).
pub fn lines(path: &Path) -> usize {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .count()
}
