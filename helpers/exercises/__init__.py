"""Checks for the notebooks' exercises.

Each exercise in a notebook has a scaffold cell the learner fills in and a
check the learner runs. A check compares the answer with something computed
here from the data (a known transform, the simulator's poses, a library
call), prints one line and returns whether the answer holds:

    correct: <what the answer shows>
    not yet: <a hint>

An empty scaffold prints ``not yet``, so the notebooks run as shipped; the
worked answers are in ``notebooks/solutions/``, which the tests run too.
One module per notebook: :mod:`.dataset`, :mod:`.registration`, ...; the checks
are imported from here (``from helpers.exercises import check_grid_step``).
"""

from __future__ import annotations

from helpers.exercises.dataset import check_edge_ray, check_scans_seeing
from helpers.exercises.loops import check_fixed_radius, check_row_slip, check_search_radius, search_graph
from helpers.exercises.maps import check_aligned_ate, check_true_rotation_map
from helpers.exercises.parameters import check_grid_step, check_skip_frames
from helpers.exercises.registration import check_least_share, check_msac_cost
from helpers.exercises.report import report, say, unanswered
from helpers.exercises.submaps import check_centre_and_reach, check_eligible

__all__ = [
    "check_aligned_ate",
    "check_centre_and_reach",
    "check_edge_ray",
    "check_eligible",
    "check_fixed_radius",
    "check_grid_step",
    "check_least_share",
    "check_msac_cost",
    "check_row_slip",
    "check_scans_seeing",
    "check_search_radius",
    "check_skip_frames",
    "check_true_rotation_map",
    "report",
    "say",
    "search_graph",
    "unanswered",
]
