"""Time and peak memory of whole runs over longer flights: the default loop flown 1, 2, 4 ... times.

    .venv/bin/python benchmarks/bench_long.py [--laps 1 2 4] [--mode tracking]
        [--search uncertainty growth] [--skip-after-loop 0 6]

Each flight repeats the first lap of the shipped waypoints (628 waypoints,
1,256 m) and ends 120 m past its start, as the default does. Every run is a
fresh process, so its peak resident memory is its own (with its helper
process's for the edges back, :mod:`helpers.slam.edges_back`: the sum of the
two peaks, an upper bound). Time should grow linearly with the number of
scans, memory should stay bounded; the figures say how far the current
pipeline is from that.

Each run is given by its laps and its loop search (``[loop_closure]
search``, ``skip_after_loop`` and ``skip_after_closed_place``; one run per
combination). A second table splits each run by lap: the seconds of the
whole run and of its loop closure spent on each lap's scans (the last lap
holds the 120 m past the start), the loops found then, each lap's time
over the first's (issue 22 asks at most 1.5 for a revisit lap), and what the
loop search's uncertainty cost (ms per accepted scan,
``RelativeUncertainty.seconds``; how often a query needed the whole graph
rather than its window).
"""

from __future__ import annotations

import argparse
import itertools
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
from helpers.config.tables import Config
from helpers.quality.evaluation import run_metrics
from helpers.slam.slam import Slam
path, mode, search, skip, lap = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5])
start = time.perf_counter()
data = helpers.create_dataset(waypoints_path=path, lazy=True)
created = time.perf_counter() - start
closed = int(sys.argv[6])
config = Config().with_values(
    registration=dict(mode=mode),
    loop_closure=dict(search=search, skip_after_loop=skip, skip_after_closed_place=closed),
)
slam = Slam(config, anchor=data.poses[0], background=True)  # as run_slam: the edges back in a helper process
laps, clock, loops = [], time.perf_counter(), 0
for index in range(len(data)):
    if slam.accepts(index):
        loops += slam.process(data.scans[index], index).loop is not None
    if (index + 1) % lap == 0 and len(data) - index - 1 >= lap or index == len(data) - 1:
        laps.append({"s": time.perf_counter() - clock, "loop_s": slam.runtime["submaps_and_loop_closure"],
                     "loops": loops, "nodes": len(slam.indices)})
result = slam.result(n_scans=len(data))
m = run_metrics(data, result)
graph = slam.loops.uncertainty
print(json.dumps({"scans": len(data), "dataset_s": created, "slam_s": time.perf_counter() - start - created,
                  "peak_gib": sum(resource.getrusage(who).ru_maxrss for who in (resource.RUSAGE_SELF,
                                                                                resource.RUSAGE_CHILDREN)) / 2**20,
                  "loops": m["n_loop_closures"], "false": m["n_false_loop_closures"],
                  "ate_m": m["ate_rmse_optimized_m"], "laps": laps, "skipped": slam.loops.skipped,
                  "cov_ms": 0.0 if graph is None else 1000 * graph.seconds / len(slam.indices),
                  "cov_query_ms": 0.0 if graph is None else 1000 * graph.seconds / max(graph.answers, 1),
                  "refreshes": 0 if graph is None else graph.refreshes,
                  "whole": 0 if graph is None else graph.whole}))
"""


def main() -> None:
    import numpy as np

    import helpers

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--laps", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--mode", default="tracking", choices=["global", "tracking"])
    parser.add_argument("--search", nargs="+", default=["uncertainty"], choices=["uncertainty", "growth"])
    parser.add_argument("--skip-after-loop", type=int, nargs="+", default=[None], help="default: the config's")
    parser.add_argument("--skip-after-closed-place", type=int, nargs="+", default=[None], help="default: the config's")
    args = parser.parse_args()
    for name in ("skip_after_loop", "skip_after_closed_place"):
        if any(s is not None and s < 0 for s in getattr(args, name)):
            option = "--" + name.replace("_", "-")
            print(f"error: {option} takes zero or a positive number of accepted scans", file=sys.stderr)
            sys.exit(2)
    lap = helpers.read_waypoints(helpers.DEFAULT_WAYPOINTS)[:LAP]
    header = (
        "laps",
        "search",
        "skip",
        "closed",
        "scans",
        "dataset s",
        "SLAM s",
        "ms/scan",
        "peak GiB",
        "loops",
        "ATE m",
    )
    print(" ".join(f"{h:>11}" for h in header))
    per_lap = []
    with tempfile.TemporaryDirectory() as work:
        defaults = helpers.Config().loop_closure
        runs = itertools.product(args.laps, args.search, args.skip_after_loop, args.skip_after_closed_place)
        for laps, search, skip, closed in runs:
            skip = defaults.skip_after_loop if skip is None else skip
            closed = defaults.skip_after_closed_place if closed is None else closed
            path = Path(work) / f"laps{laps}.csv"
            flight = np.concatenate([np.tile(lap, (laps, 1)), lap[:PAST_START]])
            np.savetxt(path, flight, delimiter=",", header="x,y", comments="")
            command = [sys.executable, "-c", CHILD, str(path), args.mode, search, str(skip), str(LAP), str(closed)]
            out = subprocess.run(command, capture_output=True, text=True)
            if out.returncode != 0:
                sys.exit(
                    f"error: the run over {laps} laps ({search}, skip {skip}/{closed}) failed:\n{out.stderr[-2000:]}"
                )
            r = json.loads(out.stdout.strip().splitlines()[-1])
            per_scan = 1000 * r["slam_s"] / r["scans"]
            print(
                f"{laps:11d} {search:>11} {skip:11d} {closed:11d} {r['scans']:11d} {r['dataset_s']:11.1f} "
                f"{r['slam_s']:11.1f} "
                f"{per_scan:11.1f} {r['peak_gib']:11.2f} {r['loops']:9d}/{r['false']} {r['ate_m']:11.3f}",
                flush=True,
            )
            per_lap.append((laps, search, f"{skip}/{closed}", r))
    print("\nper lap: seconds of the run / of its loop closure, loops found; the uncertainty's cost")
    for laps, search, skip, r in per_lap:
        before = {"s": 0.0, "loop_s": 0.0, "loops": 0, "nodes": 0}
        cells, seconds = [], []
        for row in r["laps"]:
            seconds.append(row["s"] - before["s"])
            cells.append(
                f"{seconds[-1]:.1f} / {row['loop_s'] - before['loop_s']:.1f} s, {row['loops'] - before['loops']} loops"
            )
            before = row
        ratios = ", ".join(f"{s / seconds[0]:.2f}" for s in seconds[1:])
        print(
            f"{laps} laps, {search}, skip {skip}: "
            + "; ".join(cells)
            + (f" | each lap over the first: {ratios}" if ratios else "")
            + f" | {r['skipped']} queries skipped, covariance {r['cov_ms']:.2f} ms/scan, "
            + f"{r['cov_query_ms']:.2f} ms/query ({r['refreshes']} eliminations, {r['whole']} of the whole graph "
            + "beyond the window)"
        )


if __name__ == "__main__":
    main()
