"""A LAS/LAZ file checked against its own header before laspy reads it.

laspy believes the counts and offsets a header announces: a garbage VLR
count makes it read for minutes, and lazrs aborts the process on some
damaged LAZ chunk tables. :func:`check_las_file` parses the public header
block, walks the chains of variable-length records and, for LAZ, checks the
laszip record and the chunk table, so that every malformed file ends in one
:class:`~helpers.errors.SlamError` within seconds.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from helpers.config.bounds import human_size
from helpers.errors import SlamError

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
POINTWISE = 1  # laszip's first compressor (LAZ 1.0): the points one after the other, with no chunk table
LAYERED, LAYERS = 3, {10: 9, 11: 1, 12: 2}  # laszip's layered compressor; layers per item (BYTE14: one a byte)
MAX_VLR_BYTES = 1 << 26  # real tiles hold kilobytes of VLRs; laspy reads them all into memory
# Scales and offsets that keep every coordinate a record can hold (offset + scale x a 32-bit integer) finite
# and its differences exact enough: real tiles use steps of a millimetre to a centimetre and offsets of
# map coordinates (millions of metres or feet at most).
SCALE_RANGE = (1e-9, 100.0)  # units per integer step, in absolute value
MAX_OFFSET = 1e10  # units


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
        low, high = SCALE_RANGE
        if not all(low <= abs(s) <= high for s in scales):  # NaN fails too
            raise bad(f"its scale factors {scales.tolist()} must be finite, from {low:g} to {high:g} in absolute value")
        if not all(abs(o) <= MAX_OFFSET for o in offsets):
            raise bad(f"its offsets {offsets.tolist()} must be finite and within +-{MAX_OFFSET:g}")
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
    if compressor == POINTWISE:
        return  # laszip's first format: the points compressed one after the other, no chunks, no chunk table
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
