"""Stage 3b: the coarse rigid fit of two scans from matched points (the
reference's ``estgeotform3d`` with MSAC); :mod:`helpers.slam.registration.icp` refines it.
The shared MSAC machinery (trial counts, local optimisation, input checks)
lives here too; :mod:`helpers.slam.registration.msac_yaw` builds its yaw and
translation fit on it, and :mod:`helpers.slam.registration.robust_fit` picks one.

A transform ``T`` (4 x 4) maps *moving* points onto *fixed* points:
``fixed ~ T[:3, :3] @ moving + T[:3, 3]``.
"""

from __future__ import annotations

import numpy as np

from helpers.errors import SlamError
from helpers.geometry import check_points

SAMPLE_SIZE = 3  # point pairs that fix a rigid motion
MIN_INLIERS = 2 * SAMPLE_SIZE  # the best hypothesis must explain at least this many matches
HYPOTHESES_PER_CHUNK = 256  # hypotheses scored at once; also how often the trial count is revised
DEGENERATE_SINE = 0.05  # a sample triangle whose angle at its first corner has a sine below this is skipped
LO_PER_CHUNK = 4  # a chunk's cheapest hypotheses that are locally optimised (when they beat the best so far)
LO_MAX_ROUNDS = 20  # local optimisation: least-squares refits on the inliers until the inlier set stops changing


def kabsch(moving: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """Least-squares rigid transforms of batches of point sets.

    ``moving`` and ``fixed`` are (..., N, 3); returns (..., 4, 4) transforms
    that minimise the summed squared distance (Kabsch / Umeyama without
    scale), solved with one batched SVD.
    """
    mc = moving.mean(axis=-2, keepdims=True)
    fc = fixed.mean(axis=-2, keepdims=True)
    cov = np.swapaxes(moving - mc, -1, -2) @ (fixed - fc)  # (..., 3, 3)
    u, _, vt = np.linalg.svd(cov)
    v = np.swapaxes(vt, -1, -2)
    sign = np.where(np.linalg.det(v @ np.swapaxes(u, -1, -2)) < 0, -1.0, 1.0)
    v[..., :, 2] *= sign[..., None]  # no reflections
    rot = v @ np.swapaxes(u, -1, -2)
    out = np.zeros((*rot.shape[:-2], 4, 4))
    out[..., :3, :3] = rot
    out[..., :3, 3] = fc[..., 0, :] - (rot @ np.swapaxes(mc, -1, -2))[..., 0]
    out[..., 3, 3] = 1.0
    return out


def equivalent_trials(max_trials: int, confidence: float, sample_size: int) -> int:
    """The trial cap for samples of ``sample_size`` matches that stops at the
    same inlier ratio as ``max_trials`` samples of 3.

    ``max_trials`` samples of 3 reach ``confidence`` exactly when the inlier
    ratio ``w`` satisfies ``w^3 = 1 - (1 - confidence)^(1 / max_trials)``;
    the cap is :func:`trials_needed` at that ``w`` for the smaller samples
    (the reference's 3000 at 99 % becomes 344 samples of 2). Both fits then
    draw all they may on the same hard pairs, and stop as early on easy ones.
    """
    floor = -np.expm1(np.log1p(-confidence) / max_trials)  # w^3 at the cap
    return trials_needed(floor ** (1.0 / SAMPLE_SIZE), confidence, max_trials, sample_size)


def estimate_rigid_msac(
    moving_pts, fixed_pts, max_distance: float, max_trials: int, seed: int = 0, confidence: float = 0.99
):
    """Robust rigid transform from matched points, by MSAC with local optimisation.

    ``moving_pts[i]`` is matched to ``fixed_pts[i]`` (both (K, 3)). Samples of
    3 pairs are drawn from ``numpy.random.default_rng(seed)``; each gives the
    motion that carries its moving triangle onto the fixed one (thin triangles
    are skipped), scored with the MSAC cost ``sum(min(r^2, max_distance^2))``
    over all pairs, ``HYPOTHESES_PER_CHUNK`` at a time.

    Whenever one of a chunk's ``LO_PER_CHUNK`` cheapest hypotheses beats the
    best so far, it is *locally optimised* (LO-RANSAC, Chum et al. 2003):
    refitted by least squares on its inliers (residual below
    ``max_distance``, metres), again and again until the inlier set stops
    changing. Hypotheses near the same motion end at the same inlier set, so
    the answer hardly depends on which sample happened to win, and a
    last-bit change of the input that swaps the winning sample moves it
    little (``benchmarks/bench_stability.py`` measures how little).

    The trial count follows the measured inlier ratio ``w`` of the best
    optimised model: sampling stops once ``log(1 - confidence) / log(1 - w^3)``
    samples were scored (MATLAB's ``Confidence``), and never goes past
    ``max_trials``.

    Returns ``(T, inliers)``: the 4 x 4 transform and a (K,) boolean mask.
    The same input and seed give the same result on any number of threads.
    """
    moving, fixed = check_fit_inputs(
        moving_pts, fixed_pts, SAMPLE_SIZE, "a rigid fit", max_distance, max_trials, confidence
    )

    # Work about the centroids: smaller numbers, better rounding in the cost expansion.
    moving_centre, fixed_centre = moving.mean(axis=0), fixed.mean(axis=0)
    moving_c, fixed_c = moving - moving_centre, fixed - fixed_centre
    samples = _distinct_triples(np.random.default_rng(seed), len(moving), int(max_trials))
    best, best_cost, best_raw_cost, needed = None, np.inf, np.inf, int(max_trials)
    for start in range(0, int(max_trials), HYPOTHESES_PER_CHUNK):
        if start >= needed:
            break
        chunk = samples[start : start + HYPOTHESES_PER_CHUNK]
        hypotheses, valid = _triangle_transforms(moving_c[chunk], fixed_c[chunk])
        cost = _msac_costs(hypotheses, moving_c, fixed_c, max_distance)
        cost[~valid] = np.inf
        for winner in np.argsort(cost, kind="stable")[:LO_PER_CHUNK]:
            if not cost[winner] < best_raw_cost:
                break
            model, model_cost, inliers = _locally_optimised(hypotheses[winner], moving_c, fixed_c, max_distance)
            if model_cost < best_cost:
                best, best_cost, best_inliers = model, model_cost, inliers
                needed = trials_needed(best_inliers.mean(), confidence, int(max_trials))
        best_raw_cost = min(best_raw_cost, cost.min())
    if best is None:
        raise SlamError(f"all {max_trials} samples of 3 matches were degenerate (collinear points)")
    if best_inliers.sum() < MIN_INLIERS:
        raise SlamError(
            f"no rigid motion explains enough matches: the best of {max_trials} hypotheses has "
            f"{best_inliers.sum()} inliers within {max_distance} m, at least {MIN_INLIERS} are needed"
        )
    return _uncentre(best, moving_centre, fixed_centre), best_inliers


def _locally_optimised(transform: np.ndarray, moving: np.ndarray, fixed: np.ndarray, max_distance: float):
    """Refit ``transform`` by Kabsch on its inliers until the inlier set is
    stable (:func:`locally_optimised`). Returns ``(T, cost, inliers)``."""
    return locally_optimised(
        transform,
        lambda T: _squared_residuals(T[None], moving, fixed)[0],
        lambda inliers: kabsch(moving[inliers], fixed[inliers]),
        max_distance,
        SAMPLE_SIZE,
    )


def locally_optimised(model, squared_residuals, refit, max_distance: float, sample_size: int):
    """MSAC's local optimisation: refit ``model`` on its inliers
    (``refit(inlier_mask)``) until the inlier set is stable. A refit is kept
    only while it lowers the MSAC cost, so the result is never worse than the
    hypothesis it started from. ``squared_residuals(model)`` gives every
    match's squared distance. Returns ``(model, cost, inliers)``."""
    limit = max_distance**2
    squared = squared_residuals(model)
    cost, inliers = np.minimum(squared, limit).sum(), squared < limit
    for _ in range(LO_MAX_ROUNDS):
        if inliers.sum() < sample_size:
            break
        candidate = refit(inliers)
        squared = squared_residuals(candidate)
        candidate_cost, candidate_inliers = np.minimum(squared, limit).sum(), squared < limit
        if not candidate_cost < cost:
            break
        converged = np.array_equal(candidate_inliers, inliers)
        model, cost, inliers = candidate, candidate_cost, candidate_inliers
        if converged:
            break
    return model, cost, inliers


def trials_needed(inlier_ratio: float, confidence: float, max_trials: int, sample_size: int = SAMPLE_SIZE) -> int:
    """Samples of ``sample_size`` matches needed to draw one all-inlier sample
    with ``confidence`` (the standard RANSAC count), at most ``max_trials``."""
    all_inliers = inlier_ratio**sample_size
    if all_inliers >= 1.0:
        return 1
    if all_inliers <= 0.0:
        return max_trials
    return int(min(max_trials, np.ceil(np.log(1.0 - confidence) / np.log1p(-all_inliers))))


def _distinct_triples(rng: np.random.Generator, n: int, count: int) -> np.ndarray:
    """(count, 3) index triples, three different indices in [0, n) each, uniformly."""
    a = rng.integers(0, n, count)
    b = rng.integers(0, n - 1, count)
    b += b >= a
    c = rng.integers(0, n - 2, count)
    low, high = np.minimum(a, b), np.maximum(a, b)
    c += c >= low
    c += c >= high
    return np.column_stack([a, b, c])


def _triangle_transforms(moving: np.ndarray, fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rigid motions that carry each moving triangle onto its fixed one.

    ``moving`` and ``fixed`` are (H, 3, 3) (three points each). Each triangle
    gets an orthonormal frame (first edge, normal, their cross product); the
    rotation maps one frame onto the other and the centroids onto each other.
    Returns (H, 4, 4) transforms and an (H,) mask, False for triangles too
    thin to fix a rotation.
    """

    def frames(tri):
        e1 = tri[:, 1] - tri[:, 0]
        normal = np.cross(e1, tri[:, 2] - tri[:, 0])
        e1_len = np.linalg.norm(e1, axis=1)
        n_len = np.linalg.norm(normal, axis=1)
        ok = n_len > DEGENERATE_SINE * np.maximum(e1_len, 1e-12) * np.linalg.norm(tri[:, 2] - tri[:, 0], axis=1)
        e1 = e1 / np.maximum(e1_len, 1e-12)[:, None]
        e3 = normal / np.maximum(n_len, 1e-12)[:, None]
        return np.stack([e1, np.cross(e3, e1), e3], axis=2), ok  # columns are the frame axes

    moving_frame, ok_m = frames(moving)
    fixed_frame, ok_f = frames(fixed)
    rot = fixed_frame @ np.swapaxes(moving_frame, 1, 2)
    out = np.zeros((len(rot), 4, 4))
    out[:, :3, :3] = rot
    out[:, :3, 3] = fixed.mean(axis=1) - (rot @ moving.mean(axis=1)[:, :, None])[:, :, 0]
    out[:, 3, 3] = 1.0
    return out, ok_m & ok_f


def _msac_costs(transforms: np.ndarray, moving: np.ndarray, fixed: np.ndarray, max_distance: float) -> np.ndarray:
    """(H,) MSAC cost of every hypothesis: the sum over pairs of min(r^2, max_distance^2).

    The squared residual ``|R m + t - f|^2`` expands to
    ``|t|^2 + |m|^2 + |f|^2 + 2 (R^T t).m - 2 vec(R).vec(f m^T) - 2 t.f``:
    one matrix product of (H, 17) hypothesis terms by (17, K) pair terms
    (the constants ride along as a column of ones and a row of ones) gives
    all residuals, a chunk of hypotheses at a time into one reused buffer;
    then one clipping pass and one sum. Every hypothesis is scored on every
    pair, in float64, in a fixed order: no early exit, the same costs on any
    number of threads.
    """
    rot, t = transforms[:, :3, :3], transforms[:, :3, 3]
    hyp = np.hstack(
        [
            -2.0 * rot.reshape(-1, 9),
            2.0 * (np.swapaxes(rot, 1, 2) @ t[:, :, None])[:, :, 0],
            -2.0 * t,
            (t**2).sum(axis=1)[:, None],
            np.ones((len(t), 1)),
        ]
    )
    pairs = np.vstack(
        [
            (fixed[:, :, None] * moving[:, None, :]).reshape(-1, 9).T,
            moving.T,
            fixed.T,
            np.ones((1, len(moving))),
            ((moving**2).sum(axis=1) + (fixed**2).sum(axis=1))[None],
        ]
    )
    cost = np.empty(len(transforms))
    buffer = np.empty((min(HYPOTHESES_PER_CHUNK, len(hyp)), pairs.shape[1]))  # reused: fresh pages are slow
    for start in range(0, len(transforms), HYPOTHESES_PER_CHUNK):
        stop = min(start + HYPOTHESES_PER_CHUNK, len(transforms))
        sq = buffer[: stop - start]
        np.matmul(hyp[start:stop], pairs, out=sq)
        np.minimum(sq, max_distance**2, out=sq)
        sq.sum(axis=1, out=cost[start:stop])
    return cost


def _uncentre(transform: np.ndarray, moving_centre: np.ndarray, fixed_centre: np.ndarray) -> np.ndarray:
    """A transform between centred clouds, as one between the original clouds."""
    out = transform.copy()
    out[:3, 3] = transform[:3, 3] + fixed_centre - transform[:3, :3] @ moving_centre
    return out


def _squared_residuals(transforms: np.ndarray, moving: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """(H, K) squared distances between each transformed moving point and its fixed partner."""
    h = len(transforms)
    moved = (transforms[:, :3, :3].reshape(3 * h, 3) @ moving.T).reshape(h, 3, len(moving))  # one matrix product
    moved += transforms[:, :3, 3, None]
    moved -= fixed.T
    moved *= moved
    return moved.sum(axis=1)


def check_fit_inputs(moving_pts, fixed_pts, sample_size: int, fit: str, max_distance, max_trials, confidence):
    """The matched points of a robust fit as two (K, 3) arrays, or a
    SlamError saying what is wrong with them or with the fit's settings."""
    moving = check_points(moving_pts, "the matched moving points")
    fixed = check_points(fixed_pts, "the matched fixed points")
    if len(moving) != len(fixed):
        raise SlamError(f"matched point lists differ in length: {len(moving)} moving and {len(fixed)} fixed")
    if len(moving) < sample_size:
        raise SlamError(f"{fit} needs at least {sample_size} matches, got {len(moving)}")
    if not (np.isfinite(max_distance) and max_distance > 0) or max_trials < 1:
        raise SlamError(f"max_distance must be positive and max_trials at least 1, got {max_distance}, {max_trials}")
    if not 0 < confidence < 1:
        raise SlamError(f"the robust fit's confidence must lie strictly between 0 and 1, got {confidence!r}")
    return moving, fixed
