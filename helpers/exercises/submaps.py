"""Checks for the exercises of notebook 4 (submaps).

Each check reads the truth from the run it is given (its scans and odometry
poses merged as the pipeline merges them, or the loop closer's own rule) and
prints one line.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from helpers.errors import SlamError
from helpers.exercises.report import report, unanswered
from helpers.slam.loops import closer as loop_rules
from helpers.slam.submaps import build_submap, centre_scan_id


def _submap_reach(result, submap_id: int, n_scans: int) -> tuple[np.ndarray, float, range]:
    """Submap ``submap_id`` of ``result`` had it held ``n_scans`` accepted scans: its centre (its middle
    scan's odometry position), its reach (the largest horizontal distance, m, from the centre to one of its
    points, the scans merged as the pipeline merges them) and its nodes."""
    nodes = range(submap_id * n_scans, (submap_id + 1) * n_scans)
    if nodes.stop > len(result.clouds):
        raise SlamError(f"the run has {len(result.clouds)} accepted scans: submap {submap_id} of {n_scans} lacks some")
    poses = result.poses_odometry[list(nodes)]
    points = build_submap([result.clouds[m] for m in nodes], poses, result.config.map.align_grid_step)
    centre = result.poses_odometry[centre_scan_id(submap_id, n_scans)][:3, 3]
    return centre, float(np.linalg.norm(points[:, :2] - centre[:2], axis=1).max()), nodes


def check_centre_and_reach(result, submap_id: int, centre, reach, n_scans: int | None = None) -> bool:
    """Exercise 4.1: the centre (3 numbers, m) and the reach (m) of submap ``submap_id`` of ``result``, the
    submaps holding ``n_scans`` accepted scans each (None: the run's ``n_scans_per_submap``)."""
    if unanswered(centre) or unanswered(reach):
        return report(False, "", "fill in both the centre and the reach")
    n_scans = n_scans or result.config.map.n_scans_per_submap
    true_centre, true_reach, nodes = _submap_reach(result, submap_id, n_scans)
    centre = np.asarray(centre, float).ravel()
    if centre.shape != (3,) or not np.allclose(centre, true_centre, atol=1e-6):
        return report(
            False,
            "",
            f"with {n_scans} scans a submap, submap {submap_id} holds nodes {nodes[0]} to {nodes[-1]}; "
            "its centre is the position of its middle scan's odometry pose",
        )
    if not abs(float(reach) - true_reach) < 0.01:
        return report(
            False,
            "",
            "the reach is the largest x-y distance from the centre to a point of the submap, its scans merged "
            "by build_submap on align_grid_step",
        )
    low = true_reach // 10 * 10
    return report(True, f"submap {submap_id} of {n_scans} scans reaches {low:.0f}-{low + 10:.0f} m from its centre", "")


def _eligible_submaps(result, node: int, sub_map_thresh: int) -> np.ndarray:
    """The submaps a loop query at ``node`` may search, by the loop closer's
    own rule (:func:`helpers.slam.loops.closer.eligible_submaps`)."""
    built = [s for s in result.submaps.submaps if s.scan_ids[-1] <= node]  # the submaps that exist at ``node``
    settings = replace(result.config.loop_closure, sub_map_thresh=sub_map_thresh)
    return np.arange(loop_rules.eligible_submaps(len(built), settings))


def check_eligible(result, node: int, sub_map_thresh: int, eligible) -> bool:
    """Exercise 4.2: the ids of the submaps a query at ``node`` may search, with ``sub_map_thresh``."""
    if unanswered(eligible):
        return report(False, "", "fill in the list of submap ids")
    truth = _eligible_submaps(result, node, sub_map_thresh)
    answer = np.asarray(sorted(np.asarray(eligible, int).ravel().tolist()), int)
    if answer.shape == truth.shape and np.array_equal(answer, truth):
        if len(truth) == 0:
            return report(True, f"no submap is old enough yet at node {node}", "")
        return report(True, f"at node {node} submaps 0 to {truth[-1]} may be searched ({len(truth)} of them)", "")
    return report(
        False,
        "",
        f"count the submaps built by node {node} (each is complete when its last scan arrives), "
        f"then leave out the {sub_map_thresh} newest",
    )
