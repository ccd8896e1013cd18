"""One scan prepared for registration, once (stage 3a-3b): its clouds, its descriptors, its ICP cloud.

:func:`prepare` downsamples a scan on the feature grid and on the ICP grid
(once each), describes it (FPFH, :func:`describe`) and makes its ICP cloud
ready (normals and generalized-ICP covariances). The :class:`Frame` it
returns serves twice, as the moving scan of one pair and the fixed scan of
the next (:mod:`helpers.slam.registration.pair` registers the pair), and then for the edges
back and the loop search. :func:`reads_ahead` says when a run prepares the
next scan in a thread while it registers this one.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.geometry import check_points
from helpers.slam.registration.features import BINS, HISTOGRAMS, grid_average, keypoint_fpfh
from helpers.slam.registration.icp import IcpCloud, icp_cloud


@dataclass
class Frame:
    """One scan, prepared for registration."""

    points: np.ndarray  # (N, 3) grid-averaged on grid_step: where the descriptors are
    features: np.ndarray | None  # (K, 33) normalised FPFH descriptors of the keypoints (None until :func:`describe`)
    icp_points: np.ndarray  # (M, 3) the cloud ICP works on
    timings: dict  # ms per preparation stage
    icp: IcpCloud | None = None  # icp_points made ready for the configured ICP metric, once
    keypoints: np.ndarray | None = None  # (K,) indices of the points that have descriptors (None: all)

    def described(self) -> np.ndarray:
        """Indices of the points that have descriptors, ascending."""
        return np.arange(len(self.points)) if self.keypoints is None else self.keypoints


def prepare(scan: np.ndarray, config: Config) -> Frame:
    """Downsample one scan, describe it (not yet in tracking mode: see
    :func:`describe`) and make its ICP cloud ready.

    ``timings`` has the ms of ``downsample``, ``fpfh`` and ``icp`` (the ICP
    cloud's normals, covariances and k-d tree, paid once per scan).
    """
    registration = config.registration
    timings = {}
    start = time.perf_counter()
    points = grid_average(scan, config.features.grid_step)
    icp_points = points if config.icp_grid == config.features.grid_step else grid_average(scan, config.icp_grid)
    timings["downsample"] = elapsed_ms(start)
    start = time.perf_counter()
    icp = icp_cloud(icp_points, registration.metric, registration.icp_backend)
    timings["icp"] = elapsed_ms(start)
    frame = Frame(points, None, icp_points, timings, icp)
    return frame if registration.mode == "tracking" else describe(frame, config)


def empty_first_scan(index: int) -> SlamError:
    """The error of a flight whose first scan, which anchors it, holds no point (a later one is left out)."""
    return SlamError(f"scan {index}, the first, holds no point: the flight must begin over ground it sees")


def prepare_scan(scan: np.ndarray, index: int, config: Config) -> Frame | None:
    """Scan ``index`` (sensor frame, (N, 3)) checked and made ready for every stage (:func:`prepare`); None
    for a scan that holds no point (cast entirely over water, or a dropout), which has nothing to register."""
    if scan is not None and len(scan) == 0:
        return None
    return prepare(check_points(scan, f"scan {index}"), config)


def reads_ahead(config: Config) -> bool:
    """Whether a run prepares the next scan in a thread while it registers this one
    (:func:`helpers.slam.pipeline.run_slam`, :func:`helpers.slam.odometry.run_odometry`): in global mode,
    where FPFH, which lets go of Python's lock, is most of :func:`prepare` (the default flight's
    odometry 116 → 110 ms a scan on its 1.5 m grid, 67 → 62 on 3 m, the same bits). In tracking
    mode the preparation is small_gicp's ICP cloud, and its align holds the lock: the thread cost
    2 ms a scan (31 against 33), so there each scan is prepared when its turn comes."""
    return config.registration.mode == "global"


def describe(frame: Frame, config: Config) -> Frame:
    """Give ``frame`` its FPFH descriptors and keypoints, once (none when it has no more points than
    ``[features] neighbors``)."""
    if frame.features is None:
        start = time.perf_counter()
        if len(frame.points) > config.features.neighbors:
            frame.keypoints, frame.features = keypoint_fpfh(
                frame.points, config.features.neighbors, config.features.keypoint_share
            )
        else:  # too few points to describe (a scan mostly over water): none, and its registration falls back
            frame.keypoints, frame.features = np.zeros(0, dtype=np.int64), np.zeros((0, HISTOGRAMS * BINS))
        frame.timings["fpfh"] = frame.timings.get("fpfh", 0.0) + elapsed_ms(start)
    return frame


def elapsed_ms(start: float) -> float:
    """Milliseconds since ``start`` (a ``time.perf_counter()`` reading): the stages' timings here and in
    :mod:`helpers.slam.registration.pair`."""
    return 1000.0 * (time.perf_counter() - start)
