"""Stage 3c: lidar odometry, scan to scan, as the reference's registration loop.

Every ``skip_frames``-th scan is *accepted*. Each accepted scan is registered
to the previous one, each prepared once (:mod:`helpers.slam.preprocess`:
grid-average downsampling, FPFH descriptors, the ICP cloud) and registered
(:mod:`helpers.slam.registration.pair`: descriptor matching, a robust fit and an ICP
refinement). Chaining the relative transforms from the first pose gives the
trajectory. :class:`Odometry` does it one frame at a time, keeping the
previous frame and the last motion between calls; :func:`run_odometry` runs
it over a whole flight.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.geometry import check_pose, transform_points
from helpers.progress import progress_bar
from helpers.slam.deskew import per_period
from helpers.slam.motion_guard import beyond, offset
from helpers.slam.preprocess import Frame, describe, empty_first_scan, prepare, prepare_scan, reads_ahead
from helpers.slam.registration.features import grid_average
from helpers.slam.registration.icp import icp_cloud
from helpers.slam.registration.icp_service import IcpService
from helpers.slam.registration.pair import STAGES, PairRegistration, register_frames, register_pair, track_frames
from helpers.threads import one_blas_thread

log = logging.getLogger(__name__)

__all__ = [
    "STAGES",
    "Frame",
    "Odometry",
    "OdometryResult",
    "local_map",
    "predicted_motion",
    "prepare",
    "register_frames",
    "register_pair",
    "staleness",
]


@dataclass
class OdometryResult:
    """The odometry over all accepted scans."""

    indices: np.ndarray  # (K,) indices of the accepted scans
    poses: np.ndarray  # (K, 4, 4) T_map_sensor of every accepted scan
    relative: np.ndarray  # (K-1, 4, 4) T_k_k+1: carries accepted scan k+1 into the frame of scan k
    n_matches: np.ndarray  # (K-1,) descriptor matches per step
    n_inliers: np.ndarray  # (K-1,) matches kept by MSAC (0 when it failed)
    rmse: np.ndarray  # (K-1,) m, ICP's point-to-point RMSE per step
    timings: dict[str, np.ndarray]  # ms per stage and accepted scan, (K,) each; step 0 has no match/msac/icp
    fallbacks: list[tuple[int, str]] = field(default_factory=list)  # (scan index, reason)
    checks: list = field(default_factory=list)  # (K-1,) the check that replaced each step's answer, or None
    tracked: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # (K-1,) steps tracked without features
    constraint: np.ndarray = field(
        default_factory=lambda: np.zeros(0)
    )  # (K-1,) helpers.slam.registration.icp.pairing, per step
    information: list = field(default_factory=list)  # (K-1,) 6 x 6 calibrated information per step, or None
    ungated: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # (K-1,) steps matched again ungated


class Odometry:
    """Scan-to-scan odometry, one accepted frame at a time::

        odometry = Odometry(config, T_map_first=first_pose)
        for index in accepted:
            pair = odometry.register(prepare(scans[index], config), index)  # None for the first frame
        odometry.poses[-1], odometry.result()

    It reads ``[registration]`` and ``[features]`` only; ``icp`` is the run's
    ICP service (its own when not given).
    """

    def __init__(self, config: Config, T_map_first: np.ndarray, icp: IcpService | None = None) -> None:
        self.config = config
        self.icp = icp or IcpService.from_config(config.registration, pose_graph=config.pose_graph)
        self.poses = [check_pose(T_map_first, "the first pose")]
        self.relative: list[np.ndarray] = []
        self.indices: list[int] = []
        self._pairs: list[PairRegistration] = []
        self._timings: list[dict] = []
        self.fallbacks: list[tuple[int, str]] = []
        self.blind: list[bool] = []  # per step: its motion is the last motion's, the scans pinned nothing
        self.jumped: list[bool] = []  # per step: it ended beyond the jump limits from its guess, and was kept
        self._recent: list[Frame] = []  # the last [registration] icp_local_map frames, oldest first: the previous last
        self._tracking = config.registration.mode == "tracking"

    def register(self, frame: Frame, index: int) -> PairRegistration | None:
        """Register ``frame`` (dataset scan ``index``) onto the previous frame and chain its pose."""
        with one_blas_thread():  # OpenBLAS's idle threads would spin on the core FPFH and ICP use (helpers.threads)
            return self._register(frame, index)

    def _register(self, frame: Frame, index: int) -> PairRegistration | None:
        config, recent = self.config, self._recent
        start = time.perf_counter()
        if len(recent) > 1:  # the previous frame with the last scans merged for ICP
            previous = local_map(recent, self.poses[-len(recent) :], config)
        else:
            previous = recent[-1] if recent else None
        mapped_ms = 1000.0 * (time.perf_counter() - start)
        stale = 0  # steps the guess stands on that measured nothing (see staleness)
        if config.registration.motion_guard:
            motion, stale = predicted_motion(self.relative, self.blind, self.jumped), staleness(self.blind)
        else:  # the reference's: the last step
            motion = self.relative[-1] if self.relative else None
        steps = (index - self.indices[-1]) / config.registration.skip_frames if self.indices else 1.0
        if motion is not None and steps > 1:  # scans left out (they held no point): the guess spans them too
            motion = per_period(motion, 1.0 / steps)
        timings, pair = dict.fromkeys(STAGES, 0.0), None
        timings["icp"] += mapped_ms  # the local map is made for ICP
        if previous is not None:
            # 1. Tracking: ICP from the last motion; the global registration only if that fails its checks.
            doubt = ""
            if self._tracking and motion is not None:
                pair, doubt = track_frames(frame, previous, config, motion, self.icp)
            if pair is None or doubt:
                if pair is not None:
                    log.info("scan %d: tracking doubtful (%s); registered globally", index, doubt)
                    timings["icp"] += pair.timings["icp"]
                # 2. Match, robust fit, ICP (the previous frame's descriptors, if not made yet, count here).
                described = previous.timings.get("fpfh", 0.0)
                describe(previous, config)
                timings["fpfh"] += previous.timings.get("fpfh", 0.0) - described
                pair = register_frames(
                    describe(frame, config), previous, config, guess=motion, icp=self.icp, stale=stale
                )
            for stage, ms in pair.timings.items():
                timings[stage] += ms
            if pair.fallback:
                self.fallbacks.append((int(index), pair.fallback))
                log.info("scan %d: %s", index, pair.fallback)  # counted, and summed up by helpers.quality.trust
            # 3. Chain the relative motion onto the previous pose.
            self.relative.append(pair.T_fine)
            self.blind.append(motion is not None and pair.blind(motion))
            far = motion is not None and beyond(offset(motion, pair.T_fine), config.registration, turn=1 + stale)
            self.jumped.append(bool(far))
            self.poses.append(self.poses[-1] @ pair.T_fine)
            self._pairs.append(pair)
        for stage, ms in frame.timings.items():
            timings[stage] += ms
        self._timings.append(timings)
        self.indices.append(int(index))
        self._recent = [*recent, frame][-config.registration.icp_local_map :]
        return pair

    def result(self) -> OdometryResult:
        """What the odometry estimated so far."""
        pairs = self._pairs
        return OdometryResult(
            indices=np.array(self.indices, dtype=np.int64),
            poses=np.array(self.poses[: len(self.indices)]).reshape(-1, 4, 4),
            relative=np.array(self.relative).reshape(-1, 4, 4),
            n_matches=np.array([len(p.matches) for p in pairs], dtype=np.int64),
            n_inliers=np.array([int(p.inliers.sum()) for p in pairs], dtype=np.int64),
            rmse=np.array([p.rmse for p in pairs], dtype=float),
            timings={stage: np.array([t[stage] for t in self._timings]) for stage in STAGES},
            fallbacks=list(self.fallbacks),
            checks=[p.check for p in pairs],
            tracked=np.array([p.tracked for p in pairs], dtype=bool),
            constraint=np.array([p.constraint for p in pairs], dtype=float),
            information=[p.information for p in pairs],
            ungated=np.array([p.ungated for p in pairs], dtype=bool),
        )


def local_map(recent: list[Frame], poses: list[np.ndarray], config: Config) -> Frame:
    """The last of the ``recent`` frames (oldest first), the previous scan,
    with the ICP cloud of its neighbourhood: the ICP points of all of them
    carried into its frame by their odometry ``poses`` and averaged on the ICP
    grid (``[registration] icp_grid_step``; the feature grid when it is 0).

    A scan's points lie in rows, one per ray elevation, at the same place in
    every scan's frame; over ground with little relief ICP pulls the rows of
    one scan onto those of the last, and steps come out a few per cent short
    (4 % at 250 m above Autzen, where the rows are 0.87 m apart). The rows of
    the scans before fall elsewhere: a map of several scans has none to lock
    onto. Its features stay the previous scan's (the coarse fit is scan to scan).
    """
    fit = config.registration
    to_previous = np.linalg.inv(poses[-1])
    points = np.vstack(
        [transform_points(frame.icp_points, to_previous @ pose) for frame, pose in zip(recent, poses, strict=True)]
    )
    merged = grid_average(points, config.icp_grid)
    return dataclasses.replace(recent[-1], icp_points=merged, icp=icp_cloud(merged, fit.metric, fit.icp_backend))


def predicted_motion(relative: list[np.ndarray], blind=(), jumped=(), window: int = 3) -> np.ndarray | None:
    """The constant-velocity guess for the next step: of the last ``window``
    steps (4 x 4 each), the one nearest the others (the medoid of their
    translations), or the last when fewer than three were made (None before any).

    A drone cannot change its velocity much from one scan to the next, so the
    last step is the natural guess; but one step that slid off the truth
    would then carry its error into every guess after it, and on ground too
    flat to correct it the error is kept for good (on a low flight over a
    parking lot, one 6 m mistake became 380 m). The medoid of three follows a
    steady change of speed or turn within a step and ignores one wrong step.

    ``blind`` and ``jumped`` (bools per step, or for the newest steps only):
    after a blind step (:func:`staleness`) the guess is the last step, unless
    it jumped (ended beyond the jump limits from its own guess). Blind steps
    are the momentum and the little ICP found (over a lake, the yaw of a turn
    begun): the newest of them carries the rest, and the first step measured
    after them is the freshest news of the motion; the older ones in the
    window would drag the guess back to where the flight was.
    """
    if not relative:
        return None
    last = relative[-window:]
    after_blind = len(blind) >= 2 and blind[-2] and not (jumped and jumped[-1])
    if len(last) < 3 or after_blind:
        return last[-1]
    t = np.array([step[:3, 3] for step in last])
    spread = np.linalg.norm(t[:, None] - t[None], axis=2).sum(axis=1)
    return last[len(last) - 1 - int(np.argmin(spread[::-1]))]  # on a tie (a steady flight), the newest


def staleness(blind: list[bool], window: int = 3) -> int:
    """How many steps the guess (:func:`predicted_motion` over ``window``
    steps) stands on measured nothing: the blind steps in its window, or all
    of the blind steps in a row that end the list when there are more.
    ``blind``: per step, whether its motion is the last motion's (ICP from it
    on ground too flat to move it: a lake, with no fit). Over a lake the drone
    may begin a turn nobody sees; the first step measured after it turns away
    from the guess by as much as the turn grew meanwhile."""
    in_a_row = 0
    for was_blind in reversed(blind):  # the run of blind steps that ends the list
        if not was_blind:
            break
        in_a_row += 1
    return max(in_a_row, int(sum(blind[-window:])))


def accepted_indices(n_scans: int, config: Config) -> np.ndarray:
    """The dataset indices of the accepted scans: every ``skip_frames``-th, from the first."""
    return np.arange(0, n_scans, config.registration.skip_frames)


def run_odometry(dataset_or_scans, first_pose=None, config: Config | None = None, progress=False) -> OdometryResult:
    """Odometry over the accepted scans of a Dataset (or a list of (N, 3) scans).

    ``first_pose`` (4 x 4, ``T_map_sensor``) anchors the first accepted scan;
    by default the dataset's first ground-truth pose (identity for a bare list of scans).
    """
    config = config or Config()
    scans = getattr(dataset_or_scans, "scans", dataset_or_scans)
    if first_pose is None:
        poses_gt = getattr(dataset_or_scans, "poses", None)
        first_pose = np.eye(4) if poses_gt is None else poses_gt[0]
    first_pose = np.asarray(first_pose, dtype=np.float64)
    if first_pose.shape != (4, 4):
        raise SlamError(f"the first pose must be a 4 x 4 matrix, got shape {first_pose.shape}")
    indices = accepted_indices(len(scans), config)
    if len(indices) < 2:
        raise SlamError(f"odometry needs at least 2 accepted scans, got {len(indices)} from {len(scans)} scans")
    odometry = Odometry(config, first_pose)
    bar = progress_bar(len(indices), "odometry", enabled=progress)

    def read_and_prepare(index: int) -> Frame | None:
        return prepare_scan(scans[index], index, config)

    def take(frame: Frame | None, index: int) -> None:
        if frame is not None:
            odometry.register(frame, index)
        elif index == indices[0]:
            raise empty_first_scan(index)
        # else: a scan that holds no point is left out, and the next step spans it (as Slam does)

    if not reads_ahead(config):
        for index in indices:
            take(read_and_prepare(index), index)
            bar.update(1)
    else:  # each scan read and prepared in a thread while the one before is registered (as run_slam does)
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="helpers-read-ahead") as ahead:
            upcoming = ahead.submit(read_and_prepare, indices[0])
            for k, index in enumerate(indices):
                frame = upcoming.result()
                if k + 1 < len(indices):
                    upcoming = ahead.submit(read_and_prepare, indices[k + 1])
                take(frame, index)
                bar.update(1)
    bar.close()
    return odometry.result()
