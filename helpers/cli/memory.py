"""A command's stages: running out of memory in one is an error that names it, not a traceback."""

from __future__ import annotations

import re
import resource
from contextlib import contextmanager

from helpers.errors import SlamError


@contextmanager
def stage(step: str):
    """Out of memory within ``step`` (Python's or numpy's MemoryError, a library's "out of memory") as one
    :class:`SlamError` naming the step, what it asked for when known, and the memory in use and allowed."""
    try:
        yield
    except (MemoryError, RuntimeError) as exc:
        text = re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", str(exc))  # Open3D colours its messages
        if isinstance(exc, RuntimeError) and not re.search(r"out of memory|bad_alloc|cannot allocate", text, re.I):
            raise
        from helpers.config.bounds import human_size

        asked = getattr(exc, "_total_size", None)  # numpy's _ArrayMemoryError knows it
        asked = f"{human_size(asked)} more" if asked else "more memory"
        in_use = human_size(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)  # Linux: kB
        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
        allowed = "" if limit == resource.RLIM_INFINITY else f" under a limit of {human_size(limit)} (ulimit -v)"
        raise SlamError(
            f"out of memory while {step}: it asked for {asked} with up to {in_use} in use{allowed}; "
            "free memory, raise the limit, or give a smaller map or flight"
        ) from None
