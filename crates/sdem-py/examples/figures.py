"""The Python package's figures on held-out simulated data (seeds the README's Rust figures do not
use): pair accuracy and time, the incremental loop's ATE, and optionally the time of one pair of
a dataset folder, to set beside `sdem localize DIR --reference I --query J --json`.

    python crates/sdem-py/examples/figures.py [--pairs-seed 42] [--count 20] [--run-seed 17]
    python crates/sdem-py/examples/figures.py --dataset DIR --reference 3 --query 4
"""

import argparse
import csv
import pathlib
import statistics
import time

import numpy as np

import sdem


def translation_error_m(estimate, truth):
    return float(np.linalg.norm(estimate[:3, 3] - truth[:3, 3]))


def rotation_error_deg(estimate, truth):
    cos = (np.trace(estimate[:3, :3].T @ truth[:3, :3]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def pairs_figures(seed, count, dtype, **options):
    """Median and largest errors over `count` pairs, and the times: the localization's own
    (`time_ms`) and the whole call from the arrays (both Scans built, then localize)."""
    pairs = sdem.sim.pairs(seed=seed, count=count)
    errors_m, errors_deg, own_ms, wall_ms, trusted = [], [], [], [], 0
    for pair in pairs:
        start = time.perf_counter()
        ref = sdem.Scan(pair["reference_points"].astype(dtype),
                        attitude_deg=pair["reference_attitude_deg"])
        qry = sdem.Scan(pair["query_points"].astype(dtype),
                        attitude_deg=pair["query_attitude_deg"])
        res = sdem.localize(ref, qry, window=pair["window"], **options)
        wall_ms.append((time.perf_counter() - start) * 1e3)
        own_ms.append(res.time_ms)
        errors_m.append(translation_error_m(res.reference_from_query, pair["reference_from_query"]))
        errors_deg.append(rotation_error_deg(res.reference_from_query, pair["reference_from_query"]))
        trusted += res.trusted
    name = np.dtype(dtype).name
    print(f"{count} pairs (seed {seed}, {name}, {options or 'defaults'}): "
          f"median {np.median(errors_m) * 1e3:.2f} mm / {np.median(errors_deg):.3f} deg, "
          f"largest {max(errors_m) * 1e3:.2f} mm, {trusted} trusted, "
          f"{sum(e < 0.02 for e in errors_m)} within 2 cm; "
          f"localize {statistics.median(own_ms):.0f} ms median, "
          f"with both Scans {statistics.median(wall_ms):.0f} ms")


def slam_figures(seed, stops):
    run = sdem.sim.run(seed=seed, stops=stops)
    slam = sdem.Slam()
    start = time.perf_counter()
    for points, attitude, odometry in zip(run["points"], run["attitude_deg"],
                                          run["odom_from_sensor"]):
        slam.add(points, attitude_deg=attitude, odometry=odometry)
    seconds = time.perf_counter() - start
    d = slam.poses()[:, :3, 3] - run["world_from_sensor"][:, :3, 3]
    ate = np.sqrt(np.mean(np.sum(d * d, axis=1)))
    print(f"Slam, {stops} stops with odometry (seed {seed}): ATE {ate * 100:.2f} cm, "
          f"{seconds / stops * 1e3:.0f} ms a stop, {len(slam.loop_closures)} loop closures")


def dataset_pair(folder, reference, query, repeat):
    """One pair of a dataset folder (`sdem simulate` writes one), as `sdem localize` runs it:
    the scans and attitude.csv read, both Scans built and localized with the defaults."""
    folder = pathlib.Path(folder)
    scans = sorted((folder / "scans").iterdir())
    with open(folder / "attitude.csv") as f:
        rows = {int(r["index"]): r for r in csv.DictReader(f)}
    attitude = {k: tuple(float(rows[k][c]) for c in ("roll_deg", "pitch_deg", "yaw_deg"))
                for k in (reference, query)}
    times, own = [], []
    for _ in range(repeat):
        start = time.perf_counter()
        ref = sdem.Scan(sdem.read_points(scans[reference]), attitude_deg=attitude[reference])
        qry = sdem.Scan(sdem.read_points(scans[query]), attitude_deg=attitude[query])
        res = sdem.localize(ref, qry)
        times.append((time.perf_counter() - start) * 1e3)
        own.append(res.time_ms)
    print(f"{folder} {reference}->{query}: files read, Scans built and localized in "
          f"{statistics.median(times):.0f} ms median of {repeat} (localize alone "
          f"{statistics.median(own):.0f} ms); trusted {res.trusted}")


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs-seed", type=int, default=42)
    ap.add_argument("--count", type=int, default=20)
    ap.add_argument("--run-seed", type=int, default=17)
    ap.add_argument("--stops", type=int, default=12)
    ap.add_argument("--dataset")
    ap.add_argument("--reference", type=int, default=0)
    ap.add_argument("--query", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    if a.dataset:
        dataset_pair(a.dataset, a.reference, a.query, a.repeat)
        return
    pairs_figures(a.pairs_seed, a.count, np.float64)
    pairs_figures(a.pairs_seed, a.count, np.float32)
    pairs_figures(a.pairs_seed, a.count, np.float64, step_m=0.02)  # as `sdem bench` runs
    slam_figures(a.run_seed, a.stops)


if __name__ == "__main__":
    main()
