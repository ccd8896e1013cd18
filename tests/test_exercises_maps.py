"""The checks of notebook 7's exercises say ``correct`` for a right answer
and ``not yet`` for a wrong or missing one."""

import numpy as np
from scipy.spatial.transform import Rotation

from helpers.exercises import maps as exercises
from helpers.quality.metrics import ate
from helpers.slam.submaps import build_submap


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


def test_the_true_rotation_map_check_takes_its_median_and_names_the_slips(capsys):
    """Five patches of bumpy ground seen from 50 m, their estimated poses tilted and shifted a little."""
    rng = np.random.default_rng(2)
    x, y = np.meshgrid(np.arange(-20.0, 20.0, 1.0), np.arange(-10.0, 10.0, 1.0))
    true_poses = _poses(np.column_stack([8.0 * np.arange(5), np.zeros(5), np.full(5, 50.0)]))
    ground = [np.column_stack([x.ravel() + 8.0 * k, y.ravel(), np.sin(x.ravel() / 3.0)]) for k in range(5)]
    clouds = [g - T[:3, 3] for g, T in zip(ground, true_poses, strict=True)]  # sensor frame: the pose is a shift
    poses = true_poses.copy()
    for T in poses:
        T[:3, :3] = Rotation.from_euler("xy", rng.normal(scale=0.2, size=2), degrees=True).as_matrix()
        T[:3, 3] += rng.normal(scale=0.1, size=3)
    truth_map = np.vstack(ground)

    def median_at(at):
        built = build_submap(clouds, at, 1.2)
        return np.median(np.linalg.norm(built[:, None] - truth_map[None], axis=2).min(axis=1))

    rotated = poses.copy()
    rotated[:, :3, :3] = true_poses[:, :3, :3]
    check = exercises.check_true_rotation_map
    assert check(median_at(rotated), clouds, poses, true_poses, truth_map, 1.2) and said(capsys) == "correct"
    assert not check(median_at(poses), clouds, poses, true_poses, truth_map, 1.2)
    assert "as they are" in capsys.readouterr().out
    moved = true_poses.copy()
    moved[:, :3, :3] = poses[:, :3, :3]
    assert not check(median_at(moved), clouds, poses, true_poses, truth_map, 1.2)
    assert "keep the positions" in capsys.readouterr().out
    for wrong in (None, median_at(rotated) + 0.01):
        assert not check(wrong, clouds, poses, true_poses, truth_map, 1.2) and said(capsys) == "not yet"


def _poses(positions):
    poses = np.tile(np.eye(4), (len(positions), 1, 1))
    poses[:, :3, 3] = positions
    return poses
