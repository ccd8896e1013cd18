"""ATE and RPE against analytic cases."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from helpers.errors import SlamError
from helpers.quality.metrics import ate, rpe


def _circle(n=12, radius=10.0):
    """Poses on a circle, each heading along the tangent (as GTSAM's circlePose3)."""
    poses = np.tile(np.eye(4), (n, 1, 1))
    theta = np.linspace(0, 2 * np.pi, n, endpoint=False)
    poses[:, :3, :3] = Rotation.from_euler("z", (theta + np.pi / 2)[:, None]).as_matrix()
    poses[:, 0, 3], poses[:, 1, 3] = radius * np.cos(theta), radius * np.sin(theta)
    return poses


def test_identical_trajectories_have_no_error():
    gt = _circle()
    assert ate(gt, gt).rmse == 0.0
    result = rpe(gt, gt, delta=2)
    assert result.translation.max < 1e-12 and result.rotation.max < 1e-6
    assert result.translation.unit == "m" and result.rotation.unit == "deg"


def test_ate_of_a_constant_offset_is_the_offset():
    gt = _circle()
    est = gt.copy()
    est[:, :3, 3] += [3.0, 4.0, 0.0]
    stats = ate(est, gt)
    np.testing.assert_allclose(stats.errors, 5.0)
    assert stats.rmse == pytest.approx(5.0) and stats.unit == "m"
    # A constant offset of every position in the map frame is no relative motion error in translation...
    assert rpe(est, gt).rotation.max < 1e-6


def test_rpe_sees_one_bad_step_once_and_ate_sees_it_forever():
    gt = np.tile(np.eye(4), (6, 1, 1))
    gt[:, 0, 3] = np.arange(6) * 2.0  # straight line, 2 m steps
    bump = np.eye(4)
    bump[:3, :3] = Rotation.from_euler("z", 1.0, degrees=True).as_matrix()
    bump[:3, 3] = [0.3, 0.4, 0.0]
    est = [gt[0]]
    for k in range(1, 6):
        step = np.linalg.inv(gt[k - 1]) @ gt[k]
        est.append(est[-1] @ (step @ bump if k == 3 else step))
    est = np.array(est)
    result = rpe(est, gt, delta=1)
    np.testing.assert_allclose(result.translation.errors, [0, 0, 0.5, 0, 0], atol=1e-12)
    np.testing.assert_allclose(result.rotation.errors, [0, 0, 1.0, 0, 0], atol=1e-6)
    assert result.translation.rmse == pytest.approx(0.5 / np.sqrt(5))
    errors = ate(est, gt).errors
    np.testing.assert_allclose(errors[:3], 0.0, atol=1e-12)
    assert np.all(errors[3:] >= 0.5 - 1e-9)


def test_metrics_refuse_bad_input():
    gt = _circle()
    with pytest.raises(SlamError, match="differ in length"):
        ate(gt[:5], gt)
    with pytest.raises(SlamError, match="N x 4 x 4"):
        ate(np.zeros((3, 3, 3)), np.zeros((3, 3, 3)))
    with pytest.raises(SlamError, match="step"):
        rpe(gt, gt, delta=0)
    with pytest.raises(SlamError, match="needs more"):
        rpe(gt, gt, delta=12)
    bad = gt.copy()
    bad[2, 0, 3] = np.nan
    with pytest.raises(SlamError, match="NaN"):
        ate(bad, gt)


@pytest.mark.parametrize("delta", [1, 3])
def test_ate_and_rpe_agree_with_evo(delta):
    """evo's APE (translation part, no alignment) and RPE (every pair ``delta``
    frames apart) give the same per-pose errors on a noisy ring."""
    metrics = pytest.importorskip("evo.core.metrics", reason="evo (a test dependency) is not installed")
    from evo.core.trajectory import PosePath3D

    gt = _circle(n=40)
    rng = np.random.default_rng(3)
    est = gt.copy()
    est[:, :3, 3] += rng.normal(scale=0.2, size=(40, 3))
    est[:, :3, :3] = Rotation.from_rotvec(rng.normal(scale=0.02, size=(40, 3))).as_matrix() @ est[:, :3, :3]
    pair = (PosePath3D(poses_se3=list(gt)), PosePath3D(poses_se3=list(est)))

    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data(pair)
    np.testing.assert_allclose(ate(est, gt).errors, ape.error, atol=1e-9)
    assert ate(est, gt).rmse == pytest.approx(ape.get_statistic(metrics.StatisticsType.rmse), rel=1e-9)

    ours = rpe(est, gt, delta)
    for relation, errors in (
        (metrics.PoseRelation.translation_part, ours.translation.errors),
        (metrics.PoseRelation.rotation_angle_deg, ours.rotation.errors),
    ):
        theirs = metrics.RPE(relation, delta=delta, delta_unit=metrics.Unit.frames, all_pairs=True)
        theirs.process_data(pair)
        np.testing.assert_allclose(errors, theirs.error, atol=1e-6)
