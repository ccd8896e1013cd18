"""The trust flag's rules, one function each (:mod:`helpers.quality.trust` says what they are and why).

A run is measured once into :class:`helpers.quality.trust_facts.Facts` (:func:`facts_of`: the steps
that fell back, kept a poor fit or lay on flat ground, the revisits, what the loops moved, the GNSS
graph's expected ATE, and the counts of :class:`helpers.quality.trust.Health`). Each rule reads those
facts and returns its problem in plain words (what, the likely cause, what to change), or None;
:data:`RULES` lists them in the order the problems are written; :func:`scale_unvouched` says why a
consistent run cannot vouch for its scale. The bars they test are here, with the measurements behind
them (those the facts are measured by, in :mod:`helpers.quality.trust_facts`).
"""

from __future__ import annotations

import numpy as np

from helpers.quality.graph_checks import FALSE_LOOP_SIGMAS
from helpers.quality.trust_facts import Facts
from helpers.slam.loops.places import BLIND_RUN_STEPS

MAX_FALLBACK_SHARE = 0.10  # more odometry steps than this falling back: the trajectory is not trusted
MAX_EXPECTED_ATE_M = 0.5  # m: the ATE the graph expects of itself, held by GNSS fixes or by loops, may be at most this
# (half of issue 21's 1 m: on six low flights with 2 m or 10 m fixes at every scan the ATE was 0.9-1.35 times the
# expected one; lidar only, on 13 low flights whose loops mended them, 0.6-2.0 times: benchmarks/bench_flights.py)
# (the sparse tile of scene seed 5 at 150 m: a turn of 2.8 degrees a step began over its lake, 22 steps with no
# match missed 56 degrees of it, and no revisit closed a loop)


def _fell_back(run: Facts) -> str | None:
    """Too many steps fell back to the previous motion (a drift rule)."""
    if run.held or not run.steps or len(run.fallbacks) <= MAX_FALLBACK_SHARE * run.steps:
        return None
    config = run.result.config
    skip = config.registration.skip_frames
    return (
        f"{len(run.fallbacks)} of {run.steps} odometry steps ({len(run.fallbacks) / run.steps:.0%}) could not be "
        f"registered and fell back to the previous motion (scans {_some(run.result.indices, run.fallbacks)}). "
        "Likely cause: consecutive accepted scans share too little ground (a low flight, a narrow sensor or "
        "waypoints far apart), or too few points for their descriptors. "
        + (
            f"Try [registration] skip_frames = 1 (now {skip})."
            if skip > 1
            else f"Try a finer [features] grid_step (now {config.features.grid_step} m), or fly higher."
        )
    )


def _kept_poor(run: Facts) -> str | None:
    """A step kept a poor ICP fit: the chain may break there."""
    if not len(run.poor):
        return None
    return (
        f"{len(run.poor)} odometry steps kept an ICP RMSE above {run.result.config.registration.icp_fallback_rmse} "
        f"m (scans {_some(run.result.indices, run.poor)}): the trajectory may break there. Likely cause: too "
        "little overlap or too few points. Try a smaller [registration] skip_frames or [features] grid_step."
    )


def _on_flat_ground(run: Facts) -> str | None:
    """Too many steps lay on ground too flat to pin them (a drift rule)."""
    if run.held or not run.steps or len(run.weak) <= MAX_FALLBACK_SHARE * run.steps:
        return None
    return (
        f"{len(run.weak)} of {run.steps} odometry steps ({len(run.weak) / run.steps:.0%}) were registered on ground "
        f"too flat to pin the motion along it (scans {_some(run.result.indices, run.weak)}): ICP may slide there, "
        "and the trajectory drift unseen. Likely cause: flat, featureless ground (fields, parking lots, water) "
        "under a narrow strip. Fly higher, so that each scan sees more relief."
    )


def _loops_against_the_rest(run: Facts) -> str | None:
    """Loop edges far from where the rest of the graph puts them, still moving it."""
    if not run.loops_disagree:
        return None
    config, against = run.result.config, run.against
    kernel = config.pose_graph.loop_kernel
    fate = f"the {kernel} kernel did not set them aside" if kernel != "none" else "no robust kernel"
    pairs = ", ".join(f"{loop.i}-{loop.j}" for loop in against[:4]) + (", ..." if len(against) > 4 else "")
    # Where the loops also moved the trajectory far, the rest of the graph is the drifted odometry: a true loop
    # disagrees with it as much as a false one would, and the run cannot tell them apart.
    verdict = (
        "either they are false or the odometry between their ends drifted more than its information says "
        "(the loops moved the trajectory far, below), and the run cannot tell which"
        if run.drifted
        else "they are most likely false"
    )
    return (
        f"{len(against)} of {len(run.result.loops)} loop edges (nodes {pairs}) end more than {FALSE_LOOP_SIGMAS:g} "
        f"sigmas, and farther than a false loop is off, from where the rest of the graph puts them: {verdict}; "
        f"they move the trajectory by up to {run.pull:.2f} m ({fate}). "
        "If false, the likely cause is repetitive or flat ground that matches within the loop thresholds: try "
        f"a lower [loop_closure] rmse_threshold (now {config.loop_closure.rmse_threshold} m)."
    )


def _revisits_unclosed(run: Facts) -> str | None:
    """Most revisits closed no loop: the drift stays in the map."""
    config = run.result.config
    if run.held or run.revisited < config.map.n_scans_per_submap or run.unclosed <= run.revisited / 2:
        return None
    loops = config.loop_closure
    needed = (loops.sub_map_thresh + 1) * config.map.n_scans_per_submap
    blind = runs_of(run.result.indices, run.fallbacks, BLIND_RUN_STEPS)
    cause = (
        f"odometry steps {BLIND_RUN_STEPS} or more in a row (scans {_written(blind)}) could not be registered "
        "and followed the last motion: a turn begun there went unseen, and the odometry came back too far "
        "from where it flew for the loop search (featureless ground under the whole strip: water, a field). "
        "Add GNSS fixes (run --gnss FILE), or fly higher, so that each scan sees ground with relief."
        if blind
        else f"a loop candidate must be older than [loop_closure] sub_map_thresh = {loops.sub_map_thresh} "
        f"submaps (about {needed} accepted scans), or the scans do not match within loop_closure_threshold. "
        "Try a smaller sub_map_thresh."
    )
    return (
        f"{run.revisited} accepted scans come back over ground flown earlier, and {run.unclosed} of them closed no "
        f"loop, so the drift stays in the map. Likely cause: {cause}"
    )


def _loops_moved_far(run: Facts) -> str | None:
    """The loops moved the trajectory far: the odometry drifted that much (a drift rule)."""
    if run.held or not run.drifted:
        return None
    flown, correction = run.flown, run.correction
    share = f", {correction / flown:.1%} of the {flown:.0f} m flown" if flown > 0 else " (the flight hovered)"
    return (
        f"The loop edges moved the trajectory by up to {correction:.1f} m{share}: the odometry drifted that "
        "much, and between the places where loops closed the trajectory and the map keep part of that drift. "
        "Likely cause: odometry steps on weak ground (too flat, little overlap). Fly higher, or over the same "
        "ground more than once, so that loops close in more places."
    )


def _fixes_cannot_say(run: Facts) -> str | None:
    """With GNSS fixes, GTSAM could not give the graph's marginals."""
    if not run.held or run.expected is not None:
        return None
    return (
        f"With {len(run.result.gnss_factors)} GNSS fixes the graph could not say how far off it expects its "
        f"trajectory to be ({run.unknown}). Likely cause: nodes that neither the steps nor the fixes pin "
        "(a direction no edge holds). Check the GNSS file's scan indices and sigmas."
    )


def _fixes_too_loose(run: Facts) -> str | None:
    """With GNSS fixes, the graph expects its trajectory too far off."""
    if not run.held or run.expected is None or run.expected <= MAX_EXPECTED_ATE_M:
        return None
    return (
        f"With {len(run.result.gnss_factors)} GNSS fixes the graph expects its trajectory to be {run.expected:.2f} "
        f"m off (root mean square of its nodes' position sigmas), more than {MAX_EXPECTED_ATE_M} m. Likely cause: "
        "fixes too loose or too far apart for odometry steps that pinned little between them (flat ground, "
        "steps that fell back). Give the receiver's true sigma (run --gnss-sigma), or fly where the ground "
        "has relief."
    )


# The rules in the order their problems are written, each with whether it reads the odometry's drift (the loops
# may answer those, see the module).
RULES = (
    (_fell_back, True),
    (_kept_poor, False),
    (_on_flat_ground, True),
    (_loops_against_the_rest, False),
    (_revisits_unclosed, False),
    (_loops_moved_far, True),
    (_fixes_cannot_say, False),
    (_fixes_too_loose, False),
)


SPARSE_CANOPY_BIAS_PCT = 2.0  # %: how short the odometry's steps came out over a sparse forest (forest_bc_1 thinned to
# 1.5 points per m2, 150 m above it: step ratio 0.980, benchmarks/bench_bias_odometry.py); dense canopy 0.4-1.0 %,
# roofs and open ground under 0.1 %. Said in the message only: the rule reads what the loops observe, not this.


def scale_observed(counts: dict) -> bool:
    """Whether the loops observe the flight's scale (``counts`` as :func:`helpers.quality.trust_facts.facts_of`
    gives them): a scale error of the sigma they leave moves the trajectory by at most
    :data:`MAX_EXPECTED_ATE_M`."""
    sigma = counts["loop_scale_sigma_pct"]
    return sigma is not None and sigma * counts["moved_per_scale_pct_m"] <= MAX_EXPECTED_ATE_M


def scale_unvouched(run: Facts) -> str:
    """Why a lidar-only run cannot vouch for its scale, or '' when it can: the loops observe the scale when an
    error of the sigma they leave it (:func:`helpers.quality.graph_checks.loop_scale`) moves the trajectory by at
    most :data:`MAX_EXPECTED_ATE_M`; GNSS fixes hold every node's position, scale included. Not a problem of
    the run's consistency (the rules of :data:`RULES`): a lap shrunk by biased step lengths closes on a lap
    shrunk alike, and every rule and loop agrees with it."""
    counts = run.counts
    sigma, per_pct = counts["loop_scale_sigma_pct"], counts["moved_per_scale_pct_m"]
    if run.held or scale_observed(counts):
        return ""
    seen = (
        "no loop observes the flight's scale"
        if sigma is None
        else f"the loops leave the flight's scale a sigma of {sigma:.2g} %, which moves the trajectory by "
        f"{sigma * per_pct:.2f} m, more than {MAX_EXPECTED_ATE_M} m"
    )
    cause = (
        f"every loop closes near where the flight passed before (levers up to {counts['longest_loop_lever_m']:.0f} "
        "m), and a lap shrunk alike closes on itself"
        if run.result.loops
        else "no loop closed, and the steps alone cannot see a bias they share"
    )
    return (
        f"Its scale is not observed: {seen}. A bias of 1 % in the odometry's step lengths would move the "
        f"trajectory by {per_pct:.2f} m unseen (over a sparse forest the steps came out {SPARSE_CANOPY_BIAS_PCT:g} % "
        f"short). Likely cause: {cause}. Fly parallel strips whose swaths overlap and a cross line (python -m "
        "helpers flight TILE --pattern survey), so that loops between strips measure the scale, or add GNSS "
        "fixes (run --gnss FILE)."
    )


def runs_of(indices, chosen, length: int) -> list[tuple[int, int]]:
    """The runs of at least ``length`` consecutive accepted scans (``indices``, the run's, ascending) that are
    all in ``chosen`` (scan indices): (first scan, last scan) each, in order."""
    at = np.flatnonzero(np.isin(indices, chosen))
    if not len(at):
        return []
    breaks = np.flatnonzero(np.diff(at) > 1)
    starts, ends = np.r_[0, breaks + 1], np.r_[breaks, len(at) - 1]
    indices = np.asarray(indices)
    return [
        (int(indices[at[start]]), int(indices[at[end]]))
        for start, end in zip(starts, ends, strict=True)
        if end - start + 1 >= length
    ]


def _some(indices, chosen, shown: int = 6) -> str:
    """The first ``shown`` runs of consecutive accepted scans (``indices``, the run's) in ``chosen``, as
    ``first-last`` or one scan: with ``skip_frames`` above 1, scans 3, 6 and 9 are one run, "3-9"."""
    return _written(runs_of(indices, chosen, 1), shown)


def _written(runs, shown: int = 6) -> str:
    """``runs`` ((first, last) scans) written ``first-last``, or ``first`` alone, the first ``shown`` of them."""
    words = [f"{first}-{last}" if last != first else f"{first}" for first, last in runs]
    return ", ".join(words[:shown]) + (", ..." if len(words) > shown else "")
