"""Reading an aerial map: ``.las``/``.laz``, or a ``.tar.gz`` that holds one.

The map is moved into the *map frame* the whole project works in: metres,
centred on the XY mid-point of the tile (as the reference does), heights
kept as they are (only converted to metres). Units come from the LAS
header's GeoTIFF keys or WKT, never assumed.
"""

from __future__ import annotations

import hashlib
import logging
import re
import shutil
import struct
import tarfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from . import paths
from .config import human_size
from .errors import SlamError
from .scene import BUILDING, GROUND, ROAD, TREE, WATER, HeightField

log = logging.getLogger(__name__)

# EPSG linear unit codes and their length in metres.
LINEAR_UNITS = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0, 9030: 1852.0, 9036: 1000.0}
# ASPRS classification codes -> scene labels (unlisted codes count as ground).
LAS_CLASSES = {2: GROUND, 3: TREE, 4: TREE, 5: TREE, 6: BUILDING, 9: WATER, 11: ROAD}
MAX_LAZ_RATIO = 50  # a LAZ file decompresses to at most this many times its size
# The public header block of LAS 1.0-1.4 up to the bounds: signature, version, header size, offset to the
# points, VLR count, point format, record length, point count, scales, offsets, (max, min) of x, y and z.
LAS_HEADER = struct.Struct("<4s20xBB64x4xHIIBHI20x3d3d6d")
LAS_14_FIELDS = struct.Struct("<QIQ")  # LAS 1.4, at byte 235: first EVLR, EVLR count, 64-bit point count
LAS_HEADER_SIZES = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}  # bytes of the header of LAS 1.minor
POINT_SIZES = (20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67)  # bytes of a record of point formats 0-10
VLR_HEADER, EVLR_HEADER = 54, 60  # bytes of a (extended) variable-length record before its data
LASZIP_VLR = (b"laszip encoded", 22204)  # user id and record id of the VLR that describes a LAZ's compression
MAX_LAZ_CHUNK, VARIABLE_CHUNKS = 1_000_000, 0xFFFFFFFF  # points per LAZ chunk (laszip writes 50,000), or variable
LAYERED, LAYERS = 3, {10: 9, 11: 1, 12: 2}  # laszip's layered compressor; layers per item (BYTE14: one a byte)
MAX_VLR_BYTES = 1 << 26  # real tiles hold kilobytes of VLRs; laspy reads them all into memory
MAX_MAP_CELLS = 50_000_000  # cells of the height field built from a tile: 50 km² at 1 m
CELL_BYTES = 60  # memory a cell takes while the height field is built (heights, labels, hole filling)


@dataclass(frozen=True)
class MapFrame:
    """How original map coordinates become map-frame metres:
    ``xy_m = (xy - offset) * scale_xy`` and ``z_m = z * scale_z``."""

    offset: tuple[float, float]
    scale_xy: float
    scale_z: float
    unit_name: str

    def to_map(self, xy: np.ndarray) -> np.ndarray:
        return (np.asarray(xy, np.float64)[:, :2] - np.asarray(self.offset)) * self.scale_xy


IDENTITY_FRAME = MapFrame((0.0, 0.0), 1.0, 1.0, "metre")


@dataclass(frozen=True)
class AerialMap:
    """A map in the map frame: its points, classes, and where they came from."""

    points: np.ndarray  # (N, 3) float64, m
    labels: np.ndarray  # (N,) uint8 scene labels
    frame: MapFrame
    source: str


def read_map(path: str | Path) -> AerialMap:
    """Read a ``.las``, ``.laz`` or ``.tar.gz`` holding one."""
    path = Path(path)
    if not path.is_file():
        raise SlamError(f"map file not found: {path}")
    name = path.name.lower()
    if name.endswith((".tar.gz", ".tgz")):
        return read_map(_extract_las(path))
    if not name.endswith((".las", ".laz")):
        raise SlamError(f"map must be a .las, .laz or .tar.gz file, got {path.name}")
    return _read_las(path)


def _read_las(path: Path) -> AerialMap:
    import laspy

    check_las_file(path)
    try:
        with laspy.open(path) as reader:
            header = reader.header
            data = reader.read()
    except BaseException as exc:  # laspy and lazrs raise many types for damaged files
        if not isinstance(exc, Exception) and type(exc).__name__ != "PanicException":  # a Rust panic in lazrs
            raise
        raise SlamError(f"{path.name} is not a readable LAS/LAZ file ({exc})") from None
    xy_unit, z_unit, unit_name = _units(header)
    xyz = np.column_stack([np.asarray(data.x), np.asarray(data.y), np.asarray(data.z)])
    finite = np.isfinite(xyz).all(axis=1)
    xyz = xyz[finite]
    if len(xyz) == 0:
        raise SlamError(f"{path.name} holds no finite points")
    lo, hi = xyz[:, :2].min(axis=0), xyz[:, :2].max(axis=0)
    frame = MapFrame(tuple(float(v) for v in (lo + hi) / 2), xy_unit, z_unit, unit_name)
    points = np.column_stack([frame.to_map(xyz), xyz[:, 2] * z_unit])
    classes = np.asarray(data.classification)[finite]
    labels = np.full(len(points), GROUND, np.uint8)
    for code, label in LAS_CLASSES.items():
        labels[classes == code] = label
    log.info("read %d points from %s (units: %s)", len(points), path.name, unit_name)
    return AerialMap(points, labels, frame, path.name)


def check_las_file(path: Path) -> None:
    """Refuse a LAS/LAZ file whose header does not fit the file, before laspy
    reads it: laspy believes the counts and offsets the header announces (a
    garbage VLR count makes it read for minutes)."""
    size = path.stat().st_size

    def bad(reason: str) -> SlamError:
        return SlamError(f"{path.name} is not a readable LAS/LAZ file: {reason}")

    with open(path, "rb") as f:
        head = f.read(max(LAS_HEADER_SIZES.values()))
        if len(head) < LAS_HEADER.size or head[:4] != b"LASF":
            raise bad("it does not start with a LAS header")
        _, major, minor, header_size, offset, n_vlrs, format_id, record, count, *values = LAS_HEADER.unpack_from(head)
        if major != 1 or minor not in LAS_HEADER_SIZES:
            raise bad(f"its version {major}.{minor} is not LAS 1.0 to 1.4")
        if header_size < LAS_HEADER_SIZES[minor]:
            raise bad(f"a LAS 1.{minor} header takes {LAS_HEADER_SIZES[minor]} bytes, this one claims {header_size}")
        if not header_size <= offset <= size:
            raise bad(f"its points start at byte {offset:,}, outside bytes {header_size}-{size:,} of the file")
        evlr_start, n_evlrs, count = LAS_14_FIELDS.unpack_from(head, 235) if minor == 4 else (0, 0, count)
        compressed, point_format = bool(format_id & 0x80) and not format_id & 0x40, format_id & 0x3F
        if point_format >= len(POINT_SIZES):
            raise bad(f"point format {point_format} is not one of LAS's 0-{len(POINT_SIZES) - 1}")
        if record < POINT_SIZES[point_format]:
            raise bad(f"its {record}-byte points are shorter than those of point format {point_format}")
        if count == 0:
            raise SlamError(f"{path.name} holds no points")
        points_end = offset + count * record
        if compressed and count * record > MAX_LAZ_RATIO * size:
            raise bad(f"its header claims {count:,} points, far more than a {size:,}-byte LAZ holds")
        if not compressed and points_end > size:
            raise bad(f"it is truncated: its {count:,} points need {points_end:,} bytes, the file has {size:,}")
        scales, offsets, bounds = np.array(values[:3]), np.array(values[3:6]), np.array(values[6:]).reshape(3, 2)
        if not (np.isfinite(scales).all() and scales.all()):
            raise bad(f"its scale factors {scales.tolist()} must be finite and non-zero")
        if not np.isfinite(offsets).all():
            raise bad(f"its offsets {offsets.tolist()} must be finite")
        if not (np.isfinite(bounds).all() and (bounds[:, 1] <= bounds[:, 0]).all()):
            raise bad(f"its bounds (max, min per axis) {bounds.tolist()} must be finite with min <= max")
        vlrs = _read_vlrs(f, header_size, offset, n_vlrs, bad)
        if compressed:
            _check_laszip(f, vlrs.get(LASZIP_VLR), record, offset, count, size, bad)
        if n_evlrs:
            _check_evlr_chain(f, evlr_start, n_evlrs, offset if compressed else points_end, size, bad)


def _read_vlrs(f, start: int, end: int, count: int, bad) -> dict[tuple[bytes, int], bytes]:
    """The data of the ``count`` VLRs from byte ``start`` by (user id, record
    id); they must end by byte ``end`` (the points)."""
    if end - start > MAX_VLR_BYTES:
        raise bad(f"its {human_size(end - start)} of VLRs before the points exceed {human_size(MAX_VLR_BYTES)}")
    if count * VLR_HEADER > end - start:
        raise bad(f"its header announces {count:,} VLRs, more than its {end - start:,} bytes before the points hold")
    f.seek(start)
    block, at, vlrs = f.read(end - start), 0, {}
    for _ in range(count):
        if at + VLR_HEADER > len(block):
            break
        user, record_id, length = struct.unpack_from("<2x16sHH", block, at)
        vlrs[user.rstrip(b"\0"), record_id] = block[at + VLR_HEADER : at + VLR_HEADER + length]
        at += VLR_HEADER + length
    else:
        if at <= len(block):
            return vlrs
    raise bad(f"its VLRs run past the start of its points (byte {end:,})")


def _check_laszip(f, vlr: bytes | None, record: int, offset: int, count: int, size: int, bad) -> None:
    """The laszip VLR must describe the header's points, and the chunk table
    and the chunks' layers must fit the file: lazrs trusts them all (some
    damaged ones make it panic, or ask for gigabytes and abort)."""
    if vlr is None or len(vlr) < 34:
        raise bad("its points are compressed but it has no laszip VLR")
    compressor, chunk_size, n_items = struct.unpack_from("<H10xI16xH", vlr)
    if n_items == 0 or len(vlr) != 34 + 6 * n_items:
        raise bad(f"its laszip VLR ({len(vlr)} bytes for {n_items} items) is damaged")
    items = struct.unpack_from(f"<{3 * n_items}H", vlr, 34)  # (type, size, version) per item
    kinds, sizes = items[0::3], items[1::3]
    if sum(sizes) != record:
        raise bad(f"its laszip VLR describes {sum(sizes)}-byte points, its header {record}-byte points")
    if not (0 < chunk_size <= MAX_LAZ_CHUNK or chunk_size == VARIABLE_CHUNKS):
        raise bad(f"its LAZ chunks of {chunk_size:,} points are not 1 to {MAX_LAZ_CHUNK:,} points")
    f.seek(offset)
    table = int.from_bytes(f.read(8), "little", signed=True)
    if table <= offset:  # a writer that could not go back puts it at the end
        f.seek(size - 8)
        table = int.from_bytes(f.read(8), "little", signed=True)
    if table <= offset:
        return  # no chunk table: lazrs reads the chunks one after the other
    f.seek(min(table, size))
    n_chunks = int.from_bytes(f.read(8)[4:], "little")  # after the table's version
    if not 0 < n_chunks <= count:
        raise bad(f"its chunk table at byte {table:,} does not fit its {count:,} points or the file")
    if compressor == LAYERED:
        layers = sum(n if kind == 14 else LAYERS.get(kind, 0) for kind, n in zip(kinds, sizes, strict=True))
        at = offset + 8
        for _ in range(n_chunks):  # each chunk: its first point, its point count, its layers' sizes, its layers
            f.seek(at + record + 4)
            head = f.read(4 * layers)
            at += record + 4 + len(head) + sum(struct.unpack(f"<{len(head) // 4}I", head))
            if len(head) < 4 * layers or at > table:
                raise bad(f"the layers of its LAZ chunks run past the chunk table at byte {table:,}")


def _check_evlr_chain(f, start: int, count: int, points_end: int, size: int, bad) -> None:
    """The ``count`` extended VLRs from byte ``start`` must lie after the points and end by the end of the file."""
    if not points_end <= start <= size - count * EVLR_HEADER:
        raise bad(f"its {count:,} EVLRs from byte {start:,} do not fit between its points and the end of the file")
    for number in range(count):
        f.seek(start + 20)
        start += EVLR_HEADER + int.from_bytes(f.read(8), "little")
        if start > size:
            raise bad(f"EVLR {number + 1} of {count} runs past the end of the file")


def _units(header) -> tuple[float, float, str]:
    """(horizontal metres per unit, vertical metres per unit, unit name)."""
    horizontal = vertical = None
    for vlr in header.vlrs:
        for key in getattr(vlr, "geo_keys", []):
            if key.id == 3076 and key.value_offset in LINEAR_UNITS:  # ProjLinearUnitsGeoKey
                horizontal = LINEAR_UNITS[key.value_offset]
            if key.id == 4099 and key.value_offset in LINEAR_UNITS:  # VerticalUnitsGeoKey
                vertical = LINEAR_UNITS[key.value_offset]
    if horizontal is None:
        for vlr in list(header.vlrs) + list(header.evlrs or []):
            wkt = getattr(vlr, "string", None)
            if isinstance(wkt, bytes):
                wkt = wkt.decode("ascii", "replace")
            if wkt:
                linear = _wkt_linear_units(wkt)
                if linear:
                    horizontal = linear[0]
                    vertical = vertical or (linear[1] if len(linear) > 1 else None)
                    break
    if horizontal is None:
        log.warning("no unit in the LAS header's CRS records: assuming metres")
        horizontal = 1.0
    vertical = vertical or horizontal
    return horizontal, vertical, _unit_name(horizontal)


def _wkt_linear_units(wkt: str) -> list[float]:
    """Linear UNIT factors in order of appearance (angular units skipped)."""
    factors = []
    for name, factor in re.findall(r'(?:LENGTH)?UNIT\["([^"]+)"\s*,\s*([0-9.eE+-]+)', wkt):
        if "degree" in name.lower() or "radian" in name.lower():
            continue
        factors.append(float(factor))
    return factors


def _unit_name(metres: float) -> str:
    names = {1.0: "metre", 0.3048: "foot", 1200.0 / 3937.0: "US survey foot"}
    return next((n for m, n in names.items() if abs(m - metres) < 1e-12), f"{metres:g} m")


def _extract_las(archive: Path) -> Path:
    """Extract the first .las/.laz of a tarball into the cache, once."""
    stat = archive.stat()
    key = hashlib.sha256(f"{archive.resolve()}|{stat.st_size}|{stat.st_mtime_ns}".encode()).hexdigest()[:16]
    target_dir = paths.cache_dir() / "maps" / key
    done = sorted(target_dir.glob("*.la[sz]")) if target_dir.is_dir() else []
    if done:
        return done[0]
    try:
        with tarfile.open(archive, "r:gz") as tar:
            members = sorted(
                (m for m in tar.getmembers() if m.isfile() and m.name.lower().endswith((".las", ".laz"))),
                key=lambda m: m.name,
            )
            if not members:
                raise SlamError(f"{archive.name} holds no .las or .laz file")
            member = members[0]
            source = tar.extractfile(member)
            target_dir.mkdir(parents=True, exist_ok=True)
            target = target_dir / Path(member.name).name
            paths.write_atomically(target, lambda out: shutil.copyfileobj(source, out, 1 << 20))
    except (tarfile.TarError, OSError, EOFError) as exc:
        raise SlamError(f"{archive.name} is not a readable .tar.gz archive ({exc})") from None
    return target


def height_field_from_points(points: np.ndarray, labels: np.ndarray, cell: float = 1.0, max_gap: float = 3.0):
    """A first-surface height field: the highest point of each ``cell``,
    small holes filled from the nearest cell, cells farther than ``max_gap``
    metres from any point left without surface."""
    if len(points) < 3:
        raise SlamError("the map needs at least 3 points to build a surface")
    lo = np.floor(points[:, :2].min(axis=0) / cell) * cell
    nx, ny = np.floor((points[:, :2].max(axis=0) - lo) / cell) + 1  # floats: a wild point may overflow integers
    if not 1 <= nx * ny <= MAX_MAP_CELLS:
        raise SlamError(
            f"the map spans {nx * cell:.0f} x {ny * cell:.0f} m: {nx * ny:.2g} cells of {cell:g} m "
            f"(about {human_size(nx * ny * CELL_BYTES)}); the limit is {MAX_MAP_CELLS:,} cells"
        )
    nx, ny = int(nx), int(ny)
    ij = np.floor((points[:, :2] - lo) / cell).astype(np.int64)
    flat = ij[:, 1] * nx + ij[:, 0]
    order = np.lexsort((points[:, 2], flat))  # by cell, then height
    flat_sorted = flat[order]
    top = np.r_[flat_sorted[1:] != flat_sorted[:-1], True]  # highest point per cell
    z = np.full(ny * nx, np.nan)
    lab = np.zeros(ny * nx, np.uint8)
    z[flat_sorted[top]] = points[order[top], 2]
    lab[flat_sorted[top]] = labels[order[top]]
    z, lab = z.reshape(ny, nx), lab.reshape(ny, nx)
    empty = np.isnan(z)
    distance, (ii, jj) = ndimage.distance_transform_edt(empty, return_indices=True)
    z, lab = z[ii, jj], lab[ii, jj]
    valid = distance * cell <= max_gap
    return HeightField(lo[0] + cell / 2, lo[1] + cell / 2, cell, z, lab, valid)
