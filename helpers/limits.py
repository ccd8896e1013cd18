"""What a configuration may ask for, and the checks that hold a table of
:mod:`helpers.config` to it.

The bounds are generous for real use and far below what would exhaust a
machine or overflow a computation made from them (a squared distance, a
sigma's inverse square, a float32 range); each says why it is where it is.
"""

from __future__ import annotations

import math
from typing import ClassVar

from .errors import SlamError

# What a configuration may ask for.
MAX_RAYS_PER_SCAN = 1_000_000  # 118 times the default fan (326 x 26 = 8476 rays)
MAX_RAYS_PER_FLIGHT = 200_000_000  # all scans together: 34 times the default flight (689 scans)
RAY_BYTES = 160  # memory a ray takes while its scan is cast (measured 157 on a 325k-ray fan)
POINT_BYTES = 40  # memory a return keeps until the flight is written (measured 37)
MAX_TRIALS = 1_000_000  # robust-fit hypotheses (the default draws 3000; their samples take 24 bytes each)
MAX_NEIGHBORS = 1_000  # neighbours of a normal or FPFH (the default takes 60)
MAX_EDGES_BACK = 100  # each is one more registration per scan (the default makes 4)
MAX_ITERATIONS = 10_000  # ICP iterations
MAX_SCANS = 1_000_000  # waypoints of a flight, one scan each (1450 times the default flight)
MIN_GRID = 0.01  # m: a grid step finer than a centimetre is far below the lidar's noise
MAX_LENGTH = 1_000.0  # m: grid steps and distances; a kilometre is a whole scan's width at the default height
MAX_RADIUS = 10_000.0  # m: a search radius beyond any tile (MAX_MAP_CELLS at 1 m is about 7 km across)
MAX_RANGE = 1_000_000.0  # m: lidar range; a thousand times the default and still finite in float32 rays
MIN_RMSE = 0.001  # m: RMSE thresholds; a millimetre is below any lidar's noise
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
