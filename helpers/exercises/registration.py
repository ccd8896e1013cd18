"""Checks for the exercises of notebook 3 (registration)."""

from __future__ import annotations

import math

import numpy as np

from helpers.exercises.report import say, unanswered
from helpers.geometry import rotation_angle_deg
from helpers.slam.registration.msac import SAMPLE_SIZE


def _rotations(count: int, seed: int = 0) -> np.ndarray:
    """(count, 4, 4) transforms with random axes, angles spread over [0, 180] deg, and random shifts."""
    rng = np.random.default_rng(seed)
    angles = np.radians(np.r_[0.0, 1e-3, 0.5, 179.9, 180.0, rng.uniform(0, 180, count - 5)])
    axes = rng.normal(size=(count, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    out = np.tile(np.eye(4), (count, 1, 1))
    for T, axis, angle in zip(out, axes, angles, strict=True):
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        T[:3, :3] = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k  # Rodrigues
        T[:3, 3] = rng.normal(scale=10.0, size=3)
    return out


def check_rotation_angle(angle_deg, count: int = 20, tolerance: float = 1e-4) -> None:
    """Exercise 3.1: ``angle_deg(T)`` returns the rotation angle of a 4 x 4 transform in degrees."""
    if unanswered(angle_deg):
        return say(False, "", "define `angle_deg(T)`, then run this cell again")
    transforms = _rotations(count)
    truth = rotation_angle_deg(transforms)
    try:
        answers = np.array([float(angle_deg(T)) for T in transforms])
    except Exception as exc:  # a learner's function may raise anything
        return say(False, "", f"angle_deg raised {type(exc).__name__}: {exc}")
    wrong = np.flatnonzero(~(np.abs(answers - truth) <= tolerance))
    if len(wrong):
        i = wrong[0]
        hint = f"for a rotation of {truth[i]:.4f} deg angle_deg gives {answers[i]:.4f}"
        if np.any(np.isnan(answers)):
            hint += " (a NaN: keep the cosine within [-1, 1] with np.clip)"
        return say(False, "", hint)
    return say(True, f"angle_deg gives the angle of all {count} test rotations, 0 and 180 deg included", "")


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
