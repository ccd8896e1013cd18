"""Flight plans over a tile: the tutorial's loop, or the survey a mapping drone flies.

A loop comes back over the same ground on the same line, so every loop closure measures the same place:
a trajectory shrunk or stretched by a scale error still closes on itself. A survey is flown as parallel
strips whose swaths overlap sideways (20-40 % in practice), joined by turns outside the area of
interest, and a cross line over all of them: a loop between neighbouring strips, or between a strip and
the cross line, measures the offset across the track, which a shrunk trajectory gets wrong.

Plans are waypoints in the map frame (metres, the tile centred); :func:`write_plan` writes them in the
tile's own coordinates and units, as ``python -m helpers run --waypoints`` reads them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helpers.config.sensor import SensorConfig
from helpers.errors import SlamError
from helpers.paths import write_atomically
from helpers.sim.maps import MapFrame
from helpers.sim.scene import HeightField
from helpers.sim.waypoints import DEFAULT_SPACING, loop_waypoints

PATTERNS = ("loop", "survey")
PLAN_CELL = 5.0  # m, the grid on which the plan looks for ground: coarse enough to be quick, fine enough for a tile
HOLE_M = 20.0  # m, dropouts narrower than this (water, dark roofs) are ground a flight may cross
LOOP_SHARE = 0.55  # of the tile's extent the loop spans (the default loop's shape, scaled)
MIN_STRIPS = 2  # a survey needs neighbours to overlap


def swath_width(height: float, sensor: SensorConfig) -> float:
    """Metres across the track the lidar covers from ``height`` m above flat ground: the fan's widest azimuth
    either side, or the Risley rosette's circular field of view (its full cone angle)."""
    if sensor.pattern == "risley":
        widest = np.radians(sensor.field_of_view / 2.0)
    else:
        widest = np.radians(max(abs(sensor.azimuth[0]), abs(sensor.azimuth[1])))
    return 2.0 * height * float(np.tan(widest))


def ground_bounds(field: HeightField) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) of the largest axis-aligned rectangle of the tile that holds ground: real
    tiles are cut along a survey's edge, a road or a circle, and a plan over their empty corners would cast
    scans that see nothing. Dropouts inside the tile (water), and gaps narrower than :data:`HOLE_M` along
    its edge, count as ground."""
    from scipy import ndimage

    step = max(1, round(PLAN_CELL / field.cell))
    holes = max(1, round(HOLE_M / 2 / field.cell))
    ground = ndimage.binary_closing(np.pad(field.valid, holes), iterations=holes)[holes:-holes, holes:-holes]
    ground = ndimage.binary_fill_holes(ground)  # a lake or a dark roof inside the tile is ground to fly over
    ny, nx = ground.shape[0] // step, ground.shape[1] // step
    coarse = ground[: ny * step, : nx * step].reshape(ny, step, nx, step).all(axis=(1, 3))
    if not coarse.any():
        raise SlamError("the tile holds no patch of ground to fly over")
    gaps = np.vstack([np.zeros((1, nx), int), np.cumsum(~coarse, axis=0)])  # empty cells above each row, per column
    best, where = 0, None
    for top in range(ny):  # every band of rows: the longest run of columns with ground all the way down
        full = gaps[top + 1 :] - gaps[top] == 0  # (bands from top, nx)
        runs = _longest_runs(full)
        heights = np.arange(1, ny - top + 1)
        area = runs[:, 0] * heights
        k = int(np.argmax(area))
        if area[k] > best:
            best, where = area[k], (top, top + k + 1, runs[k, 1], runs[k, 1] + runs[k, 0])
    row0, row1, col0, col1 = where
    x0, y0, size = field.x0, field.y0, step * field.cell
    return (x0 + col0 * size, x0 + col1 * size - field.cell, y0 + row0 * size, y0 + row1 * size - field.cell)


def _longest_runs(full: np.ndarray) -> np.ndarray:
    """(R, 2): per row of the boolean (R, C), the length of its longest run of True and where it starts."""
    rows = full.shape[0]
    padded = np.pad(full, ((0, 0), (1, 1))).astype(np.int8)
    edges = np.diff(padded, axis=1)
    out = np.zeros((rows, 2), int)
    r_start, c_start = np.nonzero(edges == 1)
    _, c_stop = np.nonzero(edges == -1)
    if len(r_start):
        lengths = c_stop - c_start
        order = np.lexsort((-lengths, r_start))  # per row, the longest first
        first = np.r_[True, np.diff(r_start[order]) != 0]
        out[r_start[order][first], 0] = lengths[order][first]
        out[r_start[order][first], 1] = c_start[order][first]
    return out


def ground_height(field: HeightField, xy: np.ndarray) -> float:
    """The median ground height under the waypoints ``xy`` (N, 2), m."""
    return float(np.median(field.z[field.cell_of(xy)]))


def loop_plan(field: HeightField, height: float, laps: float = 2.2, spacing: float = DEFAULT_SPACING) -> np.ndarray:
    """(N, 3) a rounded-rectangle loop over the middle of the tile, flown ``laps`` times, ``height`` m above
    the median ground under it, a waypoint every ``spacing`` m."""
    _check(height, spacing)
    if not laps >= 1:
        raise SlamError(f"a loop is flown at least once, got {laps} laps")
    xmin, xmax, ymin, ymax = ground_bounds(field)
    half_x, half_y = LOOP_SHARE * (xmax - xmin) / 2, LOOP_SHARE * (ymax - ymin) / 2
    corner = 0.5 * min(half_x, half_y)
    lap = loop_waypoints(half_x, half_y, corner, spacing, overlap=0.0)[:-1]
    count = round(laps * len(lap))
    xy = lap[np.arange(count) % len(lap)] + [(xmin + xmax) / 2, (ymin + ymax) / 2]
    return _at_height(field, xy, height)


def survey_plan(
    field: HeightField,
    height: float,
    sensor: SensorConfig | None = None,
    overlap: float = 0.3,
    spacing: float = DEFAULT_SPACING,
) -> np.ndarray:
    """(N, 3) parallel strips along the tile's longer side, each swath overlapping the next by ``overlap``,
    joined by half-circle turns beyond the area of interest, then a cross line through the middle of all
    strips; ``height`` m above the median ground, a waypoint every ``spacing`` m. The whole plan, turns
    included, stays over the tile, so every scan sees ground."""
    _check(height, spacing)
    if not 0.0 <= overlap < 0.9:
        raise SlamError(f"the side overlap is a share of the swath from 0 to 0.9, got {overlap}")
    swath = swath_width(height, sensor or SensorConfig())
    gap = swath * (1.0 - overlap)  # between neighbouring strips' centre lines
    xmin, xmax, ymin, ymax = ground_bounds(field)
    along_x = (xmax - xmin) >= (ymax - ymin)
    length, width = (xmax - xmin, ymax - ymin) if along_x else (ymax - ymin, xmax - xmin)
    inset = swath / 2  # the swath's edge stays on the tile
    strips = int(np.floor((width - 2 * inset - gap) / gap)) + 1  # a gap is left for the way to the cross line
    reach = length / 2 - inset - gap / 2  # a strip's half length: its turn (radius gap / 2) stays on the tile
    if strips < MIN_STRIPS or reach <= gap:
        raise SlamError(
            f"a survey {height:g} m above the ground sweeps a {swath:.0f} m swath: the tile's ground "
            f"({xmax - xmin:.0f} x {ymax - ymin:.0f} m) holds fewer than {MIN_STRIPS} strips "
            f"{gap:.0f} m apart with room to turn; fly lower or choose a larger tile"
        )
    offsets = (np.arange(strips) - (strips - 1) / 2) * gap
    path = np.vstack([_strips(offsets, reach, gap / 2, spacing), _cross_line(offsets, reach, gap / 2, spacing)])
    xy = (path if along_x else path[:, ::-1]) + [(xmin + xmax) / 2, (ymin + ymax) / 2]
    return _at_height(field, xy, height)


def _strips(offsets: np.ndarray, reach: float, radius: float, spacing: float) -> np.ndarray:
    """The strips in local coordinates (x along, y across), flown back and forth, joined by half circles."""
    pieces = []
    for k, y in enumerate(offsets):
        forward = k % 2 == 0
        x = np.linspace(-reach, reach, int(np.ceil(2 * reach / spacing)) + 1)  # both ends, steps up to spacing
        pieces.append(np.column_stack([x if forward else -x, np.full(len(x), y)]))
        if k + 1 < len(offsets):  # a half circle to the next strip, beyond the end of this one
            end = reach if forward else -reach
            angles = np.linspace(0.0, np.pi, int(np.ceil(np.pi * radius / spacing)) + 1)[1:-1]
            side = 1.0 if forward else -1.0
            pieces.append(np.column_stack([end + side * radius * np.sin(angles), y + radius * (1 - np.cos(angles))]))
    return np.vstack(pieces)


def _cross_line(offsets: np.ndarray, reach: float, radius: float, spacing: float) -> np.ndarray:
    """From the end of the last strip to a cross line over every strip, in local coordinates: a turn out
    beyond the last strip, back along it to the middle, a quarter turn, then straight across all strips.
    Every turn has the strips' radius: the drone never turns on the spot."""
    sign = 1.0 if (len(offsets) - 1) % 2 == 0 else -1.0  # the last strip flew towards +x (1) or -x (-1)
    last, back = offsets[-1], offsets[-1] + 2 * radius
    half = np.linspace(0.0, np.pi, int(np.ceil(np.pi * radius / spacing)) + 1)[1:]
    turn = np.column_stack([sign * (reach + radius * np.sin(half)), last + radius * (1 - np.cos(half))])
    x = np.linspace(reach, radius, int(np.ceil((reach - radius) / spacing)) + 1)[1:]
    along = np.column_stack([sign * x, np.full(len(x), back)])
    quarter = np.linspace(0.0, np.pi / 2, int(np.ceil(np.pi / 2 * radius / spacing)) + 1)[1:]
    corner = np.column_stack([sign * radius * (1 - np.sin(quarter)), back - radius + radius * np.cos(quarter)])
    y = np.arange(back - radius - spacing, offsets[0] - radius - 1e-9, -spacing)
    return np.vstack([turn, along, corner, np.column_stack([np.zeros(len(y)), y])])


def _at_height(field: HeightField, xy: np.ndarray, height: float) -> np.ndarray:
    return np.column_stack([xy, np.full(len(xy), ground_height(field, xy) + height)])


def _check(height: float, spacing: float) -> None:
    if not (np.isfinite(height) and height > 0):
        raise SlamError(f"the flight height above the ground must be a positive number of metres, got {height}")
    if not (np.isfinite(spacing) and spacing > 0):
        raise SlamError(f"the waypoint spacing must be a positive number of metres, got {spacing}")


def write_plan(path: str | Path, waypoints: np.ndarray, frame: MapFrame) -> None:
    """Write map-frame ``waypoints`` (N, 3) as a CSV ``x,y,z`` in the tile's own coordinates and units, all
    or nothing."""
    rows = frame.to_tile(waypoints)
    write_atomically(path, lambda f: np.savetxt(f, rows, fmt="%.3f", delimiter=",", header="x,y,z", comments=""))
