"""The checks of notebook 4's exercises say ``correct`` for a right answer and ``not yet`` otherwise."""

from types import SimpleNamespace

import numpy as np
import pytest

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.exercises.submaps import check_centre_and_reach, check_eligible
from helpers.slam.submaps import SubmapIndex, build_submap


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


def test_centre_and_reach_of_a_submap_of_five_scans(run, capsys):
    """Submap 3 of five scans: nodes 15 to 19 merged by build_submap, its pose node 17's."""
    nodes = list(range(15, 20))
    points = build_submap([run.clouds[m] for m in nodes], run.poses_odometry[nodes], run.config.map.align_grid_step)
    centre = run.poses_odometry[17][:3, 3]
    reach = np.linalg.norm(points[:, :2] - centre[:2], axis=1).max()
    assert check_centre_and_reach(run, 3, centre, reach, 5)
    assert "submap 3 of 5 scans" in capsys.readouterr().out
    three = run.submaps.submaps[3]  # the run's own submap 3, of three scans: nodes 9 to 11
    assert not check_centre_and_reach(run, 3, three.centre, reach, 5)
    assert "nodes 15 to 19" in capsys.readouterr().out
    assert not check_centre_and_reach(run, 3, centre, np.linalg.norm(three.points[:, :2] - centre[:2], axis=1).max(), 5)
    assert "build_submap" in capsys.readouterr().out
    with pytest.raises(SlamError):
        check_centre_and_reach(run, 12, centre, reach, 5)  # 60 scans hold submaps 0 to 11 of five


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
