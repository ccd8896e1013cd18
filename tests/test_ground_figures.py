"""Notebook 8's figures draw what they say: an ellipse along each step's loosest direction, at its size."""

import numpy as np
from matplotlib.patches import Ellipse

from helpers.viz import ground_figures


def test_each_ellipse_lies_along_its_loosest_direction_magnified():
    poses = np.tile(np.eye(4), (4, 1, 1))
    poses[:, 0, 3] = [0.0, 2.0, 4.0, 6.0]
    covariances = []
    for degrees in (0.0, 30.0, 120.0):  # each step's loosest direction, from x
        a = np.radians(degrees)
        turn = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        covariances.append(turn @ np.diag([0.1**2, 0.02**2]) @ turn.T)
    fig = ground_figures.ellipses_figure(poses, np.array(covariances), magnify=10)
    ellipses = [p for p in fig.axes[0].patches if isinstance(p, Ellipse)]
    assert len(ellipses) == 3
    for ellipse, degrees, node in zip(ellipses, (0.0, 30.0, 120.0), (1, 2, 3), strict=True):
        assert np.allclose(ellipse.center, poses[node, :2, 3])  # at the node the step reaches
        assert np.isclose(ellipse.width, 2 * 10 * 0.1) and np.isclose(ellipse.height, 2 * 10 * 0.02)
        assert np.isclose(ellipse.angle % 180, degrees, atol=1e-6)
    loosest = fig.axes[1].lines[0].get_ydata()
    assert np.allclose(loosest, 10.0)  # the loosest sigma of every step, in cm


def test_stage_errors_are_the_distances_to_the_truth():
    truth = np.tile(np.eye(4), (3, 1, 1))
    shifted = truth.copy()
    shifted[:, 1, 3] = [0.0, 0.5, 1.5]
    fig = ground_figures.stage_errors_figure(truth, {"odometry only": shifted})
    assert np.allclose(fig.axes[0].lines[0].get_ydata(), [0.0, 0.5, 1.5])
