"""The best scan of a loop query (stage 5): once old submaps match, the
current scan is registered onto their scans one by one and the lowest-RMSE
match is kept. :class:`helpers.slam.loops.closer.LoopCloser` calls it, registers
the match again on the old scan's footprint (:func:`helpers.slam.registration.overlap.on_overlap`)
and judges it; ``helpers.slam.loops.closer`` also exports it under its old name.

Frames and conventions are :mod:`helpers.slam.loops.closer`'s: a scan is an
(N, 3) array in its own frame, and a loop edge ``(i, j, T_i_j)`` says
``pose_j = pose_i @ T_i_j``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from helpers.config.tables import LoopClosureConfig
from helpers.errors import SlamError
from helpers.geometry import check_points, check_pose
from helpers.slam.graph.factors import Edge
from helpers.slam.loops.search import IcpFn, LoopCandidates
from helpers.slam.submaps import scan_ids_of


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
    matching submaps (of those registered: below), whatever its RMSE (None
    if there is no candidate).

    ``scans`` and ``poses`` are all accepted scans (own frames) and the pose
    estimates the submaps were built with. The registration onto scan ``i``
    starts from ``inv(poses[i]) @ candidates.poses[k]``, the scan's pose found
    against its submap, seen from scan ``i``, with the ICP iteration cap of
    ``settings`` (the icp_fn's own when None).

    In which order, and when to stop: the reference registers every scan,
    submap after submap (``settings.best_scan_stop`` 0, also with no
    ``settings`` or an ``icp_fn`` that cannot score). Ours registers them
    in the order they fit at their start (the surface RMSE ``icp_fn.score``
    measures without ICP) and stops at the first whose RMSE after ICP is
    under ``best_scan_stop`` times ``rmse_threshold``: the submap check has
    already aligned the scan with them, and a scan that fits that well after
    ICP leaves little for another to improve on. Over the default flight, two
    laps of it, Autzen at 250 m and the sparse tile at 150 m (its flat ground
    is where a start fits worst) it ran 325 of the 1,554 registrations the
    reference's search would; the reference's best scan was another in 14 of
    the 217 queries, its RMSE lower by at most 2.6 cm, and no loop was lost
    (``benchmarks/bench_best_scan.py``; ``bench_long.py`` measures the time
    saved on revisit laps).
    """
    cap = None if settings is None else settings.icp_max_iterations
    scan_points = check_points(scan_points, "the current scan")
    poses = np.asarray(poses, dtype=float)
    starts = []  # (scan i, its start T_i_current) for every scan of the matching submaps, in the reference's order
    for submap_id, submap_pose in zip(candidates.ids, candidates.poses, strict=True):
        for i in scan_ids_of(int(submap_id), n_scans_per_submap):
            if not 0 <= i < min(len(scans), len(poses)):
                raise SlamError(f"submap {submap_id} holds scan {i}, but only {len(scans)} scans were given")
            starts.append((i, np.linalg.inv(check_pose(poses[i], f"the pose of scan {i}")) @ submap_pose))
    order, stop = range(len(starts)), 0.0  # the reference's: every scan
    if settings is not None and settings.best_scan_stop > 0 and len(starts) > 1 and hasattr(icp_fn, "score"):
        fits = [icp_fn.score(moving=scan_points, fixed=scans[i], T_fixed_moving=init) for i, init in starts]
        order, stop = np.argsort(fits, kind="stable"), settings.best_scan_stop * settings.rmse_threshold
    best, best_at = None, len(starts)
    for k in order:
        i, init = starts[k]
        fit = icp_fn(moving=scan_points, fixed=scans[i], T_fixed_moving=init, max_iterations=cap)
        (T_i_j, rmse), information = fit, getattr(fit, "information", None)
        if best is None or (rmse, k) < (best.surface_rmse, best_at):  # ties: the first in the reference's order
            T_i_j = check_pose(T_i_j, "the ICP result")
            best, best_at = Edge(i, int(current_id), T_i_j, float(rmse), information=information), k
        if rmse < stop:
            break
    return best
