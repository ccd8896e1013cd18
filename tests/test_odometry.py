"""Odometry over a short stretch of the default flight, including a turn."""

import numpy as np
import pytest

from helpers.config.tables import Config, noise_seed_from_environment
from helpers.errors import SlamError
from helpers.geometry import rotation_angle_deg
from helpers.quality.metrics import ate, rpe
from helpers.slam.odometry import (
    Frame,
    local_map,
    predicted_motion,
    prepare,
    register_frames,
    run_odometry,
    staleness,
)
from helpers.slam.registration.fallbacks import CHECKS
from helpers.slam.registration.icp import WEAK_CONSTRAINT

WAYPOINT_ROWS = slice(60, 130)  # a straight stretch and most of a 90-degree turn


@pytest.fixture(scope="module")
def flight(flight_over):
    return flight_over(WAYPOINT_ROWS)


@pytest.fixture(scope="module")
def odometry(flight):
    return run_odometry(flight, flight.poses[0], Config())


def test_odometry_meets_the_relative_error_bar(flight, odometry):
    gt = flight.poses[odometry.indices]
    np.testing.assert_array_equal(odometry.indices, np.arange(0, len(flight), 3))
    np.testing.assert_allclose(odometry.poses[0], flight.poses[0])
    step = rpe(odometry.poses, gt, delta=1)
    assert step.translation.rmse <= 0.15, str(step)
    assert step.rotation.rmse <= 0.1, str(step)
    assert ate(odometry.poses, gt).rmse < 1.0
    assert odometry.fallbacks == []


STEP_BOUND_M = 0.3  # no step of the whole default flight is further off (benchmarks/bench_stability.py: 0.27 m)
# A step that flips between success and failure moves by metres; ICP stopping at another iteration moves it by
# centimetres (the whole flight, seeds 0-2: at most 8 cm).
NUDGE_BOUND_M = 0.15


# Three lidar noises: the fixtures' own (the default seed, whose flight and odometry are reused) and two others.
RUN_SEED = noise_seed_from_environment()
NOISE_SEEDS = [RUN_SEED] + [seed for seed in (0, 1, 2) if seed != RUN_SEED][:2]


@pytest.mark.parametrize("noise_seed", NOISE_SEEDS)
def test_every_step_stays_within_bounds_whatever_the_noise(flight_over, flight, odometry, noise_seed):
    """The same stretch under three lidar noises: every step within the same
    bound of the true motion and none falling back; and nudging every point
    by up to a micrometre (far more than the last-bit differences between
    CPUs) moves no step by more than a few centimetres."""
    config = Config()
    if noise_seed == flight.sensor.seed:
        data, result = flight, odometry
    else:
        data = flight_over(WAYPOINT_ROWS, noise_seed=noise_seed)
        result = run_odometry(data, config=config)
    truth = np.linalg.inv(data.poses[result.indices[:-1]]) @ data.poses[result.indices[1:]]
    error = np.linalg.norm(result.relative[:, :3, 3] - truth[:, :3, 3], axis=1)
    assert result.fallbacks == [] and error.max() < STEP_BOUND_M, error.max()
    rng = np.random.default_rng(noise_seed)
    nudged = run_odometry([s + rng.uniform(-1e-6, 1e-6, s.shape) for s in data.scans], data.poses[0], config)
    moved = np.linalg.norm(nudged.relative[:, :3, 3] - result.relative[:, :3, 3], axis=1)
    assert nudged.fallbacks == [] and moved.max() < NUDGE_BOUND_M, moved.max()


def test_odometry_result_is_complete(odometry):
    k = len(odometry.indices)
    assert odometry.poses.shape == (k, 4, 4) and odometry.relative.shape == (k - 1, 4, 4)
    assert len(odometry.n_matches) == len(odometry.n_inliers) == len(odometry.rmse) == k - 1
    assert np.all(odometry.n_inliers >= 20) and np.all(odometry.n_inliers <= odometry.n_matches)
    assert set(odometry.timings) == {"downsample", "fpfh", "match", "msac", "icp"}
    np.testing.assert_allclose(odometry.poses[1:], odometry.poses[:-1] @ odometry.relative)


def test_odometry_falls_back_on_a_hard_scan_instead_of_crashing(flight):
    scans = list(flight.scans[:10])
    rng = np.random.default_rng(0)
    scans[6] = rng.uniform([-30, -140, -620], [30, 140, -570], (4000, 3))  # noise: nothing matches
    result = run_odometry(scans, flight.poses[0], Config())
    assert len(result.poses) == 4
    # Scan 6 cannot be registered to scan 3, nor scan 9 to scan 6.
    assert [index for index, _ in result.fallbacks] == [6, 9]
    assert np.isfinite(result.poses).all()


def test_a_scan_too_sparse_to_describe_falls_back_instead_of_crashing(flight):
    """A scan with no more points than FPFH's neighbours (a swath mostly over water) gets no descriptors:
    its step is registered by ICP from the last motion and the run goes on."""
    scans = list(flight.scans[:13])
    scans[9] = scans[9][np.random.default_rng(0).choice(len(scans[9]), Config().features.neighbors, replace=False)]
    result = run_odometry(scans, flight.poses[0], Config())
    assert len(result.poses) == 5 and np.isfinite(result.poses).all()
    assert [index for index, _ in result.fallbacks] == [9, 12]
    assert "robust fit failed" in dict(result.fallbacks)[9]
    # every fallback named by its check, one per step that fell back (the names a run's health counts)
    named = [(index, check) for index, check in zip(result.indices[1:], result.checks, strict=True) if check]
    assert [index for index, _ in named] == [9, 12] and dict(named)[9] == "robust fit failed"
    assert all(check in CHECKS for _, check in named)


def test_odometry_refuses_too_few_scans(flight):
    with pytest.raises(SlamError, match="at least 2 accepted scans"):
        run_odometry(flight.scans[:2], np.eye(4), Config())


def test_prepared_frames_register_like_bare_ones(flight):
    # prepare() readies the ICP cloud once; a Frame built by hand, without it, must register the same.
    config = Config()
    moving, fixed = prepare(flight.scans[9], config), prepare(flight.scans[6], config)
    assert moving.icp is not None and moving.icp.metric == config.registration.metric
    assert set(moving.timings) == {"downsample", "fpfh", "icp"}
    bare_moving, bare_fixed = (
        Frame(f.points, f.features, f.icp_points, {}, keypoints=f.keypoints) for f in (moving, fixed)
    )
    ready = register_frames(moving, fixed, config)
    bare = register_frames(bare_moving, bare_fixed, config)
    np.testing.assert_array_equal(ready.matches, bare.matches)
    np.testing.assert_allclose(ready.T_fine, bare.T_fine, atol=1e-9)


def test_tracking_registers_like_the_global_workflow_without_its_features(flight, odometry):
    """Tracking: ICP from the last motion; the global workflow only for the first step (no motion yet)
    and where a check fails. Every step stays within the same bound of the truth as the reference's."""
    tracking = run_odometry(flight, flight.poses[0], Config().with_values(registration=dict(mode="tracking")))
    truth = np.linalg.inv(flight.poses[tracking.indices[:-1]]) @ flight.poses[tracking.indices[1:]]
    error = np.linalg.norm(tracking.relative[:, :3, 3] - truth[:, :3, 3], axis=1)
    assert error.max() < STEP_BOUND_M and tracking.fallbacks == []
    assert not tracking.tracked[0] and tracking.tracked[1:].mean() > 0.9
    assert tracking.timings["fpfh"][2:].sum() < odometry.timings["fpfh"][2:].sum() / 5  # few scans described
    gt = flight.poses[tracking.indices]
    assert abs(ate(tracking.poses, gt).rmse - ate(odometry.poses, gt).rmse) < 0.2


def test_tracking_hands_doubtful_steps_to_the_global_workflow(flight):
    """With a jump limit no real motion change passes, every step after the first is checked, found
    doubtful and registered globally: the result equals the global workflow's odometry (with the same
    limit, which it also reads: a fit that ends farther from the last motion meets ICP from it)."""
    strict = dict(tracking_max_jump_m=1e-9, tracking_max_jump_deg=1e-9)
    tracking = Config().with_values(registration={**strict, "mode": "tracking"})
    doubtful = run_odometry(flight.scans[:30], flight.poses[0], tracking)
    reference = run_odometry(flight.scans[:30], flight.poses[0], Config().with_values(registration=strict))
    assert not doubtful.tracked.any()
    np.testing.assert_allclose(doubtful.relative, reference.relative, atol=1e-9)


@pytest.mark.parametrize("crop", [False, True])
def test_a_fit_that_pairs_little_of_the_scan_is_retried_from_the_last_motion(flight, monkeypatch, crop):
    """A robust fit tens of metres off can leave ICP with a low RMSE over the
    few points it still pairs (flat ground matches itself anywhere): the
    registration must see how little it paired, restart from the last motion
    and keep the answer that pairs more, near the truth. With the overlap crop,
    made at the last motion, ICP from the fit pairs too little to fit well, and
    the RMSE check restarts it first."""
    import helpers.slam.registration.fallbacks as fallbacks
    import helpers.slam.registration.pair as frames

    config = Config().with_values(registration={"overlap_crop": crop})
    fixed_id, moving_id = 30, 33
    truth = np.linalg.inv(flight.poses[fixed_id]) @ flight.poses[moving_id]
    far = truth.copy()
    far[:3, 3] += [40.0, 0.0, 0.0]  # most of the 53 m strip along the track: ICP settles 100 m off on few pairs
    monkeypatch.setattr(fallbacks, "robust_fit", lambda *args, **kwargs: (far, np.zeros(0, bool)))
    fixed, moving = (frames.describe(prepare(flight.scans[k], config), config) for k in (fixed_id, moving_id))
    pair = register_frames(moving, fixed, config, guess=truth @ _nudge(0.5))
    assert ("paired" if not crop else "restarted from the previous motion") in (pair.fallback or ""), pair.fallback
    assert pair.check == ("little paired" if not crop else "far off, restarted")  # the name a run counts it by
    assert np.linalg.norm(pair.T_fine[:3, 3] - truth[:3, 3]) < 0.3


def _nudge(metres: float) -> np.ndarray:
    """A last motion half a metre off the truth, as a previous step's would be."""
    nudge = np.eye(4)
    nudge[:3, 3] = [metres, 0.0, 0.0]
    return nudge


def test_on_a_featureless_plane_a_jump_from_the_last_motion_is_not_believed(flat_plane, monkeypatch):
    """Over a plane every horizontal slide scores the same, so a robust fit
    (here forced) 4 m off is as good as any to ICP: the registration must
    see that the pairs pin nothing along the plane and keep the last motion
    (the flight's momentum) instead of the jump."""
    import helpers
    import helpers.slam.registration.fallbacks as fallbacks
    import helpers.slam.registration.pair as frames

    data = helpers.create_dataset(*flat_plane)
    config = Config()
    truth = np.linalg.inv(data.poses[3]) @ data.poses[6]
    far = truth.copy()
    far[:3, 3] += [4.0, 0.0, 0.0]  # still over the plane: as many pairs as the truth
    monkeypatch.setattr(fallbacks, "robust_fit", lambda *args, **kwargs: (far, np.zeros(0, bool)))
    fixed, moving = (frames.describe(prepare(data.scans[k], config), config) for k in (3, 6))
    pair = register_frames(moving, fixed, config, guess=truth)
    assert "too flat" in (pair.fallback or "") and pair.check == "flat ground", pair.fallback
    assert np.linalg.norm(pair.T_fine[:3, 3] - truth[:3, 3]) < 0.5


def test_on_repeating_ground_a_fit_one_ridge_off_loses_to_the_last_motion(grid_tile, tmp_path, monkeypatch):
    """Ridges every 6 m across the track and waves along it pin every
    direction, yet a fit one ridge off (forced here) pairs as much of the
    scan as the truth and ICP settles there. The registration must run ICP
    from the last motion too and, the fit being no better, keep the flight's
    momentum: a drone does not jump 6 m sideways between two scans."""
    import helpers
    import helpers.slam.registration.fallbacks as fallbacks
    import helpers.slam.registration.pair as frames

    def ridges(x, y):
        return 100.0 + 1.5 * np.sin(2 * np.pi * y / 6.0) + 2.0 * np.sin(2 * np.pi * x / 23.0)

    tile = grid_tile("ridges.las", 300.0, 200.0, ridges)
    flight = tmp_path / "flight.csv"
    np.savetxt(flight, np.column_stack([np.arange(-30.0, 30.0, 2.0), np.zeros(30)]), delimiter=",")
    data = helpers.create_dataset(tile, flight)
    config = Config()
    truth = np.linalg.inv(data.poses[3]) @ data.poses[6]
    far = truth.copy()
    far[:3, 3] += [0.0, 6.0, 0.0]  # one ridge over
    monkeypatch.setattr(fallbacks, "robust_fit", lambda *args, **kwargs: (far, np.zeros(0, bool)))
    fixed, moving = (frames.describe(prepare(data.scans[k], config), config) for k in (3, 6))
    pair = register_frames(moving, fixed, config, guess=truth @ _nudge(0.5))
    assert pair.constraint > WEAK_CONSTRAINT, pair.constraint  # the ground pins the motion: not the flat case
    assert "last motion kept" in (pair.fallback or "") and pair.check == "jump", pair.fallback
    assert np.linalg.norm(pair.T_fine[:3, 3] - truth[:3, 3]) < 0.3


def test_a_fit_turned_half_round_loses_to_the_last_motion(flat_plane, monkeypatch):
    """A yaw-and-translation fit on few inliers can turn the scan half round about its own centre (12 of 204
    matches did, 150 m above Autzen): the translation lands where the last motion puts it, ICP settles with
    a low RMSE on smooth ground, and only the turn gives the jump away. The registration must doubt a fit
    that turns more than ``tracking_max_jump_deg`` from the last motion and keep ICP from it. (On a plane
    the turned scan fits as well as the true one; 150 m above Autzen the turned fit kept fitting no better,
    and ``tests/test_step_bias.py`` has that flight.)"""
    import helpers
    import helpers.slam.registration.fallbacks as fallbacks
    import helpers.slam.registration.pair as frames

    data = helpers.create_dataset(*flat_plane)
    config = Config()
    truth = np.linalg.inv(data.poses[3]) @ data.poses[6]
    half_round = np.diag([-1.0, -1.0, 1.0, 1.0])  # 180 degrees about the moving scan's vertical
    monkeypatch.setattr(fallbacks, "robust_fit", lambda *args, **kwargs: (truth @ half_round, np.zeros(0, bool)))
    fixed, moving = (frames.describe(prepare(data.scans[k], config), config) for k in (3, 6))
    pair = register_frames(moving, fixed, config, guess=truth @ _nudge(0.5))
    assert "and 180 deg from the last motion" in (pair.fallback or ""), pair.fallback
    assert pair.check == ("flat ground" if "too flat" in pair.fallback else "jump")  # named as its message says
    assert rotation_angle_deg(np.linalg.inv(truth) @ pair.T_fine) < 1.0
    assert np.linalg.norm(pair.T_fine[:3, 3] - truth[:3, 3]) < 0.6


def test_a_sharp_turn_the_guess_lags_behind_is_confirmed_not_doubted(monkeypatch):
    """Entering a sharp turn, the last motion turns 10 degrees less than the step: the fit is doubted, ICP
    runs from the last motion too and lands on the same motion, which confirms the fit. No fallback is
    recorded (20 of 45 steps of a tight test loop were before this), and the fit's answer stands."""
    from test_step_bias import STRIPS, turned_strips, yawed

    import helpers.slam.registration.fallbacks as fallbacks
    import helpers.slam.registration.pair as frames

    config = STRIPS
    moving_points, fixed_points, truth = turned_strips(10.0)
    monkeypatch.setattr(fallbacks, "robust_fit", lambda *args, **kwargs: (truth, np.zeros(0, bool)))
    moving, fixed = (frames.describe(prepare(p, config), config) for p in (moving_points, fixed_points))
    lagging = truth @ np.linalg.inv(yawed(10.0, (0.0, 0.0, 0.0)))
    pair = register_frames(moving, fixed, config, guess=lagging)
    assert pair.fallback is None, pair.fallback
    assert np.array_equal(pair.T_coarse, truth)
    assert np.linalg.norm(pair.T_fine[:3, 3] - truth[:3, 3]) < 0.05
    assert rotation_angle_deg(np.linalg.inv(truth) @ pair.T_fine) < 0.2


def test_the_guess_ignores_one_wrong_step():
    """The constant-velocity guess is the medoid of the last three steps: a
    steady flight gives its newest step, one step 6 m off is ignored, and
    fewer than three steps give the last."""
    step = np.eye(4)
    step[:3, 3] = [2.0, 0.0, 0.0]
    wrong = step.copy()
    wrong[:3, 3] = [8.0, 0.0, 0.0]
    assert predicted_motion([]) is None
    assert predicted_motion([step, wrong]) is wrong
    assert predicted_motion([step, step.copy(), wrong]) is not wrong
    faster = step.copy()
    faster[:3, 3] = [2.1, 0.0, 0.0]
    steady = [step, step.copy(), faster]
    np.testing.assert_allclose(predicted_motion(steady)[:3, 3], [2.0, 0.0, 0.0])
    newest = step.copy()
    assert predicted_motion([step, step.copy(), newest]) is newest


def test_after_a_blind_step_the_guess_is_the_last_step_and_its_age_is_counted():
    """Steps whose motion is the last motion's (blind: a lake, no fit) measured nothing but the yaw ICP found.
    After a blind step the guess is the last step: the newest blind one, or the first step measured after
    them, unless that one jumped from its own guess (the medoid then ignores it, as it ignores one wrong
    step). The guess's age is the blind steps in its window, or the whole blind run when longer."""
    from test_step_bias import yawed

    straight, turning, wrong = yawed(0.0, (2.6, 0.0, 0.0)), yawed(2.5, (2.6, 0.1, 0.0)), yawed(0.0, (7.0, 0, 0))
    assert predicted_motion([straight, straight.copy(), turning], [False, True, True]) is turning
    assert predicted_motion([straight, straight.copy(), turning], [True, True, False]) is turning
    assert predicted_motion([straight, straight.copy(), turning], [False, False, True]) is not turning
    assert predicted_motion([straight, straight.copy(), wrong], [True, True, False], [False, False, True]) is not wrong
    assert predicted_motion([straight, straight.copy(), turning], [True, False]) is turning  # the newest flags only
    assert staleness([]) == 0 and staleness([True, False, False, False]) == 0
    assert staleness([True, False, False]) == 1  # the guess may stand on it: it is in the window
    assert staleness([False, True, False]) == 1
    assert staleness([False, True, True]) == 2
    assert staleness([True] * 5 + [False, False]) == 1  # the run ended: its last step is all that counts
    assert staleness([False] + [True] * 5) == 5


def test_steps_over_a_lake_keep_their_length(benchmark_flight):
    """150 m above the sparse tile (lidar noise seed 1), scans 110-125 cross a lake: no relief pins a step along
    the track. Generalized ICP's Hessian still claimed a 0.02 m sigma there, so the momentum blend followed ICP's
    slide towards the last scan, and the next guess started from the shortened step: the steps came out 0.5-1.3
    m short one after another (a mean step ratio of 0.925 over these 60), and the loops could not undo it, as
    both laps slid alike (ATE 35.8 m). Fitted for a low flight, each step's information comes from the
    point-to-plane Hessian, which is near zero along the track there, and ICP is given time to converge."""
    data, config = benchmark_flight("sparse-150", swing=0.0, seed=1)
    assert config.pose_graph.information == "plane"
    scans = list(range(70, 130))
    result = run_odometry([data.scans[k] for k in scans], data.poses[scans[0]], config)
    truth = np.linalg.inv(data.poses[scans[:-1]]) @ data.poses[scans[1:]]
    steps = np.asarray(result.relative)[:, :3, 3]
    true_m, estimated_m = np.linalg.norm(truth[:, :3, 3], axis=1), np.linalg.norm(steps, axis=1)
    errors_m = np.linalg.norm(steps - truth[:, :3, 3], axis=1)
    # a step over water follows the momentum, which wanders: within 0.75 m (0.4 here, 0.5 on seeds 0, 2 and 3),
    # and the 120 m keep their length within 3 % (0.2 % here; seed 3 ran 2 % long)
    assert errors_m.max() < 0.75, np.round(estimated_m - true_m, 2)
    assert abs(np.mean(estimated_m / true_m) - 1.0) < 0.03, np.round(estimated_m - true_m, 2)


def test_a_turn_begun_over_water_is_followed(autzen, benchmark_flight):
    """250 m above Autzen with the speed swinging by 30 %, the drone enters a 6-degree-a-step turn over the
    river (scans 64-69: flat, sparse ground, no fit explains the matches). Before the odometry knew which steps
    measured nothing, it kept the straight motion through the turn and then doubted the first fit that saw it
    (its turn was 6 degrees from the stale guess): 5 degrees lost a step, 23 in all. Every step must stay
    within a degree of the truth."""
    data, config = benchmark_flight("autzen-250", swing=0.3)
    assert config.registration.skip_frames == 1 and config.registration.motion_guard
    scans = range(58, 77)
    result = run_odometry([data.scans[k] for k in scans], data.poses[58], config)
    truth = np.linalg.inv(data.poses[list(scans)[:-1]]) @ data.poses[list(scans)[1:]]
    turned = np.degrees(np.arctan2(truth[:, 1, 0], truth[:, 0, 0]))
    assert turned[-8:].min() > 5.0  # the turn is in these scans
    assert result.fallbacks  # ... and so is the water
    errors = [rotation_angle_deg(np.linalg.inv(t) @ r) for t, r in zip(truth, result.relative, strict=True)]
    assert max(errors) < 1.0, np.round(errors, 2)


def test_a_slide_the_overlap_crop_lets_through_loses_to_the_whole_scan(benchmark_flight):
    """150 m above the sparse tile with the speed swinging, the step from scan 88 to 89 registered on the
    overlap slides 2.9 m along the track, from the fit and from the true last motion alike (constraint 0.0065,
    just above the weak bar): the crop leaves a strip too short to pin it. A drone does not jump: ICP on the
    whole scan from the last motion lands within the jump limits of it and is kept."""
    from helpers.slam.preprocess import describe

    data, config = benchmark_flight("sparse-150", swing=0.3)
    assert config.registration.overlap_crop and config.registration.motion_guard
    fixed, moving = (describe(prepare(data.scans[k], config), config) for k in (88, 89))
    truth = np.linalg.inv(data.poses[88]) @ data.poses[89]
    last_motion = np.linalg.inv(data.poses[87]) @ data.poses[88]
    pair = register_frames(moving, fixed, config, guess=last_motion)
    assert "whole scan" in (pair.fallback or "") and pair.check == "whole scan", pair.fallback
    assert np.linalg.norm(pair.T_fine[:3, 3] - truth[:3, 3]) < 0.5
    assert rotation_angle_deg(np.linalg.inv(truth) @ pair.T_fine) < 0.5


def test_the_local_map_holds_the_last_scans_in_the_previous_frame(flight):
    """Three scans carried into the last one's frame by their true poses:
    the local map covers all three footprints (it reaches back along the
    track as far as the oldest scan lies behind), every point of it lies
    where the scans' own points do (within the ICP grid), and its features
    stay the previous scan's."""
    config = Config()
    step = config.registration.icp_grid_step
    ids = [30, 33, 36]
    frames = [prepare(flight.scans[k], config) for k in ids]
    poses = [flight.poses[k] for k in ids]
    merged = local_map(frames, poses, config)
    assert merged.features is frames[-1].features and merged.points is frames[-1].points
    in_world = lambda pts, pose: pts @ pose[:3, :3].T + pose[:3, 3]  # noqa: E731
    union = np.vstack([in_world(f.icp_points, p) for f, p in zip(frames, poses, strict=True)])
    mapped = in_world(merged.icp_points, poses[-1])
    from scipy.spatial import cKDTree

    nearest, _ = cKDTree(union).query(mapped)
    assert np.percentile(nearest, 99) < step, np.percentile(nearest, 99)
    back = np.linalg.norm(poses[-1][:3, 3] - poses[0][:3, 3])  # how far behind the oldest scan lies
    along = (merged.icp_points[:, 0].min(), frames[-1].icp_points[:, 0].min())
    assert along[1] - along[0] > 0.8 * back, along  # the map reaches that far further back than the scan
    assert merged.icp is not None and len(merged.icp.points) == len(merged.icp_points)


def test_odometry_on_a_local_map_stays_on_the_truth(flight, odometry):
    """ICP onto the last four scans merged: the steps stay within the
    scan-to-scan bound, and the trajectory no worse than the scan-to-scan
    one by more than a tenth."""
    mapped = run_odometry(flight, flight.poses[0], Config().with_values(registration={"icp_local_map": 4}))
    truth = flight.poses[mapped.indices]
    assert rpe(mapped.poses, truth).translation.max < STEP_BOUND_M
    assert ate(mapped.poses, truth).rmse <= 1.1 * ate(odometry.poses, truth).rmse + 0.02


def test_run_odometry_reading_ahead_is_the_odometry_of_scans_prepared_in_turn(flight_over, monkeypatch):
    """In global mode run_odometry prepares each scan in a thread while the one before is registered:
    the same poses, steps and matches to the bit as an Odometry fed scans prepared one by one."""
    import threading

    import helpers.slam.odometry
    from helpers.slam.odometry import Odometry

    flight = flight_over(slice(0, 15))  # accepted: 0, 3, 6, 9, 12
    config = Config()
    names, real = [], helpers.slam.odometry.prepare_scan

    def spy(scan, index, cfg):
        names.append(threading.current_thread().name)
        return real(scan, index, cfg)

    monkeypatch.setattr(helpers.slam.odometry, "prepare_scan", spy)
    ahead = run_odometry(flight, config=config)
    assert len(names) == 5 and all(name.startswith("helpers-read-ahead") for name in names)
    in_turn = Odometry(config, flight.poses[0])
    for index in ahead.indices:
        in_turn.register(prepare(flight.scans[index], config), index)
    expected = in_turn.result()
    assert np.array_equal(ahead.poses, expected.poses) and np.array_equal(ahead.relative, expected.relative)
    assert np.array_equal(ahead.n_matches, expected.n_matches) and np.array_equal(ahead.rmse, expected.rmse)


def test_with_a_last_motion_the_matches_stay_inside_the_gate_and_the_step_lands_on_the_truth(flight):
    """Every match of a gated step pairs points whose cells touch, once the moving point is put where
    the last motion (half a metre off) says; the step is as right as without the gate."""
    from helpers.slam.registration.pair import gate

    config = Config()
    fixed, moving = (prepare(flight.scans[k], config) for k in (30, 33))
    truth = np.linalg.inv(flight.poses[30]) @ flight.poses[33]
    guess = truth @ _nudge(0.5)
    moving_xy, fixed_xy, cell = gate(moving, fixed, config, guess)
    assert 12 < cell < 20  # 1 m + 2 sin(3 deg) x the scan's farthest point, about 150 m out
    pair = register_frames(moving, fixed, config, guess=guess)
    ungated = register_frames(moving, fixed, config.with_values(features={"match_gate": 0.0}), guess=guess)
    assert not pair.ungated and pair.fallback is None and len(pair.matches) > 100
    on_moving, on_fixed = moving.described(), fixed.described()
    rows, fixed_rows = np.searchsorted(on_moving, pair.matches[:, 0]), np.searchsorted(on_fixed, pair.matches[:, 1])
    gap = np.abs(np.floor(moving_xy[rows] / cell) - np.floor(fixed_xy[fixed_rows] / cell))
    assert gap.max() <= 1
    for result in (pair, ungated):
        assert np.linalg.norm(result.T_fine[:3, 3] - truth[:3, 3]) < STEP_BOUND_M
        assert rotation_angle_deg(np.linalg.inv(truth) @ result.T_fine) < 0.2


def test_a_step_the_gate_misleads_is_matched_again_without_it(flight):
    """A last motion 80 m off (a wrong step before) puts the gate where the true partners are not:
    the gated fit fails or is doubted, and the step is registered again without the gate, on the truth."""
    config = Config()
    fixed, moving = (prepare(flight.scans[k], config) for k in (30, 33))
    truth = np.linalg.inv(flight.poses[30]) @ flight.poses[33]
    wrong = truth.copy()
    wrong[:3, 3] += [0.0, 80.0, 0.0]
    pair = register_frames(moving, fixed, config, guess=wrong)
    assert pair.ungated
    assert np.linalg.norm(pair.T_fine[:3, 3] - truth[:3, 3]) < STEP_BOUND_M
