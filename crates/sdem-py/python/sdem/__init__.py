"""sdem: Sphere-DEM 3D localization and mapping for stop-and-go rescue robots.

An implementation and extension of Nagatani, Ishida, Yamanaka and Tanaka, "Three-dimensional
localization and mapping for mobile robot in disaster environments" (IROS 2003), in Rust, with
numpy arrays in and out. Points are ``(N, 3)`` float32 or float64 arrays, metres, in the sensor
frame (x forward, y left, z up); poses are ``(4, 4)`` float64 homogeneous transforms named for
their frames (``reference_from_query``, ``world_from_sensor``); angles are degrees in names that
say ``_deg``.

Example::

    import numpy as np
    import sdem

    pair = sdem.sim.pairs(seed=42, count=1)[0]   # or your own scans, e.g. sdem.read_points(path)
    ref = sdem.Scan(pair["reference_points"], attitude_deg=pair["reference_attitude_deg"])
    qry = sdem.Scan(pair["query_points"], attitude_deg=pair["query_attitude_deg"])
    res = sdem.localize(ref, qry, window=pair["window"])
    if res.trusted:
        print(res.reference_from_query)
    else:
        print("best guess only:", [d.message for d in res.doubts])

    slam = sdem.Slam()
    run = sdem.sim.run(seed=17, stops=12)
    for points, attitude, odom in zip(run["points"], run["attitude_deg"], run["odom_from_sensor"]):
        world_from_sensor = slam.add(points, attitude_deg=attitude, odometry=odom)
    slam.poses()                                  # (12, 4, 4), after loop closures

The guide is docs/python.md in the repository.
"""

from . import sim
from ._errors import (
    AtScanError,
    Error,
    FileError,
    InvalidError,
    InvalidInputError,
    MatchError,
    NoMatchError,
    NoOverlapError,
    NoSurfacesError,
    NoUsablePointsError,
    NodeStoreError,
    NotFoundError,
    ParseError,
    RefinementFailedError,
    TooFewPointsError,
    TooManyCandidatesError,
)
from ._sdem import (
    DEFAULT_ATTITUDE_SIGMA_DEG,
    Doubt,
    Localization,
    Map,
    Relocalization,
    Scan,
    Slam,
    Step,
    __version__,
    grid_for_scan,
    localize,
    localize_options,
    localize_options_for_scan,
    read_points,
    slam_options,
    slam_options_for_scan,
)

__all__ = [
    "DEFAULT_ATTITUDE_SIGMA_DEG",
    "AtScanError",
    "Doubt",
    "Error",
    "FileError",
    "InvalidError",
    "InvalidInputError",
    "Localization",
    "Map",
    "MatchError",
    "NoMatchError",
    "NoOverlapError",
    "NoSurfacesError",
    "NoUsablePointsError",
    "NodeStoreError",
    "NotFoundError",
    "ParseError",
    "RefinementFailedError",
    "Relocalization",
    "Scan",
    "Slam",
    "Step",
    "TooFewPointsError",
    "TooManyCandidatesError",
    "__version__",
    "grid_for_scan",
    "localize",
    "localize_options",
    "localize_options_for_scan",
    "read_points",
    "sim",
    "slam_options",
    "slam_options_for_scan",
]
