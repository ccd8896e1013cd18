"""Can a run be trusted? What went wrong in it, counted from the run alone
(no ground truth), and, when it is too much, why in plain words and which
parameter to change.

A run is *not trusted* when

- more than :data:`MAX_FALLBACK_SHARE` of the odometry steps fell back (the
  robust fit failed or ICP ended far off), or
- any step kept an ICP RMSE above ``[registration] icp_fallback_rmse`` (the
  chain may break there), or
- more than :data:`MAX_FALLBACK_SHARE` of the steps were registered on ground
  too flat to pin the motion along it: the sigma of the step's weakest
  direction, from its calibrated information, above :data:`WEAK_SIGMA_M`, or
  ICP's ``constraint`` below :data:`WEAK_CONSTRAINT` (:func:`helpers.slam.registration.icp.pairing`:
  on a plane, generalized ICP's Hessian still counts the distances along the
  plane its covariances allow, so both are read), or
- a loop edge ends more than :data:`helpers.quality.graph_checks.FALSE_LOOP_SIGMAS` from where the rest
  of the graph puts it, whitened by its own calibrated information (the
  graph's sigmas when it has none), and farther than a false loop is off
  the truth (:func:`helpers.quality.metrics.is_false_loop`): a false loop, and
  it still moves the trajectory by more than :data:`CORRECTION_FLOOR_M`
  (without a robust kernel it bends the map; one the kernel set aside all
  but entirely is counted, not held against the run), or
- the estimated trajectory comes back over places it left and no loop was
  closed at most of them (the drift then stays in the map; where
  :data:`BLIND_RUN_STEPS` or more steps in a row fell back before, the
  message names them, :func:`helpers.quality.trust_rules.runs_of`, as the likely cause), or
- the loop edges moved the trajectory (against the same graph without them)
  by more than :data:`MAX_CORRECTION_SHARE` of the distance flown, and by more
  than :data:`CORRECTION_FLOOR_M` (a hovering flight flies no distance): the
  odometry drifted that much, and between the places where loops closed the
  optimised trajectory keeps part of it.

With GNSS fixes in the graph, the drift the odometry or the loops show no
longer stays in the map: the fixes hold every node near where they put it.
The four rules that read drift (steps that fell back, steps on flat ground,
revisits with no loop, what the loops moved) then give way to one that asks
the graph itself: the ATE it expects of its own trajectory
(:func:`helpers.quality.graph_checks.expected_ate`, from its marginal covariances) must be at most
:data:`MAX_EXPECTED_ATE_M`. A loose receiver, a sparse one or steps
whose information says they pinned nothing widen it.

Loops can hold a trajectory too. On a low flight the odometry falls back or
slides on flat ground, and the loops pull it back into place at every lap.
When one of the three rules that read the odometry's drift (steps that fell
back, steps on flat ground, what the loops moved) names a lidar-only run with
loops, the graph may answer them, if its word can be taken:

- its edges weigh by their calibrated information (``[pose_graph]
  graph_weights = "hessian"``, as :mod:`helpers.slam.flight_fit` sets it for low
  flights; the fixed sigmas of ``"icp"`` are chosen, not measured);
- no loop edge ends against the rest of it (the rule above);
- and no loop edge ends far from the graph *without it*
  (:func:`helpers.quality.graph_checks.loops_off_the_rest`: beyond
  :data:`FALSE_LOOP_SIGMAS` and farther than a false loop, each loop judged
  by its leave-one-out residual), unless those together move the trajectory
  by at most :data:`CORRECTION_FLOOR_M` (a kernel set them aside). A loop
  edge surer than the steps and far from them bends the graph to itself, so
  that it ends close to the optimised graph; left out, the graph would leave
  it metres off. Loops that agree with one another and with the steps around
  them pass, however far they moved the odometry: on low flights the
  odometry's errors run in the same direction for tens of steps (a slowly
  turning yaw error), so loops mending them move the trajectory by more of
  its sigmas than independent errors would (5-16 on the sparse tiles of
  ``benchmarks/bench_flights.py``, whose trajectories ended 0.34-0.37 m
  off), and the graph's independent steps cannot tell that from a bent
  graph. How far they moved it, in those sigmas
  (:func:`helpers.quality.graph_checks.correction_sigmas`), is still counted.

Then, if the ATE the graph expects is at most :data:`MAX_EXPECTED_ATE_M`, the
loops hold the drift those rules saw: it is counted, not held against the
run. Revisits that closed no loop stay a problem: the graph cannot see a loop
it was never given.

A run none of these rules names is *consistent*: its steps, loops and graph agree with one another. It
is *trusted* only if it also observes its *scale* (:func:`helpers.quality.trust_rules.scale_unvouched`).
A loop that closes where the flight passed before has no lever: a lap shrunk by biased step lengths
closes on a lap shrunk alike, and every rule above agrees with it (over canopy the steps come out up to
a few per cent short, ``benchmarks/README.md``). Loops between neighbouring strips have levers of the
strips' spacing and measure it; GNSS fixes hold it. Unless a scale error of the loops' sigma
(:func:`helpers.quality.graph_checks.loop_scale`) moves the trajectory by at most
:data:`MAX_EXPECTED_ATE_M`, a lidar-only run is trusted *in shape only*: it says so, and how far a
bias of 1 % would move the trajectory unseen, and vouches for no more.

The rules themselves, each a function that returns its problem or nothing,
and the bars above, are in :mod:`helpers.quality.trust_rules`; :func:`assess` runs
them and asks the graph (:func:`graph_answer`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from helpers.errors import SlamError
from helpers.quality.graph_checks import (
    FALSE_LOOP_SIGMAS,
    correction_sigmas,
    expected_ate,
    loop_pull,
    loops_off_the_rest,
)
from helpers.quality.trust_facts import CORRECTION_FLOOR_M, MAX_CORRECTION_SHARE, WEAK_SIGMA_M, facts_of
from helpers.quality.trust_rules import (
    BLIND_RUN_STEPS,
    MAX_EXPECTED_ATE_M,
    MAX_FALLBACK_SHARE,
    RULES,
    scale_observed,
    scale_unvouched,
)

__all__ = [
    "BLIND_RUN_STEPS",
    "CORRECTION_FLOOR_M",
    "MAX_CORRECTION_SHARE",
    "MAX_EXPECTED_ATE_M",
    "MAX_FALLBACK_SHARE",
    "WEAK_SIGMA_M",
    "Health",
    "assess",
    "graph_answer",
]


@dataclass
class Health:
    """What went wrong in a run, and whether its result can be trusted."""

    counts: dict  # steps, fallbacks, poor steps, loop queries, loops rejected (too flat), edges back left out, revisits
    problems: list[str] = field(default_factory=list)  # one sentence each: what, likely cause, what to change
    scale: str = ""  # why the run cannot vouch for its scale ('' when it can): what, likely cause, what to change

    @property
    def consistent(self) -> bool:
        """No rule names a problem: the steps, loops and graph agree with one another (the shape is trusted)."""
        return not self.problems

    @property
    def trusted(self) -> bool:
        """Consistent, and its scale observed: the run vouches for its trajectory whole."""
        return not self.problems and not self.scale

    def summary(self) -> str:
        """One line of counts."""
        c = self.counts
        return (
            f"{c['n_fallbacks']} of {c['n_steps']} odometry steps fell back{self._by_check()}, "
            f"{c['n_poor_steps']} kept a poor ICP fit, "
            f"{c['n_weak_steps']} lay on ground too flat to pin them; "
            f"{c['n_loops_rejected']} loop candidates rejected ({c['n_loops_too_flat']} on ground too flat), "
            f"{c['n_loops_against_graph']} loop edges against the graph"
            + (f" (moving it by {c['loops_against_graph_pull_m']:.2f} m)" if c["n_loops_against_graph"] else "")
            + "; "
            f"{c['n_edges_back_left_out']} of {c['n_edges_back_tried']} edges back left out"
            + (
                ""
                if c.get("loop_correction_sigmas") is None
                else f"; the loops moved the trajectory by {c['loop_correction_sigmas']:.1f} of the odometry's sigmas"
            )
            + (
                ""
                if not c.get("n_loops_off_the_rest")
                else f"; {c['n_loops_off_the_rest']} loop edges far from the graph without them"
            )
            + self._loop_fallbacks()
            + ("" if c.get("expected_ate_m") is None else f"; the graph expects an ATE of {c['expected_ate_m']:.2f} m")
            + self._scale()
        )

    def _by_check(self) -> str:
        """The fallbacks by the check that made them (:data:`helpers.slam.registration.fallbacks.CHECKS`)."""
        checks = self.counts.get("fallbacks_by_check") or {}
        return f" ({', '.join(f'{n} {check}' for check, n in checks.items())})" if checks else ""

    def _loop_fallbacks(self) -> str:
        """The loop queries that searched another way than the graph's gate, when there were any."""
        c = self.counts
        grown, recognised = c.get("n_queries_grown_radius", 0), c.get("n_queries_recognised", 0)
        said = [f"{grown} loop queries searched the grown radius (no gate from the graph)"] if grown else []
        if recognised:
            said.append(f"{recognised} recognised old places after a blind stretch ({c['n_loops_recognised']} closed)")
        return "".join(f"; {words}" for words in said)

    def _scale(self) -> str:
        """What the loops say of the flight's scale (:func:`helpers.quality.graph_checks.loop_scale`): observed
        when a scale error of its sigma moves the trajectory by at most :data:`MAX_EXPECTED_ATE_M`, else said
        unobserved, with what a bias of 1 % of the step lengths would move it by unseen."""
        c = self.counts
        sigma, per_pct, lever = c["loop_scale_sigma_pct"], c["moved_per_scale_pct_m"], c["longest_loop_lever_m"]
        if scale_observed(c):
            return f"; the loops observe the flight's scale to a sigma of {sigma:.2g} % (levers up to {lever:.0f} m)"
        seen = (
            "no loop observes the flight's scale"
            if sigma is None
            else f"the loops barely observe the flight's scale (a sigma of {sigma:.2g} %, levers up to {lever:.0f} m: "
            "a loop that closes where the flight passed before has none)"
        )
        if not self.scale:  # GNSS fixes hold every node's position, scale included
            return f"; {seen}: the GNSS fixes hold it"
        return (
            f"; {seen}, so this run vouches for no scale: a bias of 1 % in the odometry's step lengths would move "
            f"the trajectory by {per_pct:.2f} m"
        )

    def warning(self) -> str:
        """The plain warning of an untrusted run ('' when trusted)."""
        if self.problems:
            return "this result cannot be trusted: " + " ".join(self.problems)
        return f"this result is trusted in shape only. {self.scale}" if self.scale else ""


def assess(result) -> Health:
    """The :class:`Health` of a :class:`helpers.slam.pipeline.SlamResult`: each rule of :data:`RULES` in turn."""
    facts = facts_of(result)
    problems, drift = [], []  # drift: the indices of the problems the drift rules name (which loops may answer)
    for rule, reads_drift in RULES:
        problem = rule(facts)
        if problem:
            problems.append(problem)
            if reads_drift:
                drift.append(len(problems) - 1)
    config = result.config
    if drift and result.loops and config.pose_graph.graph_weights == "hessian" and not facts.loops_disagree:
        # The odometry drifted: do the loops hold the trajectory all the same, by the graph's own reckoning? Only
        # calibrated information can answer, and only in a graph that agrees with itself: no loop edge against
        # the rest, judged against the graph without it (a graph bent to a loop sits close to it), unless the
        # kernel set it aside.
        expected, why = graph_answer(result, facts.rebuilt, facts.without, facts.counts)
        if expected is not None and expected <= MAX_EXPECTED_ATE_M:
            problems = [problem for k, problem in enumerate(problems) if k not in drift]
        else:  # the last word of the drift rules says why the graph could not answer them
            problems[drift[-1]] += f" The loops do not answer this drift by the graph's own reckoning: {why}."
    return Health(facts.counts, problems, scale_unvouched(facts))


def graph_answer(result, rebuilt, without, counts: dict) -> tuple[float | None, str]:
    """Whether a lidar-only run's graph may answer the drift rules (the module says when): the ATE it expects
    of itself and why it does not answer when that is too much, or None and why it cannot answer at all.
    ``rebuilt`` and ``without`` as :func:`helpers.quality.graph_checks.loop_correction` takes them; the measures
    are written into ``counts`` as they are made. Where GTSAM cannot give the marginals, there is no answer,
    never an error: a run is not crashed by its own health check."""
    try:
        counts["loop_correction_sigmas"] = round(correction_sigmas(result, rebuilt, without), 2)
        bent = loops_off_the_rest(result)
    except SlamError as exc:
        return None, f"its marginals could not be computed ({exc})"
    bent_pull = loop_pull(result, [loop for loop, _ in bent], rebuilt)
    counts["n_loops_off_the_rest"] = len(bent)
    if bent_pull > CORRECTION_FLOOR_M:
        pairs = ", ".join(f"{loop.i}-{loop.j}" for loop, _ in bent[:4]) + (", ..." if len(bent) > 4 else "")
        farthest = max(residual[0] for _, residual in bent)
        return None, (
            f"{len(bent)} loop edges (nodes {pairs}) end up to {farthest:.2f} m, more than "
            f"{FALSE_LOOP_SIGMAS:g} sigmas, from where the graph without each of them puts them, and they "
            f"move it by {bent_pull:.2f} m: the graph bent to them, so it cannot vouch for itself"
        )
    try:
        expected = expected_ate(result)
    except SlamError as exc:
        return None, f"its marginals could not be computed ({exc})"
    counts["expected_ate_m"] = round(expected, 3)
    return expected, f"it expects its trajectory to be {expected:.2f} m off, more than {MAX_EXPECTED_ATE_M} m"
