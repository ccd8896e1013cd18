"""Points and poses: the checks every stage runs on its input, and the few
operations several stages share.

A cloud is an (N, 3) float64 array of points, in metres. A pose is a (4, 4)
rigid transform ``T_map_sensor``: it carries points from the sensor frame into
the map frame, ``p_map = R @ p_sensor + t``. A relative pose ``T_ij`` between
two poses says ``pose_j = pose_i @ T_ij``.
"""

from __future__ import annotations

import numpy as np

from helpers.errors import SlamError

RIGID_TOLERANCE = 1e-5  # how far a pose's rotation may be from orthonormal, and its last row from 0 0 0 1


def check_points(points, what: str = "point cloud", minimum: int = 1) -> np.ndarray:
    """``points`` as a float64 (N, 3) array, or a SlamError saying what is wrong."""
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise SlamError(f"{what} must be an N x 3 array of points, got shape {array.shape}")
    if len(array) < minimum:
        raise SlamError(f"{what} has {len(array)} points, at least {minimum} are needed")
    if not np.isfinite(array).all():
        raise SlamError(f"{what} contains NaN or infinite coordinates")
    return array


def check_pose(pose, what: str = "pose") -> np.ndarray:
    """``pose`` as a float (4, 4) rigid transform, or a SlamError saying what is wrong."""
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (4, 4):
        raise SlamError(f"{what} must be a 4 x 4 matrix, got shape {pose.shape}")
    if not np.all(np.isfinite(pose)):
        raise SlamError(f"{what} contains NaN or infinite values")
    rot = pose[:3, :3]
    rigid = np.allclose(pose[3], [0, 0, 0, 1], atol=RIGID_TOLERANCE)
    rigid &= np.allclose(rot.T @ rot, np.eye(3), atol=RIGID_TOLERANCE) and np.linalg.det(rot) > 0
    if not rigid:
        raise SlamError(f"{what} is not a rigid transform (rotation not orthonormal or last row not 0 0 0 1)")
    return pose


def transform_points(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """The (N, 3) ``points`` moved by the (4, 4) ``pose``: ``R @ p + t`` for
    every row (from the pose's source frame into its target frame)."""
    return points @ pose[:3, :3].T + pose[:3, 3]


def rotation_angle_deg(transforms: np.ndarray) -> np.ndarray:
    """The rotation angle (degrees, 0 to 180) of each (..., 4, 4) transform
    (or (..., 3, 3) rotation), from the trace: ``cos a = (tr R - 1) / 2``."""
    rotation = np.asarray(transforms)[..., :3, :3]
    cos = (np.trace(rotation, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def relative_pose_error(true_relative: np.ndarray, estimated_relative: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far an estimated relative pose is from the true one: the error
    transform ``inv(true) @ estimated`` as its translation length (m) and its
    rotation angle (deg). Takes (4, 4) or (K, 4, 4) arrays; returns scalars or (K,) arrays."""
    error = np.linalg.inv(true_relative) @ estimated_relative
    return np.linalg.norm(error[..., :3, 3], axis=-1), rotation_angle_deg(error)


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the cross-product matrices ``[v]x`` of (..., 3) vectors: ``[v]x @ w = v x w``."""
    v = np.asarray(v, dtype=np.float64)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def adjoint(T: np.ndarray) -> np.ndarray:
    """GTSAM's adjoint of the (..., 4, 4) poses ``T``, rotation first: ``[[R, 0], [[t]x R, R]]``; it carries
    a tangent six-vector (a perturbation) from the frame after ``T`` to the frame before it."""
    R = T[..., :3, :3]
    out = np.zeros(T.shape[:-2] + (6, 6))
    out[..., :3, :3] = out[..., 3:, 3:] = R
    out[..., 3:, :3] = skew(T[..., :3, 3]) @ R
    return out
