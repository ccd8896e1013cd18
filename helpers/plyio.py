"""Point clouds as binary PLY files, written straight from numpy (much
faster than a per-value writer for millions of points). Any PLY reader,
Open3D's included, opens them; :func:`read_ply` reads back what
:func:`write_ply` wrote."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import SlamError

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


def read_ply(path: str | Path) -> np.ndarray:
    """Read the (N, 3) points of a file written by :func:`write_ply`."""
    with open(path, "rb") as src:
        lines = []
        while (line := src.readline()) and line.strip() != b"end_header":
            lines.append(line.decode("ascii", "replace").split())
        body = src.read()
    try:
        count = int(next(w[2] for w in lines if w[:2] == ["element", "vertex"]))
        kinds = [w[1] for w in lines if w[0] == "property"]
        dtype = {"float": "<f4", "double": "<f8"}[kinds[0]]
    except (StopIteration, KeyError, IndexError, ValueError):
        raise SlamError(f"{path} is not a PLY file of x y z points") from None
    if lines[:2] != [["ply"], ["format", "binary_little_endian", "1.0"]] or len(kinds) != 3:
        raise SlamError(f"{path} is not a binary x y z PLY file as this package writes them")
    return np.frombuffer(body, dtype=dtype, count=3 * count).reshape(count, 3).astype(np.float64)
