"""Figures for notebook 3: one pair of scans, step by step, then the odometry (the parameter
sweeps shown after each step are in :mod:`.sweep_figures`)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import LogNorm
from matplotlib.legend_handler import HandlerTuple
from matplotlib.patches import Rectangle
from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

from helpers.geometry import transform_points
from helpers.viz.parameter_figures import MATCH_COLORS, _grid
from helpers.viz.style import COLORS, ERROR_CMAP, FIGURE_WIDTH, TEXT_PT

HISTOGRAM_NAMES = ("theta", "alpha", "phi")  # FPFH's three 11-bin histograms, in Open3D's bin order
HISTOGRAM_COLORS = ("#4c72b0", "#dd8452", "#55a868")


def _top_view(ax, points, color=None, scalars=None, size=1.5, **kwargs):
    """Sensor-frame points seen from above: y (to the left) across, x (forward) up."""
    if scalars is not None:
        return ax.scatter(points[:, 1], points[:, 0], c=scalars, s=size, linewidths=0, **kwargs)
    return ax.scatter(points[:, 1], points[:, 0], color=color, s=size, linewidths=0, **kwargs)


def clouds_figure(moving, fixed, names=("moving", "fixed"), zoom_m: float = 40.0, above_m: float = 3.0):
    """Both downsampled clouds from above, each in its own sensor frame and
    overlaid as if the drone had not moved, beside a zoom of ``zoom_m``
    metres around the fixed scan's highest point near the middle of the
    strip (a roof). The zoom keeps only the points over ``above_m`` above the
    ground there (roofs, trees): the same roof shows twice, as far apart as
    the drone moved."""
    middle = np.abs(fixed[:, 1]) < 0.5 * np.abs(fixed[:, 1]).max()
    top = fixed[middle][np.argmax(fixed[middle, 2])].copy()
    top[0] = np.clip(
        top[0], fixed[:, 0].min() + zoom_m / 2, fixed[:, 0].max() - zoom_m / 2
    )  # the zoom inside the strip
    window = (top[1] + zoom_m / 2, top[1] - zoom_m / 2, top[0] - zoom_m / 2, top[0] + zoom_m / 2)
    fig, (ax, zoom) = plt.subplots(1, 2, figsize=(FIGURE_WIDTH, 3.6), width_ratios=(3.2, 1), constrained_layout=True)
    for points, name, key in ((fixed, names[1], "fixed"), (moving, names[0], "moving")):
        _top_view(ax, points, color=COLORS[key], size=1.0, alpha=0.8, label=f"{name}: {len(points)} points")
        inside = (np.abs(points[:, 1] - top[1]) < zoom_m / 2) & (np.abs(points[:, 0] - top[0]) < zoom_m / 2)
        ground = np.percentile(points[inside, 2], 20)
        _top_view(zoom, points[inside & (points[:, 2] > ground + above_m)], color=COLORS[key], size=14, alpha=0.8)
    for axis in (ax, zoom):
        axis.set(aspect="equal", ylabel="x, forward (m)")
        _grid(axis)
    ax.set(xlabel="y, to the left of the drone (m)", title="the two scans, each in its own frame")
    ax.invert_xaxis()
    ax.add_patch(Rectangle((window[1], window[2]), zoom_m, zoom_m, fill=False, edgecolor="black", lw=1.2))
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.28), ncol=2, fontsize=TEXT_PT, markerscale=6, frameon=False)
    title = f"zoom, {zoom_m:g} m square:\npoints {above_m:g} m above\nthe ground"  # as narrow as its panel
    zoom.set(xlim=window[:2], ylim=window[2:], xlabel="y (m)", title=title)
    return fig


def descriptor_figure(descriptors: dict):
    """The 33 bins of a few FPFH descriptors, side by side, coloured by histogram.

    ``descriptors`` maps a label to a (33,) normalised descriptor; the first
    is drawn as bars, the others as outlined steps over it."""
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 3.6), constrained_layout=True)
    bins = np.arange(33)
    items = list(descriptors.items())
    label, first = items[0]
    colors = np.repeat(HISTOGRAM_COLORS, 11)
    bars = ax.bar(bins, first, 0.85, color=colors)
    styles = (("black", "-"), ("#d62728", "--"), ("#555555", ":"))
    for (name, values), (color, ls) in zip(items[1:], styles, strict=False):
        ax.step(bins, values, where="mid", color=color, ls=ls, lw=1.6, label=name)
    for h, name in enumerate(HISTOGRAM_NAMES):
        ax.axvline(11 * h - 0.5, color="#999999", lw=0.8)
        ax.text(
            11 * h + 5,
            1.0,
            rf"angle $\{name}$",
            transform=ax.get_xaxis_transform(),
            ha="center",
            va="bottom",
            color=HISTOGRAM_COLORS[h],
            fontsize=10,
            fontweight="bold",
        )
    ax.set(xlim=(-0.7, 32.7), xlabel="bin (11 per angle)", ylabel="normalised count")
    ax.set_xticks([0, 5, 10, 11, 16, 21, 22, 27, 32])
    _grid(ax)
    handles, labels = ax.get_legend_handles_labels()
    one_per_angle = tuple(bars.patches[11 * h] for h in range(3))  # the bars take each histogram's colour
    ax.legend(
        [one_per_angle, *handles],
        [label, *labels],
        handler_map={tuple: HandlerTuple(ndivide=None, pad=0.2)},
        fontsize=TEXT_PT,
        loc="upper right",
    )
    return fig


def matches_figure(moving, fixed, matches, inliers, shown: int = 80, gap: float = 25.0, seed: int = 0):
    """Both clouds from above, the moving one drawn above the fixed one, and a
    random subsample of match lines: inliers of the robust fit in purple,
    rejected matches in grey."""
    rng = np.random.default_rng(seed)
    lift = fixed[:, 0].max() - moving[:, 0].min() + gap  # moving drawn this much farther forward
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 5.0), constrained_layout=True)
    _top_view(ax, fixed, color=COLORS["fixed"], size=2)
    _top_view(ax, moving + [lift, 0, 0], color=COLORS["moving"], size=2)
    for kind, mask in (("outlier", ~inliers), ("inlier", inliers)):
        picked = np.flatnonzero(mask)
        picked = rng.choice(picked, size=min(shown, len(picked)), replace=False) if len(picked) else picked
        a, b = moving[matches[picked, 0]], fixed[matches[picked, 1]]
        segments = np.stack([np.column_stack([a[:, 1], a[:, 0] + lift]), np.column_stack([b[:, 1], b[:, 0]])], 1)
        width, alpha = (1.0, 0.9) if kind == "inlier" else (0.6, 0.6)
        ax.add_collection(
            LineCollection(
                segments,
                colors=MATCH_COLORS[kind],
                linewidths=width,
                alpha=alpha,
                label=f"{kind}s ({mask.sum()}, {len(picked)} drawn)",
            )
        )
    ax.set(xlabel="y, to the left of the drone (m)", ylabel="x, forward (m)", aspect="equal")
    ax.set_yticks([])
    ax.invert_xaxis()
    ax.text(0.01, 0.97, "moving", transform=ax.transAxes, color=COLORS["moving"], fontweight="bold", va="top")
    ax.text(0.01, 0.03, "fixed", transform=ax.transAxes, color=COLORS["fixed"], fontweight="bold")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=TEXT_PT, frameon=False)
    return fig


def profile_figure(moving, fixed, stages: dict, y: float, half_width: float = 0.5):
    """Side views of the moving cloud (pink) over the fixed one (cyan), one per
    stage: the points within ``half_width`` of the line ``y`` (fixed scan's
    frame), forward distance across, height up. A wrong motion shows as
    doubled roofs and walls. ``stages`` maps a title to a 4 x 4 transform
    applied to ``moving``."""
    n = len(stages)
    fig, axes = plt.subplots(
        n, 1, figsize=(FIGURE_WIDTH, 2.2 * n + 0.4), sharex=True, sharey=True, constrained_layout=True
    )
    for ax, (title, transform) in zip(np.atleast_1d(axes), stages.items(), strict=True):
        moved = transform_points(moving, transform)
        for points, key, marker in ((fixed, "fixed", "o"), (moved, "moving", "o")):
            band = points[np.abs(points[:, 1] - y) < half_width]
            ax.plot(band[:, 0], band[:, 2], marker, color=COLORS[key], ms=3.5, label=key, alpha=0.9)
        ax.set_title(title, loc="left")
        ax.set_ylabel("z (m)")
        _grid(ax)
    # On the first panel's title line, right: inside, it covered the points of a roof.
    axes[0].legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=TEXT_PT, ncol=2, frameon=False)
    axes[-1].set_xlabel("x, forward (m)")
    return fig


def surface_error_figure(moving, errors: dict, low: float = 0.01, high: float = 3.0):
    """The moving cloud from above, once per stage, each point coloured by its
    distance to the true surface once moved by that stage's transform.

    ``errors`` maps a title to the (N,) distances in metres. The colour scale
    is logarithmic from ``low`` to ``high`` metres, on a map with no white
    end, so that a centimetre and a metre both show."""
    n = len(errors)
    fig, axes = plt.subplots(n, 1, figsize=(FIGURE_WIDTH, 2.3 * n + 0.6), sharex=True, constrained_layout=True)
    axes = np.atleast_1d(axes)
    norm = LogNorm(low, high, clip=True)
    for ax, (title, distance) in zip(axes, errors.items(), strict=True):
        order = np.argsort(distance)  # the worst points on top
        art = _top_view(ax, moving[order], scalars=np.maximum(distance[order], low), size=3, cmap=ERROR_CMAP, norm=norm)
        ax.set_title(f"{title}: median {np.median(distance) * 100:.0f} cm", loc="left")
        ax.set(ylabel="x (m)", aspect="equal")
    axes[-1].set_xlabel("y, to the left of the drone (m)")
    axes[-1].invert_xaxis()
    bar = fig.colorbar(art, ax=axes, label="distance to the true surface (m)", shrink=0.8, extend="both")
    bar.set_ticks([0.01, 0.03, 0.1, 0.3, 1.0, 3.0], labels=["0.01", "0.03", "0.1", "0.3", "1", "3"])
    return fig


def darboux_figure(p, n_p, q, n_q, frame: dict, angles: dict):
    """The Darboux frame of one pair of points, drawn in 3-D: the two points,
    their normals, and the frame ``u``, ``v``, ``w`` built at ``p`` (``frame``
    maps each name to a unit vector); ``angles`` (names to values, radians
    or cosines as the caller says) go in the title."""
    fig = plt.figure(figsize=(7.5, 5.6), constrained_layout=True)
    ax = fig.add_subplot(projection="3d")
    span = np.linalg.norm(q - p)
    scale = 0.45 * span
    ax.plot(*np.column_stack([p, q]), color="#888888", ls="--", lw=1.2)
    ax.scatter(*p, color=COLORS["moving"], s=60)
    ax.scatter(*q, color=COLORS["fixed"], s=60)
    ax.text(*p, "  p", fontsize=12)
    ax.text(*q, "  q", fontsize=12)
    ax.quiver(*q, *(scale * n_q), color=COLORS["fixed"], lw=2.5, arrow_length_ratio=0.15)
    ax.text(*(q + 1.08 * scale * n_q), r"$n_q$", color=COLORS["fixed"], fontsize=12)
    for (name, vector), color in zip(frame.items(), ("#d62728", "#2ca02c", "#1f77b4"), strict=True):
        ax.quiver(*p, *(scale * vector), color=color, lw=2.5, arrow_length_ratio=0.15)
        ax.text(*(p + 1.1 * scale * vector), f"${name}$", color=color, fontsize=13, fontweight="bold")
    every = np.vstack([p, q, p + scale * np.vstack(list(frame.values())), q + scale * n_q])
    centre, half = every.mean(axis=0), 0.6 * np.ptp(every, axis=0).max()
    ax.set(
        xlim=(centre[0] - half, centre[0] + half),
        ylim=(centre[1] - half, centre[1] + half),
        zlim=(centre[2] - half, centre[2] + half),
        xlabel="x (m)",
        ylabel="y (m)",
        zlabel="z (m)",
    )
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=22, azim=-60)
    ax.set_title(",  ".join(f"{name} = {value:.2f}" for name, value in angles.items()), fontsize=11)
    return fig


def icp_convergence_figure(runs: dict):
    """ICP iteration by iteration: for each run (a title mapped to a dict of
    per-iteration arrays ``pose_cm``, ``surface_cm`` and ``rmse_m``, iteration
    0 being the start), the pose error against the truth, the median distance
    of the moved points to the true surface, and ICP's own RMSE."""
    fig, axes = plt.subplots(1, 3, figsize=(FIGURE_WIDTH, 3.4), constrained_layout=True)
    panels = (
        ("pose_cm", "pose error vs the truth (cm)", "error of the motion", True),
        ("surface_cm", "median distance to the surface (cm)", "moved points vs the true ground", True),
        ("rmse_m", "ICP RMSE (m)", "what ICP itself sees", False),
    )
    for (title, run), color in zip(runs.items(), ("#1f77b4", "#d62728", "#2ca02c"), strict=False):
        for ax, (key, label, heading, log) in zip(axes, panels, strict=True):
            values = np.asarray(run[key], float)
            ax.plot(np.arange(len(values)), values, "o-", color=color, ms=4, lw=1.6, label=title)
            ax.set(xlabel="ICP iteration", ylabel=label, title=heading)
            if log:
                ax.set_yscale("log")
                ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
                ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
                ax.yaxis.set_minor_formatter(NullFormatter())
    for ax in axes:
        _grid(ax)
    axes[2].set_ylim(0, None)
    axes[0].legend(fontsize=TEXT_PT)
    return fig
