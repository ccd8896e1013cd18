"""A scan taken while the drone moves, put back into one frame (KISS-ICP's constant-velocity deskew).

A lidar takes a scan's points one after the other over its period; the drone moves meanwhile, so a
point taken at time ``t`` lies in the sensor's frame of ``t``. Under a constant velocity the sensor's
motion from the scan's reference time ``r`` to ``t`` is ``Exp((t - r) xi)``, where ``Exp(xi)`` is its
motion over one period; the odometry's last step gives it. Each point is moved by that motion into
the frame of ``r``, the middle of the scan (its times normalised to [0, 1]), as KISS-ICP does, with
SE(3)'s exponential in closed form, vectorised over the points.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from helpers.errors import SlamError

REFERENCE = 0.5  # the scan's frame: the sensor's at the middle of its period


def normalised(times: np.ndarray) -> np.ndarray:
    """Per-point times as shares of the scan's own span, [0, 1] (all 0.5 when the span is zero)."""
    times = np.asarray(times, dtype=np.float64)
    if times.ndim != 1 or not np.all(np.isfinite(times)):
        raise SlamError(f"per-point times must be a finite vector, got shape {times.shape}")
    span = times.max() - times.min() if len(times) else 0.0
    return np.full(len(times), REFERENCE) if span <= 0 else (times - times.min()) / span


def deskew(points: np.ndarray, times: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """``points`` (N, 3), each taken at ``times`` (N,) in [0, 1] over the scan, moved into the sensor's frame
    at :data:`REFERENCE`; ``motion`` (4 x 4) is the sensor's motion over one scan period, ``T_start_end``."""
    points = np.asarray(points, dtype=np.float64)
    s = np.asarray(times, dtype=np.float64) - REFERENCE
    if len(s) != len(points):
        raise SlamError(f"{len(points)} points but {len(s)} times")
    omega, v = _log(np.asarray(motion, dtype=np.float64))
    rotations, translations = _exp(s, omega, v)
    return rotations.apply(points) + translations


def per_period(step: np.ndarray, periods: float) -> np.ndarray:
    """The motion over one period when ``step`` (4 x 4) spans ``periods`` of them (any positive number) at a
    constant velocity."""
    omega, v = _log(np.asarray(step, dtype=np.float64))
    rotation, translation = _exp(np.array([1.0 / periods]), omega, v)
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation.as_matrix()[0], translation[0]
    return out


def _coefficients(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(1 - cos x) / x^2 and (x - sin x) / x^3, with their series near 0."""
    small = np.abs(theta) < 1e-4
    x = np.where(small, 1.0, theta)
    first = np.where(small, 0.5 - theta**2 / 24, (1 - np.cos(x)) / x**2)
    second = np.where(small, 1 / 6 - theta**2 / 120, (x - np.sin(x)) / x**3)
    return first, second


def _log(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SE(3)'s logarithm of ``T``: (rotation vector, translational part v with ``t = V(omega) v``)."""
    omega = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    theta = np.linalg.norm(omega)
    first, second = _coefficients(np.array([theta]))
    W = _hat(omega)
    V = np.eye(3) + first[0] * W + second[0] * W @ W
    return omega, np.linalg.solve(V, T[:3, 3])


def _exp(s: np.ndarray, omega: np.ndarray, v: np.ndarray):
    """SE(3)'s exponential of ``s_i (omega, v)`` for every ``s_i``: (rotations, translations (N, 3))."""
    theta = np.linalg.norm(omega)
    first, second = _coefficients(s * theta)
    W = _hat(omega)
    Wv, WWv = W @ v, W @ (W @ v)
    translations = s[:, None] * v + (first * s**2)[:, None] * Wv + (second * s**3)[:, None] * WWv
    return Rotation.from_rotvec(s[:, None] * omega), translations


def _hat(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
