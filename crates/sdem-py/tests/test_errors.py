"""Bad input raises an sdem.Error subclass that says what was expected; a result with doubts is
not an exception (see test_localize)."""

import errno
import inspect

import numpy as np
import pytest

import sdem


@pytest.fixture(scope="module")
def points(pairs):
    return pairs[0]["reference_points"]


def test_every_exception_is_an_sdem_error_and_the_natural_builtin():
    classes = [getattr(sdem, name) for name in sdem.__all__ if name.endswith("Error")]
    assert len(classes) == 16
    for cls in classes:
        assert issubclass(cls, sdem.Error), cls
        assert cls.__doc__, cls
    for cls in (sdem.InvalidError, sdem.InvalidInputError, sdem.TooFewPointsError, sdem.ParseError,
                sdem.TooManyCandidatesError):
        assert issubclass(cls, ValueError)
    assert issubclass(sdem.FileError, OSError)
    assert issubclass(sdem.NodeStoreError, OSError)
    for cls in (sdem.NoOverlapError, sdem.NoMatchError, sdem.NoSurfacesError,
                sdem.RefinementFailedError, sdem.NotFoundError):
        assert issubclass(cls, sdem.MatchError) and cls.is_no_match


@pytest.mark.parametrize(
    "array, expected",
    [
        (np.zeros((100, 2)), r"expected an \(N, 3\) array .* got shape \(100, 2\)"),
        (np.zeros((100, 3, 1)), r"got shape \(100, 3, 1\)"),
        (np.zeros(300), r"got shape \(300,\)"),
        (np.zeros((100, 3), dtype=np.int64), "expected float32 or float64 .* got dtype int64"),
        (np.zeros((100, 3), dtype=">f8"), "expected float32 or float64 .* got dtype >f8"),
        ("not points", r"got shape \(\)|expected a numpy array"),
    ],
)
def test_points_of_the_wrong_shape_or_dtype_say_what_was_expected(array, expected):
    with pytest.raises(sdem.InvalidInputError, match=expected) as info:
        sdem.Scan(array)
    assert info.value.what == "points"
    assert isinstance(info.value, ValueError)


def test_an_infinite_coordinate_names_the_point_and_nan_rows_are_no_return(points):
    bad = points.copy()
    bad[17, 1] = np.inf
    with pytest.raises(sdem.InvalidInputError, match="point 17") as info:
        sdem.Scan(bad)
    assert info.value.what == "point 17" and "infinite" in info.value.problem
    holes = points.copy()
    holes[::10] = np.nan
    assert len(sdem.Scan(holes)) == len(points) - len(points[::10])


def test_too_few_points_carry_their_figures(points):
    with pytest.raises(sdem.TooFewPointsError) as info:
        sdem.Scan(points[:20])
    assert info.value.usable < info.value.needed == 100
    assert "fewer than the 100" in str(info.value)


def test_a_scan_with_no_usable_point_says_why_in_scan_and_map_localize(tmp_path, run):
    at_origin = np.zeros((500, 3))
    with pytest.raises(sdem.NoUsablePointsError) as info:
        sdem.Scan(at_origin)
    wanted = "all 500 of its points lie within 0.05 m of the sensor's origin"
    assert wanted in info.value.reason
    assert str(info.value).startswith("the scan has no usable point: " + wanted)
    # A TooFewPointsError with no usable cell, for code that catches that.
    assert isinstance(info.value, sdem.TooFewPointsError) and isinstance(info.value, ValueError)
    assert info.value.usable == 0 and info.value.needed == 100
    with pytest.raises(sdem.NoUsablePointsError, match="none of its 2 points is finite"):
        sdem.Scan(np.full((2, 3), np.nan))
    # Map.localize names it the same way, with and without a position.
    slam = sdem.Slam()
    slam.add(run["points"][0], attitude_deg=run["attitude_deg"][0])
    slam.save(tmp_path / "map")
    saved = sdem.Map.load(tmp_path / "map")
    for near in (None, (0.0, 0.0, 0.0)):
        with pytest.raises(sdem.NoUsablePointsError) as info:
            saved.localize(at_origin, near=near)
        assert wanted in info.value.reason


def test_a_bad_attitude_is_invalid_input(points):
    with pytest.raises(sdem.InvalidInputError, match="expected 3 numbers, got shape"):
        sdem.Scan(points, attitude_deg=(1.0, 2.0))
    with pytest.raises(sdem.InvalidInputError, match="finite"):
        sdem.Scan(points, attitude_deg=(0.0, float("nan"), 0.0))
    with pytest.raises(sdem.InvalidInputError, match="give attitude_deg"):
        sdem.Scan(points, yaw_sigma_deg=20.0)
    with pytest.raises(sdem.InvalidInputError, match="roll_pitch_sigma_deg: -1° must be positive"):
        sdem.Scan(points, attitude_deg=(0, 0, 0), roll_pitch_sigma_deg=-1.0)
    # An ndarray and a list both serve as an attitude.
    assert sdem.Scan(points, attitude_deg=np.array([0.5, 0.0, 10.0])).attitude_deg == \
        pytest.approx((0.5, 0.0, 10.0))


def test_a_localization_where_nothing_matches_raises_a_match_error(pairs):
    pair = pairs[0]
    ref = sdem.Scan(pair["reference_points"], attitude_deg=pair["reference_attitude_deg"])
    far = sdem.Scan(pair["query_points"] + [0.0, 0.0, 3.0],
                    attitude_deg=pair["query_attitude_deg"])
    # A small window: with the pairs' ±0.5 m the exact search bounds every box before it can
    # tell that nothing matches, which takes minutes.
    window = {"min": [-0.05, -0.05, -0.05], "max": [0.05, 0.05, 0.05]}
    with pytest.raises(sdem.MatchError) as info:
        sdem.localize(ref, far, window=window, runner_up=False)
    assert info.value.is_no_match
    assert isinstance(info.value, (sdem.NoOverlapError, sdem.NoMatchError))


def test_a_slam_step_that_matches_nothing_starts_a_new_segment_not_an_error(run):
    slam = sdem.Slam()
    slam.add(run["points"][0], attitude_deg=run["attitude_deg"][0])
    lifted = run["points"][6] + [0.0, 0.0, 2.5]  # another stop, seen 2.5 m off the floor
    slam.add(lifted, attitude_deg=run["attitude_deg"][6])
    step = slam.last_step
    assert step.status == "new_segment" and not step.trusted
    assert len(slam) == 2  # the scan is kept, in a segment of its own


def test_odometry_must_be_a_rigid_transform(run):
    slam = sdem.Slam()
    for odometry, expected in [
        (np.eye(3), r"expected a 4x4 homogeneous transform, got shape \(3, 3\)"),
        (np.diag([2.0, 1.0, 1.0, 1.0]), "not a rotation"),
        (np.diag([1.0, 1.0, -1.0, 1.0]), "not a rotation"),
        (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]]), "last row"),
    ]:
        with pytest.raises(sdem.InvalidInputError, match=expected):
            slam.add(run["points"][0], odometry=odometry)
    assert len(slam) == 0


def test_options_that_do_not_exist_are_refused():
    with pytest.raises(sdem.InvalidError, match="no option 'window_half'"):
        sdem.Slam(window_half=[0.1, 0.1, 0.1])
    with pytest.raises(sdem.InvalidError, match="max_reference_nodes"):
        sdem.Slam(max_reference_nodes=0)


def test_numpy_values_serve_as_options_and_a_number_that_is_not_finite_is_named(pairs):
    pair = pairs[0]
    ref = sdem.Scan(pair["reference_points"], attitude_deg=pair["reference_attitude_deg"])
    qry = sdem.Scan(pair["query_points"], attitude_deg=pair["query_attitude_deg"])
    window = {"min": np.array(pair["window"]["min"]), "max": np.array(pair["window"]["max"])}
    by_numpy = sdem.localize(ref, qry, window=window, step_m=np.float32(0.02))
    plain = sdem.localize(ref, qry, window=pair["window"], step_m=0.02)
    assert np.allclose(by_numpy.reference_from_query, plain.reference_from_query)
    with pytest.raises(sdem.InvalidError, match="step_m is NaN; it must be a finite number"):
        sdem.localize(ref, qry, step_m=float("nan"))
    bad = {"min": [-0.5, float("inf"), -0.1], "max": [0.5, 0.5, 0.1]}
    with pytest.raises(sdem.InvalidError, match=r"window.min\[1\] is inf"):
        sdem.localize(ref, qry, window=bad)
    with pytest.raises(sdem.InvalidError, match="step_m is a set"):
        sdem.localize(ref, qry, step_m={0.02})


def test_options_and_readings_are_checked_where_they_are_given(points):
    with pytest.raises(sdem.InvalidError, match="step"):
        sdem.localize_options(step_m=-1)
    with pytest.raises(sdem.InvalidError, match="heading window"):
        sdem.localize_options(heading={"half_range_deg": -5})
    with pytest.raises(sdem.InvalidInputError, match="yaw_sigma_deg: 0° must be positive"):
        sdem.Scan(points, attitude_deg=(0, 0, 0), yaw_sigma_deg=0)


def test_a_negative_count_is_refused_by_name():
    with pytest.raises(sdem.InvalidInputError, match="seed: -1 is negative"):
        sdem.sim.run(-1, 2)
    with pytest.raises(sdem.InvalidInputError, match="count: -1 is negative"):
        sdem.sim.pairs(1, -1)


def test_a_progress_that_cannot_be_called_is_refused_before_any_scan():
    with pytest.raises(sdem.InvalidError, match="progress must be a callable.*not a int"):
        sdem.Slam(progress=5)


def test_file_errors_are_os_errors_and_parse_errors_name_the_line(tmp_path):
    missing = tmp_path / "missing.ply"
    with pytest.raises(sdem.FileError) as info:
        sdem.read_points(missing)
    assert isinstance(info.value, OSError) and info.value.errno == errno.ENOENT
    assert info.value.filename == str(missing)
    # What the system's words leave out is said, as on the command line.
    with pytest.raises(sdem.FileError) as info:
        sdem.read_points(tmp_path / "no-such-folder" / "scan.ply")
    assert info.value.errno == errno.ENOENT and "no-such-folder does not exist" in str(info.value)
    bad = tmp_path / "bad.xyz"
    bad.write_text("1 2 3\n4 five 6\n")
    with pytest.raises(sdem.ParseError) as info:
        sdem.read_points(bad)
    assert info.value.line == 2 and info.value.path == str(bad)
    assert str(info.value).startswith(f"{bad}:2:")
    with pytest.raises(sdem.ParseError, match="not a point-cloud format"):
        sdem.read_points(tmp_path / "scan.abc")


def test_a_folder_without_a_map_or_with_a_damaged_one_is_refused(tmp_path, run):
    with pytest.raises(sdem.InvalidError, match="not a saved map"):
        sdem.Map.load(tmp_path)
    slam = sdem.Slam()
    slam.add(run["points"][0], attitude_deg=run["attitude_deg"][0])
    slam.save(tmp_path / "map")
    manifest = tmp_path / "map" / "map.json"
    manifest.write_text(manifest.read_text().replace('"scan_index": 0', '"scan_index": 7'))
    with pytest.raises(sdem.ParseError, match="checksum"):
        sdem.Map.load(tmp_path / "map")


def test_the_errors_module_documents_every_class():
    for name, cls in inspect.getmembers(sdem._errors, inspect.isclass):
        if issubclass(cls, sdem.Error):
            assert cls.__module__ == "sdem._errors" and cls.__doc__, name
