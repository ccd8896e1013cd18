"""Trajectory error measures, shaped like evo's: the raw per-pose (or per-pair)
errors are kept beside their statistics, and every figure names its unit.

Both trajectories are (N, 4, 4) sensor poses in the map frame, pose ``i`` of
one matching pose ``i`` of the other; the estimate is anchored on the first
ground-truth pose (as the reference does), so no alignment is applied.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from helpers.errors import SlamError
from helpers.geometry import relative_pose_error

FALSE_LOOP_M = 1.0  # a loop edge farther than this from the truth is false ...
FALSE_LOOP_DEG = 2.0  # ... or turned by more than this


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of a set of errors, in ``unit``."""

    errors: np.ndarray  # the raw errors
    unit: str

    @property
    def rmse(self) -> float:
        return float(np.sqrt(np.mean(self.errors**2)))

    @property
    def mean(self) -> float:
        return float(np.mean(self.errors))

    @property
    def median(self) -> float:
        return float(np.median(self.errors))

    @property
    def max(self) -> float:
        return float(np.max(self.errors))

    def __str__(self) -> str:
        return f"RMSE {self.rmse:.3f} {self.unit} (mean {self.mean:.3f}, max {self.max:.3f})"


@dataclass(frozen=True)
class RelativeError:
    """Relative pose error over ``delta``-step pairs."""

    delta: int
    translation: ErrorStats  # m
    rotation: ErrorStats  # deg

    def __str__(self) -> str:
        return f"RPE over {self.delta} step(s): translation {self.translation}, rotation {self.rotation}"


def ate(estimated, ground_truth) -> ErrorStats:
    """Absolute trajectory error: distance (m) between estimated and true
    positions, pose by pose; ``.errors`` holds the (N,) distances."""
    est, gt = _check_pair(estimated, ground_truth)
    return ErrorStats(np.linalg.norm(est[:, :3, 3] - gt[:, :3, 3], axis=1), "m")


def rpe(estimated, ground_truth, delta: int = 1) -> RelativeError:
    """Relative pose error over pairs ``(i, i + delta)``.

    For each pair the estimated relative motion ``inv(E_i) E_{i+delta}`` is
    compared with the true one ``inv(G_i) G_{i+delta}``; the error transform
    ``inv(true) @ estimated`` gives a translation error (its length, m) and a
    rotation error (its angle, deg).
    """
    est, gt = _check_pair(estimated, ground_truth)
    if not isinstance(delta, (int, np.integer)) or delta < 1:
        raise SlamError(f"the RPE step must be a positive integer, got {delta!r}")
    if delta >= len(est):
        raise SlamError(f"the RPE step {delta} needs more than {delta} poses, got {len(est)}")
    rel_est = np.linalg.inv(est[:-delta]) @ est[delta:]
    rel_gt = np.linalg.inv(gt[:-delta]) @ gt[delta:]
    translation, rotation = relative_pose_error(rel_gt, rel_est)
    return RelativeError(int(delta), ErrorStats(translation, "m"), ErrorStats(rotation, "deg"))


def _check_pair(estimated, ground_truth) -> tuple[np.ndarray, np.ndarray]:
    est = np.asarray(estimated, dtype=np.float64)
    gt = np.asarray(ground_truth, dtype=np.float64)
    for name, poses in (("estimated", est), ("ground-truth", gt)):
        if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) == 0:
            raise SlamError(f"the {name} trajectory must be an N x 4 x 4 array of poses, got shape {poses.shape}")
        if not np.isfinite(poses).all():
            raise SlamError(f"the {name} trajectory contains NaN or infinite values")
    if len(est) != len(gt):
        raise SlamError(f"the trajectories differ in length: {len(est)} estimated, {len(gt)} ground-truth poses")
    return est, gt


def json_safe(figures: dict) -> dict:
    """A copy of ``figures`` that strict JSON can hold: every NaN or infinite
    number (a figure nobody can read) becomes None, written as ``null``.

    A run with such a figure is not one to trust: if any was found,
    ``"trusted"`` becomes False and ``figures["health"]["problems"]`` (when
    present) names them. Write the result with ``json.dumps(...,
    allow_nan=False)``, which then never meets a bare ``NaN``.
    """
    bad: list[str] = []

    def clean(value, where: str):
        if isinstance(value, dict):
            return {key: clean(v, f"{where}.{key}" if where else str(key)) for key, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [clean(v, f"{where}[{i}]") for i, v in enumerate(value)]
        if isinstance(value, (float, np.floating)):
            if not np.isfinite(value):
                bad.append(where)
                return None
            return float(value)
        return value

    safe = clean(figures, "")
    if bad:
        safe["trusted"] = False
        health = safe.get("health")
        if isinstance(health, dict) and isinstance(health.get("problems"), list):
            health["problems"].append(f"figures that are not finite numbers (written as null): {', '.join(bad)}.")
    return safe


def is_false_loop(error_m: float, error_deg: float) -> bool:
    """The one rule of a false loop edge: off by more than :data:`FALSE_LOOP_M` or :data:`FALSE_LOOP_DEG`."""
    return error_m > FALSE_LOOP_M or error_deg > FALSE_LOOP_DEG
