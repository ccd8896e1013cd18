"""Figures for notebook 5: loop-candidate queries, search radii, loop-edge errors."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Circle

from helpers.geometry import transform_points
from helpers.quality.metrics import FALSE_LOOP_DEG, FALSE_LOOP_M
from helpers.viz.style import COLORS, FIGURE_WIDTH, GREY, LIGHT, TEXT_PT, grid, xy_of


def candidates_figure(
    centres,
    n_eligible: int,
    position,
    true_position,
    base_radius: float,
    radius: np.ndarray,
    tried=(),
    matched=(),
    true_centres=None,
    margin: float = 60.0,
):
    """Top view around one query: every submap centre (eligible black,
    too recent light grey), the scan's odometry position (red star) and its
    true position (green star), the reference's fixed search circle (dashed)
    and each eligible submap's search radius drawn as a faint ring. Tried
    submaps are ringed in orange, matched ones filled orange."""
    c = xy_of(centres)
    p = np.asarray(position)[:2]
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 6.2), constrained_layout=True)
    ax.plot(c[:, 0], c[:, 1], color=LIGHT, lw=1, zorder=1)
    ax.scatter(*c[n_eligible:].T, s=26, color="white", edgecolor=GREY, zorder=2, label="too recent")
    ax.scatter(*c[:n_eligible].T, s=18, color="black", zorder=3, label="eligible submap centre")
    biggest = float(np.max(radius[:n_eligible])) if n_eligible else base_radius
    ax.add_patch(
        Circle(
            p,
            base_radius,
            fill=False,
            color="black",
            ls="--",
            lw=1.5,
            zorder=4,
            label=f"reference radius {base_radius:.1f} m",
        )
    )
    nearest = int(np.argmin(np.linalg.norm(c[:n_eligible] - p, axis=1))) if n_eligible else None
    if nearest is not None:
        ax.add_patch(
            Circle(
                p,
                radius[nearest],
                fill=False,
                color=COLORS["loop"],
                lw=2,
                zorder=4,
                label=f"search radius {radius[nearest]:.1f} m (nearest old submap)",
            )
        )
    tried, matched = np.asarray(tried, int), np.asarray(matched, int)
    if len(tried):
        ax.scatter(
            *c[tried].T, s=140, facecolor="none", edgecolor=COLORS["loop"], lw=2, zorder=5, label="registered by ICP"
        )
    if len(matched):
        ax.scatter(*c[matched].T, s=60, color=COLORS["loop"], zorder=6, label="matched (RMSE below threshold)")
    if true_centres is not None:
        t = xy_of(true_centres)
        ax.scatter(
            *t[:n_eligible].T, s=8, color=COLORS["ground_truth"], zorder=2, alpha=0.6, label="true submap centres"
        )
    ax.plot(*p, "*", color=COLORS["odometry"], ms=17, zorder=7, label="the scan, odometry position")
    ax.plot(
        *np.asarray(true_position)[:2],
        "*",
        color=COLORS["ground_truth"],
        ms=13,
        zorder=7,
        label="the scan, true position",
    )
    half = max(margin, 1.3 * biggest if biggest < margin else margin)
    ax.set(
        xlim=(p[0] - 1.6 * half, p[0] + 1.6 * half),
        ylim=(p[1] - half, p[1] + half),
        aspect="equal",
        xlabel="x (m)",
        ylabel="y (m)",
    )
    grid(ax)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=TEXT_PT)
    return fig


def query_figure(seen: dict, base_radius: float):
    """:func:`candidates_figure` of one query, from what
    :func:`helpers.viz.loop_search.query_search` returned for it."""
    where = (seen[key] for key in ("centres", "n_eligible", "position", "true_position"))
    return candidates_figure(
        *where, base_radius, seen["radius"], seen["tried"], seen["matched"], true_centres=seen["true_centres"]
    )


def search_radius_figure(true, apparent, found, base_radius: float, radius=None):
    """For every node that revisits an old submap: how far that submap's
    centre truly is (x) against how far it looks on the odometry (y). Points
    on the diagonal saw no drift; points above the fixed radius (dashed) are
    out of the reference's reach. ``radius``, when given: the radius each
    query searched around that place (nan where it left no record), as
    diamonds above the point. Only what is drawn gets a legend entry."""
    true, apparent, found = np.asarray(true, float), np.asarray(apparent, float), np.asarray(found, bool)
    searched = radius is not None and np.isfinite(radius).any()
    top = max(apparent.max(), base_radius, np.nanmax(radius) if searched else 0) * 1.1
    fig, ax = plt.subplots(figsize=(8, 4.6), constrained_layout=True)
    ax.plot([0, top], [0, top], color=GREY, lw=1, label="no drift (odometry = truth)")
    ax.axhline(base_radius, ls="--", color="black", lw=1.5, label=f"the reference's fixed radius {base_radius:.1f} m")
    jitter = 0.25 * (np.arange(len(true)) % 5 - 2)  # nodes at the same true distance, side by side
    if found.any():
        ax.scatter(
            true[found] + jitter[found],
            apparent[found],
            s=30,
            color=COLORS["loop"],
            edgecolor="black",
            lw=0.5,
            zorder=3,
            label="nodes that closed a loop",
        )
    if (~found).any():
        ax.scatter(
            true[~found] + jitter[~found],
            apparent[~found],
            s=24,
            color="white",
            edgecolor=GREY,
            zorder=2,
            label="nodes that did not",
        )
    if searched:
        kept = np.isfinite(radius)
        ax.scatter(
            true[kept] + jitter[kept],
            radius[kept],
            s=30,
            marker="D",
            color="none",
            edgecolor=COLORS["loop"],
            label="radius the query searched (uncertainty gate)",
        )
    ax.set(
        xlabel="true distance to the nearest old submap centre (m)",
        ylabel="distance on the odometry (m)",
        xlim=(0, top),
        ylim=(0, top),
        aspect="equal",
    )
    grid(ax)
    ax.legend(fontsize=TEXT_PT, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    return fig


def pair_overlay_figure(moving, fixed, stages: dict, half_width: float = 60.0, slab: float = 1.5):
    """The moving scan (pink) over the fixed scan (cyan), in the fixed
    scan's frame, once per stage: a top view (top row, cropped to
    ``|y| < half_width``) and a side view of a thin slab across the track
    (bottom row, points with ``|x| < slab``). ``stages`` maps a title to the
    4 x 4 transform applied to ``moving``."""
    n = len(stages)
    fig, axes = plt.subplots(
        2,
        n,
        figsize=(min(FIGURE_WIDTH, 5.2 * n), 6.4),
        squeeze=False,
        constrained_layout=True,
        gridspec_kw={"height_ratios": [1.5, 1]},
    )
    keep_f = np.abs(fixed[:, 1]) < half_width
    for col, (title, transform) in enumerate(stages.items()):
        moved = transform_points(moving, transform)
        keep_m = np.abs(moved[:, 1]) < half_width
        top, side = axes[0, col], axes[1, col]
        for points, key in ((fixed[keep_f], "fixed"), (moved[keep_m], "moving")):
            top.scatter(points[:, 1], points[:, 0], s=2, color=COLORS[key], linewidths=0, alpha=0.8)
        top.axhspan(-slab, slab, color="black", alpha=0.08)
        top.set(title=title, aspect="equal", xlim=(half_width, -half_width), xlabel="y (m)")
        for points, key in ((fixed, "fixed"), (moved, "moving")):
            cut = points[(np.abs(points[:, 0]) < slab) & (np.abs(points[:, 1]) < half_width)]
            side.plot(cut[:, 1], cut[:, 2], ".", ms=3, color=COLORS[key])
        side.set(xlim=(half_width, -half_width), xlabel="y (m)")
        grid(side)
    axes[0, 0].set_ylabel("x, forward (m)")
    axes[1, 0].set_ylabel("z (m), slab across the track")
    for key, name in (("fixed", "fixed: the old scan"), ("moving", "moving: the current scan")):
        axes[1, -1].plot([], [], ".", ms=8, color=COLORS[key], label=name)
    axes[1, -1].legend(loc="best", fontsize=TEXT_PT, framealpha=0.95)  # the side view has free corners
    return fig


def rmse_offsets_figure(offsets, point_to_point, surface):
    """Both registration scores of one truly aligned pair shifted along the
    track by each offset: the point-to-point RMSE and the RMSE along the
    fixed cloud's normals."""
    fig, ax = plt.subplots(figsize=(8, 3.8), constrained_layout=True)
    ax.plot(offsets, point_to_point, "o-", color=GREY, lw=2, label="point-to-point RMSE (the reference's)")
    ax.plot(offsets, surface, "o-", color=COLORS["loop"], lw=2, label="RMSE along the normals (ours)")
    ax.set(xlabel="shift along the track from the true alignment (m)", ylabel="score (m)", ylim=(0, None))
    grid(ax)
    ax.legend(fontsize=TEXT_PT)
    return fig


def overlap_rounds_figure(moving, fixed, whole, kept, errors_m):
    """A loop's best match on the old scan's footprint: (top) the old scan (cyan) and its outline from above
    (black), in its frame, with the current scan where the whole scan's registration ``whole`` (4 x 4) puts
    it, its points over the outline (``kept``, the first round's crop; pink) and beyond it (grey); (bottom)
    how far each answer lies from the truth, round 0 being the whole scan's."""
    from scipy.spatial import ConvexHull

    fig = plt.figure(figsize=(FIGURE_WIDTH, 5.8), constrained_layout=True)
    grid_spec = fig.add_gridspec(2, 2, height_ratios=[1.3, 1], width_ratios=[1.2, 1])
    top, rounds, key = (
        fig.add_subplot(grid_spec[0, :]),
        fig.add_subplot(grid_spec[1, 0]),
        fig.add_subplot(grid_spec[1, 1]),
    )
    moved, kept = transform_points(moving, whole), np.asarray(kept, dtype=bool)
    top.scatter(fixed[:, 1], fixed[:, 0], s=1, color=COLORS["fixed"], linewidths=0, alpha=0.35)
    hull = fixed[ConvexHull(fixed[:, :2]).vertices]
    top.fill(hull[:, 1], hull[:, 0], fill=False, edgecolor="black", lw=1.5)
    key.plot([], [], "-", color="black", lw=1.5, label="the old scan's outline from above")
    key.plot([], [], ".", ms=8, color=COLORS["fixed"], label="the old scan")
    for points, color, label in (
        (moved[kept], COLORS["moving"], "the current scan over the outline: registered again"),
        (moved[~kept], GREY, "the current scan beyond it: left out"),
    ):
        top.scatter(points[:, 1], points[:, 0], s=2, color=color, linewidths=0, alpha=0.8)
        key.plot([], [], ".", ms=8, color=color, label=label)
    top.invert_xaxis()
    top.set(aspect="equal", xlabel="y (m)", ylabel="x, forward (m)", title="where the whole scan's answer puts it")
    key.axis("off")
    key.legend(loc="center", fontsize=TEXT_PT, frameon=False)
    rounds.plot(np.arange(len(errors_m)), errors_m, "o-", color=COLORS["loop"], lw=2)
    rounds.set(xlabel="round (0: the whole scan)", ylabel="from the truth (m)", ylim=(0, None))
    rounds.set_xticks(np.arange(len(errors_m)))
    grid(rounds)
    return fig


def queries_figure(nodes, tried, best, accepted, thresholds: dict):
    """Every loop query: each submap registered (small grey dots), the best
    scan-to-scan match of queries that found a submap (orange if it became
    a loop edge, black cross if not), and the thresholds."""
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 4.2), constrained_layout=True)
    xs = np.concatenate([np.full(len(t), n) for n, t in zip(nodes, tried, strict=True)])
    ys = np.concatenate(tried)
    ax.scatter(xs, ys, s=10, color=GREY, label="a submap registered (its RMSE)", zorder=2)
    nodes, best, accepted = np.asarray(nodes), np.asarray(best), np.asarray(accepted, bool)
    has = np.isfinite(best)
    ax.scatter(
        nodes[has & accepted],
        best[has & accepted],
        s=40,
        color=COLORS["loop"],
        edgecolor="black",
        lw=0.5,
        zorder=4,
        label="best scan match: loop edge",
    )
    ax.scatter(
        nodes[has & ~accepted],
        best[has & ~accepted],
        s=40,
        marker="x",
        color="black",
        zorder=4,
        label="best scan match: rejected",
    )
    merged = {}
    for name, value in thresholds.items():  # thresholds of equal value share one line
        merged.setdefault(value, []).append(name)
    for (value, names), ls in zip(merged.items(), ("--", ":"), strict=False):
        ax.axhline(value, color="black", ls=ls, lw=1.2, label=f"{' = '.join(names)} = {value:g} m")
    top = min(max(float(np.nanmax(ys)), *thresholds.values()) * 1.15, 3.0)
    ax.set(xlabel="node (accepted scan) of the query", ylabel="RMSE along the normals (m)", ylim=(0, top))
    grid(ax)
    ax.legend(fontsize=TEXT_PT, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


def loop_errors_figure(error_m, error_deg, limits=(FALSE_LOOP_M, FALSE_LOOP_DEG)):
    """Each accepted loop edge's error against the ground truth: translation
    (m) against rotation (deg), both on log scales so that errors a hundred
    times below the limits still spread out; the limits of a false loop are
    the dashed lines, and the shaded box is where a loop counts as right."""
    error_m, error_deg = np.asarray(error_m, float), np.asarray(error_deg, float)
    floor = 1e-4  # an error of exactly 0 has no place on a log axis: draw it at the floor
    x, y = np.maximum(error_m, floor), np.maximum(error_deg, floor)
    low_x = 10 ** np.floor(np.log10(min(x.min(initial=limits[0]), limits[0]) / 2))
    low_y = 10 ** np.floor(np.log10(min(y.min(initial=limits[1]), limits[1]) / 2))
    high_x, high_y = 4 * max(limits[0], x.max(initial=0)), 4 * max(limits[1], y.max(initial=0))
    fig, ax = plt.subplots(figsize=(7, 4.4), constrained_layout=True)
    ax.add_patch(
        plt.Rectangle(
            (low_x, low_y),
            limits[0] - low_x,
            limits[1] - low_y,
            color=COLORS["ground_truth"],
            alpha=0.12,
            label="counted as right",
        )
    )
    ax.axvline(limits[0], color="black", ls="--", lw=1.2, label=f"false beyond {limits[0]:g} m ...")
    ax.axhline(limits[1], color="black", ls=":", lw=1.2, label=f"... or {limits[1]:g} deg")
    ax.scatter(x, y, s=36, color=COLORS["loop"], edgecolor="black", lw=0.5, zorder=3, label=f"loop edges ({len(x)})")
    ax.set(
        xscale="log",
        yscale="log",
        xlabel="translation error (m, log scale)",
        ylabel="rotation error (deg, log scale)",
        xlim=(low_x, high_x),
        ylim=(low_y, high_y),
    )
    grid(ax)
    ax.legend(fontsize=TEXT_PT, loc="lower right")
    return fig
