"""Checks for the exercises of notebook 7 (map comparison).

Each check computes its own answer from the data (a rigid fit by SVD, the
package's map error; the functions that compute answers are private) and
prints one line (see :func:`helpers.exercises.report`).
"""

from __future__ import annotations

import numpy as np

from helpers.exercises.report import report, unanswered
from helpers.quality.evaluation import map_errors
from helpers.quality.metrics import ate
from helpers.slam.registration.msac import kabsch

NO_ANSWER = "fill in the cell and run it again (a hint is folded under the exercise)"

ATE_TOLERANCE_M = 1e-3  # an aligned ATE this close to the check's is right
MAP_TOLERANCE_M = 1e-6  # a median map error this close to the package's is right


def positions(trajectory) -> np.ndarray:
    """(N, 3) positions of (N, 4, 4) poses, or the (N, 3) positions themselves."""
    trajectory = np.asarray(trajectory, dtype=float)
    return trajectory[:, :3, 3] if trajectory.ndim == 3 else trajectory


def _rigid_fit(moving, fixed) -> tuple[np.ndarray, np.ndarray]:
    """The rotation R and translation t that bring the (N, 3) points ``moving``
    closest to ``fixed`` in the least-squares sense (the package's Kabsch,
    :func:`helpers.slam.registration.msac.kabsch`: by SVD, no scale, never a mirror)."""
    T_fixed_moving = kabsch(positions(moving), positions(fixed))
    return T_fixed_moving[:3, :3], T_fixed_moving[:3, 3]


def _aligned_ate(estimated, ground_truth) -> float:
    """ATE RMSE (m) of the estimated positions after the best rigid motion onto the truth."""
    est, gt = positions(estimated), positions(ground_truth)
    rotation, translation = _rigid_fit(est, gt)
    return float(np.sqrt(np.mean(np.sum((est @ rotation.T + translation - gt) ** 2, axis=1))))


def check_aligned_ate(ate_m, estimated, ground_truth) -> bool:
    """Exercise 7.1: ``ate_m`` is the ATE RMSE after a rigid alignment of ``estimated`` onto ``ground_truth``."""
    hint = "not the ATE after the best rigid motion: compare your rotation with a known one on a small case"
    if unanswered(ate_m):
        return report(False, "", NO_ANSWER)
    ate_m = float(ate_m)
    est, gt = positions(estimated), positions(ground_truth)
    truth = _aligned_ate(est, gt)
    anchored = ate(_as_poses(est), _as_poses(gt))
    if abs(ate_m - truth) <= ATE_TOLERANCE_M:
        lower = "lower than" if truth < anchored.rmse - ATE_TOLERANCE_M else "the same as"
        return report(True, f"aligned, the ATE is {lower} the anchored one of helpers.quality.metrics.ate", hint)
    if abs(ate_m - anchored.rmse) <= ATE_TOLERANCE_M:
        return report(False, "", "that is the anchored ATE (helpers.quality.metrics.ate): align the trajectories first")
    rotation, translation = _rigid_fit(est, gt)
    distances = np.linalg.norm(est @ rotation.T + translation - gt, axis=1)
    if abs(ate_m - distances.mean()) <= ATE_TOLERANCE_M:
        return report(False, "", "that is the mean distance: the ATE is the root of the mean squared distance")
    if abs(ate_m - _centred_only(est, gt)) <= ATE_TOLERANCE_M:
        return report(False, "", "centred but not turned: rotate the estimate by the SVD's rotation too")
    return report(False, "", hint)


def check_median_map_error(median_m, estimated_map, ground_truth_map) -> bool:
    """Exercise 7.2: ``median_m`` is the median distance from the points of
    ``estimated_map`` to their nearest neighbours in ``ground_truth_map``."""
    hint = "not the median distance to the nearest ground-truth point: which cloud did the tree hold?"
    if unanswered(median_m):
        return report(False, "", NO_ANSWER)
    median_m = float(median_m)
    errors = map_errors(estimated_map, ground_truth_map)
    if abs(median_m - errors.median) <= MAP_TOLERANCE_M:
        return report(True, "the median nearest-neighbour distance, as map_errors finds it", hint)
    if abs(median_m - errors.mean) <= MAP_TOLERANCE_M:
        return report(False, "", "that is the mean distance: take the median")
    return report(False, "", hint)


def _as_poses(points: np.ndarray) -> np.ndarray:
    poses = np.tile(np.eye(4), (len(points), 1, 1))
    poses[:, :3, 3] = points
    return poses


def _centred_only(est: np.ndarray, gt: np.ndarray) -> float:
    moved = est - est.mean(axis=0) + gt.mean(axis=0)
    return float(np.sqrt(np.mean(np.sum((moved - gt) ** 2, axis=1))))
