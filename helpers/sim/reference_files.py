"""The default flight written in the reference's own file formats.

The reference workflow starts from two files: ``aerialMap.tar.gz``, a LAZ
aerial tile inside a gzipped tar, and ``gTruthWayPoints.mat``, a MAT-file
whose ``gTruthTraj`` holds the flight's waypoints (N x 2, map XY). This
module writes the embedded default in exactly those formats, so that a
learner sees what their own files must look like, and so that the files in
the checkout's ``data/`` come from the package and nowhere else::

    python -m helpers.sim.reference_files data        # writes data/aerialMap.tar.gz, data/gTruthWayPoints.mat

The tile holds one point per 1 m cell of the default scene, at the cell's
centre and height, with the cell's class as an ASPRS code; read back through
:func:`helpers.sim.maps.read_map` it gives the scene's height field again (the
heights rounded to the tile's Z scale). Every byte is fixed (dates, names,
owners, gzip header), so writing twice gives the same files and a test can
compare them with the committed ones.
"""

from __future__ import annotations

import argparse
import datetime
import gzip
import io
import sys
import tarfile
from pathlib import Path

import numpy as np

from helpers import paths
from helpers.errors import SlamError
from helpers.sim.scene import BUILDING, GROUND, ROAD, TREE, WATER, HeightField, default_scene
from helpers.sim.waypoints import read_waypoints

MAP_FILE, TILE_NAME, WAYPOINTS_FILE = "aerialMap.tar.gz", "aerialMap.laz", "gTruthWayPoints.mat"
CLASS_CODES = {GROUND: 2, ROAD: 11, WATER: 9, BUILDING: 6, TREE: 5}  # scene label -> ASPRS class (mapio reads back)
SCALES = (0.01, 0.01, 0.001)  # m per LAS integer unit: cell centres fall on 0.5 m, heights to the millimetre
SYSTEM_ID = "helpers default scene"  # the LAS header's system identifier: how we recognise a tile we wrote
CREATION_DATE = datetime.date(2026, 1, 1)  # fixed, so that the file does not change with the day it is written
# A local coordinate system: the scene lies nowhere on Earth, but its units are metres and the reader must know.
WKT = (
    'LOCAL_CS["helpers default scene (procedural), metres",LOCAL_DATUM["procedural scene",0],'
    'UNIT["metre",1,AUTHORITY["EPSG","9001"]],AXIS["x",EAST],AXIS["y",NORTH]]'
)
# The committed data/ files carry this text as their writer's mark, under the module's name of when they were made.
MAT_HEADER = b"MATLAB 5.0 MAT-file, written by helpers.datafiles: the default flight's waypoints"
MAT_TEXT_BYTES = 116  # the descriptive text at the head of a MAT-file, padded with spaces


def tile_bytes(field: HeightField) -> bytes:
    """The height field as a LAZ file (LAS 1.4, point format 6): one point
    per valid cell, its class as an ASPRS code, a WKT record saying metres."""
    import laspy
    from laspy.vlrs.known import WktCoordinateSystemVlr

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales, header.offsets = np.array(SCALES), np.zeros(3)
    header.system_identifier, header.creation_date = SYSTEM_ID, CREATION_DATE
    header.global_encoding.wkt = True
    header.vlrs.append(WktCoordinateSystemVlr(WKT))
    las = laspy.LasData(header)
    valid = field.valid
    x, y = field.grid()
    las.x, las.y, las.z = x[valid], y[valid], field.z[valid]
    codes = np.zeros(256, np.uint8)
    for label, code in CLASS_CODES.items():
        codes[label] = code
    las.classification = codes[field.labels[valid]]
    buffer = io.BytesIO()
    las.write(buffer, do_compress=True)
    return buffer.getvalue()


def archive_bytes(laz: bytes, member: str = TILE_NAME) -> bytes:
    """``laz`` as the one member of a .tar.gz whose headers carry no date,
    owner or file name (so the same tile gives the same archive)."""
    tar_buffer = io.BytesIO()
    with tarfile.open(fileobj=tar_buffer, mode="w", format=tarfile.USTAR_FORMAT) as tar:
        info = tarfile.TarInfo(member)
        info.size, info.mtime, info.mode = len(laz), 0, 0o644
        info.uid = info.gid = 0
        info.uname = info.gname = ""
        tar.addfile(info, io.BytesIO(laz))
    out = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", fileobj=out, mtime=0, compresslevel=9) as gz:
        gz.write(tar_buffer.getvalue())
    return out.getvalue()


def waypoints_bytes(xy: np.ndarray) -> bytes:
    """An N x 2 ``gTruthTraj`` as a MAT-file (level 5, uncompressed), with a
    fixed header text instead of scipy's, which holds the time of writing."""
    from scipy.io import savemat

    buffer = io.BytesIO()
    savemat(buffer, {"gTruthTraj": np.asarray(xy, np.float64)[:, :2]}, do_compression=False)
    data = bytearray(buffer.getvalue())
    data[:MAT_TEXT_BYTES] = MAT_HEADER.ljust(MAT_TEXT_BYTES)
    return bytes(data)


def reference_files() -> dict[str, bytes]:
    """File name -> bytes of the two reference-format files of the default flight."""
    from helpers.sim.dataset import DEFAULT_WAYPOINTS

    return {
        MAP_FILE: archive_bytes(tile_bytes(default_scene())),
        WAYPOINTS_FILE: waypoints_bytes(read_waypoints(DEFAULT_WAYPOINTS)),
    }


def write_reference_files(folder: str | Path) -> list[Path]:
    """Write ``aerialMap.tar.gz`` and ``gTruthWayPoints.mat`` into ``folder``.

    A file of that name is replaced only if this module wrote it (a user's
    own ``aerialMap.tar.gz``, the reference's for instance, is refused before
    anything is written); each file is written whole or not at all."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise SlamError(f"{folder} exists and is not a folder")
    targets = [folder / MAP_FILE, folder / WAYPOINTS_FILE]
    for target in targets:
        if target.exists() and not written_here(target):
            raise SlamError(f"{target} exists and was not written by helpers.sim.reference_files: move it away first")
    files = reference_files()
    folder.mkdir(parents=True, exist_ok=True)
    for target in targets:
        paths.write_atomically(target, lambda out, data=files[target.name]: out.write(data))
    return targets


def written_here(path: Path) -> bool:
    """Whether ``path`` is a file this module wrote (its MAT header text, or
    a tile in the archive whose LAS system identifier is ours)."""
    if not path.is_file():
        return False
    if path.name == WAYPOINTS_FILE:
        with open(path, "rb") as f:
            return f.read(len(MAT_HEADER)) == MAT_HEADER
    try:
        with tarfile.open(path, "r:gz") as tar:
            head = tar.extractfile(TILE_NAME).read(58)
    except (tarfile.TarError, OSError, EOFError, KeyError, AttributeError):
        return False
    return head[:4] == b"LASF" and head[26:58].rstrip(b"\0").decode("ascii", "replace") == SYSTEM_ID


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m helpers.sim.reference_files",
        description="write the default flight in the reference's file formats (aerialMap.tar.gz, gTruthWayPoints.mat)",
    )
    parser.add_argument("folder", help="where to write them (the checkout's data/)")
    args = parser.parse_args(argv)
    try:
        for path in write_reference_files(args.folder):
            print(f"wrote {path} ({path.stat().st_size:,} bytes)")
    except (SlamError, OSError) as exc:  # OSError: a folder that cannot be written, a full disk
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
