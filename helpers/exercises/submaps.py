"""Checks for the exercises of notebook 4 (submaps).

Each check reads the truth from the run it is given (the pipeline's own
submaps, or a library call on them) and prints one line.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from helpers.exercises.report import report, unanswered
from helpers.slam.loops import closer as loop_rules


def _submap_reach(submap) -> tuple[np.ndarray, float]:
    """A submap's centre (its pose's position) and its reach: the largest
    horizontal distance (m) from the centre to one of its points."""
    centre = np.asarray(submap.centre, float)
    return centre, float(np.linalg.norm(submap.points[:, :2] - centre[:2], axis=1).max())


def check_centre_and_reach(result, submap_id: int, centre, reach) -> bool:
    """Exercise 4.1: the centre (3 numbers, m) and the reach (m) of submap ``submap_id`` of ``result``."""
    if unanswered(centre) or unanswered(reach):
        return report(False, "", "fill in both the centre and the reach")
    submap = result.submaps.submaps[submap_id]
    true_centre, true_reach = _submap_reach(submap)
    centre = np.asarray(centre, float).ravel()
    if centre.shape != (3,) or not np.allclose(centre, true_centre, atol=1e-6):
        middle = submap.scan_ids[len(submap.scan_ids) // 2]
        return report(False, "", f"the centre is the position of the middle scan's odometry pose (node {middle})")
    if not abs(float(reach) - true_reach) < 0.01:
        return report(False, "", "the reach is the largest distance in x-y from the centre to a point of the submap")
    return report(
        True,
        f"submap {submap_id} reaches {true_reach // 10 * 10:.0f}-{true_reach // 10 * 10 + 10:.0f} m from its centre",
        "",
    )


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
