"""Helpers for the aerial lidar SLAM tutorial.

Stage 1, the dataset (the reference's ``helperCreateDataset``)::

    from helpers import create_dataset
    data = create_dataset()            # the embedded default scene and loop
    data.scans[0], data.poses[0]       # a scan (sensor frame) and its pose

The SLAM itself, one scan at a time (:class:`helpers.slam.Slam`)::

    from helpers import Slam
    slam = Slam(config, anchor=data.poses[0])
    for index, scan in enumerate(data.scans):
        step = slam.process(scan, index)   # one line: node, pose, edges back, loop
    result = slam.result()                  # the pose graph optimised, the map

The package is built in layers, each a folder that imports only the ones
below it (``docs/ARCHITECTURE.md``): :mod:`helpers.config`, then
:mod:`helpers.sim` (the world), :mod:`helpers.slam` (the estimator),
:mod:`helpers.quality` (metrics, grading, the trust flag), :mod:`helpers.cli`
(commands and output folders) and, on top, :mod:`helpers.viz`,
:mod:`helpers.exercises` and :mod:`helpers.site`.

Transforms are named by their frames, small_gicp's way, everywhere in the
package: ``T_target_source`` carries points of the source frame into the
target frame (``p_target = T_target_source @ p_source``). A pose is
``T_map_sensor``; a registration returns ``T_fixed_moving``; an edge
between nodes ``i`` and ``j`` holds ``T_i_j``, so ``pose_j = pose_i @ T_i_j``.

Importing the package sets nothing and loads nothing heavy: each name below
is imported from its module when first used.
"""

from __future__ import annotations

import importlib

__version__ = "0.2.0"


def lazy_exports(package: str, names: dict[str, str]):
    """A package's ``__getattr__`` and ``__dir__`` that import each of ``names``
    (name -> module) from its module when first asked for (PEP 562)."""

    def __getattr__(name: str):
        module = names.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        setattr(importlib.import_module(package), name, value)
        return value

    def __dir__():
        return sorted(names)

    return __getattr__, __dir__


EXPORTS = {
    "Config": "helpers.config",
    "SensorConfig": "helpers.config",
    "load_config": "helpers.config",
    "SlamError": "helpers.errors",
    "DEFAULT_WAYPOINTS": "helpers.sim.dataset",
    "Dataset": "helpers.sim.dataset",
    "create_dataset": "helpers.sim.dataset",
    "default_scene": "helpers.sim.scene",
    "read_waypoints": "helpers.sim.waypoints",
    "Slam": "helpers.slam.slam",
    "run_slam": "helpers.slam.pipeline",
    "find_loop_candidates": "helpers.slam.loops.search",
    "write_dataset": "helpers.cli.outputs",
    "default_run": "helpers.cli.cache",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
