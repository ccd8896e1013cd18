"""The configuration: one TOML file, a table per stage, each key with its
bounds, its help text and, where it has one, the reference's name.

- :mod:`~helpers.config.tables`: :class:`Config` and the estimator's tables
  (``[features]``, ``[registration]``, ``[map]``), the reference's values;
- :mod:`~helpers.config.sensor`, :mod:`~helpers.config.loop_closure`,
  :mod:`~helpers.config.pose_graph`: the other tables;
- :mod:`~helpers.config.bounds`: how a table checks its values, and the
  limits every input is held to;
- :mod:`~helpers.config.files`: TOML in and out.

It sits below every other layer: the simulator reads ``[sensor]``, each
stage of the estimator its own table.
"""

from helpers.config.files import config_from_dict, config_to_toml, load_config
from helpers.config.loop_closure import LoopClosureConfig
from helpers.config.pose_graph import PoseGraphConfig
from helpers.config.sensor import SensorConfig
from helpers.config.tables import (
    REFERENCE_WORKFLOW,
    STAGE_TABLES,
    Config,
    FeaturesConfig,
    MapConfig,
    RegistrationConfig,
    describe,
    noise_seed_from_environment,
)

__all__ = [
    "REFERENCE_WORKFLOW",
    "STAGE_TABLES",
    "Config",
    "FeaturesConfig",
    "LoopClosureConfig",
    "MapConfig",
    "PoseGraphConfig",
    "RegistrationConfig",
    "SensorConfig",
    "config_from_dict",
    "config_to_toml",
    "describe",
    "load_config",
    "noise_seed_from_environment",
]
