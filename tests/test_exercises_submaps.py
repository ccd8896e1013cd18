"""The checks of notebook 4's exercises say ``correct`` for a right answer and ``not yet`` otherwise."""

from types import SimpleNamespace

import numpy as np
import pytest

from helpers.config.tables import Config
from helpers.exercises.submaps import check_centre_and_reach, check_eligible
from helpers.slam.submaps import SubmapIndex


@pytest.fixture(scope="module")
def run():
    """A stand-in for a SLAM result: 60 small random scans flown along x, 2 m apart, in submaps of 3."""
    config = Config()
    rng = np.random.default_rng(1)
    clouds = [rng.uniform(-20, 20, (200, 3)) for _ in range(60)]
    poses = np.repeat(np.eye(4)[None], 60, axis=0)
    poses[:, 0, 3] = 2.0 * np.arange(60)
    index = SubmapIndex(config.map.n_scans_per_submap, config.map.align_grid_step)
    for cloud, pose in zip(clouds, poses, strict=True):
        index.add_scan(cloud, pose)
    return SimpleNamespace(config=config, clouds=clouds, poses_odometry=poses, submaps=index)


def test_centre_and_reach(run, capsys):
    sub = run.submaps.submaps[4]
    centre = run.poses_odometry[sub.scan_ids[1]][:3, 3]
    reach = np.linalg.norm(sub.points[:, :2] - centre[:2], axis=1).max()
    assert check_centre_and_reach(run, 4, centre, reach)
    assert capsys.readouterr().out.startswith("correct:")
    assert not check_centre_and_reach(run, 4, run.poses_odometry[sub.scan_ids[0]][:3, 3], reach)
    assert not check_centre_and_reach(run, 4, centre, reach + 1.0)
    assert not check_centre_and_reach(run, 4, None, None)
    assert capsys.readouterr().out.count("not yet:") == 3


def test_eligible(run, capsys):
    thresh = 15
    node = 59  # 20 submaps built: 0 .. 4 are old enough
    assert check_eligible(run, node, thresh, [0, 1, 2, 3, 4])
    assert check_eligible(run, 47, thresh, [0])  # node 47 completes submap 15: 16 built, the first query
    assert check_eligible(run, 46, thresh, [])  # 15 built: none old enough
    assert capsys.readouterr().out.count("correct:") == 3
    assert not check_eligible(run, node, thresh, [0, 1, 2, 3])
    assert not check_eligible(run, node, thresh, list(range(20)))
    assert not check_eligible(run, node, thresh, ...)
    assert capsys.readouterr().out.count("not yet:") == 3
