"""Checks for the exercises of notebook 2 (the parameters)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from helpers.exercises.report import say, unanswered
from helpers.slam.registration.features import grid_average

OVERLAP_RADIUS = 1.5  # m: a moving point is on shared ground when a fixed point lies this close (one grid cell)


def check_grid_step(step, scan, target: int = 3000, tolerance: float = 0.05) -> None:
    """Exercise 2.1: a grid step that leaves ``scan`` with ``target`` points, within ``tolerance``."""
    if unanswered(step):
        return say(False, "", "set `step` to a grid step in metres, then run this cell again")
    kept = len(grid_average(scan, float(step)))
    ok = abs(kept - target) <= tolerance * target
    direction = "larger" if kept > target else "smaller"
    return say(
        ok,
        f"your grid step leaves the scan within {tolerance:.0%} of {target} points",
        f"a {float(step):g} m grid leaves {kept} points, not within {tolerance:.0%} of {target}: "
        f"try a {direction} step",
    )


def _footprint_overlap(dataset, fixed: int, moving: int, radius: float = OVERLAP_RADIUS) -> float:
    """Share of scan ``moving``'s points that, placed by the true poses, lie
    within ``radius`` metres of a point of scan ``fixed``: the ground the two share."""
    distance, _ = cKDTree(dataset.scan_in_map(fixed)).query(dataset.scan_in_map(moving))
    return float(np.mean(distance < radius))


def check_skip_frames(gap, dataset, start: int = 150, least: float = 0.5) -> None:
    """Exercise 2.2: the largest gap after scan ``start`` whose overlap with it is still at least ``least``."""
    if unanswered(gap):
        return say(False, "", "set `gap` to a whole number of scans, then run this cell again")
    gap = int(gap)
    if gap < 1:
        return say(False, "", "a gap is at least 1 scan")
    here = _footprint_overlap(dataset, start, start + gap)
    beyond = _footprint_overlap(dataset, start, start + gap + 1)
    if here < least or beyond >= least:  # one hint for both sides: measure, do not bisect
        return say(
            False,
            "",
            f"{gap} is not the largest gap that keeps {least:.0%}: place both scans with their true poses "
            "and measure the share of shared ground for every gap in a loop",
        )
    return say(
        True,
        f"{gap} scans apart the two still share {least:.0%} of their ground, {gap + 1} apart they do not",
        "",
    )
