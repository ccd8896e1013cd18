"""The figures of notebooks 2 (parameters), 3 (registration) and 4's odometry, under one name."""

from helpers.viz.parameter_figures import (
    descriptor_distance_figure,
    footprints_figure,
    grid_steps_figure,
    neighbourhood_figure,
    parameter_origin,
    parameter_table,
    trials_formula_figure,
)
from helpers.viz.registration_figures import (
    clouds_figure,
    darboux_figure,
    descriptor_figure,
    icp_convergence_figure,
    matches_figure,
    profile_figure,
    surface_error_figure,
)
from helpers.viz.submap_figures import step_errors_figure, trajectory_figure
from helpers.viz.sweep_figures import matching_figure, neighbors_figure, skip_frames_figure, trials_figure

__all__ = [
    "clouds_figure",
    "darboux_figure",
    "descriptor_distance_figure",
    "descriptor_figure",
    "footprints_figure",
    "grid_steps_figure",
    "icp_convergence_figure",
    "matches_figure",
    "matching_figure",
    "neighbors_figure",
    "neighbourhood_figure",
    "parameter_origin",
    "parameter_table",
    "profile_figure",
    "skip_frames_figure",
    "step_errors_figure",
    "surface_error_figure",
    "trajectory_figure",
    "trials_figure",
    "trials_formula_figure",
]
