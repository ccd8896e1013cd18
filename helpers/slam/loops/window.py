"""The part of the loop search's graph a computation holds (:mod:`helpers.slam.loops.uncertainty`): the
nodes nearest the anchor along the graph's edges, and, where GNSS fixes hold them, where the edges and the
fixes put those nodes."""

from __future__ import annotations

from collections import deque

import gtsam
import numpy as np

from helpers.errors import SlamError

LOOSE_SIGMAS = np.array([1.0, 1.0, 1.0, 1e4, 1e4, 1e4])  # rad, m: a prior that only settles what fixes in a line leave


def window_of(anchor: int, size: int, touching, ends) -> np.ndarray:
    """The ``size`` nodes nearest ``anchor`` along the edges, sorted (all of them when the graph holds no more):
    a breadth-first search over the graph whose node ``k`` touches the factors ``touching[k]``, factor ``f``
    joining the nodes ``ends[f]``."""
    if len(touching) <= size:
        return np.arange(len(touching))
    seen, queue = {anchor}, deque([anchor])
    while queue and len(seen) < size:
        node = queue.popleft()
        for f in touching[node]:
            for other in ends[f]:
                if other not in seen and len(seen) < size:
                    seen.add(other)
                    queue.append(other)
    return np.array(sorted(seen))


def held_solve(graph, values, window, anchor: int, fixed, held: dict, poses) -> gtsam.Values:
    """The ``window``'s nodes where its edges (``graph``) and GNSS fixes (``fixed``) put them (map frame), solved
    from the last such solution, ``held`` (node -> gtsam.Pose3, updated here); a node it did not hold is chained
    from the node before by the odometry step between their ``poses`` (gtsam.Pose3 each), or taken from
    ``values``."""
    guess: dict[int, gtsam.Pose3] = {}
    start = gtsam.Values()
    for node in map(int, window):
        if node in held:
            guess[node] = held[node]
        elif node - 1 in guess or node - 1 in held:
            before = guess.get(node - 1, held.get(node - 1))
            guess[node] = before.compose(poses[node - 1].between(poses[node]))
        else:
            guess[node] = values.atPose3(node)
        start.insert(node, guess[node])
    problem = gtsam.NonlinearFactorGraph(graph)
    for factor in fixed:
        problem.add(factor)
    problem.add(gtsam.PriorFactorPose3(anchor, start.atPose3(anchor), gtsam.noiseModel.Diagonal.Sigmas(LOOSE_SIGMAS)))
    try:
        solved = gtsam.LevenbergMarquardtOptimizer(problem, start, gtsam.LevenbergMarquardtParams()).optimize()
    except RuntimeError as exc:
        raise SlamError(f"the loop search's graph cannot be solved with its GNSS fixes: {exc}") from None
    for node in window:
        held[int(node)] = solved.atPose3(int(node))
    return solved


def matrices(values: gtsam.Values) -> np.ndarray:
    """(K, 4, 4) the poses of ``values``, sorted by key."""
    rows = gtsam.utilities.extractPose3(values)  # rows [R (9, row by row), t (3)], sorted keys
    out = np.tile(np.eye(4), (len(rows), 1, 1))
    out[:, :3, :3] = rows[:, :9].reshape(-1, 3, 3)
    out[:, :3, 3] = rows[:, 9:12]
    return out
