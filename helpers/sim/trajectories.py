"""Poses as 4 x 4 matrices, and trajectories as text: the TUM format
(``stamp tx ty tz qx qy qz qw``, one pose a line, scalar-last quaternion), the
KITTI format (the 3 x 4 of each pose, 12 numbers a line) and a CSV of
``index,x,y,z,roll,pitch,yaw`` for spreadsheets and GIS tools."""

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
    rows = _rows(path, 8, "TUM trajectory", "a TUM line")
    return rows[:, 0], from_tum(rows[:, 1:])


def write_kitti(path: str | Path, poses: np.ndarray) -> None:
    """Write (N, 4, 4) poses in the KITTI format: one pose a line, the first three rows of its matrix
    row by row (``r11 r12 r13 tx r21 ... tz``), in the poses' own frame and metres (for a run, its
    map frame). KITTI lines carry no stamp: line ``k`` is the ``k``-th pose (the TUM and CSV files
    name each pose's scan)."""
    poses = np.asarray(poses, np.float64)
    np.savetxt(path, poses[:, :3, :].reshape(len(poses), 12), fmt="%.10e")


def read_kitti(path: str | Path) -> np.ndarray:
    """KITTI poses (12 numbers a line) -> (N, 4, 4)."""
    rows = _rows(path, 12, "KITTI poses", "a KITTI pose line")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = rows.reshape(-1, 3, 4)
    return poses


def _rows(path: str | Path, width: int, what: str, line: str) -> np.ndarray:
    """The numbers of a text file of poses, ``width`` a line; a :class:`SlamError` naming ``what`` otherwise."""
    try:
        rows = np.loadtxt(path, ndmin=2)
    except (OSError, ValueError) as exc:
        raise SlamError(f"cannot read {what} {path}: {exc}") from None
    if rows.shape[1] != width:
        raise SlamError(f"{path}: {line} has {width} numbers, found {rows.shape[1]}")
    return rows


CSV_HEADER = "index,x,y,z,roll,pitch,yaw"


def to_xyz_rpy(poses: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses -> (N, 6) ``x y z roll pitch yaw``, angles in degrees, the rotation
    ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``: intrinsic Z-Y'-X'' (yaw, then pitch, then roll), the
    aerospace convention, roll and yaw in (-180, 180], pitch in [-90, 90]."""
    yaw_pitch_roll = Rotation.from_matrix(np.asarray(poses)[:, :3, :3]).as_euler("ZYX", degrees=True)
    return np.column_stack([np.asarray(poses)[:, :3, 3], yaw_pitch_roll[:, ::-1]])


def write_pose_csv(path: str | Path, poses: np.ndarray, indices=None) -> None:
    """Write (N, 4, 4) poses as a CSV with the header ``index,x,y,z,roll,pitch,yaw``: ``index`` the
    scan's (``indices``, default 0 to N-1), ``x y z`` in metres in the poses' own frame (for a run,
    its map frame), roll, pitch and yaw in degrees as :func:`to_xyz_rpy` defines them (ZYX intrinsic)."""
    indices = np.arange(len(poses)) if indices is None else np.asarray(indices)
    rows = np.column_stack([indices, to_xyz_rpy(poses)])
    np.savetxt(path, rows, fmt=["%d"] + ["%.6f"] * 6, delimiter=",", header=CSV_HEADER, comments="")
