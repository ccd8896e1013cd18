"""What the commands write, each into a folder written all at once: ``run``'s
``metrics.json``, TUM trajectories, ``map.ply`` and ``config.toml``; ``dataset``'s scans,
poses, map and sensor table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from helpers import outdir
from helpers.config.files import config_to_dict, config_to_toml
from helpers.config.tables import Config
from helpers.progress import progress_bar
from helpers.sim.dataset import Dataset
from helpers.sim.gnss import FILE_NAME as GNSS_FILE
from helpers.sim.gnss import write_gnss
from helpers.sim.ply import write_ply
from helpers.sim.tum import write_tum
from helpers.slam.slam import SlamResult

RUN_MARKER = ".helpers-run"  # lists what a run wrote: the next run may replace the folder while it holds only that
RUN_LEGACY_MARKER = "metrics.json"  # what marked a run's folder before: such a folder is left to the user
DATASET_MARKER = (
    ".helpers-dataset"  # lists what a dataset holds: the next may replace the folder while it holds only that
)
DATASET_LEGACY_MARKER = "poses_gt.txt"  # what marked a dataset's folder before: such a folder is left to the user


def write_run(result: SlamResult, out_dir, metrics: dict, poses_gt: np.ndarray) -> Path:
    """Write ``metrics.json`` (``metrics``, from :func:`helpers.quality.evaluation.run_metrics`,
    and the config), the TUM trajectories of the ground truth (``poses_gt``,
    (K, 4, 4), one per node), the odometry and the optimised poses (one line
    per accepted scan, its dataset index as the stamp), ``map.ply`` and the
    ``config.toml`` used, all or nothing, into a folder that is new, empty
    or an earlier run's (:func:`helpers.outdir.atomic_dir`)."""
    metrics = {**metrics, "config": config_to_dict(result.config)}
    with outdir.atomic_dir(out_dir, RUN_MARKER, RUN_LEGACY_MARKER) as work:
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


def write_dataset(dataset: Dataset, out_dir: str | Path, progress: bool = False) -> Path:
    """Write ``scans/000000.ply ...`` (sensor frame), ``poses_gt.txt`` (TUM),
    ``map_gt.ply`` and, with GNSS, ``gnss.csv`` (:mod:`helpers.sim.gnss`) into ``out_dir``, all or nothing: the
    files are
    written in a temporary folder beside it that replaces it at the end. An
    existing ``out_dir`` is replaced only if it is empty or an earlier
    dataset (:func:`helpers.outdir.atomic_dir`)."""
    with outdir.atomic_dir(out_dir, DATASET_MARKER, DATASET_LEGACY_MARKER) as work:
        (work / "scans").mkdir()
        bar = progress_bar(len(dataset), "writing scans", enabled=progress)
        for index, scan in enumerate(dataset.scans):
            write_ply(work / "scans" / f"{index:06d}.ply", scan)
            bar.update(1)
        bar.close()
        write_tum(work / "poses_gt.txt", dataset.poses)
        write_ply(work / "map_gt.ply", dataset.map_points)
        if dataset.gnss is not None:
            write_gnss(work / GNSS_FILE, dataset.gnss)
        sensor = config_to_toml(Config(sensor=dataset.sensor), ("sensor",), "the sensor that produced this dataset")
        (work / "sensor.toml").write_text(sensor)
    return Path(out_dir)
