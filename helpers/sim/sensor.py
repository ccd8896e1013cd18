"""The simulated aerial lidar: a fixed fan of rays (the reference's, the default) or a Risley
rosette (:mod:`.risley`), cast from every waypoint against a triangle surface with Open3D's
``RaycastingScene``.

Frames. The *sensor frame* has its origin at the waypoint, x along the
direction of travel, y to the left and z up; every ray points downwards. A
pose ``T`` (4 x 4) maps sensor coordinates to map coordinates:
``p_map = T[:3, :3] @ p_sensor + T[:3, 3]``.

A ray with azimuth ``a`` (across track) and elevation ``e`` (along track) has
the sensor-frame direction ``(sin e, cos e sin a, -cos e cos a)``; its angle
from the nadir ``theta`` obeys ``cos theta = cos e cos a``. The fan scans in an instant; a Risley scan's
points each carry their time and are cast from the pose of that time (:mod:`.risley`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import open3d as o3d

from helpers.config.bounds import angle_count
from helpers.config.sensor import SensorConfig
from helpers.errors import SlamError
from helpers.sim.risley import ScanMotion, ray_times, risley_directions, scan_motion
from helpers.sim.scene import HeightField

RAYS_PER_CAST = 200_000  # rays sent to Embree in one call (a 5 MB buffer, reused)


@dataclass(frozen=True)
class Surface:
    """A height field turned into triangles, ready for ray casting."""

    field: HeightField
    vertices: np.ndarray  # (V, 3) float32
    triangles: np.ndarray  # (T, 3) uint32

    @classmethod
    def from_height_field(cls, field: HeightField) -> Surface:
        nx = field.shape[1]
        x, y = field.grid()
        vertices = np.column_stack([x.ravel(), y.ravel(), field.z.ravel()]).astype(np.float32)
        # A grid square becomes two triangles when its four corners hold surface.
        v = field.valid
        square = v[:-1, :-1] & v[1:, :-1] & v[:-1, 1:] & v[1:, 1:]
        i, j = np.nonzero(square)
        a = i * nx + j  # lower-left corner
        b, c, d = a + 1, a + nx, a + nx + 1
        triangles = np.stack([np.column_stack([a, b, d]), np.column_stack([a, d, c])], axis=1)
        return cls(field, vertices, triangles.reshape(-1, 3).astype(np.uint32))

    @cached_property
    def scene(self) -> o3d.t.geometry.RaycastingScene:
        """The ray-casting scene, built on first use and kept."""
        return self.raycasting_scene()

    def raycasting_scene(self) -> o3d.t.geometry.RaycastingScene:
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(self.vertices), o3d.core.Tensor(self.triangles))
        return scene


def _angles(start: float, stop: float, step: float) -> np.ndarray:
    return np.radians(start + step * np.arange(angle_count(start, stop, step)))


def ray_pattern(sensor: SensorConfig) -> np.ndarray:
    """Unit ray directions in the sensor frame, (n_elevation * n_azimuth, 3),
    elevation-major (reshape to (n_elevation, n_azimuth, 3) for an image); for the Risley
    pattern, its first scan's rays (k, 3) in time order (:func:`.risley.ray_times`)."""
    if sensor.pattern == "risley":
        return risley_directions(sensor, np.zeros(1))[0]
    az = _angles(*sensor.azimuth)
    el = _angles(*sensor.elevation)
    e, a = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.sin(e), np.cos(e) * np.sin(a), -np.cos(e) * np.cos(a)], axis=-1)
    return d.reshape(-1, 3)


def poses_from_waypoints(waypoints: np.ndarray) -> np.ndarray:
    """Sensor poses (N, 4, 4) at the waypoints (N, 3), heading along the
    direction of travel, level (no roll or pitch). Where the drone does not
    move (a repeated waypoint) it keeps the heading it had before (at the
    start: the one it will take); a flight that never moves heads along +x."""
    waypoints = np.asarray(waypoints, dtype=np.float64)
    n = len(waypoints)
    step = np.gradient(waypoints[:, :2], axis=0) if n >= 2 else np.zeros((n, 2))
    moved = step.any(axis=1)
    if moved.any():
        step = step[np.maximum.accumulate(np.where(moved, np.arange(n), moved.argmax()))]
    yaw = np.arctan2(step[:, 1], step[:, 0])
    poses = np.tile(np.eye(4), (n, 1, 1))
    c, s = np.cos(yaw), np.sin(yaw)
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -s, s, c
    poses[:, :3, 3] = waypoints
    return poses


@dataclass
class ScanBatch:
    """What the lidar returned at every pose."""

    scans: list[np.ndarray]  # (Ni, 3) float64 points in the sensor frame (with noise)
    hits: np.ndarray  # (sum Ni, 3) float32 true surface points in the map frame, scan after scan
    labels: np.ndarray | None = None  # (sum Ni,) uint8 class of each hit's cell (None until asked: Dataset.map_labels)
    times: list[np.ndarray] | None = None  # (Ni,) s of each point on the flight's clock (Risley; the fan: None)


def cast_scans(
    surface: Surface,
    poses: np.ndarray,
    sensor: SensorConfig,
    progress=None,
    first_index=0,
    motion: ScanMotion | None = None,
) -> ScanBatch:
    """Cast the ray pattern from every pose and keep the returns.

    Ranges beyond ``max_range`` and misses give no point; each kept range gets
    Gaussian noise and each ray may drop out, from a generator seeded with
    ``(sensor.seed, scan index)``, so a scan does not depend on the others:
    ``poses`` are the flight's scans ``first_index``, ``first_index + 1``, ...,
    and casting them alone gives the same points as casting the whole flight.

    A Risley scan's rays are cast from the poses the drone passes during the scan, ``motion`` (the
    flight's, :func:`.risley.scan_motion`, for these poses; None: ``poses`` are the whole flight); each
    point comes back with its time on the flight's clock (``ScanBatch.times``: the scan's start,
    ``motion.start``, plus the ray's time in the scan) in the sensor's frame of that time, as a driver
    gives it, and the scan is given the pose of its start: the motion smears it until it is deskewed.
    """
    risley = sensor.pattern == "risley"
    if risley:
        motion = scan_motion(poses, sensor) if motion is None else motion
        times, pattern = ray_times(sensor), None
        k, stamps = len(times), []
    else:
        pattern = ray_pattern(sensor).astype(np.float32)
        k, stamps = len(pattern), None
    scene = surface.scene
    per_call = max(1, RAYS_PER_CAST // k)
    rays = np.empty((min(per_call, len(poses)), k, 6), np.float32)  # reused by every call
    hits = np.empty((len(poses) * k, 3), np.float32)
    scans, used = [], 0
    for first in range(0, len(poses), per_call):
        chunk = poses[first : first + per_call]
        n = len(chunk)
        batch = rays[:n]
        if risley:  # each ray from where the sensor is at its time, in the frame of the scan's start
            body = risley_directions(sensor, motion.start[first : first + n])  # (n, k, 3) in the sensor's frame
            offsets, directions = motion[first : first + n].moving_rays(body, times)
            rotations = chunk[:, :3, :3].transpose(0, 2, 1)  # rows times R^T: R @ each ray
            batch[..., :3] = chunk[:, None, :3, 3] + offsets @ rotations
            batch[..., 3:] = directions @ rotations
        else:
            batch[..., :3] = chunk[:, None, :3, 3]
            np.matmul(pattern[None], chunk[:, :3, :3].transpose(0, 2, 1).astype(np.float32), out=batch[..., 3:])
        t = scene.cast_rays(o3d.core.Tensor(batch.reshape(-1, 6)))["t_hit"].numpy().reshape(n, k)
        noise, kept = _noise_and_dropout(sensor, first_index + first, n, k)
        ok = (t <= sensor.max_range) & kept  # a miss is inf
        flat = np.flatnonzero(ok)  # flat indices are much faster to gather with than (scan, ray) pairs
        ray_of = flat % k
        t_ok = t.ravel()[flat]
        origin_and_direction = batch.reshape(-1, 6).take(flat, axis=0)
        hits[used : used + len(t_ok)] = origin_and_direction[:, :3] + t_ok[:, None] * origin_and_direction[:, 3:]
        per_scan = ok.sum(axis=1)
        ends = np.cumsum(per_scan)[:-1]  # where each scan's points end in the flat arrays
        if risley:  # the range along the ray in the sensor's frame of its time: no motion undone
            measured = (t_ok + noise.ravel()[flat])[:, None] * body.reshape(-1, 3).take(flat, axis=0)
            clock = times[ray_of] + np.repeat(motion.start[first : first + n], per_scan)  # the flight's
            stamps += np.split(clock, ends)
        else:
            measured = (t_ok + noise.ravel()[flat])[:, None] * pattern.take(ray_of, axis=0)
        if not np.isfinite(measured).all():  # the config bounds the noise; this keeps a NaN out of every later stage
            bad = first_index + first + np.unique(flat[~np.isfinite(measured).all(axis=1)] // k)
            raise SlamError(
                f"scans {index_ranges(bad)} came out with NaN or infinite points: "
                f"[sensor] range_noise = {sensor.range_noise:g} m is too large for float32 ranges"
            )
        scans += np.split(measured.astype(np.float64), ends)
        used += len(t_ok)
        if progress is not None:
            progress.update(n)
    hits = hits[:used]
    # the labels are looked up when asked for (labels_at: a quarter of the cast's time)
    return ScanBatch(scans, hits, times=stamps)


def _noise_and_dropout(sensor: SensorConfig, first: int, n: int, k: int):
    """Range noise (n, k) in metres and kept-ray mask (n, k) for scans
    first..first+n-1, each row from its own generator seeded with
    (seed, scan index)."""
    noise = np.zeros((n, k), np.float32)
    kept = np.ones((n, k), bool)
    for row in range(n):
        rng = np.random.default_rng([sensor.seed, first + row])
        if sensor.range_noise:
            noise[row] = rng.standard_normal(k, dtype=np.float32)
        if sensor.dropout:
            kept[row] = rng.random(k, dtype=np.float32) >= sensor.dropout
    return noise * np.float32(sensor.range_noise), kept


def labels_at(field: HeightField, points: np.ndarray) -> np.ndarray:
    """(N,) class of the cell of ``field`` under each of ``points`` (N, 2+), as :mod:`.scene` numbers them."""
    return field.labels[field.cell_of(points)]


def check_coverage(field: HeightField, waypoints: np.ndarray, frame=None) -> None:
    """Refuse waypoints whose XY lies outside the surface, naming them; the map's bounds in the coordinates and
    units of the waypoints' file when its ``frame`` (:class:`helpers.sim.maps.MapFrame`) is given."""
    xmin, xmax, ymin, ymax = field.bounds
    x, y = waypoints[:, 0], waypoints[:, 1]
    outside = np.flatnonzero((x < xmin) | (x > xmax) | (y < ymin) | (y > ymax))
    if len(outside):
        if frame is not None:
            (xmin, ymin, _), (xmax, ymax, _) = frame.to_tile(np.array([[xmin, ymin, 0.0], [xmax, ymax, 0.0]]))
        unit = unit_symbol(frame)
        raise SlamError(
            f"{len(outside)} of {len(waypoints)} waypoints leave the map "
            f"(x {xmin:.1f}..{xmax:.1f} {unit}, y {ymin:.1f}..{ymax:.1f} {unit}): indices {index_ranges(outside)}"
        )


def unit_symbol(frame=None) -> str:
    """The symbol of a map frame's unit ("m" without one)."""
    name = "metre" if frame is None else frame.unit_name
    return {"metre": "m", "foot": "ft", "US survey foot": "US survey ft"}.get(name, name)


def check_heights(field: HeightField, waypoints: np.ndarray, frame=None) -> None:
    """Refuse waypoints (N, 3) at or below the surface under them, naming
    them: a lidar under the ground sees nothing, or the surface's underside
    in a valley beyond, and either way no scan of the map. ``frame`` as :func:`check_coverage` takes it."""
    ground = field.z[field.cell_of(waypoints)]
    scale = 1.0 if frame is None else frame.scale_z  # the surface's height in the waypoints' file's units
    below = np.flatnonzero(waypoints[:, 2] <= ground)
    if len(below):
        raise SlamError(
            f"{len(below)} of {len(waypoints)} waypoints lie at or below the map's surface (indices "
            f"{index_ranges(below)}; the surface under them reaches {ground[below].max() / scale:.1f} "
            f"{unit_symbol(frame)}): fly higher "
            "([sensor] altitude, or the waypoints' z)"
        )


def index_ranges(indices: np.ndarray) -> str:
    """'3-7, 12, 40-41' for [3, 4, 5, 6, 7, 12, 40, 41]."""
    if len(indices) == 0:
        return ""
    breaks = np.flatnonzero(np.diff(indices) != 1)
    starts = np.r_[indices[0], indices[breaks + 1]]
    ends = np.r_[indices[breaks], indices[-1]]
    return ", ".join(f"{s}" if s == e else f"{s}-{e}" for s, e in zip(starts, ends, strict=True))
