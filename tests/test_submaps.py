"""Submaps: the grid merge keeps one point per cell, the pose is the centre scan's."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers.errors import SlamError
from helpers.slam.submaps import SubmapIndex, build_submap, centre_scan_id, scan_ids_of

STEP = 1.2  # m, the reference's alignGridStep


def pose(yaw=0.0, t=(0, 0, 0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", yaw).as_matrix()
    T[:3, 3] = t
    return T


def cells(points, step=STEP) -> np.ndarray:
    return np.floor(points / step).astype(int)


def test_merge_keeps_one_point_per_occupied_cell():
    rng = np.random.default_rng(1)
    scans = [rng.uniform(-10, 10, (2000, 3)) for _ in range(3)]
    poses = [pose(0.3 * k, (2.0 * k, -k, 0.5 * k)) for k in range(3)]
    merged = build_submap(scans, poses, STEP)
    moved = np.concatenate([s @ p[:3, :3].T + p[:3, 3] for s, p in zip(scans, poses, strict=True)])
    occupied = np.unique(cells(moved), axis=0)
    assert len(merged) == len(occupied)  # one point per occupied cell ...
    assert len(np.unique(cells(merged), axis=0)) == len(merged)  # ... each in its own cell
    assert len(merged) < len(moved)


def test_merge_averages_the_points_of_a_cell_after_moving_them():
    a = np.array([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3]])
    b = np.array([[0.1, 0.1, 0.1]])
    merged = build_submap([a, b], [pose(), pose(np.pi / 2, (0.4, 0.4, 0.4))], STEP)
    # b's point lands at (0.3, 0.5, 0.5): same cell, so the cell keeps the mean of three points
    np.testing.assert_allclose(merged, [[(0.1 + 0.3 + 0.3) / 3, (0.1 + 0.3 + 0.5) / 3, (0.1 + 0.3 + 0.5) / 3]])


def test_merge_is_deterministic_and_order_free():
    rng = np.random.default_rng(2)
    scan = rng.uniform(-5, 5, (500, 3))
    first = build_submap([scan], [pose()], STEP)
    again = build_submap([scan[rng.permutation(len(scan))]], [pose()], STEP)
    np.testing.assert_array_equal(first, build_submap([scan], [pose()], STEP))
    np.testing.assert_allclose(again, first, atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
def test_centre_scan_follows_the_reference_rule(n):
    for submap_id in range(4):
        count = (submap_id + 1) * n  # the reference's 1-based count when the group completes
        assert centre_scan_id(submap_id, n) == count - n // 2 - 1  # its 1-based index, made 0-based
        assert centre_scan_id(submap_id, n) in scan_ids_of(submap_id, n)


def test_index_groups_scans_and_takes_the_centre_pose():
    scans = [np.full((4, 3), float(k)) + np.eye(4, 3) for k in range(8)]
    poses = [pose(0.1 * k, (10.0 * k, 0, 700)) for k in range(8)]
    index = SubmapIndex(n_scans_per_submap=3, align_grid_step=STEP)
    built = [index.add_scan(s, p) for s, p in zip(scans, poses, strict=True)]
    assert [b is not None for b in built] == [False, False, True, False, False, True, False, False]
    assert len(index) == 2 and index.num_scans == 8
    assert [s.scan_ids for s in index.submaps] == [(0, 1, 2), (3, 4, 5)]
    np.testing.assert_allclose(index.submaps[1].pose, poses[4])
    np.testing.assert_allclose(index.centres, [[10, 0, 700], [40, 0, 700]])
    np.testing.assert_allclose(index.points[0], build_submap(scans[:3], poses[:3], STEP))
    batch = SubmapIndex(4, STEP)
    for scan, p in zip(scans, poses, strict=True):
        batch.add_scan(scan, p)
    assert len(batch) == 2
    np.testing.assert_allclose(batch.centres, [[10, 0, 700], [50, 0, 700]])  # scans 1 and 5


def test_bad_inputs_raise_slam_error():
    good = np.zeros((3, 3))
    with pytest.raises(SlamError, match="NaN"):
        build_submap([np.full((3, 3), np.nan)], [pose()], STEP)
    with pytest.raises(SlamError, match="rigid"):
        build_submap([good], [2 * np.eye(4)], STEP)
    with pytest.raises(SlamError, match="one pose per scan"):
        build_submap([good, good], [pose()], STEP)
    with pytest.raises(SlamError, match="grid step"):
        build_submap([good], [pose()], 0.0)
    with pytest.raises(SlamError, match="n_scans_per_submap"):
        SubmapIndex(0, STEP)
    with pytest.raises(SlamError, match="N x 3"):
        SubmapIndex(3, STEP).add_scan(np.zeros(3), pose())
