"""The checks of notebook 7's exercises say ``correct`` for a right answer
and ``not yet`` for a wrong or missing one."""

import numpy as np
from scipy.spatial.transform import Rotation

from helpers.exercises import maps as exercises
from helpers.quality.metrics import ate


def said(capsys) -> str:
    return capsys.readouterr().out.split(":")[0]


def test_the_rigid_fit_recovers_a_known_motion():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(50, 3)) * [100, 60, 5]
    rotation = Rotation.from_euler("zyx", [30, 2, -1], degrees=True).as_matrix()
    R, t = exercises._rigid_fit(points, points @ rotation.T + [5, -3, 1])
    assert np.allclose(R, rotation) and np.allclose(t, [5, -3, 1])
    assert exercises._aligned_ate(points, points @ rotation.T + [5, -3, 1]) < 1e-9


def test_the_aligned_ate_check_takes_the_answer_and_refuses_others(capsys):
    rng = np.random.default_rng(1)
    truth = np.cumsum(rng.normal(size=(80, 3)), axis=0) * [2, 2, 0.1]
    turn = Rotation.from_euler("z", 1.5, degrees=True).as_matrix()
    estimate = (truth + rng.normal(scale=0.2, size=truth.shape)) @ turn.T + [0.5, 0, 0]
    right = exercises._aligned_ate(estimate, truth)
    assert exercises.check_aligned_ate(right, estimate, truth) and said(capsys) == "correct"
    anchored = ate(_poses(estimate), _poses(truth)).rmse
    assert right < anchored
    for wrong in (None, anchored, right * 1.5):
        assert not exercises.check_aligned_ate(wrong, estimate, truth) and said(capsys) == "not yet"


def test_the_map_error_check_takes_the_median_and_refuses_the_mean(capsys):
    rng = np.random.default_rng(2)
    truth = rng.random((5000, 3)) * [100, 100, 5]
    estimate = truth[::10] + rng.normal(scale=0.1, size=(500, 3))
    distances = np.linalg.norm(estimate[:, None] - truth[None], axis=2).min(axis=1)
    assert exercises.check_median_map_error(np.median(distances), estimate, truth) and said(capsys) == "correct"
    for wrong in (None, distances.mean(), np.median(distances) + 0.01):
        assert not exercises.check_median_map_error(wrong, estimate, truth) and said(capsys) == "not yet"


def _poses(positions):
    poses = np.tile(np.eye(4), (len(positions), 1, 1))
    poses[:, :3, 3] = positions
    return poses
