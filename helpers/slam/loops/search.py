"""Where a loop query looks: which old submaps are eligible and how far
around each the search reaches (:mod:`helpers.slam.loops.closer` asks; the health
report and the figures use the same rules).

Two searches (``[loop_closure] search``): ``"growth"``, a radius grown with
the distance flown since the submap (:func:`radius_after`), and
``"uncertainty"``, the radius the graph's relative covariance allows
(:func:`mahalanobis_gate`, from the covariances
:class:`helpers.slam.loops.uncertainty.RelativeUncertainty` gives). :func:`closed_places` says
which old places have just closed a loop, so that a query there can wait.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from helpers.config.tables import LoopClosureConfig
from helpers.errors import SlamError
from helpers.geometry import check_points, check_pose

log = logging.getLogger(__name__)

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
    closed: bool = False  # True: the nearest candidate's place had just closed a loop, and none was tried


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


def reach_of_submaps(
    centres: np.ndarray,
    position: np.ndarray,
    n_eligible: int,
    settings: LoopClosureConfig,
    covariances=None,
    extents=None,
) -> np.ndarray:
    """The search radius (m) around each of the submaps whose ``centres`` are
    given, for a scan at ``position``: :func:`search_radius` (growth), or,
    given ``covariances`` ((n_eligible, 3, 3): each eligible centre's position
    relative to the scan, m²), the gate's radius along the way to each
    eligible centre; the place's extent is the fixed radius plus ``extents``
    ((n_eligible,) m, how far the submap's scans lie from its centre; 0 when
    not given). The newest submaps, never searched, keep the fixed radius; a
    NaN covariance (a place beyond the graph's window) gets radius 0: it is
    not searched."""
    if covariances is None:
        return search_radius(centres, position, settings)
    covariances = np.asarray(covariances, dtype=float).reshape(-1, 3, 3)
    extents = np.zeros(n_eligible) if extents is None else np.asarray(extents, dtype=float).ravel()
    if len(covariances) != n_eligible or len(extents) != n_eligible:
        raise SlamError(f"{len(covariances)} covariances and {len(extents)} extents for {n_eligible} eligible submaps")
    radius = np.full(len(centres), settings.loop_closure_search_radius)
    _, reach = mahalanobis_gate(
        centres[:n_eligible], position, covariances, radius[:n_eligible] + extents, settings.search_sigmas
    )
    radius[:n_eligible] = np.nan_to_num(reach, nan=0.0)  # no answer (beyond the graph's window): not searched
    return radius


def closed_places(
    loops, node: int, window: int, n_scans_per_submap: int, centres=None, radius=0.0, window_closed=None, gap=0
) -> set[int]:
    """The submaps around the old end of every loop edge (``loops``, in the
    order found) closed at most ``window`` accepted scans before ``node``,
    reaching as far along the old track as the drone has flown since: a query
    whose nearest candidate lies there would close the same place again.

    ``window_closed`` (accepted scans; None: ``window``) replaces ``window``
    for a loop whose old end lies at a place an earlier pass had closed
    already: a loop edge found more than ``gap`` scans before it has an end
    within one submap's scans of its old end (a loop found less than ``gap``
    scans before it is of the same pass: its old end moves with the drone).
    The third and later passes over a place then query less often than the
    first revisit, which has only the odometry to correct.

    Given the submaps' ``centres`` ((S, 3), m), a place is ground, not one
    pass over it: every submap whose centre lies within ``radius`` (m; one
    number, or one per submap: its reach) of one of those is closed too (on a
    flight over the same ground many times, the nearest candidate is often
    another pass's submap over the place just closed)."""
    longest = window if window_closed is None else max(window, window_closed)
    closed = set()
    for k in range(len(loops) - 1, -1, -1):
        loop = loops[k]
        if node - loop.j > longest:
            break
        wait = window
        if window_closed is not None and _closed_before(loops[:k], loop, gap, n_scans_per_submap):
            wait = window_closed
        if node - loop.j > wait:
            continue
        reach = _reach(wait, n_scans_per_submap)
        centre = loop.i // n_scans_per_submap
        closed.update(range(centre - reach, centre + reach + 1))
    if centres is not None and closed:
        centres = np.asarray(centres, dtype=float).reshape(-1, 3)
        ids = sorted(k for k in closed if 0 <= k < len(centres))
        if ids:
            gap = np.linalg.norm(centres[:, None, :] - centres[None, ids, :], axis=2).min(axis=1)
            closed.update(np.flatnonzero(gap < radius).tolist())
    return closed


def _reach(window: int, n_scans_per_submap: int) -> int:
    """Submaps a closed place reaches either side: those flown during ``window`` scans, rounded up, and one."""
    return -(-window // n_scans_per_submap) + 1


def _closed_before(earlier, loop, gap: int, span: int) -> bool:
    """Whether a loop of ``earlier`` found more than ``gap`` scans before ``loop`` has an end within ``span``
    scans of ``loop``'s old end (the same place of an old pass: one submap's scans)."""
    return any(
        loop.j - other.j > gap and min(abs(other.i - loop.i), abs(other.j - loop.i)) <= span for other in earlier
    )


def find_loop_candidates(
    submaps: Sequence[np.ndarray],
    submap_centres: np.ndarray,
    scan_points: np.ndarray,
    scan_pose: np.ndarray,
    current_submap_id: int,
    icp_fn: IcpFn,
    settings: LoopClosureConfig,
    covariances: np.ndarray | None = None,
    closed=(),
    extents: np.ndarray | None = None,
    starts: np.ndarray | None = None,
) -> LoopCandidates:
    """Old submaps that the current scan registers onto: the reference's ``helperEstimateLoopCandidates``.

    1. Only submaps ``0 .. current_submap_id - sub_map_thresh`` are eligible
       (``current_submap_id`` is the newest built submap; the ``sub_map_thresh``
       newest are skipped).
    2. Keep those whose centre is nearer than :func:`search_radius` to the
       scan's position; or, given ``covariances`` ((E, 3, 3), each eligible
       centre's position relative to the scan, m²), those in reach of
       :func:`mahalanobis_gate` (``search_sigmas``;
       the place's extent: the fixed radius plus ``extents``, (E,) m; the
       loop closer gives the centres where the graph puts them).
    3. Sort them by distance; if the nearest is among the submap ids
       ``closed`` (a loop has just closed there), stop. Otherwise register the
       scan to at most ``max_attempts`` of them, from ``scan_pose``, or from
       ``starts[k]`` ((E, 4, 4): the scan's pose in eligible submap ``k``'s
       frame where the loop closer's graph puts it) when given.
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
    radius = reach_of_submaps(centres[: current_submap_id + 1], position, len(eligible), settings, covariances, extents)
    near = np.flatnonzero(distance < radius[: len(eligible)])
    near = near[np.argsort(distance[near], kind="stable")]
    if len(near) and int(near[0]) in closed:
        return LoopCandidates(*_NONE, n_eligible=len(eligible), radius=radius, closed=True)

    # 3.-4. verify the nearest few by ICP, best first
    tried = near[:max_attempts].astype(int)
    starts = [scan_pose if starts is None else starts[k] for k in tried]
    return verified(submaps, scan_points, tried, starts, icp_fn, settings, n_eligible=len(eligible), radius=radius)


def verified(submaps, scan_points, ids, starts, icp_fn: IcpFn, settings: LoopClosureConfig, **searched):
    """The :class:`LoopCandidates` of registering the scan onto submaps ``ids`` by ICP, onto submap
    ``ids[k]`` from ``starts[k]`` (the scan's pose in its frame): those with RMSE below
    ``loop_closure_threshold``, at most ``max_returned``, lowest RMSE first. ``searched``: the
    ``n_eligible`` and ``radius`` of the search that chose them."""
    found, tried = [], []
    for submap_id, start in zip(ids, starts, strict=True):
        pose, rmse = icp_fn(
            moving=scan_points, fixed=submaps[submap_id], T_fixed_moving=start,
            max_iterations=settings.icp_max_iterations,
        )  # fmt: skip
        log.debug("submap %d: surface RMSE %.3f m", submap_id, rmse)
        tried.append(rmse)
        if rmse < settings.loop_closure_threshold:
            found.append((float(rmse), int(submap_id), check_pose(pose, "the ICP result")))
    found.sort(key=lambda item: item[0])
    found = found[: settings.max_returned]
    return LoopCandidates(
        np.array([f[1] for f in found], dtype=int),
        np.array([f[0] for f in found], dtype=float),
        np.array([f[2] for f in found], dtype=float).reshape(-1, 4, 4),
        tried_ids=np.asarray(ids, dtype=int),
        tried=np.array(tried, dtype=float),
        **searched,
    )


_NONE = (np.zeros(0, dtype=int), np.zeros(0), np.zeros((0, 4, 4)))


def _check_search(submaps, centres, current_submap_id) -> None:
    if not np.all(np.isfinite(centres)):
        raise SlamError("the submap centres contain NaN or infinite values")
    if not 0 <= current_submap_id < min(len(centres), len(submaps)):
        raise SlamError(
            f"current_submap_id {current_submap_id} is not among the {min(len(centres), len(submaps))} submaps given"
        )


def mahalanobis_gate(
    centres: np.ndarray, position: np.ndarray, covariances: np.ndarray, radius, sigmas: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which old places the scan at ``position`` may truly be over, and the
    search radius around each.

    Place ``k`` (its centre, map frame) is in reach when the offset to it,
    less ``radius`` (the place's extent, m; one number or one per place), is within
    ``sigmas`` of its uncertainty: ``d' = d max(0, 1 - radius / |d|)`` and
    ``d'^T C^-1 d' < sigmas^2`` with ``C = covariances[k]``. The radius along
    the direction ``u`` of the offset follows: ``radius + sigmas /
    sqrt(u^T C^-1 u)``, so that the gate is ``|d| < that radius``; with
    ``C = 0`` it is ``radius``. A NaN covariance (no answer) is never in
    reach, its radius NaN. Returns (in reach (K,) bool, radius (K,) m).
    """
    offset = np.asarray(centres, float).reshape(-1, 3) - np.asarray(position, float)
    distance = np.linalg.norm(offset, axis=1)
    direction = offset / np.maximum(distance, 1e-12)[:, None]
    covariances = np.asarray(covariances, float).reshape(-1, 3, 3)
    known = np.isfinite(covariances).all(axis=(1, 2))
    floor = 1e-12 * np.eye(3)  # a node at the anchor has no uncertainty at all
    inverse = np.linalg.inv(np.where(known[:, None, None], covariances, np.eye(3)) + floor)
    spread = 1.0 / np.sqrt(np.einsum("ki,kij,kj->k", direction, inverse, direction))
    reach = np.where(known, np.asarray(radius, float) + sigmas * spread, np.nan)
    return known & (distance < np.nan_to_num(reach, nan=-1.0)), reach
