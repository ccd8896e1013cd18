"""The deskew (helpers.slam.deskew) against a scan smeared by a known constant-velocity motion: each point
taken from the pose of its own time, under GTSAM's exact SE(3) exponential."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from helpers.errors import SlamError
from helpers.slam.deskew import deskew, normalised, per_period

# one period: 1 m forward, 0.1 m sideways and 2 deg of yaw (10 m/s and 20 deg/s over 0.1 s), rotation first
XI = np.array([0.0, 0.0, np.radians(2.0), 1.0, 0.1, 0.0])


def pose_at(t: float) -> np.ndarray:
    return gtsam.Pose3.Expmap(t * XI).matrix()


def smeared_scan(n: int = 4000, seed: int = 0):
    """Ground points 100 m below, each seen from the pose of its time t in [0, 1]: (seen, times, truth in
    the frame of t = 0.5)."""
    rng = np.random.default_rng(seed)
    world = np.column_stack([rng.uniform(-40, 40, n), rng.uniform(-40, 40, n), np.full(n, -100.0)])
    times = np.sort(rng.uniform(0, 1, n))
    seen = np.array([np.linalg.inv(pose_at(t)) @ np.append(p, 1.0) for p, t in zip(world, times, strict=True)])
    middle = (np.linalg.inv(pose_at(0.5)) @ np.column_stack([world, np.ones(n)]).T).T
    return seen[:, :3], times, middle[:, :3]


def test_a_scan_smeared_by_a_known_motion_is_deskewed_to_within_a_centimetre():
    seen, times, truth = smeared_scan()
    smear = np.linalg.norm(seen - truth, axis=1).max()
    fixed = np.linalg.norm(deskew(seen, times, pose_at(1.0)) - truth, axis=1).max()
    assert smear > 0.4  # the smear is real: half a period of motion at the ends
    assert fixed < 0.01


def test_points_taken_at_the_middle_do_not_move():
    points = np.random.default_rng(1).normal(size=(50, 3))
    assert np.array_equal(deskew(points, np.full(50, 0.5), pose_at(1.0)), points)


def test_a_step_over_several_periods_gives_the_motion_of_one():
    three = pose_at(3.0)
    assert np.allclose(per_period(three, 3), pose_at(1.0), atol=1e-3)


def test_times_are_shares_of_the_scans_span():
    assert np.allclose(normalised(np.array([10.0, 10.05, 10.1])), [0.0, 0.5, 1.0])
    assert np.allclose(normalised(np.array([3.0, 3.0])), [0.5, 0.5])
    with pytest.raises(SlamError, match="finite"):
        normalised(np.array([0.0, np.nan]))
