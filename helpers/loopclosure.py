"""Loop closure (stage 5): find old submaps near the current scan, verify them
by ICP, then turn the best scan-to-scan match into a loop edge.

Frames and conventions are those of :mod:`helpers.posegraph`: a scan is an
(N, 3) array in its own frame, its pose carries it into the map frame, and a
loop edge ``(i, j, T_ij)`` says ``pose_j = pose_i @ T_ij``. Submaps and their
centres are in the map frame (:mod:`helpers.submaps`).

ICP is injected as ``icp_fn(moving, fixed, init) -> (T, rmse)``, where ``T``
carries ``moving`` onto ``fixed`` starting from ``init``; :func:`icp_with`
builds one from :func:`helpers.icp.refine_icp`, and tests pass a
stub.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .config import LoopClosureConfig
from .errors import SlamError
from .geometry import check_points, check_pose, transform_points
from .submaps import scan_ids_of

log = logging.getLogger(__name__)

SURFACE_NEIGHBORS = 20  # neighbours of the normals that surface_rmse measures along
PREPARED_CLOUDS = 64  # clouds an icp_fn keeps ready for ICP: the recent scans and the submaps around them

IcpFn = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, float]]


class LoopCandidates(NamedTuple):
    """Matching submaps, best (lowest RMSE) first, and what the search tried.

    ``poses[k]`` is the scan's pose in the map frame that ICP found against
    submap ``ids[k]``; it seeds the scan-to-scan registration.
    """

    ids: np.ndarray  # (L,) submap ids
    scores: np.ndarray  # (L,) ICP RMSE, m
    poses: np.ndarray  # (L, 4, 4)
    n_eligible: int = 0  # submaps 0 .. n_eligible - 1 were old enough to be searched
    radius: np.ndarray = np.zeros(0)  # (S,) search radius (m) around each of the S submaps given, grown with the flight
    tried_ids: np.ndarray = np.zeros(0, dtype=int)  # (A,) the submaps registered by ICP, nearest first
    tried_rmse: np.ndarray = np.zeros(0)  # (A,) their ICP RMSE, m


@dataclass(frozen=True)
class LoopMatch:
    """A verified loop: ``pose_j = pose_i @ relative_pose``, ready for :meth:`PoseGraph.add_loop`."""

    i: int  # the older scan that matched
    j: int  # the current scan
    relative_pose: np.ndarray
    rmse: float


def icp_with(metric: str, inlier_distance: float, max_iterations: int, tolerance: float, backend: str) -> IcpFn:
    """An ``icp_fn``: :func:`helpers.icp.refine_icp` with these
    settings, scored by :func:`surface_rmse` (not by the point-to-point RMSE).

    The function takes ``iterations`` as a fourth, optional argument: another
    cap than ``max_iterations`` for one call. Its ``constraint(moving, fixed,
    transform)`` says how well a registration's pairs pin the translation
    (:func:`helpers.icp.pairing`).

    The same scans and submaps are registered again and again, so a cloud
    is made ready for ICP (:func:`helpers.icp.icp_cloud`) once while it is
    among the :data:`PREPARED_CLOUDS` used last, and its normals serve the
    score too. The bound keeps memory flat on long flights: a prepared cloud
    takes about 1.5 MB, 8 times its points.
    """
    from .icp import icp_cloud, pairing, refine_icp

    prepared = OrderedDict()  # id(points) -> (points, IcpCloud), least recently used first; points keep the id unique
    with_normals = metric if metric != "point-to-point" else "point-to-plane"  # the score needs normals

    def ready(points):
        key = id(points)
        if key in prepared:
            prepared.move_to_end(key)
        else:
            prepared[key] = (points, icp_cloud(points, with_normals, backend))
            if len(prepared) > PREPARED_CLOUDS:
                prepared.popitem(last=False)
        return prepared[key][1]

    def icp(moving, fixed, init, iterations=None):
        source, target = ready(moving), ready(fixed)
        if metric == "point-to-point":
            source, target = moving, fixed
        cap = max_iterations if iterations is None else iterations
        transform, _ = refine_icp(source, target, init, metric, inlier_distance, cap, tolerance, backend)
        return transform, surface_rmse(moving, ready(fixed), transform, inlier_distance)

    def constraint(moving, fixed, transform):
        """How well the pairs of a registration pin its translation (:func:`helpers.icp.pairing`)."""
        return pairing(ready(moving), ready(fixed), transform, inlier_distance)[1]

    icp.constraint = constraint
    return icp


def surface_normals(points: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) of a cloud, from :data:`SURFACE_NEIGHBORS` neighbours."""
    from .features import to_cloud

    return np.asarray(to_cloud(points, normals_knn=SURFACE_NEIGHBORS).normals)


def surface_rmse(moving: np.ndarray, fixed: np.ndarray, transform: np.ndarray, inlier_distance: float, normals=None):
    """RMS distance (m) from the moved points to the fixed cloud's *surface*:
    each moved point is paired with its nearest fixed point (pairs farther
    than ``inlier_distance`` are ignored) and measured along that point's
    normal.

    Why not the point-to-point RMSE the reference reports: this lidar's rows
    are 2.1 m apart along the track, so two perfectly aligned scans taken
    1 m apart have points about 1 m from their nearest neighbours, more than
    when they are 1 m out of line (measured: 1.11 m aligned, 0.74 m when
    1 m off). Measured along the normals, the error grows with the
    misalignment (0.33 m aligned, 0.40 m at 1 m, 0.60 m at 3 m).
    ``normals`` of ``fixed`` may be given when they are already known; a
    ``fixed`` made ready for ICP (:class:`helpers.icp.IcpCloud` with normals)
    brings its own normals and k-d tree.
    """
    from .icp import IcpCloud

    moved = transform_points(moving, transform)
    if isinstance(fixed, IcpCloud):
        squared, nearest = fixed.nearest(moved)
        fixed, normals = fixed.points, fixed.normals
    else:
        from scipy.spatial import cKDTree

        distance, nearest = cKDTree(fixed).query(moved, distance_upper_bound=inlier_distance)
        squared = distance**2
    paired = squared < inlier_distance**2
    if paired.sum() < SURFACE_NEIGHBORS:
        return float("inf")
    normals = surface_normals(fixed) if normals is None else normals
    q = nearest[paired]
    along_normal = np.einsum("ij,ij->i", moved[paired] - fixed[q], normals[q])
    return float(np.sqrt(np.mean(along_normal**2)))


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
    2. Keep those whose centre is nearer than the radius to the scan's
       position. The radius is ``loop_closure_search_radius + loop_search_growth * d``,
       with ``d`` the distance flown since the submap (:func:`distance_flown_since`):
       odometry drift grows with the distance flown, so an old place can look
       farther away than it is. A growth of 0 is the reference's fixed radius.
    3. Sort them by distance and register the scan to at most ``max_attempts``
       of them: ``icp_fn(scan_points, submap, scan_pose)``.
    4. Keep those with RMSE below ``loop_closure_threshold`` and return at most
       ``max_returned``, lowest RMSE first.

    The names in quotes are the fields of ``settings``.
    """
    centres = np.asarray(submap_centres, dtype=float).reshape(-1, 3)
    scan_points = check_points(scan_points, "the current scan")
    scan_pose = check_pose(scan_pose, "the current scan pose")
    _check_search(submaps, centres, current_submap_id)
    sub_map_thresh, max_attempts = settings.sub_map_thresh, settings.max_attempts

    # 1.-2. eligible submaps within the (growing) radius, nearest first
    position = scan_pose[:3, 3]
    eligible = centres[: max(0, current_submap_id - sub_map_thresh + 1)]
    distance = np.linalg.norm(eligible - position, axis=1)
    flown = distance_flown_since(centres[: current_submap_id + 1], position)
    radius = settings.loop_closure_search_radius + settings.loop_search_growth * flown
    near = np.flatnonzero(distance < radius[: len(eligible)])
    near = near[np.argsort(distance[near], kind="stable")]

    # 3. verify the nearest few by ICP
    found, tried = [], []
    for submap_id in near[:max_attempts]:
        pose, rmse = icp_fn(scan_points, submaps[submap_id], scan_pose)
        log.debug("submap %d at %.1f m: ICP RMSE %.3f m", submap_id, distance[submap_id], rmse)
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
        tried_rmse=np.array(tried, dtype=float),
    )


def best_scan_match(
    scan_points: np.ndarray,
    current_id: int,
    candidates: LoopCandidates,
    scans: Sequence[np.ndarray],
    poses: np.ndarray,
    n_scans_per_submap: int,
    rmse_threshold: float,
    icp_fn: IcpFn,
) -> LoopMatch | None:
    """Register the current scan to every scan of the matching submaps; keep the best.

    The lowest-RMSE match of :func:`best_scan_registration` becomes a
    :class:`LoopMatch` ``(i, current_id)`` if its RMSE is below
    ``rmse_threshold``; otherwise there is no loop (None).
    """
    best = best_scan_registration(scan_points, current_id, candidates, scans, poses, n_scans_per_submap, icp_fn)
    if best is None or not best.rmse < rmse_threshold:
        log.debug("no loop edge: best scan RMSE %s m", None if best is None else round(best.rmse, 3))
        return None
    log.info("loop edge %d -> %d, ICP RMSE %.3f m", best.i, best.j, best.rmse)
    return best


def best_scan_registration(
    scan_points: np.ndarray,
    current_id: int,
    candidates: LoopCandidates,
    scans: Sequence[np.ndarray],
    poses: np.ndarray,
    n_scans_per_submap: int,
    icp_fn: IcpFn,
) -> LoopMatch | None:
    """The lowest-RMSE registration of the current scan onto a scan of the
    matching submaps, whatever its RMSE (None if there is no candidate).

    ``scans`` and ``poses`` are all accepted scans (own frames) and the pose
    estimates the submaps were built with. The registration onto scan ``i``
    starts from ``inv(poses[i]) @ candidates.poses[k]``, the scan's pose found
    against its submap, seen from scan ``i``.
    """
    scan_points = check_points(scan_points, "the current scan")
    poses = np.asarray(poses, dtype=float)
    best = None
    for submap_id, submap_pose in zip(candidates.ids, candidates.poses, strict=True):
        for i in scan_ids_of(int(submap_id), n_scans_per_submap):
            if not 0 <= i < min(len(scans), len(poses)):
                raise SlamError(f"submap {submap_id} holds scan {i}, but only {len(scans)} scans were given")
            init = np.linalg.inv(check_pose(poses[i], f"the pose of scan {i}")) @ submap_pose
            relative, rmse = icp_fn(scan_points, scans[i], init)
            if best is None or rmse < best.rmse:
                best = LoopMatch(i, int(current_id), check_pose(relative, "the ICP result"), float(rmse))
    return best


def _check_search(submaps, centres, current_submap_id) -> None:
    if not np.all(np.isfinite(centres)):
        raise SlamError("the submap centres contain NaN or infinite values")
    if not 0 <= current_submap_id < min(len(centres), len(submaps)):
        raise SlamError(
            f"current_submap_id {current_submap_id} is not among the {min(len(centres), len(submaps))} submaps given"
        )
