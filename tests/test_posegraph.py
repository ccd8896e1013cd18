"""The pose graph recovers known trajectories, and refuses bad input."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers.config.tables import PoseGraphConfig
from helpers.errors import SlamError
from helpers.slam.graph.optimizer import PoseGraph, information_from_sigmas

RING_NODES = 24
RING_RADIUS = 50.0  # m
ICP_EDGE_SIGMAS = PoseGraphConfig().edge_sigmas  # the pipeline's edge sigmas with icp weights
NOISE_T = 0.1  # m, odometry translation noise per step (= ICP_EDGE_SIGMAS)
NOISE_R = np.radians(0.3)  # rad, odometry rotation noise per step (= ICP_EDGE_SIGMAS)


def pose(rotvec=(0, 0, 0), t=(0, 0, 0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


def ring(n: int = RING_NODES, radius: float = RING_RADIUS) -> np.ndarray:
    """Like GTSAM's circlePose3: poses on a circle, heading along it, with a small altitude wave."""
    angles = 2 * np.pi * np.arange(n) / n
    return np.array(
        [pose((0, 0, a + np.pi / 2), (radius * np.cos(a), radius * np.sin(a), 700 + 2 * np.sin(2 * a))) for a in angles]
    )


def ate(poses, truth) -> float:
    return float(np.sqrt(np.mean(np.sum((poses[:, :3, 3] - truth[:, :3, 3]) ** 2, axis=1))))


def relative(truth, i, j) -> np.ndarray:
    return np.linalg.inv(truth[i]) @ truth[j]


def noisy_ring_graph(truth, seed=0, sigmas=ICP_EDGE_SIGMAS) -> PoseGraph:
    """Odometry with per-step noise, chained from an identity first pose (as the reference starts)."""
    rng = np.random.default_rng(seed)
    graph = PoseGraph()
    graph.add_node(np.eye(4))
    for k in range(1, len(truth)):
        noise = pose(rng.normal(0, NOISE_R, 3), rng.normal(0, NOISE_T, 3))
        graph.append(relative(truth, k - 1, k) @ noise, sigmas=sigmas)
    return graph


def add_true_loop(graph, truth, sigmas=ICP_EDGE_SIGMAS):
    last = len(truth) - 1
    graph.add_loop(0, last, relative(truth, 0, last), information_from_sigmas(sigmas))


def add_wrong_loop(graph, truth, sigmas=ICP_EDGE_SIGMAS):
    """Nodes on opposite sides of the ring (100 m apart) claimed to be 3 m apart."""
    graph.add_loop(RING_NODES // 4, 3 * RING_NODES // 4, pose(t=(3, 0, 0)), information_from_sigmas(sigmas))


def test_ring_recovered_from_noisy_odometry_and_one_loop():
    truth = ring()
    graph = noisy_ring_graph(truth)
    add_true_loop(graph, truth)
    result = graph.optimize(anchor_pose=truth[0])
    before, after = ate(result.initial_poses, truth), ate(result.poses, truth)
    # measured: 1.72 m -> 0.42 m
    assert before > 1.0
    assert after < 0.6
    assert after < 0.5 * before
    assert result.error_after < result.error_before
    np.testing.assert_allclose(result.poses[0], truth[0], atol=1e-3)
    np.testing.assert_allclose(result.loop_weights, [1.0])
    assert result.loop_translation_error[0] < 0.2


def test_ring_with_reference_identity_weights_still_improves():
    truth = ring()
    graph = noisy_ring_graph(truth, sigmas=np.ones(6))  # the reference's identity information everywhere
    graph.add_loop(0, RING_NODES - 1, relative(truth, 0, RING_NODES - 1))
    before = ate(truth[0] @ graph.initial_poses, truth)
    after = ate(graph.optimize(anchor_pose=truth[0]).poses, truth)
    assert after < 0.5 * before


def test_exact_odometry_and_loop_give_the_truth():
    truth = ring()
    graph = PoseGraph()
    graph.add_node(np.eye(4))
    for k in range(1, RING_NODES):
        graph.append(relative(truth, k - 1, k))
    graph.add_loop(0, RING_NODES - 1, relative(truth, 0, RING_NODES - 1))
    result = graph.optimize(anchor_pose=truth[0])
    np.testing.assert_allclose(result.poses, truth, atol=1e-4)
    assert result.error_before < 1e-6


@pytest.mark.parametrize(("kernel", "limit"), [("cauchy", 0.6), ("huber", 4.0)])
def test_wrong_loop_is_down_weighted_by_robust_kernel(kernel, limit):
    truth = ring()
    graph = noisy_ring_graph(truth)
    add_true_loop(graph, truth)
    add_wrong_loop(graph, truth)
    trusting = graph.optimize(anchor_pose=truth[0], loop_kernel="none")
    robust = graph.optimize(anchor_pose=truth[0], loop_kernel=kernel)
    # measured: none 39.7 m, huber 3.0 m, cauchy 0.42 m
    assert ate(trusting.poses, truth) > 10.0
    assert ate(robust.poses, truth) < limit
    assert robust.loop_weights[1] < 0.05  # the wrong loop is nearly ignored ...
    assert robust.loop_weights[1] < robust.loop_weights[0]  # ... and trusted less than the right one
    np.testing.assert_array_equal(robust.loop_pairs, [[0, RING_NODES - 1], [6, 18]])
    np.testing.assert_allclose(trusting.loop_weights, [1.0, 1.0])


def test_identity_weights_leave_a_wrong_loop_undetectable():
    """Why ICP_EDGE_SIGMAS exists: with the reference's identity weights rotations are so cheap that
    the wrong loop is satisfied by bending the ring, and the kernel sees no outlier to down-weight."""
    truth = ring()
    graph = noisy_ring_graph(truth, sigmas=np.ones(6))
    add_true_loop(graph, truth, sigmas=np.ones(6))
    add_wrong_loop(graph, truth, sigmas=np.ones(6))
    result = graph.optimize(anchor_pose=truth[0], loop_kernel="cauchy")
    assert ate(result.poses, truth) > 10.0  # measured 39.1 m
    assert result.loop_weights[1] > 0.5


@pytest.mark.parametrize("weighted", ["translation", "rotation"])
def test_information_matrix_is_translation_first(weighted):
    """A loop edge that weighs only translation moves only translation, and the other way round."""
    odometry = pose((0, 0, 0.0), (10, 0, 0))
    loop = pose((0, 0, 0.2), (10, 3, 0))  # disagrees in both rotation and translation
    strong, weak = 1e6, 1e-6
    diag = [strong] * 3 + [weak] * 3 if weighted == "translation" else [weak] * 3 + [strong] * 3
    graph = PoseGraph()
    graph.add_node(np.eye(4))
    graph.append(odometry, sigmas=np.ones(6))
    graph.add_loop(0, 1, loop, information=np.diag(diag))
    moved = graph.optimize().poses[1]
    follows_t, follows_r = (loop, odometry) if weighted == "translation" else (odometry, loop)
    # The edges disagree by 3 m and 0.2 rad; a swapped ordering would miss by that much. The small
    # slack is SE(3)'s own coupling of rotation and translation (measured 0.0021 rad, 0 m).
    assert np.linalg.norm(moved[:3, 3] - follows_t[:3, 3]) < 0.05
    assert Rotation.from_matrix(follows_r[:3, :3].T @ moved[:3, :3]).magnitude() < 0.01


def test_anchor_moves_the_whole_graph_rigidly():
    truth = ring(6)
    graph = PoseGraph()
    graph.add_node(np.eye(4))
    for k in range(1, 6):
        graph.append(relative(truth, k - 1, k))
    result = graph.optimize(anchor_pose=truth[0])
    np.testing.assert_allclose(result.poses, truth, atol=1e-6)
    assert result.iterations >= 0


def test_loop_pairs_list_every_loop_in_order():
    truth = ring()
    graph = noisy_ring_graph(truth)
    add_true_loop(graph, truth)
    add_wrong_loop(graph, truth)
    assert graph.loop_pairs() == [(0, RING_NODES - 1), (6, 18)]


def test_bad_inputs_raise_slam_error():
    graph = PoseGraph()
    with pytest.raises(SlamError, match="empty"):
        graph.optimize()
    with pytest.raises(SlamError, match="empty"):
        graph.append(np.eye(4))
    with pytest.raises(SlamError, match="rigid"):
        graph.add_node(np.diag([2.0, 1, 1, 1]))
    nan = np.eye(4)
    nan[0, 3] = np.nan
    with pytest.raises(SlamError, match="NaN"):
        graph.add_node(nan)
    with pytest.raises(SlamError, match="4 x 4"):
        graph.add_node(np.eye(3))
    graph.add_node(np.eye(4))
    graph.append(pose(t=(1, 0, 0)))
    asymmetric = np.eye(6)
    asymmetric[0, 4] = 0.5
    with pytest.raises(SlamError, match="symmetric"):
        graph.add_loop(0, 1, np.eye(4), asymmetric)
    with pytest.raises(SlamError, match="positive definite"):
        graph.add_loop(0, 1, np.eye(4), np.diag([1, 1, 1, 1, 1, 0.0]))
    with pytest.raises(SlamError, match="does not exist"):
        graph.add_loop(0, 5, np.eye(4))
    with pytest.raises(SlamError, match="sigmas"):
        graph.append(np.eye(4), sigmas=[1, 1, 1, 1, 1, -1])
    with pytest.raises(SlamError, match="loop_kernel"):
        graph.optimize(loop_kernel="tukey")
    graph.add_node(np.eye(4))  # joined by no edge
    with pytest.raises(SlamError, match="no chain"):
        graph.optimize()


class PositionFix:
    """A factor kind the package does not have, defined here: a GNSS-like fix of one node's position
    (gtsam.GPSFactor), isotropic ``sigma_m``. It only has to name its nodes and add itself to GTSAM."""

    def __init__(self, node: int, position, sigma_m: float):
        self.node, self.position, self.sigma_m = node, np.asarray(position, float), sigma_m

    @property
    def nodes(self):
        return (self.node,)

    def to_gtsam(self, context):
        import gtsam

        return gtsam.GPSFactor(self.node, self.position, gtsam.noiseModel.Isotropic.Sigma(3, self.sigma_m))


def test_a_new_factor_kind_is_honoured_without_editing_the_graph():
    """Noisy odometry drifts the end of an open chain (no loop); position fixes on every fourth node,
    a factor kind defined in this test, pull the chain back onto the truth, and a fix that disagrees
    moves its node to it."""
    truth = ring()[: RING_NODES // 2]
    graph = noisy_ring_graph(truth)
    drifted = graph.optimize(anchor_pose=truth[0])
    for k in range(4, len(truth), 4):
        graph.add_factor(PositionFix(k, truth[k][:3, 3], sigma_m=0.05))
    fixed = graph.optimize(anchor_pose=truth[0])
    assert ate(drifted.poses, truth) > 0.5
    assert ate(fixed.poses, truth) < 0.5 * ate(drifted.poses, truth)
    fixes = list(range(4, len(truth), 4))
    assert np.linalg.norm(fixed.poses[fixes, :3, 3] - truth[fixes, :3, 3], axis=1).max() < 0.15
    # a fix 5 m off the truth, much stiffer than the odometry, moves its node there
    graph.add_factor(PositionFix(len(truth) - 1, truth[-1][:3, 3] + [5.0, 0, 0], sigma_m=0.001))
    pulled = graph.optimize(anchor_pose=truth[0]).poses[-1]
    np.testing.assert_allclose(pulled[:3, 3], truth[-1][:3, 3] + [5.0, 0, 0], atol=0.01)
    with pytest.raises(SlamError, match="does not exist"):
        graph.add_factor(PositionFix(len(truth), truth[0][:3, 3], 1.0))


def test_position_sigmas_add_up_along_a_chain_and_meet_a_fix_as_gaussians_do():
    """A straight chain of 2 m steps, each known to 0.1 m on every axis and to a micro-radian in rotation, from
    an anchored first node: node k's position variance is 3 k 0.1² (three axes). A 0.3 m fix on the last node
    fuses with it as two Gaussians do, axis by axis."""
    from helpers.slam.graph.factors import PositionFactor

    sigma, fix_sigma, n = 0.1, 0.3, 12
    step_sigmas = [sigma] * 3 + [1e-6] * 3
    graph = PoseGraph()
    graph.add_node(np.eye(4))
    for _ in range(n):
        graph.append(pose(t=(2, 0, 0)), sigmas=step_sigmas)
    poses = graph.optimize().poses
    chain = graph.position_sigmas(poses, np.eye(4))
    np.testing.assert_allclose(chain[1:], sigma * np.sqrt(3 * np.arange(1, n + 1)), rtol=1e-3)
    assert chain[0] < 1e-3  # the anchor
    graph.add_factor(PositionFactor(n, poses[n, :3, 3], np.full(3, fix_sigma)))
    fused = graph.position_sigmas(poses, np.eye(4))
    per_axis = 1.0 / (1.0 / (n * sigma**2) + 1.0 / fix_sigma**2)
    np.testing.assert_allclose(fused[n], np.sqrt(3 * per_axis), rtol=1e-3)
    assert fused[n] < min(chain[n], np.sqrt(3) * fix_sigma)
    with pytest.raises(SlamError, match="poses"):
        graph.position_sigmas(poses[:-1], np.eye(4))


def test_position_covariances_are_in_the_map_frame():
    """A chain flown north (the first node turned by 90 degrees), each 2 m step known to 0.1 m along its own
    x axis (the track), 0.3 m across it and 0.2 m up: in the map, the spread across the track lies along x."""
    n, north = 6, pose(rotvec=(0, 0, np.pi / 2))
    graph = PoseGraph()
    graph.add_node(north)
    for _ in range(n):
        graph.append(pose(t=(2, 0, 0)), sigmas=[0.1, 0.3, 0.2] + [1e-6] * 3)
    poses = graph.optimize(anchor_pose=north).poses
    covariances = graph.position_covariances(poses, north)
    k = np.arange(n + 1)[:, None]
    np.testing.assert_allclose(np.diagonal(covariances, axis1=1, axis2=2)[1:], (k * [0.09, 0.01, 0.04])[1:], rtol=1e-3)
    assert np.abs(covariances[1:] - covariances[1:] * np.eye(3)).max() < 1e-6  # no correlation between the axes
    np.testing.assert_allclose(graph.position_sigmas(poses, north), np.sqrt(k[:, 0] * 0.14), atol=2e-4)
