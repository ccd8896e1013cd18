"""Figures for notebook 3's parameter sweeps, each shown right after the step it tunes:
FPFH's neighbours, the match threshold and ratio, MSAC's trials, the gap between scans."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

from helpers.viz.parameter_figures import CORRECT_COLORS, MATCH_COLORS, _grid, _mark_default
from helpers.viz.style import COLORS, FIGURE_WIDTH, TEXT_PT


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
    fig, (left, right) = plt.subplots(1, 2, figsize=(FIGURE_WIDTH, 3.4), constrained_layout=True)
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
    ax.legend(handles + h2, labels + l2, loc="upper left", fontsize=TEXT_PT, framealpha=0.9)


def skip_frames_figure(gaps, overlap, n_inliers, error_cm, failed, default: int = 3):
    """Overlap, MSAC inliers and final translation error against the gap between two scans."""
    gaps, failed = np.asarray(gaps), np.asarray(failed, bool)
    fig, axes = plt.subplots(1, 3, figsize=(FIGURE_WIDTH, 3.2), constrained_layout=True)
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
    # Above the panel, not in it: inside, it covered the "default" mark or the points, whichever the gaps gave.
    fig.legend(*axes[2].get_legend_handles_labels(), loc="outside upper right", ncols=2, fontsize=TEXT_PT)
    fig.supxlabel("skip_frames (scans between the two)", fontsize=TEXT_PT)  # once: three would not fit under
    for ax in axes:
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
    ax.legend(fontsize=TEXT_PT, loc="upper left")
    return fig
