"""Figures (and the parameter table) for notebooks 2 (parameters) and 3 (registration).

Each function takes plain numbers or arrays and returns a matplotlib figure;
a notebook shows it with :func:`helpers.render.show_figure`. The colours are
those of :data:`helpers.render.COLORS`, so a moving scan, a fixed scan, the
ground truth and the odometry look the same in every notebook.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

from .config import SlamConfig, describe
from .render import COLORS

MATCH_COLORS = {"inlier": "#6a3d9a", "outlier": "#b0b0b0"}  # purple: kept by the robust fit; grey: rejected
CORRECT_COLORS = {"correct": "#6a3d9a", "wrong": "#d0d0d0"}  # the same idea, judged by the ground truth
HISTOGRAM_NAMES = ("theta", "alpha", "phi")  # FPFH's three 11-bin histograms, in Open3D's bin order
HISTOGRAM_COLORS = ("#4c72b0", "#dd8452", "#55a868")

# The reference workflow's name for each of our parameters (ours have none).
REFERENCE_NAMES = {
    "skip_frames": "skipFrames",
    "grid_step": "gridStep",
    "neighbors": "neighbors",
    "match_threshold": "matchThreshold",
    "match_ratio": "matchRatio",
    "max_distance": "maxDistance",
    "max_num_trials": "maxNumTrails",
    "confidence": "Confidence",
    "metric": "metric",
    "inlier_distance": "inlierDistance",
    "align_grid_step": "alignGridStep",
    "loop_closure_search_radius": "loopClosureSearchRadius",
    "n_scans_per_submap": "nScansPerSubmap",
    "sub_map_thresh": "subMapThresh",
    "loop_closure_threshold": "loopClosureThreshold",
    "rmse_threshold": "rmseThreshold",
}
# Which stage (and notebook) each parameter belongs to, in workflow order.
STAGES = (
    ("Registration, notebook 3", ("skip_frames", "grid_step", "neighbors", "match_threshold", "match_ratio")),
    ("", ("max_distance", "max_num_trials", "confidence", "seed", "metric", "inlier_distance", "icp_grid_step")),
    ("", ("icp_fallback_rmse",)),
    ("Submaps, notebook 4", ("align_grid_step", "n_scans_per_submap")),
    ("Loop closure, notebook 5", ("loop_closure_search_radius", "sub_map_thresh", "loop_closure_threshold")),
    ("", ("rmse_threshold", "loop_search_growth")),
    ("Pose graph, notebook 6", ("edges_back", "graph_weights", "loop_kernel")),
)


def parameter_table(config: SlamConfig | None = None) -> str:
    """Every SLAM parameter as a Markdown table, grouped by stage: name,
    value, the reference's name and meaning. Parameters no stage lists are
    put at the end, so none is ever left out."""
    rows = {name: (value, meaning) for name, value, meaning in describe(config or SlamConfig())}
    listed = [name for _, names in STAGES for name in names]
    stages = [*STAGES, ("Other", tuple(n for n in rows if n not in listed))]
    lines = ["| stage | parameter | value | reference | meaning |", "|---|---|---|---|---|"]
    for stage, names in stages:
        for i, name in enumerate(n for n in names if n in rows):
            value, meaning = rows[name]
            label = f"**{stage}**" if stage and i == 0 else ""
            reference = f"`{REFERENCE_NAMES[name]}`" if name in REFERENCE_NAMES else "(ours)"
            lines.append(f"| {label} | `{name}` | {_value(value)} | {reference} | {meaning} |")
    return "\n".join(lines)


def _value(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _grid(ax):
    ax.grid(True, color="#e5e5e5", linewidth=0.8)
    ax.set_axisbelow(True)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)


def _mark_default(ax, x, label="default", top=True):
    ax.axvline(x, color="#555555", linestyle=":", linewidth=1.2)
    where, offset = (1.0, -12) if top else (0.0, 4)
    ax.annotate(
        label,
        (x, where),
        xycoords=("data", "axes fraction"),
        xytext=(3, offset),
        textcoords="offset points",
        fontsize=9,
        color="#555555",
    )


# ----------------------------------------------------------------------------------------------------------------
# Notebook 2: one figure per parameter experiment
# ----------------------------------------------------------------------------------------------------------------


def grid_step_figure(steps, n_points, fpfh_ms, raw_points: int, default: float = 1.5):
    """Points left after grid averaging, and FPFH time, against the grid step."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
    left.plot(steps, n_points, "o-", color=COLORS["fixed"], lw=2)
    left.axhline(raw_points, color="#888888", lw=1, ls="--")
    left.annotate("raw scan", (steps[-1], raw_points), xytext=(-50, -14), textcoords="offset points", fontsize=9)
    left.set(xlabel="grid step (m)", ylabel="points after downsampling", title="cloud size", ylim=(0, None))
    right.plot(steps, fpfh_ms, "o-", color=COLORS["odometry"], lw=2)
    right.set(xlabel="grid step (m)", ylabel="FPFH time (ms)", title="descriptor time, one scan", ylim=(0, None))
    for ax in (left, right):
        _grid(ax)
        _mark_default(ax, default)
    return fig


def _stacked_matches(ax, x, correct, total, width, xlabel, default, log=False):
    correct, total = np.asarray(correct), np.asarray(total)
    ax.bar(x, correct, width, color=CORRECT_COLORS["correct"], label="correct")
    ax.bar(x, total - correct, width, bottom=correct, color=CORRECT_COLORS["wrong"], label="wrong")
    ax.set(xlabel=xlabel, ylabel="matches", ylim=(0, 1.3 * total.max()))  # room for the legend
    share = ax.twinx()
    share.plot(x, 100 * correct / np.maximum(total, 1), "o-", color="black", lw=1.6, label="share correct")
    share.set(ylabel="share correct (%)", ylim=(0, 1.3 * 100 * (correct / np.maximum(total, 1)).max()))
    if log:
        ax.set_xscale("log")
    _grid(ax)
    share.spines["top"].set_visible(False)
    _mark_default(ax, default)
    return share


def neighbors_figure(neighbors, n_correct, n_matches, default: int = 60):
    """Matches (correct ones in colour) and the share correct against the FPFH neighbourhood size."""
    fig, ax = plt.subplots(figsize=(7.5, 3.8), constrained_layout=True)
    widths = 0.25 * np.asarray(neighbors, float)
    share = _stacked_matches(ax, neighbors, n_correct, n_matches, widths, "neighbours (k)", default, log=True)
    ax.set_xticks(neighbors, [str(k) for k in neighbors])
    ax.minorticks_off()
    _legend(ax, share)
    ax.set_title("more neighbours, more telling descriptors")
    return fig


def matching_figure(thresholds, th_correct, th_total, ratios, ra_correct, ra_total, defaults=(0.1, 0.97)):
    """Matches and share correct against the match threshold (left) and the ratio (right)."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 3.8), constrained_layout=True)
    x_th, x_ra = np.arange(len(thresholds)), np.arange(len(ratios))
    s1 = _stacked_matches(left, x_th, th_correct, th_total, 0.6, "match threshold", list(thresholds).index(defaults[0]))
    s2 = _stacked_matches(right, x_ra, ra_correct, ra_total, 0.6, "match ratio", list(ratios).index(defaults[1]))
    left.set_xticks(x_th, [f"{v:g}" for v in thresholds])
    right.set_xticks(x_ra, [f"{v:g}" for v in ratios])
    left.set_title(f"match_threshold (ratio {defaults[1]:g})")
    right.set_title(f"match_ratio (threshold {defaults[0]:g})")
    top = max(s1.get_ylim()[1], s2.get_ylim()[1])
    s1.set_ylim(0, top)
    s2.set_ylim(0, top)
    bottom = max(left.get_ylim()[1], right.get_ylim()[1])
    left.set_ylim(0, bottom)
    right.set_ylim(0, bottom)
    _legend(left, s1)
    return fig


def _legend(ax, twin):
    handles, labels = ax.get_legend_handles_labels()
    h2, l2 = twin.get_legend_handles_labels()
    ax.legend(handles + h2, labels + l2, loc="upper left", fontsize=9, framealpha=0.9)


def skip_frames_figure(gaps, overlap, n_inliers, error_cm, failed, default: int = 3):
    """Overlap, MSAC inliers and final translation error against the gap between two scans."""
    gaps, failed = np.asarray(gaps), np.asarray(failed, bool)
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    axes[0].plot(gaps, 100 * np.asarray(overlap), "o-", color=COLORS["fixed"], lw=2)
    axes[0].set(ylabel="overlap (%)", title="shared ground", ylim=(0, 100))
    axes[1].plot(gaps, n_inliers, "o-", color=MATCH_COLORS["inlier"], lw=2)
    axes[1].set(ylabel="MSAC inliers", title="matches the robust fit keeps", ylim=(0, None))
    error = np.asarray(error_cm, float)
    axes[2].plot(gaps, error, "-", color=COLORS["odometry"], lw=1.5)
    axes[2].plot(gaps[~failed], error[~failed], "o", color=COLORS["odometry"], label="registered")
    axes[2].plot(gaps[failed], error[failed], "X", color="black", ms=10, label="fallback: ICP from a guess")
    axes[2].set(ylabel="translation error (cm)", title="error after ICP", yscale="log")
    axes[2].yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axes[2].yaxis.set_major_formatter(FormatStrFormatter("%g"))
    axes[2].yaxis.set_minor_formatter(NullFormatter())
    axes[2].legend(fontsize=9, loc="upper left")
    for ax in axes:
        ax.set_xlabel("skip_frames (scans between the two)")
        ax.set_xticks(gaps)
        _grid(ax)
        _mark_default(ax, default)
    return fig


def trials_figure(trials, probability, success, w: float, default: int = 3000):
    """The chance that MSAC draws at least one all-inlier sample (formula) and
    the measured share of seeds whose coarse fit lands close to the truth."""
    trials = np.asarray(trials)
    fig, ax = plt.subplots(figsize=(7.5, 3.8), constrained_layout=True)
    n = np.geomspace(trials.min(), trials.max() * 1.5, 200)
    ax.plot(n, 100 * (1 - (1 - w**3) ** n), color="black", lw=1.5, label=f"$1-(1-w^3)^N$, $w$ = {w:.2f}")
    ax.plot(trials, 100 * np.asarray(probability), "o", color="black")
    ax.plot(
        trials,
        100 * np.asarray(success),
        "s--",
        color=COLORS["optimized"],
        lw=1.5,
        label="measured: coarse fit within 3 m, over seeds",
    )
    ax.set(
        xscale="log",
        xlabel="max_num_trials (N)",
        ylabel="probability (%)",
        ylim=(0, 105),
        title="how many hypotheses are enough",
    )
    ax.set_xticks(trials, [str(t) for t in trials])
    ax.minorticks_off()
    _grid(ax)
    _mark_default(ax, default, top=False)
    ax.legend(fontsize=9, loc="upper left")
    return fig


# ----------------------------------------------------------------------------------------------------------------
# Notebook 3: one pair of scans, step by step, then the odometry
# ----------------------------------------------------------------------------------------------------------------


def _top_view(ax, points, color=None, scalars=None, size=1.5, **kwargs):
    """Sensor-frame points seen from above: y (to the left) across, x (forward) up."""
    if scalars is not None:
        return ax.scatter(points[:, 1], points[:, 0], c=scalars, s=size, linewidths=0, **kwargs)
    return ax.scatter(points[:, 1], points[:, 0], color=color, s=size, linewidths=0, **kwargs)


def clouds_figure(moving, fixed, names=("moving", "fixed")):
    """The two downsampled clouds from above, one above the other, coloured by height."""
    low, high = np.percentile(np.concatenate([moving[:, 2], fixed[:, 2]]), [1, 99])
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.2), sharex=True, constrained_layout=True)
    for ax, points, name, key in zip(axes, (moving, fixed), names, ("moving", "fixed"), strict=True):
        art = _top_view(ax, points, scalars=points[:, 2], size=3, cmap="gist_earth", vmin=low, vmax=high)
        ax.set_title(f"{name}: {len(points)} points", color=COLORS[key], fontweight="bold", loc="left")
        ax.set(ylabel="x, forward (m)", aspect="equal")
    axes[-1].set_xlabel("y, to the left of the drone (m)")
    axes[-1].invert_xaxis()
    fig.colorbar(art, ax=axes, label="z, sensor frame (m)", shrink=0.8)
    return fig


def descriptor_figure(descriptors: dict):
    """The 33 bins of a few FPFH descriptors, side by side, coloured by histogram.

    ``descriptors`` maps a label to a (33,) normalised descriptor; the first
    is drawn as bars, the others as outlined steps over it."""
    fig, ax = plt.subplots(figsize=(10, 3.6), constrained_layout=True)
    bins = np.arange(33)
    items = list(descriptors.items())
    label, first = items[0]
    colors = np.repeat(HISTOGRAM_COLORS, 11)
    ax.bar(bins, first, 0.85, color=colors, label=label)
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
    ax.legend(fontsize=9, loc="upper right")
    return fig


def matches_figure(moving, fixed, matches, inliers, shown: int = 80, gap: float = 25.0, seed: int = 0):
    """Both clouds from above, the moving one drawn above the fixed one, and a
    random subsample of match lines: inliers of the robust fit in purple,
    rejected matches in grey."""
    rng = np.random.default_rng(seed)
    lift = fixed[:, 0].max() - moving[:, 0].min() + gap  # moving drawn this much farther forward
    fig, ax = plt.subplots(figsize=(11, 5.4), constrained_layout=True)
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
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=9, frameon=False)
    return fig


def profile_figure(moving, fixed, stages: dict, y: float, half_width: float = 0.5):
    """Side views of the moving cloud (pink) over the fixed one (cyan), one per
    stage: the points within ``half_width`` of the line ``y`` (fixed scan's
    frame), forward distance across, height up. A wrong motion shows as
    doubled roofs and walls. ``stages`` maps a title to a 4 x 4 transform
    applied to ``moving``."""
    n = len(stages)
    fig, axes = plt.subplots(n, 1, figsize=(10, 2.2 * n + 0.4), sharex=True, sharey=True, constrained_layout=True)
    for ax, (title, transform) in zip(np.atleast_1d(axes), stages.items(), strict=True):
        moved = moving @ transform[:3, :3].T + transform[:3, 3]
        for points, key, marker in ((fixed, "fixed", "o"), (moved, "moving", "o")):
            band = points[np.abs(points[:, 1] - y) < half_width]
            ax.plot(band[:, 0], band[:, 2], marker, color=COLORS[key], ms=3.5, label=key, alpha=0.9)
        ax.set_title(title, loc="left")
        ax.set_ylabel("z (m)")
        _grid(ax)
    axes[0].legend(loc="upper right", fontsize=9, ncol=2, framealpha=0.95)
    axes[-1].set_xlabel("x, forward (m)")
    return fig


def surface_error_figure(moving, errors: dict, limit: float = 2.0):
    """The moving cloud from above, once per stage, each point coloured by its
    distance to the true surface once moved by that stage's transform.

    ``errors`` maps a title to the (N,) distances in metres."""
    n = len(errors)
    fig, axes = plt.subplots(n, 1, figsize=(10, 2.3 * n + 0.6), sharex=True, constrained_layout=True)
    axes = np.atleast_1d(axes)
    for ax, (title, distance) in zip(axes, errors.items(), strict=True):
        order = np.argsort(distance)  # the worst points on top
        art = _top_view(ax, moving[order], scalars=distance[order], size=3, cmap="magma_r", vmin=0, vmax=limit)
        ax.set_title(f"{title}: median {np.median(distance) * 100:.0f} cm", loc="left")
        ax.set(ylabel="x (m)", aspect="equal")
    axes[-1].set_xlabel("y, to the left of the drone (m)")
    axes[-1].invert_xaxis()
    fig.colorbar(art, ax=axes, label="distance to the true surface (m)", shrink=0.8, extend="max")
    return fig


def _inside(points, window):
    xmin, xmax, ymin, ymax = window
    return (points[:, 0] > xmin) & (points[:, 0] < xmax) & (points[:, 1] > ymin) & (points[:, 1] < ymax)


def trajectory_figure(ground_truth, estimated, label="odometry", extra=None):
    """Top view of a ground-truth and an estimated trajectory ((N, 4, 4) poses or (N, 2+) positions)."""
    gt, est = _xy(ground_truth), _xy(estimated)
    fig, ax = plt.subplots(figsize=(9, 5.4), constrained_layout=True)
    ax.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=2.5, label="ground truth")
    ax.plot(
        est[:, 0],
        est[:, 1],
        color=COLORS["odometry"] if label == "odometry" else COLORS["optimized"],
        lw=1.8,
        label=label,
    )
    ax.plot(*gt[0], "o", color="black", ms=7, label="start")
    ax.annotate("end", est[-1], xytext=(8, -4), textcoords="offset points", fontsize=9)
    ax.annotate("end", gt[-1], xytext=(8, 6), textcoords="offset points", fontsize=9)
    ax.plot(*est[-1], "s", color=COLORS["odometry"], ms=6)
    ax.plot(*gt[-1], "s", color=COLORS["ground_truth"], ms=6)
    for points, color, name in extra or ():
        ax.plot(points[:, 0], points[:, 1], color=color, lw=1.8, label=name)
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title="trajectory seen from above")
    _grid(ax)
    ax.legend(loc="center", fontsize=9)
    return fig


def _xy(trajectory):
    trajectory = np.asarray(trajectory)
    return trajectory[:, :2, 3] if trajectory.ndim == 3 else trajectory[:, :2]


def step_errors_figure(indices, translation_cm, rotation_deg, n_inliers, position_m, turning=None):
    """The odometry step by step: the error of every scan-to-scan motion
    (translation, rotation), the MSAC inliers behind it, and the position
    error they add up to. ``turning`` (one bool per step) shades the turns."""
    indices = np.asarray(indices)
    steps = indices[1:]
    fig, axes = plt.subplots(4, 1, figsize=(10, 8.6), sharex=True, constrained_layout=True)
    panels = (
        (steps, translation_cm, "translation error (cm)", "error of each scan-to-scan motion"),
        (steps, rotation_deg, "rotation error (deg)", None),
        (steps, n_inliers, "MSAC inliers", None),
    )
    for ax, (x, y, label, title) in zip(axes, panels, strict=False):
        ax.plot(x, y, ".-", color=COLORS["odometry"], lw=0.8, ms=4)
        ax.set(ylabel=label, title=title, ylim=(0, None))
    axes[2].lines[0].set_color(MATCH_COLORS["inlier"])
    axes[3].plot(indices, position_m, color=COLORS["odometry"], lw=2)
    axes[3].set(
        ylabel="position error (m)", xlabel="scan index", title="drift: distance to the true position", ylim=(0, None)
    )
    for ax in axes:
        _grid(ax)
        if turning is not None:
            _shade(ax, steps, np.asarray(turning, bool))
    if turning is not None:
        axes[0].fill_between([], [], color="#f3c623", alpha=0.25, label="turning")
        axes[0].legend(loc="upper right", fontsize=9)
    return fig


def _shade(ax, x, mask):
    """Shade the runs of ``x`` where ``mask`` is True."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(x[start] - 1.5, x[stop - 1] + 1.5, color="#f3c623", alpha=0.25, lw=0)
