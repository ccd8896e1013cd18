"""Parameters from the flight: the lengths the reference tuned for its own
flight, scaled to the footprint of another one, with the reasons.

The reference's values fit its flight: about 600 m above the ground, a
waypoint every 2 m, a strip about 53 m long along the track. Its lengths
(grid steps, distances, how far back a loop must lie) are footprint lengths
in disguise, so on a flight ``k`` times as high they are scaled by ``k``,
never finer than the surface the rays hit (a 1 m height field shows nothing
finer); counts that stand for distances (``skip_frames``, ``sub_map_thresh``)
are recomputed from the waypoint spacing. On the reference's own flight every
value comes out as the reference's but one: the descriptor grid
(:data:`DESCRIPTOR_GRID_FACTOR`), which the fit doubles for speed.

What is not scaled, and why: the loop search radius and the RMSE
thresholds (of loops and of edges back) measure drift and surface noise, not
the footprint; descriptor and robust-fit counts (neighbours, trials) do not
depend on the scale.

The values scaled are :data:`TUNED_AT`: our defaults, which are the
reference's values wherever the reference has the parameter, and ours
(``icp_grid_step``) tuned on the same flight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from helpers.config.tables import Config
from helpers.errors import SlamError

# The reference's flight, measured on the shipped default (the values were tuned for it).
REFERENCE_HEIGHT = 603.0  # m above the ground, median over the waypoints
REFERENCE_SPACING = 2.0  # m between waypoints
TUNED_AT = Config()  # the values tuned for that flight: our defaults (not Config.reference(), see above)
REFERENCE_LOOP_AGE = (  # m flown before a place can close a loop: sub_map_thresh submaps of accepted scans
    TUNED_AT.loop_closure.sub_map_thresh
    * TUNED_AT.map.n_scans_per_submap
    * TUNED_AT.registration.skip_frames
    * REFERENCE_SPACING
)
GRID_ROUNDING = 0.05  # m: fitted grid steps are multiples of this
# A grid step is the spacing of the points that registration and the map keep. With fewer than five cells
# across the narrow side of a scan's footprint, a scan shrinks to a few rows of points, a line more than a
# surface, whose normals, descriptors and ICP cannot pin the motion; the map becomes a handful of points.
# Five cells leave the reference's values room on flights four times lower than its own (150 m: a 13 m strip).
GRID_CELLS_ACROSS = 5
GRID_STEPS = (("features", "grid_step"), ("registration", "icp_grid_step"), ("map", "align_grid_step"))
# The scans are described and matched on a grid this many times the footprint's scaled step (ours; the
# reference describes on the same grid as the rest). The matcher compares every moving descriptor with every
# fixed one, so its time grows with the square of their number, and FPFH's with their number: on the default
# flight a 3 m grid keeps 2,800 of 5,800 points, and FPFH and matching take 41-42 ms a scan against 115-124 (a
# default run's stages, paired; benchmarks/README.md). ICP, the map and every distance still follow the
# footprint's step, and the floor is the surface's cell as for every grid, so low flights, whose grid is
# already held there, keep it (coarser descriptors lost them: Autzen at 150 m and the sparse tile,
# benchmarks/README.md).
DESCRIPTOR_GRID_FACTOR = 2.0
# Where every scan is accepted (skip_frames 1: a flight under half the reference's height at its spacing), the
# scans' ray rows lie about one ICP cell apart, and scan-to-scan ICP over ground with little relief pulls one
# scan's rows onto the last one's: steps come out short and turns too small (4 % short at 250 m above Autzen,
# turns 0.13 deg a step too small at 150 m), and the edges back, scan to scan too, add the same pull with more
# weight. There each scan is registered onto a local map of the last LOW_FLIGHT_LOCAL_MAP scans, whose rows
# interleave, and the edges back (which measure the same scans again) are left out. Six scans, 12 m of flight,
# measured on Autzen at 150 and 250 m and on a sparse tile at 150 m (benchmarks/bench_motion.py): three left
# half the bias, twelve no better.
LOW_FLIGHT_LOCAL_MAP = 6
# There too, a step is pinned well across the track and poorly along it (a strip of 10-20 m, over ground that is
# often flat), so the graph weighs each edge by its registration's own calibrated information (``graph_weights =
# "hessian"``), which says which way a step is loose, with Huber's kernel on the loop edges (Cauchy's, which sets
# aside an edge many of its own sigmas off, set true loops aside under those sharper weights). On the low flights of
# benchmarks/bench_flights.py it left every one nearer the truth (Autzen at 150, 200 and 250 m: 0.88, 0.72, 0.56 m
# -> 0.83, 0.69, 0.32 m, one false loop fewer at 150 and at 250 m; the sparse tile at 150 and 200 m: 2.44, 4.34 m
# -> 1.99, 2.14 m; with the speed swinging by 30 %, Autzen at 250 m and the sparse tile at 150 m: 0.91, 6.72 m ->
# 0.48, 3.88 m; not every low flight: over Autzen at 200 m on the loop `run` fits, 1.18 -> 1.41 m,
# benchmarks/README.md). On higher flights, where a few loops close and which ones decides the result, the icp sigmas
# stayed better (at 700 m over other scenes: seed 11 0.31 -> 0.45 m; benchmarks/README.md, "Measured, not taken").
# Only with the local map and no edges back, the graph they were measured on: a config that registers scan to
# scan with edges back, each measuring the ground its steps measured, keeps the fixed sigmas (under the
# information those edges count that ground several times, and 2 m GNSS fixes then pulled a low stretch only
# to 0.54 m against 0.35 m with the sigmas; tests/test_gnss.py).
# With each edge saying which way it is loose, the soft constant-velocity factor (``motion_factor``) has
# something to do: along those directions the flight's momentum holds the nodes. On the same low flights it halved
# the one-step RPE or better (Autzen at 150 and 250 m 0.100, 0.111 -> 0.059, 0.048 m; the sparse tile at 150 m
# 0.127 -> 0.095 m; swinging by 30 %, Autzen at 250 m 0.089 -> 0.031 m, the sparse tile 0.099 -> 0.064 m) and
# left the ATE within 0.06 m of its value without it (0.83 -> 0.85, 0.32 -> 0.30, 1.99 -> 2.01 m; swinging 0.48
# -> 0.44, 3.88 -> 3.82 m).
LOW_FLIGHT_GRAPH = {"graph_weights": "hessian", "loop_kernel": "huber", "motion_factor": True}
# Over a lake or a field a step is not pinned along the track at all, and two things made such steps come out
# short, 0.3-1 m a step, for tens of steps (benchmarks/bench_flights.py --seeds: a slide the loops cannot undo,
# as both laps make it). Generalized ICP's plane covariances keep a little weight along a flat ground, so its
# Hessian claimed a 0.02 m sigma along the track over water, and the momentum blend (helpers.slam.motion_guard)
# followed ICP's slide; the point-to-plane information of the same pairs says the step is loose there
# (``information = "plane"``). And ICP onto the local map, started from a coarse fit metres off, crawls along
# the weak direction: 30 iterations left it short of its minimum. Both, on three lidar noise seeds each (ATE
# optimised, m): the sparse tile at 150 m 35.8, 1.30, 0.74 -> 0.71, 0.35, 0.44; at 200 m 0.98, 0.78, 8.75 ->
# 0.22, 0.29, 0.25; Autzen at 150 m 0.96, 1.68, 0.84 -> 0.55, 0.55, 0.49; each alone helped less.
LOW_FLIGHT_ICP_ITERATIONS = 100
LOW_FLIGHT_INFORMATION = "plane"
# GNSS fixes are absolute. Against relative edges alone the graph's answer does not change when every sigma is
# scaled alike, so fixed sigmas need only the right proportions; against a fix they count at their size, and the
# fixed ones (0.3 deg a step, some twenty times the odometry's real turn error at 700 m) let the fixes' noise
# bend the trajectory. Where scans are skipped (higher flights; the low ones are decided above) a run with GNSS
# therefore weighs each edge by its registration's calibrated information. With a 2 m fix at every scan
# (benchmarks/bench_flights.py --gnss 2, optimised ATE, m): the default 0.42 -> 0.13, scene seeds 11 and 5 at
# 700 m 0.45, 0.44 -> 0.19, 0.19 (lidar alone 0.22, 0.31, 0.27); with 10 m fixes the default 1.02 -> 0.17.
GNSS_GRAPH_WEIGHTS = "hessian"
# A true loop edge's surface RMSE comes from how the two scans sample the ground: rows of rays 0.2 deg apart,
# so it shrinks with the height (0.26-0.39 m at the reference's 600 m, 0.02-0.13 m on Autzen 150 m above the
# ground), while a false one, laid on ground metres away, stayed at 0.17-0.57 m on the low flights of
# benchmarks/bench_flights.py (over a sparse tile a few true ones reach 0.28 m and are left out, others close
# instead). The reference's 0.6 m threshold follows the height, but never below this many range-noise sigmas
# (two scans of one plane differ by their noise).
LOOP_RMSE_NOISES = 4


@dataclass(frozen=True)
class Flight:
    """What the parameters depend on."""

    height: float  # m above the surface, median over the waypoints
    spacing: float  # m between waypoints, median
    surface_cell: float  # m, the resolution of the surface the rays hit
    strip: float  # m, the scan's length along the track on flat ground at that height


def flight_of(dataset) -> Flight:
    """The :class:`Flight` of a :class:`helpers.sim.dataset.Dataset`."""
    field = dataset.surface
    xy = dataset.waypoints[:, :2]
    height = float(np.median(dataset.waypoints[:, 2] - field.z[field.cell_of(xy)]))
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    spacing = float(np.median(steps[steps > 0])) if np.any(steps > 0) else REFERENCE_SPACING
    start, stop, _ = dataset.sensor.elevation
    strip = height * (math.tan(math.radians(stop)) - math.tan(math.radians(start)))
    return Flight(height, spacing, float(field.cell), strip)


def check_grid_steps(flight: Flight, config: Config) -> None:
    """Refuse a grid step coarser than the scans' footprint allows: more than
    1 / :data:`GRID_CELLS_ACROSS` of its narrow side (the strip along the
    track, or the swath across it, at the flight's height). A flight not
    above the ground has no footprint: :func:`fit_to_flight` refuses it."""
    if not flight.height > 0:
        return
    start, stop, _ = config.sensor.azimuth
    swath = flight.height * (math.tan(math.radians(stop)) - math.tan(math.radians(start)))
    narrow = min(flight.strip, swath)
    limit = narrow / GRID_CELLS_ACROSS
    for table, key in GRID_STEPS:
        value = getattr(getattr(config, table), key)
        if value > limit:  # icp_grid_step 0 (the feature clouds) always passes
            raise SlamError(
                f"[{table}] {key} = {value:g} m is too coarse for this flight: its scans cover "
                f"{flight.strip:.1f} m along the track and {swath:.1f} m across ({flight.height:.0f} m above the "
                f"ground), and a grid step may be at most 1/{GRID_CELLS_ACROSS} of the narrower, {limit:.2f} m: "
                "choose a finer one, or fly higher"
            )


def fit_to_flight(flight: Flight, config: Config, keep=frozenset(), gnss: bool = False) -> tuple[Config, list[str]]:
    """``config`` with its geometry-dependent values fitted to ``flight``, and
    one line per value saying what it became and why. ``keep``: the
    ``(table, key)`` pairs the user set, left as they are. ``gnss``: the run
    adds GNSS fixes to its graph (:data:`GNSS_GRAPH_WEIGHTS`)."""
    if not flight.height > 0:  # the lengths scale with the height, and the strip would be empty
        raise SlamError(
            f"the flight is {flight.height:.1f} m above the ground (median over the waypoints): parameters can be "
            "fitted only to a flight above the map (--reference-values keeps the configured ones)"
        )
    wanted = _scaled(flight, config)
    if wanted[("registration", "skip_frames")][0] == 1:
        wanted.update(_low_flight(config, keep))
    elif gnss:
        wanted[("pose_graph", "graph_weights")] = (
            GNSS_GRAPH_WEIGHTS,
            "GNSS fixes are absolute, and against them the edges' sigmas count at their size: each edge is "
            "weighed by its registration's calibrated information (the fixed sigmas let the fixes bend the path)",
        )
    if config.sensor.pattern == "risley":  # a simulated Risley flight runs on a clock: its speed is known
        wanted[("pose_graph", "motion_speed")] = (
            config.sensor.speed,
            "the simulated flight's own speed ([sensor] speed): the motion factor turns a step into its time",
        )
    changes, reasons = {}, []
    for (table, key), (value, why) in wanted.items():
        if (table, key) in keep:
            reasons.append(f"[{table}] {key} = {getattr(getattr(config, table), key)!r}: as given")
            continue
        changes.setdefault(table, {})[key] = value
        reasons.append(f"[{table}] {key} = {value!r}: {why}")
    return config.with_values(**changes), reasons


def _scaled(flight: Flight, config: Config) -> dict:
    """The values that scale with the flight's height and spacing: ``{(table, key): (value, why)}``."""
    k = flight.height / REFERENCE_HEIGHT
    along = flight.spacing / REFERENCE_SPACING  # how much farther apart the waypoints are
    ref_fit, ref_features = TUNED_AT.registration, TUNED_AT.features

    def grid(value):  # a multiple of GRID_ROUNDING, written as one (1.5, not 1.5000000000000002)
        return round(max(1, round(value / GRID_ROUNDING)) * GRID_ROUNDING, 6)

    skip = max(1, round(ref_fit.skip_frames * k / along))
    footprint_step = grid(max(ref_features.grid_step * k, flight.surface_cell))
    scale = footprint_step / ref_features.grid_step  # distances that follow the grid
    grid_step = grid(max(DESCRIPTOR_GRID_FACTOR * ref_features.grid_step * k, flight.surface_cell))
    doubled = (
        f"{DESCRIPTOR_GRID_FACTOR:g} x {k:.2f} x the reference's {ref_features.grid_step} m for a flight "
        f"{flight.height:.0f} m above the ground"
    )
    per_submap = config.map.n_scans_per_submap * skip * flight.spacing  # m flown per submap
    sub_map_thresh = max(1, round(REFERENCE_LOOP_AGE * k / per_submap))
    wanted = {
        ("registration", "skip_frames"): (
            skip,
            f"accepted scans {skip * flight.spacing:.1f} m apart, {skip * flight.spacing / flight.strip:.0%} of "
            f"the {flight.strip:.0f} m strip (the reference: {ref_fit.skip_frames * REFERENCE_SPACING:.0f} m)",
        ),
        ("features", "grid_step"): (
            grid_step,
            f"{doubled} (twice the scaled step: FPFH and the matcher cost in proportion to the points, or more)"
            if grid_step > flight.surface_cell
            else f"the {flight.surface_cell:g} m surface ({doubled} would be finer)",
        ),
        ("registration", "icp_grid_step"): (
            grid(ref_fit.icp_grid_step * scale),
            f"half the footprint's step, {footprint_step:g} m",
        ),
        ("map", "align_grid_step"): (grid(TUNED_AT.map.align_grid_step * scale), "0.8 x the footprint's step"),
        ("registration", "max_distance"): (round(ref_fit.max_distance * scale, 2), "follows the footprint's step"),
        ("registration", "inlier_distance"): (
            round(ref_fit.inlier_distance * scale, 2),
            "2 x the footprint's step",
        ),
        ("loop_closure", "rmse_threshold"): (
            round(max(TUNED_AT.loop_closure.rmse_threshold * k, LOOP_RMSE_NOISES * config.sensor.range_noise), 2),
            f"{k:.2f} x the reference's {TUNED_AT.loop_closure.rmse_threshold} m: a true match's surface RMSE "
            f"follows the spacing of the ray rows, not below {LOOP_RMSE_NOISES} x the {config.sensor.range_noise} m "
            "range noise",
        ),
        ("loop_closure", "sub_map_thresh"): (
            sub_map_thresh,
            f"a loop candidate lies {sub_map_thresh * per_submap:.0f} m of flight back "
            f"({k:.2f} x the reference's {REFERENCE_LOOP_AGE:.0f} m)",
        ),
    }
    return wanted


def _low_flight(config: Config, keep) -> dict:
    """The values of a flight so low that every scan is accepted (``skip_frames`` 1)."""
    wanted = {}
    wanted[("registration", "icp_local_map")] = (
        LOW_FLIGHT_LOCAL_MAP,
        "every scan is accepted, its ray rows about one ICP cell apart: ICP registers onto the last "
        f"{LOW_FLIGHT_LOCAL_MAP} scans merged, whose rows interleave (the reference: the previous scan)",
    )
    wanted[("pose_graph", "edges_back")] = (1, "the local map already holds the scans the edges back would measure")
    wanted[("registration", "icp_max_iterations")] = (
        LOW_FLIGHT_ICP_ITERATIONS,
        "ICP onto the local map crawls along the track where the ground pins it loosely: 30 iterations "
        "stopped short of its minimum",
    )
    wanted[("pose_graph", "information")] = (
        LOW_FLIGHT_INFORMATION,
        "each step's information from the point-to-plane Hessian of its pairs, which sees that a step over "
        "flat ground is loose along it (generalized ICP's own claims a few centimetres there)",
    )
    if _kept(config, keep, "registration", "icp_local_map", LOW_FLIGHT_LOCAL_MAP) > 1 and (
        _kept(config, keep, "pose_graph", "edges_back", 1) == 1
    ):  # the graph the weights were measured on (see LOW_FLIGHT_GRAPH)
        wanted[("pose_graph", "graph_weights")] = (
            LOW_FLIGHT_GRAPH["graph_weights"],
            "every scan is accepted, each step pinned across a short strip but loosely along it: each edge "
            "is weighed by its own registration's information, which says which way it is loose",
        )
        wanted[("pose_graph", "loop_kernel")] = (
            LOW_FLIGHT_GRAPH["loop_kernel"],
            "under each edge's own information a true loop may end several of its sigmas off: Huber's "
            "kernel keeps it, Cauchy's set such loops aside",
        )
        wanted[("pose_graph", "motion_factor")] = (
            LOW_FLIGHT_GRAPH["motion_factor"],
            "along the directions a step does not pin, its information is loose, and the flight's momentum "
            "(a soft constant-velocity factor over three nodes) holds them",
        )
    return wanted


def _kept(config: Config, keep, table: str, key: str, fitted):
    """The value ``(table, key)`` will have: the user's when ``keep`` holds it, else ``fitted``."""
    return getattr(getattr(config, table), key) if (table, key) in keep else fitted
