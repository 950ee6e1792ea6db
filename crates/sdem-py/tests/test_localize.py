"""sdem.Scan and sdem.localize against simulated truth."""

import numpy as np
import pytest
from conftest import rotation_error_deg, translation_error_m

import sdem


def scans(pair, dtype=np.float64, order="C"):
    ref = sdem.Scan(
        np.asarray(pair["reference_points"], dtype=dtype, order=order),
        attitude_deg=pair["reference_attitude_deg"],
    )
    qry = sdem.Scan(
        np.asarray(pair["query_points"], dtype=dtype, order=order),
        attitude_deg=pair["query_attitude_deg"],
    )
    return ref, qry


def test_held_out_pairs_localize_to_two_millimetres_median_and_no_trusted_pose_is_wrong(pairs):
    errors_m, errors_deg = [], []
    for pair in pairs:
        ref, qry = scans(pair)
        res = sdem.localize(ref, qry, window=pair["window"])
        dt = translation_error_m(res.reference_from_query, pair["reference_from_query"])
        dr = rotation_error_deg(res.reference_from_query, pair["reference_from_query"])
        if res.trusted:
            assert dt < 0.02 and dr < 0.5, (dt, dr, res)
        errors_m.append(dt)
        errors_deg.append(dr)
    print(f"median {np.median(errors_m) * 1e3:.2f} mm, {np.median(errors_deg):.3f} deg; "
          f"largest {max(errors_m) * 1e3:.2f} mm")
    assert np.median(errors_m) <= 0.002
    assert np.median(errors_deg) <= 0.1
    assert sum(e < 0.02 for e in errors_m) >= 19


def test_float32_float64_and_fortran_order_give_the_same_pose(pairs):
    pair = pairs[1]
    poses = []
    for dtype, order in ((np.float64, "C"), (np.float32, "C"), (np.float64, "F"), (np.float32, "F")):
        ref, qry = scans(pair, dtype, order)
        res = sdem.localize(ref, qry, window=pair["window"])
        assert translation_error_m(res.reference_from_query, pair["reference_from_query"]) < 0.005
        poses.append(res.reference_from_query)
    # float32 rounds coordinates by ~1e-7 relative; the S-DEM keeps float32 anyway. The order
    # changes nothing but the memory layout. (The refinement's parallel sums vary in the last
    # digits from run to run, so "the same" is to a micrometre.)
    for pose in poses[1:]:
        assert np.abs(pose - poses[0]).max() < 1e-5


def test_a_non_contiguous_view_reads_the_same_points(pairs):
    pair = pairs[2]
    wide = np.zeros((len(pair["query_points"]), 6))
    wide[:, ::2] = pair["query_points"]  # every other column: a non-contiguous (N, 3) view
    view = wide[:, ::2]
    assert not view.flags["C_CONTIGUOUS"] and not view.flags["F_CONTIGUOUS"]
    ref, qry = scans(pair)
    strided = sdem.Scan(view, attitude_deg=pair["query_attitude_deg"])
    assert len(strided) == len(qry)
    np.testing.assert_array_equal(strided.points, qry.points)


def test_the_result_holds_a_rigid_pose_covariance_doubts_time_and_diagnostics(pairs):
    pair = pairs[3]
    ref, qry = scans(pair)
    res = sdem.localize(ref, qry, window=pair["window"])
    pose = res.reference_from_query
    assert pose.shape == (4, 4) and pose.dtype == np.float64
    np.testing.assert_allclose(pose[3], [0, 0, 0, 1])
    np.testing.assert_allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-9)
    assert res.covariance.shape == (6, 6) and res.covariance.dtype == np.float64
    np.testing.assert_allclose(res.covariance, res.covariance.T, atol=1e-15)
    assert np.all(np.linalg.eigvalsh(res.covariance) > 0)
    assert res.trusted is True and res.doubts == []
    assert res.time_ms > 0
    d = res.diagnostics
    for key in ("overlap_fraction", "inlier_fraction", "cost", "overlap", "runner_up",
                "ambiguous", "covariance", "weakest_direction", "refinement"):
        assert key in d, key
    assert d["ambiguous"] is False
    assert d["cost"] == pytest.approx(res.cost) and d["overlap"] == res.overlap
    assert d["refinement"]["outcome"] == "six_dof"
    assert 0 < d["inlier_fraction"] <= 1


def test_a_window_short_of_the_truth_gives_doubts_or_an_error_never_a_wrong_trusted_pose(pairs):
    kinds_seen = set()
    for pair in pairs[:3]:
        truth = pair["reference_from_query"]
        t = truth[:3, 3]
        window = {"min": list(t - 0.3), "max": list(t + 0.3)}
        window["max"][0] = float(t[0] - 0.15)  # x stops 15 cm short of the truth
        ref, qry = scans(pair)
        try:
            res = sdem.localize(ref, qry, window=window)
        except sdem.MatchError:
            continue
        if res.trusted:
            assert translation_error_m(res.reference_from_query, truth) < 0.02
            continue
        assert res.doubts, "an untrusted result says why"
        for doubt in res.doubts:
            kinds_seen.add(doubt.kind)
            as_dict = doubt.to_dict()
            assert as_dict["kind"] == doubt.kind and as_dict["message"] == doubt.message
            assert str(doubt) == doubt.message and doubt.message
            for name, value in doubt.figures.items():
                assert getattr(doubt, name) == value and as_dict[name] == value
            assert repr(doubt).startswith("sdem.Doubt(kind='")
    assert "on_window_edge" in kinds_seen, kinds_seen
    assert kinds_seen <= {"runner_up", "flat_covariance", "flat_cost", "unconstrained", "few_inliers",
                          "refinement_failed", "on_window_edge", "attitude_corrected",
                          "another_rotation", "unrefuted_rotation", "seen_through",
                          "free_space_conflict", "taken_from_prediction",
                          "prior_conflict"}


def test_a_query_without_attitude_is_found_by_searching_its_rotation(run):
    truth = np.linalg.inv(run["world_from_sensor"][0]) @ run["world_from_sensor"][1]
    ref = sdem.Scan(run["points"][0], attitude_deg=run["attitude_deg"][0])
    qry = sdem.Scan(run["points"][1])  # no gyro: attitude unknown
    assert qry.attitude_deg is None and qry.sigma_deg is None
    res = sdem.localize(ref, qry)
    assert res.trusted, res.doubts
    assert translation_error_m(res.reference_from_query, truth) < 0.01
    assert rotation_error_deg(res.reference_from_query, truth) < 0.5


def test_the_attitude_and_its_sigma_belong_to_the_scan(pairs):
    pair = pairs[0]
    scan = sdem.Scan(pair["reference_points"], attitude_deg=(1.0, -2.0, 90.0),
                     yaw_sigma_deg=20.0)
    assert scan.attitude_deg == pytest.approx((1.0, -2.0, 90.0))
    assert scan.sigma_deg == pytest.approx((sdem.DEFAULT_ATTITUDE_SIGMA_DEG[0], 20.0))
    assert sdem.DEFAULT_ATTITUDE_SIGMA_DEG == pytest.approx((0.5, 3.5))
    assert scan.known_cells > 100 and scan.grid["resolution_deg"] == 1.0
    assert scan.points.shape == (len(scan), 3)
    coarse = sdem.Scan(pair["reference_points"], grid={"resolution_deg": 2.0})
    assert coarse.grid["resolution_deg"] == 2.0 and coarse.known_cells < scan.known_cells
    with pytest.raises(sdem.InvalidError, match="different S-DEM grids"):
        sdem.localize(scan, coarse)


def test_options_mirror_localize_options_name_for_name():
    defaults = sdem.localize_options()
    assert defaults["step_m"] == 0.01 and defaults["mode"] == "branch_and_bound"
    assert defaults["window"] == {"min": [-0.5, -0.3, -0.1], "max": [0.5, 0.6, 0.1]}
    assert defaults["cost"]["truncation_m"] == 0.05 and defaults["runner_up"] is True
    # A dict for a nested struct changes only the fields it names.
    changed = sdem.localize_options(cost={"truncation_m": 0.1}, heading={"step_deg": 0.5})
    assert changed["cost"]["truncation_m"] == 0.1
    assert changed["cost"]["min_overlap_cells"] == defaults["cost"]["min_overlap_cells"]
    assert changed["heading"] == {"half_range_deg": 10.0, "step_deg": 0.5}
    with pytest.raises(sdem.InvalidError, match="no option 'stepm'.*step_m"):
        sdem.localize_options(stepm=0.02)
    with pytest.raises(sdem.InvalidError, match="no option 'cost.truncation'"):
        sdem.localize_options(cost={"truncation": 0.1})
    with pytest.raises(sdem.InvalidError, match="invalid type"):
        sdem.localize_options(step_m="fine")
    with pytest.raises(sdem.InvalidError, match="unknown variant"):
        sdem.localize_options(mode="fastest")
    slam = sdem.slam_options(window_half_m=[0.2, 0.2, 0.1])
    assert slam["window_half_m"] == [0.2, 0.2, 0.1] and slam["localize"]["step_m"] == 0.02


def test_options_given_to_localize_are_used(pairs):
    pair = pairs[4]
    ref, qry = scans(pair)
    exhaustive = sdem.localize(ref, qry, window=pair["window"], step_m=0.05, runner_up=False,
                               mode="exhaustive", refine=False)
    d = exhaustive.diagnostics
    assert d["candidates_evaluated"] == d["candidates_total"]  # every candidate scored
    assert d["refinement"]["outcome"] == "none" and exhaustive.covariance is None
    # A grid optimum on a 5 cm grid is within a step of the truth.
    assert translation_error_m(exhaustive.reference_from_query, pair["reference_from_query"]) < 0.05
    with pytest.raises(sdem.InvalidError):
        sdem.localize(ref, qry, step_m=-1.0)


def test_a_prior_is_accepted_as_cost_prior(pairs):
    pair = pairs[5]
    ref, qry = scans(pair)
    t = pair["reference_from_query"][:3, 3]
    res = sdem.localize(ref, qry, window=pair["window"],
                        cost={"prior": {"offset": list(t), "sigma_m": 0.05}})
    assert translation_error_m(res.reference_from_query, pair["reference_from_query"]) < 0.005
    with pytest.raises(sdem.InvalidError, match="prior"):
        sdem.localize(ref, qry, cost={"prior": {"offset": [0, 0, 0]}})


def test_options_for_a_spinning_lidar_come_from_the_scan(pairs):
    points = pairs[0]["reference_points"]
    grid = sdem.grid_for_scan(points)
    assert grid["plane_reach_from_neighbours"] is True
    scan = sdem.Scan(points, attitude_deg=pairs[0]["reference_attitude_deg"], grid=grid)
    options = sdem.localize_options_for_scan(scan, runner_up=False)
    assert 0.02 <= options["step_m"] <= 0.25 and options["runner_up"] is False
    assert options["cost"]["truncation_m"] == pytest.approx(max(2 * options["step_m"], 0.05))
