"""Helpers for the aerial lidar SLAM tutorial.

Stage 1, the dataset::

    from helpers import create_dataset
    data = create_dataset()            # the embedded default scene and loop
    data.scans[0], data.poses[0]       # a scan (sensor frame) and its pose
"""

from . import display as _display

_display.select_offscreen_backend()  # before anything imports VTK

from .config import Config, SensorConfig, load_config  # noqa: E402
from .dataset import DEFAULT_WAYPOINTS, Dataset, create_dataset, write_dataset  # noqa: E402
from .errors import SlamError  # noqa: E402
from .scene import default_scene  # noqa: E402
from .waypoints import read_waypoints  # noqa: E402

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
__version__ = "0.1.0"
