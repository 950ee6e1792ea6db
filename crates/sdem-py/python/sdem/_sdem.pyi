"""Type stubs of the extension module ``sdem._sdem`` (the Rust bindings); ``import sdem`` re-exports
everything here. The full documentation is in the docstrings (``help(sdem.localize)``)."""

from __future__ import annotations

import os
import pathlib
from types import ModuleType
from typing import Any, Callable, Literal, Mapping, Sequence, Union, final

import numpy as np
import numpy.typing as npt

#: ``(N, 3)`` float32 or float64 points (x, y, z in metres, sensor frame), C- or F-ordered.
Points = Union[npt.NDArray[np.float32], npt.NDArray[np.float64], Sequence[Sequence[float]]]
#: ``(roll, pitch, yaw)`` in degrees.
AttitudeDeg = Union[Sequence[float], npt.NDArray[np.floating[Any]]]
#: A ``(4, 4)`` homogeneous rigid transform.
Matrix4 = Union[npt.NDArray[np.floating[Any]], Sequence[Sequence[float]]]
PathLike = Union[str, "os.PathLike[str]"]

__version__: str
#: The default standard deviations of an attitude reading, degrees: ``(roll_pitch, yaw)``.
DEFAULT_ATTITUDE_SIGMA_DEG: tuple[float, float]

DoubtKind = Literal[
    "runner_up",
    "flat_covariance",
    "flat_cost",
    "unconstrained",
    "few_inliers",
    "refinement_failed",
    "on_window_edge",
    "attitude_corrected",
    "another_rotation",
    "unrefuted_rotation",
    "seen_through",
    "free_space_conflict",
    "taken_from_prediction",
    "prior_conflict",
]

@final
class Scan:
    """A scan as the sensor gave it: points in the sensor frame, metres, and the gyro/compass
    attitude read when it was taken (``None``: unknown, searched by a localization)."""

    def __new__(
        cls,
        points: Points,
        attitude_deg: AttitudeDeg | None = None,
        *,
        roll_pitch_sigma_deg: float | None = None,
        yaw_sigma_deg: float | None = None,
        grid: Mapping[str, Any] | None = None,
    ) -> Scan: ...
    @property
    def attitude_deg(self) -> tuple[float, float, float] | None:
        """The attitude reading, degrees, or ``None`` when unknown."""
    @property
    def sigma_deg(self) -> tuple[float, float] | None:
        """The reading's standard deviations ``(roll_pitch, yaw)``, degrees."""
    @property
    def points(self) -> npt.NDArray[np.float64]:
        """The finite points, ``(N, 3)`` float64 (a copy)."""
    @property
    def known_cells(self) -> int:
        """The S-DEM cells that hold a return."""
    @property
    def grid(self) -> dict[str, Any]:
        """The S-DEM grid, a dict of ``SdemConfig`` fields."""
    def __len__(self) -> int: ...

@final
class Doubt:
    """One reason not to trust a pose: ``kind``, figures and ``message``, as the command
    line's JSON writes it. A figure reads as an attribute (``doubt.fraction``)."""

    @property
    def kind(self) -> DoubtKind: ...
    @property
    def message(self) -> str: ...
    @property
    def figures(self) -> dict[str, Any]: ...
    def to_dict(self) -> dict[str, Any]:
        """``{"kind": ..., <figures>, "message": ...}``, as ``sdem localize --json``."""
    def __getattr__(self, name: str) -> Any: ...

@final
class Localization:
    """The result of ``localize``: the pose with how far to trust it. A result with doubts is
    the best candidate found, not a pose to trust (``trusted`` is False)."""

    @property
    def reference_from_query(self) -> npt.NDArray[np.float64]:
        """The query sensor's pose in the reference sensor's frame, ``(4, 4)``."""
    @property
    def trusted(self) -> bool: ...
    @property
    def doubts(self) -> list[Doubt]: ...
    @property
    def covariance(self) -> npt.NDArray[np.float64] | None:
        """``(6, 6)`` over ``[x, y, z, rx, ry, rz]`` in the query sensor's frame."""
    @property
    def time_ms(self) -> float: ...
    @property
    def cost(self) -> float: ...
    @property
    def overlap(self) -> int: ...
    @property
    def runner_up(self) -> float | None: ...
    @property
    def diagnostics(self) -> dict[str, Any]:
        """The figures behind ``trusted``, as ``sdem localize --json`` reports them."""

def localize(reference: Scan, query: Scan, **options: Any) -> Localization:
    """Localizes ``query`` against ``reference``; ``options`` are ``LocalizeOptions`` fields
    (``localize_options()`` lists them with their defaults). Runs without the GIL.

    Raises ``InvalidError`` (options), ``NoOverlapError`` / ``NoMatchError`` (nothing in the
    window matches), ``NoSurfacesError``."""

def localize_options(**overrides: Any) -> dict[str, Any]:
    """Every ``LocalizeOptions`` field with its default, ``overrides`` laid over them."""

def localize_options_for_scan(scan: Scan, **overrides: Any) -> dict[str, Any]:
    """``LocalizeOptions::for_scan``: options matched to a (spinning LiDAR's) scan."""

def grid_for_scan(points: Points) -> dict[str, Any]:
    """``SdemConfig::for_scan``: the S-DEM grid matched to a scan, for ``Scan(grid=...)``."""

def slam_options(**overrides: Any) -> dict[str, Any]:
    """Every ``SlamOptions`` field with its default, ``overrides`` laid over them."""

def slam_options_for_scan(points: Points, **overrides: Any) -> dict[str, Any]:
    """``SlamOptions::for_scan``: the loop's options matched to a (LiDAR's) first scan."""

def read_points(path: PathLike) -> npt.NDArray[np.float64]:
    """Reads ``.ply``, ``.pcd``, ``.las``/``.laz``, ``.xyz``/``.txt``, KITTI ``.bin``, 3DTK
    ``.3d`` or ``.sweep`` as ``(N, 3)`` float64; raises ``FileError`` or ``ParseError``."""

@final
class Step:
    """One stop added by ``Slam.add``."""

    @property
    def world_from_sensor(self) -> npt.NDArray[np.float64]: ...
    @property
    def status(
        self,
    ) -> Literal["first", "tracked", "recovered", "relocalized", "new_segment", "doubtful"]: ...
    @property
    def trusted(self) -> bool: ...
    @property
    def doubts(self) -> list[Doubt]: ...
    @property
    def node_id(self) -> int: ...
    @property
    def time_ms(self) -> float: ...
    @property
    def report(self) -> dict[str, Any]:
        """The step as ``report.json`` holds it."""

@final
class Slam:
    """The incremental stop-and-go loop with loop closure; ``options`` are ``SlamOptions``
    fields (``slam_options()`` lists them with their defaults)."""

    def __new__(
        cls, *, progress: Callable[[Step], object] | None = None, **options: Any
    ) -> Slam: ...
    @staticmethod
    def load(
        path: PathLike, *, progress: Callable[[Step], object] | None = None
    ) -> Slam:
        """Resumes a saved map."""
    def add(
        self,
        points: Points,
        attitude_deg: AttitudeDeg | None = None,
        odometry: Matrix4 | None = None,
        *,
        roll_pitch_sigma_deg: float | None = None,
        yaw_sigma_deg: float | None = None,
    ) -> npt.NDArray[np.float64]:
        """Adds the next stop's scan; returns ``world_from_sensor`` ``(4, 4)``; the step is
        ``last_step``. ``odometry`` is ``odom_from_sensor`` (4x4)."""
    @property
    def last_step(self) -> Step | None: ...
    def poses(self) -> npt.NDArray[np.float64]:
        """``(n, 4, 4)`` ``world_from_sensor`` of every node, after loop closures."""
    def merged_cloud(self) -> npt.NDArray[np.float64]:
        """Every node's points in the world where the fused map is occupied, ``(M, 3)``."""
    @property
    def loop_closures(self) -> list[tuple[int, int]]: ...
    @property
    def options(self) -> dict[str, Any]: ...
    def save(self, path: PathLike, *, overwrite: bool = False) -> None:
        """Saves the map (atomically) for ``Map.load``, ``Slam.load`` and the command line."""
    def __len__(self) -> int: ...

@final
class Relocalization:
    """A scan relocalized in a saved map."""

    @property
    def world_from_sensor(self) -> npt.NDArray[np.float64]: ...
    @property
    def node_id(self) -> int: ...
    @property
    def tried(self) -> list[tuple[int, str]]: ...
    @property
    def cost(self) -> float: ...
    @property
    def diagnostics(self) -> dict[str, Any]: ...
    @property
    def doubts(self) -> list[Doubt]: ...
    @property
    def trusted(self) -> bool: ...
    @property
    def time_ms(self) -> float: ...

@final
class Map:
    """A saved map to relocalize scans in, as ``sdem localize --map`` does."""

    @staticmethod
    def load(path: PathLike) -> Map: ...
    def localize(
        self,
        points: Points,
        attitude_deg: AttitudeDeg | None = None,
        *,
        near: Sequence[float] | None = None,
        near_sigma_m: float | None = None,
        max_nodes: int | None = None,
        roll_pitch_sigma_deg: float | None = None,
        yaw_sigma_deg: float | None = None,
    ) -> Relocalization:
        """Finds where a scan was taken in the map; raises ``NotFoundError`` when no node
        matches, ``NoUsablePointsError`` when the scan has no usable point (saying why)."""
    def poses(self) -> npt.NDArray[np.float64]: ...
    @property
    def options(self) -> dict[str, Any]: ...
    @property
    def path(self) -> pathlib.Path: ...
    def __len__(self) -> int: ...

sim: ModuleType

__all__ = [
    "Scan",
    "Localization",
    "Doubt",
    "Slam",
    "Step",
    "Map",
    "Relocalization",
    "localize",
    "localize_options",
    "localize_options_for_scan",
    "grid_for_scan",
    "slam_options",
    "slam_options_for_scan",
    "read_points",
    "DEFAULT_ATTITUDE_SIGMA_DEG",
    "__version__",
    "sim",
]
