"""The command line: outputs on success, one clear line and exit code 2 on bad input."""

import subprocess
import sys

import numpy as np
import pytest

from helpers.__main__ import main
from helpers.config import SensorConfig, SlamConfig, load_config


def run(*args):
    return subprocess.run([sys.executable, "-m", "helpers", *args], capture_output=True, text=True, timeout=300)


def test_dataset_command_writes_the_layout(tmp_path, short_flight):
    out = tmp_path / "ds"
    result = run("dataset", "--waypoints", str(short_flight), "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "40 scans" in result.stdout
    assert len(list((out / "scans").glob("*.ply"))) == 40
    lines = (out / "poses_gt.txt").read_text().splitlines()
    assert len(lines) == 40 and len(lines[0].split()) == 8
    assert (out / "map_gt.ply").stat().st_size > 0


def test_bad_input_is_one_line_exit_2_and_no_output(tmp_path):
    out = tmp_path / "ds"
    result = run("dataset", "--map", str(tmp_path / "missing.laz"), "--out", str(out))
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [f"error: map file not found: {tmp_path / 'missing.laz'}"]
    assert "Traceback" not in result.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ("[sensor]\naltitud = 500\n", "unknown key(s) ['altitud']"),
        ("[sensors]\naltitude = 500\n", "unknown table(s) ['sensors']"),
        ("[sensor]\ndropout = 1.5\n", "dropout must be a probability in [0, 1)"),
        ("[sensor]\nazimuth = [13, -13, 0.08]\n", "azimuth must be [start, stop, step]"),
        ("[sensor]\nmax_range = 'far'\n", "max_range must be a number"),
        ("[slam]\nmetric = 'planeToPlane'\n", "metric must be one of point-to-point"),
        ("[slam]\nneighbors = 2\n", "neighbors must be an integer from 3 to 1,000"),
        ("[sensor\n", "not valid TOML"),
    ],
)
def test_config_errors(tmp_path, capsys, toml, message):
    config = tmp_path / "bad.toml"
    config.write_text(toml)
    code = main(["dataset", "--config", str(config), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_empty_scans_are_reported_as_an_error(tmp_path, capsys, short_flight):
    config = tmp_path / "short_range.toml"
    config.write_text("[sensor]\nmax_range = 100.0\n")
    code = main(["dataset", "--waypoints", str(short_flight), "--config", str(config), "--out", str(tmp_path / "o")])
    assert code == 2 and "40 of 40 scans came back empty" in capsys.readouterr().err


def test_config_file_overrides_defaults(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[sensor]\naltitude = 400\nazimuth = [-6, 6, 0.1]\nseed = 9\n[slam]\ngrid_step = 1.0\n")
    config = load_config(path)
    assert config.sensor == SensorConfig(altitude=400.0, azimuth=(-6.0, 6.0, 0.1), seed=9)
    assert config.slam == SlamConfig(grid_step=1.0)
    assert load_config(None).sensor.altitude == 700.0


def test_reference_values_are_the_defaults():
    slam = SlamConfig()
    reference = dict(skip_frames=3, grid_step=1.5, neighbors=60, match_threshold=0.1, match_ratio=0.97)
    reference |= dict(max_distance=1.0, max_num_trials=3000, metric="plane-to-plane", inlier_distance=3.0)
    reference |= dict(align_grid_step=1.2, loop_closure_search_radius=7.9, n_scans_per_submap=3)
    reference |= dict(sub_map_thresh=15, loop_closure_threshold=0.6, rmse_threshold=0.6)
    assert {k: getattr(slam, k) for k in reference} == reference
    sensor = SensorConfig()
    assert (sensor.altitude, sensor.max_range, sensor.azimuth, sensor.elevation) == (
        700.0,
        800.0,
        (-13.0, 13.0, 0.08),
        (-2.5, 2.5, 0.2),
    )
    assert np.isclose(sensor.range_noise, 0.02)
