"""Figures for notebook 4: the odometry over the whole flight and its errors, then the
submaps, their centres and the cost of a query."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Circle

from helpers.viz.parameter_figures import MATCH_COLORS
from helpers.viz.render import pyvista
from helpers.viz.style import (
    BOOK_COLUMN_PX,
    COLORS,
    FIGURE_WIDTH,
    GREY,
    HEIGHT_CMAP,
    LIGHT,
    TEXT_PT,
    grid,
    inset_zoom,
    scale_bar,
    view_text_px,
    xy_of,
)


def submap_panels(
    scans: list[np.ndarray], submap: np.ndarray, titles: list[str], pose: np.ndarray, window=(1300, 1150)
) -> np.ndarray:
    """The scans of one submap, each on its own, and the submap they merge
    into, one above the other in PyVista, all in the map frame and on one
    height colour scale. The camera looks down at 68 degrees from behind the
    drone (``pose``, the submap's pose, gives the heading), so the strip runs
    across the picture. Returns an RGB array."""
    pv = pyvista()

    clouds = [*scans, submap]
    every = np.concatenate(clouds)
    low, high = np.percentile(every[:, 2], [1, 99.5])
    clim = (low, high + 0.3 * (high - low))  # keep the highest roofs off the colour map's white end
    focal = (every.min(axis=0) + every.max(axis=0)) / 2
    width = np.ptp(every @ pose[:3, 1])  # extent across the track
    heading = pose[:3, 0] * np.array([1.0, 1.0, 0.0])
    heading /= np.linalg.norm(heading)
    elevation = np.radians(68.0)
    direction = -np.cos(elevation) * heading + np.array([0.0, 0.0, np.sin(elevation)])
    text_px = view_text_px(window[0], min(window[0], BOOK_COLUMN_PX))  # 11 px where the book shows it
    plotter = pv.Plotter(off_screen=True, window_size=list(window), shape=(len(clouds), 1), border=False)
    plotter.set_background("white")
    for k, (points, title) in enumerate(zip(clouds, titles, strict=True)):
        plotter.subplot(k, 0)
        cloud = pv.PolyData(np.asarray(points, np.float32))
        cloud["height (m)"] = points[:, 2]
        plotter.add_mesh(
            cloud,
            scalars="height (m)",
            cmap=HEIGHT_CMAP,
            clim=clim,
            point_size=2.0,
            show_scalar_bar=k == len(clouds) - 1,
            scalar_bar_args={
                "title": "height (m)",
                "color": "black",
                "vertical": True,
                "position_x": 0.91,
                "position_y": 0.1,
                "height": 0.8,
                "width": 0.05,
                "fmt": "%.0f",
                "title_font_size": text_px,
                "label_font_size": text_px,
            },
        )
        # PyVista doubles a title's size: text_px, a little larger
        plotter.add_text(f"{title}: {len(points)} points", font_size=max(11, round(0.6 * text_px)), color="black")
        plotter.camera_position = [tuple(focal + 0.56 * width * direction), tuple(focal), (0.0, 0.0, 1.0)]
    image = plotter.screenshot(return_img=True)
    plotter.close()
    return image


def submap_centres_figure(ground_truth, odometry, centres, true_centres, map_points=None, zoom_m: float = 30.0):
    """Top view: the odometry trajectory (red) and the ground truth (green),
    one dot per submap centre, over the map in grey when given; an inset
    zooms on ``zoom_m`` metres around the last centre, with where that
    submap truly is (``true_centres``): the drift is metres on a loop of
    hundreds, too small to see at the scale of the whole flight."""
    gt, odo, c, true = xy_of(ground_truth), xy_of(odometry), xy_of(centres), xy_of(true_centres)
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 5.6), constrained_layout=True)

    def draw(axis, dot=22):
        if map_points is not None:
            axis.scatter(*map_points[:, :2].T, s=0.8, color="#a9a9a9", linewidths=0, rasterized=True)
        axis.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=2.5, label="ground truth")
        axis.plot(
            odo[:, 0], odo[:, 1], color=COLORS["odometry"], lw=1.5, label="odometry (the submaps are built on it)"
        )
        axis.scatter(c[:, 0], c[:, 1], s=dot, color="black", zorder=3, label=f"submap centres ({len(c)})")
        axis.scatter(
            *true.T,
            s=dot,
            color="white",
            edgecolor=COLORS["ground_truth"],
            lw=1.5,
            zorder=3,
            label="where each submap's middle scan truly was",
        )

    draw(ax)
    low, high = gt.min(axis=0) - 40, gt.max(axis=0) + 40
    ax.set(xlim=(low[0], high[0]), ylim=(low[1], high[1]))
    ax.annotate(
        "submap 0",
        c[0],
        xytext=(-12, 12),
        textcoords="offset points",
        fontsize=TEXT_PT,
        ha="right",
        bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "none", "alpha": 0.85},
    )
    ax.annotate(
        f"submap {len(c) - 1}",
        c[-1],
        xytext=(12, -14),
        textcoords="offset points",
        fontsize=TEXT_PT,
        bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "none", "alpha": 0.85},
    )
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title="submap centres along the flight, seen from above")
    grid(ax)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=TEXT_PT)
    x, y = c[-1]
    window = (x - zoom_m / 2, x + zoom_m / 2, y - zoom_m / 2, y + zoom_m / 2)
    inset_zoom(
        ax, lambda axis: (draw(axis, 60), scale_bar(axis, zoom_m, "lower right")), window, (0.3, 0.28, 0.4, 0.44)
    )
    return fig


def heading_change_deg(poses, submaps) -> np.ndarray:
    """How far the drone turned across each submap (degrees): the change of
    heading of ``poses`` from the submap's first scan to its last."""
    poses = np.asarray(poses)
    yaw = np.degrees(np.arctan2(poses[:, 1, 0], poses[:, 0, 0]))
    return np.array([abs((yaw[s.scan_ids[-1]] - yaw[s.scan_ids[0]] + 180) % 360 - 180) for s in submaps])


def recent_rule_figure(centres, position, n_excluded: int, radius: float, title: str, base_radius: float | None = None):
    """Top view of the submap centres at one moment of the flight: the
    ``n_excluded`` newest (never candidates) in light grey, the older ones
    (eligible) in black, the current position and the search ``radius`` the
    query used (orange); ``base_radius``, when given, is drawn dashed (the
    reference's fixed radius)."""
    c = xy_of(centres)
    eligible = c[: max(0, len(c) - n_excluded)]
    excluded = c[len(eligible) :]
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 5.4), constrained_layout=True)
    ax.plot(c[:, 0], c[:, 1], color=LIGHT, lw=1, zorder=1)
    ax.scatter(*eligible.T, s=22, color="black", zorder=3, label=f"eligible ({len(eligible)} oldest)")
    ax.scatter(*excluded.T, s=30, color="white", edgecolor=GREY, zorder=3, label=f"too recent ({len(excluded)} newest)")
    ax.plot(*position[:2], "*", color=COLORS["odometry"], ms=16, zorder=4, label="the drone now")
    label = f"search radius of the query, {radius:.0f} m"
    ax.add_patch(Circle(position[:2], radius, fill=False, color=COLORS["loop"], lw=2, zorder=4, label=label))
    if base_radius is not None:
        ax.add_patch(
            Circle(
                position[:2],
                base_radius,
                fill=False,
                color="black",
                ls="--",
                lw=1.2,
                zorder=4,
                label=f"the reference's fixed radius, {base_radius:g} m",
            )
        )
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title=title)
    grid(ax)
    ax.legend(loc="center", fontsize=TEXT_PT)
    return fig


def submap_merge_figure(scans_worth, turn_deg, n_scans_per_submap: int, turn_limit: float = 5.0):
    """What the merge keeps, submap by submap: the submap's points counted
    in scans' worth (its points over the median points of a scan), against
    the submap id, marked where the drone turned by more than ``turn_limit``
    degrees across the submap's scans (``turn_deg``). The lines at 1 and at
    ``n_scans_per_submap`` are a single scan and the scans merely stacked."""
    worth, turn = np.asarray(scans_worth, float), np.asarray(turn_deg, float)
    ids = np.arange(len(worth))
    turning = turn > turn_limit
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 3.8), constrained_layout=True)
    ax.axhline(n_scans_per_submap, color="black", ls="--", lw=1.2, label=f"{n_scans_per_submap} scans stacked")
    ax.axhline(1.0, color=GREY, ls=":", lw=1.2, label="one scan")
    ax.plot(ids, worth, color=LIGHT, lw=1, zorder=1)
    ax.scatter(ids[~turning], worth[~turning], s=20, color="black", zorder=3, label="straight flight")
    ax.scatter(
        ids[turning],
        worth[turning],
        s=30,
        color=COLORS["loop"],
        edgecolor="black",
        lw=0.5,
        zorder=3,
        label=f"turning (over {turn_limit:g} deg across the submap)",
    )
    ax.set(
        xlabel="submap",
        ylabel="points, in scans' worth",
        ylim=(0, n_scans_per_submap + 0.4),
        title="what the grid merge keeps of overlapping scans",
    )
    grid(ax)
    ax.legend(fontsize=TEXT_PT, loc="center right", bbox_to_anchor=(1.0, 0.62))
    return fig


def trajectory_figure(
    ground_truth, estimated, label="odometry", extra=None, zoom_m=None, inset_at=(0.3, 0.3, 0.36, 0.42)
):
    """Top view of a ground-truth and an estimated trajectory ((N, 4, 4) poses or (N, 2+) positions).

    With ``zoom_m``, an inset shows a square of that many metres around the
    two ends, with a scale bar: metres of drift on a loop of hundreds of
    metres are invisible at the scale of the whole flight."""
    gt, est = xy_of(ground_truth), xy_of(estimated)
    color = COLORS["odometry"] if label == "odometry" else COLORS["optimized"]
    fig, ax = plt.subplots(figsize=(FIGURE_WIDTH, 5.4), constrained_layout=True)

    def draw(axis, marker_size=6):
        axis.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=2.5, label="ground truth")
        axis.plot(est[:, 0], est[:, 1], color=color, lw=1.8, label=label)
        for points, extra_color, name in extra or ():
            axis.plot(points[:, 0], points[:, 1], color=extra_color, lw=1.8, label=name)
        axis.plot(*est[-1], "s", color=color, ms=marker_size, label=f"end, {label}")
        axis.plot(*gt[-1], "s", color=COLORS["ground_truth"], ms=marker_size, label="end, ground truth")

    draw(ax)
    ax.plot(*gt[0], "o", color="black", ms=7, label="start")
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title="trajectory seen from above")
    grid(ax, color="#e5e5e5", open_frame=True)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=TEXT_PT)
    if zoom_m:
        centre = (gt[-1] + est[-1]) / 2
        window = (centre[0] - zoom_m / 2, centre[0] + zoom_m / 2, centre[1] - zoom_m / 2, centre[1] + zoom_m / 2)
        inset_zoom(ax, lambda axis: (draw(axis, 8), scale_bar(axis, zoom_m, "lower right")), window, inset_at)
    return fig


def step_errors_figure(indices, translation_cm, rotation_deg, n_inliers, position_m, turning=None):
    """The odometry step by step: the error of every scan-to-scan motion
    (translation, rotation), the MSAC inliers behind it, and the position
    error they add up to. ``turning`` (one bool per step) shades the turns."""
    indices = np.asarray(indices)
    steps = indices[1:]
    fig, axes = plt.subplots(4, 1, figsize=(FIGURE_WIDTH, 8.6), sharex=True, constrained_layout=True)
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
        grid(ax, color="#e5e5e5", open_frame=True)
        if turning is not None:
            _shade(ax, steps, np.asarray(turning, bool))
    if turning is not None:
        axes[0].fill_between([], [], color="#f3c623", alpha=0.25, label="turning")
        axes[0].legend(loc="upper right", fontsize=TEXT_PT)
    return fig


def _shade(ax, x, mask):
    """Shade the runs of ``x`` where ``mask`` is True."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(x[start] - 1.5, x[stop - 1] + 1.5, color="#f3c623", alpha=0.25, lw=0)
