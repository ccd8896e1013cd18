"""Map errors and the summary table against analytic cases."""

from types import SimpleNamespace

import numpy as np
import pytest

from helpers.errors import SlamError
from helpers.quality import evaluation
from helpers.quality.evaluation import map_errors, summary_table


def _plane(step=0.5, size=20.0):
    """A square grid of points on the plane z = 0."""
    u = np.arange(0.0, size + step / 2, step)
    x, y = np.meshgrid(u, u)
    return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])


def test_a_cloud_against_itself_has_no_error():
    plane = _plane()
    stats = map_errors(plane, plane)
    assert stats.errors.shape == (len(plane),)
    assert stats.max == 0.0 and stats.mean == 0.0 and stats.p95 == 0.0 and stats.unit == "m"


def test_a_plane_lifted_by_an_offset_is_that_far_away():
    plane = _plane()
    stats = map_errors(plane + [0.0, 0.0, 0.7], plane)
    np.testing.assert_allclose(stats.errors, 0.7)
    assert stats.mean == pytest.approx(0.7) and stats.median == pytest.approx(0.7) and stats.p95 == pytest.approx(0.7)


def test_an_in_plane_shift_is_measured_to_the_nearest_grid_point():
    plane = _plane(step=1.0)
    shifted = plane[(plane[:, 0] < 19) & (plane[:, 1] < 19)] + [0.3, 0.4, 0.0]  # stay inside the grid
    np.testing.assert_allclose(map_errors(shifted, plane).errors, 0.5)


def test_statistics_of_known_distances():
    truth = np.zeros((1, 3))
    estimated = np.column_stack([np.arange(1.0, 101.0), np.zeros(100), np.zeros(100)])  # 1 .. 100 m away
    stats = map_errors(estimated, truth)
    assert stats.mean == pytest.approx(50.5) and stats.median == pytest.approx(50.5)
    assert stats.p95 == pytest.approx(np.percentile(np.arange(1.0, 101.0), 95))
    assert "median 50.500" in str(stats)


def test_map_errors_refuse_bad_input():
    with pytest.raises(SlamError, match="estimated map"):
        map_errors(np.zeros((4, 2)), _plane())
    with pytest.raises(SlamError, match="ground-truth map"):
        map_errors(_plane(), np.empty((0, 3)))
    with pytest.raises(SlamError, match="NaN"):
        map_errors(np.full((2, 3), np.nan), _plane())


def _fake_run(offset, monkeypatch):
    """A dataset and a result, just the attributes the summary table reads
    (their metrics are given, not computed)."""
    truth = _plane()
    metrics = {
        "ate_rmse_odometry_m": 2.0,
        "ate_rmse_optimized_m": 0.5,
        "rpe_trans_1_m": 0.05,
        "rpe_rot_1_deg": 0.1,
        "rpe_trans_10_m": 0.3,
        "rpe_rot_10_deg": 0.4,
        "n_loop_closures": 7,
        "n_false_loop_closures": 0,
    }
    dataset = SimpleNamespace(map_points=truth)
    result = SimpleNamespace(map_points=truth + [0.0, 0.0, offset])
    monkeypatch.setattr(evaluation, "run_metrics", lambda dataset, result: metrics)
    return dataset, result


def test_summary_table_has_every_measure_with_its_unit(monkeypatch):
    rows = summary_table(*_fake_run(0.25, monkeypatch))
    table = {name: (value, unit) for name, value, unit in rows}
    assert table["ATE RMSE, optimised"] == (0.5, "m")
    assert table["RPE rotation, 10 steps"] == (0.4, "deg")
    assert table["loop closures accepted"] == (7, "count")
    for name in ("map error, mean", "map error, median", "map error, 95th percentile"):
        assert table[name][0] == pytest.approx(0.25) and table[name][1] == "m"
    assert len(rows) == 11


def test_summary_table_reuses_a_given_map_error(monkeypatch):
    dataset, result = _fake_run(0.25, monkeypatch)
    given = map_errors(result.map_points, dataset.map_points + [0.0, 0.0, 1.0])  # 0.75 m, not 0.25
    table = {name: value for name, value, _ in summary_table(dataset, result, given)}
    assert table["map error, median"] == pytest.approx(0.75)
