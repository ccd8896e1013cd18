"""Helpers for the aerial lidar SLAM tutorial.

Stage 1, the dataset::

    from helpers import create_dataset
    data = create_dataset()            # the embedded default scene and loop
    data.scans[0], data.poses[0]       # a scan (sensor frame) and its pose

The SLAM itself, one scan at a time (:mod:`helpers.slam`)::

    from helpers import Slam
    slam = Slam(config, anchor=data.poses[0])
    for index, scan in enumerate(data.scans):
        step = slam.process(scan, index)   # one line: node, pose, edges back, loop
    result = slam.result()                  # the pose graph optimised, the map

Transforms are named by their frames, small_gicp's way, everywhere in the
package: ``T_target_source`` carries points of the source frame into the
target frame (``p_target = T_target_source @ p_source``). A pose is
``T_map_sensor``; a registration returns ``T_fixed_moving``; an edge
between nodes ``i`` and ``j`` holds ``T_i_j``, so ``pose_j = pose_i @ T_i_j``.

Importing the package sets nothing (no environment variable, no matplotlib
back end); pictures live in :mod:`helpers.viz`, the site in :mod:`helpers.site`.
"""

from .config import Config, SensorConfig
from .configfile import load_config
from .dataset import DEFAULT_WAYPOINTS, Dataset, create_dataset, write_dataset
from .errors import SlamError
from .scene import default_scene
from .slam import Slam
from .waypoints import read_waypoints

__all__ = [
    "DEFAULT_WAYPOINTS",
    "Config",
    "Dataset",
    "SensorConfig",
    "Slam",
    "SlamError",
    "create_dataset",
    "default_scene",
    "load_config",
    "read_waypoints",
    "write_dataset",
]
__version__ = "0.2.0"
