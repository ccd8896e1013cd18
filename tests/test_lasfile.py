"""Malformed LAS/LAZ files: a small valid tile is written, one header field
(or VLR, EVLR, LAZ chunk) is damaged at a time, and reading it must end in a
SlamError that says what is wrong, within seconds, instead of hanging,
crashing the interpreter or asking for gigabytes."""

import math
import struct
import subprocess
import sys
import time
from pathlib import Path

import laspy
import numpy as np
import pytest
from laspy.vlrs.vlrlist import VLRList

from helpers.errors import SlamError
from helpers.sim.maps import height_field_from_points, read_map

N_POINTS = 300
TIME_LIMIT_S = 10  # a safety bound, not a benchmark: a damaged header once made laspy read for minutes


def write_tile(path, version: str, point_format: int, n: int = N_POINTS) -> bytes:
    """A valid tile of ``n`` random points with one VLR (and, for LAS 1.4, one EVLR)."""
    rng = np.random.default_rng(0)
    las = laspy.LasData(laspy.LasHeader(point_format=point_format, version=version))
    las.header.scales = [0.01, 0.01, 0.01]
    las.x, las.y, las.z = rng.uniform(0, 100, n), rng.uniform(0, 100, n), rng.uniform(0, 10, n)
    las.classification = rng.integers(1, 7, n)
    if path.suffix == ".las":  # laspy adds the laszip VLR to a LAZ
        las.vlrs.append(laspy.VLR("helpers test", 1, "a plain VLR", b"x" * 100))
        if version == "1.4":
            las.evlrs = VLRList([laspy.VLR("helpers test", 2, "a plain EVLR", b"y" * 100)])
    las.write(path)
    return path.read_bytes()


TILES = {  # name: (version, point format)
    "v12.las": ("1.2", 3),
    "v12.laz": ("1.2", 3),
    "v14.las": ("1.4", 6),
    "v14.laz": ("1.4", 6),
}


@pytest.fixture(scope="module")
def tiles(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tiles")
    return {name: write_tile(folder / name, *spec) for name, spec in TILES.items()}


def _u16(b, at):
    return struct.unpack_from("<H", b, at)[0]


def _u32(b, at):
    return struct.unpack_from("<I", b, at)[0]


def _put(fmt: str, at, value):
    """A damage: write ``value`` with struct format ``fmt`` at byte ``at`` (or at ``at(data)``)."""

    def damage(b: bytearray):
        struct.pack_into("<" + fmt, b, at(b) if callable(at) else at, value)

    return damage


def _first_vlr(b):
    return _u16(b, 94)  # the header size: the first VLR follows the header


def _points(b):
    return _u32(b, 96)  # offset to the point data


def _laszip(b):
    return _first_vlr(b) + 54  # the data of the laszip VLR (the only VLR laspy writes into a LAZ)


def _chunk_table(b):
    return struct.unpack_from("<q", b, _points(b))[0]


def _first_layer_size(b):
    """The first layer size of the first chunk of a layered (LAS 1.4) LAZ:
    after the chunk table offset, the raw first point and the point count."""
    return _points(b) + 8 + _u16(b, 105) + 4


def _truncate(b: bytearray):
    del b[len(b) // 2 :]


def _far_points(b: bytearray):
    """Points that start 70 MB into the file, after a gap that would be VLRs."""
    b.extend(bytes(70 << 20))
    struct.pack_into("<I", b, 96, 70 << 20)


def _evlr_start(b):
    return struct.unpack_from("<Q", b, 235)[0]


CASES = [
    # (tile, what is damaged, damage, expected message)
    ("v12.las", "signature", _put("4s", 0, b"LASX"), "does not start with a LAS header"),
    ("v12.las", "version major", _put("B", 24, 2), r"version 2\.2 is not LAS 1\.0 to 1\.4"),
    ("v12.las", "version minor", _put("B", 25, 9), r"version 1\.9 is not LAS 1\.0 to 1\.4"),
    ("v12.las", "header size too small", _put("H", 94, 100), "header takes 227 bytes, this one claims 100"),
    ("v12.las", "header size past the points", _put("H", 94, 60000), "points start at byte"),
    ("v12.las", "offset to points past the end", _put("I", 96, 0xFFFFFFFF), "points start at byte 4,294,967,295"),
    ("v12.las", "offset to points inside the VLR", _put("I", 96, 300), "its VLRs run past the start of its points"),
    ("v12.las", "70 MB before the points", _far_points, "its 70 MiB of VLRs before the points exceed 64 MiB"),
    ("v12.las", "garbage VLR count", _put("I", 100, 0xFFFFFFFF), "announces 4,294,967,295 VLRs"),
    ("v12.las", "one VLR too many", _put("I", 100, 2), "its VLRs run past the start of its points"),
    ("v12.las", "VLR record length", _put("H", lambda b: _first_vlr(b) + 20, 60000), "VLRs run past"),
    ("v12.las", "point format", _put("B", 104, 42), "point format 42 is not one of LAS's 0-10"),
    ("v12.las", "record length", _put("H", 105, 10), "10-byte points are shorter than those of point format 3"),
    ("v12.las", "huge point count", _put("I", 107, 0xFFFFFFFF), "truncated: its 4,294,967,295 points need"),
    ("v12.las", "no points", _put("I", 107, 0), "holds no points"),
    ("v12.las", "zero scale", _put("d", 131, 0.0), "scale factors"),
    ("v12.las", "NaN scale", _put("d", 139, math.nan), "scale factors"),
    ("v12.las", "infinite offset", _put("d", 155, math.inf), "offsets"),
    ("v12.las", "NaN bound", _put("d", 179, math.nan), "bounds"),
    ("v12.las", "min x above max x", _put("d", 187, 1e9), "bounds"),
    ("v12.las", "truncated file", _truncate, "truncated"),
    ("v14.las", "huge 64-bit point count", _put("Q", 247, 2**60), "truncated"),
    ("v14.las", "garbage EVLR count", _put("I", 243, 0xFFFFFFFF), "EVLRs from byte"),
    ("v14.las", "EVLR inside the points", _put("Q", 235, 400), "EVLRs from byte 400 do not fit"),
    ("v14.las", "EVLR record length", _put("Q", lambda b: _evlr_start(b) + 20, 2**40), "EVLR 1 of 1 runs past"),
    ("v14.las", "truncated file", _truncate, "truncated"),
    ("v12.laz", "huge point count", _put("I", 107, 0xFFFFFFFF), "far more than a"),
    ("v12.laz", "compressed bit on a format", _put("B", 104, 0x80 | 42), "point format 42"),
    ("v12.laz", "garbage VLR count", _put("I", 100, 0xFFFFFFFF), "announces 4,294,967,295 VLRs"),
    ("v12.laz", "no laszip VLR", _put("H", lambda b: _first_vlr(b) + 18, 1), "no laszip VLR"),
    ("v12.laz", "laszip VLR without items", _put("H", lambda b: _laszip(b) + 32, 0), "laszip VLR"),
    ("v12.laz", "laszip items of another size", _put("H", lambda b: _laszip(b) + 36, 99), "laszip VLR describes"),
    ("v12.laz", "laszip chunk size 0", _put("I", lambda b: _laszip(b) + 12, 0), "LAZ chunks of 0 points"),
    ("v12.laz", "huge laszip chunk size", _put("I", lambda b: _laszip(b) + 12, 700_000_000), "LAZ chunks of"),
    ("v12.laz", "chunk table past the end", _put("q", _points, 10**15), "chunk table at byte"),
    ("v12.laz", "garbage chunk count", _put("I", lambda b: _chunk_table(b) + 4, 0xFFFFFFFF), "chunk table"),
    ("v12.laz", "truncated file", _truncate, "chunk table"),
    ("v14.laz", "garbage 64-bit point count", _put("Q", 247, 2**60), "far more than a"),
    ("v14.laz", "huge layer size", _put("I", _first_layer_size, 0x7FFFFFFF), "layers of its LAZ chunks run past"),
    ("v14.laz", "truncated file", _truncate, "chunk table"),
]


@pytest.mark.parametrize(("tile", "what", "damage", "message"), CASES, ids=[f"{c[0]}: {c[1]}" for c in CASES])
def test_a_damaged_tile_is_refused_quickly(tiles, tmp_path, tile, what, damage, message):
    data = bytearray(tiles[tile])
    damage(data)
    assert data != tiles[tile], f"the damage to the {what} changed nothing"
    path = tmp_path / f"damaged{tile[-4:]}"
    path.write_bytes(data)
    start = time.perf_counter()
    with pytest.raises(SlamError, match=message):
        read_map(path)
    assert time.perf_counter() - start < TIME_LIMIT_S


@pytest.mark.parametrize("tile", TILES)
def test_the_undamaged_tiles_are_read(tiles, tmp_path, tile):
    path = tmp_path / tile
    path.write_bytes(tiles[tile])
    assert len(read_map(path).points) == N_POINTS


def test_a_tile_in_several_layered_chunks_is_read_and_each_chunk_is_checked(tmp_path):
    """LAS 1.4 LAZ with colour and an extra byte per point, in three chunks
    of at most 50,000 points: the damage is in the second chunk's layers."""
    path = tmp_path / "chunks.laz"
    las = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    las.add_extra_dim(laspy.ExtraBytesParams(name="amplitude", type=np.uint8))
    n = 120_000
    rng = np.random.default_rng(1)
    las.x, las.y, las.z = rng.uniform(0, 100, n), rng.uniform(0, 100, n), rng.uniform(0, 10, n)
    las.write(path)
    assert len(read_map(path).points) == n
    data = bytearray(path.read_bytes())
    record, layers = _u16(data, 105), 9 + 1 + 1  # Point14, RGB14 and one BYTE14 layer
    second = _points(data) + 8
    second += record + 4 + 4 * layers + sum(struct.unpack_from(f"<{layers}I", data, second + record + 4))
    struct.pack_into("<I", data, second + record + 4, 0x7FFFFFFF)
    path.write_bytes(data)
    with pytest.raises(SlamError, match="layers of its LAZ chunks run past"):
        read_map(path)


def test_the_real_tile_still_passes_the_checks(autzen):
    assert len(read_map(autzen).points) == 110_000


def test_a_garbage_vlr_count_gives_one_error_line_on_the_command_line(tiles, tmp_path):
    bad = tmp_path / "bad.las"
    data = bytearray(tiles["v12.las"])
    struct.pack_into("<I", data, 100, 0xFFFFFFFF)
    bad.write_bytes(data)
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-m", "helpers", "dataset", "--map", str(bad), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,  # laspy alone read such a file for over a minute
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: bad.las is not a readable LAS/LAZ file"), result.stderr
    assert "4,294,967,295 VLRs" in lines[0]
    assert not out.exists()


def test_a_map_too_wide_for_its_grid_is_refused_before_allocating():
    points = np.array([[0.0, 0.0, 0.0], [1e7, 1e7, 0.0], [5.0, 5.0, 1.0]])  # one wild point 14,000 km away
    start = time.perf_counter()
    with pytest.raises(SlamError, match=r"the map spans 10000001 x 10000001 m: 1e\+14 cells .*limit is 50,000,000"):
        height_field_from_points(points, np.zeros(3, np.uint8), cell=1.0)
    assert time.perf_counter() - start < TIME_LIMIT_S


def test_a_tile_compressed_point_by_point_is_read(tmp_path):
    """laszip's first compressor (LAZ 1.0) has no chunks and no chunk table: the real downtown tile beside the
    repository is written so; a chunked tile relabelled so is refused in one line, never a crash."""
    real = Path(__file__).resolve().parents[2] / "shared" / "data" / "urban_toronto.laz"
    if real.exists():
        assert len(read_map(real).points) == 213_093
    path = tmp_path / "relabelled.laz"
    las = laspy.LasData(laspy.LasHeader(point_format=1, version="1.2"))
    las.x, las.y, las.z = np.arange(1000.0), np.arange(1000.0), np.zeros(1000)
    las.write(path)
    data = bytearray(path.read_bytes())
    struct.pack_into("<H", data, _laszip(data), 1)  # the compressor: pointwise
    path.write_bytes(data)
    try:
        points = read_map(path).points
    except SlamError as error:
        assert "not a readable LAS/LAZ file" in str(error)
    else:
        assert points.shape[1] == 3
