"""How well a run's loops observe the flight's scale (helpers.quality.graph_checks.scale_sigma and
loop_scale), on cases whose answer is analytic, and what the trust flag's summary says of it."""

from types import SimpleNamespace

import numpy as np
import pytest
from test_health import NODES, _at, _info, _run

from helpers.config.tables import Config
from helpers.quality.graph_checks import loop_scale, scale_sigma
from helpers.quality.trust import MAX_EXPECTED_ATE_M, Health, assess
from helpers.quality.trust_rules import scale_unvouched
from helpers.slam.graph.factors import Edge

CONFIG = Config().with_values(pose_graph={"graph_weights": "hessian"})


def _yawed(x, y, degrees):
    T = _at(x, y)
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def test_loops_with_levers_measure_scale_as_their_information_says():
    """Loops of levers L_k, each with a translation sigma s: the scale's sigma is s / sqrt(sum L_k^2)."""
    poses = np.array([_at(0), _at(48), _at(0, 48), _at(30, 40)])
    pairs = [(0, 1), (0, 2), (0, 3)]  # levers 48, 48 and 50 m
    sigma, longest = scale_sigma(poses, pairs, [_info(0.1)] * 3)
    assert sigma == pytest.approx(0.1 / np.sqrt(48**2 + 48**2 + 50**2), rel=1e-9)
    assert longest == pytest.approx(50.0)


def test_a_loop_that_closes_where_the_flight_passed_before_observes_no_scale():
    """A second lap over the first: the loop's ends coincide, and a shrunk lap closes on a shrunk lap."""
    poses = np.array([_at(10, 5), _at(200, 0), _at(10, 5)])
    sigma, longest = scale_sigma(poses, [(0, 2)], [_info(0.05)])
    assert sigma == np.inf and longest == 0.0
    assert scale_sigma(poses, [], []) == (np.inf, 0.0)


def test_a_lever_is_weighed_in_the_frame_of_its_first_node():
    """Node 0 turned by 90 deg: a lever along the map's y lies along its own x, where the edge's information
    is sure (0.1 m), not along its y (10 m)."""
    poses = np.array([_yawed(0, 0, 90), _at(0, 40)])
    sure_along_x = _info(np.array([0.1, 10.0, 10.0]))
    sigma, _ = scale_sigma(poses, [(0, 1)], [sure_along_x])
    assert sigma == pytest.approx(0.1 / 40, rel=1e-9)
    unturned = np.array([_at(0, 0), _at(0, 40)])
    assert scale_sigma(unturned, [(0, 1)], [sure_along_x])[0] == pytest.approx(10.0 / 40, rel=1e-9)


def test_a_run_reports_its_loops_scale_and_what_1_percent_would_move():
    """On an optimised straight run, a loop from the first node to the last (a lever of the whole flight):
    the counts give the scale's sigma from that loop's own information and the RMS distance from the first
    node over 100; the summary says the scale is observed. With the same loop closing on itself (no lever)
    it says no scale is vouched for."""
    flown = 2.0 * (NODES - 1)
    run = _run(loops=[Edge(0, NODES - 1, _at(flown), 0.1, information=_info(0.1))], config=CONFIG)
    sigma, reach, lever = loop_scale(run)
    positions = run.graph.poses[:, :3, 3]
    assert lever == pytest.approx(flown, abs=0.01)
    assert reach == pytest.approx(np.sqrt(np.mean(np.sum((positions - positions[0]) ** 2, axis=1))))
    health = assess(run)
    c = health.counts
    assert c["moved_per_scale_pct_m"] == pytest.approx(reach / 100, abs=1e-3)
    assert c["loop_scale_sigma_pct"] == pytest.approx(100 * sigma, abs=1e-3)
    assert c["loop_scale_sigma_pct"] * c["moved_per_scale_pct_m"] <= MAX_EXPECTED_ATE_M
    assert "the loops observe the flight's scale" in health.summary() and health.trusted and not health.scale


@pytest.mark.parametrize(
    ("sigma_pct", "observed"), [(None, False), (0.05, True), (2.0, False)], ids=["no lever", "sure", "loose"]
)
def test_the_summary_vouches_for_scale_only_as_far_as_the_loops_measured_it(sigma_pct, observed):
    counts = {
        "n_fallbacks": 0, "n_steps": 10, "n_poor_steps": 0, "n_weak_steps": 0, "n_loops_rejected": 0,
        "n_loops_too_flat": 0, "n_loops_against_graph": 0, "n_edges_back_left_out": 0, "n_edges_back_tried": 0,
        "loop_scale_sigma_pct": sigma_pct, "longest_loop_lever_m": 0.0 if sigma_pct is None else 48.0,
        "moved_per_scale_pct_m": 1.5,
    }  # fmt: skip
    loops = SimpleNamespace(loops=[] if sigma_pct is None else ["a loop of lever 48 m"])
    scale = scale_unvouched(SimpleNamespace(held=False, counts=counts, result=loops))
    health = Health(counts, [], scale)
    summary = health.summary()
    assert ("the loops observe the flight's scale" in summary) == observed
    assert ("this run vouches for no scale" in summary) == (not observed)
    assert health.consistent and health.trusted == observed  # the scale alone decides between the two
    if not observed:
        assert "would move the trajectory by 1.50 m" in summary and "by 1.50 m unseen" in scale
        assert ("no loop closed" in scale) == (sigma_pct is None) != ("levers up to 48 m" in scale)
    held = scale_unvouched(
        SimpleNamespace(held=True, counts=counts, result=loops)
    )  # GNSS fixes hold every node, scale too
    assert held == "" and Health(counts, [], held).trusted
    assert observed or Health(counts, [], held).summary().endswith("the GNSS fixes hold it")
