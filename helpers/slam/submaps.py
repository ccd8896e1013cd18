"""Submaps: groups of accepted scans merged into one cloud (stage 4, the
reference's ``pcalign`` on ``nScansPerSubmap`` scans at a time).

Accepted scans are numbered 0, 1, 2, ... in the order they arrive (they are
also the pose-graph nodes). Submap ``k`` holds scans ``k*n .. k*n + n - 1``
for ``n`` scans per submap; it is built when its last scan arrives. Its pose
is the pose of its centre scan, scan ``k*n + n - 1 - n // 2`` (the reference
takes scan ``count - floor(n/2)`` of a group that ends at ``count``, counting
from 1), and its centre is that pose's position.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from helpers.errors import SlamError
from helpers.geometry import check_points, check_pose, transform_points
from helpers.slam.registration.features import grid_average


@dataclass(frozen=True)
class Submap:
    """One submap: its id, the accepted scans it holds, its points (map frame) and pose."""

    id: int
    scan_ids: tuple[int, ...]
    points: np.ndarray  # (M, 3), map frame
    pose: np.ndarray  # (4, 4), the centre scan's pose

    @property
    def centre(self) -> np.ndarray:
        return self.pose[:3, 3]


def build_submap(scans, poses, align_grid_step: float) -> np.ndarray:
    """Move every scan by its pose, merge them, and keep one point per grid cell.

    ``scans`` are (N_i, 3) arrays in their own frames, ``poses`` the matching
    4 x 4 transforms to the map frame. Each occupied cubic cell of side
    ``align_grid_step`` (m) keeps the mean of its points (as
    :func:`helpers.slam.registration.features.grid_average`); the output is (M, 3), map frame.
    """
    poses = np.asarray(poses, dtype=float)
    if len(scans) == 0 or len(scans) != len(poses):
        raise SlamError(
            f"build_submap needs one pose per scan and at least one scan, got {len(scans)} and {len(poses)}"
        )
    moved = []
    for k, (scan, pose) in enumerate(zip(scans, poses, strict=True)):
        points = check_points(scan, f"scan {k} of the submap")
        pose = check_pose(pose, f"the pose of scan {k} of the submap")
        moved.append(transform_points(points, pose))
    return grid_average(np.concatenate(moved), align_grid_step)


def scan_ids_of(submap_id: int, n_scans_per_submap: int) -> tuple[int, ...]:
    """The accepted-scan ids merged into submap ``submap_id``."""
    start = submap_id * n_scans_per_submap
    return tuple(range(start, start + n_scans_per_submap))


def centre_scan_id(submap_id: int, n_scans_per_submap: int) -> int:
    """The scan whose pose is the submap's pose (the reference's ``count - floor(n/2)``)."""
    return submap_id * n_scans_per_submap + n_scans_per_submap - 1 - n_scans_per_submap // 2


class SubmapIndex:
    """Builds a submap every ``n_scans_per_submap`` accepted scans, as they arrive.

    For example::

        index = SubmapIndex(n_scans_per_submap=3, align_grid_step=1.2)
        for scan, pose in zip(scans, poses):
            new = index.add_scan(scan, pose)  # a Submap on every 3rd scan, else None
        index.points, index.centres  # the clouds, and (K, 3) centres
    """

    def __init__(self, n_scans_per_submap: int, align_grid_step: float) -> None:
        if int(n_scans_per_submap) != n_scans_per_submap or n_scans_per_submap < 1:
            raise SlamError(f"n_scans_per_submap must be an integer of at least 1, got {n_scans_per_submap!r}")
        if not (np.isfinite(align_grid_step) and align_grid_step > 0):
            raise SlamError(f"align_grid_step must be a positive number of metres, got {align_grid_step!r}")
        self.n_scans_per_submap = int(n_scans_per_submap)
        self.align_grid_step = float(align_grid_step)
        self.submaps: list[Submap] = []
        self.num_scans = 0
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []

    def __len__(self) -> int:
        return len(self.submaps)

    def add_scan(self, points: np.ndarray, pose: np.ndarray) -> Submap | None:
        """Take the next accepted scan; return the new submap if this scan completes one."""
        what = f"accepted scan {self.num_scans}"
        self._pending.append((check_points(points, what), check_pose(pose, f"the pose of {what}")))
        self.num_scans += 1
        if len(self._pending) < self.n_scans_per_submap:
            return None
        scans, poses = zip(*self._pending, strict=True)
        self._pending = []
        k = len(self.submaps)
        cloud = build_submap(scans, poses, self.align_grid_step)
        centre = centre_scan_id(k, self.n_scans_per_submap) - k * self.n_scans_per_submap
        self.submaps.append(Submap(k, scan_ids_of(k, self.n_scans_per_submap), cloud, np.array(poses[centre], float)))
        return self.submaps[-1]

    @property
    def points(self) -> list[np.ndarray]:
        """The (M_k, 3) clouds, one per submap."""
        return [s.points for s in self.submaps]

    @property
    def centres(self) -> np.ndarray:
        """(K, 3) centre positions, one row per submap."""
        return np.array([s.centre for s in self.submaps]).reshape(-1, 3)
