"""Loop closure (stage 5): find old submaps near the current scan, verify them
by ICP, then turn the best scan-to-scan match into a loop edge.

:class:`LoopCloser` owns the submaps and every loop rule, in one place:
which submaps are old enough (:func:`eligible_submaps`), how far the search
reaches (``[loop_closure] search``: ``"growth"``, :func:`search_radius` from
:func:`radius_after`; ``"uncertainty"``, the graph's relative covariance and
:func:`mahalanobis_gate`), which places were closed just
before (``skip_after_loop``), the check of the candidates
(:func:`find_loop_candidates`), the best scan (:func:`best_scan_registration`),
registered again on the part of it over the old scan (:func:`~helpers.slam.on_overlap`, ``overlap_rounds``),
and the acceptance of a loop edge (:meth:`LoopCloser.accepts`). After a
blind stretch it also asks :mod:`helpers.slam.loops.places` which old places the
scan's descriptors recognise, wherever the odometry puts the flight. Figures,
the health report and the exercises call these rules; none re-derives one.

Frames and conventions are those of :mod:`helpers.slam.graph.factors`: a scan is an
(N, 3) array in its own frame, its pose ``T_map_sensor`` carries it into the
map frame, and a loop edge ``(i, j, T_i_j)`` says ``pose_j = pose_i @ T_i_j``.
Submaps and their centres are in the map frame (:mod:`helpers.slam.submaps`).

ICP is an ``icp_fn(moving=, fixed=, T_fixed_moving=, max_iterations=) ->
(T_fixed_moving, surface_rmse)``: the run's
:class:`helpers.slam.registration.icp_service.IcpService`, or a stub in tests.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from helpers.config.tables import LoopClosureConfig, MapConfig, PoseGraphConfig
from helpers.errors import SlamError
from helpers.slam.graph.factors import Edge
from helpers.slam.loops.best_scan import best_scan_registration
from helpers.slam.loops.search import (
    IcpFn,
    LoopCandidates,
    closed_places,
    distance_flown_since,
    eligible_submaps,
    find_loop_candidates,
    mahalanobis_gate,
    radius_after,
    search_radius,
    verified,
)
from helpers.slam.loops.uncertainty import RelativeUncertainty
from helpers.slam.registration.icp_service import SURFACE_NEIGHBORS, icp_with, surface_normals, surface_rmse
from helpers.slam.registration.overlap import on_overlap
from helpers.slam.submaps import SubmapIndex, centre_scan_id

log = logging.getLogger(__name__)

__all__ = [
    "SURFACE_NEIGHBORS",
    "LoopCandidates",
    "LoopCloser",
    "LoopQuery",
    "best_scan_registration",
    "distance_flown_since",
    "eligible_submaps",
    "find_loop_candidates",
    "icp_with",
    "radius_after",
    "search_radius",
    "surface_normals",
    "surface_rmse",
]


@dataclass(frozen=True)
class LoopQuery:
    """One loop-candidate query that registered at least one old submap: what
    it searched, what it tried and what it kept (figures read these)."""

    node: int
    n_submaps: int  # submaps built when the query ran (centres in ``SlamResult.submaps.centres``)
    n_eligible: int  # submaps 0 .. n_eligible - 1 were old enough to be searched
    radius: np.ndarray  # (n_submaps,) search radius (m) around each submap (its growth, or from the uncertainty)
    tried_ids: np.ndarray  # the submaps registered by ICP, nearest first
    tried: np.ndarray  # their surface RMSE (m), in the same order
    submap_ids: np.ndarray  # the submaps below loop_closure_threshold, best first
    scores: np.ndarray  # their surface RMSE, m
    best_scan_rmse: float  # surface RMSE of the best scan-to-scan match (inf if no submap matched)
    closure: Edge | None  # the accepted loop edge, if any
    best_scan_constraint: float = float("nan")  # how well that match pins the motion (icp.pairing; nan: not measured)
    fallback: str = ""  # "grown radius": the graph could not give the gate; "recognised": by the descriptors


class LoopCloser:
    """The submaps of a run and its loop queries, scan after scan (the
    reference's main loop after the odometry)::

        loops = LoopCloser(config.loop_closure, config.map, icp)
        query = loops.add(node, cloud, T_map_sensor, clouds, poses)  # a LoopQuery, or None

    ``clouds`` and ``poses`` are every accepted scan so far (own frames) and
    the odometry poses the submaps are built with. It reads
    ``[loop_closure]`` and ``[map]``; ``icp`` is the run's ICP service. With
    ``search = "uncertainty"`` it keeps the run's graph
    (:class:`helpers.slam.loops.uncertainty.RelativeUncertainty`, the edges' noise from
    ``graph_settings``): the odometry steps from ``poses``, its own loop
    edges, and the edges back the run hands to :meth:`add_edges`. ``places``: the run's
    :class:`helpers.slam.loops.places.PlaceRecognition` (None: no place is recognised), which the run tells of each
    scan and of the steps that fell back.
    """

    def __init__(
        self,
        settings: LoopClosureConfig,
        map_settings: MapConfig,
        icp: IcpFn,
        graph_settings: PoseGraphConfig | None = None,
        places=None,
    ) -> None:
        self.settings, self.icp, self.places = settings, icp, places
        self.submaps = SubmapIndex(map_settings.n_scans_per_submap, map_settings.align_grid_step)
        self.queries: list[LoopQuery] = []
        searched = settings.search == "uncertainty"
        self.uncertainty = RelativeUncertainty(graph_settings or PoseGraphConfig()) if searched else None
        self.skipped = 0  # queries left out: a loop had just closed on the same place

    @property
    def loops(self) -> list[Edge]:
        """The accepted loop edges, in the order they were found."""
        return [q.closure for q in self.queries if q.closure is not None]

    def add(self, node: int, cloud: np.ndarray, pose: np.ndarray, clouds, poses, information=None, fix=None):
        """Add accepted scan ``node`` to the current submap (a new one every
        ``n_scans_per_submap`` scans) and, once there are more than
        ``sub_map_thresh`` submaps, query the old ones for a loop (a
        :class:`LoopQuery`, or None). ``information``: that of the odometry
        step to ``node``, for the uncertainty graph (None: the fixed sigmas);
        ``fix``: the node's GNSS fix, (position, x y z sigmas), for it too: the search then looks where
        the fixes put the flight (:meth:`helpers.slam.loops.uncertainty.RelativeUncertainty.add_fix`)."""
        self.submaps.add_scan(cloud, pose)
        self._follow(node, poses, information)
        if fix is not None and self.uncertainty is not None:
            self.uncertainty.add_fix(node, *fix)
        if len(self.submaps) <= self.settings.sub_map_thresh:
            return None
        query = self.query(node, cloud, pose, clouds, poses)
        if query is not None:
            self.queries.append(query)
            if query.closure is not None and self.uncertainty is not None:
                self.uncertainty.add_edge(query.closure, loop=True)
        return query

    def _follow(self, node: int, poses, information=None) -> None:
        """Nodes up to ``node`` into the uncertainty graph, each joined to the one before by its odometry step
        (the last one with ``information``, if given)."""
        if self.uncertainty is not None:
            while self.uncertainty.num_nodes <= node:
                k = self.uncertainty.num_nodes
                step = None
                if k == node and k > 0 and information is not None:
                    step = Edge(k - 1, k, np.linalg.inv(poses[k - 1]) @ poses[k], information=information)
                self.uncertainty.add_node(poses[k], step)

    def add_edges(self, edges) -> None:
        """Edges the run measured besides the odometry steps and the loops (its edges back), for the uncertainty."""
        if self.uncertainty is not None:
            for edge in edges:
                self.uncertainty.add_edge(edge)

    def query(self, node: int, cloud: np.ndarray, pose: np.ndarray, clouds, poses) -> LoopQuery | None:
        """One loop query of node ``node``: (1) the old submaps near its pose,
        verified by ICP; (2) the best scan of the matching submaps, kept as a
        loop edge if :meth:`accepts` it. None if no submap was registered."""
        submaps, settings = self.submaps, self.settings
        # 1. Old submaps within the search radius (grown, or from the graph's uncertainty), verified by ICP.
        covariances, centres, extents, starts = None, submaps.centres, None, None
        fallback = ""
        self._follow(node, poses)
        if self.uncertainty is not None:
            try:
                covariances, centres, extents, starts = self._uncertain_centres(pose, poses)
            except SlamError as exc:  # never a crash: this query searches the grown radius instead
                log.warning("scan %d: %s; searching the grown radius instead", node, exc)
                covariances, centres, extents, starts = None, submaps.centres, None, None
                fallback = "grown radius"
        candidates = find_loop_candidates(
            submaps.points,
            centres,
            cloud,
            pose,
            len(submaps) - 1,
            self.icp,
            settings,
            covariances=covariances,
            extents=extents,
            starts=starts,
            closed=closed_places(
                self.loops,
                node,
                settings.skip_after_loop,
                submaps.n_scans_per_submap,
                centres=centres[: eligible_submaps(len(submaps), settings)],
                radius=settings.loop_closure_search_radius + (0.0 if extents is None else extents),
                window_closed=settings.skip_after_closed_place or None,
                gap=settings.sub_map_thresh * submaps.n_scans_per_submap,
            ),
        )
        if candidates.closed:
            self.skipped += 1
        # 2. The best scan-to-scan match of the matching submaps becomes the loop edge, if accepted.
        closure, best, pinned = self._best_scan(node, cloud, candidates, clouds, poses)
        if closure is not None and self.places is not None:
            self.places.closed()
        elif self.places is not None and self.places.lost and not candidates.closed:
            # 3. After a blind stretch the odometry may be far off: the places the scan's descriptors recognise.
            recognised = self._recognised(node, cloud, pose, clouds, poses, candidates.radius)
            if recognised is not None:
                candidates, (closure, best, pinned) = recognised
                fallback = "recognised"
        if not len(candidates.tried_ids):
            return None
        if closure is not None:
            log.info("loop edge %d -> %d, surface RMSE %.3f m", closure.i, closure.j, closure.surface_rmse)
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
            fallback=fallback,
        )

    def _best_scan(self, node: int, cloud: np.ndarray, candidates: LoopCandidates, clouds, poses):
        """(loop edge or None, its RMSE, its constraint) of the best scan of the matching ``candidates``; a
        match that fits is registered again on the old scan's footprint (``overlap_rounds``), then judged."""
        settings = self.settings
        if not len(candidates.ids):
            return None, float("inf"), float("nan")
        n, cap = self.submaps.n_scans_per_submap, settings.icp_max_iterations
        match = best_scan_registration(cloud, node, candidates, clouds, poses, n, self.icp, settings)
        fits = match.surface_rmse < settings.rmse_threshold
        if fits and settings.overlap_rounds and hasattr(self.icp, "align"):  # again on the old scan's footprint
            fit = on_overlap(cloud, clouds[match.i], match.relative, self.icp, settings.overlap_rounds, cap)
            if fit is not None:  # scored on the whole scan, as every best match is
                score = self.icp.score(moving=cloud, fixed=clouds[match.i], T_fixed_moving=fit.T_fixed_moving)
                match = Edge(match.i, match.j, fit.T_fixed_moving, score, information=fit.information)
        pinned = float("nan")
        if match.surface_rmse < settings.rmse_threshold:
            pinned = self.icp.constraint(moving=cloud, fixed=clouds[match.i], T_fixed_moving=match.relative)
        if self.accepts(match.surface_rmse, pinned):
            return match, match.surface_rmse, pinned
        if match.surface_rmse < settings.rmse_threshold:
            log.info("loop %d -> %d left out: ground too flat (constraint %.4f)", match.i, match.j, pinned)
        return None, match.surface_rmse, pinned

    def _recognised(self, node: int, cloud: np.ndarray, pose: np.ndarray, clouds, poses, radius: np.ndarray):
        """(candidates, best scan) of the submaps the scan's descriptors recognise (:mod:`helpers.slam.loops.places`),
        checked by ICP from the recognised pose as any candidate; the loop edge only if the recognition
        before agreed. None if nothing was recognised. ``radius``: what the query's own search reached
        around each submap, kept in the candidates (the descriptors looked everywhere)."""
        settings, count = self.settings, eligible_submaps(len(self.submaps), self.settings)
        ids, starts = self.places.recognise(node, poses, count)
        if not len(ids):
            return None
        candidates = verified(
            self.submaps.points, cloud, ids, starts, self.icp, settings, n_eligible=count, radius=radius
        )
        closure, best, pinned = self._best_scan(node, cloud, candidates, clouds, poses)
        if closure is not None and not self.places.confirmed(node, pose, poses[closure.i] @ closure.relative):
            log.info("loop %d -> %d recognised; it waits for the next recognition to agree", closure.i, closure.j)
            closure = None
        return candidates, (closure, best, pinned)

    def _uncertain_centres(self, pose: np.ndarray, poses):
        """For the gate, from the scan at ``pose`` (its odometry pose): each eligible submap's
        centre covariance (exact where the gate may let it in, carried over
        elsewhere, NaN outside the graph's window); every submap's centre, the
        eligible ones where the graph puts them (the odometry's, moved by the
        loop edges found); each eligible submap's extent beyond the fixed
        radius, how far its scans lie from its centre (a scan over any of them
        overlaps it); and, for ICP against each eligible submap, the scan's
        pose in that submap's frame where the graph puts the two (the
        odometry's offset moved by the loop edges found: after a loop has
        mended a drift, the odometry's own offset to an old place can be
        metres off; the scan's pose where the graph knows no better)."""
        position = pose[:3, 3]
        settings, n = self.settings, self.submaps.n_scans_per_submap
        count = eligible_submaps(len(self.submaps), settings)
        nodes = [centre_scan_id(k, n) for k in range(count)]
        scans = np.asarray(poses, dtype=float)[: count * n, :3, 3].reshape(count, n, 3)
        extents = np.linalg.norm(scans - scans[:, [n - 1 - n // 2]], axis=2).max(axis=1)
        radius, sigmas = settings.loop_closure_search_radius + extents, settings.search_sigmas

        def wanted(covariances):
            return mahalanobis_gate(self.uncertainty.positions(nodes), position, covariances, radius, sigmas)[0]

        covariances = self.uncertainty.position_covariances(nodes, wanted=wanted)
        centres = self.submaps.centres
        where = self.uncertainty.positions(nodes)
        known = np.isfinite(where).all(axis=1)  # outside the graph's window: the odometry's centre, never searched
        centres[:count][known] = where[known]
        # the graph holds the current node at its odometry pose: a centre's odometry pose times its pose in the
        # graph, inverted, carries the graph's frame into the frame the submap was built in
        solved = self.uncertainty.solved_poses(nodes)
        starts = np.repeat(np.asarray(pose, dtype=float)[None], count, axis=0)
        centre_poses = np.asarray(poses, dtype=float)[nodes]
        starts[known] = centre_poses[known] @ np.linalg.inv(solved[known]) @ pose
        return covariances, centres, extents, starts

    def accepts(self, rmse: float, constraint: float) -> bool:
        """A best scan match is a loop edge if it fits (surface RMSE below
        ``rmse_threshold``) and pins the motion (``constraint`` at least
        ``min_constraint``; nan, not measured, passes): on flat ground any
        slide fits as well."""
        return rmse < self.settings.rmse_threshold and not constraint < self.settings.min_constraint
