"""Reading an aerial map: ``.las``/``.laz``, or a ``.tar.gz`` that holds one.

The map is moved into the *map frame* the whole project works in: metres,
centred on the XY mid-point of the tile (as the reference does), heights
kept as they are (only converted to metres). Units come from the LAS
header's GeoTIFF keys or WKT, never assumed.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import shutil
import tarfile
import zlib
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from helpers import paths
from helpers.config.bounds import human_size
from helpers.errors import SlamError
from helpers.sim.las import check_las_file
from helpers.sim.scene import BUILDING, GROUND, ROAD, TREE, WATER, HeightField

log = logging.getLogger(__name__)

# EPSG linear unit codes and their length in metres.
LINEAR_UNITS = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0, 9030: 1852.0, 9036: 1000.0}
# ASPRS classification codes -> scene labels (unlisted codes count as ground).
LAS_CLASSES = {2: GROUND, 3: TREE, 4: TREE, 5: TREE, 6: BUILDING, 9: WATER, 11: ROAD}
MAX_MAP_CELLS = 50_000_000  # cells of the height field built from a tile: 50 km² at 1 m
CELL_BYTES = 60  # memory a cell takes while the height field is built (heights, labels, hole filling)
# What an archive member may unpack to. Real LAZ tiles are tens to hundreds of MB, the same tile as LAS
# about ten times that: 4 GiB holds a LAS tile of over 100 million points and stops a bomb before it fills
# a disk. gzip shrinks a LAS tile about twice and a LAZ tile not at all, so a member that expands more
# than 20 times its archive is made of repeats, not of survey points.
MAX_TILE_BYTES = 4 << 30
MAX_ARCHIVE_RATIO = 20
FREE_SPACE_MARGIN = 256 << 20  # bytes left free on the cache's disk after a tile is unpacked
RECORD = "tile.json"  # beside an unpacked tile: its name, size and SHA-256 (helpers.paths.write_checked)


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
    path = paths.input_file(path, "map file")
    name = path.name.lower()
    if name.endswith((".tar.gz", ".tgz")):
        tile = _extract_las(path)
        try:
            return _read_las(tile)
        except SlamError:  # a rejected tile is not kept in the cache
            _forget(tile.parent, tile)
            raise
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


def _units(header) -> tuple[float, float, str]:
    """(horizontal metres per unit, vertical metres per unit, unit name)."""
    horizontal = vertical = None
    for vlr in header.vlrs:
        for key in getattr(vlr, "geo_keys", []):
            if key.id == 3076 and key.value_offset in LINEAR_UNITS:  # ProjLinearUnitsGeoKey
                horizontal = LINEAR_UNITS[key.value_offset]
            if key.id == 4099 and key.value_offset in LINEAR_UNITS:  # VerticalUnitsGeoKey
                vertical = LINEAR_UNITS[key.value_offset]
    for vlr in list(header.vlrs) + list(header.evlrs or []):
        wkt = getattr(vlr, "string", None)
        if isinstance(wkt, bytes):
            wkt = wkt.decode("ascii", "replace")
        linear = _wkt_linear_units(wkt) if wkt else []
        if linear:
            if horizontal is not None and abs(linear[0] - horizontal) > 1e-9 * horizontal:
                raise SlamError(  # one of them is wrong, and a map read in the wrong unit is 3.28 times off
                    f"the tile's CRS records disagree on its unit: the GeoTIFF keys say {_unit_name(horizontal)}, "
                    f"the WKT says {_unit_name(linear[0])}: fix the header (e.g. with PDAL's writers.las a_srs)"
                )
            if horizontal is None:
                horizontal = linear[0]
                vertical = vertical or (linear[1] if len(linear) > 1 else None)
            break
    if horizontal is None:
        log.warning("no unit in the LAS header's CRS records: assuming metres")
        horizontal = 1.0
    vertical = vertical or horizontal
    return horizontal, vertical, _unit_name(horizontal)


ELLIPSOID = re.compile(r"(?:ELLIPSOID|SPHEROID)\[[^\[\]]*(?:\[[^\[\]]*\][^\[\]]*)*\]")


def _wkt_linear_units(wkt: str) -> list[float]:
    """Linear UNIT factors in order of appearance (angular units skipped)."""
    factors = []
    wkt = ELLIPSOID.sub("", wkt)  # WKT2 gives the ellipsoid's axes a LENGTHUNIT before the coordinates' own
    for name, factor in re.findall(r'(?:LENGTH)?UNIT\["([^"]+)"\s*,\s*([0-9.eE+-]+)', wkt):
        if "degree" in name.lower() or "radian" in name.lower():
            continue
        factors.append(float(factor))
    return factors


def _unit_name(metres: float) -> str:
    names = {1.0: "metre", 0.3048: "foot", 1200.0 / 3937.0: "US survey foot"}
    return next((n for m, n in names.items() if abs(m - metres) < 1e-12), f"{metres:g} m")


def _extract_las(archive: Path) -> Path:
    """The first .las/.laz of a tarball, unpacked once into the cache folder,
    keyed on the archive's content (an archive replaced under the same name,
    size and time is unpacked again) and checked against the SHA-256 recorded
    beside it when used (a damaged copy is unpacked again, with a warning).
    The member's declared size is checked against :data:`MAX_TILE_BYTES`,
    :data:`MAX_ARCHIVE_RATIO` and the free space before anything is written,
    and the bytes are counted again while they stream (a header can lie);
    whatever a refused or failed extraction wrote is removed."""
    cache = paths.cache_dir()
    try:
        with open(archive, "rb") as f:
            target_dir = cache / "maps" / hashlib.file_digest(f, "sha256").hexdigest()[:32]
    except OSError as exc:
        raise SlamError(f"{archive.name} cannot be read: {exc.strerror or exc}") from None
    paths.sweep_cache(cache)
    try:
        found = paths.read_checked(target_dir / RECORD, {}, load=False)
    except paths.Damaged as exc:
        log.warning(
            "the copy of %s in the cache folder %s is damaged (%s): unpacking it again", archive.name, cache, exc
        )
        found = None
    if found is not None:
        return found[0]
    tile = _unpack(archive, target_dir)
    paths.evict(cache, keep=target_dir)
    return tile


class _Unreadable(Exception):
    """Reading the archive failed while its member was copied (the cause says how)."""


def _unpack(archive: Path, target_dir: Path) -> Path:
    """Extract the first .las/.laz of ``archive`` into ``target_dir``, its SHA-256 recorded beside it."""
    target = None
    try:
        with tarfile.open(archive, "r:gz") as tar:
            members = []
            for m in tar:  # header after header: a size is checked before its data is skipped
                if m.isfile() and m.name.lower().endswith((".las", ".laz")):
                    _check_member_size(f"{Path(m.name).name} in {archive.name}", m.size, archive.stat().st_size)
                    members.append(m)
            if not members:
                raise SlamError(f"{archive.name} holds no .las or .laz file")
            member = min(members, key=lambda m: m.name)
            name = Path(member.name).name
            _check_free_space(f"{name} in {archive.name}", member.size, target_dir)
            source = tar.extractfile(member)
            head = source.read(4)
            if head != b"LASF":
                raise SlamError(f"{name} in {archive.name} is not a readable LAS/LAZ file: it has no LAS header")
            target, limit = target_dir / name, min(member.size, MAX_TILE_BYTES)
            try:  # every OSError here is the cache's: reading the archive raises _Unreadable
                target_dir.mkdir(parents=True, exist_ok=True)
                paths.write_checked(target, lambda out: _copy_at_most(head, source, out, limit, name), {})
                os.replace(paths.record_of(target), target_dir / RECORD)
            except OSError as exc:
                raise SlamError(_unwritable(archive, exc)) from None
    except (_Unreadable, tarfile.TarError, OSError, EOFError, zlib.error) as exc:
        _forget(target_dir, target)
        raise SlamError(f"{archive.name} is not a readable .tar.gz archive ({exc.__cause__ or exc})") from None
    except SlamError:
        _forget(target_dir, target)
        raise
    return target


def _unwritable(archive: Path, exc: OSError) -> str:
    """An OSError met while writing into the cache folder, as a message that blames the cache, not the archive."""
    cache = paths.cache_dir()
    there = next((p for p in (cache, *cache.parents) if os.path.lexists(p)), cache)
    why = f"{there} is a file, not a folder" if os.path.lexists(there) and not there.is_dir() else exc.strerror
    return f"cannot unpack {archive.name} into the cache folder {cache}: {why} (${paths.CACHE_VARIABLE} sets another)"


def _check_member_size(where: str, size: int, archive_size: int) -> None:
    """Refuse a member too large for a tile, or too compressed to hold survey points."""
    if size > MAX_TILE_BYTES:
        raise SlamError(f"{where} holds {human_size(size)}; the limit is {human_size(MAX_TILE_BYTES)} for a tile")
    if size > MAX_ARCHIVE_RATIO * archive_size:
        raise SlamError(
            f"{where} expands to {human_size(size)} from a {human_size(archive_size)} archive, "
            f"{size / max(archive_size, 1):.3g} times; the limit is {MAX_ARCHIVE_RATIO} times (tiles compress less)"
        )


def _check_free_space(where: str, size: int, target_dir: Path) -> None:
    """Refuse a member that would leave less than :data:`FREE_SPACE_MARGIN` free on the cache's disk."""
    existing = next(p for p in (target_dir, *target_dir.parents) if p.exists())
    free = shutil.disk_usage(existing).free
    if size + FREE_SPACE_MARGIN > free:
        raise SlamError(
            f"{where} needs {human_size(size)} and {human_size(FREE_SPACE_MARGIN)} to spare, but the cache "
            f"({paths.cache_dir()}) has {human_size(free)} free: free some space or set ${paths.CACHE_VARIABLE}"
        )


def _copy_at_most(head: bytes, source, out, limit: int, name: str) -> None:
    """Write ``head`` then the rest of ``source`` into ``out``, refusing it once more than ``limit`` bytes came."""
    written = len(head)
    out.write(head)
    while True:
        try:
            chunk = source.read(1 << 20)
        except (tarfile.TarError, OSError, EOFError, zlib.error) as exc:
            raise _Unreadable() from exc
        if not chunk:
            return
        written += len(chunk)
        if written > limit:
            raise SlamError(f"{name} unpacks to more than the {human_size(limit)} its archive declares or allows")
        out.write(chunk)


def _forget(folder: Path, tile: Path | None) -> None:
    """Remove an extracted ``tile`` (if any) and its record, then ``folder`` and ``maps/`` above it if that leaves
    them empty."""
    for path in () if tile is None else (tile, folder / RECORD):
        with suppress(OSError):  # a cache that cannot be written may not be cleared either
            path.unlink(missing_ok=True)
    for empty in (folder, folder.parent):
        try:
            empty.rmdir()  # only an empty folder goes
        except OSError:
            break


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
