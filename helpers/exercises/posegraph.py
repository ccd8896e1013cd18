"""Checks for the exercises of notebook 6 (pose-graph optimisation).

* :func:`check_chain`: the 1-D chain with its loop edge, solved by least
  squares, against the closed form of how a loop spreads its correction.
* :func:`check_three_poses`: a three-pose GTSAM graph built factor by factor,
  against :class:`helpers.posegraph.PoseGraph` fed the same measurements.
* :func:`check_wrong_edge_noise`: a noise model for a wrong loop edge, judged
  by the trajectory error against the true poses after optimisation.
"""

from __future__ import annotations

import gtsam
import numpy as np

from ..metrics import ate
from ..posegraph import PoseGraph, information_from_sigmas
from . import report, unanswered

_TRANSLATION_FIRST = np.array([3, 4, 5, 0, 1, 2])  # GTSAM's rotation-first sigmas -> x y z rx ry rz


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


def check_chain(x, steps, loop, sigma_odometry: float, sigma_loop: float, start: float = 0.0) -> bool:
    """Exercise 1: ``x`` holds the positions of the chain solved with its loop edge."""
    hint = (
        "append one row for the loop edge to A (-1 at the first node, +1 at the last, divided by the "
        "loop's sigma) and its measurement divided by the same sigma to b, then solve by least squares"
    )
    if unanswered(x):
        return report(False, "", hint)
    expected = chain_closed_form(steps, loop, sigma_odometry, sigma_loop, start)
    x = np.asarray(x, dtype=float).ravel()
    if x.shape != expected.shape:
        return report(False, "", f"x should hold {len(expected)} positions, one per node; got {x.size}")
    if np.allclose(x, expected, atol=1e-6, rtol=0):
        return report(True, "each step gave up the same share of the misclosure, as the closed form says", hint)
    if np.allclose(x, chain_closed_form(steps, loop, 1.0, 1.0, start), atol=1e-6, rtol=0):
        return report(False, "", "the spread is right for equal weights: divide the loop's row and value by its sigma")
    return report(False, "", hint)


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
    The expected poses come from :class:`helpers.posegraph.PoseGraph`."""
    hint = (
        "a PriorFactorPose3 on node 0 at gtsam.Pose3(), BetweenFactorPose3 for 0->1, 1->2 and the loop 0->2, "
        "each with its noise model, three initial guesses in a gtsam.Values, then "
        "gtsam.LevenbergMarquardtOptimizer(graph, initial).optimize()"
    )
    if unanswered(answer):
        return report(False, "", hint)
    try:
        poses = _poses_of(answer, 3)
    except (RuntimeError, TypeError, ValueError, IndexError):
        return report(False, "", "pass the gtsam.Values the optimiser returns, with keys 0, 1 and 2")
    if poses.shape != (3, 4, 4):
        return report(False, "", f"expected three 4 x 4 poses, got an array of shape {poses.shape}")
    odometry = np.asarray(odometry_sigmas, dtype=float)[_TRANSLATION_FIRST]
    graph = PoseGraph()
    graph.add_node(np.eye(4))
    graph.append(_matrix(step_1), odometry)
    graph.append(_matrix(step_2), odometry)
    graph.add_loop(0, 2, _matrix(loop), information_from_sigmas(np.asarray(loop_sigmas, float)[_TRANSLATION_FIRST]))
    expected = graph.optimize().poses
    moved = np.linalg.norm(poses[:, :3, 3] - expected[:, :3, 3], axis=1).max()
    cosine = (np.trace(np.transpose(poses[:, :3, :3], (0, 2, 1)) @ expected[:, :3, :3], axis1=1, axis2=2) - 1) / 2
    turned = np.degrees(np.arccos(np.clip(cosine, -1, 1))).max()
    if moved < 1e-3 and turned < 1e-2:
        return report(True, "the three optimised poses match a pose graph fed the same edges", hint)
    if np.allclose(poses, graph.initial_poses, atol=1e-6):
        return report(False, "", "these are the odometry poses: add the loop edge, then optimise")
    return report(False, "", hint + " (GTSAM's sigmas are rotation first)")


def check_wrong_edge_noise(noise, factors, initial, wrong_edge, true_poses, slack: float = 0.05) -> bool:
    """Exercise 3: ``noise`` is the noise model given to the wrong loop edge
    ``wrong_edge = (i, j, relative 4 x 4)``, added to a copy of ``factors``
    and optimised from ``initial``. Correct when the noise model is robust and
    the trajectory error (ATE against ``true_poses``) stays within ``slack``
    metres of the graph optimised without the wrong edge."""
    hint = (
        "wrap a Gaussian model in a robust kernel: gtsam.noiseModel.Robust.Create("
        "gtsam.noiseModel.mEstimator.Cauchy.Create(scale), base)"
    )
    if unanswered(noise):
        return report(False, "", hint)
    if not isinstance(noise, gtsam.noiseModel.Base):
        return report(False, "", "noise should be a gtsam noise model")
    if not isinstance(noise, gtsam.noiseModel.Robust):
        return report(
            False,
            "",
            "a plain Gaussian trusts the edge as it is (a wider one would need you to know the edge is wrong); " + hint,
        )
    i, j, relative = wrong_edge
    params = gtsam.LevenbergMarquardtParams()
    clean = gtsam.LevenbergMarquardtOptimizer(factors, initial, params).optimize()
    with_wrong = gtsam.NonlinearFactorGraph(factors)
    with_wrong.add(gtsam.BetweenFactorPose3(int(i), int(j), gtsam.Pose3(_matrix(relative)), noise))
    result = gtsam.LevenbergMarquardtOptimizer(with_wrong, initial, params).optimize()
    truth = np.asarray(true_poses, dtype=float)
    error = ate(_poses_of(result, len(truth)), truth).rmse
    clean_error = ate(_poses_of(clean, len(truth)), truth).rmse
    if error <= clean_error + slack:
        return report(
            True, f"the wrong edge is outvoted: the trajectory error stays within {slack:g} m of the clean one", hint
        )
    return report(
        False,
        "",
        f"the wrong edge still bends the trajectory (its error grows by more than {slack:g} m): "
        "a kernel that lets a far-off edge go (Cauchy), or a smaller scale",
    )
