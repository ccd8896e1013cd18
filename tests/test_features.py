"""Downsampling, FPFH descriptors and their normalisation."""

import numpy as np
import pytest

from helpers.errors import SlamError
from helpers.slam.registration.features import fpfh, grid_average, keypoint_fpfh, keypoints, normalise_descriptors


def test_grid_average_means_each_cell_in_a_stable_order():
    points = np.array([[0.1, 0.1, 0.1], [0.3, 0.5, 0.2], [1.2, 0.1, 0.1], [1.4, 0.3, 0.3], [-0.5, 0.2, 0.0]])
    out = grid_average(points, 1.0)
    np.testing.assert_allclose(out, [[-0.5, 0.2, 0.0], [0.2, 0.3, 0.15], [1.3, 0.2, 0.2]])
    np.testing.assert_array_equal(grid_average(points[::-1], 1.0), out)


def test_grid_average_refuses_bad_input():
    with pytest.raises(SlamError, match="0 points"):
        grid_average(np.zeros((0, 3)), 1.0)
    with pytest.raises(SlamError, match="NaN"):
        grid_average(np.array([[0.0, np.nan, 0.0]]), 1.0)
    with pytest.raises(SlamError, match="grid step"):
        grid_average(np.zeros((4, 3)), 0.0)


def test_fpfh_is_normalised_and_rotation_invariant():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-20, 20, (800, 2))
    points = np.column_stack([xy, np.sin(xy[:, 0] / 4) * 3 + 0.1 * xy[:, 1]])
    f = fpfh(points, 30)
    assert f.shape == (800, 33)
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), 1.0)
    c, s = np.cos(0.4), np.sin(0.4)
    turned = points @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [5.0, -2.0, 1.0]
    # Angles near a bin edge may fall either side after rounding: most rows agree exactly, all nearly.
    diff = np.abs(fpfh(turned, 30) - f).max(axis=1)
    assert np.mean(diff < 1e-3) > 0.9
    assert diff.max() < 0.1


def test_keypoints_are_the_most_tilted_points_and_keep_their_descriptors():
    rng = np.random.default_rng(4)
    xy = rng.uniform(-20, 20, (900, 2))
    roof = np.abs(xy[:, 0]) < 8  # a gabled roof in the middle of flat ground
    points = np.column_stack([xy, np.where(roof, 10 - 0.8 * np.abs(xy[:, 0]), 0.0)])
    chosen, descriptors = keypoint_fpfh(points, 20, 0.3)
    assert len(chosen) == 270 and np.all(np.diff(chosen) > 0)
    # the slopes, and ground whose 20 neighbours (about 4 m around) reach up the roof's 3.6 m eaves
    assert np.all(roof[chosen] | (np.abs(xy[chosen, 0]) < 8 + 4)) and roof[chosen].mean() > 0.8
    np.testing.assert_allclose(descriptors, fpfh(points, 20)[chosen], atol=1e-12)
    normals = np.array([[0, 0, 1.0], [0, 0.6, 0.8], [1.0, 0, 0], [0, 0, -1.0]])
    np.testing.assert_array_equal(keypoints(normals, 0.5), [1, 2])
    np.testing.assert_array_equal(keypoints(normals, 1.0), [0, 1, 2, 3])
    with pytest.raises(SlamError, match="keypoint share"):
        keypoints(normals, 0.0)


def test_normalisation_makes_histograms_fractions_then_unit_length():
    raw = np.zeros((1, 33))
    raw[0, [0, 11, 22]] = 200.0
    np.testing.assert_allclose(normalise_descriptors(raw)[0, [0, 11, 22]], 1 / np.sqrt(3))


def test_fpfh_refuses_too_few_points_and_nans():
    with pytest.raises(SlamError, match="more than 60 points"):
        fpfh(np.random.default_rng(0).random((60, 3)), 60)
    with pytest.raises(SlamError, match="0 points"):
        fpfh(np.zeros((0, 3)), 60)
    cloud = np.random.default_rng(0).random((100, 3))
    cloud[5, 2] = np.nan
    with pytest.raises(SlamError, match="NaN"):
        fpfh(cloud, 10)


def test_slam_and_odometry_steps_run_on_one_blas_thread(monkeypatch):
    """A scan's processing holds numpy's BLAS to one thread (its idle threads would spin on the
    core FPFH needs) and gives the setting back afterwards."""
    from helpers.config.tables import Config
    from helpers.slam.odometry import Odometry
    from helpers.slam.slam import Slam
    from helpers.threads import BLAS

    def blas_threads():
        return [m["num_threads"] for m in BLAS.info() if m["user_api"] == "blas"]

    before, seen = blas_threads(), []
    assert before
    monkeypatch.setattr(Odometry, "_register", lambda self, frame, index: seen.append(blas_threads()))
    monkeypatch.setattr(Slam, "_process", lambda self, scan, index, prepared: seen.append(blas_threads()))
    Odometry(Config(), np.eye(4)).register(None, 0)
    Slam(Config(), anchor=np.eye(4)).process(None, 0)
    assert seen == [[1] * len(before)] * 2
    assert blas_threads() == before
