"""Shared fixtures: the default dataset (built once per test session) and
the real aerial tile kept beside the repository.

The suite must pass on lidar noise other than the one the notebooks were
committed with: ``HELPERS_NOISE_SEED=N pytest`` changes the default scene's
noise seed for the tests and for the notebooks' kernels alike (they inherit
the environment), and the header of the run says which seed and how many
threads it used.
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import helpers
from helpers.config.tables import NOISE_SEED_VARIABLE, SensorConfig, noise_seed_from_environment
from helpers.sim.waypoints import loop_waypoints

AUTZEN = Path(__file__).resolve().parents[2] / "shared" / "data" / "autzen_trim.laz"  # the real tile beside the repo


def pytest_report_header(config):
    threads = os.environ.get("OMP_NUM_THREADS", f"all {os.cpu_count()}")
    return f"lidar noise seed: {noise_seed_from_environment()} (${NOISE_SEED_VARIABLE}); OpenMP threads: {threads}"


@pytest.fixture(scope="session")
def default_dataset():
    """The embedded scene flown along the shipped loop (689 scans, ~4 s)."""
    return helpers.create_dataset()


@pytest.fixture(scope="module")
def short_loop_csv(tmp_path_factory):
    """The waypoints of a 200 m loop over the embedded scene, flown once and 30 m past its start (115 scans)."""
    path = tmp_path_factory.mktemp("loop") / "loop.csv"
    np.savetxt(path, loop_waypoints(40.0, 30.0, 20.0, overlap=30.0), delimiter=",", header="x,y", comments="")
    return path


@pytest.fixture(scope="module")
def short_loop(short_loop_csv):
    """That loop flown: its dataset."""
    return helpers.create_dataset(waypoints_path=short_loop_csv)


@pytest.fixture()
def autzen():
    if not AUTZEN.is_file():
        pytest.skip(f"real tile not found at {AUTZEN} (it sits beside the repository in CI)")
    return AUTZEN


@pytest.fixture(scope="session")
def benchmark_flight():
    """``benchmark_flight(name, swing=0.0, seed=0)``: (lazy dataset, fitted config) of
    ``benchmarks/bench_flights.py``'s flight ``name``, two laps, the speed swinging by ``swing``, lidar noise
    seed ``seed``, as ``run`` fits it."""
    benchmarks = str(Path(__file__).resolve().parents[1] / "benchmarks")
    if benchmarks not in sys.path:
        sys.path.insert(0, benchmarks)
    from bench_flights import build_flight

    def flight(name: str, swing: float = 0.0, seed: int = 0):
        return build_flight({"name": name, "laps": 2, "swing": swing, "set": [], "map_error": False, "seed": seed})

    return flight


@pytest.fixture()
def grid_tile(tmp_path):
    """``grid_tile(name, half_x, half_y, height)``: a LAS tile of one point per m²
    on a regular grid, z = ``height(x, y)``, written into ``tmp_path``."""
    import laspy

    def write(name, half_x, half_y, height):
        x, y = np.meshgrid(np.arange(-half_x, half_x, 1.0), np.arange(-half_y, half_y, 1.0))
        las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
        las.header.scales = [0.01, 0.01, 0.01]
        las.x, las.y, las.z = x.ravel(), y.ravel(), height(x.ravel(), y.ravel())
        las.write(tmp_path / name)
        return tmp_path / name

    return write


@pytest.fixture()
def flat_plane(grid_tile, tmp_path):
    """A featureless plane 100 m up (600 x 400 m) and a 30-waypoint straight flight over it: (tile, waypoints)."""
    tile = grid_tile("flat.las", 300.0, 200.0, lambda x, y: np.full(x.size, 100.0))
    flight = tmp_path / "flight.csv"
    np.savetxt(flight, np.column_stack([np.arange(-30.0, 30.0, 2.0), np.zeros(30)]), delimiter=",")
    return tile, flight


@pytest.fixture()
def short_flight(tmp_path):
    """A 40-waypoint straight flight over the default scene, as a CSV file."""
    xy = np.column_stack([np.arange(-40.0, 40.0, 2.0), np.full(40, 10.0)])
    path = tmp_path / "short.csv"
    np.savetxt(path, xy, delimiter=",", header="x,y", comments="")
    return path


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    """Every test unpacks archives into its own cache folder."""
    monkeypatch.setenv("HELPERS_CACHE", str(tmp_path / "cache"))


@pytest.fixture(scope="session")
def flight_over(tmp_path_factory):
    """Build the dataset of a stretch of the shipped loop: ``flight_over(rows)``,
    optionally under another lidar noise seed than the default."""

    def make(rows: slice, noise_seed: int | None = None):
        xy = helpers.read_waypoints(helpers.DEFAULT_WAYPOINTS)[rows]
        path = tmp_path_factory.mktemp("flight") / "waypoints.csv"
        np.savetxt(path, xy, delimiter=",", header="x,y", comments="")
        sensor = None if noise_seed is None else SensorConfig(seed=noise_seed)  # None: the environment's seed
        return helpers.create_dataset(waypoints_path=path, sensor=sensor)

    return make


def outputs_on_1_and_2_threads(script: str) -> set[str]:
    """What a Python one-liner prints when numpy/OpenMP may use 1 and then 2 threads."""
    outputs = set()
    for threads in ("1", "2"):
        env = {**os.environ, "OMP_NUM_THREADS": threads, "OPENBLAS_NUM_THREADS": threads}
        done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
        outputs.add(done.stdout.strip())
    return outputs


@pytest.fixture()
def thread_outputs():
    return outputs_on_1_and_2_threads


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for a test module's pages (tests/browser.py), or the module's browser tests skipped."""
    from browser import CHROMIUM, Browser

    if not CHROMIUM.exists():
        pytest.skip(f"no browser at {CHROMIUM}: this check needs Debian's chromium (make test installs it as root)")
    with Browser() as opened:
        yield opened
