"""Stage 3c: ICP refinement of a coarse fit (the reference's ``pcregistericp``),
with clouds made ready once (normals, generalized-ICP covariances).

A transform ``T`` (4 x 4) maps *moving* (source) points onto *fixed* (target)
points: ``fixed ~ T[:3, :3] @ moving + T[:3, 3]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from .config import METRICS
from .errors import SlamError
from .features import to_cloud
from .geometry import check_points
from .registration import SAMPLE_SIZE

ICP_NORMAL_NEIGHBORS = 20  # neighbours for the normals point-to-plane and generalized ICP need (Open3D's own choice)
GICP_EPSILON = 1e-3  # generalized ICP: a point's covariance is this thin across its plane (Open3D's default)


@dataclass(frozen=True, eq=False)
class IcpCloud:
    """A cloud made ready for ICP once, so that every pair it is part of reuses it.

    ``cloud`` is the Open3D cloud of ``points`` with what ``metric`` needs:
    normals from ``ICP_NORMAL_NEIGHBORS`` neighbours (point-to-plane,
    plane-to-plane) and the generalized-ICP covariances (plane-to-plane).
    Open3D's generalized ICP otherwise re-estimates normals and covariances of
    both clouds at every call, and a scan is the moving cloud of one pair and
    the fixed cloud of the next.
    """

    points: np.ndarray  # (N, 3)
    cloud: o3d.geometry.PointCloud
    metric: str


def icp_cloud(points, metric: str = "plane-to-plane") -> IcpCloud:
    """``points`` (N, 3) made ready for :func:`refine_icp` with ``metric``.

    For plane-to-plane the covariances are those Open3D's generalized ICP
    would compute itself (normals from ``ICP_NORMAL_NEIGHBORS`` neighbours,
    then ``R diag(eps, 1, 1) R^T`` with ``R`` turning the x axis onto the
    normal, ``eps = GICP_EPSILON``), so a prepared cloud registers exactly
    like a bare one.
    """
    if metric not in METRICS:
        raise SlamError(f"unknown ICP metric {metric!r}: use one of {', '.join(METRICS)}")
    points = check_points(points, "the ICP cloud", minimum=SAMPLE_SIZE)
    cloud = to_cloud(points)
    if metric != "point-to-point":
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(ICP_NORMAL_NEIGHBORS))
    if metric == "plane-to-plane":
        cloud.covariances = o3d.utility.Matrix3dVector(gicp_covariances(np.asarray(cloud.normals)))
    return IcpCloud(points, cloud, metric)


def gicp_covariances(normals: np.ndarray, epsilon: float = GICP_EPSILON) -> np.ndarray:
    """(N, 3, 3) plane-like covariances from unit normals, as Open3D's generalized ICP builds them.

    ``R diag(epsilon, 1, 1) R^T`` where ``R = I + [v]x + [v]x^2 / (1 + c)``
    (``v = e1 x n``, ``c = e1 . n``) turns the x axis onto the normal; like
    Open3D, ``R = I`` when ``c < -0.99``.
    """
    n = np.asarray(normals, dtype=np.float64)
    c = n[:, 0]
    v = np.column_stack([np.zeros(len(n)), -n[:, 2], n[:, 1]])  # e1 x n
    skew = np.zeros((len(n), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    flip = c < -0.99
    factor = np.where(flip, 0.0, 1.0 / np.where(flip, 1.0, 1.0 + c))
    rot = np.eye(3) + skew + (skew @ skew) * factor[:, None, None]
    rot[flip] = np.eye(3)
    return (rot * np.array([epsilon, 1.0, 1.0])) @ np.swapaxes(rot, 1, 2)


def refine_icp(
    moving,
    fixed,
    init,
    metric: str,
    inlier_distance: float,
    max_iterations: int,
    tolerance: float,
) -> tuple[np.ndarray, float]:
    """Refine ``init`` (4 x 4, moving -> fixed) by ICP; returns ``(T, rmse)``.

    ``moving`` and ``fixed`` are (N, 3) arrays or :class:`IcpCloud` made by
    :func:`icp_cloud` for the same metric (then nothing per cloud is
    recomputed). ``metric``: ``point-to-point``, ``point-to-plane`` (fixed-cloud
    normals from ``ICP_NORMAL_NEIGHBORS`` neighbours) or ``plane-to-plane``
    (generalized ICP). Pairs farther apart than ``inlier_distance`` (m) are
    ignored. ICP stops after ``max_iterations`` or when, from one iteration to
    the next, the inlier fraction changes by less than ``tolerance`` and the
    RMSE by less than ``tolerance`` metres (Open3D compares the plain
    differences). The pipeline takes all four from ``[registration]``.

    ``rmse`` (m) is always the same measure, whatever the metric: the root
    mean square distance from each moved moving point to its nearest fixed
    point, over the pairs closer than ``inlier_distance``; ``inf`` if none is.
    Open3D computes it after its last update, at the transform it returns, so
    no second nearest-neighbour pass is needed.
    """
    init = np.asarray(init, dtype=np.float64)
    if metric not in METRICS:
        raise SlamError(f"unknown ICP metric {metric!r}: use one of {', '.join(METRICS)}")
    if init.shape != (4, 4) or not np.isfinite(init).all():
        raise SlamError(f"the initial transform must be a finite 4 x 4 matrix, got shape {init.shape}")
    source = _ready(moving, "the moving cloud", metric)
    target = _ready(fixed, "the fixed cloud", metric)
    if not (np.isfinite(inlier_distance) and inlier_distance > 0):
        raise SlamError(f"the ICP inlier distance must be a positive number of metres, got {inlier_distance!r}")
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise SlamError(f"the ICP tolerance must be zero or a positive number, got {tolerance!r}")

    reg = o3d.pipelines.registration
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
    return transform, rmse


def _ready(cloud, what: str, metric: str) -> o3d.geometry.PointCloud:
    """The Open3D cloud ICP with ``metric`` needs, from an array or an :class:`IcpCloud`."""
    if isinstance(cloud, IcpCloud):
        if cloud.metric != metric:
            raise SlamError(f"{what} was prepared for {cloud.metric} ICP, not {metric}")
        return cloud.cloud
    return icp_cloud(check_points(cloud, what, minimum=SAMPLE_SIZE), metric).cloud


def icp_rmse(source, target, transform: np.ndarray, inlier_distance: float) -> float:
    """Point-to-point RMSE (m) of the pairs closer than ``inlier_distance`` after ``transform``.

    ``source`` and ``target`` are (N, 3) arrays or Open3D clouds.
    """
    if isinstance(source, np.ndarray):
        source = to_cloud(check_points(source, "the moving cloud"))
    if isinstance(target, np.ndarray):
        target = to_cloud(check_points(target, "the fixed cloud"))
    evaluation = o3d.pipelines.registration.evaluate_registration(source, target, inlier_distance, transform)
    if len(evaluation.correspondence_set) == 0:
        return float("inf")
    return float(evaluation.inlier_rmse)
