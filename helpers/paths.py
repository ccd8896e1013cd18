"""Where the package keeps its data and its caches.

The default flight ships inside the package (``helpers/data/``, read through
:mod:`importlib.resources`), so an installed package needs no checkout. Caches
(the default run, unpacked map tiles) go to :func:`cache_dir`:
``$HELPERS_CACHE`` if set, else ``$XDG_CACHE_HOME/aerial-lidar-slam``
(``~/.cache/aerial-lidar-slam`` by default). Deleting that folder is always safe.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable
from contextlib import contextmanager
from importlib import resources
from pathlib import Path
from typing import BinaryIO

from .errors import SlamError

DATA = Path(resources.files("helpers").joinpath("data"))  # files shipped in the package
CACHE_VARIABLE = "HELPERS_CACHE"
CACHE_NAME = "aerial-lidar-slam"  # the folder under the user's cache folder


def cache_dir() -> Path:
    """The cache folder: ``$HELPERS_CACHE`` if set, else
    ``$XDG_CACHE_HOME/aerial-lidar-slam`` (``~/.cache/aerial-lidar-slam``)."""
    if os.environ.get(CACHE_VARIABLE):
        return Path(os.environ[CACHE_VARIABLE])
    user_cache = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(user_cache) / CACHE_NAME


@contextmanager
def atomic_dir(out_dir: str | Path, marker: str):
    """Write a folder all or nothing: yields a temporary folder beside
    ``out_dir`` that replaces it when the block ends without error (and is
    removed otherwise). An existing ``out_dir`` is replaced only if it is
    empty or holds ``marker`` (a file an earlier run wrote)."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise SlamError(f"output path {out_dir} exists and is not a folder")
    if Path.cwd().is_relative_to(out_dir.resolve()):
        raise SlamError(f"output folder {out_dir} holds the current folder: choose another")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (out_dir / marker).is_file():
        raise SlamError(f"output folder {out_dir} is not empty and holds no earlier {marker}: choose another")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        yield work
        if out_dir.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.old.", dir=out_dir.parent))
            os.replace(out_dir, old / "previous")
            os.replace(work, out_dir)
            shutil.rmtree(old)
        else:
            os.replace(work, out_dir)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise


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
