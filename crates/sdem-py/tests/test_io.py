"""sdem.read_points reads the formats the command line reads, as (N, 3) float64."""


import numpy as np
import pytest

import sdem

POINTS = np.array([[1.0, 2.0, 3.0], [-0.5, 0.25, 4.0], [7.0, -1.0, 0.5]])


def test_xyz_text(tmp_path):
    path = tmp_path / "scan.xyz"
    np.savetxt(path, POINTS)
    read = sdem.read_points(path)
    assert read.shape == (3, 3) and read.dtype == np.float64
    np.testing.assert_allclose(read, POINTS)


def test_binary_ply_with_a_nan_row_skipped(tmp_path):
    rows = np.vstack([POINTS, [np.nan, 0.0, 0.0]]).astype("<f4")
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 4\n"
              "property float x\nproperty float y\nproperty float z\nend_header\n")
    path = tmp_path / "scan.ply"
    path.write_bytes(header.encode() + rows.tobytes())
    np.testing.assert_allclose(sdem.read_points(str(path)), POINTS)


def test_binary_pcd(tmp_path):
    header = ("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\n"
              "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA binary\n")
    path = tmp_path / "scan.pcd"
    path.write_bytes(header.encode() + POINTS.astype("<f4").tobytes())
    np.testing.assert_allclose(sdem.read_points(path), POINTS)


def test_kitti_bin(tmp_path):
    path = tmp_path / "000000.bin"
    records = np.hstack([POINTS, np.full((3, 1), 0.5)]).astype("<f4")
    records.tofile(path)
    np.testing.assert_allclose(sdem.read_points(path), POINTS)


def test_3dtk_centimetres_become_metres_in_sdem_axes(tmp_path):
    path = tmp_path / "scan000.3d"
    # 3DTK: x right, y up, z forward, centimetres.
    path.write_text("".join(f"{-y * 100} {z * 100} {x * 100}\n" for x, y, z in POINTS))
    np.testing.assert_allclose(sdem.read_points(path), POINTS, atol=1e-12)


def test_points_read_from_a_file_localize_like_the_array(pairs, tmp_path):
    pair = pairs[6]
    for name in ("reference", "query"):
        header = ("ply\nformat binary_little_endian 1.0\n"
                  f"element vertex {len(pair[name + '_points'])}\n"
                  "property double x\nproperty double y\nproperty double z\nend_header\n")
        (tmp_path / f"{name}.ply").write_bytes(
            header.encode() + pair[name + "_points"].astype("<f8").tobytes())
    ref = sdem.Scan(sdem.read_points(tmp_path / "reference.ply"),
                    attitude_deg=pair["reference_attitude_deg"])
    qry = sdem.Scan(sdem.read_points(tmp_path / "query.ply"),
                    attitude_deg=pair["query_attitude_deg"])
    res = sdem.localize(ref, qry, window=pair["window"])
    truth = pair["reference_from_query"]
    assert np.linalg.norm(res.reference_from_query[:3, 3] - truth[:3, 3]) < 0.005


def test_an_empty_cloud_is_a_parse_error(tmp_path):
    path = tmp_path / "empty.xyz"
    path.write_text("# nothing\n")
    with pytest.raises(sdem.ParseError, match="no points"):
        sdem.read_points(path)


