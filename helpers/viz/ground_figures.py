"""Figures for notebook 8 (your own ground): trajectories of several runs
against the truth, the uncertainty of each step drawn as an ellipse along
the track, and how far each node is from the truth, stage by stage."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Ellipse

from helpers.viz.graph_figures import zoom_with_scale
from helpers.viz.style import COLORS, FIGURE_WIDTH, TEXT_PT, grid, xy_of

# One colour per run or stage of notebook 8's graph: the shared odometry red and optimised blue first, then
# colours no other notebook gives a meaning (purple is the reference's run, orange the loop edges).
STAGE_COLORS = (COLORS["odometry"], COLORS["optimized"], "#bcbd22", "#8c564b", "#7f7f7f")
ELLIPSE_COLOR = "#b8860b"  # dark goldenrod: a step's uncertainty


def runs_figure(
    ground_truth,
    runs: dict,
    title="trajectories from above",
    end_zoom=None,
    inset_at=(0.45, 0.3, 0.5, 0.4),
    colors=None,
):
    """Top view of the truth (green, with its start) and of each run in ``runs``
    (label -> (K, 4, 4) poses), one colour each, ``colors`` or those of :data:`STAGE_COLORS`
    in order; ``end_zoom`` = (width, height) metres adds a zoom, with a scale bar, on the
    end of the truth, drawn at ``inset_at`` (axes fractions)."""
    gt = xy_of(ground_truth)
    fig, ax = plt.subplots(figsize=(8, 6), constrained_layout=True)

    def draw(axis):
        axis.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=4, label="ground truth")
        for (label, poses), color in zip(runs.items(), colors or STAGE_COLORS, strict=False):
            xy = xy_of(poses)
            axis.plot(xy[:, 0], xy[:, 1], color=color, lw=1.6, label=label)

    draw(ax)
    ax.plot(*gt[0], "o", color="black", ms=8, mfc="none", mew=2, label="start")
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title=title)
    grid(ax)
    ax.legend(fontsize=TEXT_PT, loc="upper left")
    if end_zoom is not None:  # centred on the truth's last few metres, so the tracks run into it
        x, y = gt[np.linalg.norm(gt - gt[-1], axis=1) <= min(end_zoom) / 2].mean(axis=0)
        window = (x - end_zoom[0] / 2, x + end_zoom[0] / 2, y - end_zoom[1] / 2, y + end_zoom[1] / 2)
        zoom_with_scale(ax, draw, window, inset_at)
    return fig


def ellipses_figure(poses, covariances, magnify: float, ground_truth=None, every: int = 1):
    """The 2-D position covariance (map frame, (K, 2, 2), m²) of each step of
    the odometry ``poses`` drawn as its one-sigma ellipse at the node it reaches, ``magnify`` times
    larger so that centimetres show on a track of hundreds of metres; beside
    it, each step's sigma along its largest and smallest axes."""
    xy = xy_of(poses)
    cov = np.asarray(covariances, float)
    values, vectors = np.linalg.eigh(cov)  # ascending: [:, 1] is the loosest direction
    fig, (top, side) = plt.subplots(1, 2, figsize=(FIGURE_WIDTH, 4.2), constrained_layout=True, width_ratios=(1, 1))
    if ground_truth is not None:
        gt = xy_of(ground_truth)
        top.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=1.5, label="ground truth")
    top.plot(xy[:, 0], xy[:, 1], color=COLORS["odometry"], lw=1, label="odometry")
    for k in range(0, len(cov), every):
        angle = np.degrees(np.arctan2(vectors[k, 1, 1], vectors[k, 0, 1]))
        width, height = 2 * magnify * np.sqrt(np.maximum(values[k, ::-1], 0))
        top.add_patch(Ellipse(xy[k + 1], width, height, angle=angle, fc="none", ec=ELLIPSE_COLOR, lw=1.2))
    top.plot([], [], color=ELLIPSE_COLOR, lw=1.2, label=f"one-sigma ellipse of each step, x {magnify:g}")
    top.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title="how sure each step is, seen from above")
    top.legend(fontsize=TEXT_PT, loc="best")
    grid(top)
    nodes = np.arange(1, len(cov) + 1)
    side.plot(nodes, 100 * np.sqrt(values[:, 1]), color=ELLIPSE_COLOR, lw=2, label="loosest direction")
    side.plot(nodes, 100 * np.sqrt(np.maximum(values[:, 0], 0)), color="black", lw=1.5, label="surest direction")
    side.set(xlabel="node the step reaches", ylabel="sigma (cm)", ylim=(0, None))
    side.set_title("each step's sigma in the ground plane")
    side.legend(fontsize=TEXT_PT)
    grid(side)
    return fig


def stage_errors_figure(ground_truth, stages: dict, xlabel="node (accepted scan)"):
    """Distance from the true position, node by node, for each stage
    (label -> (K, 4, 4) poses), in the colours of :func:`runs_figure`."""
    truth = np.asarray(ground_truth)[:, :3, 3]
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 3.6), constrained_layout=True)
    for (label, poses), color in zip(stages.items(), STAGE_COLORS, strict=False):
        ax.plot(np.linalg.norm(np.asarray(poses)[:, :3, 3] - truth, axis=1), color=color, lw=2, label=label)
    ax.set(xlabel=xlabel, ylabel="position error (m)", ylim=(0, None))
    grid(ax)
    ax.legend(fontsize=TEXT_PT, loc="upper left")
    return fig


def sigma_errors_figure(ground_truth, graphs: dict, colors=None, xlabel="node (accepted scan)"):
    """Each node's distance from its true position (solid) beside the position sigma its graph gives it
    (dashed), for each graph (label -> ((K, 4, 4) optimised poses, (K,) sigmas in metres)): where the dashed
    line lies near the solid one, the graph knows how far it is off."""
    truth = np.asarray(ground_truth)[:, :3, 3]
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 3.6), constrained_layout=True)
    for (label, (poses, sigmas)), color in zip(graphs.items(), colors or STAGE_COLORS[2:], strict=False):
        ax.plot(np.linalg.norm(np.asarray(poses)[:, :3, 3] - truth, axis=1), color=color, lw=2, label=f"{label}: error")
        ax.plot(np.asarray(sigmas), color=color, lw=1.5, ls="--", label=f"{label}: the graph's sigma")
    ax.set(xlabel=xlabel, ylabel="metres", ylim=(0, None))
    grid(ax)
    ax.legend(fontsize=TEXT_PT, loc="upper left", ncols=2)
    return fig
