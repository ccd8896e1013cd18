"""The figures of notebooks 2 (parameters) and 3 (registration), under one name."""

from .parameter_figures import (
    grid_step_figure,
    matching_figure,
    neighbors_figure,
    parameter_table,
    skip_frames_figure,
    trials_figure,
)
from .registration_figures import (
    clouds_figure,
    descriptor_figure,
    matches_figure,
    profile_figure,
    step_errors_figure,
    surface_error_figure,
    trajectory_figure,
)

__all__ = [
    "clouds_figure",
    "descriptor_figure",
    "grid_step_figure",
    "matches_figure",
    "matching_figure",
    "neighbors_figure",
    "parameter_table",
    "profile_figure",
    "skip_frames_figure",
    "step_errors_figure",
    "surface_error_figure",
    "trajectory_figure",
    "trials_figure",
]
