"""The whole pipeline on a short loop over the default scene, and on inputs
where it cannot close a loop or cannot register at all."""

import dataclasses
import json
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

import helpers
from helpers.cli.outputs import write_run
from helpers.config.files import config_to_dict, config_to_toml
from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.quality.evaluation import grade_loops, map_errors, run_metrics
from helpers.quality.trust import assess
from helpers.sim.trajectories import read_tum
from helpers.slam.pipeline import Edge, Slam, build_pose_graph, run_slam
from helpers.slam.registration.fallbacks import CHECKS

SHORT = Config().with_values(loop_closure=dict(sub_map_thresh=3))  # a short loop has few submaps


@pytest.fixture(scope="module")
def short_run(short_loop):
    return run_slam(short_loop, SHORT)


def test_short_loop_is_closed_without_false_loops(short_loop, short_run):
    m = run_metrics(short_loop, short_run)
    assert m["n_loop_closures"] >= 1
    assert m["n_false_loop_closures"] == 0
    assert m["ate_rmse_optimized_m"] < m["ate_rmse_odometry_m"]
    assert m["rpe_trans_1_m"] < 0.15 and m["rpe_rot_1_deg"] < 0.1
    for loop in grade_loops(short_loop, short_run):  # every loop edge agrees with the truth
        assert loop.error_m < 1.0 and loop.error_deg < 2.0 and loop.rmse < SHORT.loop_closure.rmse_threshold


def test_nodes_are_the_accepted_scans_and_anchored(short_loop, short_run):
    np.testing.assert_array_equal(short_run.indices, np.arange(0, len(short_loop), SHORT.registration.skip_frames))
    np.testing.assert_allclose(short_run.poses_optimized[0], short_loop.poses[0], atol=1e-6)
    np.testing.assert_allclose(short_run.poses_odometry[0], short_loop.poses[0], atol=1e-12)
    assert len(short_run.submaps) == len(short_run.indices) // SHORT.map.n_scans_per_submap


# Two runs on one machine: counts equal, real numbers within these bounds
# (Open3D sums in parallel, so the last bits may differ from run to run).
REPEAT_REL, REPEAT_ABS = 1e-9, 1e-12


def test_same_inputs_same_numbers(short_loop, short_loop_csv, short_run, tmp_path):
    """``python -m helpers run`` in a fresh process writes the metrics this
    process computed on the same inputs (after whatever other tests ran in it):
    counts and flags identical, real numbers within the bounds above."""
    same = dataclasses.replace(SHORT, sensor=short_loop.sensor)  # the fixture's lidar noise ($HELPERS_NOISE_SEED)
    config = tmp_path / "config.toml"
    config.write_text(config_to_toml(same))
    command = [sys.executable, "-m", "helpers", "run", "--waypoints", str(short_loop_csv), "--config", str(config)]
    subprocess.run([*command, "--out", str(tmp_path / "run")], check=True, capture_output=True)
    written = json.loads((tmp_path / "run" / "metrics.json").read_text())
    errors = map_errors(short_run.map_points, short_loop.map_points)
    here = json.loads(json.dumps(run_metrics(short_loop, short_run, errors)))  # as metrics.json holds them
    for m in (written, here):
        m.pop("runtime_s")
    assert written.pop("config") == json.loads(json.dumps(config_to_dict(same)))
    assert here["n_loop_closures"] >= 1  # the run did close the loop: there is something to repeat
    assert written.keys() == here.keys()
    for key, value in here.items():
        if isinstance(value, float):
            assert written[key] == pytest.approx(value, rel=REPEAT_REL, abs=REPEAT_ABS), key
        else:
            assert written[key] == value, key


def test_written_outputs(short_loop, short_run, tmp_path):
    poses_gt = short_loop.poses[short_run.indices]
    out = write_run(short_run, tmp_path / "run", run_metrics(short_loop, short_run), poses_gt)
    metrics = json.loads((out / "metrics.json").read_text())
    for key in ("n_scans", "n_accepted", "n_loop_closures", "n_false_loop_closures", "ate_rmse_odometry_m"):
        assert key in metrics
    for key in ("ate_rmse_optimized_m", "rpe_trans_1_m", "rpe_rot_1_deg", "runtime_s", "config"):
        assert key in metrics
    assert metrics["config"]["loop_closure"]["sub_map_thresh"] == 3
    for name, poses in (("gt", poses_gt), ("optimized", short_run.poses_optimized)):
        stamps, read = read_tum(out / f"trajectory_{name}.txt")
        np.testing.assert_array_equal(stamps, short_run.indices)
        np.testing.assert_allclose(read[:, :3, 3], poses[:, :3, 3], atol=1e-5)
    assert (out / "map.ply").stat().st_size > 1000 and (out / "config.toml").is_file()


def test_no_loop_possible_ends_with_odometry_only(short_loop, short_run):
    """With no loop possible and no edges back, the graph is the odometry chain
    (the fixture's odometry reused: only the back end runs again)."""
    config = Config().with_values(loop_closure=dict(sub_map_thresh=1000), pose_graph=dict(edges_back=1))
    result = run_slam(short_loop, config, odometry=short_run.odometry)
    m = run_metrics(short_loop, result)
    assert m["n_loop_closures"] == 0 and result.queries == [] and result.extra_edges == []
    np.testing.assert_allclose(result.poses_optimized, result.poses_odometry, atol=1e-6)


def test_edges_back_keep_by_their_own_threshold(short_loop, short_run):
    """[pose_graph] edges_back_rmse_threshold decides which edges back are kept, the loop edges' threshold
    not at all (the fixture's odometry reused; no loop possible, so only the edges back run again)."""
    no_loops = dict(sub_map_thresh=1000)
    strict_loops = run_slam(
        short_loop,
        SHORT.with_values(loop_closure=dict(no_loops, rmse_threshold=0.001)),
        odometry=short_run.odometry,
    )
    assert [(e.i, e.j) for e in strict_loops.extra_edges] == [(e.i, e.j) for e in short_run.extra_edges]
    strict_edges = run_slam(
        short_loop,
        SHORT.with_values(loop_closure=no_loops, pose_graph=dict(edges_back_rmse_threshold=0.001)),
        odometry=short_run.odometry,
    )
    assert strict_edges.edges_back_tried == short_run.edges_back_tried > 0 and strict_edges.extra_edges == []


def test_flat_map_falls_back_instead_of_crashing(flat_plane):
    """Over a featureless plane nothing can be registered: every step is
    recorded as a fallback, and the run still ends with a result."""
    data = helpers.create_dataset(*flat_plane)
    result = run_slam(data, Config())
    assert len(result.odometry.fallbacks) == len(result.indices) - 1
    assert all("robust fit failed" in reason or "ICP" in reason for _, reason in result.odometry.fallbacks)
    assert np.isfinite(result.poses_optimized).all()
    # ... and says it cannot be trusted, why, and what to change
    health = assess(result)
    assert not health.consistent and health.counts["n_fallbacks"] == len(result.indices) - 1
    by_check = health.counts["fallbacks_by_check"]  # each named by the check that made it, and said so
    assert sum(by_check.values()) == len(result.indices) - 1 and set(by_check) <= set(CHECKS)
    assert "odometry steps fell back (" + ", ".join(f"{n} {c}" for c, n in by_check.items()) in health.summary()
    assert "fell back" in health.warning() and "skip_frames" in health.warning()
    assert health.counts["n_weak_steps"] == len(result.indices) - 1 and "too flat" in health.warning()
    assert run_metrics(data, result)["trusted"] is False


def test_a_good_run_is_consistent_and_counts_what_it_left_out(short_loop, short_run):
    """Nothing in the short loop disagrees. Flown once, its loops close near where it began: they barely
    observe its scale (a sigma of about 1 %, a bias of which moves it by about half a metre), and the
    whole verdict waits on that alone."""
    health = assess(short_run)
    assert health.consistent and health.trusted == (health.scale == ""), health.problems
    assert health.warning() == (f"this result is trusted in shape only. {health.scale}" if health.scale else "")
    c = health.counts
    assert c["n_steps"] == len(short_run.indices) - 1 and c["n_fallbacks"] == 0 and c["n_weak_steps"] == 0
    edges_back = SHORT.pose_graph.edges_back
    assert c["n_edges_back_tried"] == sum(min(edges_back, j) - 1 for j in range(2, len(short_run.indices)))
    assert c["n_edges_back_left_out"] == c["n_edges_back_tried"] - len(short_run.extra_edges)
    assert c["n_revisits"] > 0 and c["n_revisits_unclosed"] <= c["n_revisits"] / 2  # the loop flies 30 m past its start
    assert c["n_loops_too_flat"] == 0 and all(
        q.best_scan_constraint >= SHORT.loop_closure.min_constraint for q in short_run.queries if q.closure
    )
    m = run_metrics(short_loop, short_run)
    assert m["shape_trusted"] is True and m["trusted"] is health.trusted and m["health"]["scale"] == health.scale
    assert m["health"]["n_loop_queries"] == len(short_run.queries)


def test_a_loop_edge_the_graph_disagrees_with_is_reported_as_likely_false(short_run):
    """A wrong loop edge (5 m and 10 degrees off) added to a good run, found without the ground truth.
    The Cauchy kernel sets it aside: it is counted, and the run, which it moves by centimetres at most, is
    trusted. Without a robust kernel it bends the map by metres: the run is not trusted, and the warning
    names it."""
    import dataclasses

    true_loop = short_run.loops[0]
    wrong = Edge(true_loop.i, true_loop.j, true_loop.relative @ _transform_z(10.0, [5.0, 0.0, 0.0]), 0.1)
    queries = [*short_run.queries, dataclasses.replace(short_run.queries[-1], closure=wrong)]
    loops = [q.closure for q in queries if q.closure]
    for kernel in ("cauchy", "none"):
        config = SHORT.with_values(pose_graph={"loop_kernel": kernel})
        graph = build_pose_graph(short_run.odometry, short_run.extra_edges, loops, config)
        optimized = graph.optimize(anchor_pose=short_run.poses_odometry[0], loop_kernel=kernel)
        health = assess(dataclasses.replace(short_run, config=config, queries=queries, graph=optimized))
        pull, named = health.counts["loops_against_graph_pull_m"], health.counts["n_loops_against_graph"]
        if kernel == "cauchy":
            assert named == 1 and pull < 0.05 and health.consistent, health.problems
        else:  # bent, the graph also leaves a true loop far off: both are named
            assert named >= 1 and pull > 1.0 and not health.consistent
            assert f"{wrong.i}-{wrong.j}" in health.warning() and "no robust kernel" in health.warning()
    assert assess(short_run).counts["n_loops_against_graph"] == 0


def _transform_z(yaw_deg, shift):
    out = np.eye(4)
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    out[:2, :2] = [[c, -s], [s, c]]
    out[:3, 3] = shift
    return out


def test_a_revisit_that_closes_no_loop_is_not_trusted(short_loop, short_run):
    """The same loop with loop candidates required to be older than the whole flight
    (the fixture's odometry reused: only the back end runs again)."""
    config = Config().with_values(loop_closure=dict(sub_map_thresh=1000))
    result = run_slam(short_loop, config, odometry=short_run.odometry)
    health = assess(result)
    assert result.loops == [] and health.counts["n_revisits_unclosed"] == health.counts["n_revisits"] > 0
    assert not health.consistent and "sub_map_thresh" in health.warning()


def test_a_flight_too_short_for_10_step_errors_still_reports(flight_over):
    flight = flight_over(slice(0, 12))
    result = run_slam(flight)  # 4 accepted scans
    m = run_metrics(flight, result)
    assert m["n_accepted"] == 4 and m["rpe_trans_10_m"] is None and m["rpe_rot_10_deg"] is None
    assert m["rpe_trans_1_m"] < 0.15


def _shift(x: float) -> np.ndarray:
    transform = np.eye(4)
    transform[0, 3] = x
    return transform


@pytest.mark.parametrize(("weights", "expected_x"), [("icp", 2.1), ("identity", 2.2)])
def test_an_edge_spanning_k_steps_has_k_times_the_sigmas(weights, expected_x):
    """Two 1 m steps and an edge over both that says 2.3 m. With sigmas s,
    s and 2s (icp weights) least squares puts node 2 at 2.1 m; with equal
    weights (the reference's identity) at 2.2 m."""
    steps = [_shift(1.0)] * 2
    odometry = SimpleNamespace(poses=np.stack([_shift(0.0), _shift(1.0), _shift(2.0)]), relative=steps, information=[])
    graph = build_pose_graph(
        odometry,
        [Edge(0, 2, _shift(2.3), surface_rmse=0.1)],
        [],
        Config().with_values(pose_graph=dict(graph_weights=weights)),
    )
    poses = graph.optimize().poses
    assert poses[2][0, 3] == pytest.approx(expected_x, abs=1e-6)
    assert poses[1][0, 3] == pytest.approx(expected_x / 2, abs=1e-6)


def test_slam_driven_scan_by_scan_from_a_given_odometry_is_the_same_run(short_loop, short_run):
    """The main loop by hand, on the fixture's odometry (the back-end entry point): every step says what
    happened, skipped scans do nothing, and the result is the fixture's run."""
    slam = Slam(SHORT, anchor=short_loop.poses[0], odometry=short_run.odometry)
    steps = [slam.process(scan, index) for index, scan in enumerate(short_loop.scans)]
    again = slam.result(n_scans=len(short_loop))
    accepted = [step for step in steps if step.accepted]
    assert [step.index for step in accepted] == short_run.indices.tolist()
    assert [step.node for step in accepted] == list(range(len(short_run.indices)))
    assert [(s.loop.i, s.loop.j) for s in accepted if s.loop] == [(e.i, e.j) for e in short_run.loops]
    assert sum(len(s.edges_back) for s in accepted) == len(short_run.extra_edges)
    assert "\n" not in repr(accepted[-1]) and f"node {accepted[-1].node}" in repr(accepted[-1])
    assert repr(steps[1]) == "Step(scan 1: skipped)"
    assert again.odometry is short_run.odometry
    assert [(e.i, e.j) for e in again.extra_edges] == [(e.i, e.j) for e in short_run.extra_edges]
    np.testing.assert_allclose(again.poses_optimized, short_run.poses_optimized, atol=1e-9)
    np.testing.assert_allclose(again.map_points, short_run.map_points, atol=1e-9)
    with pytest.raises(helpers.SlamError, match="in order"):
        slam.process(short_loop.scans[0], 0)


def test_each_scan_is_downsampled_and_made_ready_for_icp_once(flight_over, monkeypatch):
    """One scan, one preparation: every accepted scan is grid-averaged once on each grid (features, ICP)
    and its ICP cloud made ready once, then shared by the odometry and the edges back."""
    import helpers.slam.preprocess
    import helpers.slam.registration.icp

    flight = flight_over(slice(0, 24))  # 8 accepted scans: each one is the fixed cloud of 3 later registrations
    prepared, averaged = [], []
    for module in (helpers.slam.preprocess, helpers.slam.registration.icp):
        real = module.icp_cloud
        monkeypatch.setattr(
            module, "icp_cloud", lambda points, *a, real=real: prepared.append(id(points)) or real(points, *a)
        )
    real_average = helpers.slam.preprocess.grid_average
    counted = lambda p, step: averaged.append(step) or real_average(p, step)  # noqa: E731
    monkeypatch.setattr(helpers.slam.preprocess, "grid_average", counted)
    result = run_slam(flight)
    assert len(result.indices) == 8 and result.edges_back_tried > 0
    assert sorted(prepared) == sorted(id(cloud) for cloud in result.clouds)  # each cloud once, and no other
    config = result.config
    assert sorted(averaged) == sorted([config.features.grid_step, config.registration.icp_grid_step] * 8)


def test_run_slam_prepares_the_next_scan_in_a_thread_and_stops_at_a_bad_one(flight_over, monkeypatch):
    """In global mode run_slam reads and prepares every accepted scan after the first in its read-ahead
    thread while the scan before is registered (in tracking mode, in turn); a scan that cannot be used
    stops the run at that scan, after the scans before it, with the message it gets in place."""
    import threading

    import helpers.slam.pipeline

    flight = flight_over(slice(0, 12))  # accepted: 0, 3, 6, 9
    read, processed = [], []
    real_prepare, real_process = helpers.slam.pipeline.prepare_scan, Slam.process

    def spy_prepare(scan, index, config):
        read.append((index, threading.current_thread().name))
        return real_prepare(scan, index, config)

    def spy_process(self, scan, index, prepared=None, times=None):
        processed.append(index)
        return real_process(self, scan, index, prepared, times)

    monkeypatch.setattr(helpers.slam.pipeline, "prepare_scan", spy_prepare)
    monkeypatch.setattr(Slam, "process", spy_process)
    result = run_slam(flight)
    assert result.indices.tolist() == processed == [0, 3, 6, 9]
    assert [index for index, _ in read] == [3, 6, 9]  # the first is prepared in place
    assert all(name.startswith("helpers-read-ahead") for _, name in read)
    read.clear(), processed.clear()
    tracking = run_slam(flight, Config().with_values(registration={"mode": "tracking"}))
    assert read == [] and processed == tracking.indices.tolist() == [0, 3, 6, 9]  # each prepared in turn
    processed.clear()
    nan = np.full((50, 3), np.nan)  # a scan that cannot be used (an empty one is left out and spanned, below)
    broken = dataclasses.replace(flight, scans=[*flight.scans[:6], nan, *flight.scans[7:]])
    with pytest.raises(helpers.SlamError, match="scan 6") as raised:
        run_slam(broken)
    assert processed == [0, 3, 6]
    with pytest.raises(helpers.SlamError) as in_place:
        Slam(Config(), anchor=flight.poses[0]).process(broken.scans[6], 6)
    assert str(raised.value) == str(in_place.value)


def test_a_scan_that_holds_no_point_is_left_out_and_spanned(short_loop, short_run):
    """A scan cast entirely over water holds no point: the run records it, leaves it out, registers the next
    scan across the gap (its guess the last motion twice), and ends as close to the truth as without the gap;
    the first scan, which anchors the flight, must hold points (one error, no crash)."""
    gap = int(short_run.indices[20])  # an accepted scan in the middle of the loop
    scans = list(short_loop.scans)
    scans[gap] = np.zeros((0, 3), dtype=np.float32)
    holed = dataclasses.replace(short_loop, scans=scans)
    result = run_slam(holed, SHORT)
    assert result.empty_scans == [gap] and gap not in result.indices
    assert len(result.indices) == len(short_run.indices) - 1
    m = run_metrics(holed, result)
    assert m["health"]["n_scans_empty"] == 1 and m["n_false_loop_closures"] == 0
    assert m["ate_rmse_optimized_m"] < max(0.3, 2 * run_metrics(short_loop, short_run)["ate_rmse_optimized_m"])
    scans[0] = np.zeros((0, 3), dtype=np.float32)
    with pytest.raises(SlamError, match="scan 0, the first, holds no point"):
        run_slam(dataclasses.replace(short_loop, scans=scans), SHORT)
