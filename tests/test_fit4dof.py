"""The four-degree-of-freedom robust fit (yaw + translation, msac_yaw), on matches with a known answer."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers.errors import SlamError
from helpers.slam.registration.msac import trials_needed
from helpers.slam.registration.msac_yaw import (
    _distinct_pairs,
    _pair_terms,
    estimate_yaw_msac,
    fit_yaw,
    fit_yaw_translation,
    msac_costs,
    yaw_transform,
)

EXTENT = np.array([50.0, 50.0, 10.0])  # half-extent of the synthetic matched points, m: a scan's strip of ground


def _apply(T, points):
    return points @ T[:3, :3].T + T[:3, 3]


def _moved(seed=0, n=800, yaw_deg=25.0, translation=(6.0, -2.0, 0.4), outlier_fraction=0.0, noise=0.0):
    """Matched points moved by a known yaw + translation, a share of the fixed ones replaced by random points."""
    rng = np.random.default_rng(seed)
    moving = rng.uniform(-EXTENT, EXTENT, (n, 3)) + [1000.0, -300.0, 120.0]
    truth = yaw_transform(np.radians(yaw_deg), translation)
    fixed = _apply(truth, moving) + rng.normal(0.0, noise, (n, 3))
    outliers = rng.random(n) < outlier_fraction
    fixed[outliers] = rng.uniform(-EXTENT, EXTENT, (outliers.sum(), 3)) + fixed.mean(axis=0)
    return moving, fixed, truth, outliers


def test_exact_recovery_of_a_yaw_and_translation():
    moving, fixed, truth, _ = _moved(yaw_deg=-37.0, translation=(12.0, 5.0, -1.5))
    fit = fit_yaw_translation(moving, fixed, 1.0, 3000)
    np.testing.assert_allclose(fit.T, truth, atol=1e-9)
    assert fit.inliers.all() and fit.cost == pytest.approx(0.0, abs=1e-12)
    assert fit.trials == 64  # every match an inlier: one chunk is enough at 99 % confidence


def test_recovery_with_60_percent_outlier_matches():
    moving, fixed, truth, outliers = _moved(seed=4, outlier_fraction=0.6, noise=0.05)
    fit = fit_yaw_translation(moving, fixed, 0.3, 3000, seed=1)
    # Measured at the points (they lie a kilometre from the origin, where a tiny yaw error moves a lot).
    assert np.sqrt(np.mean(np.sum((_apply(fit.T, moving) - _apply(truth, moving)) ** 2, axis=1))) < 0.02
    error = np.linalg.inv(truth) @ fit.T
    assert np.degrees(abs(np.arctan2(error[1, 0], error[0, 0]))) < 0.02
    # The inliers are the true matches, less the few random points that fell near their partner by chance.
    assert np.mean(fit.inliers[~outliers]) > 0.99
    assert np.mean(fit.inliers[outliers]) < 0.01
    # 40 % inliers: 2-point samples need 27 draws at 99 % confidence; 3-point samples need 70.
    assert trials_needed(0.4, 0.99, 3000, 2) == 27 and trials_needed(0.4, 0.99, 3000, 3) == 70
    assert fit.trials < 3000


def test_a_small_tilt_biases_the_fit_by_no_more_than_it_moves_the_points():
    """With a true roll and pitch the fit (which has none) is the least-squares yaw + translation: it
    maps the matches' centroid where the truth does, gets the yaw nearly right, and leaves each point
    off by at most what the tilt moves it about the centroid."""
    rng = np.random.default_rng(7)
    moving = rng.uniform(-EXTENT, EXTENT, (600, 3))
    truth = np.eye(4)
    tilt_deg = 0.5
    truth[:3, :3] = Rotation.from_euler("xyz", [tilt_deg, -tilt_deg, 20.0], degrees=True).as_matrix()
    truth[:3, 3] = [5.0, 1.0, -0.3]
    fixed = _apply(truth, moving)
    fit = fit_yaw_translation(moving, fixed, 1.0, 3000)
    assert fit.T[2, :3] == pytest.approx([0.0, 0.0, 1.0]) and fit.T[:3, 2] == pytest.approx([0.0, 0.0, 1.0])
    assert fit.inliers.all()  # 0.7 degree of tilt moves no point of this strip by 1 m
    centre = moving.mean(axis=0)
    np.testing.assert_allclose(_apply(fit.T, centre[None]), _apply(truth, centre[None]), atol=1e-6)
    yaw_error = np.degrees(np.arctan2(fit.T[1, 0], fit.T[0, 0])) - 20.0
    assert abs(yaw_error) < 0.05
    tilt_rad = np.radians(np.hypot(tilt_deg, tilt_deg))
    reach = np.linalg.norm(moving - centre, axis=1).max()
    worst = np.linalg.norm(_apply(fit.T, moving) - fixed, axis=1).max()
    assert 0.2 * tilt_rad * reach < worst <= tilt_rad * reach  # biased, and by no more than the tilt explains


def test_the_same_seed_gives_the_same_fit_and_another_seed_a_close_one():
    moving, fixed, _, _ = _moved(seed=2, outlier_fraction=0.7, noise=0.1)
    first, again = (fit_yaw_translation(moving, fixed, 0.5, 500, seed=3) for _ in range(2))
    np.testing.assert_array_equal(first.T, again.T)
    np.testing.assert_array_equal(first.inliers, again.inliers)
    assert first.trials == again.trials and first.cost == again.cost
    other = fit_yaw_translation(moving, fixed, 0.5, 500, seed=4)
    assert np.linalg.norm(other.T[:3, 3] - first.T[:3, 3]) < 0.05
    T, inliers = estimate_yaw_msac(moving, fixed, 0.5, 500, seed=3)  # the 6-DoF fit's signature and result
    np.testing.assert_array_equal(T, first.T)
    np.testing.assert_array_equal(inliers, first.inliers)


def test_points_on_a_vertical_line_are_refused_in_one_clear_error():
    z = np.linspace(0.0, 30.0, 50)
    moving = np.column_stack([np.full(50, 3.0), np.full(50, -2.0), z])
    fixed = moving + [1.0, 2.0, 0.5]
    with pytest.raises(SlamError, match=r"degenerate.*fix no yaw"):
        fit_yaw_translation(moving, fixed, 1.0, 300)


def test_too_few_inliers_and_bad_arguments_are_refused():
    rng = np.random.default_rng(0)
    moving, fixed = rng.uniform(-EXTENT, EXTENT, (2, 200, 3))  # no motion explains random pairs
    with pytest.raises(SlamError, match="explains enough matches"):
        fit_yaw_translation(moving, fixed, 0.05, 300)
    with pytest.raises(SlamError, match="differ in length"):
        fit_yaw_translation(moving, fixed[:-1], 1.0, 300)
    with pytest.raises(SlamError, match="at least 2 matches"):
        fit_yaw_translation(moving[:1], fixed[:1], 1.0, 300)
    with pytest.raises(SlamError, match="max_distance must be positive"):
        fit_yaw_translation(moving, fixed, 0.0, 300)
    with pytest.raises(SlamError, match="confidence"):
        fit_yaw_translation(moving, fixed, 1.0, 300, confidence=1.0)


def test_the_expanded_cost_equals_the_clipped_squared_residuals():
    rng = np.random.default_rng(5)
    moving, fixed = rng.normal(0.0, 5.0, (2, 300, 3))
    yaw, offset = rng.uniform(-np.pi, np.pi, 20), rng.normal(0.0, 3.0, (20, 3))
    terms = _pair_terms(moving, fixed)
    for limit in (1.0, 100.0):  # clipping most residuals, and none
        direct = [
            np.minimum(((_apply(yaw_transform(a, t), moving) - fixed) ** 2).sum(axis=1), limit**2).sum()
            for a, t in zip(yaw, offset, strict=True)
        ]
        np.testing.assert_allclose(msac_costs(yaw, offset, terms, limit), direct, rtol=1e-9)


def test_weighted_least_squares_yaw_ignores_pairs_of_zero_weight():
    moving, fixed, truth, outliers = _moved(seed=9, outlier_fraction=0.3)
    angle, offset = fit_yaw(moving, fixed, weights=(~outliers).astype(float))
    np.testing.assert_allclose(yaw_transform(angle, offset), truth, atol=1e-9)


def test_a_lower_trial_cap_cuts_the_same_samples_short():
    moving, fixed, _, _ = _moved(seed=6, outlier_fraction=0.85, noise=0.05)
    full = fit_yaw_translation(moving, fixed, 0.3, 3000, seed=2)
    cut = fit_yaw_translation(moving, fixed, 0.3, full.trials, seed=2)
    assert full.trials < 3000  # it stopped early, after the very samples the cut run draws
    np.testing.assert_array_equal(cut.T, full.T)
    pairs = _distinct_pairs(np.random.default_rng(0), 5, 20000)
    assert (pairs[:, 0] != pairs[:, 1]).all() and pairs.min() == 0 and pairs.max() == 4
    assert np.bincount(pairs.ravel(), minlength=5) == pytest.approx(np.full(5, 8000), rel=0.05)
