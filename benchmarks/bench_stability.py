"""Is registration a stable function of its input? Odometry on the default
flight under several lidar noise seeds, each also re-run on scans nudged by
a micrometre (the size of the last-bit differences between CPUs, amplified
a thousandfold): prints, per seed, the per-step error against the ground
truth, the fallbacks, and how far each step moved under the nudge.

    python benchmarks/bench_stability.py [--seeds 0 1 2] [--nudge 1e-6]
"""

import argparse
import dataclasses
import time

import numpy as np

import helpers
from helpers.config.tables import Config, SensorConfig
from helpers.slam.odometry import run_odometry


def step_errors(relative: np.ndarray, poses_gt: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """(K-1,) translation error (m) of each relative motion against the truth."""
    truth = np.linalg.inv(poses_gt[indices[:-1]]) @ poses_gt[indices[1:]]
    return np.linalg.norm(relative[:, :3, 3] - truth[:, :3, 3], axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--nudge", type=float, default=1e-6, help="metres of uniform jitter added to every point")
    args = parser.parse_args()
    config = Config()
    print(f"{'seed':>4} {'steps':>5} {'median':>8} {'p95':>8} {'max':>8} {'fallbacks':>9} {'moved max':>10} {'s':>5}")
    for seed in args.seeds:
        data = helpers.create_dataset(sensor=dataclasses.replace(SensorConfig(), seed=seed))
        start = time.perf_counter()
        odo = run_odometry(data, config=config)
        seconds = time.perf_counter() - start
        rng = np.random.default_rng(seed + 1000)
        nudged = [scan + rng.uniform(-args.nudge, args.nudge, scan.shape) for scan in data.scans]
        again = run_odometry(nudged, first_pose=data.poses[0], config=config)
        error = step_errors(odo.relative, data.poses, odo.indices)
        moved = np.linalg.norm(again.relative[:, :3, 3] - odo.relative[:, :3, 3], axis=1)
        print(
            f"{seed:4d} {len(error):5d} {np.median(error):7.3f}m {np.percentile(error, 95):7.3f}m {error.max():7.3f}m "
            f"{len(odo.fallbacks):4d} / {len(again.fallbacks):<4d}{moved.max():9.4f}m {seconds:5.0f}"
        )


if __name__ == "__main__":
    main()
