"""sdem.Slam (the incremental loop), saving it, sdem.Map (relocalizing in a saved map)."""

import threading

import numpy as np
import pytest
from conftest import PAIRS_SEED, RUN_SEED, ate_m, translation_error_m

import sdem


def map_run(run, slam, stops=range(12)):
    for k in stops:
        slam.add(run["points"][k], attitude_deg=run["attitude_deg"][k],
                 odometry=run["odom_from_sensor"][k])
    return slam


@pytest.fixture(scope="module")
def mapped(run):
    steps = []
    slam = map_run(run, sdem.Slam(progress=steps.append))
    return slam, steps


def test_twelve_held_out_stops_with_odometry_reach_two_centimetres_ate(run, mapped):
    slam, _ = mapped
    poses = slam.poses()
    assert poses.shape == (12, 4, 4) and poses.dtype == np.float64
    ate = ate_m(poses, run["world_from_sensor"])
    print(f"ATE {ate * 100:.2f} cm over 12 stops")
    assert ate <= 0.02
    assert len(slam) == 12


def test_add_returns_world_from_sensor_and_the_step_says_how_it_went(run):
    slam = sdem.Slam()
    assert slam.last_step is None
    first = slam.add(run["points"][0], attitude_deg=run["attitude_deg"][0],
                     odometry=run["odom_from_sensor"][0])
    assert first.shape == (4, 4)
    assert slam.last_step.status == "first" and slam.last_step.node_id == 0
    second = slam.add(run["points"][1], attitude_deg=run["attitude_deg"][1],
                      odometry=run["odom_from_sensor"][1])
    step = slam.last_step
    np.testing.assert_array_equal(step.world_from_sensor, second)
    assert translation_error_m(second, run["world_from_sensor"][1]) < 0.01
    assert step.status == "tracked" and step.trusted and step.doubts == []
    report = step.report
    assert report["node_id"] == 1 and report["reference_nodes"][0][0] == 0
    assert report["heading_prior"] == "odometry" and report["trusted"] is True
    assert report["world_from_sensor"]["x"] == pytest.approx(second[0, 3])
    assert step.time_ms > 0
    # The match's covariance as an array, the report's figures; none for the first scan.
    assert step.covariance.shape == (6, 6)
    np.testing.assert_allclose(step.covariance, report["covariance"])
    assert np.all(np.linalg.eigvalsh(step.covariance) > 0)
    fresh = sdem.Slam()
    fresh.add(run["points"][0], attitude_deg=run["attitude_deg"][0])
    assert fresh.last_step.covariance is None


def test_progress_is_a_callback_with_each_step_in_order(mapped):
    slam, steps = mapped
    assert [s.node_id for s in steps] == list(range(12))
    assert [s.status for s in steps][0] == "first"
    assert all(isinstance(s, sdem.Step) for s in steps)
    np.testing.assert_allclose(steps[-1].world_from_sensor, slam.poses()[-1], atol=1e-9)


def test_the_merged_cloud_and_options_are_there(mapped):
    slam, _ = mapped
    cloud = slam.merged_cloud()
    assert cloud.ndim == 2 and cloud.shape[1] == 3 and len(cloud) > 1000
    assert slam.options == sdem.slam_options()
    assert isinstance(slam.loop_closures, list)


def lidar_scan(offset=(0.0, 0.0)):
    """A 20 m square room (walls, floor, ceiling) seen by 32 lasers 1° apart over every azimuth
    (0.2° steps), from `offset` (metres) at its middle's height."""
    el = np.radians(np.arange(32) - 20.0)[:, None]
    az = np.radians(np.arange(1800) * 0.2)[None, :]
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el) * np.ones_like(az)], -1)
    d = d.reshape(-1, 3)
    # Distance along each ray to the square's walls |x|, |y| = 10 m around `offset`.
    o = np.array([offset[0], offset[1], 0.0])
    with np.errstate(divide="ignore"):
        tx = np.where(d[:, 0] > 0, 10 - o[0], -10 - o[0]) / d[:, 0]
        ty = np.where(d[:, 1] > 0, 10 - o[1], -10 - o[1]) / d[:, 1]
    t = np.minimum(np.abs(tx), np.abs(ty))
    # A floor 1.7 m below the sensor, a ceiling 2 m above it.
    with np.errstate(divide="ignore"):
        tz = np.where(d[:, 2] < 0, -1.7 / d[:, 2], np.where(d[:, 2] > 0, 2.0 / d[:, 2], np.inf))
    t = np.minimum(t, tz)
    keep = np.isfinite(t)
    return d[keep] * t[keep, None]


def test_options_for_a_spinning_lidar_come_from_its_first_scan(run):
    lidar = sdem.slam_options_for_scan(lidar_scan())
    # The grid's band of elevations is the lasers' (−20°..+11°, with a margin), the search's
    # step and the fused map's rays follow the ranges (20 m walls: a 25 cm step, 20 m rays).
    assert (lidar["sdem"]["elevation_min_deg"], lidar["sdem"]["elevation_max_deg"]) == (-25.0, 16.0)
    assert lidar["localize"]["step_m"] == 0.25 and lidar["voxel"]["max_range_m"] == 20.0
    # A tilting laser's scan keeps the defaults; overrides are laid over either.
    assert sdem.slam_options_for_scan(run["points"][0]) == sdem.slam_options()
    assert sdem.slam_options_for_scan(lidar_scan(), max_reference_nodes=2)["max_reference_nodes"] == 2
    slam = sdem.Slam(**lidar)
    slam.add(lidar_scan())
    slam.add(lidar_scan((0.3, 0.1)))
    assert slam.last_step.status in ("tracked", "recovered")
    assert np.linalg.norm(slam.poses()[1][:2, 3] - [0.3, 0.1]) < 0.05


def test_a_saved_map_reloaded_relocalizes_new_scans_near_the_truth(run, mapped, tmp_path):
    slam, _ = mapped
    slam.save(tmp_path / "map")
    loaded = sdem.Map.load(tmp_path)  # the parent folder works too, as `sdem slam` writes OUT/map
    assert len(loaded) == 12
    np.testing.assert_allclose(loaded.poses(), slam.poses(), atol=1e-6)
    assert loaded.options == slam.options
    # Scans taken elsewhere along the same route (pairs of the same seed: each query within
    # ±0.5 m of a stop the map holds), with an honest compass.
    assert PAIRS_SEED != RUN_SEED
    queries = [p for p in sdem.sim.pairs(seed=RUN_SEED, count=30, compass_error_max_deg=0.0)
               if p["reference_stop"] < 12]
    assert len(queries) >= 4
    found = 0
    for pair in queries[:4]:
        np.testing.assert_allclose(pair["world_from_reference"],
                                   run["world_from_sensor"][pair["reference_stop"]], atol=1e-9)
        try:
            res = loaded.localize(pair["query_points"], attitude_deg=pair["query_attitude_deg"])
        except sdem.NotFoundError as e:
            assert e.tried
            continue
        error = translation_error_m(res.world_from_sensor, pair["world_from_query"])
        print(f"relocalized at node {res.node_id}: {error * 1000:.1f} mm, trusted {res.trusted}")
        if res.trusted:
            assert error < 0.02, res
            found += 1
    assert found >= 3


def test_relocalizing_near_a_position_and_with_bad_arguments(run, mapped, tmp_path):
    slam, _ = mapped
    slam.save(tmp_path)
    loaded = sdem.Map.load(tmp_path)
    truth = run["world_from_sensor"][5]
    res = loaded.localize(run["points"][5], attitude_deg=run["attitude_deg"][5],
                          near=truth[:3, 3] + [0.1, -0.1, 0.0], near_sigma_m=0.2)
    assert translation_error_m(res.world_from_sensor, truth) < 0.02
    assert res.diagnostics["inlier_fraction"] > 0.5 and res.time_ms > 0
    np.testing.assert_allclose(res.covariance, res.diagnostics["covariance"])
    # One σ of the position under a centimetre, as the error is.
    assert np.all(np.sqrt(np.diag(res.covariance)[:3]) < 0.01)
    with pytest.raises(sdem.InvalidInputError, match="give near"):
        loaded.localize(run["points"][5], near_sigma_m=0.2)
    with pytest.raises(sdem.InvalidInputError, match="max_nodes"):
        loaded.localize(run["points"][5], max_nodes=0)


def test_saving_refuses_another_map_unless_asked_and_a_loaded_slam_goes_on(run, tmp_path):
    first = map_run(run, sdem.Slam(), range(6))
    first.save(tmp_path)
    first.save(tmp_path)  # again into its own folder: only new nodes are written
    with pytest.raises(sdem.InvalidError, match="overwrite=True"):
        sdem.Slam().save(tmp_path)
    # Refused elsewhere, a Slam still knows its own folder and saves there again.
    other = tmp_path / "other"
    map_run(run, sdem.Slam(), range(2)).save(other)
    with pytest.raises(sdem.InvalidError, match="overwrite=True"):
        first.save(other)
    first.save(tmp_path)
    resumed = sdem.Slam.load(tmp_path)
    assert len(resumed) == 6
    np.testing.assert_allclose(resumed.poses(), first.poses(), atol=1e-6)
    map_run(run, resumed, range(6, 12))
    resumed.save(tmp_path)
    assert len(sdem.Map.load(tmp_path)) == 12
    assert ate_m(resumed.poses(), run["world_from_sensor"]) <= 0.02
    empty = sdem.Slam()
    empty.save(tmp_path, overwrite=True)
    assert len(sdem.Map.load(tmp_path)) == 0


def test_add_runs_without_the_gil_and_a_second_call_meanwhile_is_refused(run):
    # While one thread is inside add (the GIL released), another can run Python and finds the
    # Slam borrowed; were the GIL held, it could not run until add returned.
    slam = map_run(run, sdem.Slam(), range(1))
    refused = []
    done = threading.Event()

    def add():
        try:
            map_run(run, slam, range(1, 4))
        finally:
            done.set()

    worker = threading.Thread(target=add)
    worker.start()
    while not done.is_set():
        try:
            len(slam)
        except RuntimeError as e:
            refused.append(str(e))
    worker.join()
    assert len(slam) == 4
    assert refused and "in use by another thread" in refused[0]
    assert "threading.Lock" in refused[0]
