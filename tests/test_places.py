"""Place recognition after a blind stretch: a revisit the odometry's missed turn hid is found by its
descriptors and closed with true loops, and a recognition only counts once the next one agrees."""

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from helpers.config.tables import Config
from helpers.quality.trust import assess
from helpers.slam.loops.places import AGREE_DEG, AGREE_M, CONFIRM_NODES, PlaceRecognition


def turned(yaw_deg: float, xyz=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    T[:3, 3] = xyz
    return T


def test_a_recognition_counts_only_when_the_one_before_put_the_flight_in_the_same_place():
    places = PlaceRecognition(Config())
    pose = turned(10.0, (300.0, 50.0, 700.0))  # where the odometry puts the scan
    correction = turned(40.0, (20.0, -160.0, 0.0))  # where the recognised place puts it, from there
    assert not places.confirmed(30, pose, correction @ pose)  # the first has nothing to agree with
    later = pose @ turned(1.0, (6.0, 0.0, 0.0))  # three nodes on, the same correction within centimetres
    nudge = turned(0.2 * AGREE_DEG, (0.2 * AGREE_M, 0.0, 0.0))
    assert places.confirmed(33, later, nudge @ correction @ later)
    # a place recognised 3 AGREE_M away (repeating ground) does not confirm, nor is it confirmed by the last
    assert not places.confirmed(36, later, turned(0.0, (3 * AGREE_M, 0.0, 0.0)) @ correction @ later)
    # turned by more than AGREE_DEG about the scan: the same position, another heading
    about = turned(0.0, later[:3, 3]) @ turned(2 * AGREE_DEG) @ turned(0.0, -later[:3, 3])
    assert not places.confirmed(37, later, correction @ about @ later)
    assert places.confirmed(38, later, correction @ about @ later)  # ... but it confirms the next that agrees
    # an agreeing recognition too long after the last is not a confirmation
    assert not places.confirmed(38 + CONFIRM_NODES + 1, later, correction @ about @ later)


def test_after_a_blind_stretch_the_revisit_a_missed_turn_hid_is_recognised(short_loop):
    # The short flight's own odometry, its steps 4-8 made blind (they fell back, as over a lake) and 45 degrees
    # of an early turn taken out there: the flight comes back to its start some 40 m and 45 degrees from where
    # the odometry puts it, where the loop search (held at the odometry) finds nothing. Place recognition finds
    # the start by its descriptors, and the pose graph bends the blind steps to the loops.
    from helpers.quality.evaluation import grade_loops, run_metrics
    from helpers.slam.pipeline import run_slam

    config = Config().with_values(
        loop_closure={"sub_map_thresh": 3, "search": "uncertainty", "skip_after_loop": 0},
        pose_graph={"graph_weights": "hessian", "loop_kernel": "huber"},  # each step's own information
    )
    odometry = run_slam(short_loop, config).odometry
    relative = odometry.relative.copy()
    relative[8] = relative[8] @ np.linalg.inv(turned(45.0))
    poses = [odometry.poses[0]]
    for motion in relative:
        poses.append(poses[-1] @ motion)
    blind = [(int(i), "no match (a lake)") for i in odometry.indices[5:10]]  # the steps to nodes 5-9
    # what such steps say of themselves: over a bare field nothing pins the turn or the slide along the track
    loose = np.diag(1.0 / np.array([2.0, 0.2, 0.2, 0.01, 0.01, np.radians(15.0)]) ** 2)
    information = [loose if 4 <= k <= 8 else info for k, info in enumerate(odometry.information)]
    bent = dataclasses.replace(
        odometry, poses=np.array(poses), relative=relative, fallbacks=blind, information=information
    )
    off = config.with_values(loop_closure={"place_recognition": False})
    assert run_metrics(short_loop, run_slam(short_loop, off, odometry=bent))["n_loop_closures"] == 0
    result = run_slam(short_loop, config, odometry=bent)
    m = run_metrics(short_loop, result)
    assert m["ate_rmse_odometry_m"] > 20.0
    assert m["n_loop_closures"] >= 2 and m["n_false_loop_closures"] == 0
    for loop in grade_loops(short_loop, result):
        assert loop.error_m < 1.0 and loop.error_deg < 2.0
    assert m["ate_rmse_optimized_m"] < 0.5  # the loops bend the blind steps: from some 40 m
    # the first loop came by recognition (the search at the odometry found none), and the run counts them
    recognised = [q for q in result.queries if q.fallback == "recognised"]
    by_recognition = {q.closure.j for q in recognised if q.closure}
    assert by_recognition and min(by_recognition) == min(loop.j for loop in result.loops)
    assert m["health"]["n_loops_recognised"] == len(by_recognition)
    assert m["health"]["n_queries_recognised"] == len(recognised) >= len(result.loops)
    assert "recognised old places after a blind stretch" in assess(result).summary()
    # without the blind stretch the run never asks: the same odometry, no fallbacks, closes nothing
    seeing = dataclasses.replace(bent, fallbacks=[])
    assert run_metrics(short_loop, run_slam(short_loop, config, odometry=seeing))["n_loop_closures"] == 0
