"""The checks of notebook 5's exercises say ``correct`` for a right answer and ``not yet`` otherwise."""

from types import SimpleNamespace

import gtsam
import numpy as np
import pytest

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.exercises.loops import check_row_slip, check_search_radius
from helpers.slam.pipeline import Edge
from helpers.slam.registration.icp import icp_rmse
from helpers.slam.registration.icp_service import surface_rmse


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


def row_slip_run(rmse_threshold):
    """Two scans of rolling ground with a house, the second taken 6 m further along x and turned by 5 deg;
    the run's loop edge between them is right, and a copy of it slipped 2.1 m along the track is not."""
    x, y = np.meshgrid(np.arange(-30.0, 30.0, 0.7), np.arange(-20.0, 20.0, 0.7))
    z = 2.0 * np.sin(x / 7.0) * np.cos(y / 5.0) + 6.0 * ((np.abs(x - 4) < 5) & (np.abs(y) < 4))
    ground = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    T_true = pose(6.0, 0.0, 5.0)
    moving = ground @ np.linalg.inv(T_true)[:3, :3].T + np.linalg.inv(T_true)[:3, 3]
    config = Config().with_values(loop_closure={"rmse_threshold": rmse_threshold})
    result = SimpleNamespace(config=config, indices=np.array([0, 1]), clouds=[ground, moving])
    dataset = SimpleNamespace(poses=np.array([np.eye(4), T_true]))
    slipped = pose(2.1, 0.0) @ T_true
    return result, dataset, Edge(0, 1, T_true, 0.0), Edge(0, 1, slipped, 0.0)


def test_row_slip(capsys):
    result, dataset, right, slipped = row_slip_run(rmse_threshold=10.0)
    moving, fixed = result.clouds[1], result.clouds[0]
    score = surface_rmse(moving, fixed, slipped.relative, 3.0)
    assert surface_rmse(moving, fixed, right.relative, 3.0) < 0.01 < score < 10.0
    assert check_row_slip(result, dataset, slipped, True, score, True)
    assert "a false loop edge, and its score is under rmse_threshold" in capsys.readouterr().out
    strict, _, _, _ = row_slip_run(rmse_threshold=score / 2)
    assert check_row_slip(strict, dataset, slipped, True, score, False)
    assert "the threshold refuses it" in capsys.readouterr().out
    assert check_row_slip(result, dataset, right, False, 0.0, True)
    assert "a right loop edge" in capsys.readouterr().out
    assert not check_row_slip(result, dataset, slipped, False, score, True)  # the verdict
    assert "how far off" in capsys.readouterr().out
    p2p = icp_rmse(moving, fixed, slipped.relative, 3.0)
    assert not check_row_slip(result, dataset, slipped, True, p2p, True)  # the point-to-point RMSE
    assert "point-to-point" in capsys.readouterr().out
    assert not check_row_slip(result, dataset, slipped, True, score, False)  # the threshold's answer
    assert not check_row_slip(result, dataset, slipped, None, score, True)
    assert capsys.readouterr().out.count("not yet:") == 2


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
