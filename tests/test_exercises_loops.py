"""The checks of notebook 5's exercises say ``correct`` for a right answer and ``not yet`` otherwise."""

from types import SimpleNamespace

import gtsam
import numpy as np
import pytest

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.exercises.loops import check_false_loop, check_search_radius
from helpers.slam.pipeline import Edge


def pose(x, y, yaw_deg=0.0):
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:2, 3] = x, y
    return T


def straight_run(config, n_nodes=60, step=6.0):
    """A run flown straight along x, one node every ``step`` m, no edge back, no loop."""
    poses = np.array([pose(step * k, 0.0) for k in range(n_nodes)])
    n = config.map.n_scans_per_submap
    centres = poses[n // 2 : n * (n_nodes // n) : n, :3, 3]
    return SimpleNamespace(
        config=config,
        queries=[SimpleNamespace(node=n_nodes - 1)],
        poses_odometry=poses,
        odometry=SimpleNamespace(information=[]),
        submaps=SimpleNamespace(centres=centres),
        extra_edges=[],
        loops=[],
    )


def test_search_radius_growth(capsys):
    config = Config.reference().with_values(loop_closure={"loop_search_growth": 0.02})
    result = straight_run(config)
    flown = 6.0 * (59 - 1)  # from submap 0's centre (node 1) to node 59
    truth = config.loop_closure.loop_closure_search_radius + 0.02 * flown
    assert check_search_radius(result, 59, 0, truth + 0.01)
    assert capsys.readouterr().out.startswith("correct:")
    assert not check_search_radius(result, 59, 0, config.loop_closure.loop_closure_search_radius)
    assert not check_search_radius(result, 59, 0, None)
    assert capsys.readouterr().out.count("not yet:") == 2
    with pytest.raises(SlamError):
        check_search_radius(result, 58, 0, truth)


def test_search_radius_uncertainty(capsys):
    """The gate's radius from the marginal covariance of submap 0's centre node
    with the current node held (GTSAM's Marginals, computed here directly)."""
    config = Config()
    assert config.loop_closure.search == "uncertainty"
    result = straight_run(config)
    poses, node, centre = result.poses_odometry, 59, 1
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    sigmas = config.pose_graph.edge_sigmas  # translation first; GTSAM's order is rotation first
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.concatenate([sigmas[3:], sigmas[:3]]))
    for k, T in enumerate(poses):
        values.insert(k, gtsam.Pose3(T))
        if k:
            graph.add(gtsam.BetweenFactorPose3(k - 1, k, gtsam.Pose3(np.linalg.inv(poses[k - 1]) @ T), noise))
    graph.add(gtsam.PriorFactorPose3(node, gtsam.Pose3(poses[node]), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
    covariance = gtsam.Marginals(graph, values).marginalCovariance(centre)[3:, 3:]  # node 1's frame = the map's
    offset = poses[centre, :3, 3] - poses[node, :3, 3]
    u = offset / np.linalg.norm(offset)
    extent = 6.0  # submap 0's scans lie 6 m either side of its centre
    settings = config.loop_closure
    truth = (
        settings.loop_closure_search_radius
        + extent
        + settings.search_sigmas / np.sqrt(u @ np.linalg.inv(covariance) @ u)
    )
    assert truth > settings.loop_closure_search_radius + extent + 1.0  # drift along the track widens it
    assert check_search_radius(result, node, 0, truth + 0.02)
    assert capsys.readouterr().out.startswith("correct:")
    assert not check_search_radius(result, node, 0, truth + 0.2)
    assert "search_sigmas" in capsys.readouterr().out


def test_false_loop(capsys):
    poses_gt = np.array([pose(0, 0), pose(5, 1, 10), pose(9, 3, 20)])
    truth = np.linalg.inv(poses_gt[0]) @ poses_gt[2]
    right = Edge(0, 2, truth @ pose(0.3, 0, 0.5), 0.2)
    wrong = Edge(0, 2, truth @ pose(0.2, 0, 3.0), 0.2)  # a small shift, but turned too far
    assert check_false_loop(poses_gt, right, 0.3, 0.5, False)
    assert check_false_loop(poses_gt, wrong, 0.2, 3.0, True)
    assert capsys.readouterr().out.count("correct:") == 2
    assert not check_false_loop(poses_gt, wrong, 0.2, 3.0, False)  # the verdict
    assert not check_false_loop(poses_gt, right, 0.5, 0.5, False)  # the distance
    assert not check_false_loop(poses_gt, right, None, 0.5, False)
    assert capsys.readouterr().out.count("not yet:") == 3


def test_fixed_radius(monkeypatch, capsys):
    import helpers.exercises.loops as loops

    monkeypatch.setattr(loops, "_fixed_radius_loops", lambda result, end: [210, 211])
    result = SimpleNamespace(loops=[SimpleNamespace(j=j) for j in (206, 207, 210, 211, 230)])
    assert loops.check_fixed_radius(result, 212, [211, 210])
    assert "misses" in capsys.readouterr().out
    result.loops = result.loops[2:]
    assert loops.check_fixed_radius(result, 212, [210, 211])
    assert "finds every" in capsys.readouterr().out
    assert not loops.check_fixed_radius(result, 212, [206, 207, 210, 211])
    assert not loops.check_fixed_radius(result, 212, None)
    assert capsys.readouterr().out.count("not yet:") == 2
