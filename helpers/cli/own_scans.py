"""``run --scans DIR``: the SLAM on a folder of the user's own scans (:mod:`helpers.cli.scans`), graded
against ``--truth`` poses when given, else with the run's own figures and its trust flag only."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from helpers.errors import SlamError

if TYPE_CHECKING:  # numpy is imported where a run needs it: --help stays quick
    import numpy as np

NADIR_DEG = 5.0  # points within this angle of the sensor's -z axis measure the height (the sensor frame's nadir)
DEFAULT_SPACING = 2.0  # m between scans when neither --truth nor --scan-spacing tells it (the reference's)

SCANS_HELP = (
    "run the SLAM on your own scans instead of simulating them: a folder of one file per scan in the sensor "
    "frame (x along the track, y to the left, z up: the ground lies below, at -z), in natural name order: "
    ".ply, .pcd, .las/.laz, .npy (N x 3+), KITTI .bin; not with --map/--waypoints. The fit to the flight takes "
    "the height from --sensor-height, else from the median range straight down in the first scans, and the "
    "distance between scans from --scan-spacing, else from --truth, else 2 m"
)


def add_scan_arguments(run_parser: argparse.ArgumentParser) -> None:
    """Add ``--scans``, ``--truth``, ``--sensor-height`` and ``--scan-spacing`` to the ``run`` parser."""
    group = run_parser.add_argument_group("your own scans")
    group.add_argument("--scans", metavar="DIR", help=SCANS_HELP)
    group.add_argument(
        "--truth",
        metavar="POSES",
        help="true sensor poses of the scans, TUM (stamp = scan index, or a time stamp with one line per scan) "
        "or KITTI (12 numbers a line, one line per scan): adds ATE/RPE and false loops to metrics.json, and "
        "its first pose anchors the trajectory (identity without it)",
    )
    group.add_argument(
        "--sensor-height",
        metavar="M",
        type=float,
        help="height of the flight above the ground, m (default: the median range within "
        f"{NADIR_DEG:g} deg of straight down in the first scans)",
    )
    group.add_argument(
        "--scan-spacing",
        metavar="M",
        type=float,
        help=f"distance flown between scans, m (default: from --truth, else {DEFAULT_SPACING:g} m)",
    )


def wants_scans(args) -> bool:
    """Whether ``run`` is asked to run on a folder of scans (``--scans``); the options that only such a run
    reads, given without it, are a :class:`SlamError`."""
    if getattr(args, "scans", None):
        return True
    given = [name for name in ("truth", "sensor_height", "scan_spacing") if getattr(args, name, None) is not None]
    if given:
        options = ", ".join("--" + name.replace("_", "-") for name in given)
        raise SlamError(f"{options} go with your own scans: give their folder with --scans DIR")
    return False


@dataclass
class ScanDataset:
    """What :func:`helpers.slam.pipeline.run_slam` and :func:`helpers.quality.evaluation.run_metrics` read of a
    dataset: ``scans``, ``len`` and ``poses`` (the truth at each kept scan, or the identity anchor alone)."""

    scans: object  # helpers.cli.scans.ScanFolder
    poses: np.ndarray
    truth: bool

    def __len__(self) -> int:
        return len(self.scans)


def run_on_scans(args) -> int:
    """The whole ``run --scans`` command; a :class:`SlamError` for bad input, before any work where it can."""
    import numpy as np

    from helpers.cli.memory import stage as _stage
    from helpers.cli.outputs import write_run
    from helpers.cli.terminal import report_run
    from helpers.quality.trust import assess
    from helpers.slam.pipeline import run_slam

    start = time.perf_counter()
    folder, data, config, gnss = _prepare(args)
    read = time.perf_counter() - start
    interactive = sys.stderr.isatty()
    with _stage("running SLAM"):
        times = data.scans.times if data.scans.has_times else None
        result = run_slam(data, config, progress=interactive, gnss=gnss, times=times)
    result.runtime_s = {"reading": read, **result.runtime_s}
    with _stage("evaluating the run"):
        health = assess(result)
        metrics = scan_metrics(data, result, health, folder, args)
    poses_gt = data.poses[result.indices] if data.truth else None
    files = dataclasses.replace(result, indices=np.asarray(folder.kept)[result.indices])  # stamps: file numbers
    with _stage("writing the run"):
        out = write_run(files, args.out, metrics, poses_gt)
    report_run(metrics, health, out)
    return 0


def _prepare(args):
    """(folder, dataset, fitted config, GNSS fixes) of ``run --scans``: input and output place checked, every
    scan read once (:meth:`~helpers.cli.scans.ScanFolder.survey`), the parameters fitted to the flight."""
    from helpers.cli.outputs import RUN_LEGACY_MARKER, RUN_MARKER
    from helpers.cli.scans import open_scan_folder
    from helpers.cli.terminal import say
    from helpers.config.files import given_keys, load_config
    from helpers.outdir import check_output_place
    from helpers.progress import progress_bar
    from helpers.sim.gnss import read_fixes
    from helpers.slam.flight_fit import check_grid_steps, fit_to_flight

    if getattr(args, "map", None) or getattr(args, "waypoints", None):
        raise SlamError("--scans runs on your scans: --map and --waypoints (which simulate them) cannot go with it")
    check_output_place(args.out, RUN_MARKER, RUN_LEGACY_MARKER)
    config = load_config(args.config)
    gnss = read_fixes(args.gnss, args.gnss_sigma, config.sensor)
    folder = open_scan_folder(args.scans)
    truth = read_truth(args.truth, len(folder.files)) if args.truth else None
    bar = progress_bar(len(folder.files), "reading scans", enabled=sys.stderr.isatty())
    folder.survey(bar)
    bar.close()
    data = _dataset(folder, truth, args.truth)
    gnss = _kept_gnss(gnss, folder, args.gnss)
    flight, how = flight_of_scans(folder, config, args.sensor_height, args.scan_spacing, truth)
    reference = getattr(args, "reference_values", False)
    if not reference:
        config, reasons = fit_to_flight(flight, config, given_keys(args.config), gnss=gnss is not None)
    check_grid_steps(flight, config)  # before a word about the fit: a refused run prints only its error
    skipped = f", {len(folder.skipped)} skipped" if folder.skipped else ""
    times = " (per-point times: each scan deskewed with the last motion)" if folder.has_times else ""
    say(f"{len(folder)} {folder.format} scans in {args.scans}{skipped}{times}")
    if not reference:
        say(
            f"parameters fitted to the flight ({flight.height:.0f} m above the ground {how[0]}, a scan every "
            f"{flight.spacing:.1f} m {how[1]}; --reference-values keeps the reference's):",
            *(f"  {line}" for line in reasons),
        )
    return folder, data, config, gnss


def read_truth(path, n_files: int):
    """(n_files, 4, 4) true poses, one per file of the folder (NaN where a TUM file has none): TUM whose stamps
    are scan indices (0 to n_files - 1) or time stamps (then one line per scan, in order), or KITTI."""
    import numpy as np

    from helpers.sim.trajectories import from_tum

    try:
        rows = np.loadtxt(path, ndmin=2, comments="#")
    except (OSError, ValueError) as exc:
        raise SlamError(f"cannot read --truth {path}: {exc}") from None
    poses = np.full((n_files, 4, 4), np.nan)
    if rows.shape[1] == 12:
        if len(rows) != n_files:
            raise SlamError(f"--truth {path}: KITTI poses are one line per scan: {len(rows)} lines, {n_files} scans")
        poses[:] = np.eye(4)
        poses[:, :3, :] = rows.reshape(-1, 3, 4)
    elif rows.shape[1] == 8:
        stamps = rows[:, 0]
        as_index = np.all(stamps == np.round(stamps)) and np.all((0 <= stamps) & (stamps < n_files))
        if as_index and len(np.unique(stamps)) == len(stamps):
            poses[stamps.astype(int)] = from_tum(rows[:, 1:])
        elif len(rows) == n_files:
            poses[:] = from_tum(rows[np.argsort(stamps, kind="stable"), 1:])
        else:
            raise SlamError(
                f"--truth {path}: its {len(rows)} TUM stamps are neither scan indices 0-{n_files - 1} nor one time "
                f"stamp per scan ({n_files} scans)"
            )
    else:
        raise SlamError(f"--truth {path}: a line of TUM has 8 numbers and of KITTI 12, found {rows.shape[1]}")
    if not np.all(np.isfinite(poses[np.isfinite(poses).all(axis=(1, 2))])):
        raise SlamError(f"--truth {path}: its poses must be finite numbers")
    return poses


def _dataset(folder, truth, source) -> ScanDataset:
    import numpy as np

    if truth is None:
        return ScanDataset(folder, np.eye(4)[None], False)
    kept = truth[folder.kept]
    missing = [folder.files[k].name for k, pose in zip(folder.kept, kept, strict=True) if not np.isfinite(pose).all()]
    if missing:
        raise SlamError(f"--truth {source} has no pose for {len(missing)} scans, e.g. {missing[0]}")
    return ScanDataset(folder, kept, True)


def _kept_gnss(gnss, folder, source):
    """The GNSS fixes of the kept scans, renumbered as they are (fixes index the folder's files)."""
    import numpy as np

    if gnss is None:
        return None
    from helpers.sim.gnss import GnssFixes

    gnss.check_flight(len(folder.files), source)
    renumber = np.full(len(folder.files), -1)
    renumber[folder.kept] = np.arange(len(folder.kept))
    new = renumber[gnss.indices]
    keep = new >= 0
    return GnssFixes(new[keep], gnss.positions[keep], gnss.sigmas)


def flight_of_scans(folder, config, height=None, spacing=None, truth=None):
    """The :class:`helpers.slam.flight_fit.Flight` of a folder of scans, and how its height and spacing were
    found: ``height`` else the median nadir range of the first scans; ``spacing`` else the truth's median step
    else :data:`DEFAULT_SPACING`; the surface cell is the first scan's median point spacing."""
    import numpy as np
    from scipy.spatial import cKDTree

    from helpers.cli.scans import first_scans
    from helpers.slam.flight_fit import Flight

    scans = [points for _, points in first_scans(folder)]
    how = ["(--sensor-height)", "(--scan-spacing)"]
    if height is None:
        height, how[0] = float(np.median([nadir_range(s) for s in scans])), "(the first scans' nadir range)"
    if not height > 0:
        raise SlamError(
            f"the first scans of {folder.root} have no points within {NADIR_DEG:g} deg below the sensor to tell "
            "the flight's height (or it is not above 0 m): give it with --sensor-height M"
        )
    if spacing is not None and not spacing > 0:
        raise SlamError(f"--scan-spacing {spacing:g}: the distance between scans must be above 0 m")
    if spacing is None and truth is not None:
        xy = truth[folder.kept][:, :2, 3]
        steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        if np.any(steps > 0):
            spacing, how[1] = float(np.median(steps[steps > 0])), "(the truth)"
    if spacing is None:
        spacing, how[1] = DEFAULT_SPACING, "(assumed: --scan-spacing tells it)"
    cell = float(np.median(cKDTree(scans[0]).query(scans[0], k=2)[0][:, 1]))
    start, stop, _ = config.sensor.elevation
    strip = height * (math.tan(math.radians(stop)) - math.tan(math.radians(start)))
    return Flight(height, spacing, cell, strip), how


def nadir_range(points: np.ndarray) -> float:
    """The median range of ``points`` within :data:`NADIR_DEG` of the sensor's -z axis (NaN if none)."""
    import numpy as np

    down = -points[:, 2]
    angle = np.degrees(np.arctan2(np.hypot(points[:, 0], points[:, 1]), down))
    near = down[angle <= NADIR_DEG]
    return float(np.median(near)) if len(near) else float("nan")


def scan_metrics(data: ScanDataset, result, health, folder, args) -> dict:
    """The figures of a run on a folder: :func:`helpers.quality.evaluation.run_metrics` with ``--truth``; without
    it the run's own (counts, trajectory, loops, timings, trust flag) and ``"truth": null``."""
    import numpy as np

    from helpers.quality.evaluation import run_metrics
    from helpers.quality.metrics import json_safe
    from helpers.sim.trajectories import to_tum

    scans = {
        "folder": str(args.scans),
        "format": folder.format,
        "n_files": len(folder.files),
        "n_skipped": len(folder.skipped),
        "skipped": folder.skipped,
        "n_nonfinite_points_dropped": folder.nonfinite,
        "per_point_times": folder.has_times,  # each scan deskewed with the odometry's last motion
    }
    if data.truth:
        return {**run_metrics(data, result, None, health), "truth": str(args.truth), "scans": scans}
    steps = result.odometry.timings
    metrics = {
        "trusted": health.trusted,
        "shape_trusted": health.consistent,
        "health": {**health.counts, "problems": health.problems, "scale": health.scale},
        "truth": None,
        "n_scans": result.n_scans,
        "n_accepted": len(result.indices),
        "n_loop_closures": len(result.loops),
        "loops": [{"i": int(loop.i), "j": int(loop.j), "surface_rmse_m": loop.surface_rmse} for loop in result.loops],
        "n_odometry_fallbacks": len(result.odometry.fallbacks),
        "n_extra_edges": len(result.extra_edges),
        "graph_error_before": result.graph.error_before,
        "graph_error_after": result.graph.error_after,
        "trajectory_optimized_tum": np.column_stack(
            [np.asarray(folder.kept)[result.indices], to_tum(result.poses_optimized)]
        ).tolist(),
        "runtime_s": {
            "total": sum(result.runtime_s.values()),
            **result.runtime_s,
            "odometry_per_scan_ms": {stage: float(np.mean(ms)) for stage, ms in steps.items()},
        },
        "scans": scans,
    }
    return json_safe(metrics)
