"""One ICP service for a whole run: the odometry, the loop checks and the
edges back all register through it, with keyword arguments named by the
frames (``T_fixed_moving`` carries the moving cloud into the fixed cloud's
frame, as :func:`helpers.slam.registration.icp.refine_icp` returns it).

The same scans and submaps are registered again and again (a scan is the
fixed cloud of the next odometry step, of the edges back of the next nodes
and of later loop checks), so a cloud is made ready for ICP
(:func:`helpers.slam.registration.icp.icp_cloud`) once while it is among the
:data:`PREPARED_CLOUDS` used last, and its normals serve the surface score
too. The bound keeps memory flat on long flights: a cloud the search can no
longer reach soon leaves the cache, and one it reaches again is prepared anew.

Two measures of fit, never mixed up:

* ``rmse``: ICP's own point-to-point RMSE over its pairs (the odometry's);
* ``surface_rmse``: the RMS distance along the fixed cloud's normals (edges
  back and loops; :func:`surface_rmse` says why).

Both calls return an :class:`helpers.slam.registration.icp.IcpResult`: it unpacks as
``(T_fixed_moving, rmse)`` and carries the registration's ``information``
CALIBRATED (:func:`helpers.slam.graph.information.calibrated`, with the service's
``information_scale`` and ``min_sigmas``, ``[pose_graph]``'s in a run; None
for point-to-point ICP), so every edge made from it says how sure it is.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from helpers.config.tables import PoseGraphConfig, RegistrationConfig
from helpers.geometry import transform_points
from helpers.slam.graph.information import calibrated
from helpers.slam.registration import icp as _icp

SURFACE_NEIGHBORS = 20  # neighbours of the normals that surface_rmse measures along
PREPARED_CLOUDS = 64  # clouds the service keeps ready: the recent scans and the submaps around them


class IcpService:
    """ICP with one metric, inlier distance, tolerance and back end (the
    ``[registration]`` table's), and the cache of clouds made ready for it.

    Each caller passes its own iteration cap (``max_iterations``), from its
    own table. Calling the service registers and scores by surface RMSE::

        icp = IcpService.from_config(config.registration)
        T_fixed_moving, surface = icp(moving=scan, fixed=submap, T_fixed_moving=guess, max_iterations=50)
    """

    def __init__(
        self,
        *,
        metric: str,
        inlier_distance: float,
        tolerance: float,
        backend: str,
        max_iterations=30,
        information_scale: float | None = None,
        min_sigmas=None,
        information: str | None = None,
    ):
        self.metric, self.inlier_distance, self.tolerance, self.backend = metric, inlier_distance, tolerance, backend
        self.max_iterations = int(max_iterations)
        graph = PoseGraphConfig()  # the calibration of the defaults when none is given
        self.information_scale = graph.information_scale if information_scale is None else information_scale
        self.min_sigmas = graph.min_sigmas if min_sigmas is None else np.asarray(min_sigmas, dtype=float)
        self.information = graph.information if information is None else information
        # the score needs normals: point-to-point ICP is scored on clouds prepared for point-to-plane
        self.surface_metric = metric if metric != "point-to-point" else "point-to-plane"
        self._prepared: OrderedDict = OrderedDict()  # id(points) -> (points, IcpCloud), least recently used first

    @classmethod
    def from_config(
        cls,
        registration: RegistrationConfig,
        max_iterations: int | None = None,
        pose_graph: PoseGraphConfig | None = None,
    ) -> IcpService:
        """The service of a run; ``max_iterations`` is the cap when a call gives none; ``pose_graph``
        calibrates the information (the defaults' calibration when None)."""
        cap = registration.icp_max_iterations if max_iterations is None else max_iterations
        pose_graph = pose_graph or PoseGraphConfig()
        return cls(
            information_scale=pose_graph.information_scale,
            min_sigmas=pose_graph.min_sigmas,
            information=pose_graph.information,
            metric=registration.metric,
            inlier_distance=registration.inlier_distance,
            tolerance=registration.icp_tolerance,
            backend=registration.icp_backend,
            max_iterations=cap,
        )

    def ready(self, points: np.ndarray) -> _icp.IcpCloud:
        """``points`` made ready for ICP and the surface score, once while recently used."""
        key = id(points)
        if key in self._prepared:
            self._prepared.move_to_end(key)
        else:
            self.keep(points, _icp.icp_cloud(points, self.surface_metric, self.backend))
        return self._prepared[key][1]

    def keep(self, points: np.ndarray, cloud: _icp.IcpCloud) -> None:
        """Adopt ``cloud``, ``points`` prepared elsewhere (the odometry's), if it suits this service."""
        if (cloud.metric, cloud.backend) != (self.surface_metric, self.backend):
            return
        self._prepared[id(points)] = (points, cloud)
        self._prepared.move_to_end(id(points))
        while len(self._prepared) > PREPARED_CLOUDS:
            self._prepared.popitem(last=False)

    def target(self, points: np.ndarray):
        """``points`` as this service's ICP takes them: prepared through the cache, or the bare points for
        point-to-point ICP (whose cost needs no normals)."""
        return points if self.metric == "point-to-point" else self.ready(points)

    def align(self, *, moving, fixed, T_fixed_moving: np.ndarray, max_iterations: int | None = None):
        """ICP from ``T_fixed_moving``; returns the refined ``(T_fixed_moving, rmse)`` (point-to-point)
        as an :class:`helpers.slam.registration.icp.IcpResult` with its ``information``.

        ``moving`` and ``fixed`` are (N, 3) arrays or clouds made ready for
        this metric; arrays are prepared for this call only.
        """
        cap = self.max_iterations if max_iterations is None else max_iterations
        fit = _icp.refine_icp(
            moving,
            fixed,
            T_fixed_moving,
            metric=self.metric,
            inlier_distance=self.inlier_distance,
            max_iterations=cap,
            tolerance=self.tolerance,
            backend=self.backend,
            information=self.information,
        )
        return _icp.IcpResult(fit.T_fixed_moving, fit.rmse, self.calibrated(fit.information), fit.nearest)

    def calibrated(self, information):
        """A raw information scaled and capped as this service's are (None stays None)."""
        if information is None:
            return None
        return calibrated(information, self.information_scale, self.min_sigmas)

    def __call__(self, *, moving: np.ndarray, fixed: np.ndarray, T_fixed_moving: np.ndarray, max_iterations=None):
        """Register ``moving`` onto ``fixed`` (arrays, prepared through the cache)
        and score the result: ``(T_fixed_moving, surface_rmse)``, an :class:`.icp.IcpResult`."""
        source, target = self.target(moving), self.target(fixed)
        ready_fixed = self.ready(fixed)  # what the score measures against (normals, k-d tree), whatever ICP aligns on
        fit = self.align(moving=source, fixed=target, T_fixed_moving=T_fixed_moving, max_iterations=max_iterations)
        T = fit.T_fixed_moving
        # the alignment's last pass paired these points with this cloud at T: the score reuses it
        nearest = fit.nearest if target is ready_fixed else None
        surface = surface_rmse(moving, ready_fixed, T, self.inlier_distance, nearest=nearest)
        return _icp.IcpResult(T, surface, fit.information)

    def score(self, *, moving: np.ndarray, fixed: np.ndarray, T_fixed_moving: np.ndarray) -> float:
        """The surface RMSE of ``moving`` on ``fixed`` (arrays; ``fixed`` prepared through the cache) where
        ``T_fixed_moving`` puts it, without ICP: what :meth:`__call__` scores its result by."""
        return surface_rmse(moving, self.ready(fixed), T_fixed_moving, self.inlier_distance)

    def constraint(self, *, moving: np.ndarray, fixed: np.ndarray, T_fixed_moving: np.ndarray) -> float:
        """How well a registration pins its translation, for each point of ``moving``: the pairs'
        constraint (:func:`helpers.slam.registration.icp.pairing`, the weakest over the strongest direction of their
        normals) times the share of ``moving``'s points paired. Pairs over half the scan pin half as much
        as the whole scan over the same ground would. A revisit's first scan, seeing only the edge of the
        old ground, paired 42-47 % of itself on Autzen at 150 m and on sparse19-140, with constraints
        just above ``min_constraint``, and those loops slid 1-2 m along the track
        (``benchmarks/README.md``)."""
        overlap, constraint = _icp.pairing(self.ready(moving), self.ready(fixed), T_fixed_moving, self.inlier_distance)
        return overlap * constraint


def icp_with(metric: str, inlier_distance: float, max_iterations: int, tolerance: float, backend: str) -> IcpService:
    """An :class:`IcpService` with these settings (the name notebooks 5 and its solutions call)."""
    return IcpService(
        metric=metric,
        inlier_distance=inlier_distance,
        tolerance=tolerance,
        backend=backend,
        max_iterations=max_iterations,
    )


def surface_normals(points: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) of a cloud, from :data:`SURFACE_NEIGHBORS` neighbours."""
    from helpers.slam.registration.features import to_cloud

    return np.asarray(to_cloud(points, normals_knn=SURFACE_NEIGHBORS).normals)


def surface_rmse(
    moving: np.ndarray, fixed, T_fixed_moving: np.ndarray, inlier_distance: float, normals=None, nearest=None
):
    """RMS distance (m) from the moved points to the fixed cloud's *surface*:
    each moved point is paired with its nearest fixed point (pairs farther
    than ``inlier_distance`` are ignored) and measured along that point's
    normal.

    Why not the point-to-point RMSE the reference reports: the lidar's rows
    lie far apart along the track, farther than the spacing of the points
    across it, so two perfectly aligned scans taken between two rows have
    points about half a row from their nearest neighbours, and a point-to-point
    RMSE can be lower when they are out of line. Measured along the normals,
    the error grows with the misalignment (tests/test_loopclosure.py checks it
    on the default flight). ``normals`` of ``fixed`` may be given when they
    are already known; a ``fixed`` made ready for ICP
    (:class:`helpers.slam.registration.icp.IcpCloud` with normals) brings its own normals and k-d tree, and ``nearest``
    (:attr:`.icp.IcpResult.nearest`) the pass over that tree an alignment made at ``T_fixed_moving``.
    """
    moved = transform_points(moving, T_fixed_moving)
    if isinstance(fixed, _icp.IcpCloud):
        squared, nearest = fixed.nearest(moved) if nearest is None else nearest
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
