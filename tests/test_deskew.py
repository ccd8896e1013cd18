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


def _slam_after_steps(step: np.ndarray, starts, span: float, skip: int = 1):
    """A Slam whose odometry measured ``step`` (4 x 4) last, that has deskewed scans with times beginning at
    ``starts`` (all but the last) and ``span`` s long: (the Slam, the last scan's times)."""
    from helpers.config.tables import Config
    from helpers.slam.slam import Slam

    slam = Slam(Config().with_values(registration={"skip_frames": skip}))
    for start in starts[:-1]:
        slam._deskewed(np.zeros((3, 3)), start + np.array([0.0, span / 2, span]))
    slam.odometry.relative.append(step)
    return slam, starts[-1] + np.linspace(0.0, span, 4000)


def test_a_scan_taken_in_part_of_a_step_is_deskewed_with_that_part_of_it():
    """Scans of 0.1 s every 0.2 s on one clock (the simulator's Risley flights at 10 m/s with 2 m waypoints):
    the last step took 0.2 s, so the scan's own motion is half of it. The smear of ``smeared_scan`` over
    the scan's span is then undone by a step of two of its spans, to within a centimetre."""
    seen, share, truth = smeared_scan()
    slam, times = _slam_after_steps(pose_at(2.0), [10.0, 10.2, 10.4], span=0.1)
    times = 10.4 + 0.1 * share  # each point's time on the clock, in the order of the smeared scan
    assert np.linalg.norm(slam._deskewed(seen, times) - truth, axis=1).max() < 0.01
    # Read as if each scan filled its step, the same scan would be deskewed twice too far.
    assert np.linalg.norm(deskew(seen, share, pose_at(2.0)) - truth, axis=1).max() > 0.4


def test_scans_whose_times_start_again_at_zero_fill_their_step():
    """Times from each scan's own start (a PLY's per-scan field): the scans follow one another, and a step of
    ``skip_frames`` scans spans that many of them."""
    seen, share, truth = smeared_scan()
    slam, _ = _slam_after_steps(pose_at(3.0), [0.0, 0.0, 0.0], span=0.1, skip=3)
    assert np.linalg.norm(slam._deskewed(seen, 0.1 * share) - truth, axis=1).max() < 0.01
