"""Waypoints: the default loop, and the readers for ``.mat`` and ``.csv``.

A waypoint file gives XY (and optionally Z) in the map's *original*
coordinates and units, as the reference's ``gTruthTraj`` does; the caller
moves them into the centred, metric map frame with the map's own offset and
scale (see :func:`helpers.mapio.MapFrame`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import SlamError

DEFAULT_SPACING = 2.0  # m between waypoints, as in the reference trajectory
MAX_WAYPOINTS = 1_000_000  # one scan each: 1450 times the default flight
MAT_KINDS = {"U": "text", "S": "text", "O": "a cell array or sparse matrix", "V": "a struct", "c": "complex numbers"}


def loop_waypoints(
    half_x: float = 220.0,
    half_y: float = 120.0,
    corner: float = 60.0,
    spacing: float = DEFAULT_SPACING,
    overlap: float = 120.0,
) -> np.ndarray:
    """A counter-clockwise rounded-rectangle loop centred on (0, 0), (N, 2).

    It starts in the middle of the bottom side heading +x, goes once round
    and flies on ``overlap`` metres over its own start, so that the end of
    the flight revisits the beginning (where loop closures can happen).
    """
    if not (0 < corner <= min(half_x, half_y)):
        raise SlamError("the loop's corner radius must be positive and fit inside the rectangle")
    # The outline, piece by piece, then resampled at equal arc length.
    ax, ay = half_x - corner, half_y - corner
    pieces = [np.array([[0.0, -half_y]])]
    for (cx, cy), a0 in zip([(ax, -ay), (ax, ay), (-ax, ay), (-ax, -ay)], [-90, 0, 90, 180], strict=True):
        a = np.radians(np.linspace(a0, a0 + 90, 181))
        pieces.append(np.column_stack([cx + corner * np.cos(a), cy + corner * np.sin(a)]))
    pieces.append(np.array([[0.0, -half_y]]))
    outline = np.vstack(pieces)
    seg = np.hypot(*np.diff(outline, axis=0).T)
    s = np.r_[0.0, np.cumsum(seg)]
    perimeter = s[-1]
    stations = np.arange(0.0, perimeter + overlap + 1e-9, spacing)
    wrapped = stations % perimeter
    return np.column_stack([np.interp(wrapped, s, outline[:, 0]), np.interp(wrapped, s, outline[:, 1])])


def read_waypoints(path: str | Path) -> np.ndarray:
    """Read waypoints from ``.mat`` (``gTruthTraj``, N x 2 or N x 3) or
    ``.csv`` (x,y[,z] per line, an optional header line). Returns (N, 2|3)."""
    path = Path(path)
    if not path.is_file():
        raise SlamError(f"waypoints file not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".mat":
        points = _read_mat(path)
    elif suffix == ".csv":
        points = _read_csv(path)
    else:
        raise SlamError(f"waypoints must be a .mat or .csv file, got {path.name}")
    if points.size == 0:
        raise SlamError(f"{path.name} holds no waypoints")
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise SlamError(f"{path.name}: expected an N x 2 or N x 3 array of waypoints, got shape {points.shape}")
    _check_count(path, len(points))
    if not np.isfinite(points).all():
        raise SlamError(f"{path.name}: waypoints contain NaN or infinite values")
    return points


def _read_mat(path: Path) -> np.ndarray:
    from scipy.io import loadmat

    try:
        data = loadmat(path)
    except NotImplementedError:  # MATLAB v7.3 files are HDF5
        raise SlamError(f"{path.name}: MATLAB v7.3 (HDF5) files are not supported; save with -v7") from None
    except Exception as exc:  # scipy raises several types for corrupt files
        raise SlamError(f"{path.name} is not a readable MAT-file ({exc})") from None
    if "gTruthTraj" not in data:
        names = sorted(k for k in data if not k.startswith("__"))
        raise SlamError(f"{path.name} has no variable gTruthTraj (it holds {names})")
    points = np.asarray(data["gTruthTraj"])
    if points.dtype.kind not in "biuf":
        kind = MAT_KINDS.get(points.dtype.kind, f"{points.dtype} values")
        raise SlamError(f"{path.name}: gTruthTraj must be a matrix of real numbers, it holds {kind}")
    return points.astype(np.float64)


def _read_csv(path: Path) -> np.ndarray:
    lines = [line.strip() for line in path.read_text(errors="replace").splitlines() if line.strip()]
    if lines and not _is_number(lines[0].split(",")[0]):
        lines = lines[1:]  # a header such as "x,y,z"
    if not lines:
        return np.empty((0, 2))
    _check_count(path, len(lines))
    try:
        rows = [[float(v) for v in line.split(",")] for line in lines]
    except ValueError:
        raise SlamError(f"{path.name}: every line must be x,y or x,y,z numbers") from None
    if len({len(r) for r in rows}) > 1:
        raise SlamError(f"{path.name}: lines have different numbers of columns")
    return np.array(rows, dtype=np.float64).reshape(len(rows), -1)


def _check_count(path: Path, n: int) -> None:
    if n > MAX_WAYPOINTS:
        raise SlamError(f"{path.name} holds {n:,} waypoints; the limit is {MAX_WAYPOINTS:,} (one scan each)")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
