"""What ``run`` writes: ``metrics.json``, the TUM trajectories, ``map.ply`` and
the ``config.toml`` the run used, into a folder written all at once."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from . import outdir
from .configfile import config_to_dict, config_to_toml
from .pipeline import SlamResult
from .plyio import write_ply
from .trajectory import write_tum

MARKER = ".helpers-run"  # lists what a run wrote: the next run may replace the folder while it holds only that
LEGACY_MARKER = "metrics.json"  # what marked a run's folder before: such a folder is left to the user


def write_run(result: SlamResult, out_dir, metrics: dict, poses_gt: np.ndarray) -> Path:
    """Write ``metrics.json`` (``metrics``, from :func:`helpers.evaluation.run_metrics`,
    and the config), the TUM trajectories of the ground truth (``poses_gt``,
    (K, 4, 4), one per node), the odometry and the optimised poses (one line
    per accepted scan, its dataset index as the stamp), ``map.ply`` and the
    ``config.toml`` used, all or nothing, into a folder that is new, empty
    or an earlier run's (:func:`helpers.outdir.atomic_dir`)."""
    metrics = {**metrics, "config": config_to_dict(result.config)}
    with outdir.atomic_dir(out_dir, MARKER, LEGACY_MARKER) as work:
        (work / "metrics.json").write_text(json.dumps(metrics, indent=2, allow_nan=False) + "\n")
        for name, poses in (
            ("gt", poses_gt),
            ("odometry", result.poses_odometry),
            ("optimized", result.poses_optimized),
        ):
            write_tum(work / f"trajectory_{name}.txt", poses, result.indices)
        write_ply(work / "map.ply", result.map_points)
        (work / "config.toml").write_text(config_to_toml(result.config))
    return Path(out_dir)
