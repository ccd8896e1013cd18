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
adds it with :meth:`helpers.posegraph.PoseGraph.add_factor` and
:meth:`~helpers.posegraph.PoseGraph.optimize` needs no change.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import gtsam
import numpy as np

from .config import LOOP_KERNELS
from .errors import SlamError

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
_TO_GTSAM = np.array([3, 4, 5, 0, 1, 2])  # translation-first index -> rotation-first order


@dataclass(frozen=True)
class Edge:
    """One measured relative pose between two nodes, whoever measured it
    (an odometry step, an edge back, a loop): ``pose_j = pose_i @ relative``,
    ``relative`` being ``T_i_j``."""

    i: int
    j: int
    relative: np.ndarray  # (4, 4) T_i_j
    surface_rmse: float = float("nan")  # m, of the registration that measured it (nan: not scored)
    # 6 x 6, translation first, how sure the registration is (helpers.information; calibrated when the pose
    # graph is built); None: the configured fixed sigmas
    information: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def rmse(self) -> float:
        """``surface_rmse`` by its short name (the notebooks read it)."""
        return self.surface_rmse

    @property
    def relative_pose(self) -> np.ndarray:
        """``relative`` by the name loop matches used to have (notebook 5 reads it)."""
        return self.relative


@dataclass(frozen=True)
class FactorContext:
    """What :meth:`~helpers.posegraph.PoseGraph.optimize` tells every factor: the noise of loop edges."""

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
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(self.sigmas, float)[_TO_GTSAM])
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
    return gtsam.noiseModel.Gaussian.Information(information[np.ix_(_TO_GTSAM, _TO_GTSAM)])


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
