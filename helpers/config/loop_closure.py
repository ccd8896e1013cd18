"""The loop closure's table, ``[loop_closure]``: which old submaps a scan is
compared with, how far a query reaches, and when a match is a loop edge
(notebook 5).

It is a table of :class:`helpers.config.tables.Config` and is imported from there;
it lives here to keep that module a single sitting's read.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from helpers.config.bounds import (
    MAX_EDGES_BACK,
    MAX_ITERATIONS,
    MAX_LENGTH,
    MAX_RADIUS,
    MAX_SCANS,
    MAX_SIGMAS,
    MIN_RMSE,
    BoundedTable,
    param,
)

LOOP_SEARCHES = ("uncertainty", "growth")


@dataclass(frozen=True)
class LoopClosureConfig(BoundedTable):
    """Which old submaps a scan is compared with, and when a match is a loop (notebook 5)."""

    TABLE: ClassVar[str] = "loop_closure"
    loop_closure_search_radius: float = param(
        7.9, "submaps whose centre is nearer than this (metres) are candidates", "loopClosureSearchRadius"
    )
    sub_map_thresh: int = param(15, "the most recent submaps are never loop candidates", "subMapThresh")
    loop_closure_threshold: float = param(0.6, "surface RMSE (m) below which a submap matches", "loopClosureThreshold")
    rmse_threshold: float = param(
        0.6, "surface RMSE (m) below which the best scan match is a loop edge", "rmseThreshold"
    )
    loop_search_growth: float = param(
        0.02, "search radius grows by this share of the distance flown (drift grows with it; 0: the reference)"
    )
    search: str = param(
        "uncertainty",
        "how far a query reaches: uncertainty (the graph's, gated in sigmas) or growth (per metre flown)",
    )
    search_sigmas: float = param(
        3.0, "uncertainty search: an old submap is a candidate if within the radius this many sigmas away"
    )
    skip_after_loop: int = param(
        3, "no query for this many accepted scans after a loop edge closed on the same place (0: the reference)"
    )
    skip_after_closed_place: int = param(
        12,
        "skip_after_loop where an earlier pass had closed the place already (0: skip_after_loop's, the reference)",
    )
    max_attempts: int = param(3, "submaps registered at most per query, nearest first")
    max_returned: int = param(3, "matching submaps kept at most, best first")
    icp_max_iterations: int = param(50, "most ICP iterations when checking a submap or a loop edge")
    best_scan_stop: float = param(
        0.5,
        "the best-scan search registers the matching submaps' scans best fitting first and stops at one whose "
        "surface RMSE is under this share of rmse_threshold (0: every scan, the reference)",
    )
    min_constraint: float = param(
        0.005,
        "a loop edge must pin the motion: ICP's weakest over strongest direction, times the share of the scan paired, "
        "at least this (0: the reference)",
    )
    overlap_rounds: int = param(
        20,
        "the best scan match is registered again on the part of the scan over the old scan's footprint, until "
        "that part stops changing, at most this many times (helpers.slam.on_overlap; 0: the whole scan, the "
        "reference)",
    )
    place_recognition: bool = param(
        True,
        "after steps that fell back in a row, also look for the scan's place by its descriptors, wherever the "
        "odometry puts it (helpers.slam.loops.places; false: the reference)",
    )

    def __post_init__(self):
        self._between("loop_closure_search_radius", 0.0, MAX_RADIUS, "zero (no loops) or a positive number of metres")
        for name in ("loop_closure_threshold", "rmse_threshold"):
            self._between(name, MIN_RMSE, MAX_LENGTH, "a positive number of metres")
        self._check("sub_map_thresh", lambda v: v >= 0, "zero or a positive integer")  # a run needs 1: Config
        self._within("sub_map_thresh", 0, MAX_SCANS)
        # A place is never farther than the path flown to it: at growth 1 every old submap is already in reach.
        self._between("loop_search_growth", 0.0, 1.0, "zero or a positive fraction")
        self._one_of("search", LOOP_SEARCHES)
        self._between("search_sigmas", 0.0, MAX_SIGMAS, "zero or a positive number of sigmas")
        self._within("skip_after_loop", 0, MAX_SCANS)
        self._within("skip_after_closed_place", 0, MAX_SCANS)
        self._within("max_attempts", 1, MAX_EDGES_BACK)
        self._within("max_returned", 1, MAX_EDGES_BACK)
        self._within("icp_max_iterations", 1, MAX_ITERATIONS)
        self._within("overlap_rounds", 0, MAX_ITERATIONS)
        self._check("best_scan_stop", lambda v: 0 <= v <= 1, "a fraction in [0, 1]")
        self._check("place_recognition", lambda v: isinstance(v, bool), "true or false")
        self._check("min_constraint", lambda v: 0 <= v <= 1, "a fraction in [0, 1]")
