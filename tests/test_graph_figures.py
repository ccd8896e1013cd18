"""Notebook 6's top views: the zoom sits on the longest loop edge and carries a scale bar of a round length."""

import numpy as np
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

from helpers.viz import graph_figures


def _line(n=50):
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.arange(n, dtype=float)  # 1 m apart along x
    return poses


def test_the_window_is_centred_on_the_longest_loop_edge():
    poses = _line()
    window = graph_figures.around_longest_loop(poses, poses, [(0, 10), (5, 45)], (24.0, 18.0))
    assert np.allclose(window, (13.0, 37.0, -9.0, 9.0))  # edge 5-45, its middle at x = 25
    raised = graph_figures.around_longest_loop(poses, poses, [(5, 45)], (24.0, 18.0), lift=3.0)
    assert np.allclose(raised, (13.0, 37.0, -6.0, 12.0))


def test_the_pose_graph_zoom_shows_that_window_and_a_round_scale_bar():
    poses = _line()
    fig = graph_figures.pose_graph_figure(poses, [(0, 10), (5, 45)], zoom=(24.0, 18.0))
    zoom = fig.axes[0].child_axes[0]
    assert np.allclose([*zoom.get_xlim(), *zoom.get_ylim()], (13.0, 37.0, -9.0, 9.0))
    bars = [artist for artist in zoom.artists if isinstance(artist, AnchoredSizeBar)]
    assert len(bars) == 1
    assert bars[0].txt_label.get_text() == "5 m"  # a round length, at most a third of 24 m


def test_the_left_out_figure_sets_each_edges_two_residuals_side_by_side():
    """One pair of bars per loop edge, the optimised graph's residual left of the left-out one, on a log scale."""
    fig = graph_figures.left_out_figure(["0-50", "3-120"], [0.9, 3.0], [357.0, 4.5])
    ax = fig.axes[0]
    assert ax.get_yscale() == "log"
    at_optimum, left_out = ax.containers
    assert [bar.get_height() for bar in at_optimum] == [0.9, 3.0]
    assert [bar.get_height() for bar in left_out] == [357.0, 4.5]
    assert all(a.get_x() < b.get_x() for a, b in zip(at_optimum, left_out, strict=True))
    assert [tick.get_text() for tick in ax.get_xticklabels()] == ["0-50", "3-120"]
