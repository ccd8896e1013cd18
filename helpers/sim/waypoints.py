"""Waypoints: the default loop, and the readers for ``.mat`` and ``.csv``.

A waypoint file gives XY (and optionally Z) in the map's *original*
coordinates and units, as the reference's ``gTruthTraj`` does; the caller
moves them into the centred, metric map frame with the map's own offset and
scale (see :func:`helpers.sim.maps.MapFrame`).
"""

from __future__ import annotations

import re
import struct
import zlib
from pathlib import Path

import numpy as np

from helpers.config.bounds import MAX_SCANS, human_size
from helpers.errors import SlamError
from helpers.paths import input_file

DEFAULT_SPACING = 2.0  # m between waypoints, as in the reference trajectory
MAX_WAYPOINTS = MAX_SCANS  # one scan each
MAT_KINDS = {"U": "text", "S": "text", "O": "a cell array or sparse matrix", "V": "a struct", "c": "complex numbers"}
# MATLAB classes by their code in a MAT-file (as scipy's whosmat names them); the numeric ones; the others in words.
MAT_CLASS_CODES = {1: "cell", 2: "struct", 3: "object", 4: "char", 5: "sparse", 6: "double", 7: "single", 8: "int8"}
MAT_CLASS_CODES |= {9: "uint8", 10: "int16", 11: "uint16", 12: "int32", 13: "uint32", 14: "int64", 15: "uint64"}
MAT_CLASS_CODES |= {16: "function_handle", 17: "opaque"}
MAT_NUMERIC = {"double", "single", *(f"{s}int{b}" for s in ("", "u") for b in (8, 16, 32, 64))}
MAT_CLASSES = {"char": "text", "cell": "a cell array or sparse matrix", "sparse": "a cell array or sparse matrix"}
MAT_CLASSES |= {"struct": "a struct", "object": "a MATLAB object", "function_handle": "a function handle"}
MAT_CLASSES |= {"complex": "complex numbers", "logical": "true/false values (a logical array), not coordinates"}
MI_MATRIX, MI_COMPRESSED = 14, 15  # MAT-file v5 data types: a matrix, a zlib-compressed element
# A CSV line of three numbers of full double precision ("-1234567.123456789012,...") takes under 100 bytes:
# a larger file holds more waypoints than a flight may have, and is refused before it is read into memory.
MAX_CSV_BYTES = 100 * MAX_WAYPOINTS
AXIS_NAME = re.compile(r"([xyz])(?:[\s_(\[].*)?")  # a waypoint CSV's column: x, y or z, then maybe a unit
MAT_HEAD_BYTES = 1024  # of a matrix element: its flags, dimensions and name (a 63-character name, 200 dimensions)


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
    ``.csv`` (x,y[,z] per line, or the columns a header names). Returns (N, 2|3)."""
    path = input_file(path, "waypoints file")
    suffix = path.suffix.lower()
    if suffix == ".mat":
        points = _read_mat(path)
    elif suffix == ".csv":
        points = _read_csv(path)
    else:
        raise SlamError(f"waypoints must be a .mat or .csv file, got {path.name}")
    _check_shape(path, points.shape)
    if not np.isfinite(points).all():
        raise SlamError(f"{path.name}: waypoints contain NaN or infinite values")
    return points


def _read_mat(path: Path) -> np.ndarray:
    """``gTruthTraj`` of a MAT-file: its class and shape are read from the
    variable's header first, so that a huge matrix (compressed zeros take
    little room on disk) is refused before its data is decompressed."""
    from scipy.io import loadmat

    try:
        headers = mat_variables(path)
        if "gTruthTraj" not in headers:
            raise SlamError(f"{path.name} has no variable gTruthTraj (it holds {sorted(headers)})")
        shape, kind = headers["gTruthTraj"]
        if kind not in MAT_NUMERIC:
            raise SlamError(
                f"{path.name}: gTruthTraj must be a matrix of real numbers, it holds {MAT_CLASSES.get(kind, kind)}"
            )
        _check_shape(path, shape)
        points = np.asarray(loadmat(path, variable_names=["gTruthTraj"])["gTruthTraj"])
    except NotImplementedError:  # MATLAB v7.3 files are HDF5
        raise SlamError(f"{path.name}: MATLAB v7.3 (HDF5) files are not supported; save with -v7") from None
    except SlamError:
        raise
    except Exception as exc:  # scipy raises several types for corrupt files
        raise SlamError(f"{path.name} is not a readable MAT-file ({exc})") from None
    if points.dtype.kind not in "biuf":
        kind = MAT_KINDS.get(points.dtype.kind, f"{points.dtype} values")
        raise SlamError(f"{path.name}: gTruthTraj must be a matrix of real numbers, it holds {kind}")
    return points.astype(np.float64)


def mat_variables(path: Path) -> dict[str, tuple[tuple[int, ...], str]]:
    """Name -> (shape, class) of every variable of a MAT-file, from the
    variables' headers alone: a compressed variable (v7) is decompressed only
    as far as its header, so this takes kilobytes of memory whatever the
    variables hold. Files other than v5/v7 go to scipy's ``whosmat``."""
    with open(path, "rb") as f:
        head = f.read(128)
        order = {b"IM": "<", b"MI": ">"}.get(head[126:128])
        if len(head) < 128 or order is None or struct.unpack(order + "H", head[124:126])[0] != 0x0100:
            from scipy.io import whosmat

            return {name: (tuple(shape), kind) for name, shape, kind in whosmat(path)}
        end, at, variables = f.seek(0, 2), 128, {}
        while at + 8 <= end:
            f.seek(at)
            tag = f.read(8)
            kind, nbytes = struct.unpack(order + "II", tag)
            if kind == MI_COMPRESSED:
                element, at = _inflate_start(f, nbytes), at + 8 + nbytes
            else:
                element, at = tag + f.read(min(nbytes, MAT_HEAD_BYTES)), at + 8 + nbytes + (-nbytes % 8)
            name, shape, mclass = _matrix_header(element, order)
            variables[name] = (shape, mclass)
    return variables


def _inflate_start(f, nbytes: int) -> bytes:
    """The first :data:`MAT_HEAD_BYTES` of the zlib stream of ``nbytes`` at the file's position."""
    inflater, out, left, pending = zlib.decompressobj(), b"", nbytes, b""
    while len(out) < MAT_HEAD_BYTES and not inflater.eof:
        if not pending:
            pending = f.read(min(4096, left))
            left -= len(pending)
            if not pending:
                break
        out += inflater.decompress(pending, MAT_HEAD_BYTES - len(out))  # never more than the header asks
        pending = inflater.unconsumed_tail
    return out


def _matrix_header(element: bytes, order: str) -> tuple[str, tuple[int, ...], str]:
    """(name, shape, class) from the start of a MAT v5 matrix element: its
    tag, then three sub-elements (array flags, dimensions, name), each a tag
    and data padded to 8 bytes, or a small element (size and type in one
    word, up to 4 bytes of data in the next)."""
    kind, _ = struct.unpack_from(order + "II", element)
    if kind != MI_MATRIX:
        raise ValueError(f"a variable of data type {kind}, not a matrix")
    at, parts = 8, []
    for _ in range(3):
        (word,) = struct.unpack_from(order + "I", element, at)
        if word >> 16:  # a small data element
            size, data_at, at = word >> 16, at + 4, at + 8
        else:
            size = struct.unpack_from(order + "I", element, at + 4)[0]
            data_at, at = at + 8, at + 8 + size + (-size % 8)
        if data_at + size > len(element):
            raise ValueError("a variable header runs past its data")
        parts.append(element[data_at : data_at + size])
    flags, dims, name = parts
    (flag_word,) = struct.unpack_from(order + "I", flags)
    mclass = "logical" if flag_word & 0x0200 else MAT_CLASS_CODES.get(flag_word & 0xFF, "unknown")
    if flag_word & 0x0800 and mclass in MAT_NUMERIC:  # complex
        mclass = "complex"
    shape = struct.unpack(order + f"{len(dims) // 4}i", dims[: len(dims) // 4 * 4])
    return name.decode("latin1"), shape, mclass


def _read_csv(path: Path) -> np.ndarray:
    """Rows of numbers separated by commas, or by semicolons; a first row that holds no number is a header
    naming the columns x, y and optionally z, in any order and any case (no header: x,y[,z] in that order).
    Any other row that is not numbers is an error naming its line: none is dropped."""
    size = path.stat().st_size
    if size > MAX_CSV_BYTES:
        raise SlamError(
            f"{path.name} is {human_size(size)}, more than {MAX_WAYPOINTS:,} waypoints (one scan each) take; "
            f"the limit is {human_size(MAX_CSV_BYTES)}"
        )
    text = path.read_text(encoding="utf-8-sig", errors="replace")  # utf-8-sig: a byte-order mark is not data
    lines = [(number, line.strip()) for number, line in enumerate(text.splitlines(), 1) if line.strip()]
    separator = ";" if lines and ";" in lines[0][1] and "," not in lines[0][1] else ","
    order = None
    if lines and not any(_is_number(cell) for cell in lines[0][1].split(separator)):
        order = _header_order(path, lines[0][1].split(separator))  # a header such as "x,y,z" or "Y;X"
        lines = lines[1:]
    if not lines:
        return np.empty((0, 2))
    _check_count(path, len(lines))
    rows = []
    for number, line in lines:
        try:
            rows.append([_number(v) for v in line.split(separator)])
        except ValueError:
            raise SlamError(
                f"{path.name} line {number}: every line must be x,y or x,y,z numbers (separated by "
                f"{'semicolons' if separator == ';' else 'commas'}), got {line[:40]!r}"
            ) from None
    if len({len(r) for r in rows} | ({len(order)} if order else set())) > 1:
        raise SlamError(f"{path.name}: lines have different numbers of columns")
    points = np.array(rows, dtype=np.float64).reshape(len(rows), -1)
    return points if order is None else points[:, order]


def _header_order(path: Path, names: list[str]) -> list[int]:
    """The columns of x, y and z (when named) from a header's names: any case, quotes and spaces aside, and a
    unit after the letter allowed ("x_m", "X (ft)")."""
    found = [name.strip().strip("\"'").strip() for name in names]
    keys = [axis.group(1) if (axis := AXIS_NAME.fullmatch(name.lower())) else name for name in found]
    if sorted(keys) not in (["x", "y"], ["x", "y", "z"]):
        raise SlamError(
            f"{path.name}: the header names the columns {', '.join(repr(n) for n in found)}; a waypoint CSV's "
            "header names x and y, and optionally z (in any order and any case), or the file has no header "
            "and its columns are x,y[,z]"
        )
    return [keys.index(axis) for axis in ("x", "y", "z") if axis in keys]


def _check_shape(path: Path, shape: tuple[int, ...]) -> None:
    if 0 in shape:
        raise SlamError(f"{path.name} holds no waypoints")
    if len(shape) != 2 or shape[1] not in (2, 3):
        raise SlamError(f"{path.name}: expected an N x 2 or N x 3 array of waypoints, got shape {tuple(shape)}")
    _check_count(path, shape[0])


def _check_count(path: Path, n: int) -> None:
    if n > MAX_WAYPOINTS:
        raise SlamError(f"{path.name} holds {n:,} waypoints; the limit is {MAX_WAYPOINTS:,} (one scan each)")


def _number(text: str) -> float:
    """A CSV number. Python's float also reads "1_000" as 1000, which no
    other program writes or reads so: such a cell is an error, not a value."""
    if "_" in text:
        raise ValueError(f"not a number: {text!r}")
    return float(text)


def _is_number(text: str) -> bool:
    try:
        _number(text)
    except ValueError:
        return False
    return True
