"""The whole SLAM pipeline, stage after stage, as the reference's main loop:
odometry over the accepted scans, submaps, loop-closure queries, the pose
graph, and the map rebuilt at the optimised poses.

Accepted scans are the pose-graph nodes, numbered 0, 1, 2, ...;
``result.indices[k]`` is the dataset index of node ``k``.
"""

from __future__ import annotations

import hashlib
import logging
import pickle
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import paths
from .config import Config
from .configfile import config_to_toml
from .dataset import Dataset, create_dataset
from .features import grid_average
from .loopclosure import best_scan_registration, find_loop_candidates, icp_with
from .odometry import OdometryResult, run_odometry
from .posegraph import OptimizationResult, PoseGraph, information_from_sigmas
from .progress import progress_bar
from .submaps import SubmapIndex, build_submap

log = logging.getLogger(__name__)

PICTURE_PACKAGES = ("viz", "site", "exercises")  # subpackages that draw, publish or check, never change a run's numbers


@dataclass(frozen=True)
class Edge:
    """A registration ``pose_j = pose_i @ relative`` between two nodes."""

    i: int
    j: int
    relative: np.ndarray
    rmse: float  # m, surface RMSE of the registration


@dataclass(frozen=True)
class LoopQuery:
    """One loop-candidate query that registered at least one old submap: what
    it searched, what it tried and what it kept (figures read these)."""

    node: int
    n_submaps: int  # submaps built when the query ran (centres in ``SlamResult.submaps.centres``)
    n_eligible: int  # submaps 0 .. n_eligible - 1 were old enough to be searched
    radius: np.ndarray  # (n_submaps,) search radius (m) around each submap, grown with the distance flown since it
    tried_ids: np.ndarray  # the submaps registered by ICP, nearest first
    tried: np.ndarray  # their surface RMSE (m), in the same order
    submap_ids: np.ndarray  # the submaps below loop_closure_threshold, best first
    scores: np.ndarray  # their RMSE, m
    best_scan_rmse: float  # RMSE of the best scan-to-scan match (inf if no submap matched)
    closure: Edge | None  # the accepted loop edge, if any
    best_scan_constraint: float = float("nan")  # how well that match pins the motion (icp.pairing; nan: not measured)


@dataclass
class SlamResult:
    """What a run estimated; :mod:`helpers.evaluation` grades it against the ground truth."""

    config: Config
    indices: np.ndarray  # (K,) dataset index of each node
    odometry: OdometryResult
    clouds: list[np.ndarray]  # (N_k, 3) downsampled scans, sensor frame
    submaps: SubmapIndex
    queries: list[LoopQuery]
    graph: OptimizationResult
    extra_edges: list[Edge]  # odometry edges that skip nodes (see ``[pose_graph] edges_back``)
    map_points: np.ndarray  # (M, 3) global map at the optimised poses
    n_scans: int  # scans in the dataset, accepted or not
    runtime_s: dict = field(default_factory=dict)
    edges_back_tried: int = 0  # registrations to older scans attempted (``extra_edges`` holds those kept)

    @property
    def loops(self) -> list[Edge]:
        """The accepted loop edges, in the order they were found."""
        return [q.closure for q in self.queries if q.closure is not None]

    @property
    def poses_odometry(self) -> np.ndarray:
        return self.odometry.poses

    @property
    def poses_optimized(self) -> np.ndarray:
        return self.graph.poses


def run_slam(dataset: Dataset, config: Config | None = None, progress: bool = False) -> SlamResult:
    """Estimate the trajectory and the map from ``dataset.scans`` alone (the
    first ground-truth pose anchors the first node, as in the reference; no
    other true pose is read: :mod:`helpers.evaluation` grades the result)."""
    config = config or Config()
    runtime = {}
    anchor = dataset.poses[0]

    # 1. Odometry: register every accepted scan to the previous one.
    start = time.perf_counter()
    odometry = run_odometry(dataset.scans, anchor, config, progress=progress)
    runtime["odometry"] = time.perf_counter() - start

    # 2.-3. Submaps and loop-closure queries, scan after scan, on the odometry
    #       poses. ICP works on the same finer clouds as in the odometry.
    start = time.perf_counter()
    step = config.registration.icp_grid_step or config.features.grid_step
    clouds = [grid_average(dataset.scans[i], step) for i in odometry.indices]
    icp = _loop_icp(config)  # one for the loops and the edges back: each cloud is made ready for ICP once
    submaps, queries = submaps_and_loops(clouds, odometry.poses, config, icp, progress)
    runtime["submaps_and_loop_closure"] = time.perf_counter() - start

    # 4. Pose graph: odometry edges, edges to older scans, loop edges, the
    #    first node anchored.
    start = time.perf_counter()
    extra, tried = _edges_back(clouds, odometry.relative, config, icp)
    runtime["edges_back"] = time.perf_counter() - start
    start = time.perf_counter()
    graph = build_pose_graph(odometry, extra, [q.closure for q in queries if q.closure], config)
    optimized = graph.optimize(anchor_pose=anchor, loop_kernel=config.pose_graph.loop_kernel)
    runtime["pose_graph"] = time.perf_counter() - start

    # 5. The map: every accepted scan at its optimised pose, merged on a grid.
    start = time.perf_counter()
    map_points = build_submap(clouds, optimized.poses, config.map.align_grid_step)
    runtime["map"] = time.perf_counter() - start

    return SlamResult(
        config=config,
        indices=odometry.indices,
        odometry=odometry,
        clouds=clouds,
        submaps=submaps,
        queries=queries,
        graph=optimized,
        extra_edges=extra,
        map_points=map_points,
        n_scans=len(dataset),
        runtime_s=runtime,
        edges_back_tried=tried,
    )


def submaps_and_loops(clouds, poses, config: Config, icp, progress: bool = False):
    """The reference's main loop over the accepted scans (own frames, at their
    odometry ``poses``): add the scan to the current submap (a new one every
    ``n_scans_per_submap`` scans) and, once there are more than
    ``sub_map_thresh`` submaps, query the old ones for a loop.
    ``icp`` is an ``icp_fn`` of :func:`helpers.loopclosure.icp_with`.
    Returns the submaps and the queries that registered something."""
    submaps = SubmapIndex(config.map.n_scans_per_submap, config.map.align_grid_step)
    queries: list[LoopQuery] = []
    bar = progress_bar(len(clouds), "submaps and loops", enabled=progress)
    for node, (cloud, pose) in enumerate(zip(clouds, poses, strict=True)):
        submaps.add_scan(cloud, pose)
        if len(submaps) > config.loop_closure.sub_map_thresh:
            query = loop_query(node, cloud, pose, submaps, clouds, poses, icp, config)
            if query is not None:
                queries.append(query)
        bar.set_postfix(loops=sum(q.closure is not None for q in queries), refresh=False)
        bar.update(1)
    bar.close()
    return submaps, queries


def loop_query(node: int, cloud, pose, submaps: SubmapIndex, clouds, poses, icp, config: Config):
    """One loop query of node ``node``: (1) the old submaps near its pose,
    verified by ICP; (2) the best scan of the matching submaps, kept as a loop
    edge if its RMSE is below ``rmse_threshold`` and it pins the motion
    (constraint at least ``min_constraint``). None if no submap was registered."""
    loops = config.loop_closure
    # 1. Old submaps within the (growing) search radius, verified by ICP.
    candidates = find_loop_candidates(
        submaps.points,
        submaps.centres,
        cloud,
        pose,
        current_submap_id=len(submaps) - 1,
        icp_fn=icp,
        settings=loops,
    )
    if not len(candidates.tried_ids):
        return None

    # 2. The best scan-to-scan match of the matching submaps becomes the loop edge,
    #    if it fits and pins the motion: on flat ground any slide fits as well.
    closure, best, pinned = None, float("inf"), float("nan")
    if len(candidates.ids):
        match = best_scan_registration(cloud, node, candidates, clouds, poses, config.map.n_scans_per_submap, icp)
        best = match.rmse
        if match.rmse < loops.rmse_threshold:
            pinned = icp.constraint(cloud, clouds[match.i], match.relative_pose)
            if not pinned < loops.min_constraint:  # nan (not measured) passes
                log.info("loop edge %d -> %d, ICP RMSE %.3f m", match.i, match.j, match.rmse)
                closure = Edge(match.i, match.j, match.relative_pose, match.rmse)
            else:
                log.info("loop %d -> %d left out: ground too flat (constraint %.4f)", match.i, match.j, pinned)
    return LoopQuery(
        node=node,
        n_submaps=len(submaps),
        n_eligible=candidates.n_eligible,
        radius=candidates.radius,
        tried_ids=candidates.tried_ids,
        tried=candidates.tried_rmse,
        submap_ids=candidates.ids,
        scores=candidates.scores,
        best_scan_rmse=best,
        closure=closure,
        best_scan_constraint=pinned,
    )


def _loop_icp(config: Config):
    """The ICP of loop checks and edges back: the odometry's metric and
    inlier distance, the loop closure's iteration cap, scored by surface RMSE."""
    fit = config.registration
    return icp_with(
        fit.metric, fit.inlier_distance, config.loop_closure.icp_max_iterations, fit.icp_tolerance, fit.icp_backend
    )


def _edges_back(clouds, relative: np.ndarray, config: Config, icp) -> tuple[list[Edge], int]:
    """Register every node to the nodes 2 .. ``edges_back`` before it, from
    the chained odometry as the initial guess. Each extra edge measures the
    motion again with other points, so the pose graph can average the
    odometry's random errors instead of summing them. Registrations scored
    above ``rmse_threshold`` are left out.

    ICP starts close and stops after ``edges_back_icp_max_iterations``: on
    the default flight one edge in six never meets the tolerance but
    oscillates by millimetres until any cap, and 15 iterations give the same
    trajectory as 50 in two thirds of the time. Node after node, so that the
    clouds ``icp`` keeps ready are the recent ones; edges are returned
    ordered by span, then by node, with the number of registrations tried."""
    edges, tried = [], 0
    for j in range(2, len(clouds)):
        for back in range(2, min(config.pose_graph.edges_back, j) + 1):
            guess = np.linalg.multi_dot([np.eye(4), *relative[j - back : j]])
            transform, rmse = icp(clouds[j], clouds[j - back], guess, config.pose_graph.edges_back_icp_max_iterations)
            tried += 1
            if rmse < config.loop_closure.rmse_threshold:
                edges.append(Edge(j - back, j, transform, rmse))
            else:
                log.info("edge %d -> %d left out: surface RMSE %.2f m", j - back, j, rmse)
    return sorted(edges, key=lambda e: (e.j - e.i, e.j)), tried


def build_pose_graph(odometry: OdometryResult, extra: list[Edge], loops, config: Config) -> PoseGraph:
    """The pose graph of a run: the first node at the first odometry pose, an
    edge per odometry step, the ``extra`` edges that skip nodes and the
    ``loops`` (anything with ``i``, ``j`` and ``relative``) as loop edges.

    With ``graph_weights = "icp"`` every registration gets the sigmas of
    ``[pose_graph] edge_sigma_m`` and ``edge_sigma_deg``, times the number of
    steps an edge spans: an edge to the scan ``k`` nodes back is measured on a
    smaller overlap and is less sure (notebook 6 measures how much).
    """
    icp_weights = config.pose_graph.graph_weights == "icp"
    sigmas = config.pose_graph.edge_sigmas if icp_weights else np.ones(6)
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


def core_fingerprint() -> bytes:
    """The SLAM core's files (every file of the package outside
    :data:`PICTURE_PACKAGES`: code and the shipped flight), names and contents,
    in a fixed order: what decides a run's numbers."""
    root = Path(__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*")):
        relative = path.relative_to(root)
        if path.is_file() and relative.parts[0] not in PICTURE_PACKAGES and "__pycache__" not in relative.parts:
            digest.update(relative.as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.digest()


def default_run(config: Config | None = None) -> tuple[Dataset, SlamResult]:
    """The dataset and the SLAM result of the embedded default, computed
    once and then read from :func:`helpers.paths.cache_dir` (keyed by the
    configuration and the core package's files, so any change recomputes; so
    does a damaged file). Notebooks 4 to 7 start from here instead of from
    hidden state; two of them computing it at once each write a whole file."""
    config = config or Config()
    key = hashlib.sha256(config_to_toml(config).encode() + core_fingerprint()).hexdigest()[:16]
    cache = paths.cache_dir() / f"slam-{key}.pkl"
    dataset = create_dataset(sensor=config.sensor)
    try:
        with open(cache, "rb") as f:
            return dataset, pickle.load(f)
    except FileNotFoundError:
        pass
    except Exception as exc:  # a damaged pickle raises many types: it is a miss
        log.warning("cache %s is unreadable (%s): computing the run again", cache, exc)
    result = run_slam(dataset, config)
    cache.parent.mkdir(parents=True, exist_ok=True)
    paths.write_atomically(cache, lambda f: pickle.dump(result, f))
    return dataset, result
