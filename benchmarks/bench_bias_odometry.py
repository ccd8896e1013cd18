"""Step-length bias of the whole odometry, per target ICP registers onto: which cause removes it?

    nice -n 10 .venv/bin/python benchmarks/bench_bias_odometry.py TILE RUN [--variants shipped truth-map ...]
        [--scans N]

``bench_bias.py`` measures pairs of scans; here the odometry itself runs (its local map of the last
scans, its tracking and fallbacks) over a run of ``bench_ground.py`` (``TILE`` a name in
``../shared/data``, ``RUN`` one of its runs: ``loop150``, ``thin150``, ``survey150`` ...), once per
variant, and prints the mean ratio of estimated to true step length, the ratio of the lengths of the
whole paths, the errors of each step in the true frame of its first scan (mean along the track,
standard deviation along it, RMS rotation) and where the odometry ends. Variants, each one hypothesis:

* ``shipped``: the package as it is;
* ``truth-map``: the local map merged with the true poses of its scans, not the odometry's (does the
  map's own error feed the bias, or hold it back?);
* ``previous-scan``: ICP onto the previous scan alone (``[registration] icp_local_map = 1``): the
  ray pattern both scans share, undiluted;
* ``voxel-map``: small_gicp's voxelized GICP onto Gaussian voxels of twice the ICP grid made from the
  local map, not onto its points (the voxels' means and covariances carry less of the pattern);
* ``incidence-60``: every scan's ICP cloud without its points hit at more than 60 degrees from their
  surface's normal (crown walls, seen differently from every place).

The variants replace one function of the package for this process only (the benchmark's own
wrappers, below); nothing of it is shipped.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

os.environ.setdefault("OMP_WAIT_POLICY", "passive")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
import small_gicp

sys.path.insert(0, os.path.dirname(__file__))
from bench_ground import DATA, build_run

import helpers.slam.odometry as odometry_module
import helpers.slam.preprocess as preprocess_module
import helpers.slam.registration.icp as icp_module
from helpers.slam.registration.icp import icp_cloud

VARIANTS = ("shipped", "truth-map", "previous-scan", "voxel-map", "incidence-60")
VOXELS_PER_GRID = 2.0  # the voxel map's voxel over the ICP grid step (1 m at 150 m: 0.5 m gave +0.36 %, 2 m +1.6 %)
INCIDENCE_DEG = 60.0  # incidence-60: the widest angle kept between a ray and its surface's normal (45: +0.7 %)
TRUTH: dict[int, np.ndarray] = {}  # scan index -> its true pose (truth-map)

_local_map, _prepare, _small_gicp = odometry_module.local_map, preprocess_module.prepare, icp_module._small_gicp
_register = odometry_module.Odometry.register


def truth_local_map(recent, poses, config):
    """The local map of ``recent`` merged with their true poses."""
    return _local_map(recent, [TRUTH[frame.index] for frame in recent], config)


def registering_with_index(self, frame, index):
    frame.index = index  # truth-map reads each frame's scan index
    return _register(self, frame, index)


def voxel_gicp(moving, fixed, init, metric, inlier_distance, max_iterations, tolerance, source, voxel=1.0):
    """small_gicp's VGICP onto Gaussian voxels of ``voxel`` m made from the fixed cloud, scored as the
    package scores its own alignment."""
    voxels = small_gicp.GaussianVoxelMap(voxel)
    voxels.insert(fixed.cloud)
    result = small_gicp.align(
        voxels, moving.cloud, init_T_target_source=init, max_correspondence_distance=inlier_distance,
        num_threads=1, max_iterations=int(max_iterations), rotation_epsilon=tolerance / max(moving.reach, 1.0),
        translation_epsilon=tolerance,
    )  # fmt: skip
    return icp_module.scored_alignment(result, moving, fixed, metric, inlier_distance, source)


def without_grazing(scan, config):
    """The scan prepared as the package prepares it, its ICP cloud without the points hit at grazing incidence."""
    frame = _prepare(scan, config)
    points = frame.icp_points
    incidence = np.abs((frame.icp.normals * points).sum(axis=1)) / np.linalg.norm(points, axis=1)
    keep = incidence >= np.cos(np.radians(INCIDENCE_DEG))
    if keep.sum() < 50:  # too few left to register: the scan as it was
        return frame
    fit = config.registration
    return dataclasses.replace(frame, icp_points=points[keep], icp=icp_cloud(points[keep], fit.metric, fit.icp_backend))


def configured(variant: str, config):
    """Install ``variant``'s wrapper (this process only) and return the configuration it runs with."""
    if variant == "truth-map":
        odometry_module.local_map = truth_local_map
        odometry_module.Odometry.register = registering_with_index
    elif variant == "previous-scan":
        config = config.with_values(registration={"icp_local_map": 1})
    elif variant == "voxel-map":
        voxel = VOXELS_PER_GRID * config.icp_grid
        icp_module._small_gicp = lambda *args: voxel_gicp(*args, voxel=voxel)
    elif variant == "incidence-60":
        preprocess_module.prepare = without_grazing
    return config


def measured(truth: np.ndarray, estimated: np.ndarray) -> dict:
    """Step ratios and step errors of an odometry (K, 4, 4) against the true poses of its scans."""
    true_steps = np.linalg.norm(np.diff(truth[:, :3, 3], axis=0), axis=1)
    steps = np.linalg.norm(np.diff(estimated[:, :3, 3], axis=0), axis=1)
    moving = true_steps > 0.05
    true_rel = np.linalg.inv(truth[:-1]) @ truth[1:]
    rel = np.linalg.inv(estimated[:-1]) @ estimated[1:]
    along = true_rel[:, :3, 3] / np.linalg.norm(true_rel[:, :3, 3], axis=1, keepdims=True)
    error_along = np.einsum("ij,ij->i", rel[:, :3, 3] - true_rel[:, :3, 3], along)
    off = np.linalg.inv(true_rel) @ rel
    angle = np.degrees(np.arccos(np.clip((np.trace(off[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)))
    return {
        "ratio": float(np.mean(steps[moving] / true_steps[moving])),
        "path": float(steps.sum() / true_steps.sum()),
        "along_mm": 1000 * float(error_along[moving].mean()),
        "along_sd_mm": 1000 * float(error_along[moving].std()),
        "rotation_deg": float(np.sqrt(np.mean(angle**2))),
        "end_m": float(np.linalg.norm(estimated[-1, :3, 3] - truth[-1, :3, 3])),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tile", help="a tile of ../shared/data, by name (forest_bc_1)")
    parser.add_argument("run", help="a run of bench_ground.py (loop150, thin150, survey150, ...)")
    parser.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS))
    parser.add_argument("--scans", type=int, default=None, help="only the first N accepted scans")
    args = parser.parse_args()
    if len(args.variants) > 1:  # each variant in a process of its own: the wrappers replace package functions
        import subprocess

        for variant in args.variants:
            command = [sys.executable, __file__, args.tile, args.run, "--variants", variant]
            subprocess.run(command + (["--scans", str(args.scans)] if args.scans else []), check=False)
        return
    paths = sorted(DATA.glob(f"{args.tile}.*"))
    if not paths:
        sys.exit(f"error: no tile {args.tile!r} in {DATA}")
    data, config = build_run({"tile": str(paths[0]), "run": args.run, "seed": 0})
    config = configured(args.variants[0], config)
    TRUTH.update(enumerate(data.poses))
    last = odometry_module.accepted_indices(len(data.poses), config)[: args.scans][-1]
    start = time.perf_counter()
    result = odometry_module.run_odometry([data.scans[i] for i in range(last + 1)], data.poses[0], config)
    seconds = time.perf_counter() - start
    m = measured(data.poses[result.indices], result.poses)
    print(
        f"{args.tile:18} {args.run:10} {args.variants[0]:14} {len(result.indices):5d} steps  ratio {m['ratio']:.4f}"
        f"  path {m['path']:.4f}  along {m['along_mm']:+6.1f} mm (sd {m['along_sd_mm']:5.1f})"
        f"  rotation {m['rotation_deg']:.4f} deg  end {m['end_m']:6.2f} m  fallbacks {len(result.fallbacks):3d}"
        f"  {seconds:4.0f} s",
        flush=True,
    )


if __name__ == "__main__":
    main()
