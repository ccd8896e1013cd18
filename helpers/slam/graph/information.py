"""How sure a registration is: the information matrix of an edge (stage 3c, read by stage 6 and the health check).

ICP minimises a sum of squared residuals; near its solution the cost is a
quadratic bowl whose curvature, the Hessian ``H``, says how sharply each
direction of motion is pinned. On flat ground a slide along the ground
changes no residual, so ``H`` is about zero along it: the registration does
not know where it is along the track. ``H`` divided by the variance of one
residual is the registration's information (the inverse of its
covariance), as if each pair of points were an independent measurement.

They are not independent (neighbouring points share their grid cell, their
normal and the same small surface errors), so a raw information is
over-confident by a large factor. :func:`calibrated` multiplies it by
``[pose_graph] information_scale``, found on flights whose truth is known
(``benchmarks/bench_information.py``), and adds a floor of
``[pose_graph] min_sigma_m`` / ``min_sigma_deg`` to its covariance, so no
edge claims to be surer than a registration ever is.

Six-vectors and matrices here are TRANSLATION FIRST, ``[x y z rx ry rz]``,
in the MOVING cloud's frame: the perturbation ``T_fixed_moving @ exp(xi)``,
the convention of GTSAM's between factor and of small_gicp's Hessian.
"""

from __future__ import annotations

import numpy as np

from helpers.geometry import transform_points

MIN_PAIRS = 6  # fewer pairs than unknowns: no information
MIN_RESIDUAL = 1e-3  # m: a residual variance is never taken below this sigma (exact synthetic clouds)
MAX_SIGMA = 1e3  # m or rad: the loosest direction an information may leave (keeps the graph's matrices finite)
# Our 6-vectors and 6 x 6 matrices are translation first (x y z rx ry rz); GTSAM's and small_gicp's are rotation
# first. Indexing with this swaps the halves, either way (the permutation is its own inverse).
SWAP_ROTATION_TRANSLATION = np.array([3, 4, 5, 0, 1, 2])


def swap_blocks(matrix: np.ndarray) -> np.ndarray:
    """A 6 x 6 matrix with its rotation and translation rows and columns swapped (either way round)."""
    return np.asarray(matrix, dtype=float)[np.ix_(SWAP_ROTATION_TRANSLATION, SWAP_ROTATION_TRANSLATION)]


def plane_information(moving_points, fixed_points, fixed_normals, T_fixed_moving, inlier_distance, nearest):
    """The point-to-plane information (6 x 6, translation first) of the registration ``T_fixed_moving``.

    Each moving point is paired with its nearest fixed point (``nearest``:
    points -> (squared distances, indices), the fixed cloud's k-d tree);
    pairs farther than ``inlier_distance`` (m) are ignored. A pair's residual
    is its distance along the fixed normal ``n``; moving the moving cloud by
    ``exp(xi)`` changes it by ``J xi`` with ``J = [m, p x m]``, ``p`` the
    moving point and ``m = R^T n`` the normal seen from the moving frame.
    The information is ``sum(J^T J) / s2``, ``s2`` the mean squared residual.
    None with fewer than :data:`MIN_PAIRS` pairs.
    """
    T = np.asarray(T_fixed_moving, dtype=float)
    moved = transform_points(moving_points, T)
    squared, index = nearest(moved)
    paired = squared < inlier_distance**2
    if paired.sum() < MIN_PAIRS:
        return None
    normals = fixed_normals[index[paired]]
    residual = np.einsum("ij,ij->i", moved[paired] - fixed_points[index[paired]], normals)
    m = normals @ T[:3, :3]
    J = np.hstack([m, np.cross(moving_points[paired], m)])
    return (J.T @ J) / max(float(np.mean(residual**2)), MIN_RESIDUAL**2)


def hessian_information(H, error: float, num_inliers: int):
    """small_gicp's Hessian ``H`` (rotation first) as an information (translation first).

    small_gicp's ``error`` is half the sum of its whitened squared residuals
    over ``num_inliers`` pairs; ``H`` is scaled by their mean, as
    :func:`plane_information` divides by the residual variance. None without pairs.
    """
    if num_inliers < MIN_PAIRS or not error > 0:
        return None
    H = swap_blocks(H)
    return H / max(2.0 * error / num_inliers, MIN_RESIDUAL**2)


def covariance(information) -> np.ndarray:
    """The covariance of an information matrix, directions it leaves loose capped at :data:`MAX_SIGMA`."""
    info = 0.5 * (np.asarray(information, dtype=float) + np.asarray(information, dtype=float).T)
    values, vectors = np.linalg.eigh(info)
    values = np.maximum(values, MAX_SIGMA**-2)
    return (vectors / values) @ vectors.T


def calibrated(information, scale: float, min_sigmas) -> np.ndarray:
    """``information`` times ``scale``, its covariance floored by ``min_sigmas`` (x y z m, rx ry rz rad)."""
    cov = covariance(np.asarray(information, dtype=float) * scale) + np.diag(np.asarray(min_sigmas, float) ** 2)
    out = np.linalg.inv(cov)
    return 0.5 * (out + out.T)


def weakest(information) -> tuple[float, np.ndarray]:
    """The sigma (m) of the translation direction an edge pins least, and that unit direction (x y z).

    The translation block of the covariance (rotations free): its largest
    eigenvalue is the variance along the direction the registration knows least.
    """
    block = covariance(information)[:3, :3]
    values, vectors = np.linalg.eigh(block)
    return float(np.sqrt(max(values[-1], 0.0))), vectors[:, -1]


def whitened(error, information) -> float:
    """The Mahalanobis norm (in sigmas) of a six-vector ``error`` (translation first) under ``information``."""
    e = np.asarray(error, dtype=float)
    return float(np.sqrt(max(e @ np.asarray(information, dtype=float) @ e, 0.0)))


def blended(guess, measured, information, prior_sigmas) -> np.ndarray:
    """The motion that best agrees with both a registration and a prior guess.

    ``measured`` (4 x 4) is what ICP found, sure of it as its ``information``
    says (6 x 6, translation first); ``guess`` (4 x 4) is the prior, sure of
    itself to ``prior_sigmas`` (x y z m, rx ry rz rad). With ``d`` the
    registration's offset from the guess (a tangent six-vector) the answer is
    the guess moved by ``(H + P)^-1 H d``: the minimum of the two quadratic
    costs. Along what the registration pins (``H`` large) it is the
    registration; along what it does not (a slide over flat ground) it stays
    with the guess.
    """
    import gtsam  # the one function here that needs it

    start = gtsam.Pose3(np.asarray(guess, dtype=float))
    offset = gtsam.Pose3.Logmap(start.between(gtsam.Pose3(np.asarray(measured, dtype=float))))  # rotation first
    d = np.concatenate([offset[3:], offset[:3]])
    H = np.asarray(information, dtype=float)
    prior = np.diag(1.0 / np.asarray(prior_sigmas, dtype=float) ** 2)
    step = np.linalg.solve(H + prior, H @ d)
    return start.compose(gtsam.Pose3.Expmap(np.concatenate([step[3:], step[:3]]))).matrix()
