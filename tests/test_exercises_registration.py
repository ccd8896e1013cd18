"""The checks of notebook 3's exercises say "correct" for a right answer and "not yet" otherwise."""

import numpy as np

from helpers.exercises.registration import check_rotation_angle, check_trials, trials_for


def _angle_deg(T):
    return np.degrees(np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1, 1)))


def test_rotation_angle(capsys):
    check_rotation_angle(_angle_deg)
    check_rotation_angle(lambda T: np.radians(_angle_deg(T)))  # radians, not degrees
    check_rotation_angle(lambda T: np.degrees(np.arccos(np.clip(T[0, 0], -1, 1))))  # right about z only
    check_rotation_angle(None)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["correct"] + ["not yet"] * 3


def _matches(inlier_share=0.4, count=300, seed=0):
    """Matched points: a share of them moved by a known motion, the rest anywhere."""
    rng = np.random.default_rng(seed)
    moving = rng.uniform(-50, 50, (count, 3))
    T = np.eye(4)
    angle = np.radians(5.0)
    T[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    T[:3, 3] = [6.0, 0.5, 0.1]
    fixed = moving @ T[:3, :3].T + T[:3, 3]
    wrong = rng.random(count) >= inlier_share
    fixed[wrong] = rng.uniform(-50, 50, (wrong.sum(), 3))
    return moving, fixed, T


def test_trials(capsys):
    moving, fixed, T = _matches()
    w = np.mean(np.linalg.norm(moving @ T[:3, :3].T + T[:3, 3] - fixed, axis=1) < 1.0)
    right = trials_for(w, 0.999)
    check_trials(right, moving, fixed, T, 1.0)
    check_trials(2 * right, moving, fixed, T, 1.0)
    check_trials(trials_for(w, 0.99), moving, fixed, T, 1.0)  # the wrong confidence
    check_trials(None, moving, fixed, T, 1.0)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["correct"] + ["not yet"] * 3
