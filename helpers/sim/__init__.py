"""The world the drone flies in: the simulator. Nothing here knows the estimator.

- :mod:`~helpers.sim.scene`: the embedded default scene, a height field with classes;
- :mod:`~helpers.sim.maps` and :mod:`~helpers.sim.las`: aerial tiles (LAS/LAZ, the reference's ``.tar.gz``) read
  as a surface; :mod:`~helpers.sim.tiles`: procedural tiles as sparse as real ones;
- :mod:`~helpers.sim.waypoints`: flights from CSV or MAT files, or fitted to a map;
- :mod:`~helpers.sim.sensor`: the lidar's rays, cast on the surface;
- :mod:`~helpers.sim.dataset`: the reference's ``helperCreateDataset``: a scan per waypoint, the true poses;
- :mod:`~helpers.sim.gnss`: simulated position fixes, and GNSS files read;
- :mod:`~helpers.sim.ply`, :mod:`~helpers.sim.trajectories`: the point and pose files the simulator writes;
- :mod:`~helpers.sim.reference_files`: the default flight in the reference's own file formats (``data/``).
"""

from helpers import lazy_exports

EXPORTS = {
    "CLASS_NAMES": "helpers.sim.scene",
    "HeightField": "helpers.sim.scene",
    "default_scene": "helpers.sim.scene",
    "LAS_CLASSES": "helpers.sim.maps",
    "height_field_from_points": "helpers.sim.maps",
    "read_map": "helpers.sim.maps",
    "TILE_DENSITY": "helpers.sim.tiles",
    "TILE_SIZE": "helpers.sim.tiles",
    "low_flight": "helpers.sim.tiles",
    "sparse_tile": "helpers.sim.tiles",
    "read_waypoints": "helpers.sim.waypoints",
    "loop_waypoints": "helpers.sim.waypoints",
    "Surface": "helpers.sim.sensor",
    "poses_from_waypoints": "helpers.sim.sensor",
    "ray_pattern": "helpers.sim.sensor",
    "DEFAULT_WAYPOINTS": "helpers.sim.dataset",
    "Dataset": "helpers.sim.dataset",
    "create_dataset": "helpers.sim.dataset",
    "GnssFixes": "helpers.sim.gnss",
    "read_gnss": "helpers.sim.gnss",
    "simulate_gnss": "helpers.sim.gnss",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
