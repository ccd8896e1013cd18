"""Figures for notebooks 4 (submaps), 5 (loop closure) and 6 (pose graph).

Each function takes arrays (positions, clouds, errors) and returns a
matplotlib figure, or an RGB array for the PyVista views; a notebook shows
it with :func:`helpers.render.show_figure` or :func:`helpers.render.show`.
The colours are those of :data:`helpers.render.COLORS`: ground truth green,
odometry red, optimised blue, loop edges orange, the moving scan pink and
the fixed one cyan.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.patches import Circle

from .render import COLORS, HEIGHT_CMAP, WINDOW
from .submaps import centre_scan_id

GREY = "#9a9a9a"
LIGHT = "#d9d9d9"


def _grid(ax):
    ax.grid(True, color="#e6e6e6", lw=0.8)
    ax.set_axisbelow(True)


def _xy(trajectory) -> np.ndarray:
    """(N, 2) positions from (N, 4, 4) poses or (N, 2+) positions."""
    trajectory = np.asarray(trajectory, dtype=float)
    return trajectory[:, :2, 3] if trajectory.ndim == 3 else trajectory[:, :2]


def _segments(a, b) -> np.ndarray:
    """(L, 2, 2) top-view segments from two (L, 2+) arrays of end points."""
    return np.stack([np.asarray(a)[:, :2], np.asarray(b)[:, :2]], axis=1)


# ----------------------------------------------------------------------------------------------------------------
# Notebook 4: submaps
# ----------------------------------------------------------------------------------------------------------------


def submap_panels(
    scans: list[np.ndarray], submap: np.ndarray, titles: list[str], pose: np.ndarray, window=(1300, 1150)
) -> np.ndarray:
    """The scans of one submap, each on its own, and the submap they merge
    into, one above the other in PyVista, all in the map frame and on one
    height colour scale. The camera looks down at 68 degrees from behind the
    drone (``pose``, the submap's pose, gives the heading), so the strip runs
    across the picture. Returns an RGB array."""
    import pyvista as pv

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
            },
        )
        plotter.add_text(f"{title}: {len(points)} points", font_size=11, color="black")
        plotter.camera_position = [tuple(focal + 0.56 * width * direction), tuple(focal), (0.0, 0.0, 1.0)]
    image = plotter.screenshot(return_img=True)
    plotter.close()
    return image


def submap_centres_figure(ground_truth, odometry, centres, scan_points=None, label_every: int = 10):
    """Top view: the odometry trajectory (red) and the ground truth (green),
    one dot per submap centre (its id every ``label_every``), over the
    submap points in light grey when given."""
    gt, odo, c = _xy(ground_truth), _xy(odometry), _xy(centres)
    fig, ax = plt.subplots(figsize=(10, 5.6), constrained_layout=True)
    if scan_points is not None:
        low, high = gt.min(axis=0) - 40, gt.max(axis=0) + 40
        near = np.all((scan_points[:, :2] > low) & (scan_points[:, :2] < high), axis=1)
        ax.scatter(*scan_points[near, :2].T, s=0.6, color="#c8c8c8", linewidths=0, rasterized=True)
        ax.set(xlim=(low[0], high[0]), ylim=(low[1], high[1]))
    ax.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=2.5, label="ground truth")
    ax.plot(odo[:, 0], odo[:, 1], color=COLORS["odometry"], lw=1.5, label="odometry (the submaps are built on it)")
    ax.scatter(c[:, 0], c[:, 1], s=22, color="black", zorder=3, label=f"submap centres ({len(c)})")
    for k in range(0, len(c), label_every):
        ax.annotate(str(k), c[k], xytext=(5, 5), textcoords="offset points", fontsize=9)
    ax.plot(*gt[0], "o", color="black", ms=9, mfc="none", mew=2, label="start")
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title="submap centres along the flight, seen from above")
    _grid(ax)
    ax.legend(loc="center", fontsize=9)
    return fig


def recent_rule_figure(centres, position, n_excluded: int, radius: float, title: str):
    """Top view of the submap centres at one moment of the flight: the
    ``n_excluded`` newest (never candidates) in light grey, the older ones
    (eligible) in black, the current position and the search radius."""
    c = _xy(centres)
    eligible = c[: max(0, len(c) - n_excluded)]
    excluded = c[len(eligible) :]
    fig, ax = plt.subplots(figsize=(10, 5.4), constrained_layout=True)
    ax.plot(c[:, 0], c[:, 1], color=LIGHT, lw=1, zorder=1)
    ax.scatter(*eligible.T, s=22, color="black", zorder=3, label=f"eligible ({len(eligible)} oldest)")
    ax.scatter(*excluded.T, s=30, color="white", edgecolor=GREY, zorder=3, label=f"too recent ({len(excluded)} newest)")
    ax.plot(*position[:2], "*", color=COLORS["odometry"], ms=16, zorder=4, label="the drone now")
    ax.add_patch(Circle(position[:2], radius, fill=False, color=COLORS["loop"], lw=2, zorder=4, label="search radius"))
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title=title)
    _grid(ax)
    ax.legend(loc="center", fontsize=9)
    return fig


def query_cost_figure(n_scans, n_submaps, points_per_scan, points_per_submap):
    """Two bars each: how many clouds a query could register against, and
    how many points each of them holds, for scans and for submaps."""
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2), constrained_layout=True)
    names = ["scans", "submaps"]
    colors = [GREY, COLORS["loop"]]
    for ax, values, title in (
        (axes[0], [n_scans, n_submaps], "clouds to register against"),
        (axes[1], [points_per_scan, points_per_submap], "points per cloud (median)"),
    ):
        bars = ax.bar(names, values, color=colors, width=0.6)
        ax.bar_label(bars, fmt="%d", padding=2)
        ax.set(title=title, ylim=(0, 1.18 * max(values)))
        _grid(ax)
    return fig


# ----------------------------------------------------------------------------------------------------------------
# Notebook 5: loop closure
# ----------------------------------------------------------------------------------------------------------------


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
    and each eligible submap's grown radius drawn as a faint ring. Tried
    submaps are ringed in orange, matched ones filled orange."""
    c = _xy(centres)
    p = np.asarray(position)[:2]
    fig, ax = plt.subplots(figsize=(9, 6.2), constrained_layout=True)
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
                label=f"grown radius {radius[nearest]:.1f} m (nearest old submap)",
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
        t = _xy(true_centres)
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
    _grid(ax)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9)
    return fig


def query_search(result, node: int) -> dict:
    """What the loop query of ``node`` saw, rebuilt from a pipeline result:
    the submap centres that existed then (odometry frame), how many were
    eligible, each one's grown search radius, the submaps registered by ICP
    (nearest first) and the scan's odometry and true positions."""
    from .loopclosure import distance_flown_since

    config = result.config
    count = (node + 1) // config.n_scans_per_submap  # submaps built by then
    centres = result.submaps.centres[:count]
    position = result.poses_odometry[node][:3, 3]
    radius = config.loop_closure_search_radius + config.loop_search_growth * distance_flown_since(centres, position)
    n_eligible = max(0, count - config.sub_map_thresh)
    distance = np.linalg.norm(centres[:n_eligible] - position, axis=1)
    near = np.flatnonzero(distance < radius[:n_eligible])
    near = near[np.argsort(distance[near], kind="stable")]
    query = next((q for q in result.queries if q.node == node), None)
    tried = near[: len(query.tried)] if query is not None else near[:0]
    true_centres = np.array(
        [result.poses_gt[centre_scan_id(s.id, len(s.scan_ids))][:3, 3] for s in result.submaps.submaps]
    )
    return {
        "centres": centres,
        "true_centres": true_centres[:count],
        "n_eligible": n_eligible,
        "radius": radius,
        "distance": distance,
        "tried": tried,
        "matched": np.array([] if query is None else query.submap_ids, int),
        "position": position,
        "true_position": result.poses_gt[node][:3, 3],
    }


def revisits(result, max_true_distance: float = 10.0) -> dict:
    """Every node that truly flies over an eligible old submap (true centre
    within ``max_true_distance`` m): the distance flown since that submap,
    how far away it looks on the odometry, and whether the node closed a loop."""
    from .loopclosure import distance_flown_since

    config = result.config
    n = config.n_scans_per_submap
    subs = result.submaps.submaps
    true_centres = np.array([result.poses_gt[centre_scan_id(s.id, len(s.scan_ids))][:3, 3] for s in subs])
    closed = {loop.j for loop in result.loops}
    rows = []
    for node in range(len(result.indices)):
        count = (node + 1) // n
        n_eligible = count - config.sub_map_thresh
        if n_eligible <= 0:
            continue
        true_distance = np.linalg.norm(true_centres[:n_eligible] - result.poses_gt[node][:3, 3], axis=1)
        k = int(np.argmin(true_distance))
        if true_distance[k] > max_true_distance:
            continue
        position = result.poses_odometry[node][:3, 3]
        flown = distance_flown_since(result.submaps.centres[:count], position)[k]
        apparent = np.linalg.norm(result.submaps.centres[k] - position)
        rows.append((node, flown, apparent, node in closed))
    nodes, flown, apparent, found = (np.array(c) for c in zip(*rows, strict=True)) if rows else ([],) * 4
    return {"nodes": nodes, "flown": flown, "apparent": apparent, "closed": np.asarray(found, bool)}


def search_radius_figure(flown, apparent, found, base_radius: float, growth: float):
    """For every query: the distance flown since the place it revisits (x)
    against how far away that place looks on the odometry (y), with the
    reference's fixed radius and the grown one. Places below a line are in
    reach of that search."""
    flown, apparent, found = map(np.asarray, (flown, apparent, found))
    fig, ax = plt.subplots(figsize=(9, 4.2), constrained_layout=True)
    x = np.linspace(0, 1.05 * flown.max(), 50)
    ax.plot(x, np.full_like(x, base_radius), "--", color="black", lw=1.5, label=f"fixed radius {base_radius:.1f} m")
    ax.plot(
        x,
        base_radius + growth * x,
        color=COLORS["loop"],
        lw=2,
        label=f"grown radius: {base_radius:.1f} m + {growth:.0%} of the distance flown",
    )
    ax.scatter(
        flown[found],
        apparent[found],
        s=22,
        color=COLORS["loop"],
        edgecolor="black",
        lw=0.5,
        zorder=3,
        label="queries that closed a loop",
    )
    ax.scatter(
        flown[~found], apparent[~found], s=18, color="white", edgecolor=GREY, zorder=2, label="queries that did not"
    )
    ax.set(
        xlabel="distance flown since the revisited submap (m)",
        ylabel="its distance on the odometry (m)",
        ylim=(0, None),
        xlim=(0, x[-1]),
    )
    _grid(ax)
    ax.legend(fontsize=9, loc="upper left")
    return fig


def _moved(points, transform):
    return points @ transform[:3, :3].T + transform[:3, 3]


def pair_overlay_figure(moving, fixed, stages: dict, half_width: float = 60.0, slab: float = 1.5):
    """The moving scan (pink) over the fixed scan (cyan), in the fixed
    scan's frame, once per stage: a top view (top row, cropped to
    ``|y| < half_width``) and a side view of a thin slab across the track
    (bottom row, points with ``|x| < slab``). ``stages`` maps a title to the
    4 x 4 transform applied to ``moving``."""
    n = len(stages)
    fig, axes = plt.subplots(
        2, n, figsize=(5.2 * n, 6.4), squeeze=False, constrained_layout=True, gridspec_kw={"height_ratios": [1.5, 1]}
    )
    keep_f = np.abs(fixed[:, 1]) < half_width
    for col, (title, transform) in enumerate(stages.items()):
        moved = _moved(moving, transform)
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
        _grid(side)
    axes[0, 0].set_ylabel("x, forward (m)")
    axes[1, 0].set_ylabel("z (m), slab across the track")
    for key, name in (("fixed", "fixed: the old scan"), ("moving", "moving: the current scan")):
        axes[0, -1].scatter([], [], color=COLORS[key], s=25, label=name)
    axes[0, -1].legend(loc="upper right", fontsize=9, framealpha=0.95)
    return fig


def rmse_offsets_figure(offsets, point_to_point, surface):
    """Both registration scores of one truly aligned pair shifted along the
    track by each offset: the point-to-point RMSE and the RMSE along the
    fixed cloud's normals."""
    fig, ax = plt.subplots(figsize=(8, 3.8), constrained_layout=True)
    ax.plot(offsets, point_to_point, "o-", color=GREY, lw=2, label="point-to-point RMSE (the reference's)")
    ax.plot(offsets, surface, "o-", color=COLORS["loop"], lw=2, label="RMSE along the normals (ours)")
    ax.set(xlabel="shift along the track from the true alignment (m)", ylabel="score (m)", ylim=(0, None))
    _grid(ax)
    ax.legend(fontsize=9)
    return fig


def queries_figure(nodes, tried, best, accepted, thresholds: dict):
    """Every loop query: each submap registered (small grey dots), the best
    scan-to-scan match of queries that found a submap (orange if it became
    a loop edge, black cross if not), and the thresholds."""
    fig, ax = plt.subplots(figsize=(10, 4.2), constrained_layout=True)
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
    _grid(ax)
    ax.legend(fontsize=9, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


def loop_errors_figure(error_m, error_deg, limits=(1.0, 2.0)):
    """Each accepted loop edge's error against the ground truth: translation
    (m) against rotation (deg), with the box inside which a loop counts as right."""
    fig, ax = plt.subplots(figsize=(6.5, 4), constrained_layout=True)
    ax.add_patch(plt.Rectangle((0, 0), *limits, color=COLORS["ground_truth"], alpha=0.12, label="counted as right"))
    ax.scatter(
        error_m,
        error_deg,
        s=36,
        color=COLORS["loop"],
        edgecolor="black",
        lw=0.5,
        zorder=3,
        label=f"loop edges ({len(error_m)})",
    )
    ax.set(
        xlabel="translation error (m)",
        ylabel="rotation error (deg)",
        xlim=(0, 1.15 * max(limits[0], np.max(error_m, initial=0))),
        ylim=(0, 1.15 * max(limits[1], np.max(error_deg, initial=0))),
    )
    _grid(ax)
    ax.legend(fontsize=9, loc="upper right")
    return fig


# ----------------------------------------------------------------------------------------------------------------
# Notebook 6: pose graph
# ----------------------------------------------------------------------------------------------------------------


def pose_graph_figure(poses, loop_pairs, every: int = 1, inset=None, inset_at=(0.42, 0.2, 0.42, 0.6)):
    """The pose graph drawn on its initial (odometry) poses: nodes as dots,
    odometry edges as a red line, loop edges in orange. ``inset`` =
    (xmin, xmax, ymin, ymax) adds a zoom on that window, drawn at ``inset_at``
    (x0, y0, width, height in axes fractions)."""
    xy = _xy(poses)
    pairs = np.asarray(loop_pairs, int).reshape(-1, 2)
    fig, ax = plt.subplots(figsize=(10, 5.8), constrained_layout=True)

    def draw(axis, size):
        axis.plot(xy[:, 0], xy[:, 1], color=COLORS["odometry"], lw=1.2, zorder=2)
        axis.scatter(xy[::every, 0], xy[::every, 1], s=size, color="black", zorder=3)
        axis.add_collection(
            LineCollection(_segments(xy[pairs[:, 0]], xy[pairs[:, 1]]), colors=COLORS["loop"], linewidths=2.2, zorder=4)
        )

    draw(ax, 6)
    ax.plot([], [], color=COLORS["odometry"], lw=1.2, label=f"odometry edges ({len(xy) - 1})")
    ax.scatter([], [], s=6, color="black", label=f"nodes ({len(xy)})")
    ax.plot([], [], color=COLORS["loop"], lw=2.2, label=f"loop edges ({len(pairs)})")
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title="the pose graph on the odometry poses")
    _grid(ax)
    ax.legend(loc="center left", bbox_to_anchor=(0.1, 0.5) if inset is not None else (0.35, 0.5), fontsize=9)
    if inset is not None:
        zoom = ax.inset_axes(list(inset_at))
        draw(zoom, 14)
        zoom.set(xlim=inset[:2], ylim=inset[2:], aspect="equal", xticks=[], yticks=[])
        ax.indicate_inset_zoom(zoom, edgecolor="black")
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
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.4), constrained_layout=True)
    for (name, (rho, weight)), color in zip(costs.items(), ("black", "#6a3d9a", COLORS["loop"]), strict=False):
        left.plot(r, rho, color=color, lw=2, label=name)
        right.plot(r, weight, color=color, lw=2, label=name)
    left.set(xlabel="whitened residual r (sigmas)", ylabel="cost rho(r)", ylim=(0, limit**2 / 4), title="cost")
    right.set(xlabel="whitened residual r (sigmas)", ylabel="weight w(r)", ylim=(0, 1.05), title="weight")
    for ax in (left, right):
        _grid(ax)
    right.legend(fontsize=9)
    return fig


def trajectories_figure(
    ground_truth,
    odometry,
    optimized,
    loop_pairs=(),
    inset=None,
    title="trajectories from above",
    inset_at=(0.42, 0.2, 0.42, 0.6),
):
    """Top view of the three trajectories in their colours, loop edges
    drawn on the optimised one; ``inset`` = (xmin, xmax, ymin, ymax) zooms."""
    gt, odo, opt = _xy(ground_truth), _xy(odometry), _xy(optimized)
    pairs = np.asarray(loop_pairs, int).reshape(-1, 2)
    fig, ax = plt.subplots(figsize=(10, 5.8), constrained_layout=True)

    def draw(axis):
        axis.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=3, label="ground truth")
        axis.plot(odo[:, 0], odo[:, 1], color=COLORS["odometry"], lw=1.6, label="odometry only")
        axis.plot(opt[:, 0], opt[:, 1], color=COLORS["optimized"], lw=1.6, label="after optimisation")
        if len(pairs):
            axis.add_collection(
                LineCollection(
                    _segments(opt[pairs[:, 0]], opt[pairs[:, 1]]),
                    colors=COLORS["loop"],
                    linewidths=1.2,
                    alpha=0.7,
                    zorder=1,
                    label="loop edges",
                )
            )

    draw(ax)
    ax.plot(*gt[0], "o", color="black", ms=8, mfc="none", mew=2, label="start")
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title=title)
    _grid(ax)
    ax.legend(loc="center left", bbox_to_anchor=(0.1, 0.5) if inset is not None else (0.35, 0.5), fontsize=9)
    if inset is not None:
        zoom = ax.inset_axes(list(inset_at))
        draw(zoom)
        zoom.set(xlim=inset[:2], ylim=inset[2:], aspect="equal", xticks=[], yticks=[])
        ax.indicate_inset_zoom(zoom, edgecolor="black")
    return fig


def position_errors_figure(x, errors: dict, xlabel="node (accepted scan)", loop_nodes=()):
    """Distance from the true position, node by node, one line per
    trajectory; ``errors`` maps a label (whose colour key is found from
    "odometry"/"optimi") to (N,) errors in metres. Loop nodes are marked."""
    fig, ax = plt.subplots(figsize=(10, 3.6), constrained_layout=True)
    for name, values in errors.items():
        color = COLORS["odometry"] if "odometry" in name else COLORS["optimized"]
        ax.plot(x, values, color=color, lw=2, label=name)
    for k, node in enumerate(loop_nodes):
        ax.axvline(node, color=COLORS["loop"], lw=1, alpha=0.6, label="a loop edge arrives" if k == 0 else None)
    ax.set(xlabel=xlabel, ylabel="position error (m)", ylim=(0, None))
    _grid(ax)
    ax.legend(fontsize=9, loc="upper left")
    return fig


def loop_weights_figure(labels, whitened, weights):
    """Each loop edge after optimisation: its whitened residual (sigmas) and
    the weight the robust kernel gave it."""
    x = np.arange(len(labels))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 4.6), sharex=True, constrained_layout=True)
    top.bar(x, whitened, color=COLORS["loop"], width=0.7)
    top.set(ylabel="residual (sigmas)", title="loop edges after optimisation")
    bottom.bar(x, weights, color=COLORS["loop"], width=0.7)
    bottom.axhline(1, color="black", lw=1, ls="--")
    bottom.set(ylabel="kernel weight", ylim=(0, 1.1))
    bottom.set_xticks(x, labels, rotation=60, fontsize=8)
    bottom.set_xlabel("loop edge (older node - current node)")
    for ax in (top, bottom):
        _grid(ax)
    return fig


def bad_edge_figure(ground_truth, results: dict, bad_pair, inset=None):
    """One panel per kernel: the trajectory optimised with a deliberately
    wrong loop edge (drawn dashed black), against the ground truth."""
    gt = _xy(ground_truth)
    n = len(results)
    fig, axes = plt.subplots(1, n, figsize=(6.2 * n, 4.4), squeeze=False, sharey=True, constrained_layout=True)
    for ax, (title, poses) in zip(axes[0], results.items(), strict=True):
        xy = _xy(poses)
        ax.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=3, label="ground truth")
        ax.plot(xy[:, 0], xy[:, 1], color=COLORS["optimized"], lw=1.6, label="after optimisation")
        i, j = bad_pair
        ax.plot(*_segments(xy[[i]], xy[[j]])[0].T, "k--", lw=1.5, label="the wrong loop edge")
        ax.plot(*xy[[i, j]].T, "ko", ms=5)
        ax.set(title=title, xlabel="x (m)", aspect="equal")
        _grid(ax)
    axes[0, 0].set_ylabel("y (m)")
    axes[0, 0].legend(loc="center", fontsize=9)
    return fig


__all__ = [
    "WINDOW",
    "bad_edge_figure",
    "candidates_figure",
    "kernels_figure",
    "loop_errors_figure",
    "loop_weights_figure",
    "pair_overlay_figure",
    "pose_graph_figure",
    "position_errors_figure",
    "queries_figure",
    "query_cost_figure",
    "query_search",
    "recent_rule_figure",
    "revisits",
    "rmse_offsets_figure",
    "search_radius_figure",
    "submap_centres_figure",
    "submap_panels",
    "trajectories_figure",
]
