"""Checks for the exercises of notebook 1 (the dataset).

Each check computes its own answer from the data (a ray cast against the
same surface, the sensor's ray pattern) and prints one line (see
:func:`helpers.exercises.report`).
"""

from __future__ import annotations

import numpy as np

from ..sensor import Surface, ray_pattern
from . import report, unanswered

HIT_TOLERANCE_M = 0.05  # a hit point this close to the true one is right
WIDTH_TOLERANCE_M = 0.5  # a footprint width this close to the formula's is right
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
        return report(False, "", hint)
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


def _footprint_width(sensor, depth: float) -> float:
    """Width (m) across the track of the strip the fan covers on flat ground ``depth`` metres below."""
    across = np.tan(np.radians(_azimuths(sensor)))
    return float(depth * (across.max() - across.min()))


def check_footprint_width(width_m, sensor, depth: float, scans=None) -> bool:
    """Exercise 1.2: ``width_m`` is the footprint's width on flat ground ``depth`` below the sensor;
    with ``scans``, the answer is also compared with the widths the scans measure."""
    hint = "the outermost rays leave at the first and last azimuth; each lands depth x tan(azimuth) to the side"
    if unanswered(width_m):
        return report(False, "", hint)
    width_m = float(width_m)
    truth = _footprint_width(sensor, depth)
    if abs(width_m - truth) <= WIDTH_TOLERANCE_M:
        seen = ""
        if scans is not None:
            measured = np.median([np.ptp(scan[:, 1]) for scan in scans])
            seen = f"; the scans measure {'within 5 %' if abs(measured / truth - 1) < 0.05 else 'further off'} of it"
        return report(True, f"the strip is about {truth / depth:.2f} times as wide as the drone is high{seen}", hint)
    if abs(width_m - truth / 2) <= WIDTH_TOLERANCE_M:
        return report(False, "", "that is half the strip: count both sides of the track")
    half_angle = np.radians(np.abs(_azimuths(sensor)).max())
    if abs(width_m - 2 * depth * np.sin(half_angle)) <= WIDTH_TOLERANCE_M:
        return report(False, "", "sine gives the point on a circle; flat ground is met at depth x tan(angle)")
    return report(False, "", hint + " (angles in radians)")


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
