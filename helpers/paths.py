"""Where the project keeps its data and its caches."""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"


def cache_dir() -> Path:
    """The cache folder: ``$HELPERS_CACHE`` if set, else ``data/cache`` (git-ignored)."""
    return Path(os.environ.get("HELPERS_CACHE", DATA / "cache"))


def shared_data(name: str) -> Path:
    """A file of the real data kept beside the repository (``../shared/data``)."""
    return REPO.parent / "shared" / "data" / name
