"""Stage 3b: the robust fit of two scans from matched points (the
reference's ``estgeotform3d`` with MSAC), with its two solvers:
:func:`estimate_rigid_msac` (six degrees of freedom, samples of 3 matches:
the reference's) and :func:`estimate_yaw_msac` (yaw and translation, samples
of 2). ``[registration] robust_fit`` names the one a run uses;
:mod:`helpers.slam.registration.icp` refines its answer.
"""

from __future__ import annotations

import numpy as np

from helpers.errors import SlamError
from helpers.slam.registration.msac import equivalent_trials, estimate_rigid_msac
from helpers.slam.registration.msac_yaw import SAMPLE_SIZE as PAIR_SIZE
from helpers.slam.registration.msac_yaw import estimate_yaw_msac

__all__ = ["equivalent_trials", "estimate_rigid_msac", "estimate_yaw_msac", "robust_fit"]


def robust_fit(moving_pts, fixed_pts, fit) -> tuple[np.ndarray, np.ndarray]:
    """The robust fit ``fit.robust_fit`` names (``fit``: a
    :class:`helpers.config.tables.RegistrationConfig`), with its distance, trial cap,
    seed and confidence: ``(T, inliers)`` as :func:`estimate_rigid_msac` returns.

    ``"msac"``: :func:`estimate_rigid_msac`, at most ``max_num_trials``
    samples of 3 matches. ``"msac4"``: :func:`estimate_yaw_msac`,
    roll and pitch left to ICP; its cap is :func:`equivalent_trials`, so that
    it gives up at the same inlier ratio as the rigid fit would.
    """
    if fit.robust_fit == "msac":
        return estimate_rigid_msac(
            moving_pts, fixed_pts, fit.max_distance, fit.max_num_trials, fit.seed, fit.confidence
        )
    if fit.robust_fit == "msac4":
        cap = equivalent_trials(fit.max_num_trials, fit.confidence, PAIR_SIZE)
        return estimate_yaw_msac(moving_pts, fixed_pts, fit.max_distance, cap, fit.seed, fit.confidence)
    raise SlamError(f"unknown robust fit {fit.robust_fit!r}: use msac or msac4")
