"""Checks for the exercises of notebook 6 (pose-graph optimisation).

* :func:`check_chain`: the 1-D chain with two loop edges, solved by least
  squares, against the least-squares positions computed here.
* :func:`check_three_poses`: a three-pose GTSAM graph built factor by factor,
  against :class:`helpers.slam.graph.optimizer.PoseGraph` fed the same measurements.
* :func:`check_loop_kernel`: one robust noise model for every loop edge, a
  wrong one among them, judged by the trajectory error against the true poses.

:func:`chain_closed_form` is notebook 6's closed form for one loop edge; the
functions that compute an exercise's answer are private.
"""

from __future__ import annotations

import gtsam
import numpy as np

from helpers.exercises.report import report, unanswered
from helpers.quality.metrics import ate
from helpers.slam.graph.information import SWAP_ROTATION_TRANSLATION
from helpers.slam.graph.optimizer import PoseGraph, information_from_sigmas

NO_ANSWER = "fill in the cell and run it again (a hint is folded under the exercise)"


def chain_closed_form(steps, loop, sigma_odometry: float, sigma_loop: float, start: float = 0.0) -> np.ndarray:
    """The least-squares positions of a 1-D chain with one loop edge from the
    first node to the last: each step gives up the same share of the
    misclosure ``m = sum(steps) - loop``,

        x_k = start + (steps[0] + ... + steps[k-1]) - k m s_o^2 / (n s_o^2 + s_l^2),

    with ``n`` steps, ``s_o`` the odometry sigma and ``s_l`` the loop's (node 0
    held at ``start``)."""
    steps = np.asarray(steps, dtype=float)
    n = len(steps)
    misclosure = steps.sum() - float(loop)
    share = misclosure * sigma_odometry**2 / (n * sigma_odometry**2 + sigma_loop**2)
    return start + np.concatenate([[0.0], np.cumsum(steps)]) - np.arange(n + 1) * share


def _chain_least_squares(steps, loops, sigma_odometry: float, start: float = 0.0) -> np.ndarray:
    """The positions of a 1-D chain (node 0 held at ``start``) with odometry
    ``steps`` and loop edges ``loops`` = [(i, j, measured j - i, sigma), ...],
    by weighted least squares."""
    steps = np.asarray(steps, dtype=float)
    n = len(steps)
    rows, values = [np.eye(n + 1)[0] * 1e4], [start * 1e4]
    for k, step in enumerate(steps):
        row = np.zeros(n + 1)
        row[k], row[k + 1] = -1.0, 1.0
        rows.append(row / sigma_odometry)
        values.append(step / sigma_odometry)
    for i, j, measured, sigma in loops:
        row = np.zeros(n + 1)
        row[int(i)], row[int(j)] = -1.0, 1.0
        rows.append(row / sigma)
        values.append(measured / sigma)
    return np.linalg.lstsq(np.array(rows), np.array(values), rcond=None)[0]


def check_chain(x, steps, loops, sigma_odometry: float, start: float = 0.0) -> bool:
    """Exercise 6.1: ``x`` holds the positions of the chain with odometry
    ``steps`` and every loop edge of ``loops`` = [(i, j, measured, sigma), ...]."""
    if unanswered(x):
        return report(False, "", NO_ANSWER)
    expected = _chain_least_squares(steps, loops, sigma_odometry, start)
    x = np.asarray(x, dtype=float).ravel()
    if x.shape != expected.shape:
        return report(False, "", f"x should hold {len(expected)} positions, one per node; got {x.size}")
    if np.allclose(x, expected, atol=1e-4, rtol=0):
        return report(True, "every edge gave way by its variance: the least-squares positions", "")
    for k in range(len(loops)):
        if np.allclose(x, _chain_least_squares(steps, [loops[k]], sigma_odometry, start), atol=1e-4, rtol=0):
            return report(False, "", "these positions honour one loop edge only: give every loop edge its row")
    unweighted = [(i, j, measured, sigma_odometry) for i, j, measured, _ in loops]
    if np.allclose(x, _chain_least_squares(steps, unweighted, sigma_odometry, start), atol=1e-4, rtol=0):
        return report(False, "", "the loop edges are weighted like the steps: divide their rows by their own sigma")
    return report(False, "", "not the least-squares positions: one row per edge, each divided by its sigma")


def _poses_of(answer, count: int) -> np.ndarray:
    if isinstance(answer, gtsam.Values):
        return np.array([answer.atPose3(k).matrix() for k in range(count)])
    return np.array([p.matrix() if isinstance(p, gtsam.Pose3) else np.asarray(p, dtype=float) for p in answer])


def _matrix(pose) -> np.ndarray:
    return pose.matrix() if isinstance(pose, gtsam.Pose3) else np.asarray(pose, dtype=float)


def check_three_poses(answer, step_1, step_2, loop, odometry_sigmas, loop_sigmas) -> bool:
    """Exercise 2: ``answer`` is the optimised ``gtsam.Values`` (or three 4 x 4
    poses) of nodes 0, 1, 2: node 0 held at the identity, odometry edges
    ``step_1`` (0 -> 1) and ``step_2`` (1 -> 2), and a loop edge ``loop``
    (0 -> 2). Sigmas are in GTSAM's order: three rotations (rad), then x y z (m).
    The expected poses come from :class:`helpers.slam.graph.optimizer.PoseGraph`."""
    hint = "the graph needs a prior on node 0, the two steps and the loop edge, each with its own noise model"
    if unanswered(answer):
        return report(False, "", NO_ANSWER)
    try:
        poses = _poses_of(answer, 3)
    except (RuntimeError, TypeError, ValueError, IndexError):
        return report(False, "", "pass the gtsam.Values the optimiser returns, with keys 0, 1 and 2")
    if poses.shape != (3, 4, 4):
        return report(False, "", f"expected three 4 x 4 poses, got an array of shape {poses.shape}")
    odometry = np.asarray(odometry_sigmas, dtype=float)[SWAP_ROTATION_TRANSLATION]
    graph = PoseGraph()
    graph.add_node(np.eye(4))
    graph.append(_matrix(step_1), odometry)
    graph.append(_matrix(step_2), odometry)
    graph.add_loop(
        0, 2, _matrix(loop), information_from_sigmas(np.asarray(loop_sigmas, float)[SWAP_ROTATION_TRANSLATION])
    )
    expected = graph.optimize().poses
    moved = np.linalg.norm(poses[:, :3, 3] - expected[:, :3, 3], axis=1).max()
    cosine = (np.trace(np.transpose(poses[:, :3, :3], (0, 2, 1)) @ expected[:, :3, :3], axis1=1, axis2=2) - 1) / 2
    turned = np.degrees(np.arccos(np.clip(cosine, -1, 1))).max()
    if moved < 1e-3 and turned < 1e-2:
        return report(True, "the three optimised poses match a pose graph fed the same edges", hint)
    if np.allclose(poses, graph.initial_poses, atol=1e-6):
        return report(False, "", "these are the odometry poses: add the loop edge, then optimise")
    return report(False, "", hint + " (GTSAM's sigmas are rotation first)")


def _optimised_ate(factors, initial, truth) -> float:
    values = gtsam.LevenbergMarquardtOptimizer(factors, initial, gtsam.LevenbergMarquardtParams()).optimize()
    return ate(_poses_of(values, len(truth)), truth).rmse


def check_loop_kernel(noise, factors, initial, loops, wrong_edge, true_poses, slack: float = 0.05) -> bool:
    """Exercise 6.3: ``noise`` is one noise model for every loop edge. The
    check takes ``factors`` (the graph of notebook 6.6, its ``len(loops)`` loop
    edges last), gives each loop edge of ``loops`` and the wrong one,
    ``wrong_edge``, this model, optimises from ``initial`` and compares the
    trajectory error (ATE against ``true_poses``) with the graph's own: correct
    within ``slack`` metres, with a kernel other than the pipeline's Cauchy."""
    if unanswered(noise):
        return report(False, "", NO_ANSWER)
    if not isinstance(noise, gtsam.noiseModel.Base):
        return report(False, "", "noise should be a gtsam noise model")
    truth = np.asarray(true_poses, dtype=float)
    lidar_only = gtsam.NonlinearFactorGraph()
    for index in range(factors.size() - len(loops)):
        lidar_only.add(factors.at(index))
    with_loops = gtsam.NonlinearFactorGraph(lidar_only)
    for i, j, relative in [*loops, wrong_edge]:
        with_loops.add(gtsam.BetweenFactorPose3(int(i), int(j), gtsam.Pose3(_matrix(relative)), noise))
    error = _optimised_ate(with_loops, initial, truth)
    clean = _optimised_ate(factors, initial, truth)
    no_loops = _optimised_ate(lidar_only, initial, truth)
    if error > clean + slack:
        if abs(error - no_loops) <= slack:
            return report(False, "", f"ATE {error:.2f} m, as with no loop edge at all: the right ones were let go too")
        return report(False, "", f"ATE {error:.2f} m against {clean:.2f} m: the wrong edge still bends the trajectory")
    robust = noise.robust() if isinstance(noise, gtsam.noiseModel.Robust) else None
    if isinstance(robust, gtsam.noiseModel.mEstimator.Cauchy):
        return report(False, "", "that is the pipeline's Cauchy of notebook 6.6: it works; now find another kernel")
    return report(True, f"the wrong edge is outvoted: the ATE stays within {slack:g} m of the graph's own", "")
