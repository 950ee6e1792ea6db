//! Scans in the formats other tools write, through the real binary: a held-out pair saved by
//! Open3D as compressed PCD (committed in `tests/fixtures/open3d-pair`, see its README), and
//! scans written by laspy (LAZ) and pye57 (E57) at test time with `SDEM_TEST_PYTHON`.

mod common;

use common::{run_json, run_ok, run_python};
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn s(path: &Path) -> &str {
    path.to_str().expect("paths are UTF-8")
}

#[test]
fn a_pair_saved_by_open3d_as_compressed_pcd_localizes_within_a_centimetre() {
    let dir = tempfile::tempdir().unwrap();
    let pair = fixture("open3d-pair");
    let head = std::fs::read(pair.join("scans/000001.pcd")).unwrap();
    assert!(
        String::from_utf8_lossy(&head[..300]).contains("DATA binary_compressed"),
        "the fixture is not compressed PCD"
    );
    let json = run_json(
        dir.path(),
        &[
            "localize",
            s(&pair),
            "--reference",
            "0",
            "--query",
            "1",
            "--json",
        ],
    );
    assert_eq!(json["trusted"], true, "{json}");
    let error_m = json["error_m"].as_f64().unwrap();
    assert!(error_m <= 0.01, "error {error_m} m against poses_truth.txt");
}

/// Rewrites every `scans/NNNNNN.ply` of the dataset `dataset` as `scans/NNNNNN.laz` written by
/// laspy (LAS 1.4, point format 6, 0.1 mm steps, lazrs), through `.xyz` text.
fn scans_to_laz(dataset: &Path) {
    let scans = dataset.join("scans");
    let mut plys: Vec<PathBuf> = std::fs::read_dir(&scans)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "ply"))
        .collect();
    plys.sort();
    for ply in &plys {
        let points = sdem_io::read_points(ply).unwrap();
        let text: String = points
            .iter()
            .map(|p| format!("{} {} {}\n", p.x, p.y, p.z))
            .collect();
        std::fs::write(ply.with_extension("xyz"), text).unwrap();
        std::fs::remove_file(ply).unwrap();
    }
    run_python(
        &scans,
        r#"
import glob, os
import laspy
import numpy as np
for xyz in sorted(glob.glob("*.xyz")):
    points = np.loadtxt(xyz)
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([1e-4, 1e-4, 1e-4])
    header.offsets = np.array([0.0, 0.0, 0.0])
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    las.write(xyz[:-4] + ".laz", laz_backend=laspy.LazBackend.Lazrs)
    os.remove(xyz)
"#,
        &[],
    );
}

#[test]
fn a_pair_of_laz_scans_written_by_laspy_localizes_within_a_centimetre() {
    let dir = tempfile::tempdir().unwrap();
    let pair = dir.path().join("pair");
    run_ok(
        dir.path(),
        &[
            "simulate",
            "--out",
            s(&pair),
            "--seed",
            "12",
            "--stops",
            "2",
        ],
    );
    scans_to_laz(&pair);
    assert!(pair.join("scans/000001.laz").is_file());
    let json = run_json(
        dir.path(),
        &[
            "localize",
            s(&pair),
            "--reference",
            "0",
            "--query",
            "1",
            "--json",
        ],
    );
    assert_eq!(json["trusted"], true, "{json}");
    let error_m = json["error_m"].as_f64().unwrap();
    assert!(error_m <= 0.01, "error {error_m} m against poses_truth.txt");
}
