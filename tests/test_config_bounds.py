"""Every configuration value has a lower and an upper bound (issue 19): a
value a run could not compute with, or that would end it after minutes of
work, is refused when the file is read; nothing non-finite reaches the
scans or metrics.json."""

import dataclasses
import json
import math
import time

import numpy as np
import pytest

from helpers.__main__ import main
from helpers.config.bounds import MAX_LENGTH, MAX_RAYS_PER_SCAN, angle_count
from helpers.config.files import config_from_dict, load_config
from helpers.config.tables import STAGE_TABLES, Config, SensorConfig
from helpers.errors import SlamError
from helpers.slam.flight_fit import Flight, fit_to_flight
from helpers.slam.graph.factors import constant_velocity_sigmas
from helpers.slam.graph.optimizer import information_from_sigmas

# The cases of the issue: each was accepted and then aborted a run, or gave NaN and inf with exit 0.
ISSUE_CASES = [
    ("[loop_closure]\nsub_map_thresh = 0\n", "sub_map_thresh must be at least 1"),
    ("[loop_closure]\nloop_closure_search_radius = 1e308\n", "loop_closure_search_radius must be"),
    ("[loop_closure]\nloop_search_growth = 1e308\n", "loop_search_growth must be"),
    ("[loop_closure]\nloop_search_growth = 5\n", "loop_search_growth must be"),
    ("[sensor]\nelevation = [0.0, 0.0, 0.2]\n", "elevation must hold at least two angles"),
    ("[sensor]\nazimuth = [1.0, 1.1, 0.2]\n", "azimuth must hold at least two angles"),
    ("[registration]\ninlier_distance = 1e308\n", "inlier_distance must be"),
    ("[registration]\nmax_distance = 1e308\n", "max_distance must be"),
    ("[sensor]\nrange_noise = 1e300\n", "range_noise must be zero or a positive number of metres up to max_range"),
    ("[map]\nalign_grid_step = 1e-300\n", "align_grid_step must be a positive number of metres from 0.01"),
    ("[pose_graph]\nedge_sigma_m = 1e-300\n", "edge_sigma_m must be a positive number of metres from 1e-06"),
]


@pytest.mark.parametrize(("text", "message"), ISSUE_CASES)
def test_values_that_cannot_be_computed_are_refused_when_read(tmp_path, text, message):
    path = tmp_path / "config.toml"
    path.write_text(text)
    with pytest.raises(SlamError, match=message):
        load_config(path)


def test_a_refused_value_ends_in_one_error_line_before_any_work(tmp_path, capsys):
    path = tmp_path / "config.toml"
    path.write_text("[loop_closure]\nsub_map_thresh = 0\n")
    start = time.perf_counter()
    code = main(["run", "--config", str(path), "--out", str(tmp_path / "out")])
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), lines
    assert time.perf_counter() - start < 5 and not (tmp_path / "out").exists()


# Every key at extreme values --------------------------------------------------

EXTREMES = ["0", "-1", "1", "1e308", "-1e308", "1e-300", "nan", "inf", "-inf", "'x'", "[1, 2]", "true", "10_000_000"]
ANGLE_EXTREMES = ["[0, 0, 0]", "[-13, 13, 1e-300]", "[-88, 88, 1e-3]", "[-1e308, 1e308, 1]", "[nan, 1, 1]", "[1, 2]"]
ANGLE_EXTREMES += ["[-13, 13, 1e308]", "[0, 0.1, 0.2]", "[-1, 1, 2]", "[-13, 13, 'x']"]
KEYS = [(table, f.name) for table in STAGE_TABLES for f in dataclasses.fields(getattr(Config(), table))]
SEEDS = {("sensor", "seed"), ("registration", "seed")}  # any non-negative 64-bit integer is a seed


def _cases():
    for table, key in KEYS:
        values = ANGLE_EXTREMES if key in ("azimuth", "elevation") else EXTREMES
        for value in values:
            yield pytest.param(table, key, value, id=f"{table}.{key}={value}")


def _computable(config: Config) -> None:
    """What a run computes from the values, done here: it must all be finite."""
    for table in STAGE_TABLES:
        for name, value in dataclasses.asdict(getattr(config, table)).items():
            for v in np.ravel(value) if not isinstance(value, str) else []:
                assert math.isfinite(v), (table, name, v)
                assert math.isfinite(float(v) ** 2), (table, name, v)  # squared distances, Python floats
    sensor = config.sensor
    assert 2 <= angle_count(*sensor.azimuth) and 2 <= angle_count(*sensor.elevation)
    assert sensor.rays_per_scan <= MAX_RAYS_PER_SCAN
    assert np.isfinite(np.float32(sensor.max_range) + np.float32(8) * np.float32(sensor.range_noise))  # float32 rays
    graph = config.pose_graph
    for steps in (1, graph.edges_back):
        assert np.isfinite(information_from_sigmas(graph.edge_sigmas * steps)).all()
    for step in (1e-3, MAX_LENGTH):  # the motion factor's sigmas, between nodes from 1 mm to 1 km apart
        angular = math.radians(graph.motion_angular_acceleration)
        sigmas = constant_velocity_sigmas(step, graph.motion_speed, graph.motion_acceleration, angular)
        assert np.isfinite(information_from_sigmas(sigmas)).all()
    loops = config.loop_closure
    assert loops.sub_map_thresh >= 1
    flown = 1e6 * 1e3  # a flight of the most scans, a kilometre apart
    assert math.isfinite(loops.loop_closure_search_radius + loops.loop_search_growth * flown)
    assert 0 < config.features.grid_step and 0 < config.map.align_grid_step


@pytest.mark.parametrize(("table", "key", "value"), list(_cases()))
def test_every_key_at_an_extreme_value_is_refused_or_computable(tmp_path, table, key, value):
    path = tmp_path / "config.toml"
    path.write_text(f"[{table}]\n{key} = {value}\n")
    try:
        config = load_config(path)
    except SlamError as exc:
        assert str(exc).count("\n") == 0 and key in str(exc)
    else:
        _computable(config)


@pytest.mark.parametrize(("table", "key"), [k for k in KEYS if k not in SEEDS])
def test_every_number_has_a_lower_and_an_upper_bound(table, key):
    default = getattr(getattr(Config(), table), key)
    if isinstance(default, str):
        pytest.skip("a choice among names")
    if isinstance(default, tuple):
        too_low, too_high = [-1e308, -1e308, 1.0], [1e308, 1e308, 1.0]
    elif isinstance(default, int):
        too_low, too_high = -(2**62), 2**62
    else:
        too_low, too_high = -1e308, 1e308
    for value in (too_low, too_high):
        with pytest.raises(SlamError, match=key):
            config_from_dict({table: {key: value}})


def test_the_defaults_the_reference_and_fitted_values_lie_within_the_bounds():
    assert Config() and Config.reference()
    for height in (30.0, 150.0, 603.0, 3000.0, 20_000.0):
        for spacing in (0.1, 2.0, 50.0):
            flight = Flight(height=height, spacing=spacing, surface_cell=1.0, strip=height * 0.087)
            fitted, _ = fit_to_flight(flight, Config())
            _computable(fitted)


@pytest.mark.parametrize("height", [0.0, -5.0])
def test_a_flight_that_is_not_above_the_ground_is_not_fitted(height):
    with pytest.raises(SlamError, match="above the ground"):
        fit_to_flight(Flight(height=height, spacing=2.0, surface_cell=1.0, strip=0.0), Config())


# Nothing non-finite in scans or metrics ------------------------------------------


def test_scans_with_non_finite_points_are_refused_where_they_are_made(tmp_path):
    from helpers.sim.dataset import create_dataset

    sensor = SensorConfig()
    object.__setattr__(sensor, "range_noise", 1e300)  # past the config's bound, as an older file might give
    path = tmp_path / "flight.csv"
    path.write_text("x,y\n0,0\n2,0\n4,0\n")
    with pytest.raises(SlamError, match=r"scans 0-2 came out with NaN or infinite points"):
        create_dataset(waypoints_path=path, sensor=sensor)


def test_non_finite_figures_become_null_and_the_run_untrusted():
    from helpers.quality.metrics import json_safe

    figures = {
        "trusted": True,
        "health": {"steps": 3, "problems": []},
        "graph_error_after": float("nan"),
        "runtime_s": {"total": 1.5, "per_scan": [np.float64(np.inf), 2.0]},
        "rpe_trans_10_m": None,
        "n_scans": 3,
    }
    safe = json_safe(figures)
    text = json.dumps(safe, allow_nan=False)  # strict JSON: no bare NaN
    assert json.loads(text) == {
        "trusted": False,
        "health": {
            "steps": 3,
            "problems": [
                "figures that are not finite numbers (written as null): graph_error_after, runtime_s.per_scan[0]."
            ],
        },
        "graph_error_after": None,
        "runtime_s": {"total": 1.5, "per_scan": [None, 2.0]},
        "rpe_trans_10_m": None,
        "n_scans": 3,
    }
    assert figures["trusted"] is True and math.isnan(figures["graph_error_after"])  # the input is left as it was
    assert json_safe({"trusted": True, "x": 1.0}) == {"trusted": True, "x": 1.0}
