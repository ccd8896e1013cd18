"""What the trust flag (:mod:`helpers.quality.trust`) reads from a run's pose graph: the graph rebuilt from the
run's edges and optimised again with some loop edges left out (what the loops moved, how far doubtful
loops still pull), where the optimised graph leaves each loop edge, the ATE the graph expects of its own
trajectory (from its marginal covariances), how well the loops observe the flight's scale, and the scans
that come back over ground flown earlier.
Each is a measure, not a verdict: :func:`helpers.quality.trust.assess` turns them into one.
"""

from __future__ import annotations

import gtsam
import numpy as np

from helpers.errors import SlamError
from helpers.quality.metrics import is_false_loop
from helpers.slam.graph.build import build_pose_graph
from helpers.slam.graph.factors import FactorContext, edge_information, pose3
from helpers.slam.graph.information import SWAP_ROTATION_TRANSLATION, whitened
from helpers.slam.loops.closer import radius_after

LEFT_FACTOR = 4.0  # a revisit: back within the search radius after flying this many (fixed) radii away
MOVE_FLOOR_M = 0.01  # m: a move this small is no move (correction_sigmas)
FALSE_LOOP_SIGMAS = 5.0  # a loop edge left this far off by the optimisation disagrees with the graph
# (true loops end within a few sigmas of where the graph puts them, false ones far beyond: the benchmarks on the
# default flight and on Autzen measure both)


def expected_ate(result) -> float:
    """The ATE (m) the run's graph expects of its own trajectory: the root mean square, over its nodes, of
    each node's position sigma (:meth:`helpers.slam.graph.optimizer.PoseGraph.position_sigmas`), in the graph the run
    optimised (its edges, loops and GNSS fixes, the first node held where the run held it) at the optimised
    poses. It is as honest as the edges' information: with calibrated information and a fix at every scan
    the ATE was 0.9-1.35 times it on six low flights, four with 2 m fixes and two with 10 m ones
    (``benchmarks/README.md``, "The motion factor and GNSS")."""
    graph = _graph_as_run(result)
    sigmas = graph.position_sigmas(
        result.graph.poses, result.graph.initial_poses[0], loop_kernel=result.config.pose_graph.loop_kernel
    )
    return float(np.sqrt(np.mean(sigmas**2)))


def loop_scale(result) -> tuple[float, float, float]:
    """How well the run's loop edges observe the flight's scale: (the scale's sigma, a share of 1, by
    :func:`scale_sigma` at the optimised poses, each loop weighed by the information the graph gave it; the
    RMS distance (m) of the nodes from the first, which a scale error of 1 moves them by; the longest lever,
    m)."""
    poses = np.asarray(result.graph.poses, dtype=float)
    loops = result.loops
    information = [edge_information(loop, result.config.pose_graph, loop=True) for loop in loops]
    sigma, lever = scale_sigma(poses, [(loop.i, loop.j) for loop in loops], information)
    reach = float(np.sqrt(np.mean(np.sum((poses[:, :3, 3] - poses[0, :3, 3]) ** 2, axis=1))))
    return sigma, reach, lever


def scale_sigma(poses: np.ndarray, pairs, information) -> tuple[float, float]:
    """(sigma of a scale error of the whole flight, the longest lever in m) as loop edges observe it.

    A flight whose step lengths are all off by a share ``s`` (a biased odometry) has every position moved
    from the first by ``s`` times its offset from it, and the offset between the two ends of a loop edge
    by ``s`` times that offset, the edge's *lever*. A loop that closes where the flight passed before
    has almost none: a shrunk lap closes on a shrunk lap, and the edge agrees with both. Each edge
    (``pairs`` of node indices into ``poses``, (N, 4, 4) map-frame, with its 6 x 6 translation-first
    ``information``, in the frame of its first node) measures ``s`` with the information
    ``lever' C^-1 lever``, C its translation covariance; the sigma is one over the root of their sum
    (``inf`` with no loop, or none with a lever)."""
    total, longest = 0.0, 0.0
    for (i, j), info in zip(pairs, information, strict=True):
        lever = poses[i, :3, :3].T @ (poses[j, :3, 3] - poses[i, :3, 3])  # in the frame of node i
        covariance = np.linalg.inv(np.asarray(info, dtype=float))[:3, :3]
        total += float(lever @ np.linalg.solve(covariance, lever))
        longest = max(longest, float(np.linalg.norm(lever)))
    return (1.0 / np.sqrt(total) if total > 0 else float("inf")), longest


def loop_correction(result, rebuilt=None, without=None) -> float:
    """How far (m) the loop edges moved any pose: the run's graph against the same graph without them, both
    rebuilt from the run's edges (as :func:`loop_pull`: GNSS fixes in the run's own graph move it too, and
    that is not the loops' doing). ``rebuilt``: the run's graph's poses so rebuilt, and ``without``: those of
    the graph without loops (``optimized_with(result, [])``), if already computed."""
    if not result.loops:
        return 0.0
    rebuilt = rebuilt_poses(result) if rebuilt is None else rebuilt
    return _moved(rebuilt, optimized_with(result, []) if without is None else without)


def correction_sigmas(result, rebuilt=None, without=None) -> float:
    """How far the loop edges moved the trajectory, in sigmas of the odometry's own uncertainty: the largest,
    over the nodes, of the Mahalanobis length of a node's move (the run's graph against the same graph without
    loops, as :func:`loop_correction`) under its position covariance in the graph without loops
    (:meth:`helpers.slam.graph.optimizer.PoseGraph.position_covariances`, widened by :data:`MOVE_FLOOR_M`: the anchored
    first node is known to micrometres). Odometry whose errors are independent, as its information says,
    comes back by a few sigmas; a loop that bends the graph beyond what its steps allow moves it by many, and
    so do loops mending errors that ran the same way for tens of steps (:mod:`helpers.quality.trust` counts it, and
    tells the two apart by :func:`loops_off_the_rest`). ``rebuilt`` and ``without`` as for
    :func:`loop_correction`."""
    if not result.loops:
        return 0.0
    rebuilt = rebuilt_poses(result) if rebuilt is None else rebuilt
    free = optimized_with(result, []) if without is None else without
    kernel = result.config.pose_graph.loop_kernel
    covariances = _run_graph(result, []).position_covariances(free, result.odometry.poses[0], loop_kernel=kernel)
    covariances = covariances + MOVE_FLOOR_M**2 * np.eye(3)
    moved = rebuilt[:, :3, 3] - free[:, :3, 3]
    squared = np.einsum("ki,ki->k", moved, np.linalg.solve(covariances, moved[:, :, None])[:, :, 0])
    return float(np.sqrt(squared.max()))


def left_out_residuals(result) -> list[tuple[float, float, float]]:
    """Per loop edge: how far it ends from where the run's graph *without it* puts it, (m, deg, sigmas)
    (:func:`deleted_residuals` in the graph the run optimised: its edges, loops and GNSS fixes, at its
    optimised poses). Unlike :func:`loop_residuals` it sees a loop the graph bent to: surer than the steps
    around it, such a loop ends near the optimised graph, but far from the graph without it. Raises
    :class:`helpers.errors.SlamError` when GTSAM cannot compute the marginals."""
    if not result.loops:
        return []
    residuals, lengths = deleted_residuals(
        _graph_as_run(result),
        result.graph.poses,
        result.graph.initial_poses[0],
        loop_kernel=result.config.pose_graph.loop_kernel,
    )
    metres, degrees = np.linalg.norm(residuals[:, 3:], axis=1), np.degrees(np.linalg.norm(residuals[:, :3], axis=1))
    return [(float(m), float(d), float(n)) for m, d, n in zip(metres, degrees, lengths, strict=True)]


def deleted_residuals(graph, poses, anchor_pose, loop_kernel: str = "none") -> tuple[np.ndarray, np.ndarray]:
    """Where each loop edge of ``graph`` (a :class:`helpers.slam.graph.optimizer.PoseGraph`) ends against the graph
    *without it*: its leave-one-out (deleted) residual, the graph linearised at ``poses`` (its optimised
    poses, the loops weighed by ``loop_kernel`` as the optimisation weighed them) with the first node held
    at ``anchor_pose``. Returns ((L, 6) residuals, rotation first as GTSAM's ``Pose3.Logmap`` gives them,
    and (L,) their Mahalanobis lengths under the loop's own information and the graph's uncertainty without
    it), in loop-edge order.

    A loop's residual at the optimum understates how far it is from the rest of the graph: the graph has
    moved towards it, all the way when it is surer than the edges around it. With ``A`` the loop factor's
    whitened Jacobian on its two nodes, ``b`` its right-hand side and ``P`` their joint marginal covariance,
    leaving it out moves them by ``-P A^T S^-1 b``, ``S = I - A P A^T``, and widens ``P`` by
    ``P A^T S^-1 A P`` (regression's deletion formulas, one linear step from the optimum); the loop's plain
    Gaussian factor there gives the residual, and its information plus the widened ``P`` its covariance.
    Under a kernel the other loops keep the weights the optimum gave them (optimised again without the loop,
    they could weigh a little differently). A loop that alone joins its ends (``S`` singular) gets infinite
    ones. Raises :class:`helpers.errors.SlamError` when GTSAM cannot compute the marginals."""
    loops, loop_factors, values, marginals = graph.linearised(poses, anchor_pose, loop_kernel)
    residuals, lengths = np.full((len(loops), 6), np.inf), np.full(len(loops), np.inf)
    for k, (factor, loop) in enumerate(zip(loop_factors, loops, strict=True)):
        A, b = factor.linearize(values).jacobian()
        keys = list(factor.keys())
        try:
            joint = marginals.jointMarginalCovariance(gtsam.KeyVector(keys))
        except RuntimeError as exc:
            raise SlamError(f"GTSAM could not compute loop edge {loop.i}-{loop.j}'s marginals: {exc}") from None
        P = np.block([[joint.at(row, column) for column in keys] for row in keys])
        S = np.eye(len(b)) - A @ P @ A.T
        if np.linalg.eigvalsh(S).min() <= 1e-9:  # the loop alone joins its ends
            continue
        AP = A @ P
        move = -AP.T @ np.linalg.solve(S, b)
        P_without = P + AP.T @ np.linalg.solve(S, AP)
        plain_A, plain_b = loop.to_gtsam(FactorContext()).linearize(values).jacobian()
        off = plain_A @ move - plain_b  # whitened by the loop's own information
        spread = np.eye(len(off)) + plain_A @ P_without @ plain_A.T
        lengths[k] = np.sqrt(max(float(off @ np.linalg.solve(spread, off)), 0.0))
        # unwhitened through the Jacobian on the loop's second node (identity at a zero residual)
        residuals[k] = np.linalg.solve(plain_A[:, 6 * keys.index(loop.j) :][:, :6], off)
    return residuals, lengths


def loops_off_the_rest(result) -> list[tuple[object, tuple[float, float, float]]]:
    """The loop edges the rest of the graph disagrees with, each judged against the graph without it
    (:func:`left_out_residuals`): beyond :data:`FALSE_LOOP_SIGMAS` and farther off than a false loop
    (:func:`helpers.quality.metrics.is_false_loop`). Each as (loop edge, (m, deg, sigmas))."""

    return [
        (loop, residual)
        for loop, residual in zip(result.loops, left_out_residuals(result), strict=True)
        if residual[2] > FALSE_LOOP_SIGMAS and is_false_loop(residual[0], residual[1])
    ]


def loop_pull(result, suspects, rebuilt=None) -> float:
    """How far (m) the loop edges ``suspects`` still move any pose: the run's graph against the same graph
    without them, both rebuilt from the run's edges (the run's own graph may hold GNSS fixes, whose pull is
    not the suspects'). A false loop that a robust kernel set aside pulls by millimetres to centimetres; one
    it could not, or with no kernel, by metres. ``rebuilt`` as for :func:`loop_correction`."""
    if not suspects:
        return 0.0
    kept = [loop for loop in result.loops if not any(loop is suspect for suspect in suspects)]
    rebuilt = rebuilt_poses(result) if rebuilt is None else rebuilt
    return _moved(rebuilt, optimized_with(result, kept))


def rebuilt_poses(result) -> np.ndarray:
    """(N, 4, 4) poses of the run's graph rebuilt from its edges (GNSS fixes left out). Without fixes, and
    anchored where the odometry starts, that is the run's own graph optimised from the same start: its
    poses are taken as they are (the same bits on every flight measured), which saves a whole
    optimisation (1.2-1.7 s on the 570-620-node tile flights)."""
    anchored = np.allclose(result.graph.initial_poses[0], result.odometry.poses[0], rtol=0.0, atol=1e-9)
    if not result.gnss_factors and anchored:
        return result.graph.poses
    return optimized_with(result, result.loops)


def optimized_with(result, loops) -> np.ndarray:
    """(N, 4, 4) poses of the run's graph with only ``loops`` as its loop edges, optimised as the run was."""
    graph = _run_graph(result, loops)
    return graph.optimize(anchor_pose=result.odometry.poses[0], loop_kernel=result.config.pose_graph.loop_kernel).poses


def _run_graph(result, loops):
    """The run's pose graph rebuilt from its edges (:func:`helpers.slam.graph.build.build_pose_graph`) with ``loops`` as
    its loop edges and no GNSS fix."""

    return build_pose_graph(result.odometry, result.extra_edges, loops, result.config)


def _graph_as_run(result):
    """The graph the run optimised, rebuilt: its edges, its loop edges and its GNSS fixes."""
    graph = _run_graph(result, result.loops)
    for fix in result.gnss_factors:
        graph.add_factor(fix)
    return graph


def _moved(poses: np.ndarray, other: np.ndarray) -> float:
    """The largest distance (m) between the positions of two trajectories of the same nodes."""
    return float(np.linalg.norm(poses[:, :3, 3] - other[:, :3, 3], axis=1).max())


def loop_residuals(result) -> list[tuple[float, float, float]]:
    """Per loop edge: how far the optimised graph leaves it, (m, deg, sigmas). The sigmas whiten the
    residual by the edge's own calibrated information, or are the graph's when it has none."""
    poses, out = result.graph.poses, []
    for k, loop in enumerate(result.loops):
        estimate = np.linalg.inv(poses[loop.i]) @ poses[loop.j]
        xi = np.asarray(gtsam.Pose3.Logmap(pose3(np.linalg.inv(loop.relative) @ estimate)))[SWAP_ROTATION_TRANSLATION]
        info = loop.information
        norm = whitened(xi, info) if info is not None else float(result.graph.loop_whitened_norm[k])
        out.append((float(np.linalg.norm(xi[:3])), float(np.degrees(np.linalg.norm(xi[3:]))), norm))
    return out


def loops_against_graph(result) -> list:
    """The loop edges the rest of the graph disagrees with: beyond :data:`FALSE_LOOP_SIGMAS` and farther
    off than a false loop (:func:`helpers.quality.metrics.is_false_loop`, the graph taken for the truth)."""

    residuals = loop_residuals(result)
    return [
        loop
        for loop, (metres, degrees, sigmas) in zip(result.loops, residuals, strict=True)
        if sigmas > FALSE_LOOP_SIGMAS and is_false_loop(metres, degrees)
    ]


def revisits(result, flown: np.ndarray) -> tuple[int, int]:
    """Nodes whose odometry position comes back within the loop search radius
    (the loop closer's, :func:`helpers.slam.loops.closer.radius_after`) of a node
    left more than ``LEFT_FACTOR`` fixed radii of flight earlier (revisits),
    and how many of them have no loop edge within that many radii of flight.
    ``flown``: the distance flown to each node, along the odometry."""
    positions = result.odometry.poses[:, :3, 3]
    if len(positions) < 3:
        return 0, 0
    settings = result.config.loop_closure
    since = flown[:, None] - flown[None, :]  # row k flew that far since column i
    reach = radius_after(np.abs(since), settings)  # the loop closer's search radius between each pair
    near = np.linalg.norm(positions[:, None, :2] - positions[None, :, :2], axis=2) < reach
    radius = radius_after(0.0, settings)  # around a place just left: the fixed radius
    left = since > LEFT_FACTOR * radius
    revisit = (near & left).any(axis=1)
    closed = np.zeros(len(positions), bool)
    for loop in result.loops:
        closed |= np.abs(flown - flown[loop.j]) <= LEFT_FACTOR * radius
    return int(revisit.sum()), int((revisit & ~closed).sum())
