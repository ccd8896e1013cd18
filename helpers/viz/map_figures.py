"""Figures and tables for notebook 7: two runs of the same flight side by side
(the reference workflow against ours), graded against the ground truth."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from helpers.quality.evaluation import run_metrics
from helpers.quality.metrics import ate, rpe
from helpers.viz.style import COLORS, FIGURE_WIDTH, TEXT_PT, grid, xy_of


def comparison_rows(runs: dict) -> list[tuple[str, str, dict]]:
    """``(measure, unit, {run name: value})`` rows for runs given as
    ``{name: (dataset, result, map_error)}``; every trajectory figure says
    which trajectory it is of (odometry only, or optimised)."""
    figures = {}
    for name, (dataset, result, map_error) in runs.items():
        m = run_metrics(dataset, result, map_error)
        truth = dataset.poses[result.indices]
        step_odometry = rpe(result.poses_odometry, truth, 1)
        figures[name] = {
            "loop closures accepted": m["n_loop_closures"],
            "loop closures false": m["n_false_loop_closures"],
            "ATE RMSE, odometry only": m["ate_rmse_odometry_m"],
            "ATE RMSE, optimised": m["ate_rmse_optimized_m"],
            "RPE 1 step, odometry only": step_odometry.translation.rmse,
            "RPE 1 step, optimised": m["rpe_trans_1_m"],
            "RPE 1 step rotation, odometry only": step_odometry.rotation.rmse,
            "RPE 1 step rotation, optimised": m["rpe_rot_1_deg"],
            "map error, median": m["map_error_median_m"],
            "map error, 95th percentile": m["map_error_p95_m"],
        }
    units = {"loop": "count", "rotation": "deg"}
    first = next(iter(figures.values()))
    unit_of = {measure: next((u for key, u in units.items() if key in measure), "m") for measure in first}
    return [(measure, unit_of[measure], {n: f[measure] for n, f in figures.items()}) for measure in first]


def error_histograms_figure(maps: dict, top_m: float = 2.0):
    """One step histogram per map of its points' distances to the truth
    (``maps``: label -> (errors in m, colour)), on a log count scale, each
    median dashed; the last bin gathers everything at ``top_m`` and beyond."""
    fig, ax = plt.subplots(figsize=(8, 3.6), constrained_layout=True)
    bins = np.linspace(0.0, top_m, 81)
    for label, (errors, color) in maps.items():
        errors = np.asarray(errors, float)
        ax.hist(np.minimum(errors, top_m), bins=bins, histtype="step", lw=1.6, color=color, label=label)
        ax.axvline(np.median(errors), color=color, ls="--", lw=1)
    ax.plot([], [], color="black", ls="--", lw=1, label="median (dashed)")
    xlabel = f"distance to the ground-truth map (m); last bin: {top_m:g} m and more"
    ax.set(xlabel=xlabel, ylabel="map points", yscale="log")
    grid(ax)
    ax.legend(fontsize=TEXT_PT)
    return fig


def markdown_table(header, rows) -> str:
    """A GitHub-style Markdown table: ``header`` (column titles) and ``rows``
    (lists of cells, shown as given), the first column left-aligned, the others right."""
    lines = ["| " + " | ".join(header) + " |", "|:--|" + "--:|" * (len(header) - 1)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def comparison_markdown(rows, digits: int = 2) -> str:
    """The rows of :func:`comparison_rows` as a :func:`markdown_table` (measure,
    unit, one column per run), numbers to ``digits`` significant figures (counts whole)."""
    names = list(rows[0][2])

    def shown(v):
        return f"{v:d}" if isinstance(v, (int, np.integer)) else f"{v:.{digits}g}"

    body = [[measure, unit, *(shown(v) for v in values.values())] for measure, unit, values in rows]
    return markdown_table(["measure", "unit", *names], body)


def runs_figure(ground_truth, optimized: dict, colors: dict, odometry: dict | None = None, zoom_m: float = 8.0):
    """Two optimised trajectories against the truth: (left) the whole flight
    from above, (middle) a window ``2 zoom_m`` wide around the pose where the
    first of them is farthest off, (bottom) each one's position error along
    the flight, with the odometry's dashed if ``odometry`` is given.

    ``optimized`` and ``odometry`` map a run name to (N, 4, 4) poses;
    ``colors`` maps a run name to its colour."""
    truth = np.asarray(ground_truth)
    gt = xy_of(truth)
    fig = plt.figure(figsize=(FIGURE_WIDTH, 7.0), constrained_layout=True)
    spec = fig.add_gridspec(2, 2, height_ratios=(1.35, 1), width_ratios=(1.7, 1))
    whole, zoom, along = fig.add_subplot(spec[0, 0]), fig.add_subplot(spec[0, 1]), fig.add_subplot(spec[1, :])
    first = next(iter(optimized))
    worst = int(np.argmax(ate(optimized[first], truth).errors))
    centre = gt[worst]
    for ax in (whole, zoom):
        ax.plot(gt[:, 0], gt[:, 1], color=COLORS["ground_truth"], lw=4, alpha=0.6, label="ground truth")
        for name, poses in optimized.items():
            xy = xy_of(poses)
            ax.plot(xy[:, 0], xy[:, 1], color=colors[name], lw=1.5, marker="." if ax is zoom else None, label=name)
        ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal")
        grid(ax)
    whole.add_patch(
        plt.Rectangle(centre - zoom_m, 2 * zoom_m, 2 * zoom_m, fill=False, edgecolor="black", lw=1.2, zorder=5)
    )
    whole.set_title("optimised trajectories from above (the square: the window on the right)")
    whole.legend(fontsize=TEXT_PT, loc="center")
    zoom.set(xlim=(centre[0] - zoom_m, centre[0] + zoom_m), ylim=(centre[1] - zoom_m, centre[1] + zoom_m))
    zoom.set_title(f"where the {first} is farthest off", fontsize=10)
    flown = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(gt, axis=0), axis=1))]
    for name, poses in optimized.items():
        along.plot(flown, ate(poses, truth).errors, color=colors[name], lw=2, label=f"{name}, optimised")
    for name, poses in (odometry or {}).items():
        along.plot(flown, ate(poses, truth).errors, color=colors[name], lw=1.2, ls="--", label=f"{name}, odometry only")
    along.set(xlabel="distance flown (m)", ylabel="position error (m)", ylim=(0, None), xlim=(0, flown[-1]))
    along.set_title("distance from the true position, pose by pose", fontsize=10)
    grid(along)
    along.legend(fontsize=TEXT_PT, loc="upper left", ncol=2)
    return fig
