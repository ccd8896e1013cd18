"""The pose graph's table, ``[pose_graph]``: which edges the graph holds
beyond the odometry, how each is weighed, the robust kernel on loop edges
and the motion factor (notebooks 6 and 8).

It is the last table of :class:`helpers.config.tables.Config` and is imported from
there; it lives here to keep that module a single sitting's read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from helpers.config.bounds import (
    MAX_ACCELERATION,
    MAX_ANGULAR_ACCELERATION,
    MAX_EDGES_BACK,
    MAX_ITERATIONS,
    MAX_LENGTH,
    MAX_SPEED,
    MIN_RMSE,
    MIN_SIGMA,
    BoundedTable,
    param,
)

GRAPH_WEIGHTS = ("hessian", "icp", "identity")
INFORMATION_SOURCES = ("gicp", "plane")
LOOP_KERNELS = ("none", "huber", "cauchy")


@dataclass(frozen=True)
class PoseGraphConfig(BoundedTable):
    """The pose graph's extra edges, weights and robust kernel (notebook 6).

    With the reference's identity weights a rotation of 0.1 rad costs as
    little as 0.1 m, so a wrong loop can fold the whole trajectory cheaply and
    no robust kernel can tell it from a right one. The icp weights give every
    edge sigmas close to the real error of ICP between overlapping scans, for
    odometry and loops alike: then a residual "in sigmas" means something.
    The hessian weights (ours, one value away) give each edge its own: the
    information of the registration that measured it, calibrated on flights
    whose truth is known (``benchmarks/bench_information.py``), so a step over
    flat ground says how little it knows along the track. That information is
    generalized ICP's own Hessian (``information = "gicp"``) or the
    point-to-plane Hessian of the same final pairs (``"plane"``): the plane
    covariances of generalized ICP keep a little weight along a flat ground,
    so its Hessian stays sure of a slide the plane one shows as loose.
    """

    TABLE: ClassVar[str] = "pose_graph"
    edges_back: int = param(
        4, "each scan is also registered to the scans up to this many nodes back (1: the reference)"
    )
    edges_back_icp_max_iterations: int = param(
        6, "most ICP iterations of an edge back (its guess, the chained odometry, is close already)"
    )
    edges_back_rmse_threshold: float = param(
        0.6, "surface RMSE (m) below which an edge back is kept (as a loop edge's rmse_threshold)"
    )
    graph_weights: str = param(
        "icp", "edge weights: hessian (each registration's own, calibrated), icp (the sigmas below), identity"
    )
    edge_sigma_m: float = param(0.1, "icp weights: an edge's translation sigma per step spanned, metres")
    edge_sigma_deg: float = param(0.3, "icp weights: an edge's rotation sigma per step spanned, degrees")
    information: str = param(
        "gicp",
        "what an edge's information is measured from: gicp (small_gicp's Hessian of its cost) or plane "
        "(point-to-plane of the final pairs, which sees a slide along flat ground)",
    )
    information_scale: float = param(
        0.35, "hessian weights: ICP's information (Hessian over residual variance) is multiplied by this"
    )
    min_sigma_m: float = param(0.001, "hessian weights: no edge is surer than this along any translation, metres")
    min_sigma_deg: float = param(0.001, "hessian weights: ... nor than this about any axis, degrees")
    loop_kernel: str = param("cauchy", "robust kernel on loop edges: none (the reference), huber or cauchy")
    motion_factor: bool = param(
        False, "a soft constant-velocity factor over every three consecutive nodes (false: the reference)"
    )
    motion_speed: float = param(
        10.0, "motion factor: the drone's nominal ground speed, m/s (turns the step between nodes into a time)"
    )
    motion_acceleration: float = param(
        1.0, "motion factor: the acceleration the drone may have, m/s^2 (its translation sigma: a dt^2)"
    )
    motion_angular_acceleration: float = param(
        20.0, "motion factor: the change of turn rate the drone may have, deg/s^2 (its rotation sigma)"
    )

    def __post_init__(self):
        self._within("edges_back", 1, MAX_EDGES_BACK)
        self._within("edges_back_icp_max_iterations", 1, MAX_ITERATIONS)
        self._between("edges_back_rmse_threshold", MIN_RMSE, MAX_LENGTH, "a positive number of metres")
        self._one_of("graph_weights", GRAPH_WEIGHTS)
        self._between("edge_sigma_m", MIN_SIGMA, MAX_LENGTH, "a positive number of metres")
        self._between("edge_sigma_deg", MIN_SIGMA, 180.0, "a positive number of degrees")
        self._one_of("information", INFORMATION_SOURCES)
        self._between("information_scale", MIN_SIGMA, 1.0, "a positive fraction (ICP is never surer than its Hessian)")
        self._between("min_sigma_m", MIN_SIGMA, MAX_LENGTH, "a positive number of metres")
        self._between("min_sigma_deg", MIN_SIGMA, 180.0, "a positive number of degrees")
        self._one_of("loop_kernel", LOOP_KERNELS)
        self._check("motion_factor", lambda v: isinstance(v, bool), "true or false")
        self._between("motion_speed", MIN_SIGMA, MAX_SPEED, "a positive number of metres per second")
        self._between("motion_acceleration", MIN_SIGMA, MAX_ACCELERATION, "a positive number of m/s^2")
        self._between(
            "motion_angular_acceleration", MIN_SIGMA, MAX_ANGULAR_ACCELERATION, "a positive number of deg/s^2"
        )

    @property
    def edge_sigmas(self) -> np.ndarray:
        """(6,) translation-first sigmas of a one-step edge with icp weights: metres, then radians."""
        return six_sigmas(self.edge_sigma_m, self.edge_sigma_deg)

    @property
    def min_sigmas(self) -> np.ndarray:
        """(6,) translation-first floor of an edge's sigmas with hessian weights: metres, then radians."""
        return six_sigmas(self.min_sigma_m, self.min_sigma_deg)


def six_sigmas(metres: float, degrees: float) -> np.ndarray:
    """(6,) translation-first sigmas, the same on every axis: ``metres`` three times, then ``degrees`` in radians."""
    return np.array([metres] * 3 + [math.radians(degrees)] * 3)
