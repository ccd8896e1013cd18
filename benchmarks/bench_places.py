"""Place recognition on its own: does it find true loops, and only true ones?

    .venv/bin/python benchmarks/bench_places.py [--flights autzen-150 sparse-150 default autzen-250 ...]

A run asks :mod:`helpers.slam.loops.places` only after a blind stretch, and only at
queries the loop search closed nothing at, so on most flights it is never
asked and a wrong recognition would be rare to see. Here every flight runs
with the loop search's own candidates taken away (``find_loop_candidates``
finds none) and place recognition asked from the first query on, as often as
a run asks it (every second submap's worth of nodes, every submap's while a
recognition waits to be confirmed), never stopping: every loop of the run is a
recognised one, the confirmation by the recognition before it included.
Each flight runs once, in a fresh process, with its parameters fitted as
``bench_flights.py`` fits them (two laps on tiles), and prints:

* recognitions asked, the loops they closed and how many were false
  (:func:`helpers.quality.metrics.is_false_loop`), and the loop farthest from the
  truth (m, deg);
* the optimised ATE and the run's seconds.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from bench_flights import child_result

HERE = Path(__file__).resolve().parent

CHILD = r"""
import json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[2])
import helpers.slam.loops.closer as lc
import helpers.slam.loops.places as places
from bench_flights import build_flight
from helpers.quality.evaluation import grade_loops, run_metrics
from helpers.slam.loops.search import LoopCandidates
from helpers.slam.pipeline import run_slam

asked = []
follow, recognise = places.PlaceRecognition.follow, places.PlaceRecognition.recognise


def always(self, node, frame, fell_back):  # lost from the first scan on, and never found again
    follow(self, node, frame, fell_back)
    self.lost = True


def counted(self, node, poses, eligible):
    found = recognise(self, node, poses, eligible)
    if self.asked == node:  # it ran (not skipped: one was asked too few nodes before)
        asked.append(node)
    return found


places.PlaceRecognition.follow, places.PlaceRecognition.recognise = always, counted
places.PlaceRecognition.closed = lambda self: None
none = (np.zeros(0, dtype=int), np.zeros(0), np.zeros((0, 4, 4)))
lc.find_loop_candidates = lambda *args, **kw: LoopCandidates(*none, n_eligible=0, radius=np.zeros(0))
data, config = build_flight({"name": sys.argv[1], "laps": 2, "swing": 0.0, "set": [], "seed": 0})
start = time.perf_counter()
result = run_slam(data, config)
seconds = time.perf_counter() - start
m = run_metrics(data, result)
graded = grade_loops(data, result)
print(json.dumps({"asked": len(asked), "loops": m["n_loop_closures"], "false": m["n_false_loop_closures"],
                  "worst_m": max((g.error_m for g in graded), default=0.0),
                  "worst_deg": max((g.error_deg for g in graded), default=0.0),
                  "ate": m["ate_rmse_optimized_m"], "s": seconds}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flights", nargs="+", default=["autzen-150", "sparse-150", "default", "autzen-250"])
    args = parser.parse_args()
    print(f"{'flight':14s} {'asked':>5s} {'loops':>9s} {'worst m':>8s} {'deg':>5s} {'ATE m':>6s} {'s':>5s}")
    for name in args.flights:
        r, error = child_result(CHILD, name, str(HERE))
        if r is None:
            print(f"{name:14s} failed: {error}", flush=True)
            continue
        print(
            f"{name:14s} {r['asked']:5d} {r['loops']:5d} ({r['false']}) {r['worst_m']:8.2f} {r['worst_deg']:5.2f}"
            f" {r['ate']:6.2f} {r['s']:5.0f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
