"""What the loop queries of a run searched, in arrays for notebook 5's figures
(:mod:`helpers.viz.loop_figures` draws them): read from the run's own
records, with the loop closer's own rules (:mod:`helpers.slam.loops.closer`).
"""

from __future__ import annotations

import numpy as np

from helpers.errors import SlamError
from helpers.slam.loops.closer import distance_flown_since, eligible_submaps
from helpers.slam.submaps import centre_scan_id


def query_search(result, node: int, poses_gt) -> dict:
    """What the loop query of ``node`` saw, as the pipeline recorded it
    (:class:`helpers.slam.pipeline.LoopQuery`): the submap centres that existed
    then (odometry frame), how many were eligible, each one's search
    radius, the submaps registered by ICP (nearest first) and those matched;
    with the scan's odometry and true positions (``poses_gt``: (K, 4, 4), the
    true poses of the nodes, e.g. ``dataset.poses[result.indices]``)."""
    query = next((q for q in result.queries if q.node == node), None)
    if query is None:
        raise SlamError(f"node {node} registered no old submap: it has no loop query")
    centres = result.submaps.centres[: query.n_submaps]
    position = result.poses_odometry[node][:3, 3]
    true_centres = np.array([poses_gt[centre_scan_id(s.id, len(s.scan_ids))][:3, 3] for s in result.submaps.submaps])
    return {
        "centres": centres,
        "true_centres": true_centres[: query.n_submaps],
        "n_eligible": query.n_eligible,
        "radius": query.radius,
        "distance": np.linalg.norm(centres[: query.n_eligible] - position, axis=1),
        "tried": query.tried_ids,
        "matched": np.asarray(query.submap_ids, int),
        "position": position,
        "true_position": poses_gt[node][:3, 3],
    }


def true_revisits(result, poses_gt, max_true_distance: float = 10.0) -> dict:
    """Every node that truly flies over an eligible old submap (true centre
    within ``max_true_distance`` m; ``poses_gt``: (K, 4, 4), the true poses of
    the nodes): the distance flown since that submap, how far away it truly
    is and how far it looks on the odometry, whether the node closed a loop, and the search radius its
    query recorded around that submap (nan: the node registered no submap, so
    its query left no record)."""
    n = result.config.map.n_scans_per_submap
    subs = result.submaps.submaps
    true_centres = np.array([poses_gt[centre_scan_id(s.id, len(s.scan_ids))][:3, 3] for s in subs])
    closed = {loop.j for loop in result.loops}
    queries = {q.node: q for q in result.queries}
    rows = []
    for node in range(len(result.indices)):
        count = (node + 1) // n
        n_eligible = eligible_submaps(count, result.config.loop_closure)  # the loop closer's own rule
        if n_eligible == 0:
            continue
        true_distance = np.linalg.norm(true_centres[:n_eligible] - poses_gt[node][:3, 3], axis=1)
        k = int(np.argmin(true_distance))
        if true_distance[k] > max_true_distance:
            continue
        position = result.poses_odometry[node][:3, 3]
        flown = distance_flown_since(result.submaps.centres[:count], position)[k]
        apparent = np.linalg.norm(result.submaps.centres[k] - position)
        radius = queries[node].radius[k] if node in queries else np.nan
        rows.append((node, flown, true_distance[k], apparent, node in closed, radius))
    nodes, flown, true, apparent, found, radius = (np.array(c) for c in zip(*rows, strict=True)) if rows else ([],) * 6
    return {
        "nodes": nodes,
        "flown": flown,
        "true": true,
        "apparent": apparent,
        "closed": np.asarray(found, bool),
        "radius": np.asarray(radius, float),
    }
