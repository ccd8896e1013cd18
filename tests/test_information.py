"""The information of a registration (helpers.slam.graph.information) against cases whose answer is known."""

import numpy as np
import pytest

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.geometry import transform_points
from helpers.slam.graph.build import build_pose_graph
from helpers.slam.graph.factors import Edge
from helpers.slam.graph.information import MAX_SIGMA, blended, calibrated, plane_information, weakest, whitened
from helpers.slam.odometry import OdometryResult
from helpers.slam.registration.icp import icp_cloud, refine_icp

ICP = {"inlier_distance": 2.0, "max_iterations": 30, "tolerance": 1e-6}


def _plane(n=4000, noise=0.02, seed=0):
    """Points of the plane z = 0 (a 40 m square) with Gaussian noise of ``noise`` m along z."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-20, 20, (n, 2)), rng.normal(0, noise, n)])


def _hills(n=6000, seed=1):
    """A surface with relief in every direction: slopes pin x, y and the rotations."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-20, 20, (n, 2))
    z = 3 * np.sin(xy[:, 0] / 4) + 2 * np.cos(xy[:, 1] / 3) + 0.5 * np.sin((xy[:, 0] + xy[:, 1]) / 2)
    return np.column_stack([xy, z + rng.normal(0, 0.01, n)])


def _transform(yaw_deg, shift):
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = shift
    return T


def test_plane_information_is_the_analytic_sum_over_the_pairs():
    """On the plane z = 0 each pair's Jacobian is [0, 0, 1, y, -x, 0]: the information is their outer
    products over the residual variance, nothing in x, y or about z."""
    fixed = icp_cloud(_plane(noise=0.0, seed=0), "point-to-plane", "small_gicp")  # exact normals
    moving = _plane(seed=1)
    info = plane_information(moving, fixed.points, fixed.normals, np.eye(4), 2.0, fixed.nearest)
    assert np.abs(fixed.normals[:, 2]).min() > 1 - 1e-9  # the plane's own normals
    J = np.zeros((len(moving), 6))
    J[:, 2], J[:, 3], J[:, 4] = 1.0, moving[:, 1], -moving[:, 0]
    expected = J.T @ J / np.mean(moving[:, 2] ** 2)  # the residuals are the heights
    assert np.allclose(info, expected, rtol=1e-6, atol=1e-9 * expected.max())


@pytest.mark.parametrize("backend", ["small_gicp", "open3d"])
def test_a_plane_leaves_x_y_and_yaw_unpinned(backend):
    """ICP of a plane onto itself: the three loose directions of its information are tx, ty and rz
    (small_gicp's own Hessian, or Open3D's pairs in numpy), the three others pinned."""
    fixed, moving = _plane(seed=2), _plane(seed=3)
    result = refine_icp(moving, fixed, np.eye(4), metric="plane-to-plane", backend=backend, **ICP)
    sigmas = np.sqrt(np.diag(np.linalg.inv(result.information)))  # x y z m, rx ry rz rad
    assert min(sigmas[0], sigmas[1]) > 20 * sigmas[2]
    assert sigmas[5] > 20 * max(sigmas[3], sigmas[4])
    sigma, direction = weakest(result.information)
    assert sigma > 20 * sigmas[2] and abs(direction[2]) < 0.05  # the weakest translation lies in the plane


def test_the_information_lives_in_the_moving_frame():
    """The moving cloud is the plane x = 0 of its own frame, carried onto the fixed plane z = 0: the
    translation it cannot tell lies in its own y-z plane, not in the fixed frame's x-y plane."""
    fixed = _plane(seed=4)
    T = np.eye(4)
    T[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]  # moving x -> fixed z
    moving = transform_points(_plane(seed=5), np.linalg.inv(T))  # a plane x = 0 in the moving frame
    result = refine_icp(moving, fixed, T, metric="plane-to-plane", backend="small_gicp", **ICP)
    translation = result.information[:3, :3]
    assert translation[0, 0] > 100 * max(translation[1, 1], translation[2, 2])
    assert abs(weakest(result.information)[1][0]) < 0.01


@pytest.mark.parametrize("backend", ["small_gicp", "open3d"])
def test_a_known_transform_is_recovered_and_sure_in_every_direction(backend):
    """Hills moved by a known transform and registered back: the transform within a few centimetres,
    an information pinning all six directions, and that transform's error well inside its covariance."""
    fixed = _hills(seed=6)
    truth = _transform(2.0, [0.8, -0.5, 0.1])
    moving = transform_points(_hills(seed=7), np.linalg.inv(truth))
    result = refine_icp(moving, fixed, np.eye(4), metric="plane-to-plane", backend=backend, **ICP)
    T, rmse = result  # still unpacks as it always did
    assert np.isfinite(rmse) and np.allclose(T[:3, 3], truth[:3, 3], atol=0.05)
    values = np.linalg.eigvalsh(result.information)
    assert values.min() > 0 and values.max() / values.min() < 1e6
    assert weakest(result.information)[0] < 0.05  # m


def test_both_back_ends_measure_about_the_same_information():
    """small_gicp's Hessian (GICP cost) and the point-to-plane sum in numpy agree on the same pair."""
    fixed = _hills(seed=8)
    moving = transform_points(_hills(seed=9), np.linalg.inv(_transform(1.0, [0.3, 0.2, 0.0])))
    a, b = (
        refine_icp(moving, fixed, np.eye(4), metric="plane-to-plane", backend=k, **ICP).information
        for k in ("small_gicp", "open3d")
    )
    sigmas_a, sigmas_b = (np.sqrt(np.diag(np.linalg.inv(i))) for i in (a, b))
    assert np.all(sigmas_a / sigmas_b > 1 / 4) and np.all(sigmas_a / sigmas_b < 4)


def test_point_to_point_has_no_information():
    fixed = _hills(seed=10)
    moving = _hills(seed=11)
    for backend in ("small_gicp", "open3d"):
        assert refine_icp(moving, fixed, np.eye(4), metric="point-to-point", backend=backend, **ICP).information is None


def test_calibration_scales_and_caps():
    """Scaling by s multiplies every sigma by 1/sqrt(s); the floor holds the surest direction; a direction
    left free stays at the cap, finite."""
    info = np.diag([1e2, 1e4, 1e8, 0.0, 1e6, 1e6])
    out = calibrated(info, 0.25, np.full(6, 1e-3))
    sigmas = np.sqrt(np.diag(np.linalg.inv(out)))
    assert np.allclose(sigmas[:2], np.hypot([0.2, 0.02], 1e-3), rtol=1e-6)
    assert np.isclose(sigmas[2], np.hypot(2e-4, 1e-3), rtol=1e-6)  # the floor adds to the covariance
    assert np.isclose(sigmas[3], MAX_SIGMA, rtol=1e-3)
    assert np.isclose(whitened([np.hypot(0.2, 1e-3), 0, 0, 0, 0, 0], out), 1.0, rtol=1e-6)


def _step(x):
    T = np.eye(4)
    T[0, 3] = x
    return T


@pytest.mark.parametrize(("weights", "expected"), [("hessian", 1.0), ("icp", 4 / 3)])
def test_hessian_weights_believe_the_edge_that_is_sure(weights, expected):
    """Two measurements of one step along x: the odometry says 1 m and is sure along x; an edge back
    says 2 m and is not (it slid along flat ground). With hessian weights the graph follows the sure one;
    with the fixed icp sigmas it weighs them by span alone."""
    sure = np.diag([1e4, 1e4, 1e4, 1e6, 1e6, 1e6])
    unsure = np.diag([1e-2, 1e4, 1e4, 1e6, 1e6, 1e6])
    odometry = OdometryResult(
        indices=np.arange(3),
        poses=np.array([np.eye(4), _step(1.0), _step(1.0)]),
        relative=np.array([_step(1.0), np.eye(4)]),
        n_matches=np.zeros(2, int),
        n_inliers=np.zeros(2, int),
        rmse=np.zeros(2),
        timings={},
        information=[sure, sure],
    )
    extra = [Edge(0, 2, _step(2.0), 0.1, information=unsure)]
    config = Config().with_values(pose_graph={"graph_weights": weights})
    result = build_pose_graph(odometry, extra, [], config).optimize(anchor_pose=np.eye(4), loop_kernel="none")
    assert result.poses[2][0, 3] == pytest.approx(expected, abs=0.01)


def test_the_icp_service_hands_out_calibrated_information():
    """What the run's ICP service returns is the raw information scaled and floored by [pose_graph]."""
    from helpers.slam.registration.icp_service import IcpService

    config = Config().with_values(pose_graph={"information_scale": 0.2, "min_sigma_m": 0.01, "min_sigma_deg": 0.02})
    run = IcpService.from_config(config.registration, pose_graph=config.pose_graph)
    assert run.information_scale == 0.2 and np.array_equal(run.min_sigmas, config.pose_graph.min_sigmas)
    service = IcpService(
        metric="plane-to-plane",
        inlier_distance=ICP["inlier_distance"],
        tolerance=ICP["tolerance"],
        backend="small_gicp",
        information_scale=run.information_scale,
        min_sigmas=run.min_sigmas,
    )
    fixed = _hills(seed=12)
    moving = transform_points(_hills(seed=13), np.linalg.inv(_transform(1.0, [0.4, 0.1, 0.0])))
    raw = refine_icp(moving, fixed, np.eye(4), metric="plane-to-plane", backend="small_gicp", **ICP)
    fit = service.align(moving=moving, fixed=fixed, T_fixed_moving=np.eye(4), max_iterations=ICP["max_iterations"])
    assert np.allclose(fit.T_fixed_moving, raw.T_fixed_moving)
    assert np.allclose(fit.information, calibrated(raw.information, 0.2, run.min_sigmas))
    sigmas = np.sqrt(np.diag(np.linalg.inv(fit.information)))
    assert sigmas[:3].min() >= 0.01 and np.degrees(sigmas[3:]).min() >= 0.02


def _gentle(n=6000, seed=0):
    """Nearly flat ground: 5 cm of relief over 40 m (slopes under a degree), 2 cm of noise."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-20, 20, (n, 2))
    z = 0.05 * np.sin(xy[:, 0] / 5) + 0.05 * np.cos(xy[:, 1] / 4)
    return np.column_stack([xy, z + rng.normal(0, 0.02, n)])


def test_the_plane_source_is_the_point_to_plane_sum_of_the_final_pairs():
    """With information="plane" small_gicp's result carries the point-to-plane information of its own
    final pairs: what plane_information gives at the transform it returns (Open3D's always)."""
    fixed = icp_cloud(_hills(seed=14), "plane-to-plane", "small_gicp")
    moving = icp_cloud(
        transform_points(_hills(seed=15), np.linalg.inv(_transform(1.0, [0.3, -0.2, 0.0]))),
        "plane-to-plane",
        "small_gicp",
    )
    kw = {"metric": "plane-to-plane", "backend": "small_gicp", **ICP}
    result = refine_icp(moving, fixed, np.eye(4), information="plane", **kw)
    expected = plane_information(
        moving.points, fixed.points, fixed.normals, result.T_fixed_moving, ICP["inlier_distance"], fixed.nearest
    )
    assert np.allclose(result.information, expected, rtol=1e-9)
    assert not np.allclose(result.information, refine_icp(moving, fixed, np.eye(4), **kw).information, rtol=0.1)


def test_over_nearly_flat_ground_the_plane_source_knows_it_does_not_know():
    """Generalized ICP's plane covariances keep a little weight along the ground, so its Hessian stays
    sure of the along-ground position that slopes under a degree barely pin; the point-to-plane
    information of the same pairs is several times looser there, and as sure of height and tilt."""
    fixed, moving = _gentle(seed=1), _gentle(seed=2)
    kw = {"metric": "plane-to-plane", "backend": "small_gicp", **ICP}
    gicp, plane = (
        np.sqrt(np.diag(np.linalg.inv(refine_icp(moving, fixed, np.eye(4), information=s, **kw).information)))
        for s in ("gicp", "plane")
    )
    assert np.all(plane[:2] > 2 * gicp[:2])  # x, y: loose
    assert np.allclose(plane[2:5], gicp[2:5], rtol=0.25)  # z, roll, pitch: pinned alike


def test_an_unknown_information_source_is_refused():
    with pytest.raises(SlamError, match="information"):
        Config().with_values(pose_graph={"information": "lidar"})
    with pytest.raises(SlamError, match="information source"):
        refine_icp(
            _hills(seed=16),
            _hills(seed=17),
            np.eye(4),
            metric="plane-to-plane",
            backend="small_gicp",
            information="lidar",
            **ICP,
        )


def test_a_blend_keeps_the_guess_where_the_registration_knows_nothing():
    """Over flat ground ICP pins height and tilt, not a slide: the blend of its
    answer with the last motion takes the registration's height and the
    guess's position along the ground, and tends to either one as the other
    knows nothing."""
    guess = np.eye(4)
    guess[:3, 3] = [2.0, 0.0, 0.0]
    measured = np.eye(4)
    measured[:3, 3] = [1.5, 0.3, 0.1]  # slid back and sideways, and 10 cm higher
    sure, unsure = 1e12, 1e-12
    flat = np.diag([unsure, unsure, sure, sure, sure, unsure])  # x y z rx ry rz
    prior = np.array([0.04] * 3 + [0.01] * 3)
    out = blended(guess, measured, flat, prior)
    np.testing.assert_allclose(out[:3, 3], [2.0, 0.0, 0.1], atol=1e-6)
    np.testing.assert_allclose(blended(guess, measured, np.eye(6) * sure, prior), measured, atol=1e-6)
    np.testing.assert_allclose(blended(guess, measured, np.eye(6) * unsure, prior), guess, atol=1e-6)
    # Equally sure: halfway (to first order in the offset).
    even = np.diag(1.0 / prior**2)
    np.testing.assert_allclose(blended(guess, measured, even, prior)[:3, 3], [1.75, 0.15, 0.05], atol=1e-3)
