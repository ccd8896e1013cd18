"""Reading an aerial map: ``.las``/``.laz``, or a ``.tar.gz`` that holds one.

The map is moved into the *map frame* the whole project works in: metres,
centred on the XY mid-point of the tile (as the reference does), heights
kept as they are (only converted to metres). Units come from the LAS
header's GeoTIFF keys or WKT, never assumed. The tile's coordinate-system
records travel with the frame (:class:`CrsRecord`), so that what is made in
the map frame can be written back in the tile's own system
(:mod:`helpers.sim.map_laz`).
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from helpers import paths
from helpers.config.bounds import human_size
from helpers.errors import SlamError
from helpers.sim.archive import extract_las, forget
from helpers.sim.las import check_las_file
from helpers.sim.scene import BUILDING, GROUND, ROAD, TREE, WATER, HeightField

log = logging.getLogger(__name__)

# EPSG linear unit codes and their length in metres.
LINEAR_UNITS = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0, 9030: 1852.0, 9036: 1000.0}
# ASPRS classification codes -> scene labels (unlisted codes count as ground).
LAS_CLASSES = {2: GROUND, 3: TREE, 4: TREE, 5: TREE, 6: BUILDING, 9: WATER, 11: ROAD}
MAX_MAP_CELLS = 50_000_000  # cells of the height field built from a tile: 50 km² at 1 m
CELL_BYTES = 60  # memory a cell takes while the height field is built (heights, labels, hole filling)


CRS_USER_ID = "LASF_Projection"  # the user id of the LAS coordinate-system records
WKT_RECORDS = (2112, 2111)  # OGC coordinate system WKT, OGC math transform WKT
GEOTIFF_RECORDS = (34735, 34736, 34737)  # GeoKeyDirectoryTag, GeoDoubleParamsTag, GeoAsciiParamsTag


@dataclass(frozen=True)
class CrsRecord:
    """One coordinate-system record of a tile's header (a ``LASF_Projection`` VLR or EVLR), kept as its bytes."""

    record_id: int
    description: str
    data: bytes

    @property
    def is_wkt(self) -> bool:
        return self.record_id in WKT_RECORDS


@dataclass(frozen=True)
class MapFrame:
    """How original map coordinates become map-frame metres:
    ``xy_m = (xy - offset) * scale_xy`` and ``z_m = z * scale_z``; ``crs``: the
    tile's coordinate-system records (none for the embedded scene or a tile without them)."""

    offset: tuple[float, float]
    scale_xy: float
    scale_z: float
    unit_name: str
    crs: tuple[CrsRecord, ...] = ()

    def to_map(self, xy: np.ndarray) -> np.ndarray:
        return (np.asarray(xy, np.float64)[:, :2] - np.asarray(self.offset)) * self.scale_xy

    def to_tile(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) map-frame metres -> the tile's own coordinates and units (the inverse of :meth:`to_map`
        and of ``z_m = z * scale_z``)."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        xy = points[:, :2] / self.scale_xy + np.asarray(self.offset)
        return np.column_stack([xy, points[:, 2] / self.scale_z])


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
        tile = extract_las(path)
        try:
            return _read_las(tile)
        except SlamError:  # a rejected tile is not kept in the cache
            forget(tile.parent, tile)
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
    frame = MapFrame(tuple(float(v) for v in (lo + hi) / 2), xy_unit, z_unit, unit_name, _crs_records(header))
    points = np.column_stack([frame.to_map(xyz), xyz[:, 2] * z_unit])
    classes = np.asarray(data.classification)[finite]
    labels = np.full(len(points), GROUND, np.uint8)
    for code, label in LAS_CLASSES.items():
        labels[classes == code] = label
    log.info("read %d points from %s (units: %s)", len(points), path.name, unit_name)
    return AerialMap(points, labels, frame, path.name)


def _crs_records(header) -> tuple[CrsRecord, ...]:
    """The header's coordinate-system records (VLRs, then EVLRs), as the tile has them."""
    return tuple(
        CrsRecord(vlr.record_id, vlr.description, bytes(vlr.record_data_bytes()))
        for vlr in list(header.vlrs) + list(header.evlrs or [])
        if vlr.user_id == CRS_USER_ID
    )


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
