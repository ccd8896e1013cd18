"""A run's map as a LAS 1.4 file (``map.laz``, compressed by lazrs) where users' tools (QGIS,
CloudCompare, PDAL, lidR) read it: in the tile's own coordinate system and units, with the tile's
coordinate-system records copied, or in the run's local map frame when there is no tile.

The records are copied as the tile had them: its WKT (point format 6, the WKT bit of the global
encoding set, as LAS 1.4 asks) or, when the tile had only GeoTIFF keys, those (point format 1). The
header says which frame the points are in: its system identifier, and a description record
(:data:`FRAME_USER_ID`) in words.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from helpers import __version__
from helpers.sim.maps import CRS_USER_ID, GEOTIFF_RECORDS, IDENTITY_FRAME, MapFrame

log = logging.getLogger(__name__)

STEP_M = 1e-4  # m: the coordinates' step is at most this (a tenth of a millimetre) while the map fits a 32-bit record
MAX_STEPS = 2**31 - 2  # a coordinate is stored as a signed 32-bit count of steps from the offset
MAX_VLR_DATA = 65535  # bytes a VLR can hold: a longer record goes in an EVLR
FRAME_USER_ID = "AerialLidarSLAM"  # user id of the record that says in words which frame the points are in
FRAME_RECORD_ID = 1


def write_map_laz(path: str | Path, points: np.ndarray, frame: MapFrame | None = None) -> None:
    """Write map-frame ``points`` (N, 3, metres) as LAS 1.4 (compressed when ``path`` ends in ``.laz``).
    ``frame``: the tile's :class:`~helpers.sim.maps.MapFrame`; the points are moved back into the tile's
    coordinates and units by its inverse and the tile's CRS records are copied. None (or the identity
    frame of the embedded scene) writes the run's local map frame in metres, with no CRS."""
    import laspy
    from laspy.vlrs.vlrlist import VLRList

    frame = frame or IDENTITY_FRAME
    xyz = frame.to_tile(points)
    wkt = [r for r in frame.crs if r.is_wkt]
    records = wkt or [r for r in frame.crs if r.record_id in GEOTIFF_RECORDS]
    header = laspy.LasHeader(version="1.4", point_format=6 if wkt or not records else 1)
    header.global_encoding.wkt = bool(wkt)
    header.system_identifier, description = _frame_words(frame, wkt)
    header.generating_software = f"aerial-lidar-slam {__version__}"
    header.offsets, header.scales = _quantisation(xyz, frame)
    evlrs = []
    for record in records:
        vlr = laspy.VLR(CRS_USER_ID, record.record_id, record.description, record.data)
        (header.vlrs if len(record.data) <= MAX_VLR_DATA else evlrs).append(vlr)
    header.vlrs.append(laspy.VLR(FRAME_USER_ID, FRAME_RECORD_ID, "coordinate frame", description.encode()))
    if evlrs:
        header.evlrs = VLRList(evlrs)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.write(str(path))


def _frame_words(frame: MapFrame, wkt: list) -> tuple[str, str]:
    """(the header's system identifier, at most 32 characters; a sentence for the description record)."""
    if frame.crs:
        kind = "WKT" if wkt else "GeoTIFF keys"
        return "SLAM map, tile CRS", (
            f"The run's map in the source tile's coordinate system and units ({frame.unit_name}); "
            f"its CRS records ({kind}) are copied from the tile."
        )
    if frame == IDENTITY_FRAME:
        return "SLAM map, local frame", (
            "The run's local map frame: metres, no CRS (the run flew over the embedded scene or scans without a tile)."
        )
    return "SLAM map, tile coordinates", (
        f"The run's map in the source tile's coordinates and units ({frame.unit_name}); the tile had no CRS record."
    )


def _quantisation(xyz: np.ndarray, frame: MapFrame) -> tuple[np.ndarray, np.ndarray]:
    """(offsets, scales) of the three axes: whole-unit offsets at the points' centre, and steps of at most
    :data:`STEP_M` (a power of ten in the tile's unit), coarser only where the map would not fit 32 bits."""
    if len(xyz) == 0:
        return np.zeros(3), np.full(3, 0.001)
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    offsets = np.floor((lo + hi) / 2)
    reach = np.maximum(hi - offsets, offsets - lo)
    scales = []
    for metres in (frame.scale_xy, frame.scale_xy, frame.scale_z):
        scales.append(10.0 ** np.floor(np.log10(STEP_M / metres)))
    scales = np.array(scales)
    scales[:2] = scales[:2].max()  # x and y in the same step
    while np.any(reach / scales > MAX_STEPS):
        scales = np.where(reach / scales > MAX_STEPS, scales * 10, scales)
        scales[:2] = scales[:2].max()
    if np.any(scales * np.array([frame.scale_xy, frame.scale_xy, frame.scale_z]) > 2e-3):
        log.warning("the map spans too far for millimetre steps in a LAS file: steps of %s (tile units)", scales)
    return offsets, scales
