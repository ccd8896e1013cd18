"""Ground unlike the default one, for notebook 8: the default scene resampled
as a real tile is sampled, and a low flight over it.

The default scene is a dense 1 m height field and its flight is 600 m above
the ground, where the parameters were found. Tiles users bring are sparser
(one or two points per m²) and are often flown far lower. :func:`sparse_tile`
takes a square of a scene, keeps random points at a tile's density and
rebuilds the surface from them as :func:`helpers.sim.dataset.create_dataset`
does for a LAS tile; :func:`low_flight` flies the loop fitted to that tile
``above`` metres over its ground, its scans cast lazily.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from helpers.config.tables import SensorConfig
from helpers.errors import SlamError
from helpers.sim.dataset import MAP_CELL, Dataset, LazyScans, fitted_loop
from helpers.sim.maps import IDENTITY_FRAME, height_field_from_points
from helpers.sim.scene import HeightField
from helpers.sim.sensor import Surface, check_coverage, poses_from_waypoints

TILE_DENSITY = 1.8  # points per m², as the real tiles of 1-2 points per m² the issue reports
TILE_SIZE = 300.0  # m, the side of the square, about a real tile's


def sparse_tile(field: HeightField, density: float = TILE_DENSITY, size: float = TILE_SIZE, seed: int = 0):
    """A ``size`` m square from the middle of ``field``, sampled at ``density``
    random points per m² (heights interpolated, each point the class of its
    cell) and rebuilt as a tile is: a 1 m first-surface height field."""
    xmin, xmax, ymin, ymax = field.bounds
    if not (density > 0 and 0 < size <= min(xmax - xmin, ymax - ymin)):
        raise SlamError(f"a sparse tile needs a positive density and a size within the scene, got {density}, {size}")
    rng = np.random.default_rng(seed)
    centre = np.array([(xmin + xmax) / 2, (ymin + ymax) / 2])
    xy = rng.uniform(centre - size / 2, centre + size / 2, (int(density * size**2), 2))
    x, y = field.grid()
    z = RegularGridInterpolator((y[:, 0], x[0]), field.z)(xy[:, ::-1])
    return height_field_from_points(np.column_stack([xy, z]), field.labels[field.cell_of(xy)], MAP_CELL)


def low_flight(
    field: HeightField, above: float, scans: int | None = None, seed: int = 0, name: str = "low flight"
) -> Dataset:
    """The loop fitted to ``field`` (:func:`helpers.sim.dataset.fitted_loop`), or
    its first ``scans`` waypoints, flown at ``above`` metres over the median
    ground under it, with the default lidar (noise ``seed``); scans are cast
    when read."""
    xy = fitted_loop(field)[:scans]
    if not (above > 0 and len(xy) >= 2):
        raise SlamError(f"a flight needs to be above the ground and at least 2 scans long, got {above} m, {len(xy)}")
    altitude = float(np.median(field.z[field.cell_of(xy)])) + above
    sensor = SensorConfig(altitude=altitude, seed=seed)
    waypoints = np.column_stack([xy, np.full(len(xy), altitude)])
    check_coverage(field, waypoints)
    poses = poses_from_waypoints(waypoints)
    scans = LazyScans(Surface.from_height_field(field), poses, sensor)
    return Dataset(scans, poses, waypoints, field, IDENTITY_FRAME, sensor, name)
