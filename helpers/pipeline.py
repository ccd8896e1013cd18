"""The whole SLAM pipeline over a dataset: :class:`helpers.slam.Slam` fed
every scan of the flight, then the pose graph and the map
(:meth:`~helpers.slam.Slam.result`); and the default run, cached.

Accepted scans are the pose-graph nodes, numbered 0, 1, 2, ...;
``result.indices[k]`` is the dataset index of node ``k``.
"""

from __future__ import annotations

import hashlib
import logging
import pickle
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from . import paths
from .config import Config, noise_seed_from_environment
from .configfile import config_to_toml
from .dataset import Dataset, create_dataset, is_default
from .edges_worker import STARTUP_NODES
from .errors import SlamError
from .factors import Edge
from .loopclosure import LoopQuery
from .odometry import OdometryResult
from .preparation import prepare_scan, reads_ahead
from .progress import progress_bar
from .slam import Slam, SlamResult, Step, build_pose_graph

log = logging.getLogger(__name__)

__all__ = ["Edge", "LoopQuery", "Slam", "SlamResult", "Step", "build_pose_graph", "default_run", "run_slam"]

PICTURE_PACKAGES = ("viz", "site", "exercises")  # subpackages that draw, publish or check, never change a run's numbers


def run_slam(
    dataset: Dataset,
    config: Config | None = None,
    progress: bool = False,
    odometry: OdometryResult | None = None,
    gnss=None,
) -> SlamResult:
    """Estimate the trajectory and the map from ``dataset.scans`` alone (the
    first ground-truth pose anchors the first node, as in the reference; no
    other true pose is read: :mod:`helpers.evaluation` grades the result).
    ``odometry``: reuse one already computed on this dataset with this
    configuration (the stages after it run as usual). ``gnss``: position
    fixes (:class:`helpers.gnss.GnssFixes`) added to the pose graph.
    A flight of :data:`~helpers.edges_worker.STARTUP_NODES` nodes or more
    registers its edges back in a helper process while the next scan is
    registered (:mod:`helpers.edges_worker`), and a run in global mode reads
    and prepares the next accepted scan in a thread while this one is
    registered (:func:`helpers.preparation.reads_ahead`): the same result, sooner."""
    config = config or Config()
    skip = config.registration.skip_frames
    nodes = len(odometry.indices) if odometry is not None else -(-len(dataset) // skip)
    background = nodes >= STARTUP_NODES
    slam = Slam(config, anchor=dataset.poses[0], odometry=odometry, gnss=gnss, background=background)
    bar = progress_bar(len(dataset), "slam", enabled=progress)
    loops, following = 0, None  # following: the future of the next accepted scan (index + skip), prepared meanwhile
    reading = odometry is None and reads_ahead(config)

    def read_and_prepare(index: int):
        return prepare_scan(dataset.scans[index], index, config)

    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="helpers-read-ahead") as ahead:
        for index in range(len(dataset)):
            if slam.accepts(index):  # skipped scans are never read (nor cast, for a lazy dataset)
                prepared, following = following, None
                scan = dataset.scans[index] if prepared is None else None
                if reading and index + skip < len(dataset):
                    following = ahead.submit(read_and_prepare, index + skip)
                loops += slam.process(scan, index, prepared).loop is not None
                bar.set_postfix(loops=loops, refresh=False)
            bar.update(1)
    bar.close()
    return slam.result(n_scans=len(dataset))


def default_config(dataset: Dataset, config: Config) -> Config:
    """``config`` fitted to ``dataset``'s flight as ``python -m helpers run``
    fits it (:func:`helpers.fitting.fit_to_flight`). On the embedded default
    the fit keeps every value but the descriptor grid, 3 m instead of the
    reference's 1.5 m: the same trajectory, loops and map error (README,
    "Your own data"), the run 23 s against 30 s on two cores."""
    from .fitting import fit_to_flight, flight_of

    return fit_to_flight(flight_of(dataset), config)[0]


def core_fingerprint() -> bytes:
    """The SLAM core's files (every file of the package outside
    :data:`PICTURE_PACKAGES`: code and the shipped flight), names and contents,
    in a fixed order: what decides a run's numbers."""
    root = Path(__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*")):
        relative = path.relative_to(root)
        if path.is_file() and relative.parts[0] not in PICTURE_PACKAGES and "__pycache__" not in relative.parts:
            digest.update(relative.as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.digest()


def default_run(config: Config | None = None, dataset: Dataset | None = None) -> tuple[Dataset, SlamResult]:
    """The dataset and the SLAM result of the embedded default, computed
    once and then read from :func:`helpers.paths.cache_dir` (keyed by the
    configuration and the core package's files, so any change recomputes; so
    does a damaged file). Notebooks 4 to 7 start from here instead of from
    hidden state; two of them computing it at once each write a whole file.
    ``config``: None is the run ``python -m helpers run`` makes of the
    default: the defaults with the noise seed of
    :func:`~helpers.config.noise_seed_from_environment`, fitted to the flight
    (:func:`default_config`). A configuration given is taken as it is.
    ``dataset``: the embedded default already cast with ``config``'s sensor,
    returned as it is (a notebook's second run of the same flight then casts
    no scan again); None casts it."""
    fit = config is None
    config = config or Config().with_values(sensor={"seed": noise_seed_from_environment()})
    if dataset is None:
        dataset = create_dataset(sensor=config.sensor)
    elif not is_default(dataset, config.sensor):
        raise SlamError(
            "default_run's dataset must be the embedded default (the default scene, the shipped loop) cast with "
            f"the configuration's sensor; this one is the {dataset.name}"
            f"{'' if dataset.sensor == config.sensor else ' cast with another sensor'}"
        )
    if fit:
        config = default_config(dataset, config)
    key = hashlib.sha256(config_to_toml(config).encode() + core_fingerprint()).hexdigest()[:16]
    cache = paths.cache_dir() / f"slam-{key}.pkl"
    try:
        with open(cache, "rb") as f:
            return dataset, pickle.load(f)
    except FileNotFoundError:
        pass
    except Exception as exc:  # a damaged pickle raises many types: it is a miss
        log.warning("cache %s is unreadable (%s): computing the run again", cache, exc)
    result = run_slam(dataset, config)
    cache.parent.mkdir(parents=True, exist_ok=True)
    paths.write_atomically(cache, lambda f: pickle.dump(result, f))
    return dataset, result
