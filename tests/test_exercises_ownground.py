"""The checks of notebook 8's exercises say ``correct`` for a right answer and ``not yet`` for a wrong one."""

import gtsam
import numpy as np

from helpers.exercises import ownground as ex
from helpers.quality.metrics import ate
from helpers.slam.graph.factors import pose3


def said(capsys):
    return capsys.readouterr().out.split(":")[0]


def test_break_even_speed(capsys):
    along = np.array([0.05, 0.045, 0.09])  # the steps' sigmas along the track, m: median 0.05
    # 0.5 m/s² and nodes 1.5 m apart: a (1.5 / v)^2 = 0.05 m at v = 1.5 sqrt(10) = 4.74 m/s
    ex.check_break_even_speed(1.5 * np.sqrt(10), 1.5, 0.5, along)
    assert said(capsys) == "correct"
    for wrong in (None, 15.0, 1.5 * np.sqrt(5), 4.0):  # unanswered, a dt = sigma, a dt^2 / 2 = sigma, a guess
        ex.check_break_even_speed(wrong, 1.5, 0.5, along)
        assert said(capsys) == "not yet"
    ex.check_break_even_speed(15.0, 1.5, 0.5, along)
    assert "change of speed" in capsys.readouterr().out


def _information(sigmas, yaw_deg):
    """A translation-first information whose horizontal covariance is ``sigmas`` along axes turned by ``yaw_deg``."""
    a = np.radians(yaw_deg)
    turn = np.eye(6)
    turn[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    covariance = turn @ np.diag(np.asarray(sigmas, float) ** 2) @ turn.T
    return np.linalg.inv(covariance)


def test_weak_direction(capsys):
    info = _information([0.08, 0.01, 0.02, 0.001, 0.001, 0.001], 30.0)
    ex.check_weak_direction(info, 30.0, 0.08)
    assert said(capsys) == "correct"
    ex.check_weak_direction(info, 210.0, 0.08)  # the same direction, the other way round
    assert said(capsys) == "correct"
    for angle, sigma in ((None, 0.08), (120.0, 0.08), (30.0, 0.0064), (30.0, 0.01)):
        ex.check_weak_direction(info, angle, sigma)
        assert said(capsys) == "not yet"


def test_weak_direction_needs_the_whole_inverse(capsys):
    """A slide along x that trades for a yaw: the 2 x 2 block inverted alone gives too small a sigma."""
    covariance = np.diag([0.05, 0.01, 0.02, 0.001, 0.001, 0.004]) ** 2
    covariance[0, 5] = covariance[5, 0] = 0.9 * 0.05 * 0.004  # x and yaw strongly correlated
    info = np.linalg.inv(covariance)
    alone = np.sqrt(np.linalg.eigvalsh(np.linalg.inv(info[:2, :2]))[-1])
    assert alone < 0.9 * 0.05
    ex.check_weak_direction(info, 0.0, alone)
    assert "whole 6 x 6" in capsys.readouterr().out
    ex.check_weak_direction(info, 0.0, 0.05)
    assert said(capsys) == "correct"


def _line_graph(n=20):
    """A straight flight of ``n`` nodes 2 m apart, its odometry 1 % short, as a GTSAM graph with a prior."""
    truth = np.tile(np.eye(4), (n, 1, 1))
    truth[:, 0, 3] = 2.0 * np.arange(n)
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose3(0, pose3(truth[0]), gtsam.noiseModel.Isotropic.Sigma(6, 1e-4)))
    step = np.eye(4)
    step[0, 3] = 1.98
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.001] * 3 + [0.05] * 3))
    initial = gtsam.Values()
    for k in range(n):
        initial.insert(k, pose3(truth[0] @ np.linalg.matrix_power(step, k)))
        if k:
            graph.add(gtsam.BetweenFactorPose3(k - 1, k, pose3(step), noise))
    fixes = truth[:, :3, 3] + np.random.default_rng(3).normal(0, 1.0, (n, 3))
    return graph, initial, fixes, truth


def test_sparse_fixes(capsys):
    graph, initial, fixes, truth = _line_graph()
    with_fixes = gtsam.NonlinearFactorGraph()
    for index in range(graph.size()):
        with_fixes.add(graph.at(index))
    for k in range(0, len(fixes), 4):
        with_fixes.add(gtsam.GPSFactor(k, fixes[k], gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
    values = gtsam.LevenbergMarquardtOptimizer(with_fixes, initial, gtsam.LevenbergMarquardtParams()).optimize()
    answer = ate(np.array([values.atPose3(k).matrix() for k in range(initial.size())]), truth).rmse
    ex.check_sparse_fixes(answer, 4, graph, initial, fixes, 1.0, truth)
    assert said(capsys) == "correct"
    odometry = np.array([initial.atPose3(k).matrix() for k in range(initial.size())])
    every_node = ex._sparse_fixes_ate(1, graph, initial, fixes, 1.0, truth)
    assert not np.isclose(every_node, answer, rtol=0.01)
    for wrong in (None, ate(odometry, truth).rmse, every_node):
        ex.check_sparse_fixes(wrong, 4, graph, initial, fixes, 1.0, truth)
        assert said(capsys) == "not yet"
    assert graph.size() == 20  # the check added its factors to a graph of its own


def _along_x(offsets):
    """(K, 4, 4) poses at x = 2 k + ``offsets[k]``."""
    poses = np.tile(np.eye(4), (len(offsets), 1, 1))
    poses[:, 0, 3] = 2.0 * np.arange(len(offsets)) + np.asarray(offsets, float)
    return poses


def test_sigmas_off(capsys):
    truth = _along_x(np.zeros(6))
    poses = _along_x([0.0, 0.1, 0.3, 0.2, 0.5, 0.6])
    sigmas = np.array([1e-4, 0.1, 0.1, 0.2, 0.5, 0.6])  # node 2 is 3 sigmas off; node 5, farthest in metres, 1
    ex.check_sigmas_off(2, 3.0, truth, poses, sigmas)
    assert said(capsys) == "correct"
    ex.check_sigmas_off(5, 1.0, truth, poses, sigmas)  # the farthest in metres
    assert "farthest off in metres" in capsys.readouterr().out
    rms = np.sqrt(np.mean([0, 0.01, 0.09, 0.04, 0.25, 0.36]) / np.mean(sigmas**2))
    ex.check_sigmas_off(2, rms, truth, poses, sigmas)
    assert "over all nodes" in capsys.readouterr().out
    ex.check_sigmas_off(2, 9.0, truth, poses, sigmas)
    assert "squared ratio" in capsys.readouterr().out
    for node, value in ((None, 3.0), (2, None), (3, 3.0), (2, 2.0)):
        ex.check_sigmas_off(node, value, truth, poses, sigmas)
        assert said(capsys) == "not yet"


def test_lever_sigma(capsys):
    """A circle of 150 m flown twice, 100 scans a lap; twenty loops from the second lap to the scan five ahead on
    the first: each lever is the chord 2 r sin(pi 5 / 100), and edges known to 5 cm see the scale to
    0.05 / (chord sqrt(20))."""
    angle = np.linspace(0.0, 2 * np.pi, 100, endpoint=False)
    lap = np.tile(np.eye(4), (200, 1, 1))
    lap[:, :2, 3] = np.vstack([150.0 * np.c_[np.cos(angle), np.sin(angle)]] * 2)
    information = np.diag([1 / 0.05**2] * 3 + [1 / np.radians(0.1) ** 2] * 3)
    chord = 2 * 150.0 * np.sin(np.pi * 5 / 100)
    expected = 0.05 / (chord * np.sqrt(20))
    ex.check_lever_sigma(expected, lap, information)
    assert said(capsys) == "correct"
    ex.check_lever_sigma(100 * expected, lap, information)
    assert "per cent" in capsys.readouterr().out
    ex.check_lever_sigma(float("inf"), lap, information)
    assert "under it" in capsys.readouterr().out
    for value in (None, 2 * expected, 0.05 / chord):  # one loop's sigma, not twenty's
        ex.check_lever_sigma(value, lap, information)
        assert said(capsys) == "not yet"
