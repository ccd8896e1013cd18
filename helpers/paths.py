"""Where the package keeps its data and its caches.

The default flight ships inside the package (``helpers/data/``, read through
:mod:`importlib.resources`), so an installed package needs no checkout. Caches
(the default run, unpacked map tiles) go to :func:`cache_dir`:
``$HELPERS_CACHE`` if set, else ``$XDG_CACHE_HOME/aerial-lidar-slam``
(``~/.cache/aerial-lidar-slam`` by default). Deleting that folder is always safe.

The commands' output folders are checked and written by :mod:`helpers.outdir`.
"""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import BinaryIO

from .errors import SlamError

DATA = Path(resources.files("helpers").joinpath("data"))  # files shipped in the package
CACHE_VARIABLE = "HELPERS_CACHE"
CACHE_NAME = "aerial-lidar-slam"  # the folder under the user's cache folder


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
    ``$XDG_CACHE_HOME/aerial-lidar-slam`` (``~/.cache/aerial-lidar-slam``)."""
    if os.environ.get(CACHE_VARIABLE):
        return Path(os.environ[CACHE_VARIABLE])
    user_cache = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(user_cache) / CACHE_NAME


def write_atomically(path: str | Path, write: Callable[[BinaryIO], object]) -> None:
    """Write a file all or nothing: ``write(f)`` fills a temporary file of its
    own beside ``path``, which then replaces ``path`` in one step. Readers see
    the old file or the new one, never a part, even with several writers at
    once; the temporary file is removed if ``write`` fails."""
    path = Path(path)
    fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
