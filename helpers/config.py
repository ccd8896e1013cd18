"""Every tunable value of the project, in one place.

The defaults are the reference workflow's values. A TOML file can override
any of them, table by table::

    [sensor]
    altitude = 700.0                 # flight height, m, in the map frame
    azimuth = [-13.0, 13.0, 0.08]    # across track: start, stop, step, deg
    elevation = [-2.5, 2.5, 0.2]     # along track: start, stop, step, deg

Unknown tables or keys and out-of-range values are refused at load time
with one sentence saying which and why.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .errors import SlamError

NOISE_SEED_VARIABLE = "HELPERS_NOISE_SEED"  # the default lidar noise seed, when set (the tests' robustness run)


def default_noise_seed() -> int:
    """The default ``[sensor] seed``: 0, or ``$HELPERS_NOISE_SEED`` when it is set.

    The variable lets the whole test suite, notebooks included, run on other
    lidar noise than the committed outputs were made with (see the README's
    development notes); nothing else needs it.
    """
    value = os.environ.get(NOISE_SEED_VARIABLE, "0")
    if not value.isdigit():
        raise SlamError(f"${NOISE_SEED_VARIABLE} must be a non-negative integer, got {value!r}")
    return int(value)


# What a configuration may ask for: generous for real use, far below what would exhaust a machine.
MAX_RAYS_PER_SCAN = 1_000_000  # 118 times the default fan (326 x 26 = 8476 rays)
MAX_RAYS_PER_FLIGHT = 200_000_000  # all scans together: 34 times the default flight (689 scans)
RAY_BYTES = 160  # memory a ray takes while its scan is cast (measured 157 on a 325k-ray fan)
POINT_BYTES = 40  # memory a return keeps until the flight is written (measured 37)
MAX_TRIALS = 1_000_000  # robust-fit hypotheses (the default draws 3000; their samples take 24 bytes each)
MAX_NEIGHBORS = 1_000  # neighbours of a normal or FPFH (the default takes 60)
MAX_EDGES_BACK = 100  # each is one more registration per scan (the default makes 4)


def angle_count(start: float, stop: float, step: float) -> int:
    """How many angles ``start, start + step, ...`` up to ``stop`` a ray fan has."""
    return math.floor((stop - start) / step + 1e-9) + 1


def human_size(nbytes: float) -> str:
    """A byte count in words: '189 TiB'."""
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if nbytes < 1024:
            return f"{nbytes:.3g} {unit}"
        nbytes /= 1024
    return f"{nbytes:.3g} TiB"


def _param(default, help: str):
    """A parameter with its one-line meaning (shown by :func:`describe`)."""
    return field(default=default, metadata={"help": help})


@dataclass(frozen=True)
class SensorConfig:
    """The simulated lidar and how it flies."""

    altitude: float = _param(700.0, "flight height in metres (z in the map frame), constant")
    azimuth: tuple[float, float, float] = _param((-13.0, 13.0, 0.08), "ray angles across track [start, stop, step] deg")
    elevation: tuple[float, float, float] = _param((-2.5, 2.5, 0.2), "ray angles along track [start, stop, step] deg")
    max_range: float = _param(800.0, "returns farther than this many metres are lost")
    range_noise: float = _param(0.02, "standard deviation of the range error, metres")
    dropout: float = _param(0.01, "probability that a ray gives no return")
    seed: int = field(default_factory=default_noise_seed, metadata={"help": "seed of the range noise and dropouts"})

    def __post_init__(self):
        for name in ("azimuth", "elevation"):
            start, stop, step = _triple(self, name)
            if not (-89.0 < start <= stop < 89.0 and 0 < step < math.inf):
                raise SlamError(
                    f"[sensor] {name} must be [start, stop, step] degrees with "
                    f"-89 < start <= stop < 89 and a finite step > 0, got {list(getattr(self, name))}"
                )
        rays = math.prod((stop - start) / step + 1 for start, stop, step in (self.azimuth, self.elevation))
        if rays > MAX_RAYS_PER_SCAN:
            raise SlamError(
                f"[sensor] asks for {rays:.2g} rays per scan (about {human_size(rays * RAY_BYTES)} of ray "
                f"buffers); the limit is {MAX_RAYS_PER_SCAN:,} rays: use larger azimuth or elevation steps"
            )
        _check(self, "altitude", lambda v: math.isfinite(v), "a finite number of metres")
        _check(self, "max_range", lambda v: 0 < v < math.inf, "a positive number of metres")
        _check(self, "range_noise", lambda v: 0 <= v < math.inf, "zero or a positive number of metres")
        _check(self, "dropout", lambda v: 0 <= v < 1, "a probability in [0, 1)")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise SlamError(f"[sensor] seed must be a non-negative integer, got {self.seed!r}")

    @property
    def rays_per_scan(self) -> int:
        return angle_count(*self.azimuth) * angle_count(*self.elevation)

    def check_flight(self, n_scans: int) -> None:
        """Refuse a flight whose scans together ask for more than :data:`MAX_RAYS_PER_FLIGHT` rays."""
        rays = n_scans * self.rays_per_scan
        if rays > MAX_RAYS_PER_FLIGHT:
            raise SlamError(
                f"{n_scans:,} scans of {self.rays_per_scan:,} rays ask for {rays:.2g} rays "
                f"(about {human_size(rays * POINT_BYTES)} of points); the limit is {MAX_RAYS_PER_FLIGHT:,} rays "
                "per flight: fly fewer waypoints or use larger angle steps"
            )


METRICS = ("point-to-point", "point-to-plane", "plane-to-plane")
GRAPH_WEIGHTS = ("icp", "identity")
LOOP_KERNELS = ("none", "huber", "cauchy")


@dataclass(frozen=True)
class SlamConfig:
    """The SLAM pipeline (the reference's parameter block, in snake_case)."""

    # Registration (stage 3)
    skip_frames: int = _param(3, "register every n-th scan only: the accepted scans")
    grid_step: float = _param(1.5, "cell of the grid-average downsampling before features, metres")
    neighbors: int = _param(60, "nearest neighbours for normals and FPFH")
    match_threshold: float = _param(0.1, "largest normalised descriptor distance of a match")
    match_ratio: float = _param(0.97, "ratio test: best / second-best distance must be below it")
    max_distance: float = _param(1.0, "inlier distance of the robust rigid fit (MSAC), metres")
    max_num_trials: int = _param(3000, "most hypotheses the robust fit draws")
    confidence: float = _param(0.99, "the robust fit stops once it is this sure to have drawn an all-inlier sample")
    metric: str = _param("plane-to-plane", "ICP metric: point-to-point, point-to-plane, plane-to-plane")
    inlier_distance: float = _param(3.0, "ICP ignores correspondences farther apart than this, metres")
    seed: int = _param(0, "seed of the robust fit's sampling")
    icp_grid_step: float = _param(0.75, "grid of the clouds ICP refines on, metres (0: the feature clouds)")
    icp_fallback_rmse: float = _param(1.5, "an ICP RMSE above this (metres) counts as a failed registration")
    # Mapping and loop closure (stages 4-5)
    align_grid_step: float = _param(1.2, "grid of the merge that builds submaps and the map, metres")
    loop_closure_search_radius: float = _param(7.9, "submaps whose centre is nearer than this (metres) are candidates")
    n_scans_per_submap: int = _param(3, "accepted scans per submap")
    sub_map_thresh: int = _param(15, "the most recent submaps are never loop candidates")
    loop_closure_threshold: float = _param(0.6, "surface RMSE (m) below which a submap matches")
    rmse_threshold: float = _param(0.6, "surface RMSE (m) below which the best scan match is a loop edge")
    loop_search_growth: float = _param(0.02, "search radius grows by this share of the distance flown (0: reference)")
    # Pose graph (stage 6)
    edges_back: int = _param(
        4, "each scan is also registered to the scans up to this many nodes back (1: the reference)"
    )
    graph_weights: str = _param("icp", "edge weights: icp (realistic sigmas) or identity (the reference)")
    loop_kernel: str = _param("cauchy", "robust kernel on loop edges: none (the reference), huber or cauchy")

    def __post_init__(self):
        positive = ("grid_step", "max_distance", "inlier_distance", "align_grid_step")
        positive += ("loop_closure_search_radius", "loop_closure_threshold", "rmse_threshold")
        for name in positive:
            _check(self, name, lambda v: math.isfinite(v) and v > 0, "a positive number")
        for name in ("skip_frames", "n_scans_per_submap"):
            _check(self, name, lambda v: v >= 1, "an integer of at least 1")
        _check(self, "max_num_trials", lambda v: 1 <= v <= MAX_TRIALS, f"an integer from 1 to {MAX_TRIALS:,}")
        _check(self, "neighbors", lambda v: 3 <= v <= MAX_NEIGHBORS, f"an integer from 3 to {MAX_NEIGHBORS:,}")
        _check(self, "sub_map_thresh", lambda v: v >= 0, "zero or a positive integer")
        _check(self, "seed", lambda v: v >= 0, "zero or a positive integer")
        _check(self, "match_threshold", lambda v: 0 < v <= 1, "in (0, 1]")
        _check(self, "match_ratio", lambda v: 0 < v <= 1, "in (0, 1]")
        _check(self, "confidence", lambda v: 0 < v < 1, "in (0, 1)")
        _check(self, "metric", lambda v: v in METRICS, f"one of {', '.join(METRICS)}")
        _check(self, "icp_grid_step", lambda v: math.isfinite(v) and v >= 0, "zero or a positive number")
        _check(self, "icp_fallback_rmse", lambda v: math.isfinite(v) and v > 0, "a positive number")
        _check(self, "loop_search_growth", lambda v: math.isfinite(v) and v >= 0, "zero or a positive fraction")
        _check(self, "edges_back", lambda v: 1 <= v <= MAX_EDGES_BACK, f"an integer from 1 to {MAX_EDGES_BACK}")
        _check(self, "graph_weights", lambda v: v in GRAPH_WEIGHTS, f"one of {', '.join(GRAPH_WEIGHTS)}")
        _check(self, "loop_kernel", lambda v: v in LOOP_KERNELS, f"one of {', '.join(LOOP_KERNELS)}")


@dataclass(frozen=True)
class Config:
    """The whole configuration, one table per stage."""

    sensor: SensorConfig = field(default_factory=SensorConfig)
    slam: SlamConfig = field(default_factory=SlamConfig)


def describe(table) -> list[tuple[str, object, str]]:
    """(name, value, meaning) for every parameter of a config table."""
    return [(f.name, getattr(table, f.name), f.metadata.get("help", "")) for f in dataclasses.fields(table)]


def load_config(path: str | Path | None = None) -> Config:
    """Read a TOML configuration; no path gives the reference defaults."""
    if path is None:
        return Config()
    path = Path(path)
    if not path.is_file():
        raise SlamError(f"config file not found: {path}")
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SlamError(f"config file {path} is not valid TOML: {exc}") from None
    except RecursionError:
        raise SlamError(f"config file {path} nests its values too deeply") from None
    return config_from_dict(data, source=str(path))


def config_from_dict(data: dict, source: str = "config") -> Config:
    """Build a :class:`Config` from nested dictionaries, refusing unknown keys."""
    tables = {f.name: f.type for f in dataclasses.fields(Config)}
    unknown = sorted(set(data) - set(tables))
    if unknown:
        raise SlamError(f"{source}: unknown table(s) {unknown}; known tables are {sorted(tables)}")
    parts = {}
    for f in dataclasses.fields(Config):
        table = data.get(f.name, {})
        if not isinstance(table, dict):
            raise SlamError(f"{source}: [{f.name}] must be a table")
        parts[f.name] = _build(f.default_factory, table, f"{source} [{f.name}]")
    return Config(**parts)


def config_to_dict(config: Config) -> dict:
    """The configuration as plain nested dictionaries (for JSON or TOML)."""
    return {name: _plain(value) for name, value in dataclasses.asdict(config).items()}


def config_to_toml(config: Config) -> str:
    """The configuration as a TOML file that :func:`load_config` reads back."""
    lines = []
    for table, values in config_to_dict(config).items():
        lines.append(f"[{table}]")
        for key, value in values.items():
            lines.append(f"{key} = {_toml_value(value)}")
        lines.append("")
    return "\n".join(lines)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)


def _build(cls, table: dict, where: str):
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise SlamError(f"{where}: unknown key(s) {unknown}; known keys are {sorted(fields)}")
    values = {}
    for key, value in table.items():
        default = getattr(cls(), key)
        values[key] = _coerce(value, default, f"{where} {key}")
    return cls(**values)


def _coerce(value, default, where: str):
    """Give ``value`` the type of ``default``, or explain why it cannot have it."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise SlamError(f"{where} must be true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int) or not -(2**63) <= value < 2**63:
            raise SlamError(f"{where} must be a 64-bit integer, got {value!r}")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SlamError(f"{where} must be a number, got {value!r}")
        try:
            return float(value)
        except OverflowError:  # an integer beyond any float
            raise SlamError(f"{where} is too large a number") from None
    if isinstance(default, tuple):
        if not isinstance(value, list) or len(value) != len(default):
            raise SlamError(f"{where} must be a list of {len(default)} numbers, got {value!r}")
        return tuple(_coerce(v, d, where) for v, d in zip(value, default, strict=True))
    if isinstance(default, str):
        if not isinstance(value, str):
            raise SlamError(f"{where} must be a string, got {value!r}")
        return value
    raise TypeError(f"no coercion for {type(default).__name__}")  # a bug, not user input


def _triple(obj, name: str) -> tuple[float, float, float]:
    value = getattr(obj, name)
    if len(value) != 3:
        raise SlamError(f"[sensor] {name} must be [start, stop, step], got {value!r}")
    return tuple(float(v) for v in value)


def _check(obj, name: str, ok, expected: str) -> None:
    value = getattr(obj, name)
    if not ok(value):
        raise SlamError(f"[{_table_of(obj)}] {name} must be {expected}, got {value!r}")


def _table_of(obj) -> str:
    for f in dataclasses.fields(Config):
        if isinstance(obj, f.default_factory):
            return f.name
    return type(obj).__name__


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value
