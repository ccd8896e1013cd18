"""Helpers for the aerial lidar SLAM tutorial.

Stage 1, the dataset::

    from helpers import create_dataset
    data = create_dataset()            # the embedded default scene and loop
    data.scans[0], data.poses[0]       # a scan (sensor frame) and its pose

Importing the package sets nothing (no environment variable, no matplotlib
back end); pictures live in :mod:`helpers.viz`, the site in :mod:`helpers.site`.
"""

from .config import Config, SensorConfig
from .configfile import load_config
from .dataset import DEFAULT_WAYPOINTS, Dataset, create_dataset, write_dataset
from .errors import SlamError
from .scene import default_scene
from .waypoints import read_waypoints

__all__ = [
    "DEFAULT_WAYPOINTS",
    "Config",
    "Dataset",
    "SensorConfig",
    "SlamError",
    "create_dataset",
    "default_scene",
    "load_config",
    "read_waypoints",
    "write_dataset",
]
__version__ = "0.2.0"
