"""sdem beside small_gicp and KISS-ICP on the same numpy arrays: 20 held-out simulated pairs, each
method given the two clouds (the peers from no guess, the identity; sdem with the gyro/compass
readings and the pairs' ±0.5 m window), scored against the truth. Success: under 2 cm. The same
code as docs/python.md shows.

    pip install small_gicp kiss-icp        # beside sdem
    python crates/sdem-py/examples/beside_peers.py
"""

import os, time
import numpy as np
import small_gicp
from kiss_icp.mapping import VoxelHashMap
from kiss_icp.registration import Registration
from kiss_icp.voxelization import voxel_down_sample
import sdem

def with_sdem(pair):
    ref = sdem.Scan(pair["reference_points"], attitude_deg=pair["reference_attitude_deg"])
    qry = sdem.Scan(pair["query_points"], attitude_deg=pair["query_attitude_deg"])
    return sdem.localize(ref, qry, window=pair["window"]).reference_from_query

def with_small_gicp(pair):  # T_target_source, the reference as the target
    return small_gicp.align(pair["reference_points"], pair["query_points"],
                            registration_type="GICP", downsampling_resolution=0.05,
                            max_correspondence_distance=0.25, num_threads=os.cpu_count(),
                            max_iterations=50).T_target_source

def with_kiss_icp(pair, voxel=0.1, max_correspondence=0.25):
    local_map = VoxelHashMap(voxel_size=voxel, max_distance=1e4, max_points_per_voxel=20)
    local_map.add_points(voxel_down_sample(pair["reference_points"], 0.5 * voxel))
    source = voxel_down_sample(voxel_down_sample(pair["query_points"], 0.5 * voxel), 1.5 * voxel)
    return Registration(max_num_iterations=50, convergence_criterion=1e-4,
                        max_num_threads=os.cpu_count()).align_points_to_map(
        source, local_map, np.eye(4), max_correspondence, max_correspondence / 3)

pairs = sdem.sim.pairs(seed=42, count=20)
for name, align in (("sdem", with_sdem), ("small_gicp GICP", with_small_gicp),
                    ("KISS-ICP", with_kiss_icp)):
    errors, times = [], []
    for pair in pairs:
        start = time.perf_counter()
        reference_from_query = align(pair)
        times.append((time.perf_counter() - start) * 1e3)
        errors.append(np.linalg.norm(reference_from_query[:3, 3] - pair["reference_from_query"][:3, 3]))
    errors = np.array(errors)
    print(f"{name:16s} median {np.median(errors) * 100:5.2f} cm  p95 {np.percentile(errors, 95) * 100:6.2f} cm"
          f"  success {np.mean(errors < 0.02):4.0%}  {np.median(times):4.0f} ms a pair")
