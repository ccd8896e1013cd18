"""Checks for the exercises of notebook 8 (your own ground).

* :func:`check_break_even_speed`: the ground speed at which a
  constant-velocity factor is exactly as sure along the track as the
  lidar's steps.
* :func:`check_weak_direction`: the horizontal direction an edge's
  information pins least, and its sigma there.
* :func:`check_sparse_fixes`: the ATE of a graph given a GNSS fix on every
  few nodes only, recomputed here with GTSAM.
* :func:`check_sigmas_off`: the node farthest from the truth in its own
  position sigmas, and by how many.
* :func:`check_lever_sigma`: the scale's sigma that loops along the track, a
  few scans apart, see on a lap flown twice.
"""

from __future__ import annotations

import gtsam
import numpy as np

from helpers.exercises.report import say, unanswered
from helpers.quality.graph_checks import scale_sigma
from helpers.quality.metrics import ate

NO_ANSWER = "fill in the cell and run it again (a hint is folded under the exercise)"


def _break_even_speed(spacing: float, acceleration: float, sigma: float) -> float:
    """The speed (m/s) at which ``a dt^2``, ``dt = spacing / speed``, equals ``sigma`` (m)."""
    return spacing * np.sqrt(acceleration / sigma)


def check_break_even_speed(speed, spacing: float, acceleration: float, along_sigmas) -> None:
    """Exercise 8.1: ``speed`` (m/s) at which a constant-velocity factor over
    nodes ``spacing`` m apart, for a drone that accelerates by at most
    ``acceleration`` m/s², is as sure along the track as the median of
    ``along_sigmas``, the steps' sigmas along the track (m)."""
    if unanswered(speed):
        return say(False, "", NO_ANSWER)
    median = float(np.median(along_sigmas))
    expected = _break_even_speed(spacing, acceleration, median)
    value = float(speed)
    if np.isclose(value, acceleration * spacing / median, rtol=0.02):
        return say(False, "", "that sets a change of speed (a dt, m/s) equal to a length: the factor compares steps")
    if np.isclose(value, _break_even_speed(spacing, acceleration / 2, median), rtol=0.02):
        return say(False, "", "a dt^2 / 2 is how far a body starting at rest moves; a step changes by a dt^2")
    if not np.isclose(value, expected, rtol=0.02):
        return say(False, "", "not the speed at which the factor's sigma equals the steps' median sigma")
    say(True, "faster than that, the nodes come sooner and the motion factor is the surer one", "")


def _weak_direction(information) -> tuple[float, float]:
    """(angle in degrees from x in [0, 180), sigma in m) of the loosest horizontal direction of a
    translation-first 6 x 6 information: the largest eigenvector of the xy block of its inverse."""
    block = np.linalg.inv(np.asarray(information, dtype=float))[:2, :2]
    values, vectors = np.linalg.eigh(block)
    angle = np.degrees(np.arctan2(vectors[1, 1], vectors[0, 1])) % 180.0
    return float(angle), float(np.sqrt(values[1]))


def _angle_apart(a: float, b: float) -> float:
    """Degrees between two undirected directions."""
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)


def check_weak_direction(information, angle_deg, sigma_m) -> None:
    """Exercise 2: the horizontal direction ``information`` (6 x 6,
    translation first) pins least, as an angle from x in degrees, and the
    sigma (m) along it."""
    hint = "not the direction the step pins least: where does a 6 x 6 information keep its sigmas?"
    if unanswered(angle_deg) or unanswered(sigma_m):
        return say(False, "", NO_ANSWER)
    angle, sigma = _weak_direction(information)
    info = np.asarray(information, dtype=float)
    # the 2 x 2 block inverted alone: the rotation taken as known
    alone = float(np.sqrt(np.linalg.eigvalsh(np.linalg.inv(info[:2, :2]))[1]))
    if _angle_apart(float(angle_deg), angle) > 2.0:
        return say(False, "", hint + " (an angle from the x axis: arctan2 of its y and x components)")
    if np.isclose(float(sigma_m), alone, rtol=0.02) and not np.isclose(alone, sigma, rtol=0.02):
        return say(False, "", "invert the whole 6 x 6 first, then take the xy block: its block alone assumes "
                   "the other four directions known exactly")  # fmt: skip
    if np.isclose(float(sigma_m), sigma**2, rtol=0.02):
        return say(False, "", "that is a variance (m²): the sigma is its square root")
    if not np.isclose(float(sigma_m), sigma, rtol=0.02):
        return say(False, "", "the sigma is the square root of that eigenvalue")
    say(True, f"{angle:.0f} deg from the heading, {sigma * 100:.2g} cm", "")


def _sparse_fixes_ate(every: int, graph, initial, fixes, sigma: float, truth) -> float:
    """The ATE (m) of ``graph`` given a GPS factor on nodes 0, ``every``, 2 ``every``, ..."""
    with_fixes = gtsam.NonlinearFactorGraph()
    for index in range(graph.size()):
        with_fixes.add(graph.at(index))
    noise = gtsam.noiseModel.Isotropic.Sigma(3, sigma)
    for k in range(0, len(fixes), every):
        with_fixes.add(gtsam.GPSFactor(k, np.asarray(fixes[k], dtype=float), noise))
    values = gtsam.LevenbergMarquardtOptimizer(with_fixes, initial, gtsam.LevenbergMarquardtParams()).optimize()
    poses = np.array([values.atPose3(k).matrix() for k in range(initial.size())])
    return ate(poses, truth).rmse


def check_sparse_fixes(ate_value, every: int, graph, initial, fixes, sigma: float, truth) -> None:
    """Exercise 3: ``ate_value`` (m), the ATE of ``graph`` (without GPS factors)
    once a fix of ``fixes`` (sigma ``sigma`` m) is added on every ``every``-th node."""
    hint = f"not the ATE with a fix on every {every}th node, from the same graph, fixes and sigma"
    if unanswered(ate_value):
        return say(False, "", NO_ANSWER)
    expected = _sparse_fixes_ate(every, graph, initial, fixes, sigma, truth)
    if not np.isclose(float(ate_value), expected, rtol=0.01, atol=0.005):
        every_node = _sparse_fixes_ate(1, graph, initial, fixes, sigma, truth)
        if np.isclose(float(ate_value), every_node, rtol=0.01, atol=0.005):
            return say(False, "", f"that is the ATE with a fix on every node: keep only every {every}th")
        return say(False, "", hint)
    every_node = _sparse_fixes_ate(1, graph, initial, fixes, sigma, truth)
    ratio = expected / every_node
    say(
        True,
        f"ATE {expected:.2f} m, {ratio:.2g} x that of a fix on every node (sqrt({every}) = {np.sqrt(every):.2g})",
        "",
    )


def _sigmas_off(truth, poses, sigmas) -> tuple[int, float, np.ndarray]:
    """(node, its distance from the truth over its sigma, every node's) for (K, 4, 4) ``poses`` and ``truth``
    and (K,) position ``sigmas`` (m); the anchored first node, known to a fraction of a millimetre, left out."""
    errors = np.linalg.norm(np.asarray(poses)[:, :3, 3] - np.asarray(truth)[:, :3, 3], axis=1)
    ratios = errors / np.asarray(sigmas, dtype=float)
    ratios[0] = 0.0
    node = int(np.argmax(ratios))
    return node, float(ratios[node]), errors


def check_sigmas_off(node, sigmas_off, truth, poses, sigmas) -> None:
    """Exercise 4: ``node``, the node of ``poses`` (K x 4 x 4) farthest from ``truth`` in its own position
    ``sigmas`` (K,, m), and ``sigmas_off``, its distance from the truth over its sigma."""
    if unanswered(node) or unanswered(sigmas_off):
        return say(False, "", NO_ANSWER)
    expected_node, expected, errors = _sigmas_off(truth, poses, sigmas)
    sigmas = np.asarray(sigmas, dtype=float)
    rms = np.sqrt(np.mean(errors**2)) / np.sqrt(np.mean(sigmas**2))
    if np.isclose(float(sigmas_off), rms, rtol=0.02):
        return say(False, "", "that is the ATE over the expected ATE, over all nodes: take each node in its own sigma")
    if int(node) == int(np.argmax(errors)) and int(node) != expected_node:
        return say(False, "", "that node is the farthest off in metres; its sigma is larger than some others'")
    if np.isclose(float(sigmas_off), expected**2, rtol=0.02):
        return say(False, "", "that is a squared ratio: divide the distance by the sigma itself")
    if int(node) != expected_node or not np.isclose(float(sigmas_off), expected, rtol=0.02):
        return say(False, "", "divide each node's distance from the truth by its sigma, and take the largest")
    say(True, "independent errors would rarely leave a node more than two or three of its sigmas off", "")


def ahead_pairs(per_lap: int, ahead: int = 5, every: int = 5) -> list[tuple[int, int]]:
    """Loop edges of a lap flown twice (``per_lap`` scans a lap): every ``every``-th scan of the second lap
    joined to the first lap's scan ``ahead`` scans further along."""
    return [(k + per_lap, (k + ahead) % per_lap) for k in range(0, per_lap, every)]


def check_lever_sigma(sigma, lap, loop_information) -> None:
    """Exercise 8.5: ``sigma``, the scale's sigma (a share of 1) that the loops of :func:`ahead_pairs` see on
    ``lap`` ((2 n, 4, 4) poses, a lap flown twice), each edge with the 6 x 6 ``loop_information``."""
    if unanswered(sigma):
        return say(False, "", NO_ANSWER)
    pairs = ahead_pairs(len(lap) // 2)
    expected, lever = scale_sigma(np.asarray(lap, dtype=float), pairs, [loop_information] * len(pairs))
    value = float(sigma)
    if not np.isfinite(value):
        return say(False, "", "those loops still join a scan to the one under it: join it to the scan five ahead")
    if np.isclose(value, 100 * expected, rtol=0.02):
        return say(False, "", "that is a per cent: give the sigma as a share of 1")
    if not np.isclose(value, expected, rtol=0.02):
        return say(False, "", "not the sigma of these loops: each sees the scale through its lever (scale_sigma)")
    say(
        True,
        f"levers of {lever:.0f} m see the scale about as well as the strips' 48 m: the information does not ask "
        "which way a lever points",
        "",
    )
