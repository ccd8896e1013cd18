"""What the commands write, each into a folder written all at once: ``run``'s
``metrics.json``, trajectories (TUM, KITTI, CSV), ``map.ply``, ``map.laz`` and ``config.toml``;
``dataset``'s scans, poses, map and sensor table."""

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
from helpers.sim.map_laz import write_map_laz
from helpers.sim.maps import MapFrame
from helpers.sim.ply import write_ply
from helpers.sim.trajectories import write_kitti, write_pose_csv, write_tum
from helpers.slam.slam import SlamResult

RUN_MARKER = ".helpers-run"  # lists what a run wrote: the next run may replace the folder while it holds only that
RUN_LEGACY_MARKER = "metrics.json"  # what marked a run's folder before: such a folder is left to the user
DATASET_MARKER = (
    ".helpers-dataset"  # lists what a dataset holds: the next may replace the folder while it holds only that
)
DATASET_LEGACY_MARKER = "poses_gt.txt"  # what marked a dataset's folder before: such a folder is left to the user


def write_run(
    result: SlamResult, out_dir, metrics: dict, poses_gt: np.ndarray | None = None, *, frame: MapFrame | None = None
) -> Path:
    """Write, all or nothing, into a folder that is new, empty or an earlier run's
    (:func:`helpers.outdir.atomic_dir`):

    - ``metrics.json``: ``metrics`` (from :func:`helpers.quality.evaluation.run_metrics`) and the config;
    - ``trajectory_{odometry,optimized,gt}``: the odometry, the optimised poses and the ground truth
      (``poses_gt``, (K, 4, 4), one per node; None for a run without truth: no ``trajectory_gt``), each
      as TUM ``.txt`` (the scan's dataset index as the stamp), KITTI ``.kitti`` and ``.csv`` of
      ``index,x,y,z,roll,pitch,yaw`` (:mod:`helpers.sim.trajectories`), all in the run's map frame, metres;
    - ``map.ply`` (map frame, metres) and ``map.laz``, the same points in the tile's coordinate system,
      units and CRS (``frame``, the dataset's :class:`~helpers.sim.maps.MapFrame`; None: the run's local
      frame, :func:`helpers.sim.map_laz.write_map_laz`);
    - the ``config.toml`` used."""
    metrics = {**metrics, "config": config_to_dict(result.config)}
    trajectories = {"odometry": result.poses_odometry, "optimized": result.poses_optimized}
    if poses_gt is not None:
        trajectories = {"gt": poses_gt, **trajectories}
    with outdir.atomic_dir(out_dir, RUN_MARKER, RUN_LEGACY_MARKER) as work:
        (work / "metrics.json").write_text(json.dumps(metrics, indent=2, allow_nan=False) + "\n")
        for name, poses in trajectories.items():
            write_tum(work / f"trajectory_{name}.txt", poses, result.indices)
            write_kitti(work / f"trajectory_{name}.kitti", poses)
            write_pose_csv(work / f"trajectory_{name}.csv", poses, result.indices)
        write_ply(work / "map.ply", result.map_points)
        write_map_laz(work / "map.laz", result.map_points, frame)
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
