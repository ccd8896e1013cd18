"""The embedded default scene: a procedural aerial map that plays the
reference tile's part.

The scene is a 2.5-D height field (one height per grid cell, as an airborne
lidar sees the world from above) with a class label per cell: rolling
terrain, roads, a lake, buildings with flat or gabled roofs, and trees. Every
random number comes from one seeded ``numpy.random.Generator`` and every
operation is deterministic, so the same seed gives the same scene bit for
bit on any machine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Class labels of the cells (and of the lidar returns that hit them).
GROUND, ROAD, WATER, BUILDING, TREE = range(5)
CLASS_NAMES = ("ground", "road", "water", "building", "tree")

DEFAULT_SEED = 7
DEFAULT_SIZE = (800.0, 600.0)  # m, x by y: a 440 x 240 m loop plus the swath
DEFAULT_CELL = 1.0  # m, as the reference's 1 m occupancy cells


@dataclass(frozen=True)
class HeightField:
    """Heights on a regular grid; cell (row i, column j) is centred at
    ``(x0 + j * cell, y0 + i * cell)``. Cells where ``valid`` is False hold
    no surface (rays pass through them)."""

    x0: float
    y0: float
    cell: float
    z: np.ndarray  # (ny, nx) float64, m
    labels: np.ndarray  # (ny, nx) uint8, one of the class labels above
    valid: np.ndarray  # (ny, nx) bool

    @property
    def shape(self) -> tuple[int, int]:
        return self.z.shape

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the cell centres."""
        ny, nx = self.z.shape
        return (self.x0, self.x0 + (nx - 1) * self.cell, self.y0, self.y0 + (ny - 1) * self.cell)

    def grid(self) -> tuple[np.ndarray, np.ndarray]:
        """x and y coordinates of every cell centre, each (ny, nx)."""
        ny, nx = self.z.shape
        return np.meshgrid(self.x0 + self.cell * np.arange(nx), self.y0 + self.cell * np.arange(ny))

    def cell_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row and column (i, j) of the cell whose centre is nearest each XY point (N, 2+), clipped to the grid."""
        ny, nx = self.z.shape
        j = np.clip(np.rint((xy[:, 0] - self.x0) / self.cell).astype(int), 0, nx - 1)
        i = np.clip(np.rint((xy[:, 1] - self.y0) / self.cell).astype(int), 0, ny - 1)
        return i, j

    def points(self) -> np.ndarray:
        """The valid cell centres as an (N, 3) array."""
        x, y = self.grid()
        return np.column_stack([x[self.valid], y[self.valid], self.z[self.valid]])


def default_scene(seed: int = DEFAULT_SEED, size=DEFAULT_SIZE, cell: float = DEFAULT_CELL) -> HeightField:
    """Generate the default aerial scene, centred on (0, 0)."""
    rng = np.random.default_rng(seed)
    nx, ny = round(size[0] / cell), round(size[1] / cell)
    x0, y0 = -(nx - 1) * cell / 2, -(ny - 1) * cell / 2
    x, y = np.meshgrid(x0 + cell * np.arange(nx), y0 + cell * np.arange(ny))

    # 1. Rolling terrain between about 85 and 115 m, with a little roughness.
    hills = _fractal_noise(rng, (ny, nx), cell, wavelength=350.0, beta=2.2)
    ground = 85.0 + 30.0 * (hills - hills.min()) / np.ptp(hills)
    ground += 0.15 * _fractal_noise(rng, (ny, nx), cell, wavelength=6.0, beta=1.0)
    z = ground.copy()
    labels = np.full((ny, nx), GROUND, np.uint8)

    # 2. A lake with a flat surface in the lowest part of a chosen basin.
    _add_lake(rng, x, y, z, labels)

    # 3. Roads: a few long gently curved strips, slightly below the terrain.
    for _ in range(5):
        _add_road(rng, x, y, z, labels, size)

    # 4. Buildings, clustered in a few neighbourhoods, stand on bare earth.
    bare = z.copy()
    towns = rng.uniform(-0.35, 0.35, (4, 2)) * np.array(size)
    for _ in range(260):
        centre = towns[rng.integers(len(towns))] + rng.normal(0, 70, 2)
        _add_building(rng, x0, y0, cell, centre, bare, z, labels)

    # 5. Trees, denser where a smooth "vegetation" field is high.
    vegetation = _fractal_noise(rng, (ny, nx), cell, wavelength=150.0, beta=2.0)
    candidates = rng.uniform([x0, y0], [x0 + (nx - 1) * cell, y0 + (ny - 1) * cell], (9000, 2))
    for cx, cy in candidates:
        i, j = int((cy - y0) / cell), int((cx - x0) / cell)
        if vegetation[i, j] > 0.3 or rng.random() < 0.04:
            _add_tree(rng, x0, y0, cell, (cx, cy), bare, z, labels)

    return HeightField(x0, y0, cell, z, labels, np.ones((ny, nx), bool))


def _fractal_noise(rng, shape, cell, wavelength, beta):
    """Zero-mean, unit-variance noise whose spectrum falls as 1/f**beta below
    ``1/wavelength`` (spectral synthesis with a real FFT)."""
    ny, nx = shape
    fy = np.fft.fftfreq(ny, d=cell)[:, None]
    fx = np.fft.rfftfreq(nx, d=cell)[None, :]
    f = np.hypot(fx, fy)
    f0 = 1.0 / wavelength
    amplitude = (np.maximum(f, f0) / f0) ** (-beta)
    amplitude[0, 0] = 0.0
    spectrum = (rng.standard_normal(f.shape) + 1j * rng.standard_normal(f.shape)) * amplitude
    field = np.fft.irfft2(spectrum, s=shape)
    return (field - field.mean()) / field.std()


def _add_lake(rng, x, y, z, labels):
    cx, cy = rng.uniform(-150, 150), rng.uniform(-120, 120)
    angle = np.arctan2(y - cy, x - cx)
    radius = 45.0 + 10 * np.sin(3 * angle + rng.uniform(0, 2 * np.pi)) + 6 * np.cos(5 * angle)
    d = np.hypot(x - cx, y - cy) / radius  # < 1 inside the shore
    inside = d < 1.0
    level = z[inside].min() - 0.5
    bank = np.clip((d - 1.0) / 0.4, 0.0, 1.0)  # shores slope down over 40 % of the radius
    near = d < 1.4
    z[near] = level + (z[near] - level) * bank[near] ** 2
    z[inside] = level
    labels[inside] = WATER


def _add_road(rng, x, y, z, labels, size):
    """A road: a straight centre line with a slow sinusoidal bend, 7-10 m wide."""
    theta = rng.uniform(0, np.pi)
    offset = rng.uniform(-0.4, 0.4) * min(size)
    u = x * np.cos(theta) + y * np.sin(theta)  # along the road
    v = -x * np.sin(theta) + y * np.cos(theta) - offset  # across it
    v = v - 25.0 * np.sin(u / rng.uniform(120, 250) + rng.uniform(0, 2 * np.pi))
    road = (np.abs(v) < rng.uniform(3.5, 5.0)) & (labels == GROUND)
    z[road] -= 0.15
    labels[road] = ROAD


def _window(x0, y0, cell, shape, cx, cy, half):
    """Row and column slices of the cells within ``half`` m of (cx, cy)."""
    ny, nx = shape
    i0, i1 = int((cy - half - y0) / cell), int((cy + half - y0) / cell) + 2
    j0, j1 = int((cx - half - x0) / cell), int((cx + half - x0) / cell) + 2
    i0, j0, i1, j1 = max(i0, 0), max(j0, 0), min(i1, ny), min(j1, nx)
    if i0 >= i1 or j0 >= j1:
        return None
    return slice(i0, i1), slice(j0, j1)


def _offsets(x0, y0, cell, window, centre):
    """x and y of the window's cells relative to ``centre``, each (rows, cols)."""
    rows, cols = window
    xs = x0 + cell * np.arange(cols.start, cols.stop)
    ys = y0 + cell * np.arange(rows.start, rows.stop)
    return np.meshgrid(xs - centre[0], ys - centre[1])


def _add_building(rng, x0, y0, cell, centre, bare, z, labels):
    length, width = rng.uniform(10, 42), rng.uniform(8, 22)
    height = rng.uniform(4, 14) if rng.random() < 0.85 else rng.uniform(18, 40)
    angle = rng.uniform(0, np.pi)
    gabled = rng.random() < 0.45 and height < 15
    window = _window(x0, y0, cell, z.shape, *centre, half=0.5 * np.hypot(length, width) + 1)
    if window is None:
        return
    rows, cols = window
    gx, gy = _offsets(x0, y0, cell, window, centre)
    u = gx * np.cos(angle) + gy * np.sin(angle)
    v = -gx * np.sin(angle) + gy * np.cos(angle)
    footprint = (np.abs(u) < length / 2) & (np.abs(v) < width / 2)
    # Keep clear of roads, water and other buildings (a 3 m margin).
    margin = (np.abs(u) < length / 2 + 3) & (np.abs(v) < width / 2 + 3)
    if not footprint.any() or (labels[rows, cols][margin] != GROUND).any():
        return
    base = bare[rows, cols][footprint].min()
    roof = np.full(footprint.shape, base + height)
    if gabled:  # ridge along the long axis, 35 degree pitch
        roof += np.tan(np.radians(35)) * (width / 2 - np.abs(v))
    elif rng.random() < 0.5:  # a plant room on a flat roof
        box = (np.abs(u - rng.uniform(-0.2, 0.2) * length) < 3) & (np.abs(v) < 2.5)
        roof += 2.5 * box
    z[rows, cols][footprint] = roof[footprint]
    labels[rows, cols][footprint] = BUILDING


def _add_tree(rng, x0, y0, cell, centre, bare, z, labels):
    radius, height = rng.uniform(1.8, 4.5), rng.uniform(6, 18)
    window = _window(x0, y0, cell, z.shape, *centre, half=radius)
    if window is None:
        return
    rows, cols = window
    gx, gy = _offsets(x0, y0, cell, window, centre)
    r = np.hypot(gx, gy) / radius
    crown = r < 1.0
    block = labels[rows, cols]
    if not crown.any() or np.isin(block[crown], (ROAD, WATER, BUILDING)).any():
        return
    ground = bare[rows, cols]
    top = ground + height * (0.35 + 0.65 * np.sqrt(np.clip(1.0 - r**2, 0.0, 1.0)))
    higher = crown & (top > z[rows, cols])
    z[rows, cols][higher] = top[higher]
    labels[rows, cols][higher] = TREE
