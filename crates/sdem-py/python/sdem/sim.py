"""Seeded scans with their truth from sdem's simulator, to try sdem and to test it without data
files: ``pairs`` (the benchmark's scan pairs in a simulated collapsed building) and ``run`` (a
stop-and-go run through it with odometry). A seed gives the same scans on every machine."""

from ._sdem import sim as _sim

pairs = _sim.pairs
run = _sim.run

__all__ = ["pairs", "run"]
