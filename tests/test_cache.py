"""Files written whole: several writers of one file (two notebooks computing
the default run at once) leave one whole file, a reader never sees a part,
a failed write leaves nothing behind, and a damaged cache is computed again."""

import pickle
import threading

import numpy as np
import pytest

from helpers import pipeline
from helpers.paths import write_atomically

N_WRITERS, N_WRITES = 6, 15
N_VALUES = 400_000  # 3.2 MB a pickle: each write takes several system calls


def _payload(writer: int) -> dict:
    return {"writer": writer, "values": np.full(N_VALUES, writer, np.int64)}


def test_concurrent_writers_leave_a_whole_file_and_readers_never_see_a_part(tmp_path):
    path = tmp_path / "cache.pkl"
    start = threading.Barrier(N_WRITERS + 1)
    errors, reads = [], []

    def write(writer):
        start.wait()
        try:
            for _ in range(N_WRITES):
                write_atomically(path, lambda f: pickle.dump(_payload(writer), f))
        except Exception as exc:  # reported below: a writer must not fail either
            errors.append(exc)

    writers = [threading.Thread(target=write, args=(i,)) for i in range(N_WRITERS)]
    for thread in writers:
        thread.start()
    start.wait()
    while any(thread.is_alive() for thread in writers):
        try:
            with open(path, "rb") as f:
                reads.append(pickle.load(f))
        except FileNotFoundError:
            pass  # no writer has finished yet
    for thread in writers:
        thread.join()
    assert not errors, errors
    assert reads, "the reader never got to read"
    for got in [*reads, pickle.loads(path.read_bytes())]:
        assert got["values"].shape == (N_VALUES,) and (got["values"] == got["writer"]).all()
    assert [p.name for p in tmp_path.iterdir()] == ["cache.pkl"]  # no temporary file left


def test_a_failed_write_leaves_the_old_file_and_no_temporary_one(tmp_path):
    path = tmp_path / "cache.pkl"
    write_atomically(path, lambda f: f.write(b"old"))

    def fail(f):
        f.write(b"half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        write_atomically(path, fail)
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["cache.pkl"]


@pytest.fixture()
def stand_in_run(monkeypatch):
    """default_run with a stand-in dataset and SLAM run (the real one takes a minute); counts the runs."""
    runs = []

    def run_slam(dataset, config):
        runs.append(config)
        return {"result": len(runs), "values": np.arange(1000.0)}

    monkeypatch.setattr(pipeline, "create_dataset", lambda sensor: "dataset")
    monkeypatch.setattr(pipeline, "default_config", lambda dataset, config: config)  # no flight to fit to
    monkeypatch.setattr(pipeline, "run_slam", run_slam)
    return runs


def _cache_files(tmp_path):
    return sorted((tmp_path / "cache").iterdir())  # HELPERS_CACHE points there (tests/conftest.py)


@pytest.mark.parametrize(
    "damage",
    [lambda data: data[: len(data) // 2], lambda data: b"", lambda data: b"\x80\x05garbage" + data[10:]],
    ids=["truncated", "empty", "garbage"],
)
def test_a_damaged_cache_is_computed_again(tmp_path, stand_in_run, damage):
    dataset, first = pipeline.default_run()
    assert dataset == "dataset" and first["result"] == 1
    assert pipeline.default_run()[1]["result"] == 1 and len(stand_in_run) == 1  # read from the cache
    (cache,) = _cache_files(tmp_path)
    cache.write_bytes(damage(cache.read_bytes()))
    assert pipeline.default_run()[1]["result"] == 2  # computed again instead of crashing
    assert pickle.loads(cache.read_bytes())["result"] == 2  # and written whole
    assert _cache_files(tmp_path) == [cache]


def test_two_default_runs_at_once_write_one_whole_cache(tmp_path, stand_in_run):
    results = []
    threads = [threading.Thread(target=lambda: results.append(pipeline.default_run()[1])) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(results) == 4
    (cache,) = _cache_files(tmp_path)
    assert pickle.loads(cache.read_bytes())["result"] in range(1, 5)


def test_default_run_takes_the_dataset_it_would_cast_and_no_other(tmp_path, stand_in_run):
    """Given the embedded default already cast with the configuration's sensor, default_run returns it
    and casts nothing; another sensor's or another flight's dataset is refused, with what it is."""
    from dataclasses import replace

    from helpers.config import Config
    from helpers.dataset import DEFAULT_WAYPOINTS, create_dataset
    from helpers.errors import SlamError

    config = Config()
    cast = create_dataset(sensor=config.sensor, lazy=True)  # the scans are cast when read: none is here
    returned, result = pipeline.default_run(config, dataset=cast)
    assert returned is cast and result["result"] == 1  # the stand-in create_dataset ("dataset") was not called
    assert pipeline.default_run(config)[0] == "dataset"  # without one, it is cast (here, the stand-in)
    other_sensor = create_dataset(sensor=replace(config.sensor, seed=3), lazy=True)
    with pytest.raises(SlamError, match="default scene cast with another sensor"):
        pipeline.default_run(config, dataset=other_sensor)
    short = tmp_path / "short.csv"
    short.write_text("\n".join(DEFAULT_WAYPOINTS.read_text().splitlines()[:200]) + "\n")
    other_flight = create_dataset(waypoints_path=short, sensor=config.sensor, lazy=True)
    with pytest.raises(SlamError, match="the shipped loop"):
        pipeline.default_run(config, dataset=other_flight)
    assert len(stand_in_run) == 1  # only the first call ran (the second read its cache)


def test_default_run_without_a_configuration_runs_what_the_cli_runs(monkeypatch):
    """default_run() fits the defaults to the embedded flight as `python -m helpers run` does: on this flight
    only the descriptor grid changes (the reference's 1.5 m doubled); a configuration given is run as it is."""
    from helpers.config import Config
    from helpers.configfile import load_config
    from helpers.dataset import create_dataset
    from helpers.fitting import fit_to_flight, flight_of

    runs = []
    monkeypatch.setattr(pipeline, "create_dataset", lambda sensor: create_dataset(sensor=sensor, lazy=True))
    monkeypatch.setattr(pipeline, "run_slam", lambda dataset, config: runs.append(config) or len(runs))
    dataset, _ = pipeline.default_run()
    cli = load_config(None)  # what `run` starts from without --config, then fits (helpers.__main__)
    assert runs == [fit_to_flight(flight_of(dataset), cli)[0]]
    assert runs[0].features.grid_step == 2 * Config().features.grid_step == 3.0
    assert runs[0].with_values(features={"grid_step": Config().features.grid_step}) == cli
    given = Config(sensor=dataset.sensor)
    pipeline.default_run(given, dataset)
    assert runs[1] == given
