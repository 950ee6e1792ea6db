//! Scans in the formats other tools write, through the real binary: a held-out pair saved by
//! Open3D as compressed PCD (committed in `tests/fixtures/open3d-pair`, see its README).

mod common;

use common::run_json;
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
