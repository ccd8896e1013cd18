"""A 3-D pose graph on GTSAM, with numpy at the boundary (stage 6).

Conventions, used everywhere in this module:

* A pose is a 4 x 4 rigid transform from its scan's frame to the map frame:
  ``p_map = pose @ p_scan``.
* An edge ``(i, j, T_ij)`` says ``pose_j = pose_i @ T_ij``: ``T_ij`` carries
  points of scan ``j`` into the frame of scan ``i``. ICP that registers scan
  ``j`` (moving) onto scan ``i`` (fixed) returns exactly this ``T_ij``.
* Six-vectors and information matrices given to or returned by this module
  are TRANSLATION FIRST, ``[x y z rx ry rz]``, as in the reference's
  ``poseGraph3D``. GTSAM orders a Pose3 tangent vector rotation first, so the
  module permutes every information matrix (and sigma vector) on the way in.

The rhythm is GTSAM's own: graph, prior on the first node, odometry edges,
loop edges, initial values, optimise (Levenberg-Marquardt), with the graph
error logged before and after.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import gtsam
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .config import LOOP_KERNELS
from .errors import SlamError
from .geometry import check_pose

log = logging.getLogger(__name__)

# The reference weighs every edge, odometry and loop alike, with the identity
# information matrix: one sigma of 1 m on each translation and 1 rad on each
# rotation component. Order: x y z rx ry rz.
ODOMETRY_SIGMAS = np.ones(6)
LOOP_INFORMATION = np.eye(6)
# The anchor (the reference's FirstNodePose) is held by a very stiff prior.
PRIOR_SIGMAS = np.full(6, 1e-4)
# Robust kernels act on the whitened residual norm (in sigmas). These are the
# textbook tunings that keep 95 % efficiency on Gaussian noise.
KERNEL_SCALES = {"huber": 1.345, "cauchy": 2.3849}
_ESTIMATORS = {"huber": gtsam.noiseModel.mEstimator.Huber, "cauchy": gtsam.noiseModel.mEstimator.Cauchy}
MAX_ITERATIONS = 100

_TO_GTSAM = np.array([3, 4, 5, 0, 1, 2])  # translation-first index -> rotation-first order


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


@dataclass(frozen=True)
class _Edge:
    i: int
    j: int
    relative: np.ndarray
    information: np.ndarray  # translation first


class PoseGraph:
    """Nodes with initial 4 x 4 poses, odometry edges and loop edges.

    For example::

        graph = PoseGraph()
        graph.add_node(np.eye(4))  # node 0
        graph.append(step)  # node 1 at pose_0 @ step, joined by an odometry edge
        graph.add_loop(0, 1, T_01)  # a loop edge: pose_1 = pose_0 @ T_01
        result = graph.optimize(anchor_pose=first_true_pose, loop_kernel="cauchy")
        result.poses, result.loop_weights
    """

    def __init__(self) -> None:
        self._poses: list[np.ndarray] = []
        self._odometry: list[_Edge] = []
        self._loops: list[_Edge] = []

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

    def add_odometry(self, i: int, j: int, relative_pose: np.ndarray, sigmas=ODOMETRY_SIGMAS) -> None:
        """An odometry edge ``pose_j = pose_i @ relative_pose``, noise ``sigmas`` (x y z rx ry rz)."""
        self._odometry.append(self._edge(i, j, relative_pose, information_from_sigmas(sigmas), "odometry"))

    def append(self, relative_pose: np.ndarray, sigmas=ODOMETRY_SIGMAS) -> int:
        """Chain a new node after the last one (like ``addRelativePose`` without ids); returns its id."""
        if self.num_nodes == 0:
            raise SlamError("the pose graph is empty: add the first node with add_node() before chaining")
        step = check_pose(relative_pose, "the odometry step")
        j = self.add_node(self._poses[-1] @ step)
        self.add_odometry(j - 1, j, step, sigmas)
        return j

    def add_loop(self, i: int, j: int, relative_pose: np.ndarray, information=None) -> int:
        """A loop edge ``pose_j = pose_i @ relative_pose``; returns its index among loop edges.

        ``information`` is a symmetric positive-definite 6 x 6 matrix in the
        reference's order x y z rx ry rz (identity when not given, as in the
        reference); it is permuted to GTSAM's rotation-first order inside.
        """
        info = LOOP_INFORMATION if information is None else _check_information(information)
        self._loops.append(self._edge(i, j, relative_pose, info, "loop"))
        return len(self._loops) - 1

    def loop_pairs(self) -> list[tuple[int, int]]:
        """The (i, j) node pairs of the loop edges, in the order they were added."""
        return [(e.i, e.j) for e in self._loops]

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
        :data:`KERNEL_SCALES`). Odometry edges and the prior are never robust.
        """
        if self.num_nodes == 0:
            raise SlamError("the pose graph is empty: there is nothing to optimise")
        anchor = np.eye(4) if anchor_pose is None else check_pose(anchor_pose, "the anchor pose")
        if int(max_iterations) != max_iterations or max_iterations < 1:
            raise SlamError(f"max_iterations must be a positive integer, got {max_iterations!r}")
        loop_noise = _loop_noise_factory(loop_kernel, kernel_scale)
        self._check_connected()

        # 1. graph, with the prior holding the first node at the anchor
        graph = gtsam.NonlinearFactorGraph()
        prior_noise = gtsam.noiseModel.Diagonal.Sigmas(PRIOR_SIGMAS[_TO_GTSAM])
        graph.add(gtsam.PriorFactorPose3(0, _pose3(anchor), prior_noise))
        # 2. odometry edges
        for e in self._odometry:
            graph.add(gtsam.BetweenFactorPose3(e.i, e.j, _pose3(e.relative), _gaussian(e.information)))
        # 3. loop edges
        loop_factors = []
        for e in self._loops:
            loop_factors.append(gtsam.BetweenFactorPose3(e.i, e.j, _pose3(e.relative), loop_noise(e.information)))
            graph.add(loop_factors[-1])
        # 4. initial values, moved so that node 0 is at the anchor
        start = anchor @ np.linalg.inv(self._poses[0]) @ self.initial_poses
        initial = gtsam.Values()
        for k, pose in enumerate(start):
            initial.insert(k, _pose3(pose))
        # 5. optimise
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(max_iterations)
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        try:
            result = optimizer.optimize()
        except RuntimeError as exc:  # e.g. GTSAM's indeterminant linear system
            raise SlamError(f"GTSAM could not optimise the pose graph: {exc}") from None
        before, after = graph.error(initial), graph.error(result)
        log.info(
            "pose graph: %d nodes, %d odometry and %d loop edges (kernel %s); error %.6g -> %.6g in %d iterations",
            self.num_nodes,
            len(self._odometry),
            len(self._loops),
            loop_kernel,
            before,
            after,
            optimizer.iterations(),
        )
        poses = np.array([result.atPose3(k).matrix() for k in range(self.num_nodes)])
        report = _loop_report(loop_factors, result)
        return OptimizationResult(poses, start, before, after, optimizer.iterations(), *report)

    def _check_connected(self) -> None:
        edges = np.array([(e.i, e.j) for e in self._odometry + self._loops], dtype=int).reshape(-1, 2)
        links = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(self.num_nodes,) * 2)
        _, label = connected_components(links, directed=False)
        loose = np.flatnonzero(label != label[0])
        if loose.size:
            raise SlamError(f"node(s) {loose[:10].tolist()} are linked to node 0 by no chain of edges")

    def _edge(self, i: int, j: int, relative_pose, information: np.ndarray, kind: str) -> _Edge:
        for k in (i, j):
            if not isinstance(k, (int, np.integer)) or not 0 <= k < self.num_nodes:
                raise SlamError(f"{kind} edge ({i}, {j}): node {k} does not exist (the graph has {self.num_nodes})")
        if i == j:
            raise SlamError(f"{kind} edge ({i}, {j}) joins a node to itself")
        return _Edge(int(i), int(j), check_pose(relative_pose, f"the {kind} edge ({i}, {j})"), information)


def information_from_sigmas(sigmas) -> np.ndarray:
    """The diagonal 6 x 6 information matrix of independent sigmas (x y z in m, rx ry rz in rad)."""
    sigmas = np.asarray(sigmas, dtype=float)
    if sigmas.shape != (6,) or not np.all(np.isfinite(sigmas)) or np.any(sigmas <= 0):
        raise SlamError(f"sigmas must be 6 positive numbers (x y z rx ry rz), got {sigmas}")
    return np.diag(sigmas**-2.0)


# -- checks and conversions -------------------------------------------------
def _check_information(information) -> np.ndarray:
    info = np.asarray(information, dtype=float)
    if info.shape != (6, 6) or not np.all(np.isfinite(info)):
        raise SlamError(f"the information matrix must be a finite 6 x 6 matrix, got shape {info.shape}")
    if not np.allclose(info, info.T, rtol=1e-9, atol=1e-12 * np.abs(info).max()):
        raise SlamError("the information matrix must be symmetric")
    if np.linalg.eigvalsh(info).min() <= 0:
        raise SlamError("the information matrix must be positive definite (all eigenvalues > 0)")
    return info


def _pose3(pose: np.ndarray) -> gtsam.Pose3:
    return gtsam.Pose3(gtsam.Rot3.ClosestTo(pose[:3, :3]), pose[:3, 3].copy())


def _gaussian(information: np.ndarray):
    """Translation-first information -> GTSAM (rotation-first) Gaussian noise model."""
    return gtsam.noiseModel.Gaussian.Information(information[np.ix_(_TO_GTSAM, _TO_GTSAM)])


def _loop_noise_factory(kernel: str, scale: float | None):
    if kernel not in LOOP_KERNELS:
        raise SlamError(f"loop_kernel must be one of {', '.join(LOOP_KERNELS)}, got {kernel!r}")
    if kernel == "none":
        return _gaussian
    scale = KERNEL_SCALES[kernel] if scale is None else float(scale)
    if not (np.isfinite(scale) and scale > 0):
        raise SlamError(f"kernel_scale must be a positive number of sigmas, got {scale}")
    estimator = _ESTIMATORS[kernel].Create(scale)
    return lambda information: gtsam.noiseModel.Robust.Create(estimator, _gaussian(information))


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
