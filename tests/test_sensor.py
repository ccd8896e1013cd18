"""The ray caster against cases with known answers."""

import numpy as np
import pytest

from helpers.config.tables import SensorConfig, noise_seed_from_environment
from helpers.errors import SlamError
from helpers.sim.scene import GROUND, HeightField
from helpers.sim.sensor import Surface, cast_scans, check_coverage, poses_from_waypoints, ray_pattern


def flat_field(height=100.0, half=600.0, cell=5.0):
    n = int(2 * half / cell) + 1
    z = np.full((n, n), height)
    return HeightField(-half, -half, cell, z, np.full((n, n), GROUND, np.uint8), np.ones((n, n), bool))


def test_pattern_is_the_reference_fan():
    pattern = ray_pattern(SensorConfig())
    assert pattern.shape == (326 * 26, 3)
    np.testing.assert_allclose(np.linalg.norm(pattern, axis=1), 1.0)
    assert (pattern[:, 2] < 0).all()  # every ray looks down
    # the widest ray is 13 degrees off nadir across the track, 2.5 along it
    assert np.degrees(np.arctan2(pattern[:, 1], -pattern[:, 2])).max() == pytest.approx(13.0)
    assert np.degrees(np.arcsin(pattern[:, 0])).max() == pytest.approx(2.5)


def test_flat_plane_ranges_are_height_over_cosine():
    sensor = SensorConfig(range_noise=0.0, dropout=0.0)
    altitude, ground = 700.0, 100.0
    poses = poses_from_waypoints(np.array([[0.0, 0.0, altitude], [3.0, 4.0, altitude]]))
    batch = cast_scans(Surface.from_height_field(flat_field(ground)), poses, sensor)
    pattern = ray_pattern(sensor)
    for scan in batch.scans:
        assert len(scan) == len(pattern)  # nothing lost over an endless plane
        ranges = np.linalg.norm(scan, axis=1)
        cos_theta = -pattern[:, 2]  # cos e cos a
        np.testing.assert_allclose(ranges, (altitude - ground) / cos_theta, rtol=1e-5)
    np.testing.assert_allclose(batch.hits[:, 2], ground, atol=1e-3)


def test_max_range_and_dropout_remove_returns():
    field = Surface.from_height_field(flat_field(100.0))
    poses = poses_from_waypoints(np.array([[0.0, 0.0, 700.0]]))
    short = cast_scans(field, poses, SensorConfig(max_range=601.0, range_noise=0.0, dropout=0.0))
    assert 0 < len(short.scans[0]) < 8476
    assert np.linalg.norm(short.scans[0], axis=1).max() <= 601.0 + 1e-6
    sparse = cast_scans(field, poses, SensorConfig(dropout=0.5, seed=noise_seed_from_environment()))
    assert abs(len(sparse.scans[0]) / 8476 - 0.5) < 0.03


def test_range_noise_has_the_configured_spread():
    field = Surface.from_height_field(flat_field(100.0))
    poses = poses_from_waypoints(np.array([[0.0, 0.0, 700.0]]))
    clean = cast_scans(field, poses, SensorConfig(range_noise=0.0, dropout=0.0)).scans[0]
    noisy = cast_scans(
        field, poses, SensorConfig(range_noise=0.05, dropout=0.0, seed=noise_seed_from_environment())
    ).scans[0]
    error = np.linalg.norm(noisy, axis=1) - np.linalg.norm(clean, axis=1)
    assert abs(error.mean()) < 0.005
    assert error.std() == pytest.approx(0.05, rel=0.05)


def test_heading_follows_the_direction_of_travel():
    poses = poses_from_waypoints(np.array([[0.0, 0, 700], [0, 2, 700], [0, 4, 700]]))
    np.testing.assert_allclose(poses[:, :3, 0], [[0, 1, 0]] * 3, atol=1e-12)  # x axis points north
    np.testing.assert_allclose(poses[:, :3, 2], [[0, 0, 1]] * 3, atol=1e-12)
    rotations = poses[:, :3, :3]
    np.testing.assert_allclose(rotations @ rotations.transpose(0, 2, 1), np.tile(np.eye(3), (3, 1, 1)), atol=1e-12)


def test_waypoints_off_the_map_are_named():
    with pytest.raises(SlamError, match=r"2 of 4 waypoints leave the map.*indices 2-3"):
        check_coverage(flat_field(half=100.0), np.array([[0.0, 0, 700], [50, 0, 700], [150, 0, 700], [300, 0, 700]]))
