"""The checks of notebook 2's exercises say "correct" for a right answer and "not yet" otherwise."""

import numpy as np

from helpers.exercises.parameters import _footprint_overlap, check_grid_step, check_skip_frames
from helpers.slam.registration.features import grid_average


def _plane(spacing=0.5, size=50.0):
    """A flat square of points ``spacing`` apart: a 1 m grid leaves (size / 1)^2 of them."""
    x, y = np.meshgrid(np.arange(0, size, spacing) + 0.25, np.arange(0, size, spacing) + 0.25)
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])


class _Strips:
    """A stand-in for a dataset: scan ``i`` is a 20 m x 10 m patch moved 2 m along x per scan."""

    def __init__(self):
        x, y = np.meshgrid(np.arange(0.0, 20.0), np.arange(0.0, 10.0))
        self.patch = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])

    def scan_in_map(self, index):
        return self.patch + [2.0 * index, 0.0, 0.0]


def test_grid_step(capsys):
    scan = _plane()
    target = len(grid_average(scan, 1.0))
    check_grid_step(1.0, scan, target=target)
    check_grid_step(3.0, scan, target=target)
    check_grid_step(None, scan, target=target)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["correct", "not yet", "not yet"]


def test_skip_frames(capsys):
    data = _Strips()
    right = max(gap for gap in range(1, 10) if _footprint_overlap(data, 0, gap) >= 0.5)
    check_skip_frames(right, data, start=0)
    check_skip_frames(right + 1, data, start=0)
    check_skip_frames(right - 1, data, start=0)
    check_skip_frames(..., data, start=0)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["correct"] + ["not yet"] * 3
