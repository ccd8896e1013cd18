"""Time and peak memory of whole runs over longer flights: the default loop flown 1, 2, 4 ... times.

    .venv/bin/python benchmarks/bench_long.py [--laps 1 2 4] [--mode tracking]

Each flight repeats the first lap of the shipped waypoints (628 waypoints,
1,256 m) and ends 120 m past its start, as the default does. Every run is a
fresh process, so its peak resident memory is its own. Time should grow
linearly with the number of scans, memory should stay bounded; the figures
say how far the current pipeline is from that.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

LAP = 628  # waypoints of one lap of the shipped flight (the 629th is back at the start)
PAST_START = 61  # waypoints flown past the start at the end (120 m): one lap is the shipped flight

CHILD = """
import json, resource, sys, time
import helpers
from helpers.config import Config
from helpers.pipeline import run_slam
from helpers.evaluation import run_metrics
start = time.perf_counter()
data = helpers.create_dataset(waypoints_path=sys.argv[1], lazy=True)
created = time.perf_counter() - start
result = run_slam(data, Config().with_values(registration=dict(mode=sys.argv[2])))
m = run_metrics(data, result)
print(json.dumps({"scans": len(data), "dataset_s": created, "slam_s": time.perf_counter() - start - created,
                  "peak_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
                  "loops": m["n_loop_closures"], "false": m["n_false_loop_closures"],
                  "ate_m": m["ate_rmse_optimized_m"]}))
"""


def main() -> None:
    import numpy as np

    import helpers

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--laps", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--mode", default="tracking", choices=["global", "tracking"])
    args = parser.parse_args()
    lap = helpers.read_waypoints(helpers.DEFAULT_WAYPOINTS)[:LAP]
    header = ("laps", "scans", "dataset s", "SLAM s", "ms/scan", "peak GiB", "loops", "ATE m")
    print(" ".join(f"{h:>9}" for h in header))
    with tempfile.TemporaryDirectory() as work:
        for laps in args.laps:
            path = Path(work) / f"laps{laps}.csv"
            flight = np.concatenate([np.tile(lap, (laps, 1)), lap[:PAST_START]])
            np.savetxt(path, flight, delimiter=",", header="x,y", comments="")
            out = subprocess.run([sys.executable, "-c", CHILD, str(path), args.mode], capture_output=True, text=True)
            if out.returncode != 0:
                sys.exit(f"error: the run over {laps} laps failed:\n{out.stderr[-2000:]}")
            r = json.loads(out.stdout.strip().splitlines()[-1])
            per_scan = 1000 * r["slam_s"] / r["scans"]
            print(
                f"{laps:9d} {r['scans']:9d} {r['dataset_s']:9.1f} {r['slam_s']:9.1f} {per_scan:9.1f} "
                f"{r['peak_gib']:9.2f} {r['loops']:7d}/{r['false']} {r['ate_m']:9.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
