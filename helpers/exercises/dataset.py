"""Checks for the exercises of notebook 1 (the dataset).

Each check computes its own answer from the data (a ray cast against the
same surface, the sensor's ray pattern) and prints one line (see
:func:`helpers.exercises.report`).
"""

from __future__ import annotations

import numpy as np

from helpers.exercises.report import report, unanswered
from helpers.sim.sensor import Surface, ray_pattern

HIT_TOLERANCE_M = 0.05  # a hit point this close to the true one is right
SPOT_RADIUS_M = 1.5  # a scan sees a spot when one of its returns lands this close (one grid cell of notebook 2)
HEIGHT_FIELD_M = 0.5  # a hit lies on the height field if a corner of its cell is this close in height


def _edge_ray(dataset, index: int) -> np.ndarray:
    """Where the leftmost ray of the fan (largest azimuth, elevation 0) from
    waypoint ``index`` meets the surface, in map coordinates (3,)."""
    a = np.radians(_azimuths(dataset.sensor).max())
    direction = np.array([0.0, np.sin(a), -np.cos(a)])
    pose = dataset.poses[index]
    return _cast(dataset, pose[:3, 3], pose[:3, :3] @ direction)


def check_edge_ray(hit, dataset, index: int) -> bool:
    """Exercise 1.1: ``hit`` (3,) is where the leftmost ray of scan ``index`` lands, in map coordinates."""
    hint = "cast one ray: origin the drone's position, direction the sensor-frame ray turned by the pose's rotation"
    if unanswered(hit):
        return report(False, "", "fill in `hit`: the point (x, y, z) where that ray meets the ground")
    hit = np.asarray(hit, dtype=float).reshape(-1)
    if hit.shape != (3,) or not np.isfinite(hit).all():
        return report(False, "", "the answer is one point: x, y, z in the map frame (inf means the ray missed)")
    truth = _edge_ray(dataset, index)
    pose = dataset.poses[index]
    if np.linalg.norm(hit - truth) <= HIT_TOLERANCE_M:
        return report(
            True,
            "the ray lands on the surface, at the height the height field gives there, left of the track"
            if _on_height_field(dataset.surface, truth) and _left_of_track(pose, truth)
            else "the ray lands where the ray caster says",
            hint,
        )
    local = np.linalg.inv(pose) @ np.append(truth, 1.0)
    mirrored = (pose @ (local * [1, -1, 1, 1]))[:3]  # the same ray on the drone's right
    if np.linalg.norm(hit[:2] - mirrored[:2]) < 5.0:
        return report(False, "", "that is the right ray on the wrong side: +y (positive azimuth) is the drone's left")
    if np.linalg.norm(hit[:2] - pose[:2, 3]) < 5.0:
        return report(False, "", "that point is under the drone: the edge ray leaves at the largest azimuth")
    if abs(np.linalg.norm(hit - pose[:3, 3]) - np.linalg.norm(truth - pose[:3, 3])) < 1.0:
        return report(False, "", "the range is right but the direction is not: turn the ray by the pose's rotation")
    return report(False, "", hint)


def _scans_seeing(dataset, index: int, radius: float = SPOT_RADIUS_M) -> list[int]:
    """The scans with a return within ``radius`` metres (horizontally, map
    frame) of the ground straight below waypoint ``index``."""
    spot = dataset.poses[index][:2, 3]
    seen = []
    for i, scan in enumerate(dataset.scans):
        if np.linalg.norm(dataset.poses[i][:2, 3] - spot) > np.linalg.norm(scan[:, :2], axis=1).max() + radius:
            continue  # the spot is beyond this scan's reach
        if np.any(np.linalg.norm(dataset.scan_in_map(i)[:, :2] - spot, axis=1) < radius):
            seen.append(i)
    return seen


def check_scans_seeing(count, dataset, index: int = 250) -> bool:
    """Exercise 1.2: ``count`` is how many scans of the flight see the spot
    straight below waypoint ``index`` (a return within 1.5 m of it)."""
    hint = f"a scan sees the spot when one of its returns, in the map frame, lands within {SPOT_RADIUS_M:g} m of it"
    if unanswered(count):
        return report(False, "", "fill in `count`: a whole number of scans")
    seen = _scans_seeing(dataset, index)
    if int(count) == len(seen):
        return report(
            True,
            "a spot under the track stays in view for about a footprint's length of flight",
            hint,
        )
    sensor = dataset.sensor
    depth = dataset.poses[index][2, 3] - float(np.median(dataset.scan_in_map(index)[:, 2]))
    spacing = np.linalg.norm(np.diff(dataset.poses[:, :2, 3], axis=0), axis=1).mean()
    predicted = 2 * depth * np.tan(np.radians(sensor.elevation[1])) / spacing
    if abs(float(count) - predicted) < 1.0 and round(float(count)) != len(seen):
        return report(False, "", "that is what the footprint's length predicts; count the scans themselves")
    return report(False, "", hint)


def _azimuths(sensor) -> np.ndarray:
    """The fan's azimuths (deg), read off its ray pattern: atan2(y, -z) of each ray."""
    rays = ray_pattern(sensor)
    return np.unique(np.round(np.degrees(np.arctan2(rays[:, 1], -rays[:, 2])), 9))


def _cast(dataset, origin, direction) -> np.ndarray:
    import open3d as o3d

    scene = Surface.from_height_field(dataset.surface).raycasting_scene()
    ray = np.concatenate([origin, direction]).astype(np.float32)[None]
    t = float(scene.cast_rays(o3d.core.Tensor(ray))["t_hit"].numpy()[0])
    return np.asarray(origin, float) + t * np.asarray(direction, float)


def _on_height_field(field, point) -> bool:
    i, j = field.cell_of(np.asarray(point, float)[None])
    corners = field.z[max(i[0] - 1, 0) : i[0] + 2, max(j[0] - 1, 0) : j[0] + 2]
    return bool(np.min(np.abs(corners - point[2])) < HEIGHT_FIELD_M)


def _left_of_track(pose, point) -> bool:
    return bool((np.linalg.inv(pose) @ np.append(point, 1.0))[1] > 0)
