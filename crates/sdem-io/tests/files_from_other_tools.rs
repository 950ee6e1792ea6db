//! sdem's readers on files written by other tools: PCD by Open3D (committed fixtures, see
//! `tests/fixtures/README.md`), E57 by `pye57` and LAS/LAZ by `laspy` (written here, at test
//! time, by the Python of `SDEM_TEST_PYTHON`; `scripts/test` makes it).

use sdem::geometry::Vec3;
use std::path::{Path, PathBuf};

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
