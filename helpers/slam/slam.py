"""The reference's main loop as an object that takes one scan at a time.

:class:`Slam` runs each accepted scan through the stages in turn: the
odometry registers it onto the previous accepted scan, the loop closer adds
it to the current submap and queries the old submaps for a loop, and the
scan is registered to the few scans before it (edges back,
:class:`helpers.slam.edges_back.EdgesBack`). Every stage
works on the same downsampled scan, made ready for ICP once by the run's
one :class:`helpers.slam.registration.icp_service.IcpService`. :meth:`Slam.result` then
optimises the pose graph and rebuilds the map::

    slam = Slam(config, anchor=data.poses[0])
    for index, scan in enumerate(data.scans):
        step = slam.process(scan, index)  # prints in one line
    result = slam.result()

Accepted scans are the pose-graph nodes, numbered 0, 1, 2, ...;
``result.indices[k]`` is the dataset index of node ``k``.
"""

from __future__ import annotations

import logging
import time
from concurrent.futures import Future
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.geometry import check_points, check_pose
from helpers.slam.deskew import deskew, normalised, per_period
from helpers.slam.edges_back import BackgroundEdges, EdgesBack
from helpers.slam.graph.build import build_pose_graph
from helpers.slam.graph.factors import Edge, gnss_factors
from helpers.slam.graph.optimizer import OptimizationResult
from helpers.slam.loops.closer import LoopCloser, LoopQuery
from helpers.slam.loops.places import PlaceRecognition
from helpers.slam.odometry import Odometry, OdometryResult
from helpers.slam.preprocess import empty_first_scan, prepare_scan
from helpers.slam.registration.features import grid_average
from helpers.slam.registration.icp_service import IcpService
from helpers.slam.submaps import SubmapIndex, build_submap
from helpers.threads import one_blas_thread

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Step:
    """What :meth:`Slam.process` did with one scan."""

    index: int  # dataset index of the scan
    accepted: bool  # False: skipped (``skip_frames``), nothing else happened
    node: int | None = None  # its pose-graph node
    T_map_sensor: np.ndarray | None = None  # its odometry pose
    fallback: str | None = None  # why the odometry fell back, if it did
    query: LoopQuery | None = None  # its loop query, if one registered a submap
    edges_back: tuple[Edge, ...] = ()  # the edges back kept

    @property
    def loop(self) -> Edge | None:
        """The loop edge this scan closed, if any."""
        return None if self.query is None else self.query.closure

    def __repr__(self) -> str:
        if not self.accepted:
            return f"Step(scan {self.index}: skipped)"
        x, y, z = self.T_map_sensor[:3, 3]
        loop = f"loop {self.loop.i}-{self.loop.j} ({self.loop.surface_rmse:.2f} m)" if self.loop else "no loop"
        fallback = ", fell back" if self.fallback else ""
        back = f"{len(self.edges_back)} edge{'' if len(self.edges_back) == 1 else 's'} back"
        return f"Step(scan {self.index} -> node {self.node} at ({x:.1f}, {y:.1f}, {z:.1f}) m{fallback}, {back}, {loop})"


@dataclass
class SlamResult:
    """What a run estimated; :mod:`helpers.quality.evaluation` grades it against the ground truth."""

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
    gnss_factors: list = field(
        default_factory=list
    )  # GNSS fixes in the graph (helpers.slam.graph.factors.PositionFactor)
    empty_scans: list = field(default_factory=list)  # scans that held no point, left out (the next spans them)

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


class Slam:
    """The main loop, one scan at a time (see the module's docstring).

    ``anchor`` (``T_map_sensor``, 4 x 4) is the first accepted scan's pose
    (identity when None). ``odometry``: an odometry already computed for
    these scans with this configuration; the run then reuses its poses and
    registers nothing scan to scan (a back end for tests and notebooks).
    ``gnss``: position fixes (:class:`helpers.sim.gnss.GnssFixes`) added to the pose graph, and to the
    loop search's graph as the scans arrive (it then searches where the fixes put the flight).
    ``background``: register the edges back in a helper process, one node behind
    (:mod:`helpers.slam.edges_back`: the same edges, sooner); a :class:`Step` then
    carries the edges back of the node before it.
    """

    def __init__(
        self,
        config: Config | None = None,
        anchor=None,
        odometry: OdometryResult | None = None,
        gnss=None,
        background: bool = False,
    ) -> None:
        self.config = config = config or Config()
        anchor = np.eye(4) if anchor is None else anchor
        self.anchor = check_pose(np.asarray(anchor, dtype=float), "the anchor pose")
        self.icp = IcpService.from_config(config.registration, pose_graph=config.pose_graph)
        self.odometry = Odometry(config, self.anchor, self.icp)
        self.given, self.gnss = odometry, gnss
        self._fix_rows = {} if gnss is None else {int(index): r for r, index in enumerate(gnss.indices)}
        self.places = PlaceRecognition(config) if config.loop_closure.place_recognition else None
        self.loops = LoopCloser(config.loop_closure, config.map, self.icp, config.pose_graph, self.places)
        self.edges_back = EdgesBack.from_config(self.icp, config.pose_graph)
        if background and config.pose_graph.edges_back > 1:
            self.edges_back = BackgroundEdges(self.edges_back, config)
        self._background = isinstance(self.edges_back, BackgroundEdges)
        self._given_fallbacks = set() if odometry is None else {int(i) for i, _ in odometry.fallbacks}
        self.clouds: list[np.ndarray] = []
        self.indices: list[int] = []
        self._starts: list[float] = []  # the first point's time of the last two accepted scans with times
        self.runtime = dict.fromkeys(("odometry", "submaps_and_loop_closure", "edges_back"), 0.0)
        self.empty: list[int] = []  # scans that held no point, left out

    def accepts(self, index: int) -> bool:
        """Whether scan ``index`` becomes a node: every ``skip_frames``-th (or the given odometry's)."""
        if self.given is not None:
            return len(self.indices) < len(self.given.indices) and index == self.given.indices[len(self.indices)]
        return index % self.config.registration.skip_frames == 0

    def process(self, scan: np.ndarray | None, index: int, prepared: Future | None = None, times=None) -> Step:
        """Take scan ``index`` of the flight (sensor frame, (N, 3)), in order.

        ``prepared``: the future of :func:`~helpers.slam.preprocess.prepare_scan` on this scan with
        this configuration, computed in another thread meanwhile (as
        :func:`helpers.slam.pipeline.run_slam` does for the next scan); ``scan`` is
        then not read, and may be None. Only without a given odometry. ``times``: the scan's per-point times
        (N,): it is deskewed with the odometry's last motion first (:mod:`helpers.slam.deskew`)."""
        if times is not None and scan is not None and self.accepts(index):
            scan = self._deskewed(scan, times)
        with one_blas_thread():  # OpenBLAS's idle threads would spin on the core FPFH and ICP use (helpers.threads)
            return self._process(scan, index, prepared)

    def _deskewed(self, scan: np.ndarray, times) -> np.ndarray:
        """``scan`` deskewed with the odometry's last step at a constant velocity; as it is until the odometry
        has measured a step (and with a given odometry, which registers nothing).

        The motion over the scan's own span is the last step's share of it: the span over the time the last
        step took, when the times run on one clock across scans (LAS ``gps_time``, the simulator's flight
        clock: a scan of 0.1 s taken every 0.2 s moved half a step while it was taken); when each scan's
        times start again from zero, the scans are taken one after the other and a step of ``skip_frames``
        scans spans that many of them."""
        times = np.asarray(times, dtype=np.float64)
        before = self._starts
        self._starts = [*before[-1:], float(times.min())] if len(times) else before
        if self.given is not None or not self.odometry.relative:
            return scan
        interval = before[-1] - before[-2] if len(before) == 2 else 0.0  # the last step's, on the scans' clock
        span = float(np.ptp(times)) if len(times) else 0.0
        periods = interval / span if interval > 0 and span > 0 else self.config.registration.skip_frames
        return deskew(scan, normalised(times), per_period(self.odometry.relative[-1], periods))

    def _process(self, scan: np.ndarray | None, index: int, prepared: Future | None) -> Step:
        if self.indices and index <= self.indices[-1]:
            raise SlamError(f"scan {index} comes after scan {self.indices[-1]}: scans must arrive in order")
        if not self.accepts(index):
            return Step(index, accepted=False)
        node = len(self.indices)
        # 1. Odometry: register the scan onto the previous accepted one (prepared once, for every stage).
        with self._timed("odometry"):
            frame = None  # with a given odometry nothing is registered, and no scan prepared
            if self.given is None:
                frame = prepared.result() if prepared is not None else prepare_scan(scan, index, self.config)
                if frame is None:  # a scan that holds no point: left out, the next step spans it
                    return self._left_out(index)
            frame, cloud, fallback, information = self._register(scan, index, frame)
            self.clouds.append(cloud)
            self.indices.append(int(index))
        poses, relative = self._trajectory()
        # The node before's edges back, registered meanwhile in the helper process, join the loop search's graph.
        with self._timed("edges_back"):
            collected = self._collect_edges_back()
        # 2. Submap and loop query, on the odometry poses (the search looks where the GNSS fixes, if any, put
        # them; after a blind stretch it also recognises places by their descriptors).
        with self._timed("submaps_and_loop_closure"):
            self._follow_places(node, scan, index, frame, fallback)
            query = self.loops.add(node, cloud, poses[node], self.clouds, poses, information, self._fix(index))
        # 3. Edges back to the few scans before, from the chained odometry.
        with self._timed("edges_back"):
            edges = self._add_edges_back(node, relative)
        return Step(index, True, node, poses[node], fallback, query, tuple(collected if self._background else edges))

    def _left_out(self, index: int) -> Step:
        """Scan ``index`` held no point: recorded, and the odometry's next step spans it (its guess the last
        motion for each scan left out); the first scan anchors the flight, and must hold points."""
        if not self.indices:
            raise empty_first_scan(index)
        self.empty.append(int(index))
        log.warning("scan %d holds no point: left out, the next step spans it", index)
        return Step(index, accepted=False)

    def _register(self, scan, index: int, frame):
        """The odometry step: ``(frame, cloud, fallback, information)`` of ``frame``, the scan prepared
        (:func:`prepare_scan`). With a given odometry nothing is registered: the scan is only downsampled on the
        ICP grid (``frame``, ``fallback`` and ``information`` are then None)."""
        if self.given is not None:
            return None, grid_average(check_points(scan, f"scan {index}"), self.config.icp_grid), None, None
        pair = self.odometry.register(frame, index)
        self.icp.keep(frame.icp_points, frame.icp)
        if pair is None:
            return frame, frame.icp_points, None, None
        return frame, frame.icp_points, pair.fallback, pair.information

    def _trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """The odometry's poses and steps so far (the given odometry's, whole, when there is one)."""
        source = self.given if self.given is not None else self.odometry
        return source.poses, source.relative

    def _collect_edges_back(self) -> list[Edge]:
        if not self._background:
            return []
        edges = self.edges_back.collect()
        self.loops.add_edges(edges)
        return edges

    def _follow_places(self, node: int, scan, index: int, frame, fallback: str | None) -> None:
        """Hand the scan to place recognition (with a given odometry, its frame is prepared only if asked)."""
        if self.places is None:
            return
        if self.given is not None:
            config = self.config
            self.places.follow(node, lambda: prepare_scan(scan, index, config), index in self._given_fallbacks)
        else:
            self.places.follow(node, frame, fallback is not None)

    def _fix(self, index: int):
        """The GNSS fix of scan ``index`` as ``(position, sigmas)``, or None."""
        row = self._fix_rows.get(int(index))
        return None if row is None else (self.gnss.positions[row], self.gnss.sigmas)

    def _add_edges_back(self, node: int, relative: np.ndarray) -> list[Edge]:
        if self._background:
            self.edges_back.submit(node, self.clouds, relative)
            return []
        edges = self.edges_back.add(node, self.clouds, relative)
        self.loops.add_edges(edges)  # the loop search's uncertainty graph
        return edges

    @contextmanager
    def _timed(self, stage: str):
        start = time.perf_counter()
        try:
            yield
        finally:
            self.runtime[stage] += time.perf_counter() - start

    def result(self, n_scans: int | None = None) -> SlamResult:
        """Optimise the pose graph and rebuild the map at the optimised poses.
        ``n_scans``: the flight's scans, accepted or not (by default up to the last one processed)."""
        if len(self.indices) < 2:
            raise SlamError(f"SLAM needs at least 2 accepted scans, got {len(self.indices)}")
        if self._background:  # the last node's edges back, then the process stops
            start = time.perf_counter()
            self.loops.add_edges(self.edges_back.collect())
            self.edges_back.close()
            self.runtime["edges_back"] += time.perf_counter() - start
        config, runtime = self.config, dict(self.runtime)
        odometry = self.given if self.given is not None else self.odometry.result()
        # 4. Pose graph: odometry edges, edges to older scans, loop edges, the first node anchored.
        start = time.perf_counter()
        extra = self.edges_back.sorted()
        graph = build_pose_graph(odometry, extra, self.loops.loops, config)
        fixes = gnss_factors(self.gnss, self.indices) if self.gnss is not None else []
        for fix in fixes:
            graph.add_factor(fix)
        optimized = graph.optimize(anchor_pose=self.anchor, loop_kernel=config.pose_graph.loop_kernel)
        runtime["pose_graph"] = time.perf_counter() - start
        # 5. The map: every accepted scan at its optimised pose, merged on a grid.
        start = time.perf_counter()
        map_points = build_submap(self.clouds, optimized.poses, config.map.align_grid_step)
        runtime["map"] = time.perf_counter() - start
        return SlamResult(
            config=config,
            indices=np.array(self.indices, dtype=np.int64),
            odometry=odometry,
            clouds=list(self.clouds),
            submaps=self.loops.submaps,
            queries=list(self.loops.queries),
            graph=optimized,
            extra_edges=extra,
            map_points=map_points,
            n_scans=self.indices[-1] + 1 if n_scans is None else n_scans,
            runtime_s=runtime,
            edges_back_tried=self.edges_back.tried,
            gnss_factors=list(fixes),
            empty_scans=list(self.empty),
        )
