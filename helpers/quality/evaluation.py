"""Stage 7: a run graded against the ground truth, after the run (the
pipeline itself reads no true pose but the first): its loop edges, its
trajectory errors (:mod:`helpers.quality.metrics`), its map, and its figures in one table.

The map error of a point of the estimated map is its distance to the nearest
point of the ground-truth map (the union of all true lidar hits). Like the
trajectory errors, the raw distances are kept beside their statistics and the
unit is always named.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from helpers.geometry import check_points, relative_pose_error
from helpers.quality.metrics import ErrorStats, ate, is_false_loop, json_safe, rpe
from helpers.quality.trust import assess
from helpers.slam.graph.factors import Edge

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GradedLoop(Edge):
    """A loop edge ``pose_j = pose_i @ relative`` and how far it is from the truth."""

    error_m: float = float("nan")  # translation error of ``relative`` against the ground truth
    error_deg: float = float("nan")  # rotation error, degrees

    @property
    def false(self) -> bool:
        return is_false_loop(self.error_m, self.error_deg)


def true_relative_pose(poses_gt: np.ndarray, i: int, j: int) -> np.ndarray:
    """The true ``T_i_j`` between nodes ``i`` and ``j`` (``poses_gt``: the nodes' true poses)."""
    return np.linalg.inv(poses_gt[i]) @ poses_gt[j]


def loop_error(poses_gt: np.ndarray, edge) -> tuple[float, float]:
    """How far an edge (``i``, ``j``, ``relative``) is from the truth: translation (m), rotation (deg)."""
    error_m, error_deg = relative_pose_error(true_relative_pose(poses_gt, edge.i, edge.j), edge.relative)
    return float(error_m), float(error_deg)


def grade_loops(dataset, result) -> list[GradedLoop]:
    """Every loop edge of ``result`` compared with the true relative pose of
    its two nodes (``dataset.poses`` at ``result.indices``); false ones are logged."""
    poses_gt = dataset.poses[result.indices]
    graded = []
    for loop in result.loops:
        error_m, error_deg = loop_error(poses_gt, loop)
        graded.append(GradedLoop(loop.i, loop.j, loop.relative, loop.surface_rmse, error_m, error_deg))
        if graded[-1].false:
            log.warning("false loop %d -> %d: %.2f m, %.2f deg off", loop.i, loop.j, error_m, error_deg)
    return graded


def run_metrics(dataset, result, map_error: MapError | None = None, health=None) -> dict:
    """The figures of a run, units in the names: counts, ATE and RPE against
    ``dataset.poses`` at the nodes, the graph error, the runtimes and, if
    given, the map error (:func:`map_errors`). ``trusted`` and ``health``
    come from the run alone (:func:`helpers.quality.trust.assess`); a figure that is
    not a finite number is None and makes the run untrusted
    (:func:`helpers.quality.metrics.json_safe`). ``health``: the run's
    :class:`~helpers.quality.trust.Health`, if already assessed (it optimises the
    graph again, seconds on a long flight)."""
    health = assess(result) if health is None else health
    poses_gt = dataset.poses[result.indices]
    odometry, optimized = ate(result.poses_odometry, poses_gt), ate(result.poses_optimized, poses_gt)
    rpe_1 = rpe(result.poses_optimized, poses_gt, 1)
    long_enough = len(result.indices) > 10  # a short flight has no 10-step pairs: those figures are None
    rpe_10 = rpe(result.poses_optimized, poses_gt, 10) if long_enough else None
    steps = result.odometry.timings
    metrics = {
        "trusted": health.trusted,
        "shape_trusted": health.consistent,
        "health": {**health.counts, "problems": health.problems, "scale": health.scale},
        "n_scans": result.n_scans,
        "n_accepted": len(result.indices),
        "n_loop_closures": len(result.loops),
        "n_false_loop_closures": sum(loop.false for loop in grade_loops(dataset, result)),
        "n_odometry_fallbacks": len(result.odometry.fallbacks),
        "n_odometry_ungated": int(np.sum(result.odometry.ungated)),  # gated matches redone without the gate
        "n_extra_edges": len(result.extra_edges),
        "ate_rmse_odometry_m": odometry.rmse,
        "ate_rmse_optimized_m": optimized.rmse,
        "ate_max_optimized_m": optimized.max,
        "rpe_trans_1_m": rpe_1.translation.rmse,
        "rpe_rot_1_deg": rpe_1.rotation.rmse,
        "rpe_trans_10_m": rpe_10.translation.rmse if rpe_10 else None,
        "rpe_rot_10_deg": rpe_10.rotation.rmse if rpe_10 else None,
        "graph_error_before": result.graph.error_before,
        "graph_error_after": result.graph.error_after,
        "runtime_s": {
            "total": sum(result.runtime_s.values()),
            **result.runtime_s,
            "odometry_per_scan_ms": {stage: float(np.mean(ms)) for stage, ms in steps.items()},
        },
    }
    if map_error is not None:
        metrics |= {"map_error_mean_m": map_error.mean, "map_error_median_m": map_error.median}
        metrics["map_error_p95_m"] = map_error.p95
    return json_safe(metrics)


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
    m = run_metrics(dataset, result)
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
