"""Time the registration front end on the default dataset's accepted scans and
measure the odometry's accuracy; compare with Open3D's own feature RANSAC.

    .venv/bin/python benchmarks/bench_registration.py [--pairs N]

Open3D's OpenMP threads spin after each parallel call and starve numpy's
OpenBLAS threads; ``OMP_WAIT_POLICY=passive`` (set here before Open3D is
imported) avoids that.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_WAIT_POLICY", "passive")

import numpy as np
import open3d as o3d

from helpers import create_dataset
from helpers.config.tables import Config
from helpers.quality.metrics import ate, rpe
from helpers.slam.odometry import STAGES, prepare, run_odometry
from helpers.slam.registration.features import to_cloud


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=40, help="pairs timed with Open3D's RANSAC (default 40)")
    args = parser.parse_args()
    config = Config()
    fit = config.registration
    data = create_dataset()

    # 1. Our pipeline over every accepted scan.
    start = time.perf_counter()
    result = run_odometry(data, data.poses[0], config)
    wall = time.perf_counter() - start
    steps = slice(1, None)  # the first accepted scan is only downsampled and described
    print(f"{len(result.indices)} accepted scans of {len(data)}, odometry {wall:.1f} s")
    print(f"ICP grid {fit.icp_grid_step} m, ICP tolerance {fit.icp_tolerance} m")
    print("per accepted scan, ms (mean / median / 95th percentile):")
    total = sum(result.timings[stage][steps] for stage in STAGES)
    for name, values in [*((s, result.timings[s][steps]) for s in STAGES), ("total", total)]:
        print(f"  {name:<10} {values.mean():7.1f} {np.median(values):7.1f} {np.percentile(values, 95):7.1f}")
    print(
        f"matches per step: median {np.median(result.n_matches):.0f}, MSAC inliers median "
        f"{np.median(result.n_inliers):.0f} (min {result.n_inliers.min()}); fallbacks: {len(result.fallbacks)}"
    )

    # 2. Accuracy against the ground truth.
    gt = data.poses[result.indices]
    for delta in (1, 10):
        print(rpe(result.poses, gt, delta))
    print(f"ATE (odometry only): {ate(result.poses, gt)}")

    # 3. Open3D's feature RANSAC on the same pairs and descriptors, for comparison.
    reg = o3d.pipelines.registration
    pairs = min(args.pairs, len(result.indices) - 1)
    ours, theirs, errors = [], [], []
    for k in range(1, pairs + 1):
        moving, fixed = (
            prepare(data.scans[result.indices[k]], config),
            prepare(data.scans[result.indices[k - 1]], config),
        )
        f_moving, f_fixed = reg.Feature(), reg.Feature()
        f_moving.data, f_fixed.data = moving.features.T.copy(), fixed.features.T.copy()
        o3d.utility.random.seed(fit.seed)
        start = time.perf_counter()
        ransac = reg.registration_ransac_based_on_feature_matching(
            to_cloud(moving.points),
            to_cloud(fixed.points),
            f_moving,
            f_fixed,
            True,
            fit.max_distance,
            reg.TransformationEstimationPointToPoint(False),
            3,
            [reg.CorrespondenceCheckerBasedOnDistance(fit.max_distance)],
            reg.RANSACConvergenceCriteria(fit.max_num_trials, 0.999),
        )
        theirs.append(1000 * (time.perf_counter() - start))
        ours.append(result.timings["match"][k] + result.timings["msac"][k])
        truth = np.linalg.inv(gt[k - 1]) @ gt[k]
        errors.append(np.linalg.norm((np.linalg.inv(truth) @ np.asarray(ransac.transformation))[:3, 3]))
    print(
        f"Open3D RANSAC (mutual filter, {fit.max_num_trials} trials) on {pairs} pairs: "
        f"{np.mean(theirs):.1f} ms a pair (ours, match + MSAC: {np.mean(ours):.1f} ms); "
        f"coarse translation error median {np.median(errors):.2f} m, max {np.max(errors):.2f} m"
    )


if __name__ == "__main__":
    main()
