"""The project itself, offered by the book as one zip archive
(:func:`write_archive`): a reader of the book unpacks it and runs the
README's two commands in its folder. It holds what those commands, the
notebooks and the pages' text need: the ``helpers`` package, the notebooks
with their figures and worked answers, the reference's input files in
``data/`` (notebook 1 reads them), the Makefile, the pinned packages, the
package's metadata, the licence, the README and the ``docs/``,
``benchmarks/``, ``tests/`` and ``jupyter/`` folders it and the pages name.
Nothing built, cached or installed goes in (``build/``, ``.venv/``, caches,
compiled Python)."""

from __future__ import annotations

import fnmatch
import zipfile
from pathlib import Path

NAME = "aerial-lidar-slam"
ARCHIVE = f"{NAME}.zip"  # in the book's top folder, beside index.html
# The project's files and folders the archive holds, from its top folder; one that is missing is left out
# (a book built from a folder of notebooks alone offers those).
CONTENTS = (
    "README.md",
    "LICENSE",
    "CHANGELOG.md",
    "Makefile",
    "environment.txt",
    "pyproject.toml",
    "helpers",
    "notebooks",
    "data",
    "docs",
    "benchmarks",
    "tests",
    "jupyter",
)
# Never archived, at any depth: what tools write (compiled Python, caches, checkpoints, an installed package's
# metadata) and hidden files; and the cache folder of data/.
LEFT_OUT = ("__pycache__", "*.pyc", "*.egg-info", ".*")
LEFT_OUT_PATHS = ("data/cache",)


def archived_files(root: Path, skip: tuple[Path, ...] = ()) -> list[Path]:
    """The files of ``root`` the archive holds, as paths relative to it, in a fixed order; nothing under a
    folder of ``skip`` (the book being written, if it lies inside the project)."""
    skipped = {Path(p).resolve() for p in skip}
    found = []
    for name in CONTENTS:
        top = root / name
        if top.is_file() and not top.is_symlink():
            found.append(Path(name))
        elif top.is_dir() and not top.is_symlink():
            found += _walk(root, top, skipped)
    return found


def _walk(root: Path, folder: Path, skipped: set[Path]) -> list[Path]:
    found = []
    for path in sorted(folder.iterdir()):
        relative = path.relative_to(root)
        if (
            any(fnmatch.fnmatch(path.name, pattern) for pattern in LEFT_OUT)
            or relative.as_posix() in LEFT_OUT_PATHS
            or path.is_symlink()
            or path.resolve() in skipped
        ):
            continue
        if path.is_dir():
            found += _walk(root, path, skipped)
        elif path.is_file():
            found.append(relative)
    return found


def write_archive(root: Path, target: Path, skip: tuple[Path, ...] = ()) -> Path:
    """Zips the project at ``root`` into ``target``, every file under one folder named ``NAME``; returns
    ``target``. Files keep their times and permissions (the Makefile's tabs, a script's executable bit)."""
    with zipfile.ZipFile(target, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=6) as archive:
        for relative in archived_files(root, skip):
            archive.write(root / relative, f"{NAME}/{relative.as_posix()}")
    return target
