"""Type stubs of ``sdem.sim``: seeded scans with their truth from sdem's simulator."""

from __future__ import annotations

from typing import Any, TypedDict

import numpy as np
import numpy.typing as npt

class Window(TypedDict):
    min: list[float]
    max: list[float]

class Pair(TypedDict):
    reference_points: npt.NDArray[np.float64]
    reference_attitude_deg: tuple[float, float, float]
    query_points: npt.NDArray[np.float64]
    query_attitude_deg: tuple[float, float, float]
    reference_from_query: npt.NDArray[np.float64]
    window: Window
    reference_stop: int
    world_from_reference: npt.NDArray[np.float64]
    world_from_query: npt.NDArray[np.float64]

class Run(TypedDict):
    points: list[npt.NDArray[np.float64]]
    attitude_deg: npt.NDArray[np.float64]
    world_from_sensor: npt.NDArray[np.float64]
    odom_from_sensor: npt.NDArray[np.float64]

def pairs(
    seed: int,
    count: int,
    *,
    displacement_half_m: tuple[float, float, float] = (0.5, 0.5, 0.1),
    yaw_spread_deg: float = 15.0,
    tilt_max_deg: float = 3.0,
    compass_error_max_deg: float = 10.0,
) -> list[Pair]:
    """Seeded scan pairs in the simulated collapsed building, with the truth."""

def run(seed: int, stops: int) -> Run:
    """A seeded stop-and-go run through the simulated collapsed building, with the truth and
    simulated odometry."""

__all__ = ["pairs", "run"]
