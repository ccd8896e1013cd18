"""The descriptor matcher's gate in space (``[features] match_gate``, issue 22): what it costs and what it
finds, against the search of every descriptor, on pairs of the default flight.

    .venv/bin/python benchmarks/bench_gate.py [--pairs 30 99 150 300] [--gates 0 1 2] [--grid 1.5]
        [--off 0.5 1.0] [--repeat 7] [--seed 0]

Each pair is scan k (fixed) and scan k + 3 (moving, the accepted gap), both prepared as a run prepares
them (``Config()``: the reference's 1.5 m grid and 60 neighbours; ``--grid`` changes the grid). The last
motion a run would know is the true one off by ``--off`` metres along x and degrees of yaw. Per pair and
gate (0: no gate, every fixed descriptor): the cells' width (m), the share of the fixed descriptors a moving
one is compared with, the median ms of ``match_features`` over ``--repeat`` calls on one thread (the script
sets ``OMP_NUM_THREADS=1``, which the matcher reads at each call), the matches and the correct ones (the true
motion carries the moving point within one grid step of its partner).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from helpers.config.tables import Config
from helpers.sim.dataset import create_dataset
from helpers.slam.preprocess import prepare
from helpers.slam.registration.matching import _neighbourhoods, match_features
from helpers.slam.registration.pair import gate


def compared_share(moving_xy: np.ndarray, fixed_xy: np.ndarray, cell: float) -> float:
    """Mean share of the fixed points a moving point is compared with: the matcher's own tiles
    (``matching._neighbourhoods``), each a cell's moving points against its 3 x 3 cells' fixed ones."""
    tiles = _neighbourhoods(moving_xy, fixed_xy, cell)
    return sum(len(rows) * len(columns) for rows, columns in tiles) / (len(moving_xy) * len(fixed_xy))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, nargs="+", default=[30, 99, 150, 300], help="fixed scans (moving: +3)")
    parser.add_argument("--gates", type=float, nargs="+", default=[0.0, 1.0, 2.0])
    parser.add_argument("--grid", type=float, default=None, help="descriptor grid, m (default: Config()'s)")
    parser.add_argument("--off", type=float, nargs=2, default=[0.5, 1.0], metavar=("METRES", "DEGREES"))
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--seed", type=int, default=0, help="the lidar's noise seed")
    args = parser.parse_args()
    os.environ["OMP_NUM_THREADS"] = "1"  # the matcher's threads (helpers.threads.threads reads it at each call)

    config = Config().with_values(sensor={"seed": args.seed})
    if args.grid is not None:
        config = config.with_values(features={"grid_step": args.grid})
    data = create_dataset(sensor=config.sensor)
    features = config.features
    yaw = np.radians(args.off[1])
    nudge = np.eye(4)
    nudge[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    nudge[0, 3] = args.off[0]
    print(f"grid {features.grid_step} m, {features.neighbors} neighbours; last motion {args.off[0]} m and "
          f"{args.off[1]} deg off the truth; one thread; median of {args.repeat} calls")  # fmt: skip
    print(f"{'pair':>9} {'gate':>5} {'cell m':>7} {'compared':>9} {'ms':>7} {'matches':>8} {'correct':>8}")
    for k in args.pairs:
        if not 0 <= k < len(data) - 3:
            sys.exit(f"error: pair {k} -> {k + 3} is outside the flight's {len(data)} scans")
        fixed, moving = prepare(data.scans[k], config), prepare(data.scans[k + 3], config)
        truth = np.linalg.inv(data.poses[k]) @ data.poses[k + 3]
        for factor in args.gates:
            gated = config.with_values(features={"match_gate": factor})
            near = gate(moving, fixed, gated, truth @ nudge)
            times = []
            for _ in range(args.repeat):
                start = time.perf_counter()
                pairs = match_features(
                    moving.features, fixed.features, features.match_threshold, features.match_ratio, near
                )
                times.append(1000 * (time.perf_counter() - start))
            on_moving, on_fixed = moving.described(), fixed.described()
            landed = moving.points[on_moving[pairs[:, 0]]] @ truth[:3, :3].T + truth[:3, 3]
            gap = np.linalg.norm(landed - fixed.points[on_fixed[pairs[:, 1]]], axis=1)
            correct = int(np.sum(gap < features.grid_step))
            cell, share = ("-", 1.0) if near is None else (f"{near[2]:.1f}", compared_share(*near))
            print(
                f"{k:>4}->{k + 3:<4} {factor:5g} {cell:>7} {share:9.0%} {np.median(times):7.1f} "
                f"{len(pairs):8d} {correct:8d}",
                flush=True,
            )


if __name__ == "__main__":
    main()
