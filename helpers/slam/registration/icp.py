"""Stage 3c: ICP refinement of a coarse fit (the reference's ``pcregistericp``),
with clouds made ready once (normals, generalized-ICP covariances, a k-d tree).

Two back ends run the same three metrics: small_gicp (the default; parallel
GICP and k-d trees made for this job) and Open3D (the ICP the tutorial
started with, kept reachable with ``[registration] icp_backend = "open3d"``).

Clouds are *moving* and *fixed* here, and a transform is named by its
frames (the package's rule): ``T_fixed_moving`` (4 x 4) carries moving
points into the fixed cloud's frame, ``fixed ~ T[:3, :3] @ moving + T[:3, 3]``
(small_gicp calls the two ``source`` and ``target``: ``T_target_source``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import open3d as o3d
import small_gicp

from helpers.config.pose_graph import INFORMATION_SOURCES
from helpers.config.tables import ICP_BACKENDS, METRICS
from helpers.errors import SlamError
from helpers.geometry import check_points, skew, transform_points
from helpers.slam.graph.information import hessian_information, plane_information
from helpers.slam.registration.features import to_cloud
from helpers.slam.registration.msac import SAMPLE_SIZE
from helpers.threads import threads  # small_gicp's k-d trees, covariances and searches; its alignment: ALIGN_THREADS

ICP_NORMAL_NEIGHBORS = 20  # neighbours for the normals point-to-plane and generalized ICP need (Open3D's own choice)
GICP_EPSILON = 1e-3  # generalized ICP: a point's covariance is this thin across its plane (Open3D's default)
SMALL_GICP_TYPES = {"point-to-point": "ICP", "point-to-plane": "PLANE_ICP", "plane-to-plane": "GICP"}
# Below this :func:`pairing` constraint ICP cannot tell a slide along the ground (a good step lies well above it):
# the health report counts such steps, and the registration trusts no jump on them.
WEAK_CONSTRAINT = 0.005


@dataclass(frozen=True, eq=False)
class IcpResult:
    """A refined registration. It unpacks as ``T_fixed_moving, rmse`` (what :func:`refine_icp` always
    returned); ``information`` (6 x 6, translation first, uncalibrated: :mod:`helpers.slam.graph.information`) says how
    sure it is, None for point-to-point ICP, whose cost pins no plane and gives no meaningful one.
    ``nearest``: the pass that measured ``rmse``, ``(squared distance, index)`` of the nearest fixed point
    of every moving point at ``T_fixed_moving`` (small_gicp only), for a score that needs the same pairs."""

    T_fixed_moving: np.ndarray
    rmse: float
    information: np.ndarray | None = None
    nearest: tuple[np.ndarray, np.ndarray] | None = None

    def __iter__(self):
        return iter((self.T_fixed_moving, self.rmse))

    def __getitem__(self, index):
        return (self.T_fixed_moving, self.rmse)[index]

    def __len__(self) -> int:
        return 2


ALIGN_THREADS = 1  # small_gicp's align on several threads sums in an order that changes from run to run (see below)


@dataclass(frozen=True, eq=False)
class IcpCloud:
    """A cloud made ready for ICP once, so that every pair it is part of reuses it.

    With the ``open3d`` back end, ``cloud`` is the Open3D cloud of ``points``
    with what ``metric`` needs: normals from ``ICP_NORMAL_NEIGHBORS``
    neighbours (point-to-plane, plane-to-plane) and the generalized-ICP
    covariances (plane-to-plane). With ``small_gicp``, ``cloud`` is its
    PointCloud with normals and covariances from as many neighbours, and
    ``tree`` its k-d tree. A scan is the moving cloud of one pair and the
    fixed cloud of the next, so neither is computed twice.
    """

    points: np.ndarray  # (N, 3)
    cloud: o3d.geometry.PointCloud | small_gicp.PointCloud
    metric: str
    backend: str = "open3d"
    tree: small_gicp.KdTree | None = None
    reach: float = 0.0  # m, the farthest point from the origin: how far a small rotation moves a point

    def nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For each of ``points`` (M, 3): squared distance (m²) to its nearest point here, and that point's index."""
        if self.tree is not None:
            index, squared = self.tree.batch_nearest_neighbor_search(points, num_threads=threads())
            return np.asarray(squared), np.asarray(index)
        distance, index = self._scipy_tree.query(points, workers=threads())
        return distance**2, index

    @cached_property
    def _scipy_tree(self):
        from scipy.spatial import cKDTree

        return cKDTree(self.points)

    @property
    def normals(self) -> np.ndarray:
        """(N, 3) unit normals (metrics other than point-to-point)."""
        if self.backend == "small_gicp":
            return self.cloud.normals()[:, :3]
        return np.asarray(self.cloud.normals)


def icp_cloud(points, metric: str, backend: str) -> IcpCloud:
    """``points`` (N, 3) made ready for :func:`refine_icp` with ``metric`` on ``backend``.

    For Open3D's plane-to-plane the covariances are those its generalized
    ICP would compute itself (normals from ``ICP_NORMAL_NEIGHBORS``
    neighbours, then ``R diag(eps, 1, 1) R^T`` with ``R`` turning the x axis
    onto the normal, ``eps = GICP_EPSILON``), so a prepared cloud registers
    exactly like a bare one. small_gicp estimates normals and covariances
    from the same number of neighbours in one pass.
    """
    if metric not in METRICS:
        raise SlamError(f"unknown ICP metric {metric!r}: use one of {', '.join(METRICS)}")
    if backend not in ICP_BACKENDS:
        raise SlamError(f"unknown ICP back end {backend!r}: use one of {', '.join(ICP_BACKENDS)}")
    points = check_points(points, "the ICP cloud", minimum=SAMPLE_SIZE)
    reach = float(np.sqrt((points**2).sum(axis=1).max()))
    if backend == "small_gicp":
        cloud = small_gicp.PointCloud(points)
        tree = small_gicp.KdTree(cloud, num_threads=threads())
        if metric != "point-to-point":
            small_gicp.estimate_normals_covariances(cloud, tree, ICP_NORMAL_NEIGHBORS, threads())
        return IcpCloud(points, cloud, metric, backend, tree, reach)
    cloud = to_cloud(points)
    if metric != "point-to-point":
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(ICP_NORMAL_NEIGHBORS))
    if metric == "plane-to-plane":
        cloud.covariances = o3d.utility.Matrix3dVector(gicp_covariances(np.asarray(cloud.normals)))
    return IcpCloud(points, cloud, metric, backend, None, reach)


def gicp_covariances(normals: np.ndarray, epsilon: float = GICP_EPSILON) -> np.ndarray:
    """(N, 3, 3) plane-like covariances from unit normals, as Open3D's generalized ICP builds them.

    ``R diag(epsilon, 1, 1) R^T`` where ``R = I + [v]x + [v]x^2 / (1 + c)``
    (``v = e1 x n``, ``c = e1 . n``) turns the x axis onto the normal; like
    Open3D, ``R = I`` when ``c < -0.99``.
    """
    n = np.asarray(normals, dtype=np.float64)
    c = n[:, 0]
    v = np.column_stack([np.zeros(len(n)), -n[:, 2], n[:, 1]])  # e1 x n
    cross = skew(v)
    flip = c < -0.99
    factor = np.where(flip, 0.0, 1.0 / np.where(flip, 1.0, 1.0 + c))
    rot = np.eye(3) + cross + (cross @ cross) * factor[:, None, None]
    rot[flip] = np.eye(3)
    return (rot * np.array([epsilon, 1.0, 1.0])) @ np.swapaxes(rot, 1, 2)


def refine_icp(
    moving,
    fixed,
    T_fixed_moving,
    *,
    metric: str,
    inlier_distance: float,
    max_iterations: int,
    tolerance: float,
    backend: str,
    information: str = "gicp",
) -> IcpResult:
    """Refine the guess ``T_fixed_moving`` (4 x 4) by ICP; returns the refined ``(T_fixed_moving, rmse)``
    as an :class:`IcpResult`, which also carries the registration's ``information``.

    ``moving`` and ``fixed`` are (N, 3) arrays or :class:`IcpCloud` made by
    :func:`icp_cloud` for the same metric and back end (then nothing per
    cloud is recomputed). ``metric``: ``point-to-point``, ``point-to-plane``
    (fixed-cloud normals from ``ICP_NORMAL_NEIGHBORS`` neighbours) or
    ``plane-to-plane`` (generalized ICP). Pairs farther apart than
    ``inlier_distance`` (m) are ignored. ICP stops after ``max_iterations``
    or once an iteration changes little: with Open3D, the inlier fraction by
    less than ``tolerance`` and the RMSE by less than ``tolerance`` metres;
    with small_gicp, the transform moves no point by more than about
    ``tolerance`` metres (its translation by less than ``tolerance``, its
    rotation by less than ``tolerance`` over the farthest point's range).
    :class:`helpers.slam.registration.icp_service.IcpService` takes all but the cap from ``[registration]``.

    ``rmse`` (m) is always the same measure, whatever the metric and back
    end: the root mean square distance from each moved moving point to its
    nearest fixed point, over the pairs closer than ``inlier_distance``;
    ``inf`` if none is. The result's ``information``, over the residual
    variance (:mod:`helpers.slam.graph.information`): with ``information="gicp"``
    small_gicp's Hessian of its cost, with ``"plane"`` (and always with
    Open3D) the point-to-plane Hessian of the final pairs.
    """
    init = np.asarray(T_fixed_moving, dtype=np.float64)
    if metric not in METRICS:
        raise SlamError(f"unknown ICP metric {metric!r}: use one of {', '.join(METRICS)}")
    if init.shape != (4, 4) or not np.isfinite(init).all():
        raise SlamError(f"the initial transform must be a finite 4 x 4 matrix, got shape {init.shape}")
    moving = _ready(moving, "the moving cloud", metric, backend)
    fixed = _ready(fixed, "the fixed cloud", metric, backend)
    if not (np.isfinite(inlier_distance) and inlier_distance > 0):
        raise SlamError(f"the ICP inlier distance must be a positive number of metres, got {inlier_distance!r}")
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise SlamError(f"the ICP tolerance must be zero or a positive number, got {tolerance!r}")
    if information not in INFORMATION_SOURCES:
        raise SlamError(f"unknown information source {information!r}: use one of {', '.join(INFORMATION_SOURCES)}")
    if backend == "small_gicp":
        return _small_gicp(moving, fixed, init, metric, inlier_distance, max_iterations, tolerance, information)

    reg = o3d.pipelines.registration
    source, target = moving.cloud, fixed.cloud  # Open3D's names
    criteria = reg.ICPConvergenceCriteria(tolerance, tolerance, int(max_iterations))
    if metric == "plane-to-plane":
        estimation = reg.TransformationEstimationForGeneralizedICP(GICP_EPSILON)
        result = reg.registration_generalized_icp(source, target, inlier_distance, init, estimation, criteria)
    else:
        estimation = (
            reg.TransformationEstimationPointToPlane()
            if metric == "point-to-plane"
            else reg.TransformationEstimationPointToPoint()
        )
        result = reg.registration_icp(source, target, inlier_distance, init, estimation, criteria)
    transform = np.array(result.transformation)
    rmse = float(result.inlier_rmse) if len(result.correspondence_set) else float("inf")
    information = None
    if metric != "point-to-point":
        information = plane_information(
            moving.points, fixed.points, fixed.normals, transform, inlier_distance, fixed.nearest
        )
    return IcpResult(transform, rmse, information)


def _small_gicp(moving: IcpCloud, fixed: IcpCloud, init, metric, inlier_distance, max_iterations, tolerance, source):
    """small_gicp's ICP (its target is our fixed cloud, its source the moving one),
    then the RMSE of :func:`refine_icp` and, if ``source`` is ``"plane"``, the
    point-to-plane information, both from one pass over the fixed cloud's k-d tree.

    The alignment runs on :data:`ALIGN_THREADS` (one) thread. On two, small_gicp
    adds up its Hessian in an order that changes from run to run: the same
    pair differs in the last bits, and a long flight's chain of steps carries
    them on (Autzen at 250 m ended its odometry at 7.56 and 7.74 m in two
    runs of the same code). The k-d tree and the covariances are built per
    point and stay on every core; so does the nearest-neighbour pass."""
    result = small_gicp.align(
        fixed.cloud,
        moving.cloud,
        fixed.tree,
        init_T_target_source=init,
        registration_type=SMALL_GICP_TYPES[metric],
        max_correspondence_distance=inlier_distance,
        num_threads=ALIGN_THREADS,
        max_iterations=int(max_iterations),
        rotation_epsilon=tolerance / max(moving.reach, 1.0),
        translation_epsilon=tolerance,
    )
    return scored_alignment(result, moving, fixed, metric, inlier_distance, source)


def scored_alignment(result, moving: IcpCloud, fixed: IcpCloud, metric, inlier_distance, source) -> IcpResult:
    """A small_gicp ``RegistrationResult`` of ``moving`` onto ``fixed`` as an :class:`IcpResult`: the RMSE of
    :func:`refine_icp` and the information (``source`` as :func:`_small_gicp` takes it), from one pass over the
    fixed cloud's k-d tree."""
    transform = np.array(result.T_target_source)
    squared, index = fixed.nearest(transform_points(moving.points, transform))
    paired = squared < inlier_distance**2
    rmse = float(np.sqrt(squared[paired].mean())) if paired.any() else float("inf")
    information = None
    if metric != "point-to-point" and source == "plane":
        information = plane_information(
            moving.points, fixed.points, fixed.normals, transform, inlier_distance, lambda _: (squared, index)
        )
    elif metric != "point-to-point":
        information = hessian_information(result.H, result.error, result.num_inliers)
    return IcpResult(transform, rmse, information, (squared, index))


def _ready(cloud, what: str, metric: str, backend: str) -> IcpCloud:
    """The cloud ICP with ``metric`` on ``backend`` needs, from an array or an :class:`IcpCloud`."""
    if isinstance(cloud, IcpCloud):
        if (cloud.metric, cloud.backend) != (metric, backend):
            raise SlamError(f"{what} was prepared for {cloud.metric} ICP on {cloud.backend}, not {metric} on {backend}")
        return cloud
    return icp_cloud(check_points(cloud, what, minimum=SAMPLE_SIZE), metric, backend)


def pairing(moving: IcpCloud, fixed: IcpCloud, T_fixed_moving: np.ndarray, inlier_distance: float):
    """``(overlap, constraint)`` of a registration, from one nearest-neighbour pass.

    ``overlap``: the share of ``moving``'s points that ``T_fixed_moving`` brings
    within ``inlier_distance`` (m) of ``fixed``. ``constraint``: how well
    those pairs pin a translation, the smallest over the largest eigenvalue
    of ``sum(n n^T)`` over the paired fixed normals (the translation part
    of point-to-plane ICP's information): about 0 on a plane, where ICP
    cannot tell a slide along it, up to 1 when surfaces face every way
    (nan without normals: point-to-point). On flat ground the steps with a
    low constraint are the ones that slide off the truth, which is why the
    health report and the loop closer test it (``benchmarks/`` measure how much).
    """
    T = T_fixed_moving
    squared, index = fixed.nearest(transform_points(moving.points, T))
    paired = squared < inlier_distance**2
    if not paired.any():
        return 0.0, 0.0
    if fixed.metric == "point-to-point":
        return float(paired.mean()), float("nan")
    normals = fixed.normals[index[paired]]
    eigen = np.linalg.eigvalsh(normals.T @ normals)
    # the smallest eigenvalue of this scatter is never below 0; rounding can leave it at -1e-17
    return float(paired.mean()), float(max(eigen[0], 0.0) / eigen[2]) if eigen[2] > 0 else 0.0


def icp_rmse(moving, fixed, T_fixed_moving: np.ndarray, inlier_distance: float) -> float:
    """Point-to-point RMSE (m) of the pairs closer than ``inlier_distance`` after ``T_fixed_moving``.

    ``moving`` and ``fixed`` are (N, 3) arrays or Open3D clouds.
    """
    if isinstance(moving, np.ndarray):
        moving = to_cloud(check_points(moving, "the moving cloud"))
    if isinstance(fixed, np.ndarray):
        fixed = to_cloud(check_points(fixed, "the fixed cloud"))
    evaluation = o3d.pipelines.registration.evaluate_registration(moving, fixed, inlier_distance, T_fixed_moving)
    if len(evaluation.correspondence_set) == 0:
        return float("inf")
    return float(evaluation.inlier_rmse)
