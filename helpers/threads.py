"""How many threads the package's own parallel work uses, and numpy's BLAS held to one thread.

Open3D's FPFH and small_gicp's k-d trees run OpenMP threads on every core.
numpy's and scipy's OpenBLAS start threads of their own for any product
large enough, and those threads keep spinning on their core for a while
after it: a robust fit's products then take the core the next scan's FPFH
wanted. On the reference's run of the default flight (no other process
running), holding OpenBLAS to one thread while a scan is processed took
FPFH from 77 to 51 ms a scan and the whole run from 45 to 37 s, with the
same results to the bit (its products are small: a 3 x 3 fit, a cloud
moved, a block of descriptors, none of which a second BLAS thread sped
up). :func:`one_blas_thread` does this for a block of code and then gives
the user's setting back; importing the package changes nothing.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

from threadpoolctl import ThreadpoolController

BLAS = ThreadpoolController()  # numpy's and scipy's BLAS libraries, found once
_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}  # (process id, workers) -> pool


def threads() -> int:
    """Threads for the package's parallel work (small_gicp's k-d trees, covariances and neighbour
    searches, the descriptor matcher's blocks): ``$OMP_NUM_THREADS`` when set (as Open3D and numpy
    obey it), else every core."""
    value = os.environ.get("OMP_NUM_THREADS", "")
    return int(value) if value.isdigit() and int(value) > 0 else os.cpu_count() or 1


def one_blas_thread():
    """A context in which numpy's and scipy's BLAS run on one thread (the module says why)."""
    return BLAS.limit(limits=1, user_api="blas")


def pool(workers: int) -> ThreadPoolExecutor:
    """A pool of ``workers`` threads for work that releases the GIL, made once per count and process
    and kept (a forked child makes its own: the parent's threads are not in it, and waiting on them
    would hang)."""
    key = (os.getpid(), workers)
    if key not in _POOLS:
        _POOLS[key] = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="helpers")
    return _POOLS[key]
