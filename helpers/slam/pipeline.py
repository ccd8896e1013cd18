"""The whole SLAM pipeline over a dataset: :class:`helpers.slam.slam.Slam` fed
every scan of the flight, then the pose graph and the map
(:meth:`~helpers.slam.slam.Slam.result`).

Accepted scans are the pose-graph nodes, numbered 0, 1, 2, ...;
``result.indices[k]`` is the dataset index of node ``k``.
"""

from __future__ import annotations

import logging
from concurrent.futures import ThreadPoolExecutor

from helpers.config.tables import Config
from helpers.progress import progress_bar
from helpers.sim.dataset import Dataset
from helpers.slam.edges_back import STARTUP_NODES
from helpers.slam.graph.factors import Edge
from helpers.slam.loops.closer import LoopQuery
from helpers.slam.odometry import OdometryResult
from helpers.slam.preprocess import prepare_scan, reads_ahead
from helpers.slam.slam import Slam, SlamResult, Step, build_pose_graph

log = logging.getLogger(__name__)

__all__ = ["Edge", "LoopQuery", "Slam", "SlamResult", "Step", "build_pose_graph", "run_slam"]


def run_slam(
    dataset: Dataset,
    config: Config | None = None,
    progress: bool = False,
    odometry: OdometryResult | None = None,
    gnss=None,
    times=None,
) -> SlamResult:
    """Estimate the trajectory and the map from ``dataset.scans`` alone (the
    first ground-truth pose anchors the first node, as in the reference; no
    other true pose is read: :mod:`helpers.quality.evaluation` grades the result).
    ``odometry``: reuse one already computed on this dataset with this
    configuration (the stages after it run as usual). ``gnss``: position
    fixes (:class:`helpers.sim.gnss.GnssFixes`) added to the pose graph.
    A flight of :data:`~helpers.slam.edges_back.STARTUP_NODES` nodes or more
    registers its edges back in a helper process while the next scan is
    registered (:mod:`helpers.slam.edges_back`), and a run in global mode reads
    and prepares the next accepted scan in a thread while this one is
    registered (:func:`helpers.slam.preprocess.reads_ahead`): the same result, sooner. ``times``: a
    function of the scan index giving its per-point times (or None): each scan is then deskewed with the
    last motion (:mod:`helpers.slam.deskew`), and read after the step before it."""
    config = config or Config()
    skip = config.registration.skip_frames
    nodes = len(odometry.indices) if odometry is not None else -(-len(dataset) // skip)
    background = nodes >= STARTUP_NODES
    slam = Slam(config, anchor=dataset.poses[0], odometry=odometry, gnss=gnss, background=background)
    bar = progress_bar(len(dataset), "slam", enabled=progress)
    loops, following = 0, None  # following: the future of the next accepted scan (index + skip), prepared meanwhile
    reading = odometry is None and reads_ahead(config) and times is None

    def read_and_prepare(index: int):
        return prepare_scan(dataset.scans[index], index, config)

    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="helpers-read-ahead") as ahead:
        for index in range(len(dataset)):
            if slam.accepts(index):  # skipped scans are never read (nor cast, for a lazy dataset)
                prepared, following = following, None
                scan = dataset.scans[index] if prepared is None else None
                if reading and index + skip < len(dataset):
                    following = ahead.submit(read_and_prepare, index + skip)
                stamps = None if times is None else times(index)
                loops += slam.process(scan, index, prepared, times=stamps).loop is not None
                bar.set_postfix(loops=loops, refresh=False)
            bar.update(1)
    bar.close()
    return slam.result(n_scans=len(dataset))
