"""``$HELPERS_NOISE_SEED`` puts the entry points on other lidar noise (the
robustness run) and changes nothing else: ``Config()`` is the same in any
environment."""

import pytest

from helpers.__main__ import main
from helpers.cli import cache as pipeline
from helpers.config.files import load_config
from helpers.config.tables import NOISE_SEED_VARIABLE, Config, SensorConfig, noise_seed_from_environment
from helpers.errors import SlamError
from helpers.sim.dataset import create_dataset


def test_the_configuration_never_reads_the_environment(monkeypatch):
    monkeypatch.setenv(NOISE_SEED_VARIABLE, "7")
    assert Config().sensor.seed == SensorConfig().seed == Config.reference().sensor.seed == 0
    monkeypatch.delenv(NOISE_SEED_VARIABLE)
    assert noise_seed_from_environment() == 0


def test_the_entry_points_take_the_seed_from_the_environment(monkeypatch, tmp_path, short_flight):
    monkeypatch.setenv(NOISE_SEED_VARIABLE, "7")
    assert noise_seed_from_environment() == 7
    unseeded, seeded = tmp_path / "unseeded.toml", tmp_path / "seeded.toml"
    unseeded.write_text("[sensor]\naltitude = 650.0\n")
    seeded.write_text("[sensor]\nseed = 3\n")
    assert load_config(None) == Config().with_values(sensor={"seed": 7})
    assert load_config(unseeded).sensor == SensorConfig(altitude=650.0, seed=7)
    assert load_config(seeded).sensor.seed == 3  # a seed the file sets is kept
    assert create_dataset(waypoints_path=short_flight, lazy=True).sensor.seed == 7
    assert create_dataset(waypoints_path=short_flight, sensor=SensorConfig(), lazy=True).sensor.seed == 0
    # the CLI writes the sensor it flew
    assert main(["dataset", "--waypoints", str(short_flight), "--out", str(tmp_path / "data")]) == 0
    assert "seed = 7\n" in (tmp_path / "data" / "sensor.toml").read_text()
    # default_run, with a stand-in dataset and run
    monkeypatch.setattr(pipeline, "create_dataset", lambda sensor: sensor)
    monkeypatch.setattr(pipeline, "default_config", lambda dataset, config: config)  # no flight to fit to
    monkeypatch.setattr(pipeline, "run_slam", lambda dataset, config: "result")
    assert pipeline.default_run()[0].seed == 7
    assert pipeline.default_run(Config())[0].seed == 0  # a configuration given is taken as it is


@pytest.mark.parametrize("value", ["-1", "one", "1.5", "", "²"])
def test_a_seed_that_is_not_a_count_is_one_error_line(monkeypatch, tmp_path, capsys, short_flight, value):
    monkeypatch.setenv(NOISE_SEED_VARIABLE, value)
    with pytest.raises(SlamError, match=f"\\${NOISE_SEED_VARIABLE} must be a non-negative integer"):
        noise_seed_from_environment()
    assert Config().sensor.seed == 0
    code = main(["dataset", "--waypoints", str(short_flight), "--out", str(tmp_path / "data")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "data").exists()
