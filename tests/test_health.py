"""The trust flag's rules (helpers.quality.trust) on built runs whose answer is known: a straight flight of
2 m steps (or a hover), odometry steps and loops with chosen information, the graph optimised for real."""

from types import SimpleNamespace

import numpy as np
import pytest

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.quality.graph_checks import (
    FALSE_LOOP_SIGMAS,
    correction_sigmas,
    left_out_residuals,
    loop_residuals,
    optimized_with,
    rebuilt_poses,
)
from helpers.quality.trust import BLIND_RUN_STEPS, CORRECTION_FLOOR_M, MAX_EXPECTED_ATE_M, WEAK_SIGMA_M, assess
from helpers.sim.gnss import GnssFixes
from helpers.slam.graph.build import build_pose_graph
from helpers.slam.graph.factors import Edge, gnss_factors
from helpers.slam.graph.information import calibrated
from helpers.slam.odometry import OdometryResult

CONFIG = Config().with_values(pose_graph={"graph_weights": "hessian"})
NODES = 30


def _info(sigma_m, sigma_deg=0.05):
    """A diagonal information: ``sigma_m`` (m, one number or x y z) and ``sigma_deg`` on every rotation."""
    sigmas = np.concatenate([np.broadcast_to(sigma_m, 3), np.full(3, np.radians(sigma_deg))])
    return np.diag(sigmas**-2.0)


def _at(x, y=0.0):
    T = np.eye(4)
    T[:2, 3] = x, y
    return T


def _run(step=2.0, informations=None, extra=(), loops=(), constraint=0.5, config=CONFIG, fixes=()):
    """A run of NODES nodes ``step`` m apart along x, optimised with the given edges and GNSS ``fixes``
    (factors, as the run adds them; the result's fields as a SlamResult's)."""
    informations = [_info(0.05)] * (NODES - 1) if informations is None else informations
    relative = np.array([_at(step)] * (NODES - 1))
    poses = np.array([_at(step * k) for k in range(NODES)])
    odometry = OdometryResult(
        indices=np.arange(NODES) * 3,
        poses=poses,
        relative=relative,
        n_matches=np.full(NODES - 1, 100),
        n_inliers=np.full(NODES - 1, 50),
        rmse=np.full(NODES - 1, 0.2),
        timings={},
        constraint=np.full(NODES - 1, constraint),
        information=list(informations),
    )
    graph = build_pose_graph(odometry, list(extra), list(loops), config)
    for fix in fixes:
        graph.add_factor(fix)
    optimised = graph.optimize(anchor_pose=poses[0], loop_kernel=config.pose_graph.loop_kernel)
    queries = [SimpleNamespace(closure=loop, submap_ids=[0], best_scan_constraint=0.5, fallback="") for loop in loops]
    return SimpleNamespace(
        config=config,
        indices=odometry.indices,
        odometry=odometry,
        graph=optimised,
        loops=list(loops),
        queries=queries,
        extra_edges=list(extra),
        edges_back_tried=len(extra),
        gnss_factors=list(fixes),
        empty_scans=[],
    )


def test_a_straight_well_pinned_run_is_consistent_but_vouches_for_no_scale():
    """Every step pinned and no loop: nothing disagrees, so the shape is trusted; nothing observes the scale (a
    bias in every step length would stretch the line unseen), so the run is not trusted whole, and says how far
    a bias of 1 % would move it."""
    health = assess(_run())
    assert health.consistent and not health.trusted, health.problems
    per_pct = health.counts["moved_per_scale_pct_m"]
    assert health.counts["loop_scale_sigma_pct"] is None and f"by {per_pct:.2f} m unseen" in health.scale
    assert "Likely cause: no loop closed" in health.scale
    assert health.warning().startswith("this result is trusted in shape only. Its scale is not observed")
    assert health.counts["weakest_step_sigma_m"] < WEAK_SIGMA_M


def test_steps_loose_along_the_track_are_weak_by_their_information():
    """A fifth of the steps know their position along the track only to 1 m (flat ground): the weak
    direction is read from their information, though ICP's constraint says nothing is wrong."""
    loose = _info([1.0, 0.05, 0.05])
    informations = [loose if k % 5 == 0 else _info(0.05) for k in range(NODES - 1)]
    health = assess(_run(informations=informations, constraint=0.5))
    assert health.counts["n_weak_steps"] == len(range(0, NODES - 1, 5))
    assert not health.consistent and "too flat" in health.warning()
    assert health.counts["weakest_step_sigma_m"] > 0.99


def test_a_step_on_ground_too_flat_is_weak_whatever_its_information_says():
    """ICP's constraint (its paired normals all alike) still names flat ground: generalized ICP's
    Hessian can look sure on a plane, and a step may come without information."""
    for informations in (None, [None] * (NODES - 1)):
        health = assess(_run(informations=informations, constraint=0.001))
        assert health.counts["n_weak_steps"] == NODES - 1 and not health.consistent


def _out_and_back(fell_back):
    """A flight 25 steps of 2 m out along x and 25 back along y = 4 m (over the ground it flew, beyond the
    loop search's fixed radius times LEFT_FACTOR from where it turned), closing no loop; the steps at
    positions ``fell_back`` registered by no fit and followed the last motion."""
    turn = np.diag([-1.0, -1.0, 1.0, 1.0])
    turn[1, 3] = 4.0
    relative = np.array([_at(2.0)] * 25 + [turn] + [_at(2.0)] * 24)
    poses = np.eye(4)[None]
    for step in relative:
        poses = np.concatenate([poses, [poses[-1] @ step]])
    indices = np.arange(len(poses)) * 3
    odometry = OdometryResult(
        indices=indices,
        poses=poses,
        relative=relative,
        n_matches=np.full(len(relative), 100),
        n_inliers=np.full(len(relative), 50),
        rmse=np.full(len(relative), 0.2),
        timings={},
        fallbacks=[(int(indices[k + 1]), "robust fit failed; ICP started from the previous motion") for k in fell_back],
        constraint=np.full(len(relative), 0.5),
        information=[_info(0.05)] * len(relative),
    )
    graph = build_pose_graph(odometry, [], [], CONFIG).optimize(anchor_pose=poses[0])
    return SimpleNamespace(
        config=CONFIG, indices=indices, odometry=odometry, graph=graph, loops=[], queries=[], extra_edges=[],
        edges_back_tried=0, gnss_factors=[], empty_scans=[],
    )  # fmt: skip


def test_revisits_after_a_blind_stretch_name_it_not_the_loop_settings():
    """Revisits closing no loop after BLIND_RUN_STEPS steps in a row that followed the last motion: the
    likely cause named is that stretch (a turn there goes unseen), with GNSS as the way out; the same
    number of fallbacks scattered leaves the loop settings as the likely cause. Too few fall back for
    the fallback rule (at most a tenth), so the revisit rule alone speaks."""
    in_a_row = assess(_out_and_back(range(10, 10 + BLIND_RUN_STEPS)))
    scattered = assess(_out_and_back(range(3, 3 + 4 * BLIND_RUN_STEPS, 4)))
    for health in (in_a_row, scattered):
        c = health.counts
        assert c["n_fallbacks"] == BLIND_RUN_STEPS and c["n_revisits_unclosed"] == c["n_revisits"] >= 3
        assert not health.consistent and len(health.problems) == 1, health.problems
    assert f"in a row (scans {3 * 11}-{3 * (10 + BLIND_RUN_STEPS)})" in in_a_row.warning()
    assert "--gnss" in in_a_row.warning() and "sub_map_thresh" not in in_a_row.warning()
    assert "sub_map_thresh" in scattered.warning() and "in a row" not in scattered.warning()


def test_steps_that_fell_back_are_named_as_runs_of_accepted_scans():
    """With skip_frames = 3 the accepted scans are 0, 3, 6, ...: fallbacks on seven accepted scans in a row
    are one run, first-last, not seven scans; two apart with an accepted scan between are two."""
    in_a_row = assess(_out_and_back(range(10, 17)))  # scans 33, 36, ..., 51
    apart = assess(_out_and_back([3, 5, *range(30, 36)]))  # scans 12 and 18, then 93-108
    assert "previous motion (scans 33-51)." in in_a_row.warning(), in_a_row.problems
    assert "previous motion (scans 12, 18, 93-108)." in apart.warning(), apart.problems


def _loop_off_by(metres, sigma_m):
    """A loop edge from node 0 to the last node, ``metres`` off along y, with ``sigma_m`` in its information."""
    true = _at(2.0 * (NODES - 1))
    return Edge(0, NODES - 1, true @ _at(0.0, metres), 0.1, information=calibrated(_info(sigma_m), 1.0, np.zeros(6)))


def test_a_loop_is_judged_against_the_graph_with_its_own_information():
    """A loop 1.5 m off a graph that is sure of itself: with an information that says 0.1 m it is 15
    sigmas off and named; one that says 0.5 m leaves it within 5 sigmas (not named)."""
    for sigma, named in ((0.1, True), (0.5, False)):
        run = _run(loops=[_loop_off_by(1.5, sigma)])
        (metres, _, sigmas), *_ = loop_residuals(run)
        assert metres > 1.0 and (sigmas > FALSE_LOOP_SIGMAS) == named
        health = assess(run)
        assert health.counts["n_loops_against_graph"] == named
        assert ("most likely false" in health.warning()) == named


def test_a_loop_against_a_graph_the_loops_moved_far_is_not_called_false():
    """Looser steps (0.1 m each): the same loop 3 m off both stays many sigmas from the graph and moves it by
    0.8 m, over 1 % of the 58 m flown. Then the rest of the graph may be drifted odometry as well as the loop
    false, and the warning says it cannot tell (over a sparse tile true loops were named false so)."""
    run = _run(informations=[_info(0.1)] * (NODES - 1), loops=[_loop_off_by(3.0, 0.05)])
    health = assess(run)
    assert health.counts["n_loops_against_graph"] == 1 and health.counts["largest_correction_m"] > 0.58
    warning = health.warning()
    assert "most likely false" not in warning and "cannot tell which" in warning
    assert "moved the trajectory by up to" in warning  # the drift, its own problem


def test_a_true_loop_a_little_off_is_not_called_false():
    """A loop 0.4 m off (a true loop by the evaluation's rule, 1 m) and 8 sigmas off by its information:
    improbable, yet not a false loop. The odometry is stiff, so the graph stays where it is."""
    run = _run(informations=[_info(0.005)] * (NODES - 1), loops=[_loop_off_by(0.4, 0.05)])
    assert loop_residuals(run)[0][2] > FALSE_LOOP_SIGMAS
    assert assess(run).counts["n_loops_against_graph"] == 0


def test_edges_back_moving_the_trajectory_are_no_loop_correction():
    """No loop, but edges back that pull every step 10 % longer: the graph moves the trajectory by
    metres, which the rule on loop corrections must not count (there is no loop)."""
    extra = [Edge(k, k + 2, _at(4.4), 0.1, information=_info(0.05)) for k in range(NODES - 2)]
    run = _run(extra=extra)
    moved = np.abs(run.graph.poses[:, 0, 3] - run.odometry.poses[:, 0, 3]).max()
    assert moved > 1.0
    health = assess(run)
    assert health.counts["largest_correction_m"] == 0.0 and health.consistent, health.problems


def test_a_hovering_flight_has_its_loop_corrections_judged_in_metres():
    """A hover (every step 0 m): the share of the distance flown is undefined, so a loop that moves
    the trajectory by a metre is judged against the floor, and one moving it by centimetres passes."""
    for off, trusted in ((2.0, False), (0.05, True)):
        informations = [_info(0.2)] * (NODES - 1)  # hovering drifts: the loop is the surer edge
        loop = Edge(0, NODES - 1, _at(0.0, off), 0.1, information=_info(0.01))
        run = _run(step=0.0, informations=informations, loops=[loop])
        health = assess(run)
        assert health.counts["distance_flown_m"] == 0.0
        assert (health.counts["largest_correction_m"] > CORRECTION_FLOOR_M) != trusted
        assert health.consistent == trusted, health.problems
        assert trusted or "the flight hovered" in health.warning()
        # hovering drifts by 0.2 m a step: the loop's move is within the steps' sigmas, but the graph expects the
        # nodes between its ends farther off than the bar, and the warning says so
        assert (
            trusted or f"expects its trajectory to be {health.counts['expected_ate_m']:.2f} m off" in health.warning()
        )


def test_the_loop_correction_is_what_the_loops_moved():
    """A loop that agrees with the odometry moves nothing; the correction counts only the loops' effect."""
    run = _run(loops=[_loop_off_by(0.0, 0.05)])
    assert assess(run).counts["largest_correction_m"] < 0.01


def test_gnss_fixes_moving_the_trajectory_are_no_loop_correction():
    """A loop that agrees with the odometry, and GNSS fixes 3 m to the side of every node (a biased
    receiver): the fixes swing the trajectory about its anchored first node by metres, the loop still
    moves it by nothing."""
    positions = np.array([[2.0 * k, 3.0, 0.0] for k in range(NODES)])
    fixes = gnss_factors(GnssFixes(np.arange(NODES) * 3, positions, np.full(3, 0.5)), np.arange(NODES) * 3)
    run = _run(loops=[_loop_off_by(0.0, 0.05)], fixes=fixes)
    assert run.graph.poses[-1, 1, 3] > 1.0  # the fixes did move it
    assert assess(run).counts["largest_correction_m"] < 0.01


def test_the_runs_own_graph_is_reused_only_where_it_is_the_rebuilt_one():
    """The health measures compare the run's graph rebuilt from its edges with variants of it. Without GNSS
    that graph is the run's own, to the bit, so its poses are taken as they are (one optimisation fewer);
    with fixes in the run's graph it is optimised again without them, and differs."""
    run = _run(informations=[_info(0.1)] * (NODES - 1), loops=[_loop_off_by(1.5, 0.1)])
    assert rebuilt_poses(run) is run.graph.poses
    np.testing.assert_array_equal(rebuilt_poses(run), optimized_with(run, run.loops))
    positions = np.array([[2.0 * k, 3.0, 0.0] for k in range(NODES)])
    fixes = gnss_factors(GnssFixes(np.arange(NODES) * 3, positions, np.full(3, 0.5)), np.arange(NODES) * 3)
    run = _run(informations=[_info(0.1)] * (NODES - 1), loops=[_loop_off_by(1.5, 0.1)], fixes=fixes)
    rebuilt = rebuilt_poses(run)
    np.testing.assert_array_equal(rebuilt, optimized_with(run, run.loops))
    assert np.abs(rebuilt[:, 1, 3] - run.graph.poses[:, 1, 3]).max() > 1.0  # the fixes' pull is left out


def _fixes(sigma):
    """A GNSS fix of ``sigma`` m on x, y and z at every node, on the true positions."""
    positions = np.array([[2.0 * k, 0.0, 0.0] for k in range(NODES)])
    return gnss_factors(GnssFixes(np.arange(NODES) * 3, positions, np.full(3, sigma)), np.arange(NODES) * 3)


def test_gnss_fixes_hold_a_run_whose_odometry_pinned_nothing():
    """Every step on ground too flat to pin it, each known only to 1 m: untrusted on lidar alone. With a
    0.3 m fix at every node the graph expects its trajectory well within the bar, and says why it may."""
    weak = {"informations": [_info(1.0)] * (NODES - 1), "constraint": 0.0}
    alone = assess(_run(**weak))
    assert not alone.consistent and alone.counts["expected_ate_m"] is None  # no loop holds them, no graph asked
    held = assess(_run(**weak, fixes=_fixes(0.3)))
    assert held.trusted and not held.scale, held.problems  # the fixes hold its scale too
    # 30 fixes of 0.3 m, each fused with steps of 1 m: each node's sigma is a little under the fix's sqrt(3) 0.3
    assert 0.2 < held.counts["expected_ate_m"] < np.sqrt(3) * 0.3
    assert held.counts["n_weak_steps"] == NODES - 1  # still counted, no longer held against the run


def test_gnss_fixes_too_loose_for_the_steps_leave_a_run_untrusted():
    """The same weak steps with 3 m fixes: the graph expects metres, and the run says so, naming GNSS."""
    health = assess(_run(informations=[_info(1.0)] * (NODES - 1), constraint=0.0, fixes=_fixes(3.0)))
    assert health.counts["expected_ate_m"] > MAX_EXPECTED_ATE_M
    assert not health.consistent and len(health.problems) == 1 and "GNSS fixes" in health.problems[0]


def _held_by_loops(config=CONFIG, loops=()):
    """Every step on ground too flat by ICP's constraint, each known to 5 cm, and true loop edges from the first
    node to every fifth: a low flight whose loops pull it back into place at every lap."""
    true_loops = [Edge(0, k, _at(2.0 * k), 0.1, information=_info(0.05)) for k in range(5, NODES, 5)]
    return _run(
        informations=[_info(0.05)] * (NODES - 1), constraint=0.001, loops=true_loops + list(loops), config=config
    )


def test_loops_that_hold_the_trajectory_answer_the_drift_rules():
    """The drift rules name every step too flat; the graph, its information calibrated and its loops agreeing
    with it, expects its trajectory within 0.5 m, so the run is trusted and the weak steps only counted."""
    health = assess(_held_by_loops())
    assert health.trusted, (health.problems, health.scale)  # loops of levers up to 58 m observe the scale too
    assert health.counts["n_weak_steps"] == NODES - 1
    assert 0.0 < health.counts["expected_ate_m"] <= MAX_EXPECTED_ATE_M
    assert health.counts["loop_correction_sigmas"] <= FALSE_LOOP_SIGMAS


def test_only_a_graph_of_calibrated_information_that_agrees_with_itself_answers_them():
    """The same run weighed by the fixed icp sigmas (chosen, not measured): the graph is not asked. With a
    loop edge 3 m off the others, surer than they are and no kernel on it: the graph bends to it, so no loop
    edge ends far from it, but the loops moved the trajectory by many times the sigmas of the steps between
    them (about 0.3 m at the last node), and the drift rules stand."""
    fixed = assess(_held_by_loops(config=Config().with_values(pose_graph={"graph_weights": "icp"})))
    assert not fixed.consistent and "too flat" in fixed.warning()
    assert fixed.counts["expected_ate_m"] is None and fixed.counts["loop_correction_sigmas"] is None
    run = _held_by_loops(config=CONFIG.with_values(pose_graph={"loop_kernel": "none"}), loops=[_loop_off_by(3.0, 0.01)])
    assert max(sigmas for *_, sigmas in loop_residuals(run)) < 15  # the false loop itself ends 2.5 sigmas off
    bent = assess(run)
    assert bent.counts["largest_correction_m"] > 2.5 and bent.counts["loop_correction_sigmas"] > FALSE_LOOP_SIGMAS
    assert not bent.consistent and "too flat" in bent.warning() and "moved the trajectory" in bent.warning()
    # why the graph did not answer: left out, the false loop (and the true one it pulled off) end metres away
    assert "the graph bent to them" in bent.warning() and "29" in bent.warning()
    assert bent.counts["n_loops_off_the_rest"] == 2 and bent.counts["expected_ate_m"] is None


def _drifting(slip, loop_every=5, loop_sigma=0.05, config=CONFIG):
    """A straight flight whose odometry slips ``slip`` m sideways at every step (one error, repeated: not
    the independent errors its information, 5 cm and 0.05 deg a step, describes), every step on ground too
    flat by ICP's constraint, and true loop edges (``loop_sigma`` m) from the first node to every
    ``loop_every``-th."""
    true_loops = [
        Edge(0, k, _at(2.0 * k), 0.1, information=_info(loop_sigma)) for k in range(loop_every, NODES, loop_every)
    ]
    run = _run(informations=[_info(0.05)] * (NODES - 1), constraint=0.001, loops=true_loops, config=config)
    run.odometry.relative = np.array([_at(2.0, slip)] * (NODES - 1))
    run.odometry.poses = np.array([_at(2.0 * k, slip * k) for k in range(NODES)])
    graph = build_pose_graph(run.odometry, [], run.loops, config)
    run.graph = graph.optimize(anchor_pose=run.odometry.poses[0], loop_kernel=config.pose_graph.loop_kernel)
    return run


def test_loops_that_mend_a_drift_repeated_step_after_step_answer_the_drift_rules():
    """An 8 cm slip repeated at every step takes the odometry 2.3 m off the line by the last node, some seven of
    the sigmas its independent steps allow there: the loops' move is beyond them, yet every loop agrees with the
    steps around it and with the others (each, left out, ends decimetres from the graph without it). The graph
    answers the drift rules (over sparse tiles the odometry drifted so, and loops mended it to 0.34-0.37 m).
    One loop at the far end alone, surer than the steps, mends the same drift, but nothing else checks it: left
    out, it ends 2.3 m from the drifted chain, as a false loop the graph bent to would, and the run stays
    untrusted (with no kernel, as the reference weighs loops, no loop edge ends far from the graph it bent, so
    only the loop left out shows it)."""
    mended = _drifting(0.08)
    health = assess(mended)
    assert health.counts["largest_correction_m"] > 1.5
    assert health.counts["loop_correction_sigmas"] > FALSE_LOOP_SIGMAS  # what the rule before held against it
    assert health.counts["n_loops_off_the_rest"] == 0
    assert health.consistent, health.problems
    assert max(metres for metres, *_ in left_out_residuals(mended)) < 0.5
    no_kernel = CONFIG.with_values(pose_graph={"loop_kernel": "none"})
    lone = _drifting(0.08, loop_every=NODES - 1, loop_sigma=0.01, config=no_kernel)
    assert loop_residuals(lone)[0][0] < 0.1 and left_out_residuals(lone)[0][0] > 2.0
    health = assess(lone)
    assert health.counts["n_loops_against_graph"] == 0 and health.counts["n_loops_off_the_rest"] == 1
    assert not health.consistent and "the graph bent to them" in health.warning()


def test_a_loop_left_out_ends_where_the_graph_without_it_puts_it():
    """The leave-one-out residual, one linear step from the optimum, against the graph really optimised
    without the loop: the same to a centimetre on a graph with three loops of mixed information, each off
    the odometry by its own amount. (No kernel: under one, leaving a loop out would also change how much
    the others weigh, which the linear step holds as the optimum weighed them.)"""
    loops = [
        Edge(0, 10, _at(20.0, 0.3), 0.1, information=_info(0.05)),
        Edge(0, 20, _at(40.0, -0.4), 0.1, information=_info(0.1)),
        Edge(5, NODES - 1, _at(2.0 * (NODES - 6), 0.6), 0.1, information=_info(0.02)),
    ]
    no_kernel = CONFIG.with_values(pose_graph={"loop_kernel": "none"})
    run = _run(informations=[_info(0.05, sigma_deg=0.02)] * (NODES - 1), loops=loops, config=no_kernel)
    for k, (metres, _, sigmas) in enumerate(left_out_residuals(run)):
        others = optimized_with(run, [loop for m, loop in enumerate(loops) if m != k])
        loop = loops[k]
        ends = np.linalg.inv(others[loop.i]) @ others[loop.j]
        assert metres == pytest.approx(np.linalg.norm(ends[:3, 3] - loop.relative[:3, 3]), abs=0.01)
        assert sigmas > loop_residuals(run)[k][2]  # left out, a loop is always farther than in the graph


def test_the_loops_move_is_measured_in_the_sigmas_of_the_steps_between():
    """Steps known to 0.1 m a side (rotation all but exact) and a loop edge, far surer, that puts the last node
    1 m to the side: node k moves by k / 29 m where the loop-free chain leaves it sqrt(k) 0.1 m unsure sideways,
    so the largest move is the last node's, sqrt(29) / 2.9 = 1.86 sigmas."""
    sure_rotation = [_info(0.1, sigma_deg=1e-4)] * (NODES - 1)
    loop = Edge(0, NODES - 1, _at(2.0 * (NODES - 1), 1.0), 0.1, information=_info(0.001, sigma_deg=1e-4))
    run = _run(informations=sure_rotation, loops=[loop])
    assert run.graph.poses[-1, 1, 3] == pytest.approx(1.0, abs=1e-3)
    assert correction_sigmas(run) == pytest.approx(np.sqrt(NODES - 1) / (0.1 * (NODES - 1)), rel=0.01)
    assert correction_sigmas(_run(informations=sure_rotation)) == 0.0  # no loop, no move
    # the loop ends on the optimised graph (it is far surer than the steps), but left out, 1 m off the chain,
    # whose sideways sigma there is sqrt(29) 0.1 m: 1.86 sigmas
    (metres, _, sigmas), *_ = left_out_residuals(run)
    assert loop_residuals(run)[0][0] < 0.01 and metres == pytest.approx(1.0, abs=1e-3)
    assert sigmas == pytest.approx(1.0 / np.sqrt((NODES - 1) * 0.1**2 + 0.001**2), rel=0.01)


@pytest.mark.parametrize("measure", ["loops_off_the_rest", "correction_sigmas", "expected_ate"])
def test_a_graph_whose_marginals_cannot_be_computed_does_not_answer(monkeypatch, measure):
    """Where GTSAM cannot give the marginals a measure of the graph needs (the loops left out, the loops' move
    in sigmas, the ATE it expects of itself), the graph does not vouch for itself: the drift rules stand, and
    the warning says why (a run is never crashed by its own health check)."""
    import helpers.quality.trust

    def fails(*args, **kwargs):
        raise SlamError("indeterminant linear system")

    monkeypatch.setattr(helpers.quality.trust, measure, fails)
    health = assess(_held_by_loops())
    assert not health.consistent and "too flat" in health.warning()
    assert "its marginals could not be computed (indeterminant linear system)" in health.warning()
    assert health.counts["expected_ate_m"] is None
    if measure != "expected_ate":  # the leave-one-out count is made before the expected ATE is asked
        assert health.counts["n_loops_off_the_rest"] is None


def test_gnss_fixes_whose_graph_cannot_say_how_sure_it_is_leave_a_run_untrusted(monkeypatch):
    """The run of test_gnss_fixes_hold_a_run_whose_odometry_pinned_nothing, trusted with 0.3 m fixes, when
    GTSAM cannot give the graph's marginals: not trusted, and the warning says so."""
    import helpers.quality.trust_facts  # where the run's facts, a GNSS graph's expected ATE among them, are measured

    def fails(result):
        raise SlamError("indeterminant linear system")

    monkeypatch.setattr(helpers.quality.trust_facts, "expected_ate", fails)
    health = assess(_run(informations=[_info(1.0)] * (NODES - 1), constraint=0.0, fixes=_fixes(0.3)))
    assert not health.consistent and health.counts["expected_ate_m"] is None
    assert "could not say how far off" in health.warning() and "indeterminant linear system" in health.warning()
