"""The parameter table and one figure per parameter experiment of notebook 2."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

from ..config import STAGE_TABLES, Config, describe
from .style import COLORS, grid

MATCH_COLORS = {"inlier": "#6a3d9a", "outlier": "#b0b0b0"}  # purple: kept by the robust fit; grey: rejected
CORRECT_COLORS = {"correct": "#6a3d9a", "wrong": "#d0d0d0"}  # the same idea, judged by the ground truth

# The notebook that explains each stage's table.
NOTEBOOKS = {"features": 2, "registration": 3, "map": 4, "loop_closure": 5, "pose_graph": 6}


def parameter_table(config: Config | None = None) -> str:
    """Every SLAM parameter as a Markdown table, stage by stage as the
    configuration nests them: name, value, the reference's name and meaning,
    all read from the configuration's own fields."""
    config = config or Config()
    lines = ["| stage | parameter | value | reference | meaning |", "|---|---|---|---|---|"]
    for table in STAGE_TABLES:
        if table not in NOTEBOOKS:
            continue
        for i, (name, value, meaning, reference) in enumerate(describe(getattr(config, table))):
            label = f"**[{table}]**, notebook {NOTEBOOKS[table]}" if i == 0 else ""
            ref = f"`{reference}`" if reference else "(ours)"
            lines.append(f"| {label} | `{name}` | {_value(value)} | {ref} | {meaning} |")
    return "\n".join(lines)


def _value(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _grid(ax):
    grid(ax, color="#e5e5e5", open_frame=True)


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
