"""Robust rigid fit (MSAC) and ICP refinement, on synthetic matches and on real scans."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.slam.registration.icp import icp_cloud, icp_rmse, refine_icp
from helpers.slam.registration.msac import estimate_rigid_msac, kabsch, trials_needed

ICP = {"max_iterations": 30, "tolerance": 1e-6}  # a tight tolerance: these tests want ICP converged
BACKENDS = ["small_gicp", "open3d"]
WAYPOINT_ROWS = slice(60, 110)  # a straight stretch and the start of a 90-degree turn of the default loop


def keywords(metric, backend, **changed):
    """refine_icp's settings: an inlier distance of 3 m and :data:`ICP`, with ``changed`` applied."""
    return {"metric": metric, "backend": backend, "inlier_distance": 3.0, **ICP, **changed}


@pytest.fixture(scope="module")
def flight(flight_over):
    return flight_over(WAYPOINT_ROWS)


def _transform(yaw_deg, translation):
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    out[:3, 3] = translation
    return out


def _errors(estimate, truth):
    error = np.linalg.inv(truth) @ estimate
    return np.linalg.norm(error[:, 3][:3]), np.degrees(Rotation.from_matrix(error[:3, :3]).magnitude())


def _displacement(estimate, truth, points):
    """RMS distance (m) between the points moved by ``estimate`` and by ``truth``."""
    return float(np.sqrt(np.mean(np.sum((_apply(estimate, points) - _apply(truth, points)) ** 2, axis=1))))


def _apply(T, points):
    return points @ T[:3, :3].T + T[:3, 3]


def _matches_with_outliers(seed=3, n=1000, outlier_fraction=0.8):
    rng = np.random.default_rng(seed)
    moving = rng.uniform([-30, -140, -620], [30, 140, -570], (n, 3))
    truth = _transform(30.0, [10.0, -4.0, 0.5])
    fixed = _apply(truth, moving) + rng.normal(0, 0.05, (n, 3))
    outliers = rng.random(n) < outlier_fraction
    fixed[outliers] = rng.uniform([-30, -140, -620], [30, 140, -570], (outliers.sum(), 3))
    return moving, fixed, truth, outliers


def test_kabsch_recovers_a_batch_of_transforms():
    rng = np.random.default_rng(0)
    truths = np.array([_transform(a, t) for a, t in zip([0, 10, -30], rng.normal(0, 5, (3, 3)), strict=True)])
    moving = rng.normal(0, 10, (3, 20, 3))
    fixed = np.einsum("hij,hkj->hki", truths[:, :3, :3], moving) + truths[:, None, :3, 3]
    np.testing.assert_allclose(kabsch(moving, fixed), truths, atol=1e-9)


def test_msac_survives_80_percent_outliers():
    moving, fixed, truth, outliers = _matches_with_outliers()
    assert outliers.mean() > 0.75
    T, inliers = estimate_rigid_msac(moving, fixed, max_distance=1.0, max_trials=3000, seed=0)
    # The points lie 600 m below the sensor origin: judge the fit where the points are.
    assert _displacement(T, truth, moving) < 0.05
    assert _errors(T, truth)[1] < 0.05
    assert (inliers == ~outliers).mean() > 0.99


def test_msac_same_seed_same_answer_different_seed_still_right():
    moving, fixed, truth, _ = _matches_with_outliers(seed=5)
    first, mask = estimate_rigid_msac(moving, fixed, 1.0, 3000, seed=7)
    again, mask_again = estimate_rigid_msac(moving, fixed, 1.0, 3000, seed=7)
    np.testing.assert_array_equal(first, again)
    np.testing.assert_array_equal(mask, mask_again)
    other, _ = estimate_rigid_msac(moving, fixed, 1.0, 3000, seed=8)
    assert _displacement(other, truth, moving) < 0.05


def test_msac_answer_is_the_least_squares_fit_of_its_inliers_whatever_the_seed():
    """Local optimisation ends at a fixed point: the least-squares motion of
    the inliers it keeps. Every seed finds the same inlier set here, so every
    seed gives the same transform, to rounding; so does shuffling the matches."""
    moving, fixed, _, outliers = _matches_with_outliers(seed=5)
    answers = []
    for seed in range(6):
        T, inliers = estimate_rigid_msac(moving, fixed, 1.0, 3000, seed=seed)
        np.testing.assert_array_equal(inliers, ~outliers)
        np.testing.assert_allclose(T, kabsch(moving[inliers], fixed[inliers]), atol=1e-9)
        answers.append(T)
    order = np.random.default_rng(0).permutation(len(moving))
    shuffled, _ = estimate_rigid_msac(moving[order], fixed[order], 1.0, 3000, seed=0)
    np.testing.assert_allclose(np.array(answers), np.broadcast_to(shuffled, (6, 4, 4)), atol=1e-9)


@pytest.mark.parametrize(
    ("inlier_ratio", "confidence", "expected"),
    [(0.5, 0.99, 35), (0.1, 0.99, 3000), (0.3, 0.99, 169), (0.3, 0.9, 85), (1.0, 0.99, 1), (0.0, 0.99, 3000)],
)
def test_trial_count_follows_the_inlier_ratio(inlier_ratio, confidence, expected):
    """log(1 - p) / log(1 - w^3), rounded up and capped at the 3000 trials allowed:
    w = 0.5 needs ceil(ln 0.01 / ln 0.875) = 35 samples for 99 %."""
    assert trials_needed(inlier_ratio, confidence, 3000) == expected


def test_msac_with_many_inliers_stops_early_with_the_same_answer():
    """Half the matches are inliers: 35 samples suffice for 99 %, so a cap of
    3000 and a cap of 256 (one chunk) draw the same first chunk and stop there."""
    moving, fixed, truth, _ = _matches_with_outliers(seed=9, outlier_fraction=0.5)
    capped, _ = estimate_rigid_msac(moving, fixed, 1.0, 256, seed=0)
    full, _ = estimate_rigid_msac(moving, fixed, 1.0, 3000, seed=0)
    np.testing.assert_array_equal(full, capped)
    assert _displacement(full, truth, moving) < 0.05
    with pytest.raises(SlamError, match="confidence"):
        estimate_rigid_msac(moving, fixed, 1.0, 3000, seed=0, confidence=1.0)


def test_msac_bit_identical_across_thread_counts(thread_outputs):
    script = (
        "import numpy as np, sys; sys.path.insert(0, '.'); from tests.test_registration import _matches_with_outliers;"
        "from helpers.slam.registration.msac import estimate_rigid_msac;"
        "m, f, _, _ = _matches_with_outliers(seed=11);"
        "T, _ = estimate_rigid_msac(m, f, 1.0, 3000, 0); print(T.tobytes().hex())"
    )
    outputs = thread_outputs(script)
    assert len(outputs) == 1


def test_msac_refuses_too_few_matches_and_pure_noise():
    with pytest.raises(SlamError, match="at least 3 matches"):
        estimate_rigid_msac(np.zeros((2, 3)), np.zeros((2, 3)), 1.0, 100, 0)
    rng = np.random.default_rng(2)
    with pytest.raises(SlamError, match="enough matches"):
        estimate_rigid_msac(rng.uniform(0, 1000, (40, 3)), rng.uniform(0, 1000, (40, 3)), 0.01, 200, 0)
    with pytest.raises(SlamError, match="NaN"):
        estimate_rigid_msac(np.full((5, 3), np.nan), np.zeros((5, 3)), 1.0, 100, 0)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("metric", ["point-to-point", "point-to-plane", "plane-to-plane"])
def test_icp_metrics_agree_on_an_easy_case(flight, metric, backend):
    scan = flight.scans[10]
    truth = _transform(1.0, [0.8, -0.5, 0.2])
    T, rmse = refine_icp(scan, _apply(truth, scan), np.eye(4), **keywords(metric, backend))
    dt, dr = _errors(T, truth)
    assert dt < 0.05 and dr < 0.02
    assert rmse < 0.05  # the same points: the residual vanishes whatever the metric


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("metric", ["point-to-point", "point-to-plane", "plane-to-plane"])
def test_icp_on_prepared_clouds_equals_icp_on_bare_points(flight, metric, backend):
    # Normals and covariances made once (what the odometry reuses) give what ICP computes itself.
    moving, fixed = flight.scans[13], flight.scans[10]
    init = np.linalg.inv(flight.poses[10]) @ flight.poses[13] @ _transform(0.3, [0.5, -0.4, 0.1])
    T_bare, rmse_bare = refine_icp(moving, fixed, init, **keywords(metric, backend))
    ready = icp_cloud(moving, metric, backend), icp_cloud(fixed, metric, backend)
    T_ready, rmse_ready = refine_icp(*ready, init, **keywords(metric, backend))
    np.testing.assert_allclose(T_ready, T_bare, atol=1e-9)
    assert rmse_ready == pytest.approx(rmse_bare, abs=1e-9)
    # The RMSE reported is the point-to-point RMSE of the returned transform, whatever the back end.
    assert rmse_ready == pytest.approx(icp_rmse(moving, fixed, T_ready, 3.0), abs=1e-9)


@pytest.mark.parametrize("metric", ["point-to-plane", "plane-to-plane"])
def test_both_icp_back_ends_land_on_the_true_motion(flight, metric):
    """small_gicp and Open3D, from the same guess 0.6 m and 0.3 deg off, both end within 20 cm of the truth
    (RMS over the scan's points; raw scans, their rows 2 m apart, let point-to-plane slide a little)."""
    moving, fixed = flight.scans[13], flight.scans[10]
    truth = np.linalg.inv(flight.poses[10]) @ flight.poses[13]
    init = truth @ _transform(0.3, [0.5, -0.3, 0.1])
    ends = [refine_icp(moving, fixed, init, **keywords(metric, backend, tolerance=1e-3))[0] for backend in BACKENDS]
    errors = [_displacement(T, truth, moving) for T in ends]
    assert max(errors) < 0.2, errors


def test_icp_tolerance_in_metres_stops_early_but_lands_nearby(flight):
    moving, fixed = (icp_cloud(flight.scans[k], "plane-to-plane", "open3d") for k in (13, 10))
    truth = np.linalg.inv(flight.poses[10]) @ flight.poses[13]
    init = truth @ _transform(0.5, [1.0, -0.8, 0.2])
    T_tight, _ = refine_icp(moving, fixed, init, **keywords("plane-to-plane", "open3d", tolerance=1e-6))
    T_loose, _ = refine_icp(moving, fixed, init, **keywords("plane-to-plane", "open3d", tolerance=1e-3))
    assert _displacement(T_loose, T_tight, flight.scans[13]) < 0.02


@pytest.mark.parametrize("pair", [(13, 10), (33, 30), (40, 37)])
def test_the_default_tolerance_stops_within_a_millimetre_or_two_of_convergence(flight, pair):
    # small_gicp stops once a step moves no point more than the tolerance (1 cm); Gauss-Newton closes in fast
    # near the answer, so what is left is far smaller: measured, at most 0.6 mm from the 1e-6 answer here
    moving, fixed = (icp_cloud(flight.scans[k], "plane-to-plane", "small_gicp") for k in pair)
    truth = np.linalg.inv(flight.poses[pair[1]]) @ flight.poses[pair[0]]
    init = truth @ _transform(0.5, [1.0, -0.8, 0.2])
    tolerance = Config().registration.icp_tolerance
    T_tight, _ = refine_icp(moving, fixed, init, **keywords("plane-to-plane", "small_gicp", tolerance=1e-6))
    T_default, _ = refine_icp(moving, fixed, init, **keywords("plane-to-plane", "small_gicp", tolerance=tolerance))
    assert _displacement(T_default, T_tight, flight.scans[pair[0]]) < 2e-3
    assert _displacement(T_default, truth, flight.scans[pair[0]]) < 0.05


def test_icp_refuses_a_cloud_prepared_for_another_metric(flight):
    scan = flight.scans[0]
    with pytest.raises(SlamError, match="prepared for point-to-point"):
        refine_icp(
            icp_cloud(scan, "point-to-point", "small_gicp"), scan, np.eye(4), **keywords("plane-to-plane", "small_gicp")
        )
    with pytest.raises(SlamError, match="tolerance"):
        refine_icp(scan, scan, np.eye(4), **keywords("point-to-point", "small_gicp", tolerance=-1.0))


def test_icp_refuses_bad_input(flight):
    scan = flight.scans[0]
    with pytest.raises(SlamError, match="metric"):
        refine_icp(scan, scan, np.eye(4), **keywords("plane-to-point", "small_gicp"))
    with pytest.raises(SlamError, match="4 x 4"):
        refine_icp(scan, scan, np.eye(3), **keywords("point-to-point", "small_gicp"))
    with pytest.raises(SlamError, match="points"):
        refine_icp(np.zeros((0, 3)), scan, np.eye(4), **keywords("point-to-point", "small_gicp"))
    with pytest.raises(SlamError, match="unknown ICP back end 'pcl'"):
        refine_icp(scan, scan, np.eye(4), **keywords("point-to-point", "pcl"))
    open3d_cloud = icp_cloud(scan, "plane-to-plane", "open3d")
    with pytest.raises(SlamError, match="prepared for plane-to-plane ICP on open3d"):
        refine_icp(open3d_cloud, scan, np.eye(4), **keywords("plane-to-plane", "small_gicp"))


@pytest.mark.parametrize(
    ("yaw", "shift"), [(30.0, [10.0, 0.0, 0.0]), (-20.0, [-6.0, 8.0, 1.0]), (5.0, [0.0, -10.0, 0.0])]
)
def test_register_pair_recovers_a_known_transform_on_real_scans(flight, yaw, shift):
    from helpers.slam.odometry import register_pair

    extra = _transform(yaw, shift)
    i, j = 20, 23  # two accepted scans 6 m apart
    truth = extra @ np.linalg.inv(flight.poses[i]) @ flight.poses[j]  # scan j -> moved frame of scan i
    result = register_pair(flight.scans[j], _apply(extra, flight.scans[i]))
    assert result.fallback is None
    dt, dr = _errors(result.T_fine, truth)
    assert dt < 0.15 and dr < 0.1, (dt, dr)
    coarse_dt, coarse_dr = _errors(result.T_coarse, truth)
    assert coarse_dt < 3.0 and coarse_dr < 1.0
    assert result.inliers.sum() >= 20


def test_pairing_says_how_well_the_pairs_pin_a_translation():
    """A plane cannot pin a slide along it (constraint about 0); three faces
    that look three ways pin all of it; the overlap is the share paired."""
    from helpers.slam.registration.icp import pairing

    rng = np.random.default_rng(8)
    plane = np.column_stack([rng.uniform(-20, 20, (3000, 2)), rng.normal(0, 0.01, 3000)])
    flat = icp_cloud(plane, "plane-to-plane", "small_gicp")
    share, constraint = pairing(flat, flat, _transform(0.0, [1.0, 0.0, 0.0]), 3.0)
    assert share == 1.0 and constraint < 1e-3
    a, b = rng.uniform(0, 10, (2, 1000))
    corner = np.concatenate([np.column_stack(c) for c in ((a, b, 0 * a), (a, 0 * a, b), (0 * a, a, b))])
    box = icp_cloud(corner, "plane-to-plane", "small_gicp")
    share, constraint = pairing(box, box, np.eye(4), 3.0)
    assert share == 1.0 and constraint > 0.5
    far = pairing(box, box, _transform(0.0, [50.0, 0.0, 0.0]), 3.0)
    assert far == (0.0, 0.0)  # nothing paired


@pytest.mark.parametrize(("yaw", "shift"), [(30.0, [10.0, 0.0, 0.0]), (-20.0, [-6.0, 8.0, 1.0])])
def test_register_pair_with_the_yaw_and_translation_fit_recovers_a_known_transform(flight, yaw, shift):
    """``robust_fit = "msac4"`` through the registration entry point: the coarse fit is a pure yaw and
    translation (no tilt at all, so the 4-DoF fit ran), near the truth, and ICP adds the tilt."""
    from helpers.slam.odometry import register_pair

    config = Config().with_values(registration={"robust_fit": "msac4"})
    extra = _transform(yaw, shift)
    i, j = 20, 23  # two accepted scans 6 m apart
    truth = extra @ np.linalg.inv(flight.poses[i]) @ flight.poses[j]
    result = register_pair(flight.scans[j], _apply(extra, flight.scans[i]), config)
    assert result.fallback is None
    np.testing.assert_array_equal(result.T_coarse[2, :3], [0.0, 0.0, 1.0])  # roll = pitch = 0: the 4-DoF fit
    coarse_dt, coarse_dr = _errors(result.T_coarse, truth)
    assert coarse_dt < 1.0 and coarse_dr < 0.5, (coarse_dt, coarse_dr)
    dt, dr = _errors(result.T_fine, truth)
    assert dt < 0.15 and dr < 0.1, (dt, dr)
    assert result.inliers.sum() >= 20


def test_robust_fit_runs_the_fit_the_configuration_names():
    from helpers.config.tables import RegistrationConfig
    from helpers.slam.registration.msac_yaw import estimate_yaw_msac
    from helpers.slam.registration.robust_fit import robust_fit

    moving, fixed, truth, outliers = _matches_with_outliers(outlier_fraction=0.5)
    rigid = robust_fit(moving, fixed, RegistrationConfig(max_distance=0.3, robust_fit="msac"))
    expected = estimate_rigid_msac(moving, fixed, 0.3, 3000)
    np.testing.assert_array_equal(rigid[0], expected[0])
    yaw = robust_fit(moving, fixed, RegistrationConfig(max_distance=0.3, robust_fit="msac4", seed=2))
    np.testing.assert_array_equal(yaw[0], estimate_yaw_msac(moving, fixed, 0.3, 344, seed=2)[0])
    assert _displacement(yaw[0], truth, moving) < 0.05  # the truth is a pure yaw and translation
    assert np.mean(yaw[1][~outliers]) > 0.95 and np.mean(yaw[1][outliers]) < 0.05


def test_the_yaw_fit_s_trial_cap_gives_up_at_the_rigid_fit_s_inlier_ratio():
    from helpers.slam.registration.msac import equivalent_trials

    # 3000 samples of 3 reach 99 % at w^3 = 1 - 0.01^(1/3000), w = 0.1154; samples of 2 need 344 there.
    assert equivalent_trials(3000, 0.99, 2) == 344
    assert equivalent_trials(3000, 0.99, 3) == 3000
    for cap, confidence in [(3000, 0.99), (500, 0.9), (50_000, 0.999)]:
        pairs = equivalent_trials(cap, confidence, 2)
        for w in np.linspace(0.02, 0.9, 89):
            triples_needed = trials_needed(w, confidence, 10**9, 3)
            pairs_needed = trials_needed(w, confidence, 10**9, 2)
            if triples_needed < 0.98 * cap:  # the rigid fit would stop early: so does the yaw fit
                assert pairs_needed <= pairs
            if triples_needed > 1.02 * cap:  # the rigid fit hits its cap: so does the yaw fit
                assert pairs_needed >= pairs


def test_the_configuration_refuses_an_unknown_robust_fit():
    from helpers.config.files import config_from_dict
    from helpers.config.tables import Config, RegistrationConfig

    assert RegistrationConfig().robust_fit == "msac4"  # ours: yaw and translation
    assert Config.reference().registration.robust_fit == "msac"  # the reference's rigid fit one call away
    with pytest.raises(SlamError, match=r"\[registration\] robust_fit must be one of msac, msac4, got 'ransac'"):
        Config().with_values(registration={"robust_fit": "ransac"})
    with pytest.raises(SlamError, match="robust_fit must be one of msac, msac4"):
        config_from_dict({"registration": {"robust_fit": "MSAC4"}})
    assert config_from_dict({"registration": {"robust_fit": "msac4"}}).registration.robust_fit == "msac4"


@pytest.mark.parametrize("metric", ["point-to-plane", "plane-to-plane"])
def test_small_gicp_gives_the_same_bits_every_time(flight, metric, monkeypatch):
    # On one machine the same pair must register to the same bits, its information too, even with the clouds
    # prepared on two threads: a long flight's chain of steps would carry any difference in the last bit on.
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    moving, fixed = flight.scans[13], flight.scans[10]
    init = np.linalg.inv(flight.poses[10]) @ flight.poses[13] @ _transform(0.3, [0.5, -0.4, 0.1])
    runs = []
    for _ in range(12):
        ready = icp_cloud(moving, metric, "small_gicp"), icp_cloud(fixed, metric, "small_gicp")
        result = refine_icp(*ready, init, **keywords(metric, "small_gicp", tolerance=1e-9))
        runs.append(np.concatenate([result.T_fixed_moving.ravel(), result.information.ravel(), [result.rmse]]))
    assert all(np.array_equal(run, runs[0]) for run in runs)
