"""What a configuration may ask for, and the checks that hold a table of
:mod:`helpers.config.tables` to it (with :func:`param`, how each table declares a value).

The bounds are generous for real use and far below what would exhaust a
machine or overflow a computation made from them (a squared distance, a
sigma's inverse square, a float32 range); each says why it is where it is.
"""

from __future__ import annotations

import math
from dataclasses import field
from typing import ClassVar

from helpers.errors import SlamError

# What a configuration may ask for.
MAX_RAYS_PER_SCAN = 1_000_000  # a thousand by a thousand rays: far denser than a survey lidar's fan
MAX_RAYS_PER_FLIGHT = 200_000_000  # all scans together: their returns (POINT_BYTES each) fit in a workstation
RAY_BYTES = 160  # memory a ray takes while its scan is cast, rounded up: for the size an error quotes
POINT_BYTES = 40  # memory a return keeps until the flight is written, rounded up: likewise
MAX_TRIALS = 1_000_000  # robust-fit hypotheses: their samples (24 bytes each) are held at once
MAX_NEIGHBORS = 1_000  # neighbours of a normal or FPFH: far more than a local surface needs
MAX_EDGES_BACK = 100  # each is one more registration per scan (and per loop query, for the loop limits)
MAX_ITERATIONS = 10_000  # ICP iterations: far more than a registration from a close guess takes
MAX_SCANS = 1_000_000  # waypoints of a flight, one scan each
MIN_GRID = 0.01  # m: a grid step finer than a centimetre is far below the lidar's noise
MAX_LENGTH = 1_000.0  # m: grid steps and distances; a kilometre spans a whole scan of a survey flight
MAX_RADIUS = 10_000.0  # m: a search radius beyond any tile a height field can hold (helpers.sim.maps.MAX_MAP_CELLS)
MAX_RANGE = 1_000_000.0  # m: lidar range; far beyond any lidar's and still finite in float32 rays
MIN_RMSE = 0.001  # m: RMSE thresholds; a millimetre is below any lidar's noise
MAX_SPEED = 1_000.0  # m/s: three times the speed of sound, beyond any aircraft that carries a lidar
MAX_ACCELERATION = 1_000.0  # m/s^2: a hundred g, beyond what any airframe survives
MAX_ANGULAR_ACCELERATION = 100_000.0  # deg/s^2: a full turn in about 0.1 s from rest, beyond any drone
MAX_SIGMAS = 100.0  # a gate in sigmas: beyond a few the Gaussian says nothing more; 100 already admits everything
MIN_SIGMA = 1e-6  # edge sigmas: an information of 1e12 already; 1e-300 would make it infinite


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


def param(default, help: str, reference: str | None = None):
    """A table's value: its default, its meaning and the reference's (MATLAB) name for it (None: ours alone)."""
    return field(default=default, metadata={"help": help, "reference": reference})


class BoundedTable:
    """Checks shared by the stage tables: each names its TOML table in ``TABLE``."""

    TABLE: ClassVar[str]

    def _check(self, name: str, ok, expected: str) -> None:
        value = getattr(self, name)
        if not ok(value):
            raise SlamError(f"[{self.TABLE}] {name} must be {expected}, got {value!r}")

    def _within(self, name: str, low: int, high: int) -> None:
        self._check(name, lambda v: low <= v <= high, f"an integer from {low:,} to {high:,}")

    def _between(self, name: str, low: float, high: float, what: str) -> None:
        """``low <= value <= high`` (NaN fails); ``what`` begins the sentence: 'a positive number of metres'."""
        self._check(name, lambda v: low <= v <= high, f"{what} from {low:g} to {high:g}")

    def _one_of(self, name: str, choices: tuple[str, ...]) -> None:
        self._check(name, lambda v: v in choices, f"one of {', '.join(choices)}")
