"""The simulated lidar's table, ``[sensor]``: how the drone flies and what
its lidar casts (notebook 1).

It is the first table of :class:`helpers.config.tables.Config` and is imported from
there; it lives here, apart from the SLAM stages' tables, with the checks
that keep a ray fan and a flight within what a machine can cast and hold.
The ray casting itself is :mod:`helpers.sim.sensor` (which needs Open3D; this
module does not).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from helpers.config.bounds import (
    MAX_LENGTH,
    MAX_RANGE,
    MAX_RAYS_PER_FLIGHT,
    MAX_RAYS_PER_SCAN,
    POINT_BYTES,
    RAY_BYTES,
    BoundedTable,
    angle_count,
    human_size,
    param,
)
from helpers.errors import SlamError


@dataclass(frozen=True)
class SensorConfig(BoundedTable):
    """The simulated lidar and how it flies (notebook 1)."""

    TABLE: ClassVar[str] = "sensor"
    altitude: float = param(700.0, "flight height in metres (z in the map frame), constant")
    azimuth: tuple[float, float, float] = param((-13.0, 13.0, 0.08), "ray angles across track [start, stop, step] deg")
    elevation: tuple[float, float, float] = param((-2.5, 2.5, 0.2), "ray angles along track [start, stop, step] deg")
    max_range: float = param(800.0, "returns farther than this many metres are lost")
    range_noise: float = param(0.02, "standard deviation of the range error, metres")
    dropout: float = param(0.01, "probability that a ray gives no return")
    seed: int = param(0, "seed of the range noise and dropouts (and of the GNSS noise)")
    gnss_sigma_horizontal: float = param(
        0.0, "GNSS: sigma of the simulated positions' x and y, metres (0 with the vertical one: no GNSS, the default)"
    )
    gnss_sigma_vertical: float = param(0.0, "GNSS: sigma of the simulated positions' z, metres")

    def __post_init__(self):
        for name in ("azimuth", "elevation"):
            value = getattr(self, name)
            start, stop, step = value if len(value) == 3 else (math.nan,) * 3
            if not (-89.0 < start <= stop < 89.0 and 0 < step < math.inf):
                raise SlamError(
                    f"[sensor] {name} must be [start, stop, step] degrees with "
                    f"-89 < start <= stop < 89 and a finite step > 0, got {list(value)}"
                )
            if stop - start < step * (1 - 1e-9):  # angle_count would be 1
                raise SlamError(
                    f"[sensor] {name} must hold at least two angles (stop - start >= step), got {list(value)}: "
                    "a fan of one row or one column is a line, and scans of a line cannot be registered"
                )
        rays = math.prod((stop - start) / step + 1 for start, stop, step in (self.azimuth, self.elevation))
        if rays > MAX_RAYS_PER_SCAN:
            raise SlamError(
                f"[sensor] asks for {rays:.2g} rays per scan (about {human_size(rays * RAY_BYTES)} of ray "
                f"buffers); the limit is {MAX_RAYS_PER_SCAN:,} rays: use larger azimuth or elevation steps"
            )
        # From a deep-sea trench to the edge of space: every map's heights lie between.
        self._between("altitude", -10_000.0, 100_000.0, "a finite number of metres")
        self._between("max_range", 1.0, MAX_RANGE, "a positive number of metres")
        self._between("range_noise", 0.0, self.max_range, "zero or a positive number of metres up to max_range,")
        self._check("dropout", lambda v: 0 <= v < 1, "a probability in [0, 1)")
        self._check("seed", lambda v: isinstance(v, int) and v >= 0, "a non-negative integer")
        for name in ("gnss_sigma_horizontal", "gnss_sigma_vertical"):
            self._between(name, 0.0, MAX_LENGTH, "zero (no GNSS) or a positive number of metres")
        if (self.gnss_sigma_horizontal > 0) != (self.gnss_sigma_vertical > 0):
            raise SlamError(
                "[sensor] gnss_sigma_horizontal and gnss_sigma_vertical must both be 0 (no GNSS) or both be "
                f"positive, got {self.gnss_sigma_horizontal} and {self.gnss_sigma_vertical}: a receiver that "
                "knows one axis exactly does not exist"
            )

    @property
    def gnss(self) -> bool:
        """Whether the simulator writes GNSS positions (both sigmas positive)."""
        return self.gnss_sigma_horizontal > 0

    @property
    def rays_per_scan(self) -> int:
        return angle_count(*self.azimuth) * angle_count(*self.elevation)

    def check_flight(self, n_scans: int) -> None:
        """Refuse a flight whose scans together ask for more than :data:`~.bounds.MAX_RAYS_PER_FLIGHT` rays."""
        rays = n_scans * self.rays_per_scan
        if rays > MAX_RAYS_PER_FLIGHT:
            raise SlamError(
                f"{n_scans:,} scans of {self.rays_per_scan:,} rays ask for {rays:.2g} rays "
                f"(about {human_size(rays * POINT_BYTES)} of points); the limit is {MAX_RAYS_PER_FLIGHT:,} rays "
                "per flight: fly fewer waypoints or use larger angle steps"
            )
