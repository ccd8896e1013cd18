"""Checks for the exercises of notebook 3 (registration)."""

from __future__ import annotations

import math

import numpy as np

from ..errors import SlamError
from ..geometry import rotation_angle_deg
from ..registration import SAMPLE_SIZE, estimate_rigid_msac
from . import say, unanswered

SUCCESS_M = 3.0  # a robust fit within this many metres of the truth leaves ICP an easy job (notebook 3)


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


def trials_for(w: float, confidence: float) -> int:
    """Samples of 3 needed to draw at least one all-inlier sample with ``confidence``."""
    return math.ceil(math.log(1 - confidence) / math.log(1 - w**SAMPLE_SIZE))


def check_trials(
    n_trials, moving, fixed, T_true, max_distance: float, confidence: float = 0.999, seeds: int = 10
) -> None:
    """Exercise 3.2: the trials the formula asks for, for the share of matches
    (``moving[i]`` to ``fixed[i]``) that ``T_true`` carries within
    ``max_distance``, and whether MSAC capped there finds the motion."""
    if unanswered(n_trials):
        return say(False, "", "set `n_trials` from the formula, then run this cell again")
    residual = np.linalg.norm(moving @ T_true[:3, :3].T + T_true[:3, 3] - fixed, axis=1)
    w = float(np.mean(residual < max_distance))
    expected = trials_for(w, confidence)
    if abs(int(n_trials) - expected) > max(1, 0.01 * expected):
        return say(False, "", f"with w = {w:.3f} and p = {confidence} the formula gives another number: check w^3")
    hits = 0
    for seed in range(seeds):
        try:
            T, _ = estimate_rigid_msac(moving, fixed, max_distance, int(n_trials), seed, confidence)
            hits += np.linalg.norm(T[:3, 3] - T_true[:3, 3]) < SUCCESS_M
        except SlamError:
            pass
    ok = hits >= seeds - 1
    return say(
        ok,
        f"the formula's trials; capped there, MSAC lands within {SUCCESS_M:g} m "
        f"on at least {seeds - 1} of {seeds} seeds",
        f"the formula's trials, yet MSAC landed within {SUCCESS_M:g} m on only {hits} of {seeds} seeds",
    )
