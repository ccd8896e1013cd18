"""The parameter table and one picture per parameter of notebook 2: what each
value controls, drawn on one scan before any registration is run (the sweeps
that need FPFH, MSAC or ICP are in :mod:`.sweep_figures`)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Circle, Polygon

from helpers.config.tables import REFERENCE_WORKFLOW, STAGE_TABLES, Config, describe
from helpers.viz.style import COLORS, FIGURE_WIDTH, HEIGHT_CMAP, TEXT_PT, grid

MATCH_COLORS = {"inlier": "#6a3d9a", "outlier": "#b0b0b0"}  # purple: kept by the robust fit; grey: rejected
CORRECT_COLORS = {"correct": "#6a3d9a", "wrong": "#d0d0d0"}  # the same idea, judged by the ground truth
NEIGHBOUR_COLORS = ("#fdd49e", "#fc8d59", "#b30000")  # the largest neighbourhood lightest

# Values the reference fixes inside its code instead of exposing them as parameters.
REFERENCE_FIXED = {
    ("loop_closure", "max_attempts"): "helperEstimateLoopCandidates",
    ("loop_closure", "max_returned"): "helperEstimateLoopCandidates",
    ("loop_closure", "icp_max_iterations"): "helperEstimateLoopCandidates",
}

# The notebook that explains each stage's table.
NOTEBOOKS = {"features": 3, "registration": 3, "map": 4, "loop_closure": 5, "pose_graph": 6}


def parameter_origin(table: str, name: str, reference: str | None) -> str:
    """Where a default comes from, in words: the reference's value (a
    parameter of its, or a value fixed in its code), our change of it (with
    the reference's value), or ours alone."""
    changed = REFERENCE_WORKFLOW.get(table, {})
    if name in changed:
        return f"ours; the reference: {_value(changed[name])}"
    if reference:
        return f"reference (`{reference}`)"
    if (table, name) in REFERENCE_FIXED:
        return f"reference, fixed in `{REFERENCE_FIXED[table, name]}`"
    return "ours (not in the reference)"


def parameter_table(config: Config | None = None) -> str:
    """Every SLAM parameter as a Markdown table, stage by stage as the
    configuration nests them: name, value, where the default comes from
    (:func:`parameter_origin`) and meaning, all read from the configuration's
    own fields and :data:`helpers.config.tables.REFERENCE_WORKFLOW`."""
    config = config or Config()
    lines = ["| stage | parameter | default | where it comes from | meaning |", "|---|---|---|---|---|"]
    for table in STAGE_TABLES:
        if table not in NOTEBOOKS:
            continue
        for i, (name, value, meaning, reference) in enumerate(describe(getattr(config, table))):
            label = f"**[{table}]**, notebook {NOTEBOOKS[table]}" if i == 0 else ""
            origin = parameter_origin(table, name, reference)
            lines.append(f"| {label} | `{name}` | {_value(value)} | {origin} | {meaning} |")
    return "\n".join(lines)


def _value(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, str):
        return f'"{value}"'
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
        fontsize=TEXT_PT,
        color="#555555",
    )


def _top(ax, points, **kwargs):
    """Sensor-frame points from above: y (to the left) across, x (forward) up."""
    return ax.scatter(points[:, 1], points[:, 0], linewidths=0, **kwargs)


def grid_steps_figure(scan, clouds: dict, window=((-20.0, 20.0), (-60.0, 60.0))):
    """A part of one scan as the sensor gave it and after grid averaging with
    each step: ``clouds`` maps a step (m) to its (N, 3) downsampled cloud.
    ``window`` is ((x_min, x_max), (y_min, y_max)) in the sensor frame."""
    (x0, x1), (y0, y1) = window

    def inside(points):
        return points[(points[:, 0] > x0) & (points[:, 0] < x1) & (points[:, 1] > y0) & (points[:, 1] < y1)]

    panels = {"raw scan": scan, **{f"grid_step {step:g} m": cloud for step, cloud in clouds.items()}}
    low, high = np.percentile(inside(scan)[:, 2], [1, 99])
    fig, axes = plt.subplots(
        len(panels), 1, figsize=(FIGURE_WIDTH, 2.1 * len(panels) + 0.6), sharex=True, constrained_layout=True
    )
    for ax, (title, points) in zip(axes, panels.items(), strict=True):
        part = inside(points)
        art = _top(ax, part, c=part[:, 2], s=9, cmap=HEIGHT_CMAP, vmin=low, vmax=high)
        ax.set_title(f"{title}: {len(points)} points in the whole scan", loc="left")
        ax.set(ylabel="x, forward (m)", aspect="equal", xlim=(y1, y0), ylim=(x0, x1))
    axes[-1].set_xlabel("y, to the left of the drone (m)")
    fig.colorbar(art, ax=axes, label="z, sensor frame (m)", shrink=0.8)
    return fig


def neighbourhood_figure(points, centre: int, neighbourhoods: dict, cell: float, half_width: float = 18.0):
    """The ``k`` nearest neighbours of one point for a few ``k``: the patch of
    ground a normal and an FPFH descriptor are computed from.

    ``points`` is a downsampled cloud (sensor frame), ``centre`` the index of
    the point, ``neighbourhoods`` maps ``k`` to the indices of its ``k``
    nearest neighbours; the dashed circles have the radius
    ``cell * sqrt(k / pi)`` that ``k`` points one ``cell`` apart would cover."""
    p = points[centre]
    near = np.abs(points[:, :2] - p[:2]).max(axis=1) < half_width
    fig, ax = plt.subplots(figsize=(7, 6.4), constrained_layout=True)
    _top(ax, points[near], color="#c8c8c8", s=14)
    ks = sorted(neighbourhoods, reverse=True)
    for k, color in zip(ks, NEIGHBOUR_COLORS[-len(ks) :], strict=True):
        chosen = points[neighbourhoods[k]]
        _top(ax, chosen, color=color, s=22, label=f"k = {k}")
        ax.add_patch(Circle((p[1], p[0]), cell * np.sqrt(k / np.pi), fill=False, ls="--", color=color, lw=1.2))
    ax.plot(p[1], p[0], "*", color="black", ms=14, label="the described point")
    ax.set(
        xlim=(p[1] + half_width, p[1] - half_width),
        ylim=(p[0] - half_width, p[0] + half_width),
        aspect="equal",
        xlabel="y, to the left of the drone (m)",
        ylabel="x, forward (m)",
        title=f"what a descriptor sees: its k nearest points ({cell:g} m grid)",
    )
    ax.legend(loc="upper right", fontsize=TEXT_PT, framealpha=0.95)
    return fig


def descriptor_distance_figure(examples: dict, threshold: float, ratio: float):
    """For a few moving descriptors, the normalised distance to every fixed
    descriptor (a histogram), the nearest ``d1`` and second-nearest ``d2``
    marked, and what ``match_threshold`` and ``match_ratio`` decide.
    ``examples`` maps a title to the (M,) distances of one descriptor."""
    fig, axes = plt.subplots(
        1, len(examples), figsize=(min(FIGURE_WIDTH, 6 * len(examples)), 3.8), sharey=True, constrained_layout=True
    )
    for ax, (title, distance) in zip(np.atleast_1d(axes), examples.items(), strict=True):
        d1, d2 = np.sort(distance)[:2]
        ax.hist(distance, bins=np.linspace(0, max(0.6, distance.max()), 80), color="#bdbdbd", label="every fixed point")
        ax.axvline(threshold, color="black", ls=":", lw=1.4, label=f"match_threshold {threshold:g}")
        ax.axvline(d1, color=COLORS["moving"], lw=2, label=f"nearest $d_1$ = {d1:.3f}")
        ax.axvline(d2, color=COLORS["fixed"], lw=2, label=f"second $d_2$ = {d2:.3f}")
        kept = d1 <= threshold and d1 < ratio * d2
        verdict = "kept" if kept else "dropped"
        ax.set_title(f"{title}: $d_1/d_2$ = {d1 / d2:.3f}, {verdict}", loc="left")
        ax.set(xlabel="normalised descriptor distance", yscale="log")
        _grid(ax)
        ax.legend(fontsize=TEXT_PT, loc="upper right")
    np.atleast_1d(axes)[0].set_ylabel("fixed descriptors")
    return fig


def trials_formula_figure(max_trials: int = 3000, confidences=(0.9, 0.99, 0.999), pairs_cap: int | None = None):
    """Trials the robust fit needs against the share ``w`` of correct matches:
    ``N = log(1 - p) / log(1 - w^3)`` for a few confidences ``p``, with the
    ``max_num_trials`` cap; given ``pairs_cap``, also samples of 2 at the middle
    confidence (dashed) with their cap."""
    w = np.linspace(0.04, 0.8, 400)
    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    for p, color in zip(confidences, ("#9ecae1", "#3182bd", "#08519c"), strict=False):
        ax.plot(w, np.log(1 - p) / np.log1p(-(w**3)), color=color, lw=2, label=f"samples of 3, confidence p = {p:g}")
    caps = [(max_trials, f"max_num_trials = {max_trials}")]
    if pairs_cap is not None:
        p = confidences[len(confidences) // 2]
        ax.plot(w, np.log(1 - p) / np.log1p(-(w**2)), color="#e6550d", lw=2, ls="--", label=f"samples of 2, p = {p:g}")
        caps.append((pairs_cap, f"its cap for samples of 2 = {pairs_cap}"))
    for cap, label in caps:
        ax.axhline(cap, color="black", ls=":", lw=1.4)
        ax.annotate(label, (0.8, cap), xytext=(-4, 4), textcoords="offset points", ha="right", fontsize=TEXT_PT)
    ax.set(
        xscale="linear",
        yscale="log",
        xlabel="w, share of correct matches",
        ylabel="trials N",
        title=r"trials for one all-correct sample of $s$ matches: $N = \log(1-p)\,/\,\log(1-w^s)$",
        xlim=(0.04, 0.8),
    )
    _grid(ax)
    ax.legend(fontsize=TEXT_PT)
    return fig


def footprints_figure(outlines: dict, overlap: dict, default: int = 3):
    """Left: the footprints of a fixed scan and of scans some steps later, in
    the map frame (``outlines`` maps a gap to an (P, 2) polygon, gap 0 the
    fixed scan). Right: the share of ground they share (``overlap`` maps a
    gap to a share in [0, 1])."""
    fig, (left, right) = plt.subplots(
        1, 2, figsize=(FIGURE_WIDTH, 4.0), constrained_layout=True, gridspec_kw={"width_ratios": [1.4, 1]}
    )
    shades = plt.get_cmap("RdPu")(np.linspace(0.45, 0.95, max(1, len(outlines) - 1)))
    for (gap, polygon), color in zip(sorted(outlines.items()), [COLORS["fixed"], *shades], strict=True):
        fixed = gap == 0
        left.add_patch(
            Polygon(
                polygon,
                closed=True,
                fill=fixed,
                alpha=0.35 if fixed else 1.0,
                facecolor=COLORS["fixed"] if fixed else "none",
                edgecolor=color,
                lw=2,
                label="the fixed scan" if fixed else f"{gap} scans later",
            )
        )
    every = np.vstack(list(outlines.values()))
    left.set(
        xlim=(every[:, 0].min() - 10, every[:, 0].max() + 10),
        ylim=(every[:, 1].min() - 10, every[:, 1].max() + 10),
        aspect="equal",
        xlabel="x, map (m)",
        ylabel="y, map (m)",
        title="footprints on the ground",
    )
    left.legend(fontsize=TEXT_PT, loc="best")
    _grid(left)
    gaps = sorted(overlap)
    right.plot(gaps, [100 * overlap[g] for g in gaps], "o-", color=COLORS["fixed"], lw=2)
    right.set(
        xlabel="skip_frames (scans between the two)",
        ylabel="shared ground (%)",
        ylim=(0, 100),
        xticks=gaps,  # whole scans: a tick at every gap measured, none in between
        title="overlap with the fixed scan",
    )
    _grid(right)
    _mark_default(right, default)
    return fig
