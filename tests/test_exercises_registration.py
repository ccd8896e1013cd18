"""The checks of notebook 3's exercises say "correct" for a right answer and "not yet" otherwise."""

import numpy as np

from helpers.exercises.registration import check_least_share, check_rotation_angle


def _angle_deg(T):
    return np.degrees(np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1, 1)))


def test_rotation_angle(capsys):
    check_rotation_angle(_angle_deg)
    check_rotation_angle(lambda T: np.radians(_angle_deg(T)))  # radians, not degrees
    check_rotation_angle(lambda T: np.degrees(np.arccos(np.clip(T[0, 0], -1, 1))))  # right about z only
    check_rotation_angle(None)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["correct"] + ["not yet"] * 3


def test_least_share(capsys):
    w = least_share = (1 - 0.01 ** (1 / 3000)) ** (1 / 3)  # (1 - w^3)^3000 = 1 - 0.99
    assert abs((1 - least_share**3) ** 3000 - 0.01) < 1e-12
    check_least_share(w, 3000, 0.99, w_pair=0.104)
    check_least_share(w, 3000, 0.99)
    check_least_share(w**3, 3000, 0.99)  # the share of all-correct samples, not of matches
    check_least_share((1 - 0.001 ** (1 / 3000)) ** (1 / 3), 3000, 0.99)  # the wrong confidence
    check_least_share(100 * w, 3000, 0.99)  # a percentage
    check_least_share(None, 3000, 0.99)
    check_least_share("a lot", 3000, 0.99)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["correct"] * 2 + ["not yet"] * 5
    assert "below it" in lines[0] and "0.115" in lines[0]
    assert "0 and 1" in lines[4]
