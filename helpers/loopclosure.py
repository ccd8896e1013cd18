"""Loop closure (stage 5): find old submaps near the current scan, verify them
by ICP, then turn the best scan-to-scan match into a loop edge.

:class:`LoopCloser` owns the submaps and every loop rule, in one place:
which submaps are old enough (:func:`eligible_submaps`), how far the search
reaches (:func:`search_radius`, from :func:`radius_after`), the check of the candidates
(:func:`find_loop_candidates`), the best scan (:func:`best_scan_registration`)
and the acceptance of a loop edge (:meth:`LoopCloser.accepts`). Figures,
the health report and the exercises call these rules; none re-derives one.

Frames and conventions are those of :mod:`helpers.factors`: a scan is an
(N, 3) array in its own frame, its pose ``T_map_sensor`` carries it into the
map frame, and a loop edge ``(i, j, T_i_j)`` says ``pose_j = pose_i @ T_i_j``.
Submaps and their centres are in the map frame (:mod:`helpers.submaps`).

ICP is an ``icp_fn(moving=, fixed=, T_fixed_moving=, max_iterations=) ->
(T_fixed_moving, surface_rmse)``: the run's
:class:`helpers.icp_service.IcpService`, or a stub in tests.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .config import LoopClosureConfig, MapConfig
from .errors import SlamError
from .factors import Edge
from .geometry import check_points, check_pose
from .icp_service import SURFACE_NEIGHBORS, icp_with, surface_normals, surface_rmse
from .submaps import SubmapIndex, scan_ids_of

log = logging.getLogger(__name__)

__all__ = ["SURFACE_NEIGHBORS", "LoopCloser", "LoopQuery", "icp_with", "surface_normals", "surface_rmse"]

IcpFn = Callable[..., tuple[np.ndarray, float]]


class LoopCandidates(NamedTuple):
    """Matching submaps, best (lowest RMSE) first, and what the search tried.

    ``poses[k]`` is the scan's pose ``T_map_sensor`` that ICP found against
    submap ``ids[k]``; it seeds the scan-to-scan registration.
    """

    ids: np.ndarray  # (L,) submap ids
    scores: np.ndarray  # (L,) surface RMSE, m
    poses: np.ndarray  # (L, 4, 4)
    n_eligible: int = 0  # submaps 0 .. n_eligible - 1 were old enough to be searched
    radius: np.ndarray = np.zeros(0)  # (S,) search radius (m) around each of the S submaps given, grown with the flight
    tried_ids: np.ndarray = np.zeros(0, dtype=int)  # (A,) the submaps registered by ICP, nearest first
    tried: np.ndarray = np.zeros(0)  # (A,) their surface RMSE, m (the names of LoopQuery)


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
    scores: np.ndarray  # their surface RMSE, m
    best_scan_rmse: float  # surface RMSE of the best scan-to-scan match (inf if no submap matched)
    closure: Edge | None  # the accepted loop edge, if any
    best_scan_constraint: float = float("nan")  # how well that match pins the motion (icp.pairing; nan: not measured)


class LoopCloser:
    """The submaps of a run and its loop queries, scan after scan (the
    reference's main loop after the odometry)::

        loops = LoopCloser(config.loop_closure, config.map, icp)
        query = loops.add(node, cloud, T_map_sensor, clouds, poses)  # a LoopQuery, or None

    ``clouds`` and ``poses`` are every accepted scan so far (own frames) and
    the odometry poses the submaps are built with. It reads
    ``[loop_closure]`` and ``[map]`` only; ``icp`` is the run's ICP service.
    """

    def __init__(self, settings: LoopClosureConfig, map_settings: MapConfig, icp: IcpFn) -> None:
        self.settings, self.icp = settings, icp
        self.submaps = SubmapIndex(map_settings.n_scans_per_submap, map_settings.align_grid_step)
        self.queries: list[LoopQuery] = []

    @property
    def loops(self) -> list[Edge]:
        """The accepted loop edges, in the order they were found."""
        return [q.closure for q in self.queries if q.closure is not None]

    def add(self, node: int, cloud: np.ndarray, pose: np.ndarray, clouds, poses) -> LoopQuery | None:
        """Add accepted scan ``node`` to the current submap (a new one every
        ``n_scans_per_submap`` scans) and, once there are more than
        ``sub_map_thresh`` submaps, query the old ones for a loop."""
        self.submaps.add_scan(cloud, pose)
        if len(self.submaps) <= self.settings.sub_map_thresh:
            return None
        query = self.query(node, cloud, pose, clouds, poses)
        if query is not None:
            self.queries.append(query)
        return query

    def query(self, node: int, cloud: np.ndarray, pose: np.ndarray, clouds, poses) -> LoopQuery | None:
        """One loop query of node ``node``: (1) the old submaps near its pose,
        verified by ICP; (2) the best scan of the matching submaps, kept as a
        loop edge if :meth:`accepts` it. None if no submap was registered."""
        submaps, settings = self.submaps, self.settings
        # 1. Old submaps within the (growing) search radius, verified by ICP.
        candidates = find_loop_candidates(
            submaps.points, submaps.centres, cloud, pose, len(submaps) - 1, self.icp, settings
        )
        if not len(candidates.tried_ids):
            return None
        # 2. The best scan-to-scan match of the matching submaps becomes the loop edge, if accepted.
        closure, best, pinned = None, float("inf"), float("nan")
        if len(candidates.ids):
            n = submaps.n_scans_per_submap
            match = best_scan_registration(cloud, node, candidates, clouds, poses, n, self.icp, settings)
            best = match.surface_rmse
            if match.surface_rmse < settings.rmse_threshold:
                pinned = self.icp.constraint(moving=cloud, fixed=clouds[match.i], T_fixed_moving=match.relative)
            if self.accepts(match.surface_rmse, pinned):
                log.info("loop edge %d -> %d, surface RMSE %.3f m", match.i, match.j, match.surface_rmse)
                closure = match
            elif match.surface_rmse < settings.rmse_threshold:
                log.info("loop %d -> %d left out: ground too flat (constraint %.4f)", match.i, match.j, pinned)
        return LoopQuery(
            node=node,
            n_submaps=len(submaps),
            n_eligible=candidates.n_eligible,
            radius=candidates.radius,
            tried_ids=candidates.tried_ids,
            tried=candidates.tried,
            submap_ids=candidates.ids,
            scores=candidates.scores,
            best_scan_rmse=best,
            closure=closure,
            best_scan_constraint=pinned,
        )

    def accepts(self, rmse: float, constraint: float) -> bool:
        """A best scan match is a loop edge if it fits (surface RMSE below
        ``rmse_threshold``) and pins the motion (``constraint`` at least
        ``min_constraint``; nan, not measured, passes): on flat ground any
        slide fits as well."""
        return rmse < self.settings.rmse_threshold and not constraint < self.settings.min_constraint


def eligible_submaps(n_submaps: int, settings: LoopClosureConfig) -> int:
    """How many submaps (0 .. n - 1) a query may search when ``n_submaps`` are
    built: all but the ``sub_map_thresh`` newest."""
    return max(0, n_submaps - settings.sub_map_thresh)


def radius_after(flown, settings: LoopClosureConfig):
    """The search radius (m) around a place left ``flown`` metres of flight
    ago (a number or an array): ``loop_closure_search_radius +
    loop_search_growth * flown``. Odometry drift grows with the distance
    flown, so an old place can look farther away than it is; a growth of 0
    is the reference's fixed radius."""
    return settings.loop_closure_search_radius + settings.loop_search_growth * np.asarray(flown, float)


def search_radius(submap_centres: np.ndarray, position: np.ndarray, settings: LoopClosureConfig) -> np.ndarray:
    """The search radius (m) around every submap for a scan at ``position``
    (:func:`radius_after` the distance flown since the submap,
    :func:`distance_flown_since`)."""
    return radius_after(distance_flown_since(np.asarray(submap_centres, float).reshape(-1, 3), position), settings)


def distance_flown_since(submap_centres: np.ndarray, position: np.ndarray) -> np.ndarray:
    """For every submap, the path length from its centre through the later centres to ``position``."""
    steps = np.linalg.norm(np.diff(submap_centres, axis=0), axis=1)
    to_end = np.concatenate([np.cumsum(steps[::-1])[::-1], [0.0]])
    return to_end + np.linalg.norm(position - submap_centres[-1])


def find_loop_candidates(
    submaps: Sequence[np.ndarray],
    submap_centres: np.ndarray,
    scan_points: np.ndarray,
    scan_pose: np.ndarray,
    current_submap_id: int,
    icp_fn: IcpFn,
    settings: LoopClosureConfig,
) -> LoopCandidates:
    """Old submaps that the current scan registers onto, as the reference helper does.

    1. Only submaps ``0 .. current_submap_id - sub_map_thresh`` are eligible
       (``current_submap_id`` is the newest built submap; the ``sub_map_thresh``
       newest are skipped).
    2. Keep those whose centre is nearer than :func:`search_radius` to the
       scan's position.
    3. Sort them by distance and register the scan to at most ``max_attempts``
       of them, from ``scan_pose``.
    4. Keep those with RMSE below ``loop_closure_threshold`` and return at most
       ``max_returned``, lowest RMSE first.

    The names in quotes are the fields of ``settings``.
    """
    centres = np.asarray(submap_centres, dtype=float).reshape(-1, 3)
    scan_points = check_points(scan_points, "the current scan")
    scan_pose = check_pose(scan_pose, "the current scan pose")
    _check_search(submaps, centres, current_submap_id)
    max_attempts = settings.max_attempts

    # 1.-2. eligible submaps within the (growing) radius, nearest first
    position = scan_pose[:3, 3]
    eligible = centres[: eligible_submaps(current_submap_id + 1, settings)]
    distance = np.linalg.norm(eligible - position, axis=1)
    radius = search_radius(centres[: current_submap_id + 1], position, settings)
    near = np.flatnonzero(distance < radius[: len(eligible)])
    near = near[np.argsort(distance[near], kind="stable")]

    # 3. verify the nearest few by ICP
    found, tried = [], []
    for submap_id in near[:max_attempts]:
        pose, rmse = icp_fn(
            moving=scan_points,
            fixed=submaps[submap_id],
            T_fixed_moving=scan_pose,
            max_iterations=settings.icp_max_iterations,
        )
        log.debug("submap %d at %.1f m: surface RMSE %.3f m", submap_id, distance[submap_id], rmse)
        tried.append(rmse)
        if rmse < settings.loop_closure_threshold:
            found.append((float(rmse), int(submap_id), check_pose(pose, "the ICP result")))

    # 4. best first
    found.sort(key=lambda item: item[0])
    found = found[: settings.max_returned]
    return LoopCandidates(
        np.array([f[1] for f in found], dtype=int),
        np.array([f[0] for f in found], dtype=float),
        np.array([f[2] for f in found], dtype=float).reshape(-1, 4, 4),
        n_eligible=len(eligible),
        radius=radius,
        tried_ids=near[:max_attempts].astype(int),
        tried=np.array(tried, dtype=float),
    )


def best_scan_registration(
    scan_points: np.ndarray,
    current_id: int,
    candidates: LoopCandidates,
    scans: Sequence[np.ndarray],
    poses: np.ndarray,
    n_scans_per_submap: int,
    icp_fn: IcpFn,
    settings: LoopClosureConfig | None = None,
) -> Edge | None:
    """The lowest-RMSE registration of the current scan onto a scan of the
    matching submaps, whatever its RMSE (None if there is no candidate).

    ``scans`` and ``poses`` are all accepted scans (own frames) and the pose
    estimates the submaps were built with. The registration onto scan ``i``
    starts from ``inv(poses[i]) @ candidates.poses[k]``, the scan's pose found
    against its submap, seen from scan ``i``, with the ICP iteration cap of
    ``settings`` (the icp_fn's own when None).
    """
    cap = None if settings is None else settings.icp_max_iterations
    scan_points = check_points(scan_points, "the current scan")
    poses = np.asarray(poses, dtype=float)
    best = None
    for submap_id, submap_pose in zip(candidates.ids, candidates.poses, strict=True):
        for i in scan_ids_of(int(submap_id), n_scans_per_submap):
            if not 0 <= i < min(len(scans), len(poses)):
                raise SlamError(f"submap {submap_id} holds scan {i}, but only {len(scans)} scans were given")
            init = np.linalg.inv(check_pose(poses[i], f"the pose of scan {i}")) @ submap_pose
            fit = icp_fn(moving=scan_points, fixed=scans[i], T_fixed_moving=init, max_iterations=cap)
            (T_i_j, rmse), information = fit, getattr(fit, "information", None)
            if best is None or rmse < best.surface_rmse:
                best = Edge(i, int(current_id), check_pose(T_i_j, "the ICP result"), float(rmse), information)
    return best


def _check_search(submaps, centres, current_submap_id) -> None:
    if not np.all(np.isfinite(centres)):
        raise SlamError("the submap centres contain NaN or infinite values")
    if not 0 <= current_submap_id < min(len(centres), len(submaps)):
        raise SlamError(
            f"current_submap_id {current_submap_id} is not among the {min(len(centres), len(submaps))} submaps given"
        )
