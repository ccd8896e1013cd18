"""A folder of lidar scans in the sensor frame, one file per scan, read one at a time.

Formats (one per folder): PLY (ASCII or binary), PCD (ASCII or binary), LAS/LAZ (laspy, the file checked first
by :func:`helpers.sim.las.check_las_file`), NumPy ``.npy`` (N x 3 or more columns, x y z first) and KITTI ``.bin``
(float32 x y z intensity). Files come in natural name order (``scan2`` before ``scan10``). Per-point times are
read where a format has them (LAS ``gps_time``; a PLY/PCD ``time``, ``t`` or ``timestamp`` field) and kept
beside the points (:meth:`ScanFolder.read`); nothing uses them yet (the deskew is another issue).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from helpers.errors import SlamError

log = logging.getLogger(__name__)

FORMATS = {".ply": "PLY", ".pcd": "PCD", ".las": "LAS/LAZ", ".laz": "LAS/LAZ", ".npy": "NumPy", ".bin": "KITTI"}
TIME_FIELDS = ("time", "t", "timestamp", "gps_time")
WORLD_FRAME_M = 10_000.0  # a scan whose median point lies this far from its origin is in a world frame
FIRST_SCANS = 5  # scans read before any work to check the frame (and to measure the height)
MAX_SKIPPED = 0.05  # more than this share of unreadable or empty scans is an error
# What a damaged file makes the readers raise (numpy's and ours on a bad header or body): such a scan is skipped.
READ_ERRORS = (SlamError, OSError, ValueError, EOFError, IndexError, KeyError, TypeError)
_PLY_TYPES = {
    **dict.fromkeys(("char", "int8"), "i1"),
    **dict.fromkeys(("uchar", "uint8"), "u1"),
    **dict.fromkeys(("short", "int16"), "i2"),
    **dict.fromkeys(("ushort", "uint16"), "u2"),
    **dict.fromkeys(("int", "int32"), "i4"),
    **dict.fromkeys(("uint", "uint32"), "u4"),
    **dict.fromkeys(("float", "float32"), "f4"),
    **dict.fromkeys(("double", "float64"), "f8"),
}


def natural_key(name: str) -> list:
    """Sort key of a file name with its digit runs as numbers: ``scan2`` before ``scan10``."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


@dataclass
class ScanFolder(Sequence):
    """The scans of a folder as a sequence: ``folder[i]`` reads file ``files[kept[i]]`` and returns its finite
    points (N, 3); nothing else is held in memory. :meth:`survey` drops the unreadable and empty files."""

    root: Path
    files: list[Path]
    format: str
    kept: list[int] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    nonfinite: int = 0  # points dropped for a NaN or infinite coordinate (counted by survey)
    has_times: bool = False  # some scan carries per-point times

    def __post_init__(self):
        self.kept = self.kept or list(range(len(self.files)))
        self._times_of, self._times = None, None  # the scan read last and its per-point times

    def __len__(self) -> int:
        return len(self.kept)

    def __getitem__(self, index: int) -> np.ndarray:
        points, self._times = self.read(index)  # kept for times(index): the scan read last, not re-read
        self._times_of = index
        return points

    def times(self, index: int) -> np.ndarray | None:
        """Scan ``index``'s per-point times (None without): the scan read last, or read again."""
        if self._times_of == index:
            return self._times
        return self.read(index)[1]

    def read(self, index: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Scan ``index``'s finite points (N, 3, float64) and their per-point times (N,), or None where the file
        has none."""
        points, times = read_scan(self.files[self.kept[index]])
        points = np.asarray(points, dtype=np.float64)  # the estimator's type; float32 files convert exactly
        finite = np.isfinite(points).all(axis=1)
        if finite.all():
            return points, times
        return points[finite], None if times is None else times[finite]

    def survey(self, progress=None) -> None:
        """Read every file once: an unreadable or empty one is skipped with one warning naming it, NaN or
        infinite points are counted; more than :data:`MAX_SKIPPED` of the files skipped is an error."""
        kept, self.skipped, self.nonfinite = [], [], 0
        for number, path in enumerate(self.files):
            try:
                points, times = read_scan(path)
            except READ_ERRORS as exc:
                log.warning("skipping scan %s: %s", path.name, exc)
                self.skipped.append(path.name)
            else:
                finite = int(np.isfinite(points).all(axis=1).sum())
                self.nonfinite += len(points) - finite
                self.has_times |= times is not None
                if finite:
                    kept.append(number)
                else:
                    log.warning("skipping scan %s: it holds no finite points", path.name)
                    self.skipped.append(path.name)
            if progress is not None:
                progress.update(1)
        if len(self.skipped) > MAX_SKIPPED * len(self.files):
            raise SlamError(
                f"{len(self.skipped)} of the {len(self.files)} scans in {self.root} are empty or unreadable (more "
                f"than {MAX_SKIPPED:.0%}), e.g. {self.skipped[0]}: check the folder"
            )
        self.kept = kept


def open_scan_folder(root) -> ScanFolder:
    """The scans of folder ``root``, checked before any work: it holds scans of one format, and its first
    scans are in the sensor frame (not kilometres from their origin, as a world frame's are)."""
    root = Path(root)
    if not root.is_dir():
        raise SlamError(f"--scans {root}: no such folder")
    files = sorted(
        (p for p in root.iterdir() if p.is_file() and not p.name.startswith(".")), key=lambda p: natural_key(p.name)
    )
    formats = {FORMATS[p.suffix.lower()] for p in files if p.suffix.lower() in FORMATS}
    if not formats:
        known = ", ".join(sorted(FORMATS))
        raise SlamError(f"--scans {root} holds no scans (files ending {known})")
    if len(formats) > 1:
        raise SlamError(f"--scans {root} mixes scan formats ({', '.join(sorted(formats))}): keep one per folder")
    fmt = formats.pop()
    scans = [p for p in files if FORMATS.get(p.suffix.lower()) == fmt]
    if len(scans) < len(files):
        log.info("%d files in %s that are not %s scans are left out", len(files) - len(scans), root, fmt)
    folder = ScanFolder(root, scans, fmt)
    _check_sensor_frame(folder)
    return folder


def first_scans(folder: ScanFolder, count: int = FIRST_SCANS) -> list[tuple[Path, np.ndarray]]:
    """(file, finite points) of the first ``count`` readable scans (unreadable ones are left to the survey)."""
    scans = []
    for path in folder.files:
        if len(scans) == count:
            break
        try:
            points = read_scan(path)[0]
        except READ_ERRORS:
            continue
        points = points[np.isfinite(points).all(axis=1)]
        if len(points):
            scans.append((path, points))
    return scans


def _check_sensor_frame(folder: ScanFolder) -> None:
    for path, points in first_scans(folder):
        distance = float(np.median(np.linalg.norm(points, axis=1)))
        if distance > WORLD_FRAME_M:
            raise SlamError(
                f"the scans in {folder.root} look like world coordinates, not the sensor frame: the points of "
                f"{path.name} lie a median {distance / 1000:.0f} km from its origin; give each scan in the frame "
                "of the lidar (origin at the sensor)"
            )


def read_scan(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """(points (N, 3), per-point times (N,) or None) of one scan file, by its extension."""
    suffix = path.suffix.lower()
    if path.stat().st_size == 0:
        raise SlamError("the file is empty")
    if suffix == ".ply":
        return _read_ply(path)
    if suffix == ".pcd":
        return _read_pcd(path)
    if suffix in (".las", ".laz"):
        return _read_las(path)
    if suffix == ".npy":
        array = np.load(path, allow_pickle=False)
        if array.ndim != 2 or array.shape[1] < 3:
            raise SlamError(f"a .npy scan is N x 3 or more columns, this one is {array.shape}")
        return np.array(array[:, :3], dtype=np.result_type(array.dtype, np.float32)), None
    if suffix == ".bin":
        data = np.fromfile(path, dtype="<f4")
        if data.size % 4:
            raise SlamError(f"a KITTI .bin holds float32 x y z intensity, 16 bytes a point; this has {data.size * 4}")
        return data.reshape(-1, 4)[:, :3].copy(), None
    raise SlamError(f"{path.suffix} is not a scan format ({', '.join(sorted(FORMATS))})")


def _columns(records: np.ndarray, names) -> tuple[np.ndarray, np.ndarray | None]:
    """x, y, z (and a time field, if any) of structured ``records``."""
    missing = [axis for axis in "xyz" if axis not in names]
    if missing:
        raise SlamError(f"it has no {', '.join(missing)} field (fields: {', '.join(names)})")
    points = np.column_stack([records[axis] for axis in "xyz"])
    if points.dtype.kind != "f":
        points = points.astype(float)
    time = next((name for name in TIME_FIELDS if name in names), None)
    return points, None if time is None else np.asarray(records[time], dtype=float)


def _header(f, end: bytes, limit: int = 200) -> list[list[str]]:
    """The header lines of a PLY or PCD file up to (and with) the line starting ``end``, split in words."""
    lines = []
    for _ in range(limit):
        line = f.readline()
        if not line:
            raise SlamError("its header does not end")
        words = line.decode("ascii", errors="replace").split()
        lines.append(words)
        if line.startswith(end):
            return lines
    raise SlamError(f"its header has no {end.decode()} line in {limit} lines")


def _read_ply(path: Path):
    with open(path, "rb") as f:
        lines = _header(f, b"end_header")
        if lines[0] != ["ply"]:
            raise SlamError("it does not start with 'ply'")
        fmt = next((w[1] for w in lines if w[:1] == ["format"] and len(w) > 1), None)
        count, props, elements = 0, [], 0
        for words in lines:
            if words[:1] == ["element"]:
                elements += 1
                if elements == 1 and words[1:2] == ["vertex"]:
                    count = int(words[2])
            elif words[:1] == ["property"] and elements == 1:
                if words[1] == "list" or words[1] not in _PLY_TYPES:
                    raise SlamError(f"its vertex property {' '.join(words[1:])} is not a plain number")
                props.append((words[2], _PLY_TYPES[words[1]]))
        if not count or not props:
            raise SlamError("it holds no vertices (the first element must be 'vertex')")
        names = [name for name, _ in props]
        if fmt == "ascii":
            table = _ascii_table(f, count, len(props), "vertices")
            records = {name: table[:, k] for k, name in enumerate(names)}
        elif fmt in ("binary_little_endian", "binary_big_endian"):
            order = "<" if fmt == "binary_little_endian" else ">"
            dtype = np.dtype([(name, order + kind) for name, kind in props])
            records = _binary_records(f, dtype, count, "vertices")
        else:
            raise SlamError(f"PLY format {fmt!r} is not ascii or binary")
    return _columns(records, names)


def _ascii_table(f, count: int, width: int, what: str) -> np.ndarray:
    """The ``count`` x ``width`` numbers of an ASCII body (PLY's vertices, PCD's points), as announced."""
    table = np.loadtxt(f, max_rows=count, ndmin=2)
    if table.shape != (count, width):
        raise SlamError(f"it announces {count} {what} of {width} values, read {table.shape}")
    return table


def _binary_records(f, dtype: np.dtype, count: int, what: str) -> np.ndarray:
    """The ``count`` records of a binary body (PLY's vertices, PCD's points), as announced."""
    records = np.fromfile(f, dtype=dtype, count=count)
    if len(records) < count:
        raise SlamError(f"it is truncated: {len(records)} of {count} {what}")
    return records


def _read_pcd(path: Path):
    with open(path, "rb") as f:
        lines = _header(f, b"DATA")
        head = {w[0].upper(): w[1:] for w in lines if w and not w[0].startswith("#")}
        names, sizes, types = head.get("FIELDS", []), head.get("SIZE", []), head.get("TYPE", [])
        counts = head.get("COUNT", ["1"] * len(names))
        if not names or not len(names) == len(sizes) == len(types) == len(counts):
            raise SlamError("its FIELDS, SIZE, TYPE and COUNT lines do not match")
        count = int(head.get("POINTS", ["0"])[0])
        kind = head["DATA"][0].lower()
        if kind == "ascii":
            width = sum(int(c) for c in counts)
            table = _ascii_table(f, count, width, "points")
            starts = np.cumsum([0] + [int(c) for c in counts])
            records = {name: table[:, starts[k]] for k, name in enumerate(names)}
        elif kind == "binary":
            dtype = np.dtype(
                [
                    (n, "<" + t.lower() + s, (int(c),) if c != "1" else ())
                    for n, s, t, c in zip(names, sizes, types, counts, strict=True)
                ]
            )
            records = _binary_records(f, dtype, count, "points")
        else:
            raise SlamError(f"PCD DATA {kind} is not read (ascii or binary; save binary_compressed as binary)")
    return _columns(records, names)


def _read_las(path: Path):
    import laspy

    from helpers.sim.las import check_las_file

    check_las_file(path)
    try:
        las = laspy.read(path)
    except Exception as exc:  # laspy's and its LAZ backend's errors have no common type: the scan is unreadable
        raise SlamError(f"laspy cannot read it: {exc}") from None
    points = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    names = set(las.point_format.dimension_names)
    return points, np.asarray(las.gps_time, dtype=float) if "gps_time" in names else None
