"""The checks of notebook 6's exercises say correct for a right answer and not yet for a wrong one."""

import gtsam
import numpy as np
import pytest

from helpers.exercises import posegraph as ex

STEPS = np.array([10.2, 10.1, 10.3, 10.2, 10.2, 10.3])
LOOP, SIGMA_ODOMETRY, SIGMA_LOOP = 60.0, 0.1, 0.05


LOOPS = [(0, 6, LOOP, SIGMA_LOOP), (0, 3, 30.0, SIGMA_LOOP)]  # the end of the chain, and its middle


def chain_solution(loops):
    """Weighted least squares written out: one row per edge, divided by its sigma."""
    n = len(STEPS)
    rows, values = [np.eye(n + 1)[0] / 1e-4], [0.0]
    edges = [(k, k + 1, step, SIGMA_ODOMETRY) for k, step in enumerate(STEPS)] + list(loops)
    for i, j, measured, sigma in edges:
        row = np.zeros(n + 1)
        row[i], row[j] = -1, 1
        rows.append(row / sigma)
        values.append(measured / sigma)
    return np.linalg.lstsq(np.array(rows), np.array(values), rcond=None)[0]


def said(capsys):
    return capsys.readouterr().out.split(":")[0]


def test_chain(capsys):
    assert ex.check_chain(chain_solution(LOOPS), STEPS, LOOPS, SIGMA_ODOMETRY)
    assert said(capsys) == "correct"
    unweighted = [(i, j, z, SIGMA_ODOMETRY) for i, j, z, _ in LOOPS]
    wrong = (None, np.concatenate([[0], np.cumsum(STEPS)]), chain_solution(LOOPS[:1]), chain_solution(unweighted))
    for answer in (*wrong, np.zeros(3)):
        assert not ex.check_chain(answer, STEPS, LOOPS, SIGMA_ODOMETRY)
        assert said(capsys) == "not yet"


def test_one_loop_edge_agrees_with_the_closed_form():
    x = ex._chain_least_squares(STEPS, [(0, 6, LOOP, SIGMA_LOOP)], SIGMA_ODOMETRY)
    assert np.allclose(x, ex.chain_closed_form(STEPS, LOOP, SIGMA_ODOMETRY, SIGMA_LOOP), atol=1e-6)


def test_closed_form_spreads_the_misclosure_evenly():
    x = ex.chain_closed_form(STEPS, LOOP, 1.0, 1.0)
    corrections = np.concatenate([[0], np.cumsum(STEPS)]) - x
    assert np.allclose(np.diff(corrections), (STEPS.sum() - LOOP) / (len(STEPS) + 1))


ODOMETRY_SIGMAS = np.array([0.01, 0.01, 0.01, 0.1, 0.1, 0.1])  # rotation first
STEP_1 = gtsam.Pose3(gtsam.Rot3(), np.array([10.0, 0, 0]))
STEP_2 = gtsam.Pose3(gtsam.Rot3.Yaw(np.pi / 2), np.array([10.0, 0, 0]))
LOOP_POSE = gtsam.Pose3(gtsam.Rot3.Yaw(np.pi / 2), np.array([20.5, 0.3, 0]))


def three_pose_graph(odometry_sigmas):
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose3(0, gtsam.Pose3(), gtsam.noiseModel.Diagonal.Sigmas(np.full(6, 1e-4))))
    odometry = gtsam.noiseModel.Diagonal.Sigmas(odometry_sigmas)
    graph.add(gtsam.BetweenFactorPose3(0, 1, STEP_1, odometry))
    graph.add(gtsam.BetweenFactorPose3(1, 2, STEP_2, odometry))
    graph.add(gtsam.BetweenFactorPose3(0, 2, LOOP_POSE, gtsam.noiseModel.Diagonal.Sigmas(ODOMETRY_SIGMAS)))
    initial = gtsam.Values()
    initial.insert(0, gtsam.Pose3())
    initial.insert(1, STEP_1)
    initial.insert(2, STEP_1.compose(STEP_2))
    return graph, initial


def test_three_poses(capsys):
    graph, initial = three_pose_graph(ODOMETRY_SIGMAS)
    answer = gtsam.LevenbergMarquardtOptimizer(graph, initial).optimize()
    assert ex.check_three_poses(answer, STEP_1, STEP_2, LOOP_POSE, ODOMETRY_SIGMAS, ODOMETRY_SIGMAS)
    assert said(capsys) == "correct"
    swapped, _ = three_pose_graph(ODOMETRY_SIGMAS[[3, 4, 5, 0, 1, 2]])  # translation first: wrong order
    wrong = gtsam.LevenbergMarquardtOptimizer(swapped, initial).optimize()
    for answer in (None, initial, wrong):
        assert not ex.check_three_poses(answer, STEP_1, STEP_2, LOOP_POSE, ODOMETRY_SIGMAS, ODOMETRY_SIGMAS)
        assert said(capsys) == "not yet"


@pytest.fixture(scope="module")
def ring():
    """Twenty poses on a 50 m circle, slightly perturbed odometry, one right loop edge."""
    rng = np.random.default_rng(3)
    angles = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    truth = np.array(
        [gtsam.Pose3(gtsam.Rot3.Yaw(a), np.array([50 * np.cos(a), 50 * np.sin(a), 0])).matrix() for a in angles]
    )
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.005] * 3 + [0.1] * 3))
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose3(0, gtsam.Pose3(truth[0]), gtsam.noiseModel.Diagonal.Sigmas(np.full(6, 1e-4))))
    initial = gtsam.Values()
    pose = gtsam.Pose3(truth[0])
    initial.insert(0, pose)
    for k in range(1, 20):
        step = gtsam.Pose3(np.linalg.inv(truth[k - 1]) @ truth[k]).compose(
            gtsam.Pose3.Expmap(np.r_[rng.normal(0, 0.003, 3), rng.normal(0, 0.05, 3)])
        )
        graph.add(gtsam.BetweenFactorPose3(k - 1, k, step, noise))
        pose = pose.compose(step)
        initial.insert(k, pose)
    graph.add(gtsam.BetweenFactorPose3(19, 0, gtsam.Pose3(np.linalg.inv(truth[19]) @ truth[0]), noise))
    return graph, initial, truth, noise


def test_loop_kernel(capsys, ring):
    graph, initial, truth, noise = ring
    loops = [(19, 0, np.linalg.inv(truth[19]) @ truth[0])]  # the ring's loop edge, its last factor
    wrong_edge = (5, 15, np.eye(4))  # "node 15 is where node 5 is": 100 m off
    kernel = gtsam.noiseModel.mEstimator
    tukey = gtsam.noiseModel.Robust.Create(kernel.Tukey.Create(30.0), noise)
    assert ex.check_loop_kernel(tukey, graph, initial, loops, wrong_edge, truth)
    assert said(capsys) == "correct"
    cauchy = gtsam.noiseModel.Robust.Create(kernel.Cauchy.Create(2.3849), noise)
    huber = gtsam.noiseModel.Robust.Create(kernel.Huber.Create(1.345), noise)
    for answer in (None, noise, huber, cauchy):
        assert not ex.check_loop_kernel(answer, graph, initial, loops, wrong_edge, truth)
        assert said(capsys) == "not yet"
    wide = gtsam.noiseModel.Isotropic.Sigma(6, 1e6)  # outvotes the wrong edge, and the right one with it
    assert not ex.check_loop_kernel(wide, graph, initial, loops, wrong_edge, truth)
    assert "as with no loop edge" in capsys.readouterr().out
