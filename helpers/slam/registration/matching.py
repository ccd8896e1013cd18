"""Stage 3b: descriptor matching (the reference's ``pcmatchfeatures``).

:func:`match_features` pairs the FPFH descriptors of two scans (normalised
as :mod:`helpers.slam.registration.features` says) by an exhaustive nearest-neighbour search,
the reference's threshold and ratio tests and a mutual check, optionally
gated in space by where the last motion puts each point. The search is one
float32 matrix product per block of rows, shared out between threads, each
row's answer the same whatever the threads.
"""

from __future__ import annotations

import numpy as np

from helpers.errors import SlamError
from helpers.threads import one_blas_thread, pool, threads

MATCH_BLOCK_ROWS = 128  # query rows per block of the exhaustive matcher (keeps the block in cache)
REACH_MARGIN = 1e-3  # descriptor-distance slack against float32 rounding in the exhaustive search
MAX_DESCRIPTOR_DISTANCE = np.sqrt(2.0)  # largest distance between unit descriptors with no negative entry


def match_features(f_moving, f_fixed, threshold: float, ratio: float, near=None) -> np.ndarray:
    """Pairs ``(i_moving, j_fixed)``, (K, 2) int64, of descriptors that match.

    For every moving descriptor the two nearest fixed descriptors are found
    (exhaustive search). A pair is kept when all three
    hold:

    - ``threshold``: the normalised distance to the nearest fixed descriptor,
      ``|a - b| / sqrt(2)`` (0 = identical, 1 = as far apart as unit
      descriptors can be), is at most ``threshold``;
    - ``ratio``: that distance divided by the distance to the second-nearest
      fixed descriptor is strictly below ``ratio`` (an ambiguous match, whose
      runner-up is nearly as close, is dropped; two equal distances never pass);
    - uniqueness: the moving descriptor is also the nearest moving descriptor
      of its fixed partner, so no fixed point is used twice.

    ``near``: a gate in space, ``(moving_xy, fixed_xy, cell)``: where each
    moving descriptor's point lies and where each fixed one's does (K x 2
    each, metres, both in the fixed scan's frame: the moving points carried
    there by the last motion) and a cell size in metres. Every search then
    compares a descriptor only with the other scan's descriptors whose
    points lie in its own cell of a ``cell``-metre grid or in one of the 8
    around it (so at least ``cell`` metres away in every direction, at most
    twice that), and the runner-up of the ratio test is the second nearest
    among those. A descriptor with fewer than two of them has no match.

    Pairs are sorted by moving index.
    """
    f_moving = _check_descriptors(f_moving, "moving")
    f_fixed = _check_descriptors(f_fixed, "fixed")
    if f_moving.shape[1] != f_fixed.shape[1]:
        raise SlamError(f"descriptors differ in length: {f_moving.shape[1]} and {f_fixed.shape[1]}")
    if not (0 < threshold <= 1) or not (0 < ratio <= 1):
        raise SlamError(f"match threshold and ratio must lie in (0, 1], got {threshold} and {ratio}")
    if len(f_fixed) < 2:
        raise SlamError("the ratio test needs at least 2 fixed descriptors")
    forward = backward = None
    if near is not None:
        moving_xy, fixed_xy, cell = _check_xy(near[0], len(f_moving)), _check_xy(near[1], len(f_fixed)), near[2]
        forward = _neighbourhoods(moving_xy, fixed_xy, cell)
    # Runners-up are needed only where the nearest passes the threshold.
    nearest, second = _two_nearest(f_moving, f_fixed, threshold * MAX_DESCRIPTOR_DISTANCE, forward)
    best_d = np.full(len(f_moving), np.inf)
    found = np.flatnonzero(nearest >= 0)  # all of them without a gate
    best_d[found] = _distance(f_moving[found], f_fixed[nearest[found]])
    # a ratio needs a runner-up (without a gate there always is one)
    candidates = np.flatnonzero((best_d <= threshold) & (second >= 0))
    keep = np.zeros(len(f_moving), dtype=bool)
    second_d = _distance(f_moving[candidates], f_fixed[second[candidates]])
    keep[candidates] = best_d[candidates] < ratio * second_d
    moving = np.flatnonzero(keep)
    partners = nearest[moving]
    if near is not None:
        backward = _neighbourhoods(fixed_xy[partners], moving_xy, cell)
    back, _ = _two_nearest(f_fixed[partners], f_moving, 0.0, backward)  # the nearest only
    moving = moving[back == moving]
    return np.column_stack([moving, nearest[moving]]).astype(np.int64)


def _distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise normalised distance ``|a - b| / sqrt(2)``, in float64."""
    return np.linalg.norm(a - b, axis=1) / MAX_DESCRIPTOR_DISTANCE


def _check_xy(xy, count: int) -> np.ndarray:
    array = np.asarray(xy, dtype=np.float64)
    if array.shape != (count, 2) or not np.isfinite(array).all():
        raise SlamError(f"the gate needs {count} finite x, y positions, got an array of shape {array.shape}")
    return array


def _neighbourhoods(query_xy: np.ndarray, reference_xy: np.ndarray, cell: float) -> list:
    """The gate's tiles: for every ``cell``-metre grid cell holding queries, (their indices, the
    indices, ascending, of the references in that cell and the 8 around it)."""
    if not (np.isfinite(cell) and cell > 0):
        raise SlamError(f"the gate's cell must be a positive number of metres, got {cell}")
    query_cells, reference_cells = (np.floor(np.asarray(xy) / cell).astype(np.int64) for xy in (query_xy, reference_xy))
    by_cell = dict(_groups(reference_cells))
    tiles = []
    for (cx, cy), queries in _groups(query_cells):
        around = [by_cell.get((cx + dx, cy + dy)) for dx in (-1, 0, 1) for dy in (-1, 0, 1)]
        around = [indices for indices in around if indices is not None]
        tiles.append((queries, np.sort(np.concatenate(around)) if around else np.zeros(0, dtype=np.int64)))
    return tiles


def _groups(cells: np.ndarray) -> list:
    """((cx, cy), indices ascending) for every distinct row of ``cells`` (N x 2 integers)."""
    if len(cells) == 0:
        return []
    low = cells.min(axis=0)
    key = (cells[:, 0] - low[0]) * (cells[:, 1].max() - low[1] + 1) + (cells[:, 1] - low[1])
    order = np.argsort(key, kind="stable")
    ordered = key[order]
    starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])
    bounds = np.r_[starts, len(key)]
    return [
        (tuple(cell), order[a:b])
        for cell, a, b in zip(cells[order[starts]].tolist(), bounds[:-1], bounds[1:], strict=True)
    ]


def _two_nearest(
    queries: np.ndarray, references: np.ndarray, reach: float | None, tiles: list | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the nearest and second-nearest reference of every query.

    Exhaustive search, the cost of the matcher: for every query ``q`` and
    reference ``r`` the squared distance minus ``|q|^2`` (which does not
    change the ranking) is ``|r|^2 - 2 q.r``, and appending a 1 to every
    query and ``|r|^2`` under ``-2 r`` makes it one float32 matrix product,
    a block of ``MATCH_BLOCK_ROWS`` rows at a time into one reused buffer
    (no other pass over the block before the row minima; ties go to the
    lower index). The second-nearest is searched only for the queries whose
    nearest lies within ``reach`` (plain Euclidean distance; ``None``: all
    queries, ``0``: none); the others get -1, as do all queries when there
    is one reference. ``reach`` is widened by ``REACH_MARGIN`` against
    float32 rounding.

    Why exhaustive: on a scan's worth of FPFH descriptors a k-d tree in 33
    dimensions (even bounded by the match radius) is slower than this
    product, and a tree on the first few principal components still leaves
    hundreds of candidates per query within the match radius: descriptors
    of smooth ground crowd together.

    Threads: each block's product runs on one BLAS thread (a second one
    costs more in hand-offs than it computes on blocks this small, idle or
    busy: ``benchmarks/bench_levers.py``), and the blocks are shared out,
    whole, between :func:`helpers.threads.threads` threads, which numpy's
    product and row minima let run at once: on two idle cores a scan's
    5,500 descriptors on the 1.5 m grid match in 36 ms instead of 62. Each
    row's answer is computed alone, the same whatever the threads.

    ``tiles`` (from :func:`_neighbourhoods`; None: every query against every
    reference): a list of (query indices, reference indices), each tile's
    queries searched among its references only, the tiles shared out
    between the threads whole; a query with no reference gets -1.
    """
    q = np.empty((len(queries), queries.shape[1] + 1), dtype=np.float32)
    q[:, :-1] = queries
    q[:, -1] = 1.0
    r = np.empty((references.shape[1] + 1, len(references)), dtype=np.float32)
    r[:-1] = references.T
    r[-1] = np.einsum("ij,ij->i", references, references)
    r[:-1] *= -2.0
    q_sq = np.einsum("ij,ij->i", queries, queries)
    limit = np.inf if reach is None else (reach + REACH_MARGIN) ** 2
    first = np.full(len(q), -1, dtype=np.int64)
    second = np.full(len(q), -1, dtype=np.int64)
    if tiles is not None:
        _tiled(q, r, q_sq, limit, tiles, first, second)
        return first, second
    n_blocks = -(-len(q) // MATCH_BLOCK_ROWS)
    parts = max(1, min(threads(), n_blocks))
    cuts = [MATCH_BLOCK_ROWS * (n_blocks * k // parts) for k in range(parts)] + [len(q)]

    def part(start: int, stop: int) -> None:  # one thread's rows; its buffer is reused by each of its blocks
        buffer = np.empty((min(MATCH_BLOCK_ROWS, stop - start), len(references)), dtype=np.float32)
        _blocks(q[start:stop], r, q_sq[start:stop], limit, buffer, first[start:stop], second[start:stop])

    with one_blas_thread():
        if parts == 1:
            part(0, len(q))
        else:
            list(pool(parts).map(part, cuts[:-1], cuts[1:]))  # list(): waits, and raises a thread's error
    return first, second


def _tiled(q, r, q_sq, limit, tiles, first, second) -> None:
    """:func:`_two_nearest` tile by tile, the tiles shared out whole between the threads (by their
    products' sizes), each tile's rows the same whatever thread computes them."""
    tiles = [(rows, columns) for rows, columns in tiles if len(rows) and len(columns)]
    cost = np.cumsum([len(rows) * len(columns) for rows, columns in tiles])
    parts = max(1, min(threads(), len(tiles)))
    cuts = [0] + [int(np.searchsorted(cost, cost[-1] * k / parts)) for k in range(1, parts)] + [len(tiles)]

    r_rows = np.ascontiguousarray(r.T)  # a tile's references gathered as rows (its product reads them transposed)

    def part(start: int, stop: int) -> None:
        for rows, columns in tiles[start:stop]:
            buffer = np.empty((min(MATCH_BLOCK_ROWS, len(rows)), len(columns)), dtype=np.float32)
            near, runner_up = np.empty(len(rows), dtype=np.int64), np.full(len(rows), -1, dtype=np.int64)
            _blocks(q[rows], r_rows[columns].T, q_sq[rows], limit, buffer, near, runner_up)
            first[rows] = columns[near]
            second[rows] = np.where(runner_up >= 0, columns[runner_up], -1)

    with one_blas_thread():
        if parts == 1 or not tiles:
            part(0, len(tiles))
        else:
            list(pool(parts).map(part, cuts[:-1], cuts[1:]))


def _blocks(q, r, q_sq, limit, buffer, first, second) -> None:
    """The block loop of :func:`_two_nearest`, filling ``first`` and ``second`` in place."""
    n_references = r.shape[1]
    for start in range(0, len(q), MATCH_BLOCK_ROWS):
        stop = min(start + MATCH_BLOCK_ROWS, len(q))
        block = buffer[: stop - start]
        np.matmul(q[start:stop], r, out=block)
        j = block.argmin(axis=1)
        first[start:stop] = j
        if n_references < 2:
            continue
        rows = np.arange(len(block))
        live = np.flatnonzero(block[rows, j] + q_sq[start:stop] <= limit)
        if len(live) == 0:
            continue
        block[live, j[live]] = np.inf
        if 4 * len(live) > len(block):  # one pass over the whole block costs less than copying most of it out
            second[start + live] = block.argmin(axis=1)[live]
        else:
            second[start + live] = block[live].argmin(axis=1)


def _check_descriptors(features, which: str) -> np.ndarray:
    array = np.asarray(features, dtype=np.float64)
    if array.ndim != 2 or len(array) == 0:
        raise SlamError(f"the {which} descriptors must be a non-empty M x D array, got shape {array.shape}")
    if not np.isfinite(array).all():
        raise SlamError(f"the {which} descriptors contain NaN or infinite values")
    return array
