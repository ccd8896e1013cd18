"""Files written whole: several writers of one file (two notebooks computing
the default run at once) leave one whole file, a reader never sees a part,
a failed write leaves nothing behind, and a damaged cache is computed again."""

import logging
import pickle
import threading
from dataclasses import replace

import numpy as np
import pytest

from helpers.cli import cache as pipeline
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


@pytest.fixture(scope="module")
def small_run(flight_over):
    """A real SLAM result of a few scans (what default_run stores), cheap to compute."""
    from helpers.config.tables import Config
    from helpers.slam.pipeline import run_slam

    return run_slam(flight_over(slice(0, 12)), Config())


@pytest.fixture()
def stand_in_run(monkeypatch, small_run):
    """default_run with a stand-in dataset and SLAM run (the real one takes a minute): the small run with the
    configuration asked for, its n_scans counting the runs."""
    runs = []

    def run_slam(dataset, config):
        runs.append(config)
        return replace(small_run, config=config, n_scans=len(runs))

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
@pytest.mark.parametrize("which", [".npz", ".json"])
def test_a_damaged_cache_is_computed_again(tmp_path, stand_in_run, damage, which, caplog):
    dataset, first = pipeline.default_run()
    assert dataset == "dataset" and first.n_scans == 1
    assert pipeline.default_run()[1].n_scans == 1 and len(stand_in_run) == 1  # read from the cache
    (record, data) = _cache_files(tmp_path)
    assert (record.suffix, data.suffix) == (".json", ".npz")
    damaged = record if which == ".json" else data
    damaged.write_bytes(damage(damaged.read_bytes()))
    with caplog.at_level(logging.WARNING):
        assert pipeline.default_run()[1].n_scans == 2  # computed again instead of crashing
    (warning,) = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert warning.startswith(f"the cached run in {tmp_path / 'cache'} failed its check (") and "\n" not in warning
    assert pipeline.default_run()[1].n_scans == 2  # and written whole
    assert _cache_files(tmp_path) == [record, data]


def test_two_default_runs_at_once_write_one_whole_cache(tmp_path, stand_in_run):
    results = []
    threads = [threading.Thread(target=lambda: results.append(pipeline.default_run()[1])) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(results) == 4
    assert [p.suffix for p in _cache_files(tmp_path)] == [".json", ".npz"]
    assert pipeline.default_run()[1].n_scans in range(1, 5)  # one of them, read whole


def test_default_run_takes_the_dataset_it_would_cast_and_no_other(tmp_path, stand_in_run):
    """Given the embedded default already cast with the configuration's sensor, default_run returns it
    and casts nothing; another sensor's or another flight's dataset is refused, with what it is."""
    from dataclasses import replace

    from helpers.config.tables import Config
    from helpers.errors import SlamError
    from helpers.sim.dataset import DEFAULT_WAYPOINTS, create_dataset

    config = Config()
    cast = create_dataset(sensor=config.sensor, lazy=True)  # the scans are cast when read: none is here
    returned, result = pipeline.default_run(config, dataset=cast)
    assert returned is cast and result.n_scans == 1  # the stand-in create_dataset ("dataset") was not called
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
    from helpers.config.files import load_config
    from helpers.config.tables import Config
    from helpers.sim.dataset import create_dataset
    from helpers.slam.flight_fit import fit_to_flight, flight_of

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


# Issue 63: a cache is trusted on no name; what it holds is checked, and a cache that cannot be written costs only it.


def _warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def _same_fields(a, b, where="result"):
    """``a`` and ``b`` hold the same values of the same types, field by field, arrays to the bit."""
    assert type(a) is type(b), where
    if isinstance(a, np.ndarray):
        assert (a.dtype, a.shape) == (b.dtype, b.shape) and a.tobytes() == b.tobytes(), where
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same_fields(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for key in a:
            _same_fields(a[key], b[key], f"{where}[{key!r}]")
    elif hasattr(a, "__dict__"):
        assert list(vars(a)) == list(vars(b)), where
        for name in vars(a):
            _same_fields(getattr(a, name), getattr(b, name), f"{where}.{name}")
    else:
        assert a == b or (a != a and b != b), where  # NaN is NaN


def test_a_cached_run_reads_back_equal_to_the_run_field_by_field(short_loop, monkeypatch):
    """The short loop's real run, stored as .npz and JSON and read back: every field, every array to the bit
    (loops searched from its fifth submap on, so that loop queries and their edges are in it too)."""
    from helpers.config.tables import Config

    monkeypatch.setattr(pipeline, "create_dataset", lambda sensor: short_loop)
    config = Config(sensor=short_loop.sensor).with_values(loop_closure={"sub_map_thresh": 5})
    computed = pipeline.default_run(config)[1]
    monkeypatch.setattr(pipeline, "run_slam", lambda *args: pytest.fail("computed again"))
    read = pipeline.default_run(config)[1]
    assert read is not computed and computed.loops and computed.extra_edges and computed.submaps.submaps
    _same_fields(computed, read)


def test_a_flipped_byte_in_the_cached_run_is_noticed_and_the_run_computed_again(tmp_path, stand_in_run, caplog):
    first = pipeline.default_run()[1]
    data = max(_cache_files(tmp_path), key=lambda p: p.stat().st_size)
    raw = bytearray(data.read_bytes())
    raw[len(raw) // 2] ^= 0x01  # in the middle of the arrays
    data.write_bytes(bytes(raw))
    with caplog.at_level(logging.WARNING):
        again = pipeline.default_run()[1]
    assert again.n_scans == 2 and first.n_scans == 1
    (warning,) = _warnings(caplog)
    assert "does not match the size and SHA-256 recorded when it was written" in warning


class _Mkdir:
    """A pickle that runs code when read: makes a folder."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        import os

        return (os.mkdir, (self.path,))


def test_a_file_placed_at_the_caches_name_runs_no_code(tmp_path, stand_in_run, caplog):
    """Whoever may write the cache folder (a shared one on a class server) writes a pickle there, and even the
    record's checksum to match it: reading it runs nothing, and the run is computed again."""
    import hashlib
    import json

    pipeline.default_run()
    ran = tmp_path / "code-ran"
    payload = pickle.dumps(_Mkdir(ran))
    for path in _cache_files(tmp_path):
        if path.suffix == ".json":
            record = json.loads(path.read_text())
            record.update(bytes=len(payload), sha256=hashlib.sha256(payload).hexdigest())
            path.write_text(json.dumps(record))
        else:
            path.write_bytes(payload)
    with caplog.at_level(logging.WARNING):
        result = pipeline.default_run()[1]
    assert not ran.exists()
    assert result.n_scans == 2 and len(_warnings(caplog)) == 1


@pytest.mark.parametrize("name", ["os:system", "builtins:eval", "subprocess:Popen", "helpers.slam.edges_back:Path"])
def test_a_cached_run_may_hold_only_the_packages_own_classes(name):
    import io
    import json

    tree = json.dumps({"object": [name, {}]}).encode()
    buffer = io.BytesIO()
    np.savez(buffer, tree=np.frombuffer(tree, np.uint8))
    with pytest.raises(ValueError, match="may not hold"):
        pipeline.decode(buffer.getvalue())


def test_a_run_of_another_configuration_at_the_caches_name_is_refused(tmp_path, stand_in_run, caplog):
    import hashlib
    import json

    from helpers.config.tables import Config

    mine, other = Config(), Config().with_values(sensor={"seed": 5})
    pipeline.default_run(mine)
    mine_files = _cache_files(tmp_path)
    pipeline.default_run(other)
    other_data = next(p for p in _cache_files(tmp_path) if p not in mine_files and p.suffix != ".json")
    mine_data = next(p for p in mine_files if p.suffix != ".json")
    mine_data.write_bytes(other_data.read_bytes())  # the other run's data under this one's name
    for record in [p for p in mine_files if p.suffix == ".json"]:  # and its record made to match
        described = json.loads(record.read_text())
        data = mine_data.read_bytes()
        described.update(bytes=len(data), sha256=hashlib.sha256(data).hexdigest())
        record.write_text(json.dumps(described))
    with caplog.at_level(logging.WARNING):
        result = pipeline.default_run(mine)[1]
    assert result.config == mine and result.n_scans == 3
    (warning,) = _warnings(caplog)
    assert "holds another run than its record says" in warning


def test_a_library_upgrade_computes_the_run_again(stand_in_run, monkeypatch):
    from importlib import metadata

    assert pipeline.default_run()[1].n_scans == 1
    assert pipeline.default_run()[1].n_scans == 1
    real = metadata.version
    monkeypatch.setattr(metadata, "version", lambda name: "9.9.9" if name == "gtsam" else real(name))
    assert pipeline.default_run()[1].n_scans == 2


def _refuse_writes_into_the_cache(monkeypatch, code):
    """The cache's disk full (ENOSPC) or read-only (EROFS), for every file created in it."""
    import errno
    import os

    from helpers import paths

    real = os.open

    def refuse(path, flags, *args, **kwargs):
        if flags & os.O_CREAT and os.fspath(path).startswith(str(paths.cache_dir())):
            raise OSError(code, os.strerror(code), str(path))
        return real(path, flags, *args, **kwargs)

    monkeypatch.setattr(paths.os, "open", refuse)
    return {errno.ENOSPC: "No space left on device", errno.EROFS: "Read-only file system"}[code]


@pytest.mark.parametrize("fault", ["a file in its place", "read-only", "full"])
def test_a_cache_that_cannot_be_written_costs_only_the_cache(tmp_path, stand_in_run, monkeypatch, caplog, fault):
    import errno

    cache = tmp_path / "cache"
    if fault == "a file in its place":
        cache.write_text("not a folder")
        why = f"{cache} is a file, not a folder"
    else:
        why = _refuse_writes_into_the_cache(monkeypatch, errno.EROFS if fault == "read-only" else errno.ENOSPC)
    with caplog.at_level(logging.WARNING):
        assert pipeline.default_run()[1].n_scans == 1  # the result, not a traceback
        assert pipeline.default_run()[1].n_scans == 2  # and each retry too
    expected = (
        f"the run was not saved in the cache folder {cache} ({why}): it will be computed again next time; "
        "$HELPERS_CACHE names another folder"
    )
    assert _warnings(caplog) == [expected, expected]
    assert fault == "a file in its place" or not [p for p in cache.iterdir() if p.is_file()]
