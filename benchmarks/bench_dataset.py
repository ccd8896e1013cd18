"""Dataset creation speed on the embedded default (689 scans of 8476 rays).

Prints scans per second end to end (scene generation aside, surface build
and ray-tracer set-up included) and for the steady-state casting alone.
Run: .venv/bin/python benchmarks/bench_dataset.py
"""

import time

import numpy as np

import helpers
from helpers.config.tables import SensorConfig
from helpers.sim.dataset import _default_surface
from helpers.sim.sensor import Surface, cast_scans, poses_from_waypoints, ray_pattern

REPEATS = 3


def main():
    start = time.perf_counter()
    field = _default_surface()
    print(f"scene generation: {time.perf_counter() - start:.2f} s ({field.shape[1]} x {field.shape[0]} cells)")

    sensor = SensorConfig()
    xy = helpers.read_waypoints(helpers.DEFAULT_WAYPOINTS)
    poses = poses_from_waypoints(np.column_stack([xy, np.full(len(xy), sensor.altitude)]))
    rays = len(ray_pattern(sensor))

    runs = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        data = helpers.create_dataset()
        runs.append(time.perf_counter() - start)
    best = min(runs)
    print(f"create_dataset: {len(data)} scans in {best:.2f} s = {len(data) / best:.0f} scans/s end to end")

    surface = Surface.from_height_field(field)
    cast_scans(surface, poses[:1], sensor)  # warm-up
    scene_build = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        scene = surface.raycasting_scene()
        import open3d as o3d

        scene.cast_rays(o3d.core.Tensor(np.array([[0, 0, 700, 0, 0, -1]], np.float32)))
        scene_build.append(time.perf_counter() - start)
    casting = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        cast_scans(surface, poses, sensor)
        casting.append(time.perf_counter() - start - min(scene_build))
    steady = min(casting)
    print(f"ray-tracer set-up (BVH over {len(surface.triangles):,} triangles): {min(scene_build):.2f} s")
    print(
        f"casting + noise + points: {len(poses) / steady:.0f} scans/s "
        f"({len(poses) * rays / steady / 1e6:.1f} M rays/s, {rays} rays a scan)"
    )


if __name__ == "__main__":
    main()
