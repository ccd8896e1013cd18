"""Stage 1: the dataset. One call turns a map and a flight into lidar scans
with their ground-truth poses (the reference's ``helperCreateDataset``)."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from helpers import paths
from helpers.config.tables import SensorConfig, noise_seed_from_environment
from helpers.errors import SlamError
from helpers.geometry import transform_points
from helpers.progress import progress_bar
from helpers.sim.gnss import simulate_gnss
from helpers.sim.maps import IDENTITY_FRAME, MapFrame, height_field_from_points, read_map
from helpers.sim.risley import scan_motion
from helpers.sim.scene import HeightField, default_scene
from helpers.sim.sensor import (
    ScanBatch,
    Surface,
    cast_scans,
    check_coverage,
    check_heights,
    index_ranges,
    labels_at,
    poses_from_waypoints,
)
from helpers.sim.waypoints import DEFAULT_SPACING, loop_waypoints, read_waypoints

log = logging.getLogger(__name__)

DEFAULT_WAYPOINTS = paths.DATA / "default_waypoints.csv"  # the default flight, shipped in the package (.mat beside)
DEFAULT_SCENE = "default scene"  # a dataset's name when it is cast over the embedded scene
MAP_CELL = 1.0  # m, cell of the surface built from a LAS/LAZ tile (the reference's 1 m voxels)


class LazyScans(Sequence):
    """The scans of a flight, each cast when it is asked for and not kept:
    the same points as casting the whole flight at once (each scan's noise
    has its own seed), in memory that does not grow with the flight. A Risley
    scan's per-point times: :meth:`times` (the scan read last, or cast again)."""

    def __init__(self, surface: Surface, poses: np.ndarray, sensor: SensorConfig) -> None:
        self.surface, self.poses, self.sensor = surface, poses, sensor
        self.has_times = sensor.pattern == "risley"
        self.motion = scan_motion(poses, sensor) if self.has_times else None
        self._times_of, self._times = None, None  # the scan read last and its per-point times

    def __len__(self) -> int:
        return len(self.poses)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        index = range(len(self))[index]  # negative indices; IndexError past the end
        batch = self.cast(index, index + 1)
        if batch.times is not None:
            self._times_of, self._times = index, batch.times[0]
        return batch.scans[0]

    def times(self, index: int) -> np.ndarray | None:
        """Scan ``index``'s per-point times on the flight's clock, s (None for the fan, which scans in an instant)."""
        if not self.has_times:
            return None
        index = range(len(self))[index]
        if self._times_of != index:
            self[index]  # cast again; it keeps its times
        return self._times

    def cast(self, start: int, stop: int, progress=None) -> ScanBatch:
        """Scans ``start`` to ``stop - 1`` with their true hits."""
        motion = None if self.motion is None else self.motion[start:stop]
        return cast_scans(self.surface, self.poses[start:stop], self.sensor, progress, start, motion)


@dataclass
class Dataset:
    """Everything stage 1 produces."""

    scans: Sequence[np.ndarray]  # (Ni, 3) points per scan, sensor frame, m (a list, or LazyScans)
    poses: np.ndarray  # (N, 4, 4) ground-truth sensor poses in the map frame
    waypoints: np.ndarray  # (N, 3) ground-truth positions (the poses' translations)
    surface: HeightField  # the surface the rays were cast against
    frame: MapFrame  # original map coordinates -> map frame
    sensor: SensorConfig
    name: str
    truth: ScanBatch | None = None  # the true hits (None until first asked for, with LazyScans)
    gnss: np.ndarray | None = None  # (N, 3) simulated GNSS positions, map frame (None: no GNSS, the default)
    scan_times: list[np.ndarray] | None = None  # (Ni,) s of each point on the flight's clock (Risley, not lazy)

    def __len__(self) -> int:
        return len(self.scans)

    @property
    def has_times(self) -> bool:
        """Whether the scans' points carry times (the Risley pattern; the fan scans in an instant)."""
        return self.scan_times is not None or bool(getattr(self.scans, "has_times", False))

    def times(self, index: int) -> np.ndarray | None:
        """Scan ``index``'s per-point times from its start, s, or None: what ``run_slam(times=...)`` takes."""
        if self.scan_times is not None:
            return self.scan_times[index]
        return self.scans.times(index) if self.has_times else None

    @property
    def map_points(self) -> np.ndarray:
        """(M, 3) float32 union of every true (noise-free) hit: the ground-truth map."""
        return self._truth().hits

    @property
    def map_labels(self) -> np.ndarray:
        """(M,) class of each map point (see :mod:`helpers.sim.scene`), looked up on first use."""
        truth = self._truth()
        if truth.labels is None:
            truth.labels = labels_at(self.surface, truth.hits)
        return truth.labels

    def _truth(self) -> ScanBatch:
        if self.truth is None:  # lazy scans: cast the flight once more, keeping only the hits
            batch = self.scans.cast(0, len(self.scans))
            self.truth = ScanBatch([], batch.hits)
        return self.truth

    def scan_in_map(self, index: int) -> np.ndarray:
        """Scan ``index`` moved into the map frame by its ground-truth pose."""
        return transform_points(self.scans[index], self.poses[index])

    def surface_distances(self, points: np.ndarray) -> np.ndarray:
        """Distance (m) from map-frame points to the surface the rays hit."""
        import open3d as o3d

        query = o3d.core.Tensor(np.asarray(points, np.float32))
        return self._scene.compute_distance(query).numpy().astype(np.float64)

    @cached_property
    def _scene(self):
        """The surface's ray-casting scene, built on first use."""
        return Surface.from_height_field(self.surface).raycasting_scene()


@lru_cache(maxsize=2)
def _default_surface() -> HeightField:
    return default_scene()


def create_dataset(
    map_path=None, waypoints_path=None, sensor: SensorConfig | None = None, progress=False, lazy=False
) -> Dataset:
    """Simulate one lidar scan per waypoint: the reference's ``helperCreateDataset``.

    ``map_path``: a ``.las``/``.laz``, a ``.tar.gz`` holding one, or None for
    the embedded default scene. ``waypoints_path``: ``.mat`` (``gTruthTraj``)
    or ``.csv``, in the map's original coordinates; None flies the default
    loop (the shipped one on the default scene, one fitted to the tile
    otherwise). ``progress``: show a progress bar while casting. ``lazy``:
    cast each scan when it is read instead of all now (:class:`LazyScans`,
    for flights too long to hold; every read casts again, and an empty scan
    is then found by the step that reads it). ``sensor``: None is the default
    sensor with the noise seed of
    :func:`~helpers.config.tables.noise_seed_from_environment`.
    """
    sensor = sensor or SensorConfig(seed=noise_seed_from_environment())
    if map_path is None:
        field, frame, name = _default_surface(), IDENTITY_FRAME, DEFAULT_SCENE
    else:
        tile = read_map(map_path)
        field, frame, name = height_field_from_points(tile.points, tile.labels, MAP_CELL), tile.frame, tile.source

    given = None  # the frame of a waypoint file's coordinates, for errors in its own units
    if waypoints_path is not None:
        xyz, given = _to_map_frame(read_waypoints(waypoints_path), frame, field, sensor)
    elif map_path is None:
        xyz = _with_altitude(read_waypoints(DEFAULT_WAYPOINTS), sensor)
    else:
        xyz = _with_altitude(fitted_loop(field), sensor)

    check_coverage(field, xyz, given)
    check_heights(field, xyz, given)
    sensor.check_flight(len(xyz))
    sensor.check_waypoints(xyz)
    poses = poses_from_waypoints(xyz)
    surface = Surface.from_height_field(field)
    gnss = None
    if sensor.gnss:
        gnss = simulate_gnss(poses[:, :3, 3], sensor.gnss_sigma_horizontal, sensor.gnss_sigma_vertical, sensor.seed)
    if lazy:
        scans = LazyScans(surface, poses, sensor)
        return Dataset(scans, poses, xyz, field, frame, sensor, name, gnss=gnss)
    bar = progress_bar(len(poses), "casting scans", enabled=progress)
    try:
        batch = cast_scans(surface, poses, sensor, bar)
    finally:
        bar.close()
    empty = np.flatnonzero([len(s) == 0 for s in batch.scans])
    if len(empty):
        raise SlamError(
            f"{len(empty)} of {len(poses)} scans came back empty (indices {index_ranges(empty)}): "
            "those waypoints see no map within max_range"
        )
    truth = ScanBatch([], batch.hits)
    return Dataset(batch.scans, poses, xyz, field, frame, sensor, name, truth, gnss, batch.times)


def is_default(dataset: Dataset, sensor: SensorConfig) -> bool:
    """Whether ``dataset`` is the embedded default cast with ``sensor``: the default scene, the shipped loop."""
    if dataset.name != DEFAULT_SCENE or dataset.sensor != sensor:
        return False
    return np.array_equal(dataset.waypoints, _with_altitude(read_waypoints(DEFAULT_WAYPOINTS), sensor))


def fitted_loop(field: HeightField, spacing: float = DEFAULT_SPACING) -> np.ndarray:
    """A loop inside a tile: the default loop's shape scaled to 55 % of the
    tile's extent, centred on the tile."""
    xmin, xmax, ymin, ymax = field.bounds
    half_x, half_y = 0.55 * (xmax - xmin) / 2, 0.55 * (ymax - ymin) / 2
    corner = 0.5 * min(half_x, half_y)
    perimeter = 4 * (half_x + half_y) - (8 - 2 * np.pi) * corner
    loop = loop_waypoints(half_x, half_y, corner, spacing, overlap=0.1 * perimeter)
    return loop + np.array([(xmin + xmax) / 2, (ymin + ymax) / 2])


def _with_altitude(points: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    return np.column_stack([points[:, :2], np.full(len(points), sensor.altitude)])


def _to_map_frame(
    points: np.ndarray, frame: MapFrame, field: HeightField, sensor: SensorConfig
) -> tuple[np.ndarray, MapFrame]:
    """Waypoints given in the map's original coordinates move with the map;
    waypoints that already lie in the centred map frame are taken as they
    are (whichever reading leaves fewer of them outside the map). Returns them
    and the frame they were read in (``frame``, or the centred metric one), in
    whose coordinates and units an error about them speaks."""
    xmin, xmax, ymin, ymax = field.bounds

    def outside(xy):
        return np.sum((xy[:, 0] < xmin) | (xy[:, 0] > xmax) | (xy[:, 1] < ymin) | (xy[:, 1] > ymax))

    moved = frame.to_map(points)
    xy = moved if outside(moved) <= outside(points[:, :2]) else points[:, :2]
    if xy is not moved:
        log.info("waypoints already lie in the centred map frame: taken as they are")
    z = points[:, 2] * frame.scale_z if points.shape[1] == 3 else np.full(len(points), sensor.altitude)
    given = frame if xy is moved else IDENTITY_FRAME
    return np.column_stack([xy, z]), given
