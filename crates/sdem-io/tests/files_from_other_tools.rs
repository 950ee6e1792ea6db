//! sdem's readers on files written by other tools: PCD by Open3D (committed fixtures, see
//! `tests/fixtures/README.md`), E57 by `pye57` and LAS/LAZ by `laspy` (written here, at test
//! time, by the Python of `SDEM_TEST_PYTHON`; `scripts/test` makes it).

use sdem::geometry::Vec3;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The Python that has the packages of `scripts/test-requirements.txt`, from `SDEM_TEST_PYTHON`.
/// Without it the test fails saying how to make one: it is never skipped.
fn python() -> PathBuf {
    match std::env::var_os("SDEM_TEST_PYTHON") {
        Some(python) if !python.is_empty() => PathBuf::from(python),
        _ => panic!(
            "SDEM_TEST_PYTHON is not set: this test writes its input with pye57 or laspy. Run \
             scripts/test (it makes target/test-venv from scripts/test-requirements.txt and sets \
             it), or make one: python3 -m venv target/test-venv && target/test-venv/bin/pip \
             install -r scripts/test-requirements.txt, then SDEM_TEST_PYTHON=$PWD/target/\
             test-venv/bin/python cargo test"
        ),
    }
}

/// Runs the Python `script` with `args`; panics with its output when it fails.
fn run_python(script: &str, args: &[&Path]) {
    let python = python();
    let out = Command::new(&python)
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

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The cloud of `fixtures/open3d/make_open3d_pcd.py`, as `f32`, without point 7 (NaN).
fn open3d_cloud() -> Vec<Vec3> {
    (0..40)
        .filter(|&k| k != 7)
        .map(|k| {
            let k = f64::from(k);
            let p = [
                0.75 * (k * 0.3).cos(),
                0.75 * (k * 0.3).sin(),
                0.01 * k - 0.2,
            ];
            Vec3::from(p.map(|v| f64::from(v as f32)))
        })
        .collect()
}

#[test]
fn pcd_files_written_by_open3d_read_in_every_data_mode() {
    let expected = open3d_cloud();
    for name in [
        "legacy_ascii.pcd",
        "legacy_binary.pcd",
        "legacy_compressed.pcd",
        "tensor_compressed.pcd",
    ] {
        let points = sdem_io::read_points(&fixture("open3d").join(name)).unwrap();
        assert_eq!(points.len(), expected.len(), "{name}");
        for (i, (p, q)) in points.iter().zip(&expected).enumerate() {
            // ASCII holds 10 significant digits; binary the f32 itself.
            assert!(
                (p - q).norm() < 1e-7,
                "{name}: point {i} is {p:?}, not {q:?}"
            );
        }
    }
}

/// Writes `out/a12.las`, `a12.laz` (LAS 1.2, point format 3) and `a14.las`, `a14.laz` (LAS 1.4,
/// point format 6: LAZ's layered chunks) with laspy and lazrs: 500 points at
/// (2 cos 0.1k, 2 sin 0.1k, 0.001k − 0.3), stored in millimetres from an offset of
/// (1000, −2000, 50) m, with intensities and GPS times.
const LASPY_SCRIPT: &str = r#"
import sys
import laspy
import numpy as np

out = sys.argv[1]
k = np.arange(500)
for name, version, point_format in [("a12", "1.2", 3), ("a14", "1.4", 6)]:
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([1000.0, -2000.0, 50.0])
    las = laspy.LasData(header)
    las.x = 2 * np.cos(0.1 * k)
    las.y = 2 * np.sin(0.1 * k)
    las.z = 0.001 * k - 0.3
    las.intensity = (k * 37) % 65536
    las.gps_time = 1000.0 + k
    las.write(f"{out}/{name}.las")
    las.write(f"{out}/{name}.laz", laz_backend=laspy.LazBackend.Lazrs)
"#;

#[test]
fn las_and_laz_written_by_laspy_read_with_scale_and_offset() {
    let dir = tempfile::tempdir().unwrap();
    run_python(LASPY_SCRIPT, &[dir.path()]);
    for name in ["a12.las", "a12.laz", "a14.las", "a14.laz"] {
        let points = sdem_io::read_points(&dir.path().join(name)).unwrap();
        assert_eq!(points.len(), 500, "{name}");
        for (k, p) in points.iter().enumerate() {
            let k = k as f64;
            let expected = Vec3::new(
                2.0 * (0.1 * k).cos(),
                2.0 * (0.1 * k).sin(),
                0.001 * k - 0.3,
            );
            // Millimetre steps: each coordinate within half a step.
            assert!(
                (p - expected).amax() <= 0.0005 + 1e-9,
                "{name}: point {k} is {p:?}, not {expected:?}"
            );
        }
    }
}
