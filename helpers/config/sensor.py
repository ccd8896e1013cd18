"""The simulated lidar's table, ``[sensor]``: how the drone flies and what
its lidar casts (notebook 1).

It is the first table of :class:`helpers.config.tables.Config` and is imported from
there; it lives here, apart from the SLAM stages' tables, with the checks
that keep a ray pattern and a flight within what a machine can cast and hold,
and the Risley prisms' first-order deviation those checks measure (:func:`prism_deviation`).
The ray casting itself is :mod:`helpers.sim.sensor` and :mod:`helpers.sim.risley`
(which need Open3D; this module does not).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from helpers.config.bounds import (
    MAX_LENGTH,
    MAX_RANGE,
    MAX_RAYS_PER_FLIGHT,
    MAX_RAYS_PER_SCAN,
    MAX_SPEED,
    POINT_BYTES,
    RAY_BYTES,
    BoundedTable,
    angle_count,
    human_size,
    param,
)
from helpers.errors import SlamError

PATTERNS = ("fan", "risley")
MAX_PRISM_RPM = 60_000.0  # a thousand turns a second: beyond any motor that spins a prism
MAX_FIELD_OF_VIEW = 170.0  # deg: a wider cone around the nadir looks at the horizon
FILL_CELLS = 32  # the Risley field's fill is measured on square cells of 1/32 of its diameter (about 730 in the disc)
MIN_FILL = 0.9  # share of those cells one scan's rays must reach: the rosette fills the field


@dataclass(frozen=True)
class SensorConfig(BoundedTable):
    """The simulated lidar and how it flies (notebook 1)."""

    TABLE: ClassVar[str] = "sensor"
    altitude: float = param(700.0, "flight height in metres (z in the map frame), constant")
    pattern: str = param(
        "fan",
        "fan: the reference's fixed fan, an instant at each waypoint (azimuth, elevation); risley: the rosette of "
        "two counter-rotating Risley prisms, a Livox Mid-70-class sensor, each point at its own time in the scan "
        "(prism_rpm to speed). Each pattern ignores the other's keys",
    )
    azimuth: tuple[float, float, float] = param(
        (-13.0, 13.0, 0.08), "fan: ray angles across track [start, stop, step] deg (ignored by risley)"
    )
    elevation: tuple[float, float, float] = param(
        (-2.5, 2.5, 0.2), "fan: ray angles along track [start, stop, step] deg (ignored by risley)"
    )
    prism_rpm: tuple[float, float] = param(
        (17_000.0, -10_307.0),
        "risley: the two prisms' rotation rates, turns a minute, opposite signs for counter-rotating (ours: their "
        f"rosette reaches at least {MIN_FILL:.0%} of the field's cells within one scan, and repeats only after a "
        "minute); ignored by the fan",
    )
    field_of_view: float = param(70.4, "risley: full angle of the circular field around the nadir, deg (fan: ignored)")
    point_rate: float = param(
        100_000.0,
        f"risley: points a second; a scan holds point_rate x scan_period, at most {MAX_RAYS_PER_SCAN:,} (fan: ignored)",
    )
    scan_period: float = param(
        0.1,
        "risley: seconds a scan lasts, its points taken one after the other over it; no longer than the time between "
        "two waypoints (fan: ignored)",
    )
    speed: float = param(
        10.0,
        "risley: the drone's speed along the waypoints, m/s; the time between two waypoints is their distance over "
        "it, and the sensor's pose at each point's time lies between them (fan: ignored, it scans in an instant)",
    )
    max_range: float = param(800.0, "returns farther than this many metres are lost")
    range_noise: float = param(0.02, "standard deviation of the range error, metres")
    dropout: float = param(0.01, "probability that a ray gives no return")
    seed: int = param(0, "seed of the range noise and dropouts (and of the GNSS noise)")
    gnss_sigma_horizontal: float = param(
        0.0, "GNSS: sigma of the simulated positions' x and y, metres (0 with the vertical one: no GNSS, the default)"
    )
    gnss_sigma_vertical: float = param(0.0, "GNSS: sigma of the simulated positions' z, metres")

    def __post_init__(self):
        self._one_of("pattern", PATTERNS)
        self._check_fan()
        self._check_risley()
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

    def _check_fan(self) -> None:
        """The fan's angles and the memory its rays need (checked whatever the pattern, as every key is bounded)."""
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

    def _check_risley(self) -> None:
        """The Risley keys' bounds (whatever the pattern: each key is bounded), then, for the Risley pattern, the
        memory a scan's rays need and whether one scan's rosette fills the field."""
        rates = self.prism_rpm
        if not (len(rates) == 2 and all(-MAX_PRISM_RPM <= r <= MAX_PRISM_RPM for r in rates)):
            raise SlamError(
                f"[sensor] prism_rpm must be two rotation rates from {-MAX_PRISM_RPM:g} to {MAX_PRISM_RPM:g} turns "
                f"a minute, got {list(rates)}"
            )
        self._between("field_of_view", 1.0, MAX_FIELD_OF_VIEW, "a full cone angle in degrees")
        self._between("point_rate", 1.0, 1e9, "a positive number of points a second")
        self._between("scan_period", 1e-3, 10.0, "a positive number of seconds")
        self._between("speed", 1e-3, MAX_SPEED, "a positive number of metres per second")
        if self.pattern != "risley":
            return
        rays = self.point_rate * self.scan_period
        if rays > MAX_RAYS_PER_SCAN:
            raise SlamError(
                f"[sensor] point_rate = {self.point_rate:g} a second over scan_period = {self.scan_period:g} s asks "
                f"for {rays:.2g} rays per scan (about {human_size(rays * RAY_BYTES)} of ray buffers); the limit is "
                f"{MAX_RAYS_PER_SCAN:,} rays: lower point_rate or scan_period"
            )
        fill = self.fill()
        if fill < MIN_FILL:
            raise SlamError(
                f"[sensor] prism_rpm = {list(rates)} with point_rate = {self.point_rate:g} and scan_period = "
                f"{self.scan_period:g} s reach only {fill:.0%} of the field's cells in one scan (squares of "
                f"1/{FILL_CELLS} of its width); the limit is {MIN_FILL:.0%}: faster prisms, a longer scan or rates "
                "whose ratio is no ratio of small integers (those repeat)"
            )

    @property
    def gnss(self) -> bool:
        """Whether the simulator writes GNSS positions (both sigmas positive)."""
        return self.gnss_sigma_horizontal > 0

    @property
    def rays_per_scan(self) -> int:
        if self.pattern == "risley":
            return risley_points(self.point_rate, self.scan_period)
        return angle_count(*self.azimuth) * angle_count(*self.elevation)

    def fill(self) -> float:
        """The share of the field's cells (squares of 1/:data:`FILL_CELLS` of its diameter, wholly inside its
        disc) that one scan's rosette reaches, from the prisms' start: the measure of "fills the field"."""
        times = np.arange(self.rays_per_scan) / self.point_rate
        return field_fill(prism_deviation(self.prism_rpm, self.field_of_view, times), self.field_of_view)

    def check_flight(self, n_scans: int) -> None:
        """Refuse a flight whose scans together ask for more than :data:`~.bounds.MAX_RAYS_PER_FLIGHT` rays."""
        rays = n_scans * self.rays_per_scan
        if rays > MAX_RAYS_PER_FLIGHT:
            fewer = "lower point_rate" if self.pattern == "risley" else "use larger angle steps"
            raise SlamError(
                f"{n_scans:,} scans of {self.rays_per_scan:,} rays ask for {rays:.2g} rays "
                f"(about {human_size(rays * POINT_BYTES)} of points); the limit is {MAX_RAYS_PER_FLIGHT:,} rays "
                f"per flight: fly fewer waypoints or {fewer}"
            )

    def check_waypoints(self, waypoints: np.ndarray) -> None:
        """Refuse a Risley scan that outlasts the step to the next waypoint (their distance at ``speed``): its
        pose would run past that waypoint. Waypoints that repeat (the drone hovers) take no time to reach."""
        if self.pattern != "risley" or len(waypoints) < 2:
            return
        steps = np.linalg.norm(np.diff(np.asarray(waypoints, dtype=np.float64), axis=0), axis=1)
        moving = np.flatnonzero(steps > 0)
        if len(moving) == 0:
            return
        i = moving[np.argmin(steps[moving])]
        shortest = steps[i] / self.speed
        if self.scan_period > shortest * (1 + 1e-9):
            raise SlamError(
                f"[sensor] scan_period = {self.scan_period:g} s is longer than the {shortest:.3g} s between "
                f"waypoints {i} and {i + 1} ({steps[i]:.3g} m apart at speed = {self.speed:g} m/s): the limit is "
                f"{shortest:.3g} s; shorten the scan, fly slower or space the waypoints at least "
                f"{self.scan_period * self.speed:.3g} m apart"
            )


def risley_points(point_rate: float, scan_period: float) -> int:
    """Points in a Risley scan: one every ``1 / point_rate`` s from its start, within ``[0, scan_period)``."""
    return max(1, math.ceil(point_rate * scan_period - 1e-9))


def prism_deviation(prism_rpm, field_of_view: float, times: np.ndarray) -> np.ndarray:
    """Where two rotating Risley prisms send the beam at ``times`` (s, any shape): (..., 2) deviations from the
    optical axis, radians, as a small-angle vector (x, y); the prisms start at angle 0 at time 0.

    First-order (thin-prism) refraction, as in A. Li, X. Liu and W. Sun, "Forward and inverse solutions for
    three-element Risley prism beam scanners", Opt. Express 25(7):7677, 2017 (doi:10.1364/OE.25.007677): a
    prism of index n and wedge angle alpha deviates the beam by delta = (n - 1) alpha towards its own
    azimuth, and two prisms' deviations add as vectors, each turning with its prism:
    ``delta (cos 2 pi f1 t, sin 2 pi f1 t) + delta (cos 2 pi f2 t, sin 2 pi f2 t)``. Equal deltas of a quarter
    of ``field_of_view`` each make the rosette pass through the nadir and reach the field's edge.
    """
    delta = math.radians(field_of_view) / 4
    times = np.asarray(times, dtype=np.float64)
    x, y = np.zeros_like(times), np.zeros_like(times)
    for rpm in prism_rpm:
        turns = rpm / 60.0 * times
        angle = 2 * np.pi * (turns - np.floor(turns))  # the fraction of a turn keeps long flights' times exact
        x += delta * np.cos(angle)
        y += delta * np.sin(angle)
    return np.stack([x, y], axis=-1)


def field_fill(deviation: np.ndarray, field_of_view: float) -> float:
    """The share of a circular field's cells (squares of 1/:data:`FILL_CELLS` of its diameter that lie wholly
    inside its disc) holding at least one of ``deviation`` (N, 2), radians from its centre."""
    radius = math.radians(field_of_view) / 2
    cell = 2 * radius / FILL_CELLS
    edges = (np.arange(FILL_CELLS + 1) - FILL_CELLS / 2) * cell
    centres = (edges[:-1] + edges[1:]) / 2
    x, y = np.meshgrid(np.abs(centres) + cell / 2, np.abs(centres) + cell / 2, indexing="ij")
    inside = np.hypot(x, y) <= radius  # the cell's farthest corner lies in the disc
    counts, _, _ = np.histogram2d(deviation[:, 0], deviation[:, 1], bins=[edges, edges])
    return float((counts[inside] > 0).mean())
