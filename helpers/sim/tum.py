"""Poses as 4 x 4 matrices, and trajectories in the TUM text format
(``stamp tx ty tz qx qy qz qw``, one pose a line, scalar-last quaternion)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from helpers.errors import SlamError


def to_tum(poses: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses -> (N, 7) rows ``tx ty tz qx qy qz qw`` with qw >= 0."""
    quat = Rotation.from_matrix(poses[:, :3, :3]).as_quat()  # x, y, z, w
    quat *= np.where(quat[:, 3:] < 0, -1.0, 1.0)
    return np.column_stack([poses[:, :3, 3], quat])


def from_tum(rows: np.ndarray) -> np.ndarray:
    """(N, 7) rows ``tx ty tz qx qy qz qw`` -> (N, 4, 4) poses."""
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(rows[:, 3:7]).as_matrix()
    poses[:, :3, 3] = rows[:, :3]
    return poses


def write_tum(path: str | Path, poses: np.ndarray, stamps=None) -> None:
    stamps = np.arange(len(poses)) if stamps is None else np.asarray(stamps)
    rows = np.column_stack([stamps, to_tum(poses)])
    np.savetxt(path, rows, fmt=["%d"] + ["%.6f"] * 3 + ["%.9f"] * 4)


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """-> (stamps (N,), poses (N, 4, 4))."""
    try:
        rows = np.loadtxt(path, ndmin=2)
    except (OSError, ValueError) as exc:
        raise SlamError(f"cannot read TUM trajectory {path}: {exc}") from None
    if rows.shape[1] != 8:
        raise SlamError(f"{path}: a TUM line has 8 numbers, found {rows.shape[1]}")
    return rows[:, 0], from_tum(rows[:, 1:])
