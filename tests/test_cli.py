"""The command line: outputs on success, one clear line and exit code 2 on bad input."""

import os
import subprocess
import sys

import numpy as np
import pytest

import helpers
from helpers.__main__ import ENVIRONMENT, main
from helpers.cli.terminal import reason_lines, report_run, verdict
from helpers.config.files import config_to_toml, load_config
from helpers.config.tables import Config, FeaturesConfig, SensorConfig
from helpers.quality.trust import Health


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
        ("[registration]\nmetric = 'planeToPlane'\n", "metric must be one of point-to-point"),
        ("[features]\nneighbors = 2\n", "neighbors must be an integer from 3 to 1,000"),
        (
            "[slam]\ngrid_step = 1.0\nsub_map_thresh = 4\n",
            "grid_step -> [features] grid_step; sub_map_thresh -> [loop_closure]",
        ),
        ("[registration]\ngrid_step = 1.0\n", "unknown key(s) ['grid_step']"),
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
    path.write_text("[sensor]\naltitude = 400\nazimuth = [-6, 6, 0.1]\nseed = 9\n[features]\ngrid_step = 1.0\n")
    config = load_config(path)
    assert config.sensor == SensorConfig(altitude=400.0, azimuth=(-6.0, 6.0, 0.1), seed=9)
    assert config.features == FeaturesConfig(grid_step=1.0)
    assert config == Config().with_values(
        sensor=dict(altitude=400.0, azimuth=(-6.0, 6.0, 0.1), seed=9), features=dict(grid_step=1.0)
    )
    assert load_config(None).sensor.altitude == 700.0


def test_written_config_reads_back_the_same(tmp_path):
    config = Config().with_values(
        registration=dict(metric="point-to-plane", icp_tolerance=1e-6),
        loop_closure=dict(sub_map_thresh=4),
        pose_graph=dict(loop_kernel="huber"),
    )
    path = tmp_path / "c.toml"
    path.write_text(config_to_toml(config))
    assert load_config(path) == config


def test_reference_values_are_the_defaults():
    config = Config()
    reference = {
        "features": dict(grid_step=1.5, neighbors=60, match_threshold=0.1, match_ratio=0.97),
        "registration": dict(skip_frames=3, max_distance=1.0, max_num_trials=3000, confidence=0.99),
        "map": dict(align_grid_step=1.2, n_scans_per_submap=3),
        "loop_closure": dict(loop_closure_search_radius=7.9, sub_map_thresh=15, loop_closure_threshold=0.6),
    }
    reference["registration"] |= dict(metric="plane-to-plane", inlier_distance=3.0)
    reference["loop_closure"] |= dict(rmse_threshold=0.6)
    for table, values in reference.items():
        assert {k: getattr(getattr(config, table), k) for k in values} == values
    sensor = SensorConfig()
    assert (sensor.altitude, sensor.max_range, sensor.azimuth, sensor.elevation) == (
        700.0,
        800.0,
        (-13.0, 13.0, 0.08),
        (-2.5, 2.5, 0.2),
    )
    assert np.isclose(sensor.range_noise, 0.02)


def test_an_untrusted_run_warns_once_and_says_so_in_the_metrics(flat_plane, tmp_path):
    """Over a featureless plane every step falls back: the run still writes its
    outputs and exits 0, with one warning naming the cause and the parameter."""
    import json

    tile, flight = flat_plane
    out = tmp_path / "run"
    result = run("run", "--map", str(tile), "--waypoints", str(flight), "--out", str(out))
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning:")]
    assert warnings[0] == "warning: no unit in the LAS header's CRS records: assuming metres"  # the plane's tile
    reasons = warnings[1:]  # each reason of the trust flag a warning of its own, its cause and advice under it
    assert reasons and all(line.startswith("warning: not trusted: ") for line in reasons)
    assert max(len(line) for line in result.stderr.splitlines()) < 300
    assert "\n  Try [registration] skip_frames = 1 (now 3).\n" in result.stderr
    n = len(reasons)
    assert result.stdout.splitlines()[-1] == (
        f'not trusted: {n} reason{"s" if n > 1 else ""} in the warnings above (metrics.json: "trusted": false)'
    )
    assert "scan 3:" not in result.stderr  # each fallback is counted, not printed
    assert "parameters fitted to the flight (600 m above the ground" in result.stdout  # the reference's height
    assert "9 of 9 odometry steps fell back" in result.stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["trusted"] is False and metrics["health"]["n_fallbacks"] == 9


def test_run_fits_the_parameters_to_a_low_flight_unless_told_not_to(grid_tile, tmp_path):
    """150 m above a plane: every scan accepted, the grid at the 1 m surface, and
    config.toml holds what was used; --reference-values keeps the reference's."""
    tile = grid_tile("low.las", 150.0, 100.0, lambda x, y: 0.3 * np.sin(x / 7) * np.cos(y / 5))
    flight = tmp_path / "flight.csv"
    np.savetxt(flight, np.column_stack([np.arange(-20.0, 20.0, 2.0), np.zeros(20)]), delimiter=",")
    config = tmp_path / "mine.toml"
    config.write_text("[sensor]\naltitude = 150.0\n[map]\nalign_grid_step = 1.0\n")
    common = ("run", "--map", str(tile), "--waypoints", str(flight), "--config", str(config))
    fitted = run(*common, "--out", str(tmp_path / "fitted"))
    assert fitted.returncode == 0, fitted.stderr
    assert "[registration] skip_frames = 1:" in fitted.stdout
    assert "[map] align_grid_step = 1.0: as given" in fitted.stdout
    used = load_config(tmp_path / "fitted" / "config.toml")
    assert used.registration.skip_frames == 1 and used.features.grid_step == 1.0 and used.map.align_grid_step == 1.0
    # the graph of a flight where every scan is accepted: each edge's information, Huber, the motion factor
    assert "[pose_graph] graph_weights = 'hessian':" in fitted.stdout
    pose_graph = used.pose_graph
    assert (pose_graph.graph_weights, pose_graph.loop_kernel, pose_graph.motion_factor) == ("hessian", "huber", True)
    kept = run(*common, "--reference-values", "--out", str(tmp_path / "kept"))
    assert kept.returncode == 0, kept.stderr
    assert "fitted" not in kept.stdout
    kept_config = load_config(tmp_path / "kept" / "config.toml")
    assert kept_config.registration.skip_frames == 3 and kept_config.pose_graph == Config().pose_graph


def test_version_is_the_package_version(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out == f"aerial-lidar-slam-helpers {helpers.__version__}\n"


@pytest.mark.parametrize("command", ["dataset", "run", "flight", "site"])
def test_each_command_explains_itself_with_an_example(capsys, monkeypatch, command):
    """--help: a description of its own (not only the usage), an example command line to copy whole, and no
    reStructuredText markup."""
    monkeypatch.setenv("COLUMNS", "80")
    with pytest.raises(SystemExit) as done:
        main([command, "--help"])
    assert done.value.code == 0
    text = capsys.readouterr().out
    paragraphs = text.split("\n\n")
    assert paragraphs[0].startswith(f"usage: python -m helpers {command}")
    assert paragraphs[1][0].isupper() and paragraphs[1].rstrip().endswith(".")  # the description
    heading, *examples = paragraphs[-1].splitlines()
    assert heading == ("example:" if len(examples) == 1 else "examples:") and examples
    assert all(line.startswith(f"  python -m helpers {command} ") for line in examples)  # each on one line
    assert "`" not in text


def test_the_program_help_lists_the_commands_with_examples(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    examples = text.split("examples:\n")[1].splitlines()
    assert [line.split()[3] for line in examples] == ["dataset", "run", "run", "flight", "site"]
    assert any("--scans" in line for line in examples)
    assert "--version" in text and "`" not in text


def test_help_imports_no_heavy_library():
    """--help answers before numpy, Open3D or GTSAM load: they are imported by the commands that use them."""
    code = (
        "import runpy, sys\n"
        "sys.argv = ['helpers', '--help']\n"
        "try:\n    runpy.run_module('helpers', run_name='__main__')\n"
        "except SystemExit:\n    pass\n"
        "print(sorted(m for m in ('numpy', 'open3d', 'gtsam', 'scipy', 'laspy') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "[]"


def test_the_program_sets_openmp_and_open3d_variables_unless_the_user_has(monkeypatch, capsys):
    """As the program (no argv given: the process's own), before any command imports Open3D; a caller in
    Python (argv given) keeps its environment as it is."""
    monkeypatch.setattr(sys, "argv", ["aerial-lidar-slam", "--version"])
    monkeypatch.setattr("os.environ", {"OMP_WAIT_POLICY": "active"})
    with pytest.raises(SystemExit):
        main()
    assert os.environ == {"OMP_WAIT_POLICY": "active", "OPEN3D_DISABLE_WEB_VISUALIZER": "true"}
    monkeypatch.setattr("os.environ", {})
    with pytest.raises(SystemExit):
        main(["--version"])
    assert os.environ == {}
    assert ENVIRONMENT == {"OMP_WAIT_POLICY": "passive", "OPEN3D_DISABLE_WEB_VISUALIZER": "true"}


def test_python_m_helpers_sets_the_variables_before_open3d_loads():
    """The real entry point, in a process of its own: the variables are there when the command starts."""
    code = (
        "import os, runpy, sys\n"
        "import helpers.cli.main as cli\n"
        "cli._main = lambda argv: print(os.environ.get('OMP_WAIT_POLICY'), os.environ.get("
        "'OPEN3D_DISABLE_WEB_VISUALIZER'), 'open3d' in sys.modules) or 0\n"
        "sys.argv = ['helpers', 'run']\n"
        "try:\n    runpy.run_module('helpers', run_name='__main__')\n"
        "except SystemExit:\n    pass\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ENVIRONMENT}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["passive", "true", "False"]


def test_a_reason_of_the_trust_flag_is_a_short_warning_with_its_cause_and_advice_under_it():
    problem = (
        "9 of 9 odometry steps (100%) could not be registered and fell back to the previous motion (scans 1-9). "
        "Likely cause: consecutive accepted scans share too little ground (a low flight). "
        "Try [registration] skip_frames = 1 (now 3)."
    )
    assert reason_lines(problem) == [
        "warning: not trusted: 9 of 9 odometry steps (100%) could not be registered and fell back to the previous "
        "motion (scans 1-9).",
        "  Likely cause: consecutive accepted scans share too little ground (a low flight).",
        "  Try [registration] skip_frames = 1 (now 3).",
    ]
    assert reason_lines("ICP RMSE above 0.6 m: it may break.") == [
        "warning: not trusted: ICP RMSE above 0.6 m: it may break."
    ]


def test_the_last_line_of_a_run_says_trusted_or_not():
    assert verdict([]) == "trusted"
    assert verdict(["a."]) == 'not trusted: 1 reason in the warnings above (metrics.json: "trusted": false)'
    assert verdict(["a.", "b."]).startswith("not trusted: 2 reasons")


def test_a_run_whose_scale_is_unobserved_is_reported_trusted_in_shape_only(capsys, tmp_path):
    """Nothing disagrees in the run but its loops do not observe its scale: the reason is one warning on
    standard error, the last line says trusted in shape only, and an untrusted run says only that."""
    scale = (
        "Its scale is not observed: no loop observes the flight's scale. A bias of 1 % in the odometry's step "
        "lengths would move the trajectory by 2.15 m unseen. Likely cause: every loop closes where the flight "
        "passed before."
    )
    counts = {
        "n_fallbacks": 0, "n_steps": 10, "n_poor_steps": 0, "n_weak_steps": 0, "n_loops_rejected": 0,
        "n_loops_too_flat": 0, "n_loops_against_graph": 0, "n_edges_back_left_out": 0, "n_edges_back_tried": 0,
        "loop_scale_sigma_pct": None, "longest_loop_lever_m": 0.0, "moved_per_scale_pct_m": 2.15,
    }  # fmt: skip
    metrics = {"n_accepted": 11, "n_scans": 11, "n_loop_closures": 0, "runtime_s": {"total": 1.0}}
    report_run(metrics, Health(counts, [], scale), tmp_path)
    out, err = capsys.readouterr()
    assert err.splitlines() == [
        "warning: trusted in shape only: Its scale is not observed: no loop observes the flight's scale.",
        "  A bias of 1 % in the odometry's step lengths would move the trajectory by 2.15 m unseen.",
        "  Likely cause: every loop closes where the flight passed before.",
    ]
    assert out.splitlines()[-1] == verdict([], scale)
    assert verdict([], scale).startswith("trusted in shape only: its scale is not observed")
    report_run(metrics, Health(counts, ["Too many steps fell back."], scale), tmp_path)
    out, err = capsys.readouterr()
    assert err.splitlines() == ["warning: not trusted: Too many steps fell back."]
    assert out.splitlines()[-1].startswith("not trusted: 1 reason")
