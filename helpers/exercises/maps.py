"""Checks for the exercises of notebook 7 (map comparison).

Each check computes its own answer from the data (a rigid fit by SVD, maps
merged as the pipeline merges them; the functions that compute answers are
private) and prints one line (see :func:`helpers.exercises.report`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from helpers.exercises.report import report, unanswered
from helpers.quality.metrics import ate
from helpers.slam.registration.msac import kabsch
from helpers.slam.submaps import build_submap

NO_ANSWER = "fill in the cell and run it again (a hint is folded under the exercise)"

ATE_TOLERANCE_M = 1e-3  # an aligned ATE this close to the check's is right
MAP_TOLERANCE_M = 1e-6  # a median map error this close to the check's is right


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


def _map_medians(clouds, poses, true_poses, ground_truth_map, grid_step: float) -> dict[str, float]:
    """The median map error (m) of the map built from ``clouds`` at ``poses`` with each rotation replaced by
    the true one ("true rotations"), and, to tell a slip from the answer, of the map at ``poses`` as they are
    ("as they are") and at the true positions with ``poses``' rotations ("true positions")."""
    poses, true_poses = np.asarray(poses, float), np.asarray(true_poses, float)
    true_rotations, true_positions = poses.copy(), true_poses.copy()
    true_rotations[:, :3, :3] = true_poses[:, :3, :3]
    true_positions[:, :3, :3] = poses[:, :3, :3]
    tree = cKDTree(ground_truth_map)
    built = {"true rotations": true_rotations, "as they are": poses, "true positions": true_positions}
    return {name: float(np.median(tree.query(build_submap(clouds, at, grid_step))[0])) for name, at in built.items()}


def check_true_rotation_map(median_m, clouds, poses, true_poses, ground_truth_map, grid_step: float) -> bool:
    """Exercise 7.2: ``median_m`` is the median distance from the map of ``clouds`` built at ``poses`` with
    every rotation replaced by the one of ``true_poses`` (positions kept; merged on ``grid_step``) to the
    nearest point of ``ground_truth_map``; the line compares it with the map at ``poses`` as they are."""
    hint = (
        "build the map at the poses with each rotation taken from true_poses and each position kept, "
        "then take the median distance from its points to the nearest ground-truth point"
    )
    if unanswered(median_m):
        return report(False, "", NO_ANSWER)
    median_m = float(median_m)
    medians = _map_medians(clouds, poses, true_poses, ground_truth_map, grid_step)
    if abs(median_m - medians["true rotations"]) <= MAP_TOLERANCE_M:
        if medians["true rotations"] < 0.8 * medians["as they are"]:
            fall = "falls by over a fifth: the rotations held most of the error"
        else:
            fall = "falls by less than a fifth, if at all: the tilt and the position errors partly undid each other"
        return report(True, f"with the true rotations the median error {fall}", "")
    if abs(median_m - medians["as they are"]) <= MAP_TOLERANCE_M:
        return report(False, "", "that is the map at the poses as they are: replace each rotation first")
    if abs(median_m - medians["true positions"]) <= MAP_TOLERANCE_M:
        return report(False, "", "that map has the true positions: keep the positions, replace the rotations")
    return report(False, "", hint)


def _as_poses(points: np.ndarray) -> np.ndarray:
    poses = np.tile(np.eye(4), (len(points), 1, 1))
    poses[:, :3, 3] = points
    return poses


def _centred_only(est: np.ndarray, gt: np.ndarray) -> float:
    moved = est - est.mean(axis=0) + gt.mean(axis=0)
    return float(np.sqrt(np.mean(np.sum((moved - gt) ** 2, axis=1))))
