"""The checks of notebook 6's exercises say correct for a right answer and not yet for a wrong one."""

import gtsam
import numpy as np
import pytest

from helpers.exercises import posegraph as ex

STEPS = np.array([10.2, 10.1, 10.3, 10.2, 10.2, 10.3])
LOOP, SIGMA_ODOMETRY, SIGMA_LOOP = 60.0, 0.1, 0.05


def chain_solution(sigma_loop):
    n = len(STEPS)
    rows, values = [np.eye(n + 1)[0] / 1e-4], [0.0]
    for k, step in enumerate(STEPS):
        row = np.zeros(n + 1)
        row[k], row[k + 1] = -1, 1
        rows.append(row / SIGMA_ODOMETRY)
        values.append(step / SIGMA_ODOMETRY)
    loop = np.zeros(n + 1)
    loop[0], loop[-1] = -1, 1
    rows.append(loop / sigma_loop)
    values.append(LOOP / sigma_loop)
    return np.linalg.lstsq(np.array(rows), np.array(values), rcond=None)[0]


def said(capsys):
    return capsys.readouterr().out.split(":")[0]


def test_chain(capsys):
    assert ex.check_chain(chain_solution(SIGMA_LOOP), STEPS, LOOP, SIGMA_ODOMETRY, SIGMA_LOOP)
    assert said(capsys) == "correct"
    for wrong in (None, np.concatenate([[0], np.cumsum(STEPS)]), chain_solution(SIGMA_ODOMETRY), np.zeros(3)):
        assert not ex.check_chain(wrong, STEPS, LOOP, SIGMA_ODOMETRY, SIGMA_LOOP)
        assert said(capsys) == "not yet"


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


def test_wrong_edge_noise(capsys, ring):
    graph, initial, truth, noise = ring
    wrong_edge = (5, 15, np.eye(4))  # "node 15 is where node 5 is": 100 m off
    cauchy = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(2.3849), noise)
    assert ex.check_wrong_edge_noise(cauchy, graph, initial, wrong_edge, truth)
    assert said(capsys) == "correct"
    huber = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(1.345), noise)
    for answer in (None, noise, gtsam.noiseModel.Isotropic.Sigma(6, 1e6), huber):
        assert not ex.check_wrong_edge_noise(answer, graph, initial, wrong_edge, truth)
        assert said(capsys) == "not yet"
