"""Inputs built to hurt (issue 19): archive and MAT-file bombs, damaged
archives, LAS headers whose numbers overflow, CSV files with a byte-order
mark. Each input is made inside the test, small on disk (a bomb is streamed
zeros, never kept), and each must end in one SlamError within seconds,
leaving nothing behind in the cache."""

import io
import struct
import tarfile
import time
import tracemalloc
import warnings
import zlib

import laspy
import numpy as np
import pytest

from helpers.__main__ import main
from helpers.errors import SlamError
from helpers.sim.maps import read_map
from helpers.sim.waypoints import MAX_WAYPOINTS, read_waypoints


def _small_las(path, n=40):
    """A LAS (or LAZ, by its name) tile of n x n points one metre apart, random heights."""
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    las.header.scales = [0.01, 0.01, 0.01]
    las.x, las.y, las.z = x.ravel(), y.ravel(), np.random.default_rng(0).uniform(0, 20, x.size)
    las.write(path)
    return path


def _zeros(n: int, chunk: int = 1 << 20):
    while n > 0:
        yield bytes(min(n, chunk))
        n -= chunk


def _tar_gz(path, name: str, declared: int, chunks) -> None:
    """A .tar.gz with one member ``name`` whose header declares ``declared``
    bytes, followed by the bytes ``chunks`` yields (which may be fewer: a
    header that lies), compressed as they stream."""
    info = tarfile.TarInfo(name)
    info.size = declared
    with open(path, "wb") as raw:
        packer = zlib.compressobj(9, zlib.DEFLATED, 31)  # 31: a gzip wrapper
        raw.write(packer.compress(info.tobuf(format=tarfile.GNU_FORMAT)))
        written = 0
        for chunk in chunks:
            raw.write(packer.compress(chunk))
            written += len(chunk)
        raw.write(packer.compress(bytes(-written % 512) + bytes(1024)))  # padding, then the end-of-archive blocks
        raw.write(packer.flush())


def _cache_files(tmp_path):
    cache = tmp_path / "cache"  # HELPERS_CACHE points there (tests/conftest.py)
    return sorted(str(p.relative_to(cache)) for p in cache.rglob("*") if p.name != "maps") if cache.exists() else []


def _refused_quickly(path, message):
    start = time.perf_counter()
    with pytest.raises(SlamError, match=message):
        read_map(path)
    assert time.perf_counter() - start < 5


# Archives ---------------------------------------------------------------------


def test_a_member_that_claims_3_gb_is_refused_before_extracting(tmp_path):
    archive = tmp_path / "bomb.tar.gz"
    _tar_gz(archive, "tile.laz", 3 * 10**9, _zeros(2 << 20))  # the header says 3 GB, 2 MB follow
    _refused_quickly(archive, r"tile\.laz .*2\.79 GiB.*the limit is")
    assert _cache_files(tmp_path) == []


def test_zeros_that_expand_far_beyond_a_real_tile_are_refused_and_nothing_is_kept(tmp_path):
    archive = tmp_path / "bomb.tar.gz"
    _tar_gz(archive, "tile.las", 20 << 20, _zeros(20 << 20))  # 20 MiB of zeros in about 20 kB
    assert archive.stat().st_size < 100_000
    _refused_quickly(archive, r"expands .* times")
    assert _cache_files(tmp_path) == []


def test_a_bomb_on_the_command_line_is_one_error_line_within_seconds(tmp_path, capsys):
    archive = tmp_path / "bomb.tar.gz"
    _tar_gz(archive, "tile.laz", 200 << 20, _zeros(200 << 20))  # 200 MiB of zeros in about 200 kB
    start = time.perf_counter()
    assert main(["dataset", "--map", str(archive), "--out", str(tmp_path / "o")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: tile.laz in bomb.tar.gz expands to 200 MiB"), lines
    assert time.perf_counter() - start < 5
    assert not (tmp_path / "o").exists() and _cache_files(tmp_path) == []


def test_the_size_cap_holds_while_streaming(tmp_path, monkeypatch):
    import helpers.sim.archive

    monkeypatch.setattr(helpers.sim.archive, "MAX_TILE_BYTES", 1 << 20)
    archive = tmp_path / "big.tar.gz"
    noise = np.random.default_rng(0).bytes(2 << 20)  # does not compress: passes the ratio check
    _tar_gz(archive, "tile.las", len(noise), [noise])
    _refused_quickly(archive, r"tile\.las .*2 MiB.*the limit is 1 MiB")
    assert _cache_files(tmp_path) == []


def test_an_archive_that_does_not_fit_the_free_space_is_refused(tmp_path, monkeypatch):
    import shutil

    tile = _small_las(tmp_path / "tile.las")
    archive = tmp_path / "tile.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        tar.add(tile, arcname="tile.las")
    real = shutil.disk_usage
    monkeypatch.setattr(shutil, "disk_usage", lambda p: real(p)._replace(free=1000))
    _refused_quickly(archive, r"free")
    assert _cache_files(tmp_path) == []


def test_a_member_that_is_not_a_tile_is_not_left_in_the_cache(tmp_path):
    archive = tmp_path / "junk.tar.gz"
    junk = b"not a point cloud " * 100
    _tar_gz(archive, "tile.laz", len(junk), [junk])
    _refused_quickly(archive, "not a readable LAS/LAZ file")
    assert _cache_files(tmp_path) == []


def test_a_damaged_deflate_stream_gives_one_error_line(tmp_path, capsys):
    tile = _small_las(tmp_path / "tile.las")
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as tar:
        tar.add(tile, arcname="tile.las")
    good = buffer.getvalue()
    for at in range(len(good) // 4, len(good)):  # damage in the data (not the first header) that zlib trips on
        damaged = bytearray(good)
        damaged[at] ^= 0xFF
        try:
            zlib.decompressobj(31).decompress(bytes(damaged[: at + 64]))
        except zlib.error:
            break
    archive = tmp_path / "damaged.tar.gz"
    archive.write_bytes(bytes(damaged))
    assert main(["dataset", "--map", str(archive), "--out", str(tmp_path / "o")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: damaged.tar.gz is not a readable .tar.gz"), lines
    assert not (tmp_path / "o").exists() and _cache_files(tmp_path) == []


def test_an_upper_case_member_is_extracted_once(tmp_path, monkeypatch):
    tile = _small_las(tmp_path / "tile.laz")
    archive = tmp_path / "tile.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        tar.add(tile, arcname="TILE.LAZ")
    first = read_map(archive)
    assert [name.rsplit("/", 1)[-1] for name in _cache_files(tmp_path)[1:]] == ["TILE.LAZ", "tile.json"]

    def no_second_extraction(*args, **kwargs):
        raise AssertionError("the archive was opened again")

    monkeypatch.setattr(tarfile, "open", no_second_extraction)
    np.testing.assert_array_equal(read_map(archive).points, first.points)


# LAS headers --------------------------------------------------------------------

LAS_SCALES, LAS_OFFSETS = 131, 155  # byte of the x scale and of the x offset in a LAS header


@pytest.mark.parametrize(
    ("at", "value", "message"),
    [
        (LAS_OFFSETS, 1e308, r"offsets .* within"),
        (LAS_OFFSETS, -1e300, r"offsets .* within"),
        (LAS_SCALES, 1e300, r"scale factors .* from 1e-09 to"),
        (LAS_SCALES, 1e-320, r"scale factors .* from 1e-09 to"),
        (LAS_SCALES, 0.0, "scale factors"),
        (LAS_SCALES, float("nan"), "scale factors"),
        (LAS_SCALES, float("inf"), "scale factors"),
    ],
)
def test_las_scales_and_offsets_that_overflow_are_refused_without_warnings(tmp_path, at, value, message):
    path = _small_las(tmp_path / "tile.las")
    header = bytearray(path.read_bytes())
    struct.pack_into("<d", header, at, value)
    path.write_bytes(bytes(header))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning on stderr is a failure
        with pytest.raises(SlamError, match=message):
            read_map(path)


# MAT-files ------------------------------------------------------------------------


def _mat_bomb(path, shape: tuple[int, ...]) -> None:
    """A MAT-file (v5) whose compressed variable gTruthTraj is a double
    matrix of ``shape`` holding zeros, streamed: it never exists in memory."""
    nbytes = 8 * int(np.prod(shape))
    name = b"gTruthTraj"
    dims = struct.pack(f"<{len(shape)}i", *shape)
    body = (
        struct.pack("<II", 6, 8) + struct.pack("<II", 6, 0)  # array flags: a double matrix
        + struct.pack("<II", 5, len(dims)) + dims + bytes(-len(dims) % 8)  # dimensions (miINT32)
        + struct.pack("<II", 1, len(name)) + name + bytes(-len(name) % 8)  # name (miINT8)
        + struct.pack("<II", 9, nbytes)  # the real part (miDOUBLE), its zeros follow
    )  # fmt: skip
    packer = zlib.compressobj(9)
    compressed = [packer.compress(struct.pack("<II", 14, len(body) + nbytes) + body)]
    compressed += [packer.compress(chunk) for chunk in _zeros(nbytes)]
    compressed.append(packer.flush())
    head = b"MATLAB 5.0 MAT-file, made by a test".ljust(116) + bytes(8) + struct.pack("<H2s", 0x0100, b"IM")
    size = sum(len(c) for c in compressed)
    path.write_bytes(head + struct.pack("<II", 15, size) + b"".join(compressed))


@pytest.mark.parametrize(
    ("shape", "message"),
    [
        ((5_000_000, 2), f"holds 5,000,000 waypoints; the limit is {MAX_WAYPOINTS:,}"),
        ((2, 5_000_000), r"N x 2 or N x 3 .* got shape \(2, 5000000\)"),
        ((1000, 1000, 5), r"N x 2 or N x 3 .* got shape \(1000, 1000, 5\)"),
    ],
)
def test_a_mat_bomb_is_refused_from_its_header_before_its_data_is_read(tmp_path, shape, message):
    path = tmp_path / "bomb.mat"
    _mat_bomb(path, shape)
    assert path.stat().st_size < 200_000  # 80 MB of zeros
    tracemalloc.start()
    try:
        with pytest.raises(SlamError, match=message):
            read_waypoints(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 10 << 20, f"{peak / 2**20:.0f} MiB taken to refuse it"


def test_a_hand_made_mat_file_of_the_right_shape_is_read(tmp_path):
    path = tmp_path / "flight.mat"
    _mat_bomb(path, (4, 3))  # the writer above makes real MAT-files: small ones load
    np.testing.assert_array_equal(read_waypoints(path), np.zeros((4, 3)))


# CSV ------------------------------------------------------------------------------


@pytest.mark.parametrize("header", ["", "x,y\n"])
def test_a_byte_order_mark_keeps_the_first_waypoint(tmp_path, header):
    path = tmp_path / "flight.csv"
    path.write_bytes(b"\xef\xbb\xbf" + (header + "1,2\n3,4\n").encode())
    np.testing.assert_array_equal(read_waypoints(path), [[1, 2], [3, 4]])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("x,y\n1,2\nfoo,bar\n3,4\n", r"flight\.csv line 3: .*'foo,bar'"),
        ("1,2\n\nx,y\n", r"flight\.csv line 3: .*'x,y'"),  # a header anywhere but first is an error
        ("x,y\nz,w\n1,2\n", r"line 2: every line must be x,y or x,y,z numbers"),
    ],
)
def test_a_row_that_is_not_numbers_is_named_never_dropped(tmp_path, text, message):
    path = tmp_path / "flight.csv"
    path.write_text(text)
    with pytest.raises(SlamError, match=message):
        read_waypoints(path)
