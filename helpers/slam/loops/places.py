"""Place recognition (stage 5, after a blind stretch): which old submap the
current scan shows, found from its descriptors alone, not from where the
odometry puts the flight.

Over water or a bare field the odometry measures nothing and follows the last
motion; a turn begun there goes unseen, and the flight comes back over old
ground tens of metres and degrees from where the odometry (and the loop
search's graph, built on it) puts it. The loop search looks around that place
and finds nothing: on the sparse tile of scene seed 5 at 150 m, 22 blind steps
missed 56 degrees of a turn, the second lap came back 160 m off, and no loop
closed.

So after :data:`BLIND_RUN_STEPS` steps in a row fell
back, and until the loop search closes a loop on its own again, a query
that closed none also asks the descriptors (``[loop_closure]
place_recognition``; every second submap's worth of nodes, every submap's
while a recognition waits to be confirmed):

1. each FPFH descriptor of the scan votes for the old submap whose centre
   scan holds its nearest descriptor, if that neighbour passes the ratio test
   (``[features] match_ratio``);
2. the submaps with the most votes (at least :data:`MIN_VOTES`, at most
   ``max_attempts``) are registered, scan to centre scan, by the odometry's
   own descriptor matching and robust fit, with no guess;
3. each robust fit that succeeds gives the scan's pose in that submap's
   frame, and the loop closer refines and checks the submap from there as it
   checks any candidate (ICP, submap RMSE, best scan, constraint).

Ground that repeats, or is flat enough to fit anywhere, can be recognised in
the wrong place, and nothing else guards such a loop: the search's gate is
what keeps ordinary candidates near. On Autzen at 200 m three recognitions
on the first lap passed every check a loop must (ICP RMSE, best scan,
constraint) 47-111 m from where the scan truly was. So a recognition becomes
a loop only when the recognition before it, at most :data:`CONFIRM_NODES`
nodes earlier, put the flight in the same place: the correction each implies
(the map transform that carries the scan's odometry pose to where the
recognised submap puts it) agrees within :data:`AGREE_M` and
:data:`AGREE_DEG`; those three found none that did. Once loops join the
second lap to the first, the pose graph bends the trajectory at the blind
steps, whose information says they pinned little.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.slam.preprocess import Frame, describe
from helpers.slam.registration.matching import match_features
from helpers.slam.registration.robust_fit import robust_fit
from helpers.slam.submaps import centre_scan_id
from helpers.threads import threads

log = logging.getLogger(__name__)

MIN_VOTES = 6  # descriptors that must vote for a submap: the robust fit needs as many inliers at the least
MAX_QUERY_DESCRIPTORS = 600  # descriptors of the scan that vote (evenly strided): the vote's time stays ~0.1-0.5 s
MAX_STORED_DESCRIPTORS = 1200  # ... of each centre scan kept: on the sparse tile's true places 20-300 votes won
CONFIRM_NODES = 12  # a recognition is confirmed by one at most this many nodes before it ...
AGREE_M, AGREE_DEG = 2.0, 2.0  # ... that puts the flight within this of the same place (the odometry drifts
# centimetres over a dozen steps, a recognition is off by a few; a place recognised wrongly lies metres away)

BLIND_RUN_STEPS = 5  # steps in a row that fell back to the last motion: a turn begun there goes unseen


class _Centre(NamedTuple):
    """A submap's centre scan as place recognition keeps it."""

    points: np.ndarray  # (N, 3), the feature grid's
    described: np.ndarray | None  # indices of the points with descriptors (None: not described yet)
    descriptors: np.ndarray | None  # (K, 33)
    voters: np.ndarray | None  # float32, at most MAX_STORED_DESCRIPTORS of the descriptors: what the vote searches


def _centre(points, described, descriptors) -> _Centre:
    """A :class:`_Centre`, its voters strided from ``descriptors`` once (None while undescribed)."""
    voters = None if descriptors is None else _strided(descriptors, MAX_STORED_DESCRIPTORS)
    return _Centre(points, described, descriptors, voters)


class PlaceRecognition:
    """The descriptors of each submap's centre scan, and the blind-stretch state that turns the search on.

    The run (:class:`helpers.slam.slam.Slam`) hands it every accepted scan's frame with :meth:`follow`; the loop
    closer asks :meth:`recognise` while :attr:`lost` and tells it :meth:`closed` when its own search closed a
    loop."""

    def __init__(self, config: Config) -> None:
        self.config = config
        self.n = config.map.n_scans_per_submap
        self.places: dict[int, _Centre] = {}  # submap id -> its centre scan
        self.blind = 0  # steps in a row that fell back
        self.lost = False
        self.last: tuple[int, np.ndarray] | None = None  # (node, correction) of the last recognition
        self.asked = -(10**9)  # the node that asked last

    def follow(self, node: int, frame, fell_back: bool) -> None:
        """Accepted scan ``node``'s frame (a :class:`helpers.slam.preprocess.Frame`, or a function that makes it:
        called only if needed), and whether its odometry step fell back."""
        self.blind = self.blind + 1 if fell_back else 0
        if self.blind >= BLIND_RUN_STEPS and not self.lost:
            log.info("node %d: %d steps in a row fell back; the loop search recognises places", node, self.blind)
            self.lost = True
        self._current, self._made = frame, None
        if node == centre_scan_id(node // self.n, self.n):  # its descriptors, if made; else made when first asked
            frame = frame if isinstance(frame, Frame) else self.current()
            described = None if frame.features is None else frame.described()
            self.places[node // self.n] = _centre(frame.points, described, frame.features)

    def current(self) -> Frame:
        """The frame of the scan followed last, described."""
        if self._made is None:
            self._made = _described(self._current() if callable(self._current) else self._current, self.config)
        return self._made

    def closed(self) -> None:
        """The loop search closed a loop where the graph put the flight: it knows where it is again."""
        self.lost, self.last = False, None

    def vote(self, frame: Frame, eligible: int) -> list[tuple[int, int]]:
        """(submap id, votes) of the eligible submaps (ids below ``eligible``) with the most votes from
        ``frame``'s descriptors, most first, at least :data:`MIN_VOTES` each."""
        ids = [k for k in range(eligible) if k in self.places]
        if not ids:
            return []
        stored = [self._place(k).voters for k in ids]
        owner = np.repeat(np.asarray(ids), [len(f) for f in stored])
        query = _strided(_described(frame, self.config).features, MAX_QUERY_DESCRIPTORS)
        if len(owner) < 2 or not len(query):
            return []
        distance, index = cKDTree(np.vstack(stored)).query(query, k=2, workers=threads())
        passed = distance[:, 0] < self.config.features.match_ratio * distance[:, 1]
        votes = np.bincount(owner[index[passed, 0]], minlength=eligible)
        best = np.argsort(-votes, kind="stable")[: self.config.loop_closure.max_attempts]
        return [(int(k), int(votes[k])) for k in best if votes[k] >= MIN_VOTES]

    def recognise(self, node: int, poses, eligible: int) -> tuple[np.ndarray, np.ndarray]:
        """The submaps (ids, best voted first) the current scan (node ``node``) is recognised in, and for each
        the scan's pose in that submap's frame (``poses``: those the submaps were built with): its descriptors
        matched with the centre scan's and the odometry's robust fit, no guess (a fit that fails is left out;
        the loop closer's ICP refines and checks the rest). At most once every ``2 n_scans_per_submap`` nodes
        (two submaps' worth of new ground: a place seen from the next scan is seen again), and every
        ``n_scans_per_submap`` while a recognition waits to be confirmed."""
        waiting = self.last is not None and node - self.last[0] < CONFIRM_NODES
        if node - self.asked < (self.n if waiting else 2 * self.n):
            return np.zeros(0, dtype=int), np.zeros((0, 4, 4))
        self.asked, current, features = node, self.current(), self.config.features
        ids, starts = [], []
        for submap_id, votes in self.vote(current, eligible):
            points, described, descriptors, _ = self._place(submap_id)
            matches = match_features(current.features, descriptors, features.match_threshold, features.match_ratio)
            on_current, on_centre = current.described()[matches[:, 0]], described[matches[:, 1]]
            try:
                T, inliers = robust_fit(current.points[on_current], points[on_centre], self.config.registration)
            except SlamError as exc:
                log.info("node %d: submap %d (%d votes) not recognised: %s", node, submap_id, votes, exc)
                continue
            log.info("node %d: submap %d recognised (%d votes, %d inliers)", node, submap_id, votes, inliers.sum())
            ids.append(submap_id)
            starts.append(np.asarray(poses[centre_scan_id(submap_id, self.n)], dtype=float) @ T)
        return np.asarray(ids, dtype=int), np.asarray(starts, dtype=float).reshape(-1, 4, 4)

    def _place(self, submap_id: int) -> _Centre:
        """Submap ``submap_id``'s centre scan, described once."""
        centre = self.places[submap_id]
        if centre.descriptors is None:  # a tracking run described it only if the odometry needed it
            frame = describe(Frame(centre.points, None, centre.points[:0], {}), self.config)
            self.places[submap_id] = _centre(centre.points, frame.described(), frame.features)
        return self.places[submap_id]

    def confirmed(self, node: int, pose: np.ndarray, start: np.ndarray) -> bool:
        """Whether the recognition that puts the scan at ``start`` (its odometry ``pose``) agrees with the
        one before it (see the module); it becomes the one the next is compared with."""
        correction = np.asarray(start, dtype=float) @ np.linalg.inv(np.asarray(pose, dtype=float))
        last, self.last = self.last, (node, correction)
        if last is None or node - last[0] > CONFIRM_NODES:
            return False
        apart = np.linalg.inv(last[1]) @ correction
        here = np.append(np.asarray(pose, dtype=float)[:3, 3], 1.0)
        shift = float(np.linalg.norm((correction @ here - last[1] @ here)[:3]))
        turn = float(np.degrees(np.arccos(np.clip((np.trace(apart[:3, :3]) - 1) / 2, -1.0, 1.0))))
        return shift <= AGREE_M and turn <= AGREE_DEG


def _described(frame: Frame, config: Config) -> Frame:
    """``frame`` with its descriptors (a tracking run describes a scan only when it must)."""
    return frame if frame.features is not None else describe(frame, config)


def _strided(features: np.ndarray, most: int) -> np.ndarray:
    """At most ``most`` of ``features``' rows, evenly strided (deterministic)."""
    step = max(1, -(-len(features) // most))
    return np.asarray(features[::step], dtype=np.float32)
