"""The whole SLAM pipeline, stage after stage, as the reference's main loop:
odometry over the accepted scans, submaps, loop-closure queries, the pose
graph, and the map rebuilt at the optimised poses.

Accepted scans are the pose-graph nodes, numbered 0, 1, 2, ...;
``result.indices[k]`` is the dataset index of node ``k``.
"""

from __future__ import annotations

import hashlib
import json
import logging
import pickle
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import paths
from .config import Config, SlamConfig, config_to_dict, config_to_toml
from .dataset import Dataset, create_dataset
from .features import grid_average
from .loopclosure import best_scan_match, find_loop_candidates, icp_with
from .metrics import ate, rpe
from .odometry import OdometryResult, run_odometry
from .plyio import write_ply
from .posegraph import ICP_EDGE_SIGMAS, OptimizationResult, PoseGraph, information_from_sigmas
from .progress import progress_bar
from .submaps import SubmapIndex, build_submap
from .trajectory import write_tum

log = logging.getLogger(__name__)

# The modules whose code decides a run's numbers: the cache of default_run
# is keyed by their source (figure and report modules are left out).
RUN_MODULES = (
    "config", "dataset", "features", "loopclosure", "mapio", "odometry", "pipeline",
    "posegraph", "registration", "scene", "sensor", "submaps", "waypoints",
)  # fmt: skip
FALSE_LOOP_M = 1.0  # a loop edge farther than this from the truth is false ...
FALSE_LOOP_DEG = 2.0  # ... or turned by more than this


@dataclass(frozen=True)
class LoopClosure:
    """A loop edge ``pose_j = pose_i @ relative`` and how far it is from the truth."""

    i: int  # the older node
    j: int  # the current node
    relative: np.ndarray
    rmse: float  # m, ICP RMSE of the scan-to-scan match
    error_m: float  # translation error of ``relative`` against the ground truth
    error_deg: float  # rotation error, degrees

    @property
    def false(self) -> bool:
        return self.error_m > FALSE_LOOP_M or self.error_deg > FALSE_LOOP_DEG


@dataclass(frozen=True)
class Edge:
    """A registration ``pose_j = pose_i @ relative`` between two nodes."""

    i: int
    j: int
    relative: np.ndarray
    rmse: float  # m, surface RMSE of the registration


@dataclass(frozen=True)
class LoopQuery:
    """One loop-candidate query that registered at least one old submap."""

    node: int
    tried: np.ndarray  # RMSE (m) of every submap the scan was registered to, nearest submap first
    submap_ids: np.ndarray  # the submaps below loop_closure_threshold, best first
    scores: np.ndarray  # their RMSE, m
    best_scan_rmse: float  # RMSE of the best scan-to-scan match (inf if no submap matched)
    closure: LoopClosure | None  # the accepted loop edge, if any


@dataclass
class SlamResult:
    config: SlamConfig
    indices: np.ndarray  # (K,) dataset index of each node
    poses_gt: np.ndarray  # (K, 4, 4) ground truth of the nodes
    odometry: OdometryResult
    clouds: list[np.ndarray]  # (N_k, 3) downsampled scans, sensor frame
    submaps: SubmapIndex
    queries: list[LoopQuery]
    graph: OptimizationResult
    extra_edges: list[Edge]  # odometry edges that skip nodes (see SlamConfig.edges_back)
    map_points: np.ndarray  # (M, 3) global map at the optimised poses
    n_scans: int  # scans in the dataset, accepted or not
    runtime_s: dict = field(default_factory=dict)

    @property
    def loops(self) -> list[LoopClosure]:
        return [q.closure for q in self.queries if q.closure is not None]

    @property
    def poses_odometry(self) -> np.ndarray:
        return self.odometry.poses

    @property
    def poses_optimized(self) -> np.ndarray:
        return self.graph.poses

    def metrics(self) -> dict:
        """The figures of the run, units in the names."""
        odometry, optimized = ate(self.poses_odometry, self.poses_gt), ate(self.poses_optimized, self.poses_gt)
        rpe_1 = rpe(self.poses_optimized, self.poses_gt, 1)
        long_enough = len(self.indices) > 10  # a short flight has no 10-step pairs: those figures are None
        rpe_10 = rpe(self.poses_optimized, self.poses_gt, 10) if long_enough else None
        steps = self.odometry.timings
        return {
            "n_scans": self.n_scans,
            "n_accepted": len(self.indices),
            "n_loop_closures": len(self.loops),
            "n_false_loop_closures": sum(loop.false for loop in self.loops),
            "n_odometry_fallbacks": len(self.odometry.fallbacks),
            "n_extra_edges": len(self.extra_edges),
            "ate_rmse_odometry_m": odometry.rmse,
            "ate_rmse_optimized_m": optimized.rmse,
            "ate_max_optimized_m": optimized.max,
            "rpe_trans_1_m": rpe_1.translation.rmse,
            "rpe_rot_1_deg": rpe_1.rotation.rmse,
            "rpe_trans_10_m": rpe_10.translation.rmse if rpe_10 else None,
            "rpe_rot_10_deg": rpe_10.rotation.rmse if rpe_10 else None,
            "graph_error_before": self.graph.error_before,
            "graph_error_after": self.graph.error_after,
            "runtime_s": {
                "total": sum(self.runtime_s.values()),
                **self.runtime_s,
                "odometry_per_scan_ms": {stage: float(np.mean(ms)) for stage, ms in steps.items()},
            },
        }


def run_slam(dataset: Dataset, config: SlamConfig | None = None, progress: bool = False) -> SlamResult:
    """Estimate the trajectory and the map from ``dataset.scans`` alone (the
    first ground-truth pose anchors the first node, as in the reference)."""
    config = config or SlamConfig()
    runtime = {}

    # 1. Odometry: register every accepted scan to the previous one.
    start = time.perf_counter()
    odometry = run_odometry(dataset, dataset.poses[0], config, progress=progress)
    runtime["odometry"] = time.perf_counter() - start

    # 2.-3. Submaps and loop-closure queries, scan after scan, on the odometry
    #       poses. ICP works on the same finer clouds as in the odometry.
    start = time.perf_counter()
    step = config.icp_grid_step or config.grid_step
    clouds = [grid_average(dataset.scans[i], step) for i in odometry.indices]
    submaps, queries = _submaps_and_loops(clouds, odometry.poses, dataset.poses[odometry.indices], config, progress)
    runtime["submaps_and_loop_closure"] = time.perf_counter() - start

    # 4. Pose graph: odometry edges, edges to older scans, loop edges, the
    #    first node anchored.
    start = time.perf_counter()
    extra = _edges_back(clouds, odometry.relative, config)
    runtime["edges_back"] = time.perf_counter() - start
    start = time.perf_counter()
    graph = build_pose_graph(odometry, extra, [q.closure for q in queries if q.closure], config)
    optimized = graph.optimize(anchor_pose=dataset.poses[0], loop_kernel=config.loop_kernel)
    runtime["pose_graph"] = time.perf_counter() - start

    # 5. The map: every accepted scan at its optimised pose, merged on a grid.
    start = time.perf_counter()
    map_points = build_submap(clouds, optimized.poses, config.align_grid_step)
    runtime["map"] = time.perf_counter() - start

    return SlamResult(
        config=config,
        indices=odometry.indices,
        poses_gt=dataset.poses[odometry.indices],
        odometry=odometry,
        clouds=clouds,
        submaps=submaps,
        queries=queries,
        graph=optimized,
        extra_edges=extra,
        map_points=map_points,
        n_scans=len(dataset),
        runtime_s=runtime,
    )


def _submaps_and_loops(clouds, poses, poses_gt, config: SlamConfig, progress: bool):
    """Build a submap every ``n_scans_per_submap`` nodes and query old
    submaps for loops once there are more than ``sub_map_thresh`` of them."""
    scores = []  # every registration score of the current query, in order
    icp = icp_with(config.metric, config.inlier_distance)

    def scored_icp(moving, fixed, init):
        transform, rmse = icp(moving, fixed, init)
        scores.append(rmse)
        return transform, rmse

    submaps = SubmapIndex(config.n_scans_per_submap, config.align_grid_step)
    queries: list[LoopQuery] = []
    bar = progress_bar(len(clouds), "submaps and loops") if progress else None
    for node, (cloud, pose) in enumerate(zip(clouds, poses, strict=True)):
        submaps.add_scan(cloud, pose)
        if len(submaps) > config.sub_map_thresh:
            scores.clear()
            candidates = find_loop_candidates(
                submaps.points,
                submaps.centres,
                cloud,
                pose,
                len(submaps) - 1,
                config.sub_map_thresh,
                config.loop_closure_search_radius,
                config.loop_closure_threshold,
                scored_icp,
                radius_growth=config.loop_search_growth,
            )
            tried = np.array(scores)
            closure, best = None, float("inf")
            if len(candidates.ids):
                scores.clear()
                match = best_scan_match(
                    cloud, node, candidates, clouds, poses, config.n_scans_per_submap, config.rmse_threshold, scored_icp
                )
                best = min(scores)
                closure = None if match is None else _judged(match, poses_gt)
            if len(tried):
                queries.append(LoopQuery(node, tried, candidates.ids, candidates.scores, best, closure))
        if bar is not None:
            bar.set_postfix(loops=sum(q.closure is not None for q in queries), refresh=False)
            bar.update(1)
    if bar is not None:
        bar.close()
    return submaps, queries


def _judged(match, poses_gt) -> LoopClosure:
    """Compare a loop edge with the true relative pose of its two nodes."""
    truth = np.linalg.inv(poses_gt[match.i]) @ poses_gt[match.j]
    error = np.linalg.inv(truth) @ match.relative_pose
    cos_angle = np.clip((np.trace(error[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    closure = LoopClosure(
        match.i,
        match.j,
        match.relative_pose,
        match.rmse,
        float(np.linalg.norm(error[:3, 3])),
        float(np.degrees(np.arccos(cos_angle))),
    )
    if closure.false:
        log.warning(
            "false loop %d -> %d: %.2f m, %.2f deg off", closure.i, closure.j, closure.error_m, closure.error_deg
        )
    return closure


def _edges_back(clouds, relative: np.ndarray, config: SlamConfig) -> list[Edge]:
    """Register every node to the nodes 2 .. ``edges_back`` before it, from
    the chained odometry as the initial guess. Each extra edge measures the
    motion again with other points, so the pose graph can average the
    odometry's random errors instead of summing them. Registrations scored
    above ``rmse_threshold`` are left out."""
    icp = icp_with(config.metric, config.inlier_distance)
    edges = []
    for back in range(2, config.edges_back + 1):
        for j in range(back, len(clouds)):
            guess = np.linalg.multi_dot([np.eye(4), *relative[j - back : j]])
            transform, rmse = icp(clouds[j], clouds[j - back], guess)
            if rmse < config.rmse_threshold:
                edges.append(Edge(j - back, j, transform, rmse))
            else:
                log.info("edge %d -> %d left out: surface RMSE %.2f m", j - back, j, rmse)
    return edges


def build_pose_graph(odometry: OdometryResult, extra: list[Edge], loops, config: SlamConfig) -> PoseGraph:
    """The pose graph of a run: the first node at the first odometry pose, an
    edge per odometry step, the ``extra`` edges that skip nodes and the
    ``loops`` (anything with ``i``, ``j`` and ``relative``) as loop edges.

    With ``graph_weights = "icp"`` every registration gets the sigmas of
    :data:`ICP_EDGE_SIGMAS`, times the number of steps an edge spans: an edge
    to the scan ``k`` nodes back is measured on a smaller overlap and is less
    sure (on the default the along-track error of a ``k``-step edge grows
    from 7.5 cm at ``k = 1`` to 12, 17 and 21 cm at 2, 3 and 4).
    """
    icp_weights = config.graph_weights == "icp"
    sigmas = ICP_EDGE_SIGMAS if icp_weights else np.ones(6)
    graph = PoseGraph()
    graph.add_node(odometry.poses[0])
    for step in odometry.relative:
        graph.append(step, sigmas)
    for edge in extra:
        graph.add_odometry(edge.i, edge.j, edge.relative, sigmas * (edge.j - edge.i if icp_weights else 1))
    information = information_from_sigmas(sigmas)
    for loop in loops:
        graph.add_loop(loop.i, loop.j, loop.relative, information)
    return graph


def write_run(result: SlamResult, config: Config, out_dir, map_error=None) -> Path:
    """Write ``metrics.json``, the three TUM trajectories (one line per
    accepted scan, its dataset index as the stamp), ``map.ply`` and the
    ``config.toml`` used, all or nothing. ``map_error``: the map's distances
    to the ground-truth map (:func:`helpers.evaluation.map_errors`), if known."""
    metrics = result.metrics()
    if map_error is not None:
        metrics |= {"map_error_mean_m": map_error.mean, "map_error_median_m": map_error.median}
        metrics["map_error_p95_m"] = map_error.p95
    metrics["config"] = config_to_dict(config)
    with paths.atomic_dir(out_dir, "metrics.json") as work:
        (work / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
        for name, poses in (
            ("gt", result.poses_gt),
            ("odometry", result.poses_odometry),
            ("optimized", result.poses_optimized),
        ):
            write_tum(work / f"trajectory_{name}.txt", poses, result.indices)
        write_ply(work / "map.ply", result.map_points)
        (work / "config.toml").write_text(config_to_toml(config))
    return Path(out_dir)


def default_run(config: Config | None = None) -> tuple[Dataset, SlamResult]:
    """The dataset and the SLAM result of the embedded default, computed
    once and then read from ``data/cache`` (keyed by the configuration and
    the package's source, so any change recomputes; so does a damaged file).
    Notebooks 4 to 7 start from here instead of from hidden state; two of them
    computing it at once each write a whole file."""
    config = config or Config()
    here = Path(__file__).parent
    source = b"".join((here / f"{name}.py").read_bytes() for name in RUN_MODULES)
    key = hashlib.sha256(config_to_toml(config).encode() + source).hexdigest()[:16]
    cache = paths.cache_dir() / f"slam-{key}.pkl"
    dataset = create_dataset(sensor=config.sensor)
    try:
        with open(cache, "rb") as f:
            return dataset, pickle.load(f)
    except FileNotFoundError:
        pass
    except Exception as exc:  # a damaged pickle raises many types: it is a miss
        log.warning("cache %s is unreadable (%s): computing the run again", cache, exc)
    result = run_slam(dataset, config.slam)
    cache.parent.mkdir(parents=True, exist_ok=True)
    paths.write_atomically(cache, lambda f: pickle.dump(result, f))
    return dataset, result
