"""Point clouds as binary PLY files, written straight from numpy (much
faster than a per-value writer for millions of points). Any PLY reader
opens them; Open3D's tensor reader (``open3d.t.io.read_point_cloud``) reads
them back exactly, float32 or float64."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helpers.errors import SlamError

_TYPES = {np.dtype("<f4"): "float", np.dtype("<f8"): "double"}


def write_ply(path: str | Path, points: np.ndarray) -> None:
    """Write (N, 3) points as ``x y z``, keeping float32 or float64."""
    points = np.ascontiguousarray(points)
    dtype = points.dtype.newbyteorder("<")
    if dtype not in _TYPES or points.ndim != 2 or points.shape[1] != 3:
        raise SlamError(f"write_ply takes (N, 3) float32 or float64 points, got {points.dtype} {points.shape}")
    kind = _TYPES[dtype]
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(points)}\n"
        f"property {kind} x\nproperty {kind} y\nproperty {kind} z\nend_header\n"
    )
    with open(path, "wb") as out:
        out.write(header.encode("ascii"))
        out.write(points.astype(dtype, copy=False).tobytes())
