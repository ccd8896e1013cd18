"""Stage 7: how good is the rebuilt map, and the run's figures in one table.

The map error of a point of the estimated map is its distance to the nearest
point of the ground-truth map (the union of all true lidar hits). Like the
trajectory errors of :mod:`helpers.metrics`, the raw distances are kept beside
their statistics and the unit is always named.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .features import check_points
from .metrics import ErrorStats


@dataclass(frozen=True)
class MapError(ErrorStats):
    """Distances (m) from each estimated-map point to the ground-truth map."""

    def percentile(self, q: float) -> float:
        return float(np.percentile(self.errors, q))

    @property
    def p95(self) -> float:
        return self.percentile(95.0)

    def __str__(self) -> str:
        return f"mean {self.mean:.3f} {self.unit}, median {self.median:.3f}, 95th percentile {self.p95:.3f}"


def map_errors(estimated_map, ground_truth_map, workers: int = -1) -> MapError:
    """Distance (m) from every point of ``estimated_map`` (N, 3) to its nearest
    neighbour in ``ground_truth_map`` (M, 3); ``.errors`` holds the (N,) distances.

    The ground-truth map goes into a k-d tree once; all the queries then run
    at once on ``workers`` threads (-1: every core).
    """
    estimated = check_points(estimated_map, "the estimated map")
    truth = check_points(ground_truth_map, "the ground-truth map")
    tree = cKDTree(truth, balanced_tree=False, compact_nodes=False)  # builds faster on millions of points
    distances, _ = tree.query(estimated, k=1, workers=workers)
    return MapError(distances, "m")


def summary_table(dataset, result, map_error: MapError | None = None) -> list[tuple[str, float | int, str]]:
    """The figures of a run as ``(measure, value, unit)`` rows: trajectory
    errors, loop closures and map errors. Pass ``map_error`` if it is already
    computed for ``result.map_points``; otherwise it is computed here."""
    if map_error is None:
        map_error = map_errors(result.map_points, dataset.map_points)
    m = result.metrics()
    return [
        ("ATE RMSE, odometry only", m["ate_rmse_odometry_m"], "m"),
        ("ATE RMSE, optimised", m["ate_rmse_optimized_m"], "m"),
        ("RPE translation, 1 step", m["rpe_trans_1_m"], "m"),
        ("RPE rotation, 1 step", m["rpe_rot_1_deg"], "deg"),
        ("RPE translation, 10 steps", m["rpe_trans_10_m"], "m"),
        ("RPE rotation, 10 steps", m["rpe_rot_10_deg"], "deg"),
        ("loop closures accepted", m["n_loop_closures"], "count"),
        ("loop closures false", m["n_false_loop_closures"], "count"),
        ("map error, mean", map_error.mean, "m"),
        ("map error, median", map_error.median, "m"),
        ("map error, 95th percentile", map_error.p95, "m"),
    ]


def format_table(rows, digits: int = 3) -> str:
    """The rows of :func:`summary_table` as aligned text, numbers rounded to
    ``digits`` significant figures (counts printed whole)."""
    width = max(len(name) for name, _, _ in rows)
    lines = []
    for name, value, unit in rows:
        shown = f"{value:d}" if isinstance(value, (int, np.integer)) else f"{value:.{digits}g}"
        lines.append(f"{name:<{width}}  {shown:>8}  {unit}")
    return "\n".join(lines)
