"""The figures of notebooks 4 (submaps), 5 (loop closure) and 6 (pose graph), under one name.

Each function takes arrays (positions, clouds, errors) and returns a
matplotlib figure, or an RGB array for the PyVista views; a notebook shows
it with :func:`helpers.viz.render.show_figure` or :func:`helpers.viz.render.show`.
"""

from helpers.viz.graph_figures import (
    bad_edge_figure,
    kernels_figure,
    loop_weights_figure,
    pose_graph_figure,
    position_errors_figure,
    trajectories_figure,
)
from helpers.viz.loop_figures import (
    candidates_figure,
    loop_errors_figure,
    overlap_rounds_figure,
    pair_overlay_figure,
    queries_figure,
    query_figure,
    rmse_offsets_figure,
    search_radius_figure,
)
from helpers.viz.loop_search import query_search, true_revisits
from helpers.viz.style import WINDOW
from helpers.viz.submap_figures import recent_rule_figure, submap_centres_figure, submap_merge_figure, submap_panels

__all__ = [
    "WINDOW",
    "bad_edge_figure",
    "candidates_figure",
    "kernels_figure",
    "loop_errors_figure",
    "loop_weights_figure",
    "overlap_rounds_figure",
    "pair_overlay_figure",
    "pose_graph_figure",
    "position_errors_figure",
    "queries_figure",
    "query_figure",
    "query_search",
    "recent_rule_figure",
    "rmse_offsets_figure",
    "search_radius_figure",
    "submap_centres_figure",
    "submap_merge_figure",
    "submap_panels",
    "trajectories_figure",
    "true_revisits",
]
