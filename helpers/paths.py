"""Where the package keeps its data and its caches.

The default flight ships inside the package (``helpers/data/``, read through
:mod:`importlib.resources`), so an installed package needs no checkout. Caches
(the default run, unpacked map tiles) go to :func:`cache_dir`:
``$HELPERS_CACHE`` if set, else ``$XDG_CACHE_HOME/aerial-lidar-slam``
(``~/.cache/aerial-lidar-slam`` by default). Deleting that folder is always safe.
Every entry in it is keyed on its content and checked when read; what a killed
writer left there goes at the next start (:func:`sweep_cache`), and the oldest
entries go once the folder holds more than :data:`CACHE_LIMIT` (:func:`evict`).

The commands' output folders are checked and written by :mod:`helpers.outdir`.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import logging
import os
import re
import shutil
import socket
import stat
from collections.abc import Callable
from contextlib import contextmanager, suppress
from importlib import resources
from pathlib import Path
from typing import BinaryIO

from helpers.errors import SlamError

log = logging.getLogger(__name__)

DATA = Path(resources.files("helpers").joinpath("data"))  # files shipped in the package
CACHE_VARIABLE = "HELPERS_CACHE"
CACHE_NAME = "aerial-lidar-slam"  # the folder under the user's cache folder
CACHE_LIMIT = 5 << 30  # bytes of entries the cache folder keeps: a 4 GiB tile and a dozen 80 MB runs
# A file or folder being written, named ".<name>.helpers-<kind>.<host>.<pid>.<random>": once that process is
# gone (a SIGKILL, the OOM killer) the next start on the same host knows it is a leftover.
TEMPORARY = re.compile(
    r"\.(?P<name>.+)\.helpers-(?P<kind>partial|previous|probe)\.(?P<host>[A-Za-z0-9_-]+)\.(?P<pid>[0-9]+)\.[0-9a-f]{8}"
)
# What versions before the checked cache left: pickled runs and their temporary files, temporary tiles.
LEGACY = re.compile(r"(\.?slam-[0-9a-f]{16}\.pkl(\.[a-z0-9_]{8})?)|(\..+\.(las|laz|LAS|LAZ)\.[a-z0-9_]{8})")
ENTRY = re.compile(r"[a-z]+-[0-9a-f]{16,64}|[0-9a-f]{16,64}")  # the names of our entries: slam-<key>.*, maps/<key>/
_SAID: set[str] = set()  # one-line notices given once per process


def input_file(path: str | Path, what: str) -> Path:
    """``path`` if it is a regular file (a link to one included), else a
    :class:`SlamError` saying what it is: missing, a folder, a broken link or
    a loop of links, or a named pipe or device, which would block or never
    end when read."""
    path = Path(path)
    if path.is_file():
        return path
    if not os.path.lexists(path):
        raise SlamError(f"{what} not found: {path}")
    try:
        mode = path.stat().st_mode
    except OSError:  # a link to nothing, or links that point at each other
        raise SlamError(f"{what} {path} is a broken link or a loop of links, not a file") from None
    kind = "a folder" if stat.S_ISDIR(mode) else "a named pipe" if stat.S_ISFIFO(mode) else "a device or socket"
    raise SlamError(f"{what} {path} is {kind}, not a file")


def cache_dir() -> Path:
    """The cache folder: ``$HELPERS_CACHE`` if set, else
    ``$XDG_CACHE_HOME/aerial-lidar-slam`` (``~/.cache/aerial-lidar-slam``),
    checked as ``--out`` is: a ``~`` the shell did not expand or an empty
    ``HOME`` is a :class:`SlamError`; a relative path is taken from the folder
    the user started in (``$PWD``: a notebook's kernel runs in ``notebooks/``),
    and said once."""
    if os.environ.get(CACHE_VARIABLE):
        return _place(os.environ[CACHE_VARIABLE], f"${CACHE_VARIABLE}")
    if os.environ.get("XDG_CACHE_HOME"):
        return _place(os.environ["XDG_CACHE_HOME"], "$XDG_CACHE_HOME") / CACHE_NAME
    if "HOME" in os.environ and not os.environ["HOME"].strip():
        raise SlamError(
            f"HOME is empty, which would put the cache folder at /.cache: set HOME, or ${CACHE_VARIABLE} to a folder"
        )
    return _place(str(Path.home()), "$HOME") / ".cache" / CACHE_NAME


def _place(value: str, variable: str) -> Path:
    """The folder an environment variable names, absolute."""
    path = Path(value)
    if path.parts and path.parts[0].startswith("~"):
        raise SlamError(
            f"{variable}={value} starts with {path.parts[0]}, which the shell did not expand (it was quoted, or "
            f"followed '='): set it to {os.path.expanduser(path.parts[0])}{value[len(path.parts[0]) :]}"
        )
    if path.is_absolute():
        return path
    start = os.environ.get("PWD", "")
    start = start if os.path.isabs(start) and os.path.isdir(start) else os.getcwd()
    resolved = Path(os.path.normpath(os.path.join(start, path)))
    notice = f"{variable}={value} is a relative path: the cache folder is {resolved} (from {start})"
    if notice not in _SAID:
        _SAID.add(notice)
        log.warning(notice)
    return resolved


def host_name() -> str:
    """This machine's name as a temporary name carries it: a pid means something only on its own host."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname().split(".")[0])[:20] or "host"  # short paths


def temporary_name(name: str, kind: str) -> str:
    """A new name of :data:`TEMPORARY`'s pattern for a ``kind`` of temporary copy of ``name``."""
    return f".{name}.helpers-{kind}.{host_name()}.{os.getpid()}.{os.urandom(4).hex()}"


def process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process, or a pid we cannot ask about: alive
        return True
    return True


def dead_temporary(name: str) -> re.Match | None:
    """The :data:`TEMPORARY` match of ``name`` if a process of this host wrote it and is gone, else None."""
    match = TEMPORARY.fullmatch(name)
    if match and match["host"] == host_name() and not process_alive(int(match["pid"])):
        return match
    return None


@contextmanager
def locked(folder: str | Path, shared: bool = False):
    """A lock on ``folder`` itself (flock on the directory: no lock file to leave behind), shared or exclusive."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def write_atomically(path: str | Path, write: Callable[[BinaryIO], object]) -> None:
    """Write a file all or nothing: ``write(f)`` fills a temporary file of its
    own beside ``path`` (named as :data:`TEMPORARY` says, so that what a killed
    writer leaves is known), which then replaces ``path`` in one step. Readers
    see the old file or the new one, never a part, even with several writers
    at once; the temporary file is removed if ``write`` fails."""
    path = Path(path)
    temporary = path.parent / temporary_name(path.name, "partial")
    fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


class Damaged(Exception):
    """A cache entry that failed its check; the message says how."""


def write_checked(path: Path, write: Callable[[BinaryIO], object], record: dict) -> None:
    """Write ``path`` all or nothing (:func:`write_atomically`), then its
    record beside it (:func:`record_of`): ``record`` with the file's name,
    size and SHA-256, which :func:`read_checked` verifies."""
    digest = hashlib.sha256()
    write_atomically(path, lambda f: write(_Digesting(f, digest)))
    record = {**record, "file": path.name, "bytes": path.stat().st_size, "sha256": digest.hexdigest()}
    write_atomically(record_of(path), lambda f: f.write(json.dumps(record, indent=1).encode()))


def record_of(path: Path) -> Path:
    """The record :func:`write_checked` writes beside ``path``: ``<stem>.json``."""
    return path.with_name(f"{path.stem}.json")


def read_checked(record: Path, expected: dict, load: bool = True) -> tuple[Path, bytes | None] | None:
    """The file ``record`` describes, and its bytes if ``load``, once the
    record holds ``expected``'s values and the file its size and SHA-256;
    None without a record, :class:`Damaged` saying what failed otherwise. The
    bytes returned are the bytes checked."""
    try:
        described = json.loads(record.read_bytes())
        wrong = sorted(key for key, value in expected.items() if described.get(key) != value)
        path = record.parent / Path(described["file"]).name
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise Damaged(f"{record.name} cannot be read: {_reason(exc)}") from None
    if wrong:
        raise Damaged(f"{record.name} records another {', '.join(wrong)}")
    try:
        with open(path, "rb") as f:
            data = f.read() if load else None
            size = len(data) if load else os.fstat(f.fileno()).st_size
            digest = hashlib.sha256(data) if load else hashlib.file_digest(f, "sha256")
    except OSError as exc:
        raise Damaged(f"{path.name} cannot be read: {_reason(exc)}") from None
    if size != described.get("bytes") or digest.hexdigest() != described.get("sha256"):
        raise Damaged(f"{path.name} does not match the size and SHA-256 recorded when it was written")
    with suppress(OSError):
        os.utime(record)  # used now: the last to be evicted
    return path, data


def _reason(exc: Exception) -> str:
    """An exception as a few words on one line."""
    return " ".join(str(getattr(exc, "strerror", None) or exc).split())


class _Digesting:
    """A file that also feeds what is written to it into a hash."""

    def __init__(self, f: BinaryIO, digest) -> None:
        self.f, self.digest = f, digest

    def write(self, data) -> int:
        self.digest.update(data)
        return self.f.write(data)


def sweep_cache(folder: Path) -> None:
    """Remove what dead writers left in the cache ``folder`` (their temporary
    files, of this host, whose process is gone) and the runs older versions
    pickled; a folder we cannot read or write is left as it is."""
    places = [folder]
    with suppress(OSError):
        places += [p for p in (folder / "maps").iterdir() if p.is_dir() and not p.is_symlink()]
    for place in places:
        try:
            entries = list(os.scandir(place))
        except OSError:
            continue
        for entry in entries:
            if dead_temporary(entry.name) or LEGACY.fullmatch(entry.name):
                _remove(Path(entry.path))


def evict(folder: Path, keep: Path, limit: int | None = None) -> None:
    """Remove the least recently used entries of the cache ``folder`` while
    they hold more than ``limit`` bytes (:data:`CACHE_LIMIT`), never ``keep``.
    An entry is a group of files sharing a name beside its ``.json`` (a run),
    or a folder under ``maps/`` (a tile); nothing else there is touched."""
    limit = CACHE_LIMIT if limit is None else limit
    with suppress(OSError), locked(folder):
        entries = _entries(folder)
        total = sum(size for _, size, _ in entries)
        for _, size, members in sorted(entries, key=lambda e: e[0]):
            if total <= limit:
                break
            if keep in members or any(keep.is_relative_to(m) for m in members):
                continue
            log.info("cache: removing %s (%d bytes, least recently used)", members[0], size)
            for member in members:
                _remove(member)
            total -= size


def _entries(folder: Path) -> list[tuple[float, int, list[Path]]]:
    """(last used, bytes, paths) of every entry in the cache ``folder``."""
    files = [p for p in folder.iterdir() if p.is_file() and not p.is_symlink() and not p.name.startswith(".")]
    entries = []
    for record in [p for p in files if p.suffix == ".json" and ENTRY.fullmatch(p.stem)]:
        members = [record, *(p for p in files if p.stem == record.stem and p != record)]
        entries.append((record.stat().st_mtime, sum(p.stat().st_size for p in members), members))
    with suppress(OSError):
        for tile in (folder / "maps").iterdir():
            if tile.is_dir() and not tile.is_symlink() and ENTRY.fullmatch(tile.name):
                sizes = [p.stat().st_size for p in tile.rglob("*") if p.is_file()]
                used = max([tile.stat().st_mtime, *(p.stat().st_mtime for p in tile.glob("*.json"))])
                entries.append((used, sum(sizes), [tile]))
    return entries


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with suppress(OSError):
            path.unlink()
