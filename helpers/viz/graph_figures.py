"""Figures for notebook 6: the pose graph, robust kernels and the optimised trajectories."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from helpers.viz.style import COLORS, FIGURE_WIDTH, TEXT_PT, grid, inset_zoom, scale_bar, segments, xy_of


def zoom_with_scale(ax, draw, window, at) -> None:
    """:func:`helpers.viz.style.inset_zoom` with a :func:`scale_bar` in the zoom."""
    inset_zoom(ax, draw, window, at)
    scale_bar(ax.child_axes[-1], window[1] - window[0])


def around_longest_loop(measured, centred, loop_pairs, size, lift: float = 0.0):
    """(xmin, xmax, ymin, ymax): a window ``size`` = (width, height) metres
    around the loop edge whose ends lie farthest apart on ``measured`` poses,
    centred on its middle on ``centred`` poses, raised by ``lift`` metres."""
    pairs = np.asarray(loop_pairs, int).reshape(-1, 2)
    a, b = xy_of(measured)[pairs[:, 0]], xy_of(measured)[pairs[:, 1]]
    longest = pairs[np.argmax(np.linalg.norm(a - b, axis=1))]
    x, y = xy_of(centred)[longest].mean(axis=0)
    y += lift
    return (x - size[0] / 2, x + size[0] / 2, y - size[1] / 2, y + size[1] / 2)


def loop_arcs(a, b, bend: float = 0.25, points: int = 24) -> np.ndarray:
    """(L, points, 2) arcs from ``a`` to ``b`` (top view) bulging sideways by
    ``bend`` times their length, all towards +y (or +x for chords along y):
    visible even where the two ends lie on the same line."""
    a, b = np.asarray(a, float)[:, :2], np.asarray(b, float)[:, :2]
    side = (b - a) @ np.array([[0.0, 1.0], [-1.0, 0.0]])  # the chord turned by 90 degrees
    flip = (side[:, 1] < 0) | ((side[:, 1] == 0) & (side[:, 0] < 0))
    side[flip] *= -1
    control = (a + b) / 2 + bend * side
    t = np.linspace(0, 1, points)[None, :, None]
    return (1 - t) ** 2 * a[:, None] + 2 * (1 - t) * t * control[:, None] + t**2 * b[:, None]


def chain_figure(truth, odometry, optimized, closed_form=None):
    """The 1-D chain: positions on the line (top: truth, odometry, optimised,
    with the loop edge from the first node to the last as an arc) and, below,
    each node's error before and after, and the correction the loop brought."""
    truth, odometry, optimized = (np.asarray(v, float) for v in (truth, odometry, optimized))
    nodes = np.arange(len(truth))
    fig, (top, bottom) = plt.subplots(
        2, 1, figsize=(FIGURE_WIDTH, 5.4), constrained_layout=True, height_ratios=(1, 1.4)
    )
    for row, (name, x, color) in enumerate(
        (
            ("truth", truth, COLORS["ground_truth"]),
            ("odometry", odometry, COLORS["odometry"]),
            ("optimised", optimized, COLORS["optimized"]),
        )
    ):
        y = np.full_like(x, -row)
        top.plot(x, y, "-o", color=color, ms=6, lw=1.5)
        top.text(x[0] - 0.02 * np.ptp(truth), -row, name, ha="right", va="center", color=color)
    xs = np.linspace(optimized[0], optimized[-1], 60)  # the loop edge: an arc under the optimised row
    half = (optimized[-1] - optimized[0]) / 2
    arc = -2 - 0.8 * (1 - ((xs - optimized[0] - half) / half) ** 2)
    top.plot(xs, arc, color=COLORS["loop"], lw=2)
    top.text(xs[30], -2.85, "loop edge: first node to last", color=COLORS["loop"], ha="center", va="top")
    top.set(xlabel="position on the line (m)", yticks=[], ylim=(-3.6, 0.6), title="a chain of poses on a line")
    top.set_xlim(truth[0] - 0.15 * np.ptp(truth), truth[-1] + 0.05 * np.ptp(truth))
    grid(top)
    bottom.plot(nodes, odometry - truth, "-o", color=COLORS["odometry"], label="error of the odometry")
    bottom.plot(nodes, optimized - truth, "-o", color=COLORS["optimized"], label="error after least squares")
    bottom.bar(nodes, optimized - odometry, width=0.35, color=COLORS["loop"], alpha=0.6, label="correction")
    if closed_form is not None:
        bottom.plot(nodes, np.asarray(closed_form, float) - odometry, "k--", lw=1, label="correction, closed form")
    bottom.axhline(0, color="black", lw=0.8)
    bottom.set(xlabel="node", ylabel="metres", xticks=nodes)
    grid(bottom)
    bottom.legend(fontsize=TEXT_PT, loc="lower left")
    return fig


def iterations_figure(errors, lambdas=None, title="Levenberg-Marquardt, step by step"):
    """The graph error after each iteration and, in a second panel, how far
    it still is above its final value (log scale) with the damping lambda
    the optimiser used, if given."""
    errors = np.asarray(errors, float)
    steps = np.arange(len(errors))
    fig, (left, right) = plt.subplots(1, 2, figsize=(FIGURE_WIDTH, 3.4), constrained_layout=True)
    left.plot(steps, errors, "-o", color=COLORS["optimized"])
    left.set(xlabel="iteration (0 = the initial guess)", ylabel="graph error", xticks=steps, ylim=(0, None))
    left.set_title(title)
    excess = errors[:-1] - errors[-1]
    shown = excess > 0
    label = "graph error above its final value"
    right.semilogy(steps[:-1][shown], excess[shown], "-o", color=COLORS["optimized"], label=label)
    if lambdas is not None:
        right.semilogy(steps, np.asarray(lambdas, float), "s--", color="#6a3d9a", ms=4, label="damping lambda")
    right.set(xlabel="iteration", xticks=steps, title="how fast it settles (log scale)")
    right.legend(fontsize=TEXT_PT)
    for ax in (left, right):
        grid(ax)
    return fig


def pose_graph_figure(poses, loop_pairs, every: int = 1, zoom=(24.0, 18.0), inset_at=(0.42, 0.2, 0.42, 0.6)):
    """The pose graph drawn on its initial (odometry) poses: nodes as dots,
    odometry edges as a red line, loop edges in orange. ``zoom`` = (width,
    height) metres adds a zoom, with a scale bar, around the longest loop edge,
    drawn at ``inset_at`` (x0, y0, width, height in axes fractions); None: no zoom."""
    xy = xy_of(poses)
    pairs = np.asarray(loop_pairs, int).reshape(-1, 2)
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 5.8), constrained_layout=True)

    def draw(axis, size):
        axis.plot(xy[:, 0], xy[:, 1], color=COLORS["odometry"], lw=1.2, zorder=2)
        axis.scatter(xy[::every, 0], xy[::every, 1], s=size, color="black", zorder=3)
        axis.add_collection(
            LineCollection(segments(xy[pairs[:, 0]], xy[pairs[:, 1]]), colors=COLORS["loop"], linewidths=2.2, zorder=4)
        )

    draw(ax, 6)
    ax.plot([], [], color=COLORS["odometry"], lw=1.2, label=f"odometry edges ({len(xy) - 1})")
    ax.scatter([], [], s=6, color="black", label=f"nodes ({len(xy)})")
    ax.plot([], [], color=COLORS["loop"], lw=2.2, label=f"loop edges ({len(pairs)})")
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title="the pose graph on the odometry poses")
    grid(ax)
    ax.legend(loc="center left", bbox_to_anchor=(0.1, 0.5) if zoom is not None else (0.35, 0.5), fontsize=TEXT_PT)
    if zoom is not None and len(pairs):
        window = around_longest_loop(poses, poses, pairs, zoom)
        zoom_with_scale(ax, lambda axis: draw(axis, 14), window, inset_at)
    return fig


def kernels_figure(scales: dict, limit: float = 10.0):
    """The cost rho(r) and the weight w(r) = rho'(r) / r of each robust kernel
    as functions of the whitened residual r (in sigmas)."""
    r = np.linspace(0, limit, 400)
    costs = {"none (least squares)": (r**2 / 2, np.ones_like(r))}
    if "huber" in scales:
        k = scales["huber"]
        small = np.abs(r) <= k
        costs[f"Huber, k = {k:g}"] = (
            np.where(small, r**2 / 2, k * np.abs(r) - k**2 / 2),
            np.where(small, 1.0, k / np.maximum(np.abs(r), 1e-12)),
        )
    if "cauchy" in scales:
        c = scales["cauchy"]
        costs[f"Cauchy, c = {c:g}"] = (c**2 / 2 * np.log1p((r / c) ** 2), 1 / (1 + (r / c) ** 2))
    fig, (left, right) = plt.subplots(1, 2, figsize=(FIGURE_WIDTH, 3.4), constrained_layout=True)
    for (name, (rho, weight)), color in zip(costs.items(), ("black", "#6a3d9a", COLORS["loop"]), strict=False):
        left.plot(r, rho, color=color, lw=2, label=name)
        right.plot(r, weight, color=color, lw=2, label=name)
    left.set(xlabel="whitened residual r (sigmas)", ylabel="cost rho(r)", ylim=(0, limit**2 / 4), title="cost")
    right.set(xlabel="whitened residual r (sigmas)", ylabel="weight w(r)", ylim=(0, 1.05), title="weight")
    for ax in (left, right):
        grid(ax)
    right.legend(fontsize=TEXT_PT)
    return fig


def trajectories_figure(
    ground_truth,
    odometry,
    optimized,
    loop_pairs=(),
    zoom=(50.0, 20.0),
    title="trajectories from above",
    inset_at=(0.42, 0.2, 0.42, 0.6),
):
    """Top view of the three trajectories in their colours, loop edges
    drawn on the optimised one, on top, as arcs with dots at both ends (a
    straight segment would run along the track and hide under it).
    ``zoom`` = (width, height) metres adds a zoom, with a scale bar, around the
    loop edge longest on the odometry, on the optimised poses (raised a little:
    room for the arcs above the track); None: no zoom."""
    gt, odo, opt = xy_of(ground_truth), xy_of(odometry), xy_of(optimized)
    pairs = np.asarray(loop_pairs, int).reshape(-1, 2)
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 5.8), constrained_layout=True)

    def draw(axis):
        axis.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=3, label="ground truth")
        axis.plot(odo[:, 0], odo[:, 1], color=COLORS["odometry"], lw=1.6, label="odometry only")
        axis.plot(opt[:, 0], opt[:, 1], color=COLORS["optimized"], lw=1.6, label="after optimisation")
        if len(pairs):  # on top, as arcs: both ends of a loop edge lie on the same stretch of track
            arcs = loop_arcs(opt[pairs[:, 0]], opt[pairs[:, 1]])
            axis.add_collection(LineCollection(arcs, colors=COLORS["loop"], linewidths=1.8, zorder=5))
            ends = opt[pairs.ravel()]
            axis.plot(ends[:, 0], ends[:, 1], "o", color=COLORS["loop"], ms=3.5, zorder=6)
            axis.plot([], [], "o-", color=COLORS["loop"], ms=3.5, lw=1.8, label="loop edges (drawn as arcs)")

    draw(ax)
    ax.plot(*gt[0], "o", color="black", ms=8, mfc="none", mew=2, label="start")
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title=title)
    grid(ax)
    ax.legend(loc="center left", bbox_to_anchor=(0.1, 0.5) if zoom is not None else (0.35, 0.5), fontsize=TEXT_PT)
    if zoom is not None and len(pairs):
        window = around_longest_loop(odometry, optimized, pairs, zoom, lift=0.15 * zoom[1])
        zoom_with_scale(ax, draw, window, inset_at)
    return fig


def position_errors_figure(x, errors: dict, xlabel="node (accepted scan)", loop_nodes=()):
    """Distance from the true position, node by node, one line per
    trajectory; ``errors`` maps a label (whose colour key is found from
    "odometry"/"optimi") to (N,) errors in metres. Loop nodes are marked."""
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 3.6), constrained_layout=True)
    for name, values in errors.items():
        color = COLORS["odometry"] if "odometry" in name else COLORS["optimized"]
        ax.plot(x, values, color=color, lw=2, label=name)
    for k, node in enumerate(loop_nodes):
        ax.axvline(node, color=COLORS["loop"], lw=1, alpha=0.6, label="a loop edge arrives" if k == 0 else None)
    ax.set(xlabel=xlabel, ylabel="position error (m)", ylim=(0, None))
    grid(ax)
    ax.legend(fontsize=TEXT_PT, loc="upper left")
    return fig


def loop_weights_figure(labels, whitened, weights):
    """Each loop edge after optimisation: its whitened residual (sigmas) and
    the weight the robust kernel gave it."""
    x = np.arange(len(labels))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(FIGURE_WIDTH, 4.6), sharex=True, constrained_layout=True)
    top.bar(x, whitened, color=COLORS["loop"], width=0.7)
    top.set(ylabel="residual (sigmas)", title="loop edges after optimisation")
    bottom.bar(x, weights, color=COLORS["loop"], width=0.7)
    bottom.axhline(1, color="black", lw=1, ls="--")
    bottom.set(ylabel="kernel weight", ylim=(0, 1.1))
    bottom.set_xticks(x, labels, rotation=60, fontsize=TEXT_PT)
    bottom.set_xlabel("loop edge (older node - current node)")
    for ax in (top, bottom):
        grid(ax)
    return fig


def left_out_figure(labels, at_optimum, left_out):
    """Each loop edge's whitened residual (sigmas, log scale) where the optimised graph leaves it, and where
    the graph without it would (its leave-one-out residual), side by side."""
    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 3.6), constrained_layout=True)
    ax.bar(x - 0.2, at_optimum, width=0.4, color=COLORS["optimized"], label="in the optimised graph")
    ax.bar(x + 0.2, left_out, width=0.4, color=COLORS["loop"], label="left out: against the graph without it")
    ax.set_yscale("log")
    ax.set_xticks(x, labels, rotation=30, fontsize=TEXT_PT)
    ax.set(xlabel="loop edge (older node - current node)", ylabel="residual (sigmas)")
    ax.set_title("where each loop edge ends: in the graph, and left out of it")
    ax.legend(loc="upper left", fontsize=TEXT_PT)
    grid(ax)
    return fig


def bad_edge_figure(ground_truth, results: dict, bad_pair, inset=None):
    """One panel per kernel: the trajectory optimised with a deliberately
    wrong loop edge (drawn dashed black), against the ground truth."""
    gt = xy_of(ground_truth)
    n = len(results)
    fig, axes = plt.subplots(
        1, n, figsize=(min(FIGURE_WIDTH, 6.2 * n), 2.9), squeeze=False, sharey=True, constrained_layout=True
    )
    for ax, (title, poses) in zip(axes[0], results.items(), strict=True):
        xy = xy_of(poses)
        ax.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=3, label="ground truth")
        ax.plot(xy[:, 0], xy[:, 1], color=COLORS["optimized"], lw=1.6, label="after optimisation")
        i, j = bad_pair
        ax.plot(*segments(xy[[i]], xy[[j]])[0].T, "k--", lw=1.5, label="the wrong loop edge")
        ax.plot(*xy[[i, j]].T, "ko", ms=5)
        ax.set(title=title, xlabel="x (m)", aspect="equal")
        grid(ax)
    axes[0, 0].set_ylabel("y (m)")
    # Under the panels: inside one, it would cover a trajectory the wrong edge folds across the loop.
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=TEXT_PT, frameon=False)
    return fig
