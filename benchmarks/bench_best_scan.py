"""The best-scan search of a loop query: what the stop saves, and what it changes.

    .venv/bin/python benchmarks/bench_best_scan.py [--flights default laps2 autzen-250 sparse-150]

Once old submaps match, the reference registers the current scan by ICP
onto every scan of them and keeps the lowest RMSE; ours (``[loop_closure]
best_scan_stop``) registers them best fitting first and stops at one under
that share of ``rmse_threshold`` (:func:`helpers.slam.loops.closer.best_scan_registration`).
Each flight runs once with the shipped search, in a fresh process. At every
query this script also runs the reference's search (the same function with
``best_scan_stop = 0``), to see what it would have chosen from the same
query, and reports:

* queries, the scans of their matching submaps (what the reference's search
  registers) and the registrations the stop ran;
* queries whose chosen scan is another than the reference's, and by how much
  the reference's RMSE was lower (at most);
* loops lost: queries where the reference's choice was under ``rmse_threshold``
  and ours was not (the pin test aside);
* the run's loops and optimised ATE.

Flights: ``bench_flights.py``'s names (the parameters fitted as ``run`` fits
them, two laps on tiles) and ``lapsN``, the default loop flown N times in
tracking mode as ``bench_long.py`` flies it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from bench_flights import child_result

HERE = Path(__file__).resolve().parent

CHILD = r"""
import dataclasses, json, sys, tempfile
import numpy as np
sys.path.insert(0, sys.argv[2])
import helpers
import helpers.slam.loops.closer as lc
from helpers.config.tables import Config
from helpers.quality.evaluation import run_metrics
from helpers.slam.pipeline import run_slam

name, queries = sys.argv[1], []
search = lc.best_scan_registration


class Counted:  # the run's ICP, counting the registrations a search runs
    def __init__(self, icp_fn):
        self.icp_fn, self.calls = icp_fn, 0

    def __call__(self, **kw):
        self.calls += 1
        return self.icp_fn(**kw)

    def score(self, **kw):
        return self.icp_fn.score(**kw)


def recorded(scan_points, current_id, candidates, scans, poses, n, icp_fn, settings=None):
    every, ours = Counted(icp_fn), Counted(icp_fn)  # the reference's search (every scan) on the same query, then ours
    reference = search(scan_points, current_id, candidates, scans, poses, n, every,
                       dataclasses.replace(settings, best_scan_stop=0.0))
    edge = search(scan_points, current_id, candidates, scans, poses, n, ours, settings)
    queries.append({"scans": every.calls, "run": ours.calls, "reference": reference.surface_rmse,
                    "ours": edge.surface_rmse, "threshold": settings.rmse_threshold})
    return edge


lc.best_scan_registration = recorded
if name.startswith("laps"):
    xy = helpers.read_waypoints(helpers.DEFAULT_WAYPOINTS)
    rows = np.concatenate([np.tile(xy[:628], (int(name[4:]), 1)), xy[:61]])
    path = tempfile.mktemp(suffix=".csv")
    np.savetxt(path, rows[:, :2], delimiter=",", header="x,y", comments="")
    data = helpers.create_dataset(waypoints_path=path, lazy=True)
    config = Config().with_values(registration={"mode": "tracking"})
else:
    from bench_flights import build_flight

    data, config = build_flight({"name": name, "laps": 2, "swing": 0.0, "set": [], "map_error": False})
result = run_slam(data, config)
m = run_metrics(data, result)
print(json.dumps({"queries": queries, "loops": m["n_loop_closures"], "false": m["n_false_loop_closures"],
                  "ate": m["ate_rmse_optimized_m"]}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flights", nargs="+", default=["default", "laps2", "autzen-250", "sparse-150"])
    args = parser.parse_args()
    print(
        f"{'flight':12s} {'queries':>7s} {'scans':>6s} {'ICPs':>5s} {'other':>6s} {'gap m':>6s} {'lost':>5s}"
        f" {'loops':>9s} {'ATE m':>6s}"
    )
    total = {"queries": 0, "scans": 0, "run": 0, "other": 0, "lost": 0, "gap": 0.0}
    for name in args.flights:
        r, error = child_result(CHILD, name, str(HERE))
        if r is None:
            print(f"{name:12s} failed: {error}", flush=True)
            continue
        q = r["queries"]
        other = [x for x in q if x["ours"] != x["reference"]]
        gap = max((x["ours"] - x["reference"] for x in other), default=0.0)
        lost = sum(x["reference"] < x["threshold"] <= x["ours"] for x in q)
        row = {
            "queries": len(q),
            "scans": sum(x["scans"] for x in q),
            "run": sum(x["run"] for x in q),
            "other": len(other),
            "lost": lost,
            "gap": gap,
        }
        print(
            f"{name:12s} {row['queries']:7d} {row['scans']:6d} {row['run']:5d} {row['other']:6d} {gap:6.3f}"
            f" {lost:5d} {r['loops']:6d} ({r['false']}) {r['ate']:6.2f}",
            flush=True,
        )
        for key in ("queries", "scans", "run", "other", "lost"):
            total[key] += row[key]
        total["gap"] = max(total["gap"], gap)
    print(
        f"{'all':12s} {total['queries']:7d} {total['scans']:6d} {total['run']:5d} {total['other']:6d}"
        f" {total['gap']:6.3f} {total['lost']:5d}"
    )


if __name__ == "__main__":
    main()
