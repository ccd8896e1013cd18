"""Checks for the exercises of notebook 3 (registration)."""

from __future__ import annotations

import numpy as np

from helpers.exercises.report import say, unanswered
from helpers.slam.registration.msac import SAMPLE_SIZE

COST_TOLERANCE = 1e-6  # relative: a learner's cost this close to the check's is right


def _msac_cost(T: np.ndarray, moving: np.ndarray, fixed: np.ndarray, max_distance: float) -> float:
    """MSAC's truncated cost of the motion ``T`` on matched points: the sum over the
    matches of min(r^2, max_distance^2), r the distance from a moved ``moving`` point to its ``fixed`` partner."""
    residual = np.linalg.norm(moving @ T[:3, :3].T + T[:3, 3] - fixed, axis=1)
    return float(np.minimum(residual**2, max_distance**2).sum())


def _near(value: float, truth: float) -> bool:
    return abs(value - truth) <= COST_TOLERANCE * max(abs(truth), 1.0)


def _what_it_computed(value: float, T: np.ndarray, moving, fixed, max_distance: float) -> str:
    """A hint naming the score ``value`` is when it is not MSAC's cost."""
    residual = np.linalg.norm(moving @ T[:3, :3].T + T[:3, 3] - fixed, axis=1)
    if _near(value, float(np.sum(residual**2))):
        return "a match farther off than max_distance costs max_distance squared, however far off it is"
    if _near(value, float(np.minimum(residual, max_distance).sum())):
        return "square the residuals (and max_distance) before adding them up"
    if _near(value, float(np.sum(residual < max_distance))):
        return "that counts the inliers, RANSAC's score: MSAC adds up each match's squared residual, truncated"
    return "each match costs min(r^2, max_distance^2), r the distance from T @ its moving point to its fixed point"


def check_msac_cost(msac_cost, moving, fixed, max_distance: float, motions: dict) -> None:
    """Exercise 3.1: ``msac_cost(T)`` is MSAC's truncated cost of a 4 x 4 motion on the matched points
    ``moving`` -> ``fixed`` (K x 3 each); tried on ``motions`` (names to 4 x 4 motions), whose cheapest it names."""
    if unanswered(msac_cost):
        return say(False, "", "define `msac_cost(T)`, then run this cell again")
    moving, fixed = np.asarray(moving, float), np.asarray(fixed, float)
    truth = {name: _msac_cost(np.asarray(T, float), moving, fixed, max_distance) for name, T in motions.items()}
    for name, T in motions.items():
        try:
            answer = float(msac_cost(np.asarray(T, float)))
        except Exception as exc:  # a learner's function may raise anything
            return say(False, "", f"msac_cost raised {type(exc).__name__}: {exc}")
        if not _near(answer, truth[name]):
            return say(False, "", f"for {name}: {_what_it_computed(answer, T, moving, fixed, max_distance)}")
    names = list(motions)
    cheapest = min(names, key=truth.get)
    below = f", less than {names[0]}" if cheapest != names[0] else ""
    return say(True, f"msac_cost agrees on all {len(names)} motions; {cheapest} costs least{below}", "")


def _least_share(max_trials: int, confidence: float) -> float:
    """The smallest share of correct matches ``w`` for which ``max_trials``
    samples of 3 hold an all-correct one with ``confidence``."""
    return (1 - (1 - confidence) ** (1 / max_trials)) ** (1 / SAMPLE_SIZE)


def check_least_share(w_least, max_trials: int, confidence: float, w_pair: float | None = None) -> None:
    """Exercise 3.2: the least share of correct matches for which a cap of
    ``max_trials`` samples still gives ``confidence``; ``w_pair``, when
    given, is a pair's measured share, compared with it."""
    if unanswered(w_least):
        return say(False, "", "set `w_least` (a share between 0 and 1), then run this cell again")
    truth = _least_share(max_trials, confidence)
    try:
        answer = float(w_least)
    except (TypeError, ValueError):
        return say(False, "", "`w_least` is one number, a share between 0 and 1")
    if not abs(answer - truth) <= 1e-3 * truth:
        if answer > 1:
            return say(False, "", "a share lies between 0 and 1 (0.25, not 25 %)")
        return say(False, "", f"with that w, {max_trials} samples give another confidence than {confidence}")
    verdict = ""
    if w_pair is not None:
        enough = w_pair >= truth
        verdict = f"; this pair's measured w is {'above' if enough else 'below'} it"
    return say(True, f"{max_trials} trials reach {confidence:g} confidence from w = {truth:.3f} up{verdict}", "")
