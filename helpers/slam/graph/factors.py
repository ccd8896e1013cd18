"""What a pose graph is made of (stage 6): the edge record every stage
hands over, and the factors, each of which knows how to add itself to a
GTSAM graph (the way kiss-slam's ``add_factor`` and GTSAM's own examples
add a prior, a between factor or a GPS factor).

Conventions:

* A node's pose is ``T_map_sensor``: ``p_map = pose @ p_scan``.
* An edge ``(i, j, T_i_j)`` says ``pose_j = pose_i @ T_i_j``: ``T_i_j``
  carries points of scan ``j`` into the frame of scan ``i``, exactly the
  ``T_fixed_moving`` of ICP registering scan ``j`` (moving) onto scan ``i`` (fixed).
* Six-vectors and information matrices given to or returned by this module
  are TRANSLATION FIRST, ``[x y z rx ry rz]``, as in the reference's
  ``poseGraph3D``. GTSAM orders a Pose3 tangent vector rotation first, so
  every information matrix (and sigma vector) is permuted on the way in.

A new kind of factor is one more class with ``nodes`` (the node ids it
touches) and ``to_gtsam(context)`` returning a GTSAM factor; the pose graph
adds it with :meth:`helpers.slam.graph.optimizer.PoseGraph.add_factor` and
:meth:`~helpers.slam.graph.optimizer.PoseGraph.optimize` needs no change.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import gtsam
import numpy as np

from helpers.config.pose_graph import LOOP_KERNELS
from helpers.errors import SlamError
from helpers.slam.graph.information import SWAP_ROTATION_TRANSLATION, swap_blocks

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


@dataclass(frozen=True)
class Edge:
    """One measured relative pose between two nodes, whoever measured it
    (an odometry step, an edge back, a loop): ``pose_j = pose_i @ relative``,
    ``relative`` being ``T_i_j``."""

    i: int
    j: int
    relative: np.ndarray  # (4, 4) T_i_j
    surface_rmse: float = float("nan")  # m, of the registration that measured it (nan: not scored)
    # 6 x 6, translation first, how sure the registration is (.information, calibrated by the run's ICP
    # service); None: the configured fixed sigmas. By keyword only, so records built on Edge keep their fields.
    information: np.ndarray | None = field(default=None, repr=False, compare=False, kw_only=True)

    @property
    def rmse(self) -> float:
        """``surface_rmse`` by its short name (the notebooks read it)."""
        return self.surface_rmse


@dataclass(frozen=True)
class FactorContext:
    """What :meth:`~helpers.slam.graph.optimizer.PoseGraph.optimize` tells every factor: the noise of loop edges."""

    loop_noise: object = None  # information (6 x 6, translation first) -> GTSAM noise model


class Factor(Protocol):
    """Anything a pose graph can hold."""

    nodes: tuple[int, ...]

    def to_gtsam(self, context: FactorContext) -> gtsam.NonlinearFactor: ...


@dataclass(frozen=True)
class PriorFactor:
    """Holds node ``node`` at ``T_map_sensor`` with ``sigmas`` (x y z in m, rx ry rz in rad)."""

    node: int
    T_map_sensor: np.ndarray
    sigmas: np.ndarray = field(default_factory=lambda: PRIOR_SIGMAS.copy())

    @property
    def nodes(self) -> tuple[int, ...]:
        return (self.node,)

    def to_gtsam(self, context: FactorContext) -> gtsam.NonlinearFactor:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(self.sigmas, float)[SWAP_ROTATION_TRANSLATION])
        return gtsam.PriorFactorPose3(self.node, pose3(self.T_map_sensor), noise)


@dataclass(frozen=True)
class BetweenFactor:
    """An edge ``pose_j = pose_i @ T_i_j`` with its own Gaussian noise (``information``, translation first)."""

    i: int
    j: int
    T_i_j: np.ndarray
    information: np.ndarray

    @property
    def nodes(self) -> tuple[int, ...]:
        return (self.i, self.j)

    def to_gtsam(self, context: FactorContext) -> gtsam.NonlinearFactor:
        return gtsam.BetweenFactorPose3(self.i, self.j, pose3(self.T_i_j), gaussian(self.information))


@dataclass(frozen=True)
class LoopFactor(BetweenFactor):
    """A loop edge: a between factor wrapped in the robust kernel the optimisation is given."""

    def to_gtsam(self, context: FactorContext) -> gtsam.NonlinearFactor:
        noise = (context.loop_noise or gaussian)(self.information)
        return gtsam.BetweenFactorPose3(self.i, self.j, pose3(self.T_i_j), noise)


def edge_information(edge: Edge, settings, *, loop: bool = False) -> np.ndarray:
    """The (6, 6) translation-first information of ``edge`` under the
    ``[pose_graph]`` ``settings``, the one rule the run's pose graph
    (:func:`helpers.slam.graph.build.build_pose_graph`) and the loop search's graph
    (:mod:`helpers.slam.loops.uncertainty`) both weigh their edges by: with
    ``graph_weights = "hessian"`` the registration's own (``edge.information``,
    calibrated; an edge back's divided by the steps it spans), with ``"icp"``
    the sigmas of ``[pose_graph]`` times the steps spanned (a loop edge: once),
    with ``"identity"`` the reference's 1 m and 1 rad. An edge without its own
    information gets the icp sigmas.
    """
    span = 1 if loop else abs(edge.j - edge.i)
    information = edge.information
    if settings.graph_weights == "hessian" and information is not None:
        return check_information(information) / span
    if settings.graph_weights == "identity":
        return np.eye(6)
    return information_from_sigmas(settings.edge_sigmas * span)


def information_from_sigmas(sigmas) -> np.ndarray:
    """The diagonal 6 x 6 information matrix of independent sigmas (x y z in m, rx ry rz in rad)."""
    sigmas = np.asarray(sigmas, dtype=float)
    if sigmas.shape != (6,) or not np.all(np.isfinite(sigmas)) or np.any(sigmas <= 0):
        raise SlamError(f"sigmas must be 6 positive numbers (x y z rx ry rz), got {sigmas}")
    return np.diag(sigmas**-2.0)


def check_information(information) -> np.ndarray:
    """``information`` as a symmetric positive-definite 6 x 6 array, or a SlamError."""
    info = np.asarray(information, dtype=float)
    if info.shape != (6, 6) or not np.all(np.isfinite(info)):
        raise SlamError(f"the information matrix must be a finite 6 x 6 matrix, got shape {info.shape}")
    if not np.allclose(info, info.T, rtol=1e-9, atol=1e-12 * np.abs(info).max()):
        raise SlamError("the information matrix must be symmetric")
    if np.linalg.eigvalsh(info).min() <= 0:
        raise SlamError("the information matrix must be positive definite (all eigenvalues > 0)")
    return info


def pose3(pose: np.ndarray) -> gtsam.Pose3:
    """A 4 x 4 rigid transform as a GTSAM Pose3."""
    return gtsam.Pose3(gtsam.Rot3.ClosestTo(pose[:3, :3]), pose[:3, 3].copy())


def gaussian(information: np.ndarray):
    """Translation-first information -> GTSAM (rotation-first) Gaussian noise model."""
    return gtsam.noiseModel.Gaussian.Information(swap_blocks(information))


def loop_noise_factory(kernel: str, scale: float | None):
    """information -> the noise model of a loop edge under ``kernel`` (``scale`` in sigmas)."""
    if kernel not in LOOP_KERNELS:
        raise SlamError(f"loop_kernel must be one of {', '.join(LOOP_KERNELS)}, got {kernel!r}")
    if kernel == "none":
        return gaussian
    scale = KERNEL_SCALES[kernel] if scale is None else float(scale)
    if not (np.isfinite(scale) and scale > 0):
        raise SlamError(f"kernel_scale must be a positive number of sigmas, got {scale}")
    estimator = _ESTIMATORS[kernel].Create(scale)
    return lambda information: gtsam.noiseModel.Robust.Create(estimator, gaussian(information))


@dataclass(frozen=True)
class ConstantVelocityFactor:
    """A soft motion model over three consecutive nodes ``i, j, k``: the step
    ``j -> k``, seen from node ``j``, equals the step ``i -> j`` seen from node
    ``i`` (a drone keeps its speed, and its turn rate, from one node to the
    next). Its error is ``Logmap(T_i_j^-1 T_j_k)``, zero for a straight line at
    a steady speed and for a steady turn alike; ``sigmas`` (x y z in m, rx ry rz
    in rad, translation first) say how much the step may change between
    consecutive nodes (:func:`constant_velocity_sigmas` derives them from an
    acceleration). Directions no scan pins then follow the flight's momentum
    instead of sliding freely."""

    i: int
    j: int
    k: int
    sigmas: np.ndarray

    @property
    def nodes(self) -> tuple[int, ...]:
        return (self.i, self.j, self.k)

    def to_gtsam(self, context: FactorContext) -> gtsam.NonlinearFactor:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(self.sigmas, float)[SWAP_ROTATION_TRANSLATION])
        return gtsam.CustomFactor(noise, list(self.nodes), _constant_velocity_error)


def _constant_velocity_error(factor, values, jacobians) -> np.ndarray:
    """GTSAM's callback for :class:`ConstantVelocityFactor`: the error (rotation first) and, when asked
    for, its Jacobians with respect to the three poses, chained from GTSAM's own (``between``, ``Logmap``)."""
    a, b, c = (values.atPose3(key) for key in factor.keys())
    if jacobians is None:  # the optimiser asks for the error alone far more often than for a linearisation
        return gtsam.Pose3.Logmap(a.between(b).between(b.between(c)))
    d_a, d_b1, d_b2, d_c, d_first, d_second, d_log = (np.zeros((6, 6), order="F") for _ in range(7))
    first = a.between(b, d_a, d_b1)  # T_i_j
    second = b.between(c, d_b2, d_c)  # T_j_k
    error = gtsam.Pose3.Logmap(first.between(second, d_first, d_second), d_log)
    jacobians[0] = d_log @ d_first @ d_a
    jacobians[1] = d_log @ (d_first @ d_b1 + d_second @ d_b2)
    jacobians[2] = d_log @ d_second @ d_c
    return error


def constant_velocity_sigmas(step_m: float, speed: float, acceleration: float, angular_acceleration: float):
    """The (6,) translation-first sigmas of a :class:`ConstantVelocityFactor`.

    The simulator has no clock (a scan per waypoint), so the time between two
    nodes is their step over the drone's nominal ground speed:
    ``dt = step_m / speed``. A drone that accelerates by ``a`` for ``dt``
    changes its step by ``a dt^2`` (the second difference of its positions),
    and one whose turn rate changes by ``alpha`` per second changes its turn by
    ``alpha dt^2``: ``acceleration`` (m/s^2) gives the translation sigma,
    ``angular_acceleration`` (rad/s^2) the rotation sigma.
    """
    values = np.array([step_m, speed, acceleration, angular_acceleration], dtype=float)
    if not (np.all(np.isfinite(values)) and np.all(values > 0)):
        raise SlamError(f"a constant-velocity sigma needs a positive step, speed and accelerations, got {values}")
    dt = step_m / speed
    return np.array([acceleration * dt**2] * 3 + [angular_acceleration * dt**2] * 3)


def motion_sigmas(step_m: float, table) -> np.ndarray:
    """:func:`constant_velocity_sigmas` for nodes ``step_m`` apart, with the speed and accelerations of
    ``table`` (``[pose_graph]``; its angular acceleration is in deg/s^2)."""
    angular = np.radians(table.motion_angular_acceleration)
    return constant_velocity_sigmas(step_m, table.motion_speed, table.motion_acceleration, angular)


def motion_factors(relative, table) -> list[ConstantVelocityFactor]:
    """A :class:`ConstantVelocityFactor` over every three consecutive nodes of a chain whose odometry steps
    are ``relative`` ((K-1, 4, 4)), with the accelerations of ``table`` (``[pose_graph]``): the step between
    nodes is the odometry's median step (steps shorter than a millimetre count as one)."""
    relative = np.asarray(relative, dtype=float).reshape(-1, 4, 4)
    if len(relative) < 2:
        return []
    step = max(float(np.median(np.linalg.norm(relative[:, :3, 3], axis=1))), 1e-3)
    sigmas = motion_sigmas(step, table)
    return [ConstantVelocityFactor(k - 2, k - 1, k, sigmas) for k in range(2, len(relative) + 1)]


@dataclass(frozen=True)
class PositionFactor:
    """A position fix of node ``node`` (a GNSS receiver's: GTSAM's GPS factor):
    the sensor is at ``position`` (map frame, m) with ``sigmas`` (x y z, m)."""

    node: int
    position: np.ndarray
    sigmas: np.ndarray

    @property
    def nodes(self) -> tuple[int, ...]:
        return (self.node,)

    def to_gtsam(self, context: FactorContext) -> gtsam.NonlinearFactor:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(self.sigmas, float))
        return gtsam.GPSFactor(self.node, np.asarray(self.position, float), noise)


def gnss_factors(fixes, node_indices) -> list[PositionFactor]:
    """A position factor for every node that has a fix (``fixes``: :class:`helpers.sim.gnss.GnssFixes`,
    or anything with ``indices``, ``positions`` and ``sigmas``; ``node_indices[k]``: the scan index of node ``k``)."""
    row = {int(index): r for r, index in enumerate(fixes.indices)}
    return [
        PositionFactor(node, fixes.positions[row[int(index)]], fixes.sigmas)
        for node, index in enumerate(node_indices)
        if int(index) in row
    ]
