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

/// Writes `out/survey.e57` with pye57 (libE57Format): scan "A" with 300 points at
/// (2 cos 0.1k, 2 sin 0.1k, 0.01k − 1), intensity and colour, then 20 points flagged invalid
/// (`cartesianInvalidState` 2) at (9, 9, 9), posed at (10, −5, 0.5) turned 90° about z; scan
/// "B" with the first 100 of those points and nothing else, at the identity.
const PYE57_SCRIPT: &str = r#"
import sys
import numpy as np
import pye57

out = sys.argv[1]
k = np.arange(300)
xyz = np.stack([2 * np.cos(0.1 * k), 2 * np.sin(0.1 * k), 0.01 * k - 1])
bad = np.full((3, 20), 9.0)
survey = pye57.E57(f"{out}/survey.e57", mode="w")
a = {
    "cartesianX": np.concatenate([xyz[0], bad[0]]),
    "cartesianY": np.concatenate([xyz[1], bad[1]]),
    "cartesianZ": np.concatenate([xyz[2], bad[2]]),
    "cartesianInvalidState": np.concatenate([np.zeros(300), np.full(20, 2)]).astype(np.int8),
    "intensity": np.linspace(0.0, 1.0, 320),
    "colorRed": np.full(320, 200, np.uint8),
    "colorGreen": np.full(320, 100, np.uint8),
    "colorBlue": np.full(320, 50, np.uint8),
}
half = np.sqrt(0.5)
survey.write_scan_raw(a, name="A", rotation=np.array([half, 0, 0, half]),
                      translation=np.array([10.0, -5.0, 0.5]))
b = {"cartesianX": xyz[0][:100], "cartesianY": xyz[1][:100], "cartesianZ": xyz[2][:100]}
survey.write_scan_raw(b, name="B")
survey.close()
"#;

#[test]
fn an_e57_survey_written_by_pye57_reads_every_scan_in_its_own_frame() {
    let dir = tempfile::tempdir().unwrap();
    run_python(PYE57_SCRIPT, &[dir.path()]);
    let scans = sdem_io::read_e57(&dir.path().join("survey.e57")).unwrap();
    assert_eq!(scans.len(), 2);
    let expected = |k: usize| {
        let k = k as f64;
        Vec3::new(2.0 * (0.1 * k).cos(), 2.0 * (0.1 * k).sin(), 0.01 * k - 1.0)
    };
    let (a, b) = (&scans[0], &scans[1]);
    assert_eq!(a.name.as_deref(), Some("A"));
    assert_eq!((a.points_in_sensor.len(), a.dropped), (300, 20));
    assert_eq!((b.points_in_sensor.len(), b.dropped), (100, 0));
    for scan in [a, b] {
        for (k, p) in scan.points_in_sensor.iter().enumerate() {
            // pye57 stores coordinates as scaled integers of 0.1 mm or finer.
            assert!((p - expected(k)).norm() < 1e-4, "point {k}: {p:?}");
        }
    }
    let pose = a.world_from_sensor.expect("scan A has a pose");
    assert!((pose.translation.vector - Vec3::new(10.0, -5.0, 0.5)).norm() < 1e-9);
    let x_axis = pose.rotation * Vec3::x();
    assert!((x_axis - Vec3::y()).norm() < 1e-9, "{x_axis:?}");
    let identity = b
        .world_from_sensor
        .expect("pye57 writes a pose for every scan");
    assert!(identity.to_homogeneous().is_identity(1e-12));
}
