#!/usr/bin/env python3
"""How well consecutive scans' floors and ceilings agree under a set of poses.

Usage: level_surfaces.py DATASET POSES_A [POSES_B ...]
  DATASET  a dataset folder (scans/NNNNNN.ply in the sensor frame, z up), e.g. from `sdem import`
  POSES_*  KITTI pose files (one 3x4 row-major line per scan), e.g. sdem's poses.txt and the
           dataset's poses_slam6d.txt

For each pair of consecutive scans: the later scan's points (within 5 m) are paired with the
earlier scan's nearest point within 5 cm; on level surfaces (normal within ~18° of vertical, from
an 8 cm neighbourhood) the signed point-to-plane offset is split into floor (below the sensor) and
ceiling (0.5 m above it). Prints the median offset and the tilt of the offset against the distance
along x (a least-squares slope, in degrees). A change of pitch tilts floor and ceiling alike; a
difference between their tilts lies in the scans. Needs numpy, scipy and open3d.
"""
import sys
import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree


def read_poses(path):
    poses = []
    for line in open(path):
        if line.strip():
            t = np.eye(4)
            t[:3, :] = np.array([float(v) for v in line.split()]).reshape(3, 4)
            poses.append(t)
    return poses


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    dataset, pose_files = sys.argv[1], sys.argv[2:]
    sets = {p: read_poses(p) for p in pose_files}
    n = min(len(p) for p in sets.values())
    clouds, normals = [], []
    for i in range(n):
        pts = np.asarray(o3d.io.read_point_cloud(f"{dataset}/scans/{i:06d}.ply").points)
        r = np.linalg.norm(pts, axis=1)
        pts = pts[(r < 5.0) & (r > 0.3)]
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.08, max_nn=30))
        clouds.append(pts)
        normals.append(np.asarray(pc.normals))
    for name, poses in sets.items():
        world = [(poses[i][:3, :3] @ clouds[i].T).T + poses[i][:3, 3] for i in range(n)]
        world_n = [(poses[i][:3, :3] @ normals[i].T).T for i in range(n)]
        for i in range(n - 1):
            j = i + 1
            d, k = cKDTree(world[i]).query(world[j], distance_upper_bound=0.05)
            ok = np.isfinite(d)
            nrm = world_n[i][k[ok]]
            off = np.einsum("ij,ij->i", world[j][ok] - world[i][k[ok]], nrm)
            pj = world[j][ok]
            level = np.abs(nrm[:, 2]) > 0.95
            z0 = poses[j][2, 3]
            for label, sel in (("floor", level & (pj[:, 2] < z0 - 0.2)),
                               ("ceiling", level & (pj[:, 2] > z0 + 0.5))):
                if sel.sum() < 50:
                    continue
                o = off[sel] * np.sign(nrm[sel, 2])
                x = pj[sel, 0] - poses[j][0, 3]
                slope = np.linalg.lstsq(np.c_[x, np.ones_like(x)], o, rcond=None)[0][0]
                print(f"{name} {i}->{j} {label}: {sel.sum()} points, median offset "
                      f"{100 * np.median(o):+.2f} cm, tilt {np.degrees(np.arctan(slope)):+.2f} deg")


if __name__ == "__main__":
    main()
