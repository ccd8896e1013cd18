"""A four-degree-of-freedom robust fit: yaw about the vertical and a
translation, from matched points, by MSAC on samples of 2 matches.

Why: a nadir-looking survey flight turns almost only about the vertical, and
over gently rolling ground a six-degree-of-freedom fit can trade a little
tilt for a slide along the track. Fixing roll and pitch at zero leaves one
angle and three offsets, which two matches determine; the tilt that remains
is left to ICP. Two-match samples are all-inlier far more often than
three-match ones, so far fewer samples are needed for the same confidence.

The semantics follow :func:`helpers.slam.registration.msac.estimate_rigid_msac`: the
same inputs (matched points), the same MSAC cost ``sum(min(r^2, d^2))``, the
same seeded sampling, the same early stop from the measured inlier ratio and
the same local optimisation (least-squares refits on the inliers until the
inlier set stops changing). A transform ``T_fixed_moving`` (4 x 4) carries
moving points onto fixed ones: ``fixed ~ R_z @ moving + t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from helpers.errors import SlamError
from helpers.geometry import transform_points
from helpers.slam.registration.msac import LO_PER_CHUNK, MIN_INLIERS, check_fit_inputs, locally_optimised, trials_needed

SAMPLE_SIZE = 2  # matches that fix a yaw and a translation
HYPOTHESES_PER_CHUNK = 64  # hypotheses scored at once; also how often the trial count is revised
MIN_BASELINE = 1.0  # a sample whose two points lie closer than this many max_distance horizontally is skipped


@dataclass
class YawFit:
    """What :func:`fit_yaw_translation` found."""

    T: np.ndarray  # 4 x 4 T_fixed_moving, roll = pitch = 0
    inliers: np.ndarray  # (K,) bool, matches within max_distance of the fitted motion
    cost: float  # MSAC cost of T over all matches, m^2
    trials: int  # samples drawn and scored before the early stop


def estimate_yaw_msac(
    moving_pts, fixed_pts, max_distance: float, max_trials: int, seed: int = 0, confidence: float = 0.99
):
    """:func:`fit_yaw_translation` with the signature and result ``(T, inliers)``
    of :func:`helpers.slam.registration.msac.estimate_rigid_msac`, so either can be used."""
    fit = fit_yaw_translation(moving_pts, fixed_pts, max_distance, max_trials, seed, confidence)
    return fit.T, fit.inliers


def fit_yaw_translation(
    moving_pts, fixed_pts, max_distance: float, max_trials: int, seed: int = 0, confidence: float = 0.99
) -> YawFit:
    """Robust yaw + translation from matched points (``moving_pts[i]`` matched
    to ``fixed_pts[i]``, both (K, 3)), by MSAC with local optimisation.

    All samples of 2 different matches are drawn at once from
    ``numpy.random.default_rng(seed)``; each gives in closed form the yaw that
    turns its horizontal segment onto the fixed one and the offset that
    brings the midpoints together. Samples whose two points lie less than
    ``MIN_BASELINE * max_distance`` apart horizontally (in either cloud) fix no
    yaw and are skipped. Hypotheses are scored ``HYPOTHESES_PER_CHUNK`` at a
    time; sampling stops once ``log(1 - confidence) / log(1 - w^2)`` samples
    were scored (``w``: the inlier ratio of the best model), at most
    ``max_trials``. A SlamError says why when every sample was degenerate or
    the best model explains fewer than ``MIN_INLIERS`` matches.
    """
    moving, fixed = check_fit_inputs(
        moving_pts, fixed_pts, SAMPLE_SIZE, "a yaw and translation fit", max_distance, max_trials, confidence
    )

    # Work about the centroids, as the six-degree-of-freedom fit does.
    moving_centre, fixed_centre = moving.mean(axis=0), fixed.mean(axis=0)
    moving_c, fixed_c = moving - moving_centre, fixed - fixed_centre
    max_trials = int(max_trials)
    samples = _distinct_pairs(np.random.default_rng(seed), len(moving), max_trials)
    yaw, offset, valid = _pair_motions(moving_c[samples], fixed_c[samples], MIN_BASELINE * max_distance)
    pair_terms = _pair_terms(moving_c, fixed_c)
    best, best_cost, best_raw_cost, needed, drawn = None, np.inf, np.inf, max_trials, 0
    for start in range(0, max_trials, HYPOTHESES_PER_CHUNK):
        if start >= needed:
            break
        stop = min(start + HYPOTHESES_PER_CHUNK, max_trials)
        drawn = stop
        cost = msac_costs(yaw[start:stop], offset[start:stop], pair_terms, max_distance)
        cost[~valid[start:stop]] = np.inf
        for winner in np.argsort(cost, kind="stable")[:LO_PER_CHUNK]:
            if not cost[winner] < best_raw_cost:
                break
            model = (yaw[start + winner], offset[start + winner])
            model, model_cost, inliers = _locally_optimised(model, moving_c, fixed_c, max_distance)
            if model_cost < best_cost:
                best, best_cost, best_inliers = model, model_cost, inliers
                needed = trials_needed(best_inliers.mean(), confidence, max_trials, SAMPLE_SIZE)
        best_raw_cost = min(best_raw_cost, cost.min())
    if best is None:
        raise SlamError(
            f"all {drawn} samples of 2 matches were degenerate: their points lie less than "
            f"{MIN_BASELINE * max_distance:g} m apart horizontally, so they fix no yaw"
        )
    if best_inliers.sum() < MIN_INLIERS:
        raise SlamError(
            f"no yaw and translation explains enough matches: the best of {drawn} hypotheses has "
            f"{best_inliers.sum()} inliers within {max_distance} m, at least {MIN_INLIERS} are needed"
        )
    T = yaw_transform(*best)
    T[:3, 3] += fixed_centre - T[:3, :3] @ moving_centre
    return YawFit(T, best_inliers, float(best_cost), drawn)


def fit_yaw(moving, fixed, weights=None) -> tuple[float, np.ndarray]:
    """Least-squares yaw (radians) and translation (3,) carrying ``moving`` onto
    ``fixed`` (both (N, 3)), each pair weighted by ``weights`` (default 1).

    The horizontal part is a weighted 2-D Procrustes about the vertical (the
    yaw from the summed cross and dot products of the centred horizontal
    coordinates); the height offset is the weighted mean difference, since
    a yaw does not change heights.
    """
    w = np.ones(len(moving)) if weights is None else np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    mc, fc = w @ moving, w @ fixed
    m, f = moving - mc, fixed - fc
    dot = w @ (m[:, 0] * f[:, 0] + m[:, 1] * f[:, 1])
    cross = w @ (m[:, 0] * f[:, 1] - m[:, 1] * f[:, 0])
    angle = float(np.arctan2(cross, dot))
    return angle, fc - yaw_transform(angle, np.zeros(3))[:3, :3] @ mc


def yaw_transform(yaw: float, offset) -> np.ndarray:
    """The 4 x 4 transform that turns by ``yaw`` (radians) about z, then shifts by ``offset``."""
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.eye(4)
    out[:2, :2] = [[c, -s], [s, c]]
    out[:3, 3] = offset
    return out


def msac_costs(yaw: np.ndarray, offset: np.ndarray, pair_terms: np.ndarray, max_distance: float) -> np.ndarray:
    """(H,) MSAC cost, ``sum over pairs of min(r^2, max_distance^2)``, of the
    hypotheses ``yaw`` (H,) and ``offset`` (H, 3), on :func:`_pair_terms`.

    With ``R`` the yaw, ``|R m + t - f|^2`` expands into ten products of a
    hypothesis term and a pair term, so one (H, 10) by (10, K) matrix
    product gives every squared residual of the chunk.
    """
    c, s = np.cos(yaw), np.sin(yaw)
    tx, ty, tz = offset.T
    hyp = np.column_stack(
        [-2 * c, -2 * s, 2 * (c * tx + s * ty), 2 * (c * ty - s * tx), 2 * tz, -2 * tx, -2 * ty, -2 * tz]
        + [tx * tx + ty * ty + tz * tz, np.ones_like(c)]
    )
    squared = hyp @ pair_terms
    np.minimum(squared, max_distance**2, out=squared)
    return squared.sum(axis=1)


def _pair_terms(moving: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """(10, K) the pair side of the expansion in :func:`msac_costs`."""
    mx, my, mz = moving.T
    fx, fy, fz = fixed.T
    constant = (moving**2).sum(axis=1) + (fixed**2).sum(axis=1) - 2 * mz * fz
    return np.vstack([mx * fx + my * fy, mx * fy - my * fx, mx, my, mz, fx, fy, fz, np.ones_like(mx), constant])


def _squared_residuals(model, moving: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    T = yaw_transform(*model)
    return ((transform_points(moving, T) - fixed) ** 2).sum(axis=1)


def _locally_optimised(model, moving, fixed, max_distance):
    """Refit ``model`` (yaw, offset) by least squares on its inliers until the
    inlier set is stable (:func:`helpers.slam.registration.msac.locally_optimised`).
    Returns ``(model, cost, inliers)``."""
    return locally_optimised(
        model,
        lambda m: _squared_residuals(m, moving, fixed),
        lambda inliers: fit_yaw(moving[inliers], fixed[inliers]),
        max_distance,
        SAMPLE_SIZE,
    )


def _distinct_pairs(rng: np.random.Generator, n: int, count: int) -> np.ndarray:
    """(count, 2) index pairs, two different indices in [0, n) each, uniformly.

    Drawn row by row, so a smaller ``count`` gives the first rows of a larger
    one: a lower trial cap only cuts the same sequence of samples short.
    """
    pairs = rng.integers(0, [n, n - 1], (count, 2))
    pairs[:, 1] += pairs[:, 1] >= pairs[:, 0]
    return pairs


def _pair_motions(moving: np.ndarray, fixed: np.ndarray, min_baseline: float):
    """The yaw (H,) and offset (H, 3) carrying each moving pair onto its fixed
    pair (``moving``, ``fixed``: (H, 2, 3)), and an (H,) mask, False where
    either pair is shorter than ``min_baseline`` horizontally."""
    dm = moving[:, 1, :2] - moving[:, 0, :2]
    df = fixed[:, 1, :2] - fixed[:, 0, :2]
    yaw = np.arctan2(dm[:, 0] * df[:, 1] - dm[:, 1] * df[:, 0], (dm * df).sum(axis=1))
    valid = (np.hypot(*dm.T) >= min_baseline) & (np.hypot(*df.T) >= min_baseline)
    c, s = np.cos(yaw), np.sin(yaw)
    mid_m, mid_f = moving.mean(axis=1), fixed.mean(axis=1)
    offset = np.column_stack(
        [
            mid_f[:, 0] - (c * mid_m[:, 0] - s * mid_m[:, 1]),
            mid_f[:, 1] - (s * mid_m[:, 0] + c * mid_m[:, 1]),
            mid_f[:, 2] - mid_m[:, 2],
        ]
    )
    return yaw, offset, valid
