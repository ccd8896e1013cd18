"""A tile inside a ``.tar.gz`` (the reference's ``aerialMap.tar.gz``): unpacked once into the cache
folder, keyed on the archive's SHA-256, its copy checked on every use, its size held to what a tile can be
before a byte is written."""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import tarfile
import zlib
from contextlib import suppress
from pathlib import Path

from helpers import paths
from helpers.config.bounds import human_size
from helpers.errors import SlamError

log = logging.getLogger(__name__)

# What an archive member may unpack to. Real LAZ tiles are tens to hundreds of MB, the same tile as LAS
# about ten times that: 4 GiB holds a LAS tile of over 100 million points and stops a bomb before it fills
# a disk. gzip shrinks a LAS tile about twice and a LAZ tile not at all, so a member that expands more
# than 20 times its archive is made of repeats, not of survey points.
MAX_TILE_BYTES = 4 << 30
MAX_ARCHIVE_RATIO = 20
FREE_SPACE_MARGIN = 256 << 20  # bytes left free on the cache's disk after a tile is unpacked
RECORD = "tile.json"  # beside an unpacked tile: its name, size and SHA-256 (helpers.paths.write_checked)


def extract_las(archive: Path) -> Path:
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
        forget(target_dir, target)
        raise SlamError(f"{archive.name} is not a readable .tar.gz archive ({exc.__cause__ or exc})") from None
    except SlamError:
        forget(target_dir, target)
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


def forget(folder: Path, tile: Path | None) -> None:
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
