"""The global workflow's speed levers (issue 22), each alone and combined: CPU ms per accepted scan by stage,
the coarse fit's error and the odometry's accuracy, on the default flight.

    nice -n 10 .venv/bin/python benchmarks/bench_levers.py [--levers defaults msac ...] [--blas 1 2]
        [--scans 120] [--set table.key=value ...]

Levers (named combinations of existing options; ``defaults`` is today's, whose robust fit is the
yaw-and-translation one, ``robust_fit = "msac4"``):

* ``msac``: ``[registration] robust_fit = "msac"``, the reference's rigid fit;
* ``grid2``: ``[features] grid_step = 2.0, neighbors = 40`` (the reference's 1.5 m and 60);
* ``grid3``: ``[features] grid_step = 3.0, neighbors = 30``;
* ``msac+grid2``, ``msac+grid3``: both.

Each lever runs the odometry of the default flight's first ``--scans`` accepted scans in a fresh process,
once per ``--blas`` thread count (``OPENBLAS_NUM_THREADS`` of that process: numpy's BLAS, which the
robust fit uses; the descriptor matcher holds it to one thread itself, ``helpers.threads.BLAS``, so
the count no longer reaches the matching column). Open3D and small_gicp run on ``OMP_NUM_THREADS`` (1
unless set). Stage times are process CPU times (every thread's), taken where :mod:`helpers.slam.preprocess`
and :mod:`helpers.slam.registration.pair` take their wall times, so a busy machine slows them less than wall times; the
wall time per scan is printed beside them.

Per lever: CPU ms per accepted scan (mean) of FPFH (normals and descriptors), matching, the robust fit and
ICP (downsampling and ICP's cloud preparation included), their total and the wall ms; the coarse fit's
translation error against the true step (median / max, m) and the steps off by more than 1 m; fallbacks;
the odometry's ATE and one-step RPE (m).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

LEVERS = {
    "defaults": [],
    "msac": ["registration.robust_fit=msac"],
    "grid2": ["features.grid_step=2.0", "features.neighbors=40"],
    "grid3": ["features.grid_step=3.0", "features.neighbors=30"],
    "msac+grid2": ["registration.robust_fit=msac", "features.grid_step=2.0", "features.neighbors=40"],
    "msac+grid3": ["registration.robust_fit=msac", "features.grid_step=3.0", "features.neighbors=30"],
}
COLUMNS = ("fpfh", "match", "msac", "icp")  # printed stages; downsampling is added to ICP's column


def child(options: dict) -> dict:
    """One lever's odometry, measured (runs in its own process)."""
    import numpy as np
    from bench_flights import with_settings

    import helpers.slam.preprocess as preparation
    import helpers.slam.registration.pair as frames
    from helpers import create_dataset
    from helpers.config.tables import Config
    from helpers.quality.metrics import ate, rpe
    from helpers.slam.odometry import STAGES, Odometry, accepted_indices, prepare

    frames.time = preparation.time = SimpleNamespace(perf_counter=time.process_time)  # the stages' clocks read CPU
    config = with_settings(Config(), options["set"])
    data = create_dataset(lazy=True)
    indices = accepted_indices(len(data), config)[: options["scans"]]
    scans = [data.scans[i] for i in indices]  # cast before the clocks start
    odometry = Odometry(config, data.poses[indices[0]])
    wall, cpu = time.perf_counter(), time.process_time()
    coarse = []
    for k, index in enumerate(indices):
        pair = odometry.register(prepare(scans[k], config), index)
        if pair is not None:
            truth = np.linalg.inv(data.poses[indices[k - 1]]) @ data.poses[index]
            coarse.append(float(np.linalg.norm((np.linalg.inv(truth) @ pair.T_coarse)[:3, 3])))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    result = odometry.result()
    steps = len(indices) - 1
    per_stage = {stage: float(result.timings[stage][1:].mean()) for stage in STAGES}
    per_stage["icp"] += per_stage.pop("downsample")
    truth = data.poses[result.indices]
    return {
        "stages": per_stage,
        "cpu": 1000 * cpu / steps,
        "wall": 1000 * wall / steps,
        "coarse_median": float(np.median(coarse)),
        "coarse_max": float(np.max(coarse)),
        "coarse_over_1m": int(np.sum(np.array(coarse) > 1.0)),
        "steps": steps,
        "fallbacks": len(result.fallbacks),
        "ate": float(ate(result.poses, truth).rmse),
        "rpe": float(rpe(result.poses, truth, 1).translation.rmse),
        "points": int(np.median([len(prepare(scans[i], config).points) for i in (0, len(scans) // 2)])),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levers", nargs="+", default=list(LEVERS), choices=list(LEVERS))
    parser.add_argument("--blas", nargs="+", type=int, default=[1], help="numpy BLAS threads to measure (default 1)")
    parser.add_argument("--scans", type=int, default=230, help="accepted scans of the default flight (default 230)")
    parser.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE", help="added to each lever")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(json.loads(args.child))))
        return
    if args.scans < 2 or any(b < 1 for b in args.blas):
        parser.exit(2, "error: --scans must be at least 2 and --blas counts at least 1\n")
    print(
        f"{'lever':12} {'BLAS':>4} {'FPFH':>6} {'match':>6} {'fit':>6} {'ICP':>6} {'CPU ms':>7} {'wall':>6}"
        f"  {'coarse m med/max':>16} {'>1 m':>7} {'fallb':>5} {'ATE m':>6} {'RPE m':>6}  points"
    )
    for lever in args.levers:
        for blas in args.blas:
            env = {**os.environ, "OPENBLAS_NUM_THREADS": str(blas), "OMP_WAIT_POLICY": "passive"}
            env.setdefault("OMP_NUM_THREADS", "1")
            options = {"set": LEVERS[lever] + args.set, "scans": args.scans}
            out = subprocess.run(
                [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(options)],
                capture_output=True,
                text=True,
                env=env,
            )
            if out.returncode != 0:
                print(f"{lever:12} {blas:4d} failed: {(out.stderr.strip().splitlines() or ['?'])[-1]}", flush=True)
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
            s = r["stages"]
            print(
                f"{lever:12} {blas:4d} {s['fpfh']:6.1f} {s['match']:6.1f} {s['msac']:6.1f} {s['icp']:6.1f} "
                f"{r['cpu']:7.1f} {r['wall']:6.1f}  {r['coarse_median']:7.2f} / {r['coarse_max']:6.2f} "
                f"{r['coarse_over_1m']:3d}/{r['steps']:<3d} {r['fallbacks']:5d} {r['ate']:6.3f} {r['rpe']:6.3f}  "
                f"{r['points']}",
                flush=True,
            )


if __name__ == "__main__":
    main()
