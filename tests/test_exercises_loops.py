"""The checks of notebook 5's exercises say ``correct`` for a right answer and ``not yet`` otherwise."""

from types import SimpleNamespace

import numpy as np
import pytest

from helpers.config import Config
from helpers.errors import SlamError
from helpers.exercises.loops import check_false_loop, check_search_radius
from helpers.pipeline import Edge


def pose(x, y, yaw_deg=0.0):
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:2, 3] = x, y
    return T


def test_search_radius(capsys):
    config = Config()
    query = SimpleNamespace(node=50, radius=np.array([12.0, 11.5, 11.0]))
    result = SimpleNamespace(config=config, queries=[query])
    assert check_search_radius(result, 50, 1, 11.5)
    assert capsys.readouterr().out.startswith("correct:")
    assert not check_search_radius(result, 50, 1, config.loop_closure.loop_closure_search_radius)
    assert not check_search_radius(result, 50, 1, None)
    assert capsys.readouterr().out.count("not yet:") == 2
    with pytest.raises(SlamError):
        check_search_radius(result, 49, 1, 11.5)


def test_false_loop(capsys):
    poses_gt = np.array([pose(0, 0), pose(5, 1, 10), pose(9, 3, 20)])
    truth = np.linalg.inv(poses_gt[0]) @ poses_gt[2]
    right = Edge(0, 2, truth @ pose(0.3, 0, 0.5), 0.2)
    wrong = Edge(0, 2, truth @ pose(0.2, 0, 3.0), 0.2)  # a small shift, but turned too far
    assert check_false_loop(poses_gt, right, 0.3, 0.5, False)
    assert check_false_loop(poses_gt, wrong, 0.2, 3.0, True)
    assert capsys.readouterr().out.count("correct:") == 2
    assert not check_false_loop(poses_gt, wrong, 0.2, 3.0, False)  # the verdict
    assert not check_false_loop(poses_gt, right, 0.5, 0.5, False)  # the distance
    assert not check_false_loop(poses_gt, right, None, 0.5, False)
    assert capsys.readouterr().out.count("not yet:") == 3


def test_fixed_radius(monkeypatch, capsys):
    import helpers.exercises.loops as loops

    monkeypatch.setattr(loops, "fixed_radius_loops", lambda result, end: [210, 211])
    result = SimpleNamespace(loops=[SimpleNamespace(j=j) for j in (206, 207, 210, 211, 230)])
    assert loops.check_fixed_radius(result, 212, [211, 210])
    assert "misses" in capsys.readouterr().out
    result.loops = result.loops[2:]
    assert loops.check_fixed_radius(result, 212, [210, 211])
    assert "finds every" in capsys.readouterr().out
    assert not loops.check_fixed_radius(result, 212, [206, 207, 210, 211])
    assert not loops.check_fixed_radius(result, 212, None)
    assert capsys.readouterr().out.count("not yet:") == 2
