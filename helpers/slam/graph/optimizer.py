"""A 3-D pose graph on GTSAM, with numpy at the boundary (stage 6).

The graph keeps a list of factors (:mod:`helpers.slam.graph.factors` says their
conventions: poses ``T_map_sensor``, edges ``T_i_j`` with
``pose_j = pose_i @ T_i_j``, sigmas and information translation first).
:meth:`PoseGraph.add_factor` takes any factor, a new kind included;
``add_odometry``, ``append`` and ``add_loop`` are the usual ones by name.

The rhythm is GTSAM's own: graph, prior on the first node, the factors in
the order they were added, initial values, optimise (Levenberg-Marquardt),
with the graph error logged before and after.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import gtsam
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from helpers.errors import SlamError
from helpers.geometry import check_pose
from helpers.slam.graph.factors import (
    KERNEL_SCALES,
    LOOP_INFORMATION,
    ODOMETRY_SIGMAS,
    PRIOR_SIGMAS,
    BetweenFactor,
    Factor,
    FactorContext,
    LoopFactor,
    PriorFactor,
    check_information,
    information_from_sigmas,
    loop_noise_factory,
    pose3,
)

log = logging.getLogger(__name__)

__all__ = ["KERNEL_SCALES", "PRIOR_SIGMAS", "OptimizationResult", "PoseGraph", "information_from_sigmas"]

MAX_ITERATIONS = 100


@dataclass(frozen=True)
class OptimizationResult:
    """What :meth:`PoseGraph.optimize` gives back.

    ``poses`` are the optimised (K, 4, 4) poses, ``initial_poses`` the starting
    ones moved to the anchor (the odometry-only trajectory, for comparison). The ``loop_*`` arrays have one
    entry per loop edge, in the order the edges were added: the residual left
    after optimisation (translation in m, rotation in deg), its whitened norm
    (in sigmas) and the weight the robust kernel gave it (1 = fully trusted,
    near 0 = ignored; always 1 with kernel ``"none"``).
    """

    poses: np.ndarray
    initial_poses: np.ndarray
    error_before: float
    error_after: float
    iterations: int
    loop_pairs: np.ndarray
    loop_translation_error: np.ndarray
    loop_rotation_error: np.ndarray
    loop_whitened_norm: np.ndarray
    loop_weights: np.ndarray


class PoseGraph:
    """Nodes with initial 4 x 4 poses, and factors between them.

    For example::

        graph = PoseGraph()
        graph.add_node(np.eye(4))  # node 0
        graph.append(step)  # node 1 at pose_0 @ step, joined by an odometry edge
        graph.add_loop(0, 1, T_0_1)  # a loop edge: pose_1 = pose_0 @ T_0_1
        graph.add_factor(PriorFactor(1, T_map_sensor, sigmas))  # any other factor
        result = graph.optimize(anchor_pose=first_true_pose, loop_kernel="cauchy")
        result.poses, result.loop_weights
    """

    def __init__(self) -> None:
        self._poses: list[np.ndarray] = []
        self.factors: list[Factor] = []

    # -- building -----------------------------------------------------------
    @property
    def num_nodes(self) -> int:
        return len(self._poses)

    @property
    def initial_poses(self) -> np.ndarray:
        """The (K, 4, 4) initial poses, as added."""
        return np.array(self._poses).reshape(-1, 4, 4)

    def add_node(self, pose: np.ndarray) -> int:
        """Add a node with its initial pose; returns its id (0, 1, 2, ...)."""
        self._poses.append(check_pose(pose, f"the initial pose of node {self.num_nodes}"))
        return self.num_nodes - 1

    def add_factor(self, factor: Factor) -> Factor:
        """Add any factor whose ``nodes`` exist (see :mod:`helpers.slam.graph.factors`); returns it."""
        kind = type(factor).__name__
        for k in factor.nodes:
            if not isinstance(k, (int, np.integer)) or not 0 <= k < self.num_nodes:
                raise SlamError(f"{kind} on {factor.nodes}: node {k} does not exist (the graph has {self.num_nodes})")
        if len(factor.nodes) == 2 and factor.nodes[0] == factor.nodes[1]:
            raise SlamError(f"{kind} on {factor.nodes} joins a node to itself")
        self.factors.append(factor)
        return factor

    def add_odometry(self, i: int, j: int, T_i_j: np.ndarray, sigmas=ODOMETRY_SIGMAS, information=None) -> None:
        """An odometry edge ``pose_j = pose_i @ T_i_j``, noise ``sigmas`` (x y z rx ry rz) or, when given,
        ``information`` (6 x 6, translation first)."""
        info = information_from_sigmas(sigmas) if information is None else check_information(information)
        self._between(BetweenFactor, i, j, T_i_j, info, "odometry")

    def append(self, T_last_new: np.ndarray, sigmas=ODOMETRY_SIGMAS) -> int:
        """Chain a new node after the last one, ``T_last_new`` from it (like ``addRelativePose`` without ids);
        returns its id."""
        if self.num_nodes == 0:
            raise SlamError("the pose graph is empty: add the first node with add_node() before chaining")
        step = check_pose(T_last_new, "the odometry step")
        j = self.add_node(self._poses[-1] @ step)
        self.add_odometry(j - 1, j, step, sigmas)
        return j

    def add_loop(self, i: int, j: int, T_i_j: np.ndarray, information=None) -> int:
        """A loop edge ``pose_j = pose_i @ T_i_j``; returns its index among loop edges.

        ``information`` is a symmetric positive-definite 6 x 6 matrix in the
        reference's order x y z rx ry rz (identity when not given, as in the
        reference); it is permuted to GTSAM's rotation-first order inside.
        """
        info = LOOP_INFORMATION if information is None else check_information(information)
        self._between(LoopFactor, i, j, T_i_j, info, "loop")
        return len(self._loops()) - 1

    def loop_pairs(self) -> list[tuple[int, int]]:
        """The (i, j) node pairs of the loop edges, in the order they were added."""
        return [(f.i, f.j) for f in self._loops()]

    # -- optimising ---------------------------------------------------------
    def optimize(
        self,
        anchor_pose: np.ndarray | None = None,
        loop_kernel: str = "none",
        kernel_scale: float | None = None,
        max_iterations: int = MAX_ITERATIONS,
    ) -> OptimizationResult:
        """Optimise with Levenberg-Marquardt, the first node held at ``anchor_pose``.

        The initial poses are first moved rigidly so that node 0 sits at the
        anchor (identity when not given). ``loop_kernel`` wraps every loop edge
        in a robust kernel: ``"none"`` (the reference: every loop is trusted),
        ``"huber"`` or ``"cauchy"``, with ``kernel_scale`` in sigmas (default
        :data:`KERNEL_SCALES`). Other factors are never robust.
        """
        if self.num_nodes == 0:
            raise SlamError("the pose graph is empty: there is nothing to optimise")
        anchor = np.eye(4) if anchor_pose is None else check_pose(anchor_pose, "the anchor pose")
        if int(max_iterations) != max_iterations or max_iterations < 1:
            raise SlamError(f"max_iterations must be a positive integer, got {max_iterations!r}")
        # 1-2. the prior holding the first node at the anchor, then every factor in the order added
        graph, loop_factors = self._to_gtsam(anchor, loop_kernel, kernel_scale)
        self._check_connected()
        # 3. initial values, moved so that node 0 is at the anchor
        start = anchor @ np.linalg.inv(self._poses[0]) @ self.initial_poses
        initial = gtsam.Values()
        for k, pose in enumerate(start):
            initial.insert(k, pose3(pose))
        # 4. optimise
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(max_iterations)
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        try:
            result = optimizer.optimize()
        except RuntimeError as exc:  # e.g. GTSAM's indeterminant linear system
            raise SlamError(f"GTSAM could not optimise the pose graph: {exc}") from None
        before, after = graph.error(initial), graph.error(result)
        log.info(
            "pose graph: %d nodes, %d factors, %d of them loop edges (kernel %s); error %.6g -> %.6g in %d iterations",
            self.num_nodes,
            len(self.factors),
            len(loop_factors),
            loop_kernel,
            before,
            after,
            optimizer.iterations(),
        )
        poses = np.array([result.atPose3(k).matrix() for k in range(self.num_nodes)])
        report = _loop_report(loop_factors, result)
        return OptimizationResult(poses, start, before, after, optimizer.iterations(), *report)

    def position_sigmas(
        self, poses: np.ndarray, anchor_pose: np.ndarray, loop_kernel: str = "none", kernel_scale: float | None = None
    ) -> np.ndarray:
        """(K,) how sure the graph is of each node's position, in metres: the square root of the trace of
        the node's marginal position covariance (:meth:`position_covariances`). Near the anchor it is small;
        along a chain of odometry edges it grows with their noise; absolute factors (GNSS fixes) keep it
        near their own sigmas everywhere."""
        covariances = self.position_covariances(poses, anchor_pose, loop_kernel, kernel_scale)
        return np.sqrt(np.trace(covariances, axis1=1, axis2=2))

    def position_covariances(
        self, poses: np.ndarray, anchor_pose: np.ndarray, loop_kernel: str = "none", kernel_scale: float | None = None
    ) -> np.ndarray:
        """(K, 3, 3) each node's marginal position covariance (m², ``gtsam.Marginals``) in the map frame, the
        graph linearised at ``poses`` (K x 4 x 4, its optimised poses) with the first node held at
        ``anchor_pose`` as :meth:`optimize` holds it."""
        poses = np.asarray(poses, dtype=float)
        graph, _ = self._gtsam_at(poses, anchor_pose, loop_kernel, kernel_scale)
        marginals = self._marginals(graph, self._values(poses))
        # a Pose3's covariance is rotation first and in the node's own frame: its rotation carries it to the map's
        local = np.array([marginals.marginalCovariance(k)[3:, 3:] for k in range(self.num_nodes)])
        rotations = poses[:, :3, :3]
        return rotations @ local @ np.swapaxes(rotations, 1, 2)

    def linearised(
        self, poses: np.ndarray, anchor_pose: np.ndarray, loop_kernel: str = "none", kernel_scale: float | None = None
    ) -> tuple[list[LoopFactor], list, gtsam.Values, gtsam.Marginals]:
        """The graph as GTSAM sees it at ``poses`` (K x 4 x 4, its optimised poses) with the first node held at
        ``anchor_pose``: the loop edges (ours, in the order added), their GTSAM factors (wrapped in
        ``loop_kernel``), the values and the marginals, for measures that linearise single factors
        (:func:`helpers.quality.graph_checks.left_out_residuals`)."""
        graph, loop_factors = self._gtsam_at(poses, anchor_pose, loop_kernel, kernel_scale)
        values = self._values(poses)
        return self._loops(), loop_factors, values, self._marginals(graph, values)

    def _gtsam_at(self, poses, anchor_pose, loop_kernel, kernel_scale):
        """:meth:`_to_gtsam` for marginals at ``poses`` (checked to be one per node)."""
        poses = np.asarray(poses, dtype=float)
        if poses.shape != (self.num_nodes, 4, 4):
            raise SlamError(f"the marginals need {self.num_nodes} poses (4 x 4), got an array of {poses.shape}")
        graph, loop_factors = self._to_gtsam(check_pose(anchor_pose, "the anchor pose"), loop_kernel, kernel_scale)
        self._check_connected()
        return graph, loop_factors

    @staticmethod
    def _values(poses) -> gtsam.Values:
        values = gtsam.Values()
        for k, pose in enumerate(np.asarray(poses, dtype=float)):
            values.insert(k, pose3(pose))
        return values

    @staticmethod
    def _marginals(graph, values) -> gtsam.Marginals:
        try:
            return gtsam.Marginals(graph, values)
        except RuntimeError as exc:
            raise SlamError(f"GTSAM could not compute the pose graph's marginals: {exc}") from None

    def _to_gtsam(self, anchor: np.ndarray, loop_kernel: str, kernel_scale: float | None):
        """GTSAM's factor graph: a prior holding node 0 at ``anchor``, then every factor in the order added,
        loop edges wrapped in ``loop_kernel``; and the loop edges' GTSAM factors."""
        context = FactorContext(loop_noise=loop_noise_factory(loop_kernel, kernel_scale))
        graph = gtsam.NonlinearFactorGraph()
        graph.add(PriorFactor(0, anchor).to_gtsam(context))
        loop_factors = []
        for factor in self.factors:
            added = factor.to_gtsam(context)
            graph.add(added)
            if isinstance(factor, LoopFactor):
                loop_factors.append(added)
        return graph, loop_factors

    def _loops(self) -> list[LoopFactor]:
        return [f for f in self.factors if isinstance(f, LoopFactor)]

    def _between(self, kind, i, j, T_i_j, information, name: str) -> None:
        for k in (i, j):
            if not isinstance(k, (int, np.integer)) or not 0 <= k < self.num_nodes:
                raise SlamError(f"{name} edge ({i}, {j}): node {k} does not exist (the graph has {self.num_nodes})")
        if i == j:
            raise SlamError(f"{name} edge ({i}, {j}) joins a node to itself")
        self.factors.append(kind(int(i), int(j), check_pose(T_i_j, f"the {name} edge ({i}, {j})"), information))

    def _check_connected(self) -> None:
        edges = np.array([f.nodes for f in self.factors if len(f.nodes) == 2], dtype=int).reshape(-1, 2)
        links = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(self.num_nodes,) * 2)
        _, label = connected_components(links, directed=False)
        loose = np.flatnonzero(label != label[0])
        if loose.size:
            raise SlamError(f"node(s) {loose[:10].tolist()} are linked to node 0 by no chain of edges")


def _loop_report(factors, values) -> tuple[np.ndarray, ...]:
    """Per loop edge: pairs, translation (m) and rotation (deg) residual, whitened norm, weight."""
    rows = []
    for f in factors:
        residual = f.unwhitenedError(values)  # rotation first
        noise = f.noiseModel()
        robust = isinstance(noise, gtsam.noiseModel.Robust)
        norm = float(np.linalg.norm(noise.unweightedWhiten(residual) if robust else noise.whiten(residual)))
        weight = noise.robust().weight(norm) if robust else 1.0
        rotation_deg = np.degrees(np.linalg.norm(residual[:3]))
        rows.append((*f.keys(), np.linalg.norm(residual[3:]), rotation_deg, norm, weight))
    pairs = np.array([r[:2] for r in rows], dtype=int).reshape(-1, 2)
    stats = np.array([r[2:] for r in rows], dtype=float).reshape(-1, 4)
    return (pairs, *stats.T)
