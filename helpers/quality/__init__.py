"""How good a run is: metrics shaped like evo's (:mod:`~helpers.quality.metrics`), the grade against the
simulator's truth (:mod:`~helpers.quality.evaluation`), and the trust flag a run gives itself without any truth
(:mod:`~helpers.quality.trust`, its rules in :mod:`~helpers.quality.trust_rules`, the graph's own measures in
:mod:`~helpers.quality.graph_checks`). The trust flag never reads the grader."""

from helpers import lazy_exports

EXPORTS = {
    "FALSE_LOOP_DEG": "helpers.quality.metrics",
    "FALSE_LOOP_M": "helpers.quality.metrics",
    "ate": "helpers.quality.metrics",
    "rpe": "helpers.quality.metrics",
    "is_false_loop": "helpers.quality.metrics",
    "grade_loops": "helpers.quality.evaluation",
    "map_errors": "helpers.quality.evaluation",
    "run_metrics": "helpers.quality.evaluation",
    "assess": "helpers.quality.trust",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
