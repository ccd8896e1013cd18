"""The loop search's uncertainty: the relative covariance of a chain against
its analytic sum, what a loop edge does to it, and the Mahalanobis gate."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers.config.tables import PoseGraphConfig
from helpers.errors import SlamError
from helpers.geometry import adjoint
from helpers.slam.graph.factors import Edge
from helpers.slam.loops.search import mahalanobis_gate
from helpers.slam.loops.uncertainty import RelativeUncertainty, edge_information

SIGMA_M = 0.1


def step(x=6.0, yaw_deg=0.0, pitch_deg=0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("zy", [yaw_deg, pitch_deg], degrees=True).as_matrix()
    T[:3, 3] = [x, 0.0, 0.0]
    return T


def chain(steps, settings, refresh_nodes=12):
    graph = RelativeUncertainty(settings, refresh_nodes=refresh_nodes)
    pose = np.eye(4)
    graph.add_node(pose)
    poses = [pose]
    for s in steps:
        pose = pose @ s
        graph.add_node(pose)
        poses.append(pose)
    return graph, np.array(poses)


def test_a_straight_chain_adds_its_step_variances():
    # Rotations held (almost) exactly: the position of node c relative to node n is off by n - c independent steps.
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=1e-6)
    graph, _ = chain([step()] * 30, settings)
    cov = graph.position_covariances([0, 10, 29])
    for c, covariance in zip([0, 10, 29], cov, strict=True):
        np.testing.assert_allclose(covariance, (30 - c) * SIGMA_M**2 * np.eye(3), rtol=1e-5, atol=1e-9)


def analytic_position_covariance(poses, c, step_covariance):
    """Node c's position relative to the last node: the sum over the steps between them of each
    step's noise carried to node c by the adjoint (GTSAM's right perturbation, rotation first)."""
    n = len(poses) - 1
    total = np.zeros((6, 6))
    for k in range(c + 1, n + 1):  # step k joins node k - 1 to node k; its noise sits in node k's frame
        A = adjoint(np.linalg.inv(poses[c]) @ poses[k])
        total += A @ step_covariance @ A.T
    R = poses[c][:3, :3]
    return R @ total[3:, 3:] @ R.T


@pytest.mark.parametrize("refresh_nodes", [1, 5, 100])
def test_a_turning_3d_chain_matches_the_analytic_sum(refresh_nodes):
    # Rotation noise makes the old place's position uncertain across the track, the more the farther:
    # the tracker must give the analytic compounding, whether it recomputes or reuses between nodes.
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=0.3)
    steps = [step(6.0, yaw_deg=3.0, pitch_deg=0.5 * (-1) ** k) for k in range(20)]
    graph, poses = chain(steps[:8], settings, refresh_nodes)
    graph.position_covariances([0])  # computed here, then reused as the chain grows
    for k in range(8, 20):
        graph.add_node(poses[-1] @ steps[k])
        poses = np.concatenate([poses, [poses[-1] @ steps[k]]])
    q = np.diag(np.r_[np.full(3, np.radians(0.3)), np.full(3, SIGMA_M)] ** 2)  # rotation first
    cov = graph.position_covariances([0, 7, 15])
    for c, covariance in zip([0, 7, 15], cov, strict=True):
        np.testing.assert_allclose(covariance, analytic_position_covariance(poses, c, q), rtol=1e-5, atol=1e-9)
    lateral = cov[0][1, 1]  # across the track the rotation noise dominates over the 20 steps' translation
    assert lateral > 5 * 20 * SIGMA_M**2


def test_a_loop_edge_shrinks_the_covariance_as_two_parallel_measurements():
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=1e-6)
    graph, poses = chain([step()] * 40, settings)
    before = graph.position_covariances([0])[0]
    graph.add_edge(Edge(0, 40, np.linalg.inv(poses[0]) @ poses[40]), loop=True)  # a loop edge: one step's sigma
    after = graph.position_covariances([0, 20])
    expected = 1.0 / (1.0 / (40 * SIGMA_M**2) + 1.0 / SIGMA_M**2)  # the chain and the loop, in parallel
    np.testing.assert_allclose(before, 40 * SIGMA_M**2 * np.eye(3), rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(after[0], expected * np.eye(3), rtol=1e-5, atol=1e-9)
    # Node 20 lies halfway round the closed loop: two chains of 20 and 21 steps (one of them the loop edge).
    middle = 1.0 / (1.0 / (20 * SIGMA_M**2) + 1.0 / (21 * SIGMA_M**2))
    np.testing.assert_allclose(after[1], middle * np.eye(3), rtol=1e-5, atol=1e-9)


def test_edges_take_the_weights_the_pose_graph_gives_them():
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=0.3)
    back = Edge(3, 7, np.eye(4))
    np.testing.assert_allclose(np.diag(edge_information(back, settings)), (4 * settings.edge_sigmas) ** -2.0)
    np.testing.assert_allclose(np.diag(edge_information(back, settings, loop=True)), settings.edge_sigmas**-2.0)
    np.testing.assert_allclose(edge_information(back, PoseGraphConfig(graph_weights="identity")), np.eye(6))
    own = np.diag([4.0, 1.0, 9.0, 100.0, 100.0, 100.0])
    measured = Edge(3, 7, np.eye(4))
    object.__setattr__(measured, "information", own)  # as the registration will hand it over
    # icp weights ignore it, as build_pose_graph does; hessian weights take it, an edge back's divided by its span
    np.testing.assert_allclose(edge_information(measured, settings), edge_information(back, settings))
    hessian = PoseGraphConfig(graph_weights="hessian")
    np.testing.assert_allclose(edge_information(measured, hessian), own / 4)
    np.testing.assert_allclose(edge_information(measured, hessian, loop=True), own)


def test_the_gate_keeps_a_true_revisit_and_refuses_a_far_place():
    radius, sigmas = 7.9, 3.0
    here = np.array([0.0, 0.0, 700.0])
    drift = np.diag([4.0, 1.0, 0.25])  # 2 m along x, 1 m along y, 0.5 m in height
    centres = here + np.array(
        [
            [5.0, 0.0, 0.0],  # within the fixed radius: a revisit whatever the uncertainty
            [7.9 + 5.0, 0.0, 0.0],  # 5 m beyond it along x: 2.5 sigmas, in reach
            [0.0, 7.9 + 5.0, 0.0],  # 5 m beyond it along y: 5 sigmas, out of reach
            [100.0, 0.0, 0.0],  # far away
        ]
    )
    reach, radii = mahalanobis_gate(centres, here, np.repeat(drift[None], 4, 0), radius, sigmas)
    assert reach.tolist() == [True, True, False, False]
    np.testing.assert_allclose(radii, [radius + 6.0, radius + 6.0, radius + 3.0, radius + 6.0])
    reach, radii = mahalanobis_gate(centres, here, np.zeros((4, 3, 3)), radius, sigmas)  # no uncertainty
    assert reach.tolist() == [True, False, False, False]
    np.testing.assert_allclose(radii, radius, atol=1e-5)


def test_bad_nodes_and_edges_raise_slam_error():
    graph, _ = chain([step()] * 3, PoseGraphConfig())
    with pytest.raises(SlamError):
        graph.position_covariances([4])
    with pytest.raises(SlamError):
        graph.add_edge(Edge(0, 5, np.eye(4)))
    with pytest.raises(SlamError):
        graph.add_node(np.eye(4), Edge(0, 4, np.eye(4)))


class AlwaysMatches:
    """ICP that finds every old place where the odometry puts it (RMSE 0.1 m, well pinned), counting its calls."""

    def __init__(self):
        self.calls = 0

    def __call__(self, *, moving, fixed, T_fixed_moving, max_iterations=None):
        self.calls += 1
        return T_fixed_moving, 0.1

    def constraint(self, **_):
        return 1.0


def hairpin(closer, n_out=30):
    """Out along x in 6 m steps, then back over the same line: every node on the way back is a revisit.
    Returns the nodes that closed a loop and how many queries registered anything."""
    xs = np.r_[6.0 * np.arange(n_out), 6.0 * np.arange(n_out - 1, -1, -1) + 1.0]
    poses, clouds, closed, queried = [], [], [], 0
    for node, x in enumerate(xs):
        poses.append(step(x))
        clouds.append(np.zeros((4, 3)))
        query = closer.add(node, clouds[-1], poses[-1], clouds, np.array(poses))
        queried += query is not None
        if query is not None and query.closure is not None:
            closed.append(node)
    return closed, queried


@pytest.mark.parametrize("search", ["uncertainty", "growth"])
def test_after_a_loop_the_same_place_waits_skip_after_loop_scans(search):
    from helpers.config.tables import Config
    from helpers.slam.loops.closer import LoopCloser

    def run(skip):
        settings = Config().with_values(loop_closure={"sub_map_thresh": 2, "search": search, "skip_after_loop": skip})
        icp = AlwaysMatches()
        closer = LoopCloser(settings.loop_closure, settings.map, icp, settings.pose_graph)
        closed, queried = hairpin(closer)
        return closed, queried, icp.calls, closer.skipped

    every, queried, calls, skipped = run(0)
    assert skipped == 0 and len(every) == queried > 20  # every revisiting node queries and closes
    waited, _, calls_6, skipped_6 = run(6)
    assert set(waited) <= set(every) and skipped_6 > 0 and calls_6 < calls / 4
    # The loops that matter stay: the first revisit closes as before, and no stretch of the way back
    # goes longer than the window without a loop edge.
    assert waited[0] == every[0]
    assert np.diff(waited).max() <= 7 and every[-1] - waited[-1] <= 7


def test_answers_carried_over_are_never_narrower_and_a_wanted_node_is_exact():
    # A loop and more nodes after the first answers: a node no query wants keeps its carried answer,
    # at least as wide as the exact one; a wanted node gets the exact one, as a graph computed afresh.
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=0.3)
    steps = [step(6.0, yaw_deg=4.0) for _ in range(61)]  # the last query computes anew (every 5 nodes from 41)
    graph, poses = chain(steps[:40], settings, refresh_nodes=5)
    old = [0, 10, 20]
    graph.position_covariances(old)
    graph.add_edge(Edge(0, 40, np.linalg.inv(poses[0]) @ poses[40]), loop=True)
    for s in steps[40:]:
        poses = np.concatenate([poses, [poses[-1] @ s]])
        graph.add_node(poses[-1])
        graph.add_edge(Edge(len(poses) - 3, len(poses) - 1, np.linalg.inv(poses[-3]) @ poses[-1]))  # edges back
        carried = graph.position_covariances(old, wanted=lambda c: np.zeros(len(c), bool))
    fresh, _ = chain(steps[:40], settings)
    fresh.add_edge(Edge(0, 40, np.linalg.inv(poses[0]) @ poses[40]), loop=True)
    for k in range(41, 62):
        fresh.add_node(poses[k])
        fresh.add_edge(Edge(k - 2, k, np.linalg.inv(poses[k - 2]) @ poses[k]))
    exact = fresh.position_covariances(old)
    for wide, right in zip(carried, exact, strict=True):
        assert np.linalg.eigvalsh(wide - right).min() > -1e-9 * np.trace(right)
    assert np.trace(carried[0]) > 1.5 * np.trace(exact[0])  # the loop's shrinking was not carried over
    wanted = graph.position_covariances(old, wanted=lambda c: np.array([True, False, True]))
    np.testing.assert_allclose(wanted[[0, 2]], exact[[0, 2]], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(wanted[1], carried[1])


def test_after_a_loop_the_graph_moves_the_old_places_by_the_weighted_measurements():
    # The chain says node 0 lies 240 m behind node 40, a loop edge (one step's sigma) says 236 m: held at node 40,
    # the graph puts node 0 at the inverse-variance mean, and node 20 shares the correction by its chain's share.
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=1e-6)
    graph, poses = chain([step()] * 40, settings)
    graph.add_edge(Edge(0, 40, step(236.0)), loop=True)
    graph.position_covariances([0, 20])
    w_chain, w_loop = 1 / (40 * SIGMA_M**2), 1 / SIGMA_M**2
    behind = (240.0 * w_chain + 236.0 * w_loop) / (w_chain + w_loop)
    expected_0 = poses[40][:3, 3] - [behind, 0, 0]
    expected_20 = poses[20][:3, 3] + [(240.0 - behind) * 20 / 40, 0, 0]
    np.testing.assert_allclose(graph.positions([0, 20]), [expected_0, expected_20], atol=1e-6)


def test_the_uncertainty_search_closes_the_loop_of_a_short_flight(short_loop):
    from helpers.config.tables import Config
    from helpers.quality.evaluation import grade_loops, run_metrics
    from helpers.slam.pipeline import run_slam

    config = Config().with_values(loop_closure={"sub_map_thresh": 3, "search": "uncertainty", "skip_after_loop": 0})
    result = run_slam(short_loop, config)
    m = run_metrics(short_loop, result)
    assert m["n_loop_closures"] >= 3 and m["n_false_loop_closures"] == 0
    assert m["ate_rmse_optimized_m"] < 0.5 * m["ate_rmse_odometry_m"]
    for loop in grade_loops(short_loop, result):
        assert loop.error_m < 1.0 and loop.error_deg < 2.0


def test_with_gnss_the_loop_search_finds_the_revisit_a_missed_turn_hid(short_loop):
    # The short flight's own odometry with 45 degrees of one early turn taken out (a turn over a featureless
    # field): it comes back to its start some 40 m off, and the search held at the odometry closes nothing.
    # With a 1 m fix at every scan the run hands the fixes to its loop search (Slam -> LoopCloser ->
    # RelativeUncertainty.add_fix), which then looks where they put the flight and closes true loops.
    import dataclasses

    from helpers.config.tables import Config
    from helpers.quality.evaluation import grade_loops, run_metrics
    from helpers.sim.gnss import GnssFixes, simulate_gnss
    from helpers.slam.pipeline import run_slam

    config = Config().with_values(loop_closure={"sub_map_thresh": 3, "search": "uncertainty", "skip_after_loop": 0})
    odometry = run_slam(short_loop, config).odometry
    relative = odometry.relative.copy()
    relative[8] = relative[8] @ np.linalg.inv(step(0.0, yaw_deg=45.0))
    poses = [odometry.poses[0]]
    for motion in relative:
        poses.append(poses[-1] @ motion)
    bent = dataclasses.replace(odometry, poses=np.array(poses), relative=relative)
    sigma = 1.0
    fixes = simulate_gnss(short_loop.poses[:, :3, 3], sigma, sigma, seed=0)
    gnss = GnssFixes(np.arange(len(short_loop)), fixes, np.full(3, sigma))
    alone, held = run_slam(short_loop, config, odometry=bent), run_slam(short_loop, config, odometry=bent, gnss=gnss)
    assert run_metrics(short_loop, alone)["n_loop_closures"] == 0
    m = run_metrics(short_loop, held)
    assert m["ate_rmse_odometry_m"] > 20.0
    assert m["n_loop_closures"] >= 2 and m["n_false_loop_closures"] == 0
    for loop in grade_loops(short_loop, held):
        assert loop.error_m < 1.0 and loop.error_deg < 2.0


def laps_graph(settings, n_laps=3, per_lap=60, window_nodes=None):
    """A 60-node circle flown ``n_laps`` times, edges back over 2 nodes and a loop edge every 4th node of
    every lap after the first to the same place one lap before; the graph holding it and the poses."""

    def pose(k):
        a = 2 * np.pi * k / per_lap
        T = step(0.0, yaw_deg=np.degrees(a))
        T[:3, 3] = [60.0 * np.cos(a), 60.0 * np.sin(a), 0.0]
        return T

    graph = RelativeUncertainty(settings, window_nodes=window_nodes or n_laps * per_lap)
    poses = [pose(k) for k in range(n_laps * per_lap)]
    for k, T in enumerate(poses):
        graph.add_node(T)
        if k >= 2:
            graph.add_edge(Edge(k - 2, k, np.linalg.inv(poses[k - 2]) @ T))
        if k >= per_lap and k % 4 == 0:
            graph.add_edge(Edge(k - per_lap, k, np.linalg.inv(poses[k - per_lap]) @ T), loop=True)
    return graph, np.array(poses)


def test_a_window_of_the_graph_answers_on_the_wide_side_and_nothing_outside_it():
    # Three laps (180 nodes), a window of 70: the nodes near the current one along the edges (the last lap's end
    # and the places it closed loops with) are answered, never narrower than the whole graph; the rest is NaN.
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=0.3)
    whole, _ = laps_graph(settings)
    windowed, poses = laps_graph(settings, window_nodes=70)
    nodes = np.arange(0, 170, 3)
    exact = whole.position_covariances(nodes)
    answer = windowed.position_covariances(nodes, wanted=lambda c: np.isfinite(c).all(axis=(1, 2)))
    inside = np.isfinite(answer).all(axis=(1, 2))
    assert 15 <= inside.sum() <= 24 and windowed.whole == 0  # at most 70 nodes, and every third of them asked
    near = lambda lo, hi: (nodes >= lo) & (nodes <= hi)  # noqa: E731
    # this lap's end and the same place in each lap before (joined to it by loop edges) are in; the far side is not
    assert inside[near(162, 179) | near(105, 127) | near(47, 65)].all() and not inside[near(10, 40)].any()
    for wide, right in zip(answer[inside], exact[inside], strict=True):
        assert np.linalg.eigvalsh(wide - right).min() > -1e-9 * np.trace(right)
    assert np.isnan(windowed.positions(nodes[~inside])).all()
    np.testing.assert_allclose(windowed.positions([179]), poses[[179], :3, 3], atol=1e-6)  # the anchor stays put


def test_a_place_only_the_whole_graph_reaches_is_answered_from_it():
    # If no node of the window could be in reach (a first revisit: only the long way round joins it), the query
    # computes the whole graph for its anchor, and answers as a graph that never had a window.
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=0.3)
    whole, _ = laps_graph(settings)
    windowed, _ = laps_graph(settings, window_nodes=70)
    nodes = np.arange(0, 40, 3)  # the first lap's start: beyond the window
    answer = windowed.position_covariances(nodes, wanted=lambda c: np.isfinite(c).all(axis=(1, 2)) & False)
    assert windowed.whole == 1 and np.isfinite(answer).all()
    exact, far = whole.position_covariances(nodes), nodes > 4  # nodes 0 and 3 were answered by the window first
    np.testing.assert_allclose(answer[far], exact[far], rtol=1e-6, atol=1e-12)
    for wide, right in zip(answer[~far], exact[~far], strict=True):
        assert np.linalg.eigvalsh(wide - right).min() > -1e-9 * np.trace(right)
    np.testing.assert_allclose(windowed.positions(nodes), whole.positions(nodes), atol=1e-6)


def test_a_closed_place_is_the_ground_not_one_pass_over_it():
    # Pass A flies submaps 0-9 out along x (centres every 10 m), pass B submaps 10-19 back 1 m beside it. A loop
    # just closed on submap 3 closes submaps 1-5 of pass A (the old track flown since) and, given the centres,
    # pass B's submaps over the same ground (within the 7.9 m radius of one of them), and no others.
    from helpers.slam.loops.search import closed_places

    centres = np.zeros((20, 3))
    centres[:10, 0] = 10.0 * np.arange(10)
    centres[10:, 0] = 91.0 - 10.0 * np.arange(10)
    loops = [Edge(17, 120, np.eye(4))]  # scan 17 lies in submap 3 (5 scans a submap)
    assert closed_places(loops, 122, 3, 5) == {1, 2, 3, 4, 5}
    assert closed_places(loops, 122, 3, 5, centres=centres, radius=7.9) == {1, 2, 3, 4, 5, 14, 15, 16, 17, 18}
    assert closed_places(loops, 124, 3, 5, centres=centres, radius=7.9) == set()  # the window has passed


def test_a_place_an_earlier_pass_closed_waits_longer():
    """Three passes, 5 scans a submap: the second closed scan 17's place at scan 70, the third closes scan 70's
    at 140. That place was closed before (by the loop found 70 scans earlier, beyond the 45-scan gap), so its
    wait is window_closed (12 scans, reaching 4 submaps either side) instead of 3; a first closure, or a loop
    whose earlier neighbour lies within the gap (the same pass), keeps the short wait."""
    from helpers.slam.loops.search import closed_places

    third_pass = [Edge(17, 70, np.eye(4)), Edge(70, 140, np.eye(4))]
    assert closed_places(third_pass, 145, 3, 5, window_closed=12, gap=45) == set(range(10, 19))
    assert closed_places(third_pass, 145, 3, 5) == set()  # without it the 3-scan wait has passed
    assert closed_places(third_pass, 153, 3, 5, window_closed=12, gap=45) == set()  # so has the 12-scan one
    first = [Edge(17, 120, np.eye(4))]
    assert closed_places(first, 122, 3, 5, window_closed=12, gap=45) == closed_places(first, 122, 3, 5)
    assert closed_places(first, 125, 3, 5, window_closed=12, gap=45) == set()
    same_pass = [Edge(17, 120, np.eye(4)), Edge(18, 124, np.eye(4))]
    assert closed_places(same_pass, 126, 3, 5, window_closed=12, gap=45) == {1, 2, 3, 4, 5}


def test_a_loop_search_on_a_window_of_the_graph_closes_the_same_loops():
    # The hairpin's way back with a window of 20 nodes: the first revisit is joined to the scan only the long way
    # round (beyond the window), so it is searched on the whole graph; the loops found are the whole graph's.
    from helpers.config.tables import Config
    from helpers.slam.loops.closer import LoopCloser

    def run(window_nodes):
        settings = Config().with_values(loop_closure={"sub_map_thresh": 2, "skip_after_loop": 0})
        closer = LoopCloser(settings.loop_closure, settings.map, AlwaysMatches(), settings.pose_graph)
        closer.uncertainty.window_nodes = window_nodes
        return hairpin(closer), closer.uncertainty

    (every, _), whole = run(1000)
    (windowed, _), graph = run(20)
    assert whole.whole == 0 and graph.whole >= 1 and len(every) > 20
    assert windowed == every


def test_the_whole_graph_it_hands_out_gives_gtsams_own_marginals():
    # Notebook 5 computes the gate's covariance by hand from `graph` and `values`: GTSAM's Marginals of the
    # whole graph held at the current node must be the answer, even once the queries use a window.
    import gtsam

    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=0.3)
    windowed, poses = laps_graph(settings, window_nodes=70)
    held = windowed.graph
    assert held.size() == 179 + 178 + 30  # odometry steps, edges back over 2 nodes, loop edges
    held.add(gtsam.PriorFactorPose3(179, windowed.values.atPose3(179), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
    sigma = gtsam.Marginals(held, windowed.values).marginalCovariance(30)
    R = poses[30][:3, :3]
    np.testing.assert_allclose(windowed.position_covariances([30])[0], R @ sigma[3:, 3:] @ R.T, rtol=1e-5)


class TrueIcp:
    """ICP that always lands on the truth, whatever its start: a submap (map frame) gets the current scan's true
    pose (``truth``, set before each scan is added), old scan ``i`` (a cloud of four points at ``(i, i, i)``) the
    true pose relative to it (``truths``); it records every start it was given for a submap."""

    def __init__(self):
        self.node, self.truth, self.truths, self.starts = None, None, [], []

    def __call__(self, *, moving, fixed, T_fixed_moving, max_iterations=None):
        if len(fixed) == 4 and np.all(fixed == fixed[0, 0]):  # old scan i
            return np.linalg.inv(self.truths[int(fixed[0, 0])]) @ self.truth, 0.1
        self.starts.append((self.node, T_fixed_moving.copy()))
        return self.truth, 0.1

    def constraint(self, **_):
        return 1.0


def test_after_a_loop_icp_starts_where_the_graph_puts_the_scan():
    """Out along x and back over the same line, the odometry of the way back 2 m to the side of the truth
    (the way out is exact, and the submaps are built on it). The first revisit can only start ICP from the
    odometry, 2 m off; its loop edge tells the graph where the way back lies, and every later query starts
    ICP there: decimetres from the truth after the first loops, centimetres once more have closed, never from
    the odometry's pose 2 m away."""
    from helpers.config.tables import Config
    from helpers.slam.loops.closer import LoopCloser

    settings = Config().with_values(loop_closure={"sub_map_thresh": 2, "search": "uncertainty", "skip_after_loop": 0})
    icp = TrueIcp()
    closer = LoopCloser(settings.loop_closure, settings.map, icp, settings.pose_graph)
    n_out = 30
    xs = np.r_[6.0 * np.arange(n_out), 6.0 * np.arange(n_out - 1, -1, -1) + 1.0]
    poses, clouds = [], []
    for node, x in enumerate(xs):
        truth = step(x)
        odometry = truth.copy()
        if node >= n_out:
            odometry[1, 3] += 2.0  # the way back drifted 2 m to the side
        poses.append(odometry)
        icp.truths.append(truth)
        clouds.append(np.full((4, 3), float(node)))
        icp.truth, icp.node = truth, node
        closer.add(node, clouds[-1], poses[-1], clouds, np.array(poses))
    loops = closer.loops
    assert len(loops) > 10
    first = loops[0].j
    offsets = {node: np.linalg.norm(start[:3, 3] - icp.truths[node][:3, 3]) for node, start in icp.starts}
    assert offsets[first] == pytest.approx(2.0, abs=1e-6)  # nothing told the graph yet
    later = [offset for node, offset in offsets.items() if node > first]
    # the first loop edges move the old places part of the way (weighed against the chain of steps); the more
    # loops, the nearer the truth
    assert len(later) > 10 and max(later) < 0.5 and np.median(later) < 0.05


def square_flight(missed_deg: float):
    """A 60-node square flown counter-clockwise back over its start, 6 m a step: the true poses, and an
    odometry whose first turn misses ``missed_deg`` degrees at one step (a turn begun over a field too flat
    to see it) and is right everywhere else."""
    true_steps, odometry_steps = [], []
    for k in range(60):
        turning = k % 15 in (10, 11, 12)  # three steps of 30 degrees: a corner
        true_steps.append(step(6.0, yaw_deg=30.0 if turning else 0.0))
        missed = missed_deg if k == 11 else 0.0
        odometry_steps.append(step(6.0, yaw_deg=(30.0 if turning else 0.0) - missed))
    truth, odometry = [np.eye(4)], [np.eye(4)]
    for t, o in zip(true_steps, odometry_steps, strict=True):
        truth.append(truth[-1] @ t)
        odometry.append(odometry[-1] @ o)
    return np.array(truth), np.array(odometry)


def test_gnss_fixes_place_the_old_nodes_where_the_flight_was_after_a_missed_turn():
    # The odometry missed 20 degrees of its first turn: back over the start it puts node 0 some 25 m from where
    # it is. Fixes (1 m sigma, seeded noise) at every node bend the chain back: held at the current node's
    # odometry pose, node 0 lies where the truth puts it seen from the current node, within a few metres, and
    # its covariance is a few square metres, not the chain's; without the fixes the answer is the odometry's.
    truth, odometry = square_flight(missed_deg=20.0)
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=0.3)
    fixes = truth[:, :3, 3] + np.random.default_rng(1).normal(0.0, 1.0, (len(truth), 3))
    with_fixes, without = RelativeUncertainty(settings), RelativeUncertainty(settings)
    for node, pose in enumerate(odometry):
        for graph in (with_fixes, without):
            graph.add_node(pose)
        with_fixes.add_fix(node, fixes[node], np.ones(3))
    current = len(odometry) - 1
    seen = odometry[current] @ np.linalg.inv(truth[current]) @ truth[0]  # node 0 where it is, from the current node
    odometry_error = np.linalg.norm(odometry[0, :3, 3] - seen[:3, 3])
    assert odometry_error > 20.0
    cov_with, cov_without = with_fixes.position_covariances([0])[0], without.position_covariances([0])[0]
    assert np.linalg.norm(with_fixes.positions([0])[0] - seen[:3, 3]) < 3.0
    np.testing.assert_allclose(without.positions([0])[0], odometry[0, :3, 3], atol=1e-6)
    assert np.trace(cov_with) < 10.0 < np.trace(cov_without)
    # ICP against node 0 starts from the scan's pose where the fixes put it: most of the missed turn is
    # restored (the edges' 0.3 degree sigmas spread the rest of it along the chain)

    def turned(pose):
        return np.degrees(np.linalg.norm(Rotation.from_matrix(pose[:3, :3].T @ seen[:3, :3]).as_rotvec()))

    assert turned(odometry[0]) == pytest.approx(20.0, abs=0.01)
    assert turned(with_fixes.solved_poses([0])[0]) < 5.0


def test_too_few_fixes_leave_the_graph_held_at_the_anchor():
    truth, odometry = square_flight(missed_deg=20.0)
    settings = PoseGraphConfig(edge_sigma_m=SIGMA_M, edge_sigma_deg=0.3)
    graph = RelativeUncertainty(settings)
    for pose in odometry:
        graph.add_node(pose)
    for node in (0, 30):  # two fixes: fewer than MIN_FIXES
        graph.add_fix(node, truth[node, :3, 3], np.ones(3))
    graph.position_covariances([0])
    np.testing.assert_allclose(graph.positions([0])[0], odometry[0, :3, 3], atol=1e-6)
    with pytest.raises(SlamError, match="not in the graph"):
        graph.add_fix(len(odometry), truth[0, :3, 3], np.ones(3))


def test_a_query_whose_graph_gives_no_gate_searches_the_grown_radius_and_says_so(monkeypatch):
    # GTSAM cannot give the covariances (an indeterminant graph): never a crash, the query searches the radius
    # grown with the distance flown, as search = "growth" would, and names that fallback; the run counts it.
    from helpers.config.tables import Config
    from helpers.errors import SlamError
    from helpers.slam.loops.closer import LoopCloser

    settings = Config().with_values(loop_closure={"sub_map_thresh": 2, "skip_after_loop": 0})

    def queries(failing):
        closer = LoopCloser(settings.loop_closure, settings.map, AlwaysMatches(), settings.pose_graph)
        if failing:

            def indeterminant(*args):
                raise SlamError("the graph is indeterminant")

            monkeypatch.setattr(closer, "_uncertain_centres", indeterminant)
        closed, _ = hairpin(closer)
        return closer.queries, closed

    gated, closed_gated = queries(False)
    grown, closed_grown = queries(True)
    assert {q.fallback for q in gated} == {""} and {q.fallback for q in grown} == {"grown radius"}
    assert closed_gated and closed_grown  # the way back closes loops either way
