"""The Risley-prism lidar (a Livox Mid-70-class sensor): its rays over a scan, each at its own time, and
the sensor's motion while it takes them.

Two counter-rotating wedge prisms steer one beam around a non-repetitive rosette
(:func:`helpers.config.sensor.prism_deviation`, first-order refraction after Li, Liu and Sun, Opt. Express
25(7):7677, 2017). A deviation of angle ``rho`` from the nadir towards azimuth ``psi`` is the sensor-frame
direction ``(sin rho cos psi, sin rho sin psi, -cos rho)``: every ray lies within half the field of view of
the nadir. The points of a scan are taken one every ``1 / point_rate`` s over ``scan_period`` while the drone
flies on, so each is cast from the pose of its own time. As a sensor's driver gives them, each point is its
range along its ray in the sensor's frame of that time, and the scan as a whole carries the pose of its
start: read in that one frame, it is smeared by the motion, and a deskew with the motion
(:mod:`helpers.slam.deskew`) puts it back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from helpers.config.sensor import SensorConfig, prism_deviation


def ray_times(sensor: SensorConfig) -> np.ndarray:
    """(k,) time of each ray of a scan from its start, s: ``0, 1 / point_rate, ...`` below ``scan_period``."""
    return np.arange(sensor.rays_per_scan) / sensor.point_rate


def risley_directions(sensor: SensorConfig, starts: np.ndarray) -> np.ndarray:
    """(n, k, 3) unit ray directions in the sensor frame of the scans that begin at ``starts`` (n,) on the
    prisms' clock (s), ray after ray in time."""
    times = np.asarray(starts, dtype=np.float64)[:, None] + ray_times(sensor)[None]
    deviation = prism_deviation(sensor.prism_rpm, sensor.field_of_view, times)
    rho = np.hypot(deviation[..., 0], deviation[..., 1])  # the angle from the nadir
    across = deviation * np.sinc(rho / np.pi)[..., None]  # sin(rho) towards the deviation's azimuth
    return np.concatenate([across, -np.cos(rho)[..., None]], axis=-1)


@dataclass(frozen=True)
class ScanMotion:
    """How the sensor moves while it takes each scan of a flight: from the scan's pose ``T`` (its start), the
    pose at time ``t`` is ``T @ [Rz(yaw_rate t), velocity t]``: a straight line and a steady turn."""

    velocity: np.ndarray  # (N, 3) m/s, in the sensor frame of the scan's start
    yaw_rate: np.ndarray  # (N,) rad/s about the sensor's z
    start: np.ndarray  # (N,) s, when the scan begins on the flight's clock (the prisms' angles follow it)

    def __len__(self) -> int:
        return len(self.start)

    def __getitem__(self, index: slice) -> ScanMotion:
        return ScanMotion(self.velocity[index], self.yaw_rate[index], self.start[index])

    def moving_rays(self, directions: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays (n, k, 3) at ``times`` (k,) of these n scans, in each scan's start frame: (where the sensor is
        at each ray's time, the ray's direction then)."""
        angle = self.yaw_rate[:, None] * times[None]  # (n, k)
        c, s = np.cos(angle), np.sin(angle)
        x, y = directions[..., 0], directions[..., 1]
        turned = np.stack([c * x - s * y, s * x + c * y, directions[..., 2]], axis=-1)
        return self.velocity[:, None, :] * times[None, :, None], turned


def scan_motion(poses: np.ndarray, sensor: SensorConfig) -> ScanMotion:
    """The motion during each scan of a flight of ``poses`` (N, 4, 4), one scan at each: from each pose to the
    next at ``sensor.speed`` (the time between them their distance over it), the position along the straight
    line and the heading turning evenly; the last scan goes on as the one before it. A repeated pose is a
    hover: no motion, and the clock moves on by one scan period."""
    poses = np.asarray(poses, dtype=np.float64)
    n = len(poses)
    velocity, yaw_rate, seconds = np.zeros((n, 3)), np.zeros(n), np.zeros(n)
    if n >= 2:
        step = poses[1:, :3, 3] - poses[:-1, :3, 3]
        distance = np.linalg.norm(step, axis=1)
        moving = distance > 0
        seconds[:-1] = np.where(moving, distance / sensor.speed, sensor.scan_period)
        rotations = poses[:, :3, :3]
        local = np.einsum("nji,nj->ni", rotations[:-1], step)  # R^T step: the step in the scan's start frame
        turn = np.einsum("nji,njk->nik", rotations[:-1], rotations[1:])  # R_i^T R_(i+1)
        yaw = np.arctan2(turn[:, 1, 0], turn[:, 0, 0])
        velocity[:-1] = np.where(moving[:, None], local / seconds[:-1, None], 0.0)
        yaw_rate[:-1] = np.where(moving, yaw / seconds[:-1], 0.0)
        velocity[-1], yaw_rate[-1] = velocity[-2], yaw_rate[-2]
    start = np.concatenate([[0.0], np.cumsum(seconds[:-1])]) if n else seconds
    return ScanMotion(velocity, yaw_rate, start)


def standing(n: int) -> ScanMotion:
    """``n`` scans taken standing still, each from the prisms' start."""
    return ScanMotion(np.zeros((n, 3)), np.zeros(n), np.zeros(n))
